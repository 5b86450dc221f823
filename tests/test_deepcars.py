"""DeepCars: dynamics on hand-built grids, encodings, seeding, the reproduction (a tiny smoke run by
default, the quick one with -m slow)."""

import functools
import json
import tempfile

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.env_checker import check_env
from typer.testing import CliRunner

import stack.deepcars.reproduce as reproduce_module
from records import N_ACTIONS, Command
from stack.apps.cli import app
from stack.deepcars.reproduce import Budget, lookahead, reproduce
from stack.deepcars.rows import tabular_learner
from stack.deepcars.spec import PAPER_RULES, PUBLIC_RULES
from stack.deepcars.world import DeepCarsBatch
from stack.sim.envs import DEEPCARS


def empty(**kwargs) -> DeepCarsBatch:
    batch = DeepCarsBatch(1, spawn_probability=0.0, **kwargs)
    batch.cars[:] = False
    return batch


def test_cars_move_down_and_are_passed_when_they_leave_row_zero():
    batch = empty()
    batch.cars[0, 0, 0] = batch.cars[0, 3, 4] = True
    _, rewards, crashed, _, counts = batch.step(np.array([Command.STAY]))
    assert rewards[0] == 1.0 and not crashed[0]
    assert counts["passed"][0] == 1 and batch.passed == 1
    assert batch.cars[0].nonzero() == (np.array([2]), np.array([4]))


def test_a_car_reaching_the_egos_cell_is_a_collision_that_ends_the_episode():
    batch = empty()
    batch.ego[0] = 2
    batch.cars[0, 1, 2] = True
    _, rewards, crashed, truncated, counts = batch.step(np.array([Command.STAY]))
    assert rewards[0] == -1.0 and crashed[0] and not truncated[0]
    assert batch.collisions == 1 and batch.passed == 0
    assert counts["final_observation"][0][:10].tolist() == [0, 0, 1, 0, 0, 0, 0, 0, 0, 0]
    assert not batch.cars.any() and batch.ego[0] == 2, "the env reset itself"


def test_dodging_and_moving_into_a_car():
    batch = empty()
    batch.ego[0] = 2
    batch.cars[0, 1, 2] = True
    _, _, crashed, _, _ = batch.step(np.array([Command.LEFT]))
    assert not crashed[0] and batch.ego[0] == 1
    batch.cars[0, 1, 0] = True
    _, _, crashed, _, _ = batch.step(np.array([Command.LEFT]))
    assert crashed[0]


def test_moves_off_the_road_are_no_ops():
    batch = empty(lanes=3)
    batch.ego[0] = 0
    batch.step(np.array([Command.LEFT]))
    assert batch.ego[0] == 0
    batch.ego[0] = 2
    batch.step(np.array([Command.RIGHT]))
    assert batch.ego[0] == 2


def test_spawn_puts_one_car_in_the_top_row_each_step():
    batch = DeepCarsBatch(200, seed=3)
    batch.cars[:] = False
    batch.step(np.full(200, Command.STAY))
    assert (batch.cars[:, -1].sum(axis=1) == 1).all()
    assert not batch.cars[:, :-1].any()
    lanes = batch.cars[:, -1].argmax(axis=1)
    assert set(lanes.tolist()) == {0, 1, 2, 3, 4}


def test_encodings():
    batch = empty()
    batch.ego[0] = 3
    batch.cars[0, 2, 1] = batch.cars[0, 0, 4] = True
    binary = batch.observe()[0]
    assert binary.shape == (9 * 5 + 3,)
    assert binary[-3:].tolist() == [0, 1, 1]
    assert binary[2 * 5 + 1] == 1 and binary[4] == 1
    assert empty(encoding="one-hot").observe()[0][-5:].tolist() == [0, 0, 1, 0, 0]
    tabular = empty(encoding="tabular")
    tabular.ego[0] = 2
    tabular.cars[0, 6, 0] = tabular.cars[0, 3, 1] = tabular.cars[0, 0, 3] = True
    assert tabular.observe()[0].tolist() == [2, 6, 3, 8, 0, 8], "the paper's example state"


