"""Training on batched worlds (`train.worlds`): the CLI run, its refusals, resume and determinism,
the replay ratio, and the per-world path left as it was."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from planner.learned import load_agent
from planner.model_file import load_model
from stack.apps.cli import app
from stack.apps.training import training_owner
from stack.runtime.owner import fingerprint
from stack.settings.history import HOW_NOT_WHAT
from stack.settings.run import build_config
from stack.training.batch_env import TrainingWorlds, batched_worlds
from stack.training.checkpoint import DqnCounters, read_checkpoint
from stack.training.model import build_dqn
from stack.training.summary import TrainSummary
from stack.training.trainer import Trainer
from stack.training.world_shards import WorldShards
from tests.test_train import TINY

WORLDS = {**TINY, "train": {**TINY["train"], "worlds": 4, "target_update_interval": 8}}


def written(tmp_path: Path, data: dict) -> Path:
    config = tmp_path / "worlds.yaml"
    config.write_text(yaml.safe_dump(data))
    return config


def test_the_cli_trains_on_batched_worlds_with_the_action_mask_and_demonstrations(tmp_path):
    train = {**WORLDS["train"], "worlds": None, "envs": 2, "action_mask": True, "replay_ratio": 0.5}
    train["demonstrations"] = {"expert": "mobil", "episodes": 2, "pretrain_steps": 5}
    data = {**WORLDS, "train": train}
    out = tmp_path / "out"
    args = ["train", "-c", str(written(tmp_path, data)), "--worlds", "4", "--out", str(out)]
    result = CliRunner().invoke(app, [*args, "--no-progress"])
    assert result.exit_code == 0, result.output
    summary = TrainSummary.from_json(json.loads((out / "summary.json").read_text()))
    assert summary.steps == 40 and summary.worlds == 4, "--worlds replaces the config's 2 envs"
    assert summary.validations == 6, "the pre-trained start at step 0, then at 10, 20, 30, 40 (10: twice)"
    assert summary.gradient_steps_per_decision == 0.5, "2 gradient steps after each step of 4 worlds"
    assert summary.best_model is not None and summary.best_validation is not None
    assert summary.demonstrations is not None and summary.demonstrations.episodes == 2
    final = load_agent(out / "final.npz")
    assert final.metadata.trained_steps == 40 and final.metadata.action_mask
    assert load_agent(out / "best.npz").metadata.validation is not None


def test_the_replay_ratio_sets_the_gradient_steps_and_defaults_to_today_s(tmp_path):
    for envs in (1, 2):
        config = build_config({**TINY, "train": {**TINY["train"], "envs": envs}})
        assert config.train.gradient_steps == envs, "one gradient step per transition, as before"
    config = build_config({**WORLDS, "train": {**WORLDS["train"], "replay_ratio": 0.25}})
    env = TrainingWorlds(config, 4)
    try:
        assert build_dqn(config, env, tmp_path).gradient_steps == 1
    finally:
        env.close()


REFUSED = [
    ({"train.algorithm": "tabular", "train.encoding": "tabular"}, "tabular Q-learning steps one environment"),
    ({"train.envs": 3}, "train.worlds 4 does not split evenly over train.envs 3 processes"),
    ({"train.encoding": "paper"}, "train.encoding observation, not 'paper'"),
    ({"controller.type": "mpc"}, "batched worlds run the PID tracker"),
    ({"perception.features": "[ttc, traffic]"}, "not perception.features traffic"),
    ({"train.replay_ratio": 0.1}, "a whole number of gradient steps"),
]


@pytest.mark.parametrize(("sets", "message"), REFUSED)
def test_what_the_batch_does_not_run_is_refused_in_one_line(tmp_path, sets, message):
    args = ["train", "-c", str(written(tmp_path, WORLDS)), "--out", str(tmp_path / "o"), "--no-progress"]
    for key, value in sets.items():
        args += ["--set", f"{key}={value}"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and message in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


MIX = {
    **WORLDS,
    "perception": {**TINY["perception"], "lane_code": "sides"},
    "train": {**WORLDS["train"], "scenarios": {"lanes-3": 3.0, "lanes-5": 1.0}},
}


OVERLAPPED = {**WORLDS, "train": {**WORLDS["train"], "overlap": True, "replay_ratio": 0.5}}


@pytest.mark.parametrize(
    ("data", "envs"),
    [(WORLDS, 1), (MIX, 1), pytest.param(MIX, 2, marks=pytest.mark.slow), (OVERLAPPED, 2)],
    ids=["one-world", "mix", "mix-on-2-shards", "overlapped-on-2-shards"],
)
def test_a_stopped_and_resumed_batched_run_gives_the_model_of_an_uninterrupted_one(tmp_path, data, envs):
    """Stopped mid-episode, the checkpoint holds each world's episode under way (its generator's
    state when it began and its actions): the resumed run replays them and ends with the counts and
    the very weights of the run never stopped, which is also the same model file for the same
    config and seed. In a mix each world's episode draws its member (three or five lanes) as the
    per-world env does. Split over two processes (`envs: 2`), the shards' episodes are gathered
    into the checkpoint and each replays its own."""
    config = build_config({**data, "train": {**data["train"], "envs": envs}})
    Trainer(config, tmp_path / "whole", progress=False).run()
    if config.train.overlap:
        last = read_checkpoint(load_model(tmp_path / "whole" / "checkpoint.npz", 2**31)[1], DqnCounters)
        assert last.counters.pending_gradient_steps, "the last step's gradient steps wait for a next step"
    trainer = Trainer(config, tmp_path / "cut", progress=False)
    worlds = batched_worlds(trainer.env)
    assert isinstance(worlds, TrainingWorlds if envs == 1 else WorldShards) and worlds.num_envs == 4
    real_step, calls = worlds.step_wait, []

    def step_then_signal():
        calls.append(1)
        if len(calls) == 3:
            trainer._request_stop(15, None)
        return real_step()

    worlds.step_wait = step_then_signal  # type: ignore[method-assign]
    assert trainer.run().interrupted
    stopped = read_checkpoint(load_model(tmp_path / "cut" / "checkpoint.npz", 2**31)[1], DqnCounters)
    assert 0 < stopped.counters.num_timesteps < 40
    assert stopped.counters.episodes is not None and len(stopped.counters.episodes) == 4
    assert any(episode.actions for episode in stopped.counters.episodes), "stopped mid-episode"
    resumed = Trainer.resume(tmp_path / "cut", steps=None, progress=False).run()
    assert resumed.steps == 40 and not resumed.interrupted
    for name in ("checkpoint.npz", "final.npz"):
        whole_arrays, whole = load_model(tmp_path / "whole" / name, 2**31)
        cut_arrays, cut = load_model(tmp_path / "cut" / name, 2**31)
        if name == "checkpoint.npz":
            assert read_checkpoint(cut, DqnCounters).counters == read_checkpoint(whole, DqnCounters).counters
        assert cut_arrays.keys() == whole_arrays.keys()
        for key, value in whole_arrays.items():
            np.testing.assert_array_equal(cut_arrays[key], value, err_msg=f"{name}: {key}")
    assert (tmp_path / "cut" / "final.npz").read_bytes() == (tmp_path / "whole" / "final.npz").read_bytes()


def test_learning_while_the_worlds_step_is_one_run_on_any_split_and_another_run_than_in_turns(tmp_path):
    """`train.overlap`: the gradient steps due after a step run while the shards take the next
    one, on the transitions up to the step before. The same model file in one process and over
    two (the order is the algorithm's, not the processes'); not the model of SB3's order, which
    learns from the newest step first."""
    files = {}
    for name, overlap, envs in [("one", True, 1), ("two", True, 2), ("in-turns", False, 2)]:
        train = {**OVERLAPPED["train"], "overlap": overlap, "envs": envs}
        config = build_config({**OVERLAPPED, "train": train})
        summary = Trainer(config, tmp_path / name, progress=False).run()
        assert summary.steps == 40
        files[name] = (tmp_path / name / "final.npz").read_bytes()
    assert files["one"] == files["two"]
    assert files["one"] != files["in-turns"]


def test_overlap_is_refused_for_dqn_in_one_line(tmp_path):
    data = {**WORLDS, "train": {**WORLDS["train"], "algorithm": "dqn", "overlap": True}}
    args = ["train", "-c", str(written(tmp_path, data)), "--out", str(tmp_path / "o"), "--no-progress"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "overlap: only the ddqn algorithm" in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_folder_written_before_overlap_existed_keeps_its_fingerprint():
    """A run folder records its config's fingerprint; one written before `train.overlap` existed
    has none of it, and still resumes: the key is left out while it holds that run's value."""
    config = build_config(WORLDS)
    former = _fingerprint_without(config, *FORMER)
    assert training_owner(config).config == former
    overlapped = build_config({**WORLDS, "train": {**WORLDS["train"], "overlap": True}})
    assert training_owner(overlapped).config != training_owner(config).config


