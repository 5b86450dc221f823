"""DeepCars: dynamics on hand-built grids, encodings, seeding, the quick reproduction."""

import json

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env

from stack.deepcars.reproduce import lookahead, reproduce
from stack.deepcars.world import LEFT, RIGHT, STAY, DeepCarsBatch
from stack.sim.envs import DEEPCARS


def empty(**kwargs) -> DeepCarsBatch:
    batch = DeepCarsBatch(1, spawn_probability=0.0, **kwargs)
    batch.cars[:] = False
    return batch


def test_cars_move_down_and_are_passed_when_they_leave_row_zero():
    batch = empty()
    batch.cars[0, 0, 0] = batch.cars[0, 3, 4] = True
    _, rewards, crashed, _, counts = batch.step(np.array([STAY]))
    assert rewards[0] == 1.0 and not crashed[0]
    assert counts["passed"][0] == 1 and batch.passed == 1
    assert batch.cars[0].nonzero() == (np.array([2]), np.array([4]))


def test_a_car_reaching_the_egos_cell_is_a_collision_that_ends_the_episode():
    batch = empty()
    batch.ego[0] = 2
    batch.cars[0, 1, 2] = True
    _, rewards, crashed, truncated, counts = batch.step(np.array([STAY]))
    assert rewards[0] == -1.0 and crashed[0] and not truncated[0]
    assert batch.collisions == 1 and batch.passed == 0
    assert counts["final_observation"][0][:10].tolist() == [0, 0, 1, 0, 0, 0, 0, 0, 0, 0]
    assert not batch.cars.any() and batch.ego[0] == 2, "the env reset itself"


def test_dodging_and_moving_into_a_car():
    batch = empty()
    batch.ego[0] = 2
    batch.cars[0, 1, 2] = True
    _, _, crashed, _, _ = batch.step(np.array([LEFT]))
    assert not crashed[0] and batch.ego[0] == 1
    batch.cars[0, 1, 0] = True
    _, _, crashed, _, _ = batch.step(np.array([LEFT]))
    assert crashed[0]


def test_moves_off_the_road_are_no_ops():
    batch = empty(lanes=3)
    batch.ego[0] = 0
    batch.step(np.array([LEFT]))
    assert batch.ego[0] == 0
    batch.ego[0] = 2
    batch.step(np.array([RIGHT]))
    assert batch.ego[0] == 2


def test_spawn_puts_one_car_in_the_top_row_each_step():
    batch = DeepCarsBatch(200, seed=3)
    batch.cars[:] = False
    batch.step(np.full(200, STAY))
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
        actions = np.random.default_rng(0).integers(0, 3, (50, 4))
        runs.append([batch.step(a)[0].copy() for a in actions])
    assert all(np.array_equal(a, b) for a, b in zip(*runs, strict=True))
    env = gym.make(DEEPCARS)
    check_env(env.unwrapped)
    first = [env.reset(seed=5)[0]] + [env.step(1)[0] for _ in range(5)]
    second = [env.reset(seed=5)[0]] + [env.step(1)[0] for _ in range(5)]
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


def test_quick_reproduction_reports_every_row(tmp_path):
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
