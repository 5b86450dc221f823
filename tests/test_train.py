"""Training: the validation callback, checkpoints and resume, the env, the CLI smoke run."""

import dataclasses
import json
import types
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
import yaml
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.env_checker import check_env
from typer.testing import CliRunner

from perception.grid import OccupancyGridBuilder
from planner.learned import load_agent
from planner.model_file import load_model
from planner.validation import RealTimeValidation, Validation
from stack.apps.cli import app
from stack.settings.run import build_config, grid_config
from stack.sim.envs import HIERARCHICAL_HIGHWAY
from stack.training.checkpoint import DqnCounters, TabularCounters, read_checkpoint
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.summary import TrainSummary
from stack.training.trainer import Trainer
from tests.helpers import scene

TINY = {
    "seed": 1,
    "highway": {"vehicles_count": 12, "duration": 5},
    "perception": {"lanes": "ego", "features": ["relative_speed", "ttc", "ego_speed"]},
    "train": {
        "steps": 40,
        "learning_starts": 5,
        "batch_size": 8,
        "buffer_size": 200,
        "checkpoint_every": 10,
        "network": "16",
        "validation": {"short_every": 10, "short_episodes": 1, "long_every": 20, "long_episodes": 2},
    },
}


class Scripted(gym.Env):
    """One-step episodes whose outcome (crash or not, return) the test sets: `outcome` for the
    episode of seed 0, `later` (default: the same) for the others."""

    observation_space, action_space = gym.spaces.Box(0, 1, (1,)), gym.spaces.Discrete(3)
    outcome, later = (False, 1.0), None

    def reset(self, *, seed=None, options=None):
        self.seed_ = seed
        return np.zeros(1, np.float32), {}

    def step(self, action):
        crashed, reward = self.outcome if self.seed_ == 0 or self.later is None else self.later
        return np.zeros(1, np.float32), reward, crashed, not crashed, {"crashed": crashed, "speed": 20.0}


class FakeModel:
    num_timesteps = 0

    def predict(self, observation, deterministic=True):
        return 1, None


def test_validation_keeps_a_model_only_when_its_long_validation_improves():
    env, saved = Scripted(), []
    callback = RealTimeValidation(env, 10, 1, 50, 3, 0, lambda model, v: saved.append(v.step))
    callback.model = FakeModel()
    for step, outcome, later in [
        (10, (False, 1.0), None),
        (20, (False, 0.5), None),
        (30, (True, 9.0), None),
        (40, (False, 2.0), None),
        (50, (False, 2.0), None),
        (60, (False, 5.0), (True, 0.0)),
    ]:
        env.outcome, env.later = outcome, later
        callback.num_timesteps = step
        callback._on_step()
    assert saved == [10, 40], "a lower return, a crash, an equal score or a bad long run is not kept"
    periods = [(v.step, v.period) for v in callback.history]
    assert periods == [
        (10, "short"),
        (10, "long"),
        (20, "short"),
        (30, "short"),
        (40, "short"),
        (40, "long"),
        (50, "long"),
        (60, "short"),
        (60, "long"),
    ], "a short improvement promotes the model to a long validation at once"
    assert callback.history[-1].collision_rate == pytest.approx(2 / 3)
    assert callback.history[3].collision_rate == 1.0


def test_hierarchical_env_passes_sb3_check_and_reports_info():
    env = gym.make(HIERARCHICAL_HIGHWAY, config=TINY)
    check_env(env.unwrapped)
    observation, info = env.reset(seed=3)
    assert env.observation_space.contains(observation)
    _, reward, _, _, info = env.step(1)
    assert {"crashed", "speed", "passed_cars", "masked"} <= set(info)
    assert reward == pytest.approx(1.0)