def test_a_resolved_config_written_before_the_abort_looked_ahead_reproduces_its_run():
    """A folder's config.yaml written before `planner.safety.abort_lookahead_s` existed lists every
    other safety key: it reads the key as 0 (how its run aborted) and keeps its fingerprint; a
    config that names only some safety keys gets the default."""
    then = build_config(WORLDS, planner__safety__abort_lookahead_s=0.0)
    written = then.model_dump(mode="json")
    written["planner"]["safety"].pop("abort_lookahead_s")
    read = build_config(written)
    assert read == then and read.planner.safety.abort_lookahead_s == 0.0
    assert training_owner(read).config == _fingerprint_without(
        then, *FORMER, "planner.safety.abort_lookahead_s"
    )
    partial = build_config({**WORLDS, "planner": {"safety": {"abort_gap_m": 2.0}}})
    assert (
        partial.planner.safety.abort_lookahead_s
        == build_config(WORLDS).planner.safety.abort_lookahead_s
        == 1.0
    )
    assert training_owner(partial).config != training_owner(read).config


def test_a_resolved_config_written_before_the_change_margin_reproduces_its_run():
    """A folder's config.yaml written before `planner.change_margin` (and the abort's lookahead)
    existed reads both as its run had them (no margin) and keeps its fingerprint; a margin, or the
    default that reads the model file's, changes it."""
    then = build_config(WORLDS, planner__safety__abort_lookahead_s=0.0, planner__change_margin=0.0)
    written = then.model_dump(mode="json")
    written["planner"].pop("change_margin"), written["planner"]["safety"].pop("abort_lookahead_s")
    read = build_config(written)
    assert read == then and read.planner.change_margin == 0.0
    assert training_owner(read).config == _fingerprint_without(
        then, *FORMER, "planner.change_margin", "planner.safety.abort_lookahead_s"
    )
    assert build_config(WORLDS).planner.change_margin is None
    held = build_config(WORLDS, planner__change_margin=0.4)
    assert training_owner(held).config != training_owner(build_config(WORLDS)).config


