"""Batched worlds split over processes (`train.worlds` with `train.envs` > 1): world k of the shards
is world k of the one-process env, step for step across episode ends, in its episode records and
replays, and in a whole training run; the split is refused in one line when it is not even; the
shard processes end with the env."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from stack.settings.run import build_config
from stack.training.batch_env import TrainingWorlds, batched_worlds
from stack.training.envs import EnvWorkerDied
from stack.training.trainer import Trainer
from stack.training.world_shards import WorldShards
from tests.test_train_signals import started_training, stopped_with_its_checkpoint
from tests.test_train_worlds import MIX, WORLDS

SHORT = {"highway": {"duration": 6}}
"""Episodes of 6 s: several end, and are reset, within a few decisions."""


def assert_same_step(found: tuple, expected: tuple) -> int:
    """Assert two SB3 step results equal, bit for bit; the episodes they end."""
    for mine, theirs in zip(found[:3], expected[:3], strict=True):
        assert mine.dtype == theirs.dtype
        np.testing.assert_array_equal(mine, theirs)
    for info, other in zip(found[3], expected[3], strict=True):
        assert info.keys() == other.keys()
        for key, value in info.items():
            assert np.array_equal(value, other[key]), key
    return int(found[2].sum())


def test_the_shards_step_the_worlds_of_the_one_process_env_bit_for_bit():
    config = build_config(SHORT, "test")
    one, sharded = TrainingWorlds(config, 4), WorldShards(config, 4, 2)
    try:
        assert sharded.observation_space == one.observation_space
        for env in (one, sharded):
            env.seed(7)
        np.testing.assert_array_equal(sharded.reset(), one.reset())
        rng, ends = np.random.default_rng(3), 0
        for _ in range(30):
            actions = rng.integers(0, 3, 4)
            one.step_async(actions)
            sharded.step_async(actions)
            ends += assert_same_step(sharded.step_wait(), one.step_wait())
        assert ends >= 4, "episodes ended and were reset"
        records = sharded.episode_records()
        assert records == one.episode_records()
        assert any(record.actions for record in records)
        np.testing.assert_array_equal(sharded.replay(records), one.replay(records))
        actions = rng.integers(0, 3, 4)
        one.step_async(actions)
        sharded.step_async(actions)
        assert_same_step(sharded.step_wait(), one.step_wait())
    finally:
        one.close()
        sharded.close()
    assert not any(process.is_alive() for process in sharded.processes)


@pytest.mark.parametrize(
    "data", [WORLDS, pytest.param(MIX, marks=pytest.mark.slow)], ids=["one-world", "mix"]
)
def test_a_run_on_shards_writes_the_model_of_the_run_in_one_process(tmp_path, data):
    one = build_config(data)
    sharded = build_config({**data, "train": {**data["train"], "envs": 2}})
    Trainer(one, tmp_path / "one", progress=False).run()
    trainer = Trainer(sharded, tmp_path / "sharded", progress=False)
    assert isinstance(batched_worlds(trainer.env), WorldShards)
    assert trainer.run().steps == 40
    for name in ("final.npz", "best.npz"):
        assert (tmp_path / "sharded" / name).read_bytes() == (tmp_path / "one" / name).read_bytes(), name
    assert trainer.env.unwrapped.closed
    assert not any(process.is_alive() for process in trainer.env.unwrapped.processes)


@pytest.mark.parametrize(("worlds", "envs"), [(4, 3), (2, 4)])
def test_an_uneven_split_is_refused_in_one_line(worlds, envs):
    with pytest.raises(ValueError) as refused:
        build_config({**WORLDS, "train": {**WORLDS["train"], "worlds": worlds, "envs": envs}})
    message = str(refused.value)
    assert f"train.worlds {worlds} does not split evenly over train.envs {envs} processes" in message
    assert "\n" not in message


def test_the_shards_end_when_a_run_fails(tmp_path):
    """An exception in the learner (here its first step) still closes the shard processes."""
    config = build_config({**WORLDS, "train": {**WORLDS["train"], "envs": 2}})
    trainer = Trainer(config, tmp_path / "t", progress=False)
    shards = trainer.env.unwrapped
    assert isinstance(shards, WorldShards)

    def fail(*_: object) -> None:
        raise RuntimeError("learner failed")

    shards.step_async = fail  # type: ignore[method-assign]
    with pytest.raises(RuntimeError, match="learner failed"):
        trainer.run()
    assert shards.closed and not any(process.is_alive() for process in shards.processes)


def test_a_dead_shard_ends_training_in_one_line_with_its_checkpoint_kept(tmp_path):
    config = build_config({**WORLDS, "train": {**WORLDS["train"], "envs": 2, "steps": 400}})
    trainer = Trainer(config, tmp_path / "t", progress=False)
    shards = trainer.env.unwrapped
    real_save = trainer._save_checkpoint

    def save_then_kill_a_shard() -> int:
        steps = real_save()
        os.kill(shards.processes[1].pid, signal.SIGKILL)
        return steps

    trainer._save_checkpoint = save_then_kill_a_shard  # type: ignore[method-assign]
    started = time.monotonic()
    with pytest.raises(EnvWorkerDied, match="a training environment process died .*--resume"):
        trainer.run()
    assert time.monotonic() - started < 60, "no hang"
    assert (tmp_path / "t" / "checkpoint.npz").is_file()
    assert shards.closed and not any(process.is_alive() for process in shards.processes)


@pytest.mark.parametrize("signum", [pytest.param(signal.SIGINT, marks=pytest.mark.slow), signal.SIGTERM])
def test_ctrl_c_or_sigterm_checkpoints_and_ends_every_shard(tmp_path, signum):
    """Ctrl-C reaches the whole process group: the shards ignore it, the learner writes its
    checkpoint (which asks the shards for their episodes) and closes them; so does SIGTERM to the
    learner."""
    data = {**WORLDS, "train": {**WORLDS["train"], "envs": 2, "steps": 50_000}}
    process, out = started_training(tmp_path, data, deadline_s=90.0, start_new_session=True)
    if signum == signal.SIGINT:
        os.killpg(process.pid, signum)
    else:
        process.send_signal(signum)
    checkpoint = stopped_with_its_checkpoint(process, out)
    assert len(checkpoint["counters"]["episodes"]) == 4
    deadline = time.monotonic() + 10
    while group_alive(process.pid):
        assert time.monotonic() < deadline, "a shard process outlived the run"
        time.sleep(0.05)


def group_alive(group: int) -> bool:
    """Whether a process of the process group `group` is still running."""
    try:
        os.killpg(group, 0)
    except ProcessLookupError:
        return False
    return True