def test_every_step_spans_one_decision_period_and_a_lane_change_ignores_new_actions():
    env = gym.make(
        HIERARCHICAL_HIGHWAY,
        config={
            **TINY,
            "highway": {"vehicles_count": 1, "duration": 10},
            "train": {**TINY["train"], "reward": {"lane_change": 0.25}},
            # the one other car starts 16 m ahead in the lane beyond: not what this test is about
            "planner": {"safety": {"far_lane_leader": False}},
        },
    )
    env.reset(seed=0)
    loop = env.unwrapped.loop
    towards_centre = 0 if loop.maneuver.lane > 0 else 2
    times, rewards = [loop.world.time], []
    for action in (towards_centre, 2 - towards_centre, 2 - towards_centre, 2 - towards_centre):
        rewards.append(env.step(action)[1])
        times.append(loop.world.time)
    assert np.diff(times) == pytest.approx([1.0] * 4)
    assert rewards == pytest.approx([0.75, 1.0, 1.0, 1.0]), "only the request that counts pays the cost"

    assert loop.maneuver.changing_lane and loop.maneuver.lane_changes == 1
    while loop.maneuver.changing_lane:
        env.step(1)
    assert loop.maneuver.lane_changes == 1 and loop.safety.masked == 0


def test_training_resumes_after_an_interruption(tmp_path, monkeypatch):

    config = build_config(TINY)
    out = tmp_path / "run"
    trainer = Trainer(config, out, progress=False)
    real_step = type(trainer.env.unwrapped).step
    calls = {"n": 0}

    def step_then_interrupt(self, action):
        calls["n"] += 1
        if calls["n"] == 25:
            raise KeyboardInterrupt
        return real_step(self, action)

    monkeypatch.setattr(type(trainer.env.unwrapped), "step", step_then_interrupt)
    summary = trainer.run()
    assert summary.interrupted
    _, checkpoint = load_model(out / "checkpoint.npz")
    done = checkpoint["counters"]["num_timesteps"]
    assert 10 <= done < 40
    monkeypatch.setattr(type(trainer.env.unwrapped), "step", real_step)
    resumed = Trainer.resume(out, steps=None, progress=False).run()
    assert not resumed.interrupted and resumed.steps == 40
    history = json.loads((out / "validation.json").read_text())
    assert [v["step"] for v in history] == [10, 20, 30, 40], "validations before the interruption are kept"
    assert load_agent(out / "final.npz").metadata.trained_steps == 40