def test_a_resolved_config_written_before_the_far_lane_check_reproduces_its_run():
    """A folder's config.yaml written before `planner.safety.far_lane_gap_m` and `train.members`
    existed reads the check as off (how its run changed lanes) and one member, and keeps its
    fingerprint; the check's default (2 m) changes it."""
    then = build_config({**WORLDS, "planner": {"safety": {"far_lane_gap_m": None}}})
    written = then.model_dump(mode="json")
    written["planner"]["safety"].pop("far_lane_gap_m"), written["train"].pop("members")
    read = build_config(written)
    assert read == then and read.planner.safety.far_lane_gap_m is None and read.train.members == 1
    assert training_owner(read).config == _fingerprint_without(then, *FORMER, "planner.safety.far_lane_gap_m")
    assert build_config(WORLDS).planner.safety.far_lane_gap_m == 2.0
    assert training_owner(build_config(WORLDS)).config != training_owner(read).config


def test_a_resolved_config_written_before_the_follower_check_reproduces_its_run():
    """A folder's config.yaml written before `planner.safety.far_lane_leader` and the follower's
    braking check existed reads both as off (how its run changed lanes) and keeps its fingerprint."""
    off = {"far_lane_leader": False, "follower_braking_mps2": None}
    then = build_config({**WORLDS, "planner": {"safety": off}})
    written = then.model_dump(mode="json")
    for key in (*off, "follower_reaction_s"):
        written["planner"]["safety"].pop(key)
    read = build_config(written)
    assert read == then and read.planner.safety.follower_braking_mps2 is None
    dotted = [f"planner.safety.{key}" for key in off]
    assert training_owner(read).config == _fingerprint_without(then, *FORMER, *dotted)
    assert build_config(WORLDS).planner.safety.follower_braking_mps2 == 3.0
    assert training_owner(build_config(WORLDS)).config != training_owner(read).config


FORMER = ("train.overlap", "train.members", "planner.safety.follower_reaction_s")
"""The keys added later that `WORLDS` holds at their former values."""


def _fingerprint_without(config, *dotted_keys: str) -> str:
    """The fingerprint of `config` as a folder written before `dotted_keys` existed recorded it."""
    former = config.model_dump(mode="json", exclude=HOW_NOT_WHAT)
    former["train"].pop("steps")
    for dotted in dotted_keys:
        *sections, key = dotted.split(".")
        node = former
        for section in sections:
            node = node[section]
        node.pop(key)
    return fingerprint(json.dumps(former, sort_keys=True))