def test_same_seed_same_episode_and_the_gym_env():
    runs = []
    for _ in range(2):
        batch = DeepCarsBatch(4, seed=11)
        actions = np.random.default_rng(0).integers(0, N_ACTIONS, (50, 4))
        runs.append([batch.step(a)[0].copy() for a in actions])
    assert all(np.array_equal(a, b) for a, b in zip(*runs, strict=True))
    env = gym.make(DEEPCARS)
    check_env(env.unwrapped)
    first = [env.reset(seed=5)[0]] + [env.step(Command.STAY)[0] for _ in range(5)]
    second = [env.reset(seed=5)[0]] + [env.step(Command.STAY)[0] for _ in range(5)]
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="spawn_probability"):
        DeepCarsBatch(spawn_probability=2.0)
    with pytest.raises(ValueError, match="unknown encoding 'rgb'"):
        DeepCarsBatch(encoding="rgb")


def test_lookahead_rule_never_crashes():
    batch = DeepCarsBatch(100, encoding="tabular", seed=2)
    observations = batch.observe()
    for _ in range(300):
        observations, *_ = batch.step(lookahead(observations))
    assert batch.collisions == 0 and batch.passed > 25_000


@pytest.fixture
def one_torch_thread():
    """Torch's default two threads make the tiny networks' steps several times slower on a loaded
    2-core machine (threads waiting on each other); the rows do not depend on it."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


TINY = Budget(
    tabular_steps=300,
    tabular_long_steps=600,
    dqn_max_steps=1_200,
    eval_steps=2_000,
    short_every=400,
    long_every=800,
    short_episodes=1,
    long_episodes=1,
)
"""Enough for a few gradient steps (DQN learns from step 1000) and both validation periods."""


def test_tiny_reproduction_runs_every_kind_of_row_end_to_end(tmp_path, monkeypatch, one_torch_thread):
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    rows = reproduce(tmp_path, budget=TINY, networks=("16",))
    assert list(temp.glob("SB3-*")) == []
    agents = [(r.agent, r.network, r.training_steps) for r in rows]
    assert agents == [
        ("tabular", "-", 300),
        ("tabular", "-", 600),
        ("dqn", "16", 1_200),
        ("ddqn", "16", 1_200),
        ("random", "-", 0),
        ("always-stay", "-", 0),
        ("lookahead-rule", "-", 0),
    ]
    for row in rows:
        assert row.eval_passed + row.eval_collisions > 0 and 0 <= row.eval_accuracy <= 100
        assert row.eval_accuracy == pytest.approx(
            100 * row.eval_passed / (row.eval_passed + row.eval_collisions)
        )
        assert row.train_accuracy is None or 0 <= row.train_accuracy <= 100
    assert rows[-1].eval_accuracy == 100.0 and rows[-2].eval_collisions > 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["budget"]["dqn_max_steps"] == 1_200 and not summary["quick"]
    assert [entry["eval_passed"] for entry in summary["rows"]] == [r.eval_passed for r in rows]
    table = (tmp_path / "results.md").read_text()
    assert table.count("\n| ") == 8 and "| dqn | 16 | 1200 |" in table and "98.28 %" in table
    for figure in ("training_curves.png", "tabular_q_table.png"):
        assert (tmp_path / figure).read_bytes().startswith(b"\x89PNG")


@pytest.mark.slow
def test_quick_reproduction_reports_every_row(tmp_path, one_torch_thread):
    rows = reproduce(tmp_path, quick=True)
    agents = [(r.agent, r.network) for r in rows]
    assert agents[:2] == [("tabular", "-"), ("tabular", "-")]
    for algorithm in ("dqn", "ddqn"):
        for network in ("shallow", "medium", "deep", "16", "16x16"):
            assert (algorithm, network) in agents
    assert agents[-3:] == [("random", "-"), ("always-stay", "-"), ("lookahead-rule", "-")]
    results = json.loads((tmp_path / "summary.json").read_text())
    assert len(results["rows"]) == 15 and results["quick"]
    table = (tmp_path / "results.md").read_text()
    assert table.count("\n| ") == 16 and "98.28 %" in table and "99.14 %" in table
    assert (tmp_path / "training_curves.png").is_file() and (tmp_path / "tabular_q_table.png").is_file()
    assert rows[-1].eval_accuracy == 100.0


def test_the_public_rules_see_four_rows_the_paper_nine():
    for rules, rows in ((PAPER_RULES, 9), (PUBLIC_RULES, 4)):
        world, _ = tabular_learner(rules, seed=0)
        assert world.rows == rows and world.observation_space().high.tolist() == [4] + [rows - 1] * 5
        world.cars[0, rows - 1, 0] = True
        assert world.observe()[0, 1] == rows - 1, "a car in the top row is seen"
        grid = DeepCarsBatch(1, line_of_sight=rules.line_of_sight, encoding="binary")
        assert grid.observe().shape == (1, rows * 5 + 3)
    world, _ = tabular_learner(PUBLIC_RULES, seed=0)
    world.cars[:] = False
    world.step(np.array([Command.STAY]))
    assert world.cars[0, 3].sum() == 1, "spawned in row 3, the public code's top row"


def test_the_public_rules_decay_epsilon_by_0995_per_step_the_paper_keeps_02():
    _, public = tabular_learner(PUBLIC_RULES, seed=0)
    _, paper = tabular_learner(PAPER_RULES, seed=0)
    state = np.array([2, 3, 3, 3, 3, 3])
    assert public.epsilon == 1.0
    for step in range(1, 1200):
        public.predict(state, deterministic=False)
        paper.predict(state, deterministic=False)
        assert public.epsilon == pytest.approx(max(0.01, 0.995**step))
        assert public.epsilon == pytest.approx(PUBLIC_RULES.epsilon_after(step))
    assert public.epsilon == 0.01 and paper.epsilon == 0.2
    public.predict(state)
    assert public.epsilon == 0.01, "greedy predictions do not decay it"


def test_cli_reproduces_under_both_rule_sets(tmp_path, monkeypatch, one_torch_thread):
    tiny = functools.partial(reproduce_module.reproduce, budget=TINY, networks=("16",))
    monkeypatch.setattr(reproduce_module, "reproduce", tiny)
    result = CliRunner().invoke(app, ["reproduce", "deepcars", "--variant", "all", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    table = (tmp_path / "results.md").read_text()
    assert table.count("| paper |") == 7 and table.count("| public |") == 7
    assert table.index("| paper | tabular |") < table.index("| public | tabular |")
    assert "- public: 4-row line of sight, tabular epsilon 1 x0.995 per step, floor 0.01" in table
    assert "- paper: 9-row line of sight, tabular epsilon 0.2" in table
    for figure in ("tabular_q_table.png", "tabular_q_table-public.png", "training_curves.png"):
        assert (tmp_path / figure).read_bytes().startswith(b"\x89PNG")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [r["line_of_sight"] for r in summary["rules"]] == [9, 4]


def test_bad_variant_is_one_line_exit_2(tmp_path):
    result = CliRunner().invoke(app, ["reproduce", "deepcars", "--variant", "github", "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert result.output.strip() == "error: --variant: unknown 'github'; available: paper, public, all"


def test_a_stopped_reproduction_keeps_the_rows_it_finished(tmp_path, one_torch_thread, monkeypatch):
    """Ctrl-C during the DQN rows: the two tabular rows, written as they finished, stay in
    summary.json and results.md (state `interrupted`); nothing half-written is left."""
    import stack.deepcars.reproduce as module

    def interrupted(*arguments, **keywords):
        assert json.loads((tmp_path / "summary.json").read_text())["state"] == "running"
        raise KeyboardInterrupt

    monkeypatch.setattr(module, "deep", interrupted)
    rows = reproduce(tmp_path, budget=TINY, networks=("16",))
    assert [r.agent for r in rows] == ["tabular", "tabular"]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["state"] == "interrupted" and len(summary["rows"]) == 2
    assert (tmp_path / "results.md").read_text().count("| tabular |") == 2
    assert not list(tmp_path.glob(".*partial*"))