def trained(tmp_path: Path, data: dict) -> tuple[Path, Path]:
    """`drivestack train` of config `data` (written to tmp_path): the config file and the folder."""
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["train", "--config", str(config), "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    return config, out


def test_train_cli_smoke_writes_best_model_and_curve(tmp_path):
    config, out = trained(tmp_path, TINY)
    for name in (
        "best.npz",
        "final.npz",
        "checkpoint.npz",
        "training_curve.png",
        "summary.json",
        "config.yaml",
    ):
        assert (out / name).is_file(), name
    assert any(Path(out / "tensorboard").rglob("events.out.tfevents.*"))
    written = json.loads((out / "summary.json").read_text())
    summary = TrainSummary.from_json(written)
    assert summary.to_json() == written and list(summary.to_json()) == list(written), "a JSON round-trip"
    assert summary.steps == 40 and summary.validations == 5, (
        "short 10 (promoted: long 10), long 20, short 30, long 40"
    )
    assert summary.best_validation is not None and summary.best_validation.period == "long"

    run = CliRunner().invoke(
        app,
        [
            "run",
            "--agent",
            "ddqn",
            "--model",
            str(out / "best.npz"),
            "--episodes",
            "1",
            "--out",
            str(tmp_path / "drive"),
            "--no-progress",
            "-c",
            str(config),
        ],
    )
    assert run.exit_code == 0, run.output


@pytest.mark.parametrize("algorithm", ["dqn", "tabular"])
def test_other_algorithms_train_too(tmp_path, algorithm):
    data = {
        **TINY,
        "train": {
            **TINY["train"],
            "algorithm": algorithm,
            "encoding": "tabular" if algorithm == "tabular" else "observation",
        },
    }
    summary = Trainer(build_config(data), tmp_path / algorithm, progress=False).run()
    assert summary.steps == 40
    assert load_agent(tmp_path / algorithm / "best.npz").metadata.algorithm == algorithm


@pytest.mark.slow
def test_parallel_environments_give_the_same_model_for_the_same_config(tmp_path):
    """`--envs 2`: two processes step the env; the same config, seed and N give the same weights,
    and checkpoints and validations still come at every multiple of their period."""
    data = {**TINY, "train": {**TINY["train"], "envs": 2}}
    runs = []
    for name in ("a", "b"):
        summary = Trainer(build_config(data), tmp_path / name, progress=False).run()
        assert summary.steps == 40 and summary.validations == 5
        runs.append(load_model(tmp_path / name / "final.npz")[0])
    assert runs[0].keys() == runs[1].keys()
    for key in runs[0]:
        np.testing.assert_array_equal(runs[0][key], runs[1][key], err_msg=key)


def test_envs_must_be_at_least_one_and_one_for_tables(tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    result = CliRunner().invoke(
        app, ["train", "-c", str(config), "--envs", "0", "--out", str(tmp_path / "o")]
    )
    assert (
        result.exit_code == 2
        and "train.envs" in result.output
        and "greater than or equal to 1" in result.output
    )
    result = CliRunner().invoke(
        app, ["train", "-c", str(config), "--envs", "2", "--agent", "tabular", "--out", str(tmp_path / "o")]
    )
    assert result.exit_code == 2 and "envs: tabular Q-learning steps one environment" in result.output
    assert not (tmp_path / "o").exists()


def test_a_scenario_mix_draws_each_episode_s_world_from_its_shares():
    data = {
        **TINY,
        "perception": {**TINY["perception"], "lane_code": "sides"},
        "train": {**TINY["train"], "scenarios": {"lanes-3": 1.0, "lanes-5": 1.0}},
    }
    env = gym.make(HIERARCHICAL_HIGHWAY, config=data)
    drawn = []
    for seed in range(8):
        observation, _ = env.reset(seed=seed)
        assert env.observation_space.contains(observation)
        drawn.append(env.unwrapped.loop.config.scenario)
        env.step(1)
    assert set(drawn) == {"lanes-3", "lanes-5"}
    again = gym.make(HIERARCHICAL_HIGHWAY, config=data)
    assert [again.reset(seed=seed) and again.unwrapped.loop.config.scenario for seed in range(8)] == drawn


def test_a_mix_of_roads_needs_an_encoding_of_one_size(tmp_path):
    config = tmp_path / "mix.yaml"
    config.write_text(
        yaml.safe_dump({**TINY, "train": {**TINY["train"], "scenarios": {"lanes-3": 1, "lanes-5": 1}}})
    )
    result = CliRunner().invoke(app, ["train", "-c", str(config), "--out", str(tmp_path / "o")])
    assert (
        result.exit_code == 2
        and "train.scenarios: the observation encoding has a different size" in result.output
    )
    assert not (tmp_path / "o").exists()


DEMONSTRATIONS = {"expert": "mobil", "episodes": 2, "pretrain_steps": 20}
RESUMABLE = [
    pytest.param("ddqn", 1, None, id="ddqn"),
    pytest.param("tabular", 1, None, id="tabular"),
    pytest.param("ddqn", 1, DEMONSTRATIONS, id="ddqn-demonstrations"),
    pytest.param("ddqn", 2, None, id="ddqn-2-envs", marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("algorithm", "envs", "demonstrations"), RESUMABLE)
def test_a_stopped_and_resumed_run_ends_as_an_uninterrupted_one(
    tmp_path, monkeypatch, algorithm, envs, demonstrations
):
    """SIGTERM twice (here: the handler, called at a step of the env class or, for the workers, of
    the validation) stops at the next consistent point, mid-episode: the checkpoint holds every
    transition collected, every gradient step taken, the generators, the episodes under way and
    the demonstrations, so the resumed run ends with the counts and the very weights of a run
    never stopped (and does not record or pre-train again)."""
    encoding = "tabular" if algorithm == "tabular" else "observation"
    train = {**TINY["train"], "algorithm": algorithm, "encoding": encoding, "envs": envs}
    train |= {"target_update_interval": 8, "demonstrations": demonstrations}
    highway = {**TINY["highway"], "duration": 5 if envs == 1 else 7}
    config = build_config({**TINY, "highway": highway, "train": train})
    Trainer(config, tmp_path / "whole", progress=False).run()
    whole_arrays, whole = load_model(tmp_path / "whole" / "checkpoint.npz", 2**31)
    trainer = Trainer(config, tmp_path / "cut", progress=False)
    real_step = HierarchicalHighwayEnv.step
    calls = {"n": 0}

    def step_then_signal(self, action):
        calls["n"] += 1
        if calls["n"] == (3 if envs > 1 else 27 if demonstrations is None else 14):
            trainer._request_stop(15, None)
            trainer._request_stop(15, None)  # a second signal waits too
        return real_step(self, action)

    if envs == 1:
        monkeypatch.setattr(HierarchicalHighwayEnv, "step", step_then_signal)
    else:
        trainer.validation_env.step = types.MethodType(step_then_signal, trainer.validation_env)
    assert trainer.run().interrupted
    counters = TabularCounters if algorithm == "tabular" else DqnCounters
    stopped_arrays, stopped_metadata = load_model(tmp_path / "cut" / "checkpoint.npz", 2**31)
    stopped = read_checkpoint(stopped_metadata, counters).counters
    assert 0 < stopped.num_timesteps < 40
    if algorithm != "tabular":
        assert isinstance(stopped, DqnCounters) and not stopped.buffer_full
        assert len(stopped_arrays["buffer/observations"]) == stopped.buffer_pos < 200, "filled rows only"
    assert stopped.episodes is not None and any(episode.actions for episode in stopped.episodes), (
        "stopped mid-episode"
    )
    monkeypatch.setattr(HierarchicalHighwayEnv, "step", real_step)
    Trainer.resume(tmp_path / "cut", steps=None, progress=False).run()
    resumed_arrays, resumed = load_model(tmp_path / "cut" / "checkpoint.npz", 2**31)
    assert read_checkpoint(resumed, counters).counters == read_checkpoint(whole, counters).counters
    checkpoint = read_checkpoint(resumed, counters).to_json()
    assert checkpoint == {key: value for key, value in resumed.items() if key != "format"}, "a round-trip"
    assert resumed_arrays.keys() == whole_arrays.keys()
    for name, weights in whole_arrays.items():
        np.testing.assert_array_equal(resumed_arrays[name], weights, err_msg=name)


def test_no_empty_training_curve_is_drawn(tmp_path):
    data = {
        **TINY,
        "train": {**TINY["train"], "steps": 5, "validation": {"short_every": 100, "long_every": 200}},
    }
    summary = Trainer(build_config(data), tmp_path / "short", progress=False).run()
    assert summary.validations == 0 and summary.training_curve == "not drawn: no validation ran yet"
    assert not (tmp_path / "short" / "training_curve.png").exists()


def test_n_step_returns_discount_each_sample_by_gamma_to_its_length(tmp_path):
    """`train.n_steps` switches SB3 to its n-step buffer: a sample's reward sums up to n rewards
    and its discount is gamma^k, k <= n (shorter where the episode ended)."""
    config = build_config({**TINY, "train": {**TINY["train"], "n_steps": 3, "gamma": 0.9}})
    trainer = Trainer(config, tmp_path, progress=False)
    trainer.run()
    buffer = trainer.model.replay_buffer
    assert isinstance(buffer, NStepReplayBuffer) and buffer.n_steps == 3
    discounts = buffer.sample(200).discounts.numpy().ravel()
    assert np.isclose(discounts[:, None], [0.9, 0.81, 0.729]).any(axis=1).all()
    assert np.isclose(discounts, 0.729).mean() > 0.5, "most samples span three decisions"


def test_a_run_starts_from_init_model_and_refuses_one_that_does_not_fit(tmp_path):
    """`train.init_model`: the online and target networks start as the file's network (no gradient
    step before learning_starts, so the final model is that network), validated at step 0 as the
    first model to keep; a file with other hidden
    layers, a missing file or a tabular run are refused in one line before any episode."""
    Trainer(build_config(TINY), tmp_path / "first", progress=False).run()
    start = tmp_path / "first" / "final.npz"
    data = {**TINY, "train": {**TINY["train"], "steps": 6, "learning_starts": 100, "init_model": str(start)}}
    trainer = Trainer(build_config(data), tmp_path / "tuned", progress=False)
    trainer.run()
    tuned, original = load_model(tmp_path / "tuned" / "final.npz")[0], load_model(start)[0]
    for key in original:
        np.testing.assert_array_equal(tuned[key], original[key], err_msg=key)
    target = trainer.model.policy.q_net_target.q_net.state_dict()
    np.testing.assert_array_equal(target["0.weight"].numpy(), original["0.weight"])
    first = trainer.history[0]
    assert (first.step, first.period, first.improved) == (0, "long", True), "the start is a candidate"

    config = tmp_path / "other.yaml"
    for change, message in (
        ({"network": "16x16"}, "train.init_model: " + str(start) + " has hidden layers [16]"),
        ({"init_model": str(tmp_path / "none.npz")}, "no such model file"),
        ({"algorithm": "tabular", "encoding": "tabular"}, "init_model: tabular Q-learning starts"),
    ):
        config.write_text(yaml.safe_dump({**data, "train": {**data["train"], **change}}))
        result = CliRunner().invoke(app, ["train", "-c", str(config), "--out", str(tmp_path / "o")])
        assert result.exit_code == 2 and message in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_a_start_seeing_fewer_features_is_widened_and_decides_as_before(tmp_path):
    """A start model without the run's `traffic` feature starts the run (its first layer widened,
    the new inputs at zero weight): on any observation the widened network gives the start's
    Q-values on the same world seen without the feature; a start with a feature the run lacks is
    refused in one line."""
    Trainer(build_config(TINY), tmp_path / "first", progress=False).run()
    start = tmp_path / "first" / "final.npz"
    wider = {**TINY["perception"], "features": [*TINY["perception"]["features"], "traffic"]}
    data = {
        **TINY,
        "perception": wider,
        "train": {**TINY["train"], "steps": 6, "learning_starts": 100, "init_model": str(start)},
    }
    config = build_config(data)
    trainer = Trainer(config, tmp_path / "wide", progress=False)
    trainer.run()
    narrow_agent = load_agent(start)
    wide_network = trainer.model.policy.q_net.q_net
    env = HierarchicalHighwayEnv(config)
    env.reset(seed=3)
    narrow_view = OccupancyGridBuilder(narrow_agent.grid_config)
    wide_view = OccupancyGridBuilder(grid_config(config))
    for _ in range(4):
        world = env.loop.perceived
        wide = wide_view.build(world)
        assert np.abs(wide.traffic).sum() > 0, "the feature sees traffic ahead"
        with th.no_grad():
            q_wide = wide_network(th.as_tensor(wide.to_observation()[None])).numpy()
        q_narrow = narrow_agent.q_values(narrow_view.build(world).to_observation())
        np.testing.assert_allclose(q_wide, q_narrow, rtol=1e-5, atol=1e-6)
        env.step(1)

    narrower = tmp_path / "narrower.yaml"
    fewer = {**TINY["perception"], "features": ["relative_speed", "ttc"]}
    narrower.write_text(yaml.safe_dump({**data, "perception": fewer}))
    result = CliRunner().invoke(app, ["train", "-c", str(narrower), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "train.init_model" in result.output and "grid" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_a_paper_state_start_with_fewer_features_starts_as_it_is(tmp_path):
    """On the paper's state the features are not in the observation: a start that lists fewer of
    them has the run's input size and starts the run unchanged (no widening)."""
    paper = {**TINY, "train": {**TINY["train"], "encoding": "paper"}}
    Trainer(build_config(paper), tmp_path / "first", progress=False).run()
    start = tmp_path / "first" / "final.npz"
    more = {**paper["perception"], "features": [*paper["perception"]["features"], "traffic"]}
    data = {**paper, "perception": more}
    data["train"] = {**paper["train"], "steps": 6, "learning_starts": 100, "init_model": str(start)}
    Trainer(build_config(data), tmp_path / "tuned", progress=False).run()
    tuned, original = load_model(tmp_path / "tuned" / "final.npz")[0], load_model(start)[0]
    for key in original:
        np.testing.assert_array_equal(tuned[key], original[key], err_msg=key)


def test_a_mobil_prior_decides_in_rollouts_validation_and_the_written_files(tmp_path):
    """`train.mobil_prior`: the SB3 model's greedy actions and the agent loaded from its files are
    the same prior's decisions; a run that cannot show MOBIL its lanes is refused in one line."""
    data = {**TINY, "train": {**TINY["train"], "mobil_prior": 0.5}}
    trainer = Trainer(build_config(data), tmp_path / "prior", progress=False)
    trainer.run()
    agent = load_agent(tmp_path / "prior" / "best.npz")
    assert agent.metadata.mobil_prior == 0.5 and agent.prior is not None
    assert trainer.model.policy.q_net.prior.bonus == 0.5
    env = HierarchicalHighwayEnv(trainer.config)
    observations = [env.reset(seed=5)[0]]
    for _ in range(6):
        observations.append(env.step(1)[0])
    slow_leader = scene(4, (0.0, 1), [(15.0, 4.0), (-30.0, 8.0)], speed=25.0, other_speed=15.0)
    observations.append(OccupancyGridBuilder(grid_config(trainer.config)).build(slow_leader).to_observation())
    final = load_agent(tmp_path / "prior" / "final.npz")
    batch = np.stack(observations)
    greedy, _ = trainer.model.predict(batch, deterministic=True)
    assert greedy.tolist() == final.choose(batch).tolist()
    assert final.prior.bonuses(batch)[-1].tolist() == [0.5, 0, 0], "MOBIL proposes LEFT"

    refused = tmp_path / "refused.yaml"
    for change, message in (
        ({"perception": {"lanes": "ego", "features": ["ttc"]}}, "train.mobil_prior: MOBIL needs"),
        ({"train": {**data["train"], "algorithm": "dqn"}}, "mobil_prior: only the ddqn algorithm"),
    ):
        refused.write_text(yaml.safe_dump({**data, **change}))
        result = CliRunner().invoke(app, ["train", "-c", str(refused), "--out", str(tmp_path / "o")])
        assert result.exit_code == 2 and message in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_a_config_names_its_starting_model_beside_it_from_any_working_directory(tmp_path, monkeypatch):
    """A relative `train.init_model` naming a file beside the config file is that file (the former
    shipped model's config starts from `ddqn-stage3.npz` beside it, which started from
    `ddqn-stage2.npz` and that from `ddqn-stage1.npz`; the shipped config is taught by
    `ddqn-stage4.npz` beside it; also from an installed wheel)."""
    from stack.settings.run import load_config

    folder = tmp_path / "configs"
    folder.mkdir()
    (folder / "start.npz").write_bytes(b"")
    (folder / "train.yaml").write_text(yaml.safe_dump({"train": {"init_model": "start.npz"}}))
    monkeypatch.chdir(tmp_path)
    assert load_config("configs/train.yaml").train.init_model == str(folder / "start.npz")
    shipped = Path(__file__).parents[1] / "configs" / "train"
    for config, start in (
        ("ddqn-stage4.yaml", "ddqn-stage3.npz"),
        ("ddqn-stage3.yaml", "ddqn-stage2.npz"),
        ("ddqn-stage2.yaml", "ddqn-stage1.npz"),
    ):
        assert Path(load_config(shipped / config).train.init_model).samefile(shipped / start)
    teacher = load_config(shipped / "ddqn.yaml").train.demonstrations
    assert teacher is not None and Path(teacher.expert_model or "").samefile(shipped / "ddqn-stage4.npz")


def test_validation_scores_every_world_of_a_mix_and_shows_it():
    from planner.validation import validate

    data = {
        **TINY,
        "perception": {**TINY["perception"], "lane_code": "sides"},
        "train": {**TINY["train"], "scenarios": {"lanes-3": 1.0, "random": 1.0}},
    }
    env = gym.make(HIERARCHICAL_HIGHWAY, config=data)
    score = validate(lambda observation, deterministic: (1, None), env, 6, seed=3)
    assert set(score.worlds) == {"lanes-3", "random"}
    assert sum(world.episodes for world in score.worlds.values()) == 6
    assert all(world.mean_speed > 0 for world in score.worlds.values())
    validation = Validation(
        10, "long", 6, score.collision_rate, score.mean_return, score.mean_speed, True, score.worlds
    )
    line = validation.line()
    assert "lanes-3" in line and "random" in line and "(kept)" in line
    assert Validation.from_json(json.loads(json.dumps(dataclasses.asdict(validation)))) == validation


def test_training_on_roads_of_several_lane_counts_needs_an_encoding_of_one_size(tmp_path):
    config = tmp_path / "random.yaml"
    config.write_text(yaml.safe_dump({**TINY, "perception": {"lanes": "absolute"}}))
    result = CliRunner().invoke(
        app, ["train", "-c", str(config), "--scenario", "random", "--out", str(tmp_path / "o")]
    )
    assert result.exit_code == 2
    assert "has a different size on random (lane counts [2, 3, 4, 5, 6])" in result.output
    assert not (tmp_path / "o").exists()
