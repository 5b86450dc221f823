"""`drivestack train --ray`: the batched worlds' shards as Ray actors on a local 2-CPU instance
write the model their shard processes write (`--envs 2`), bit for bit; a dead actor ends the run
in one line (exit 1) naming the shard, its last checkpoint kept, and `--resume` finishes the model
of the run never cut; bad input is one line (exit 2) before any work."""

import os
import signal
import time

import pytest
from typer.testing import CliRunner

from planner.model_file import load_model
from stack.apps.cli import app
from stack.apps.training import train_and_report
from stack.settings.run import build_config
from stack.training.batch_env import batched_worlds
from stack.training.checkpoint import DqnCounters, read_checkpoint
from stack.training.trainer import Trainer
from tests.test_train_signals import started_training, stopped_with_its_checkpoint
from tests.test_train_worlds import WORLDS
from tests.test_world_shards import group_alive

ray = pytest.importorskip("ray")

SHARDED = {**WORLDS, "train": {**WORLDS["train"], "envs": 2}}
"""4 worlds as 2 shards of 2, 40 steps, a checkpoint every 10."""


@pytest.fixture(scope="module")
def on_processes(tmp_path_factory):
    """The run of `SHARDED` on two shard processes (`--envs 2`): the folder of its files."""
    out = tmp_path_factory.mktemp("processes")
    Trainer(build_config(SHARDED), out, progress=False).run()
    return out


def assert_same_arrays(found, expected, name: str) -> None:
    """Assert the model files `found` and `expected` hold the same arrays, byte for byte."""
    found_arrays, _ = load_model(found / name, 2**31)
    expected_arrays, _ = load_model(expected / name, 2**31)
    assert found_arrays.keys() == expected_arrays.keys()
    for key, value in expected_arrays.items():
        assert found_arrays[key].dtype == value.dtype
        assert found_arrays[key].tobytes() == value.tobytes(), f"{name}: {key}"


def test_shards_as_ray_actors_write_the_model_of_shard_processes(tmp_path, local_ray, on_processes):
    from stack.training.ray_shards import RayWorldShards

    trainer = Trainer(build_config(SHARDED), tmp_path / "ray", progress=False, ray="local")
    shards = batched_worlds(trainer.env)
    assert isinstance(shards, RayWorldShards) and len(shards.actors) == 2
    assert trainer.run().steps == 40
    for name in ("final.npz", "best.npz"):
        assert_same_arrays(tmp_path / "ray", on_processes, name)
        assert (tmp_path / "ray" / name).read_bytes() == (on_processes / name).read_bytes(), name
    assert shards.closed
    assert_ended(shards.actors)


def assert_ended(actors: list) -> None:
    """Assert that every actor of `actors` has ended."""
    for actor in actors:
        with pytest.raises(ray.exceptions.RayActorError):
            ray.get(actor.host.remote(), timeout=30)


@pytest.mark.slow
def test_a_dead_actor_is_one_line_with_the_checkpoint_kept_and_resume_finishes_the_model(
    tmp_path, local_ray, on_processes, capsys, monkeypatch
):
    """Ray kills the second shard's actor after the first checkpoint (step 12 of 40): the run ends
    in one line naming the shard and `--resume`, exit code 1; resumed on new actors from that
    checkpoint, it ends with the very weights and counters of the run never cut."""
    config, out = build_config(SHARDED), tmp_path / "cut"
    real_save, killed, actors = Trainer._save_checkpoint, [], []

    def save_then_kill_an_actor(trainer: Trainer) -> int:
        steps = real_save(trainer)
        if not killed:
            killed.append(steps)
            actors.extend(batched_worlds(trainer.env).actors)  # type: ignore[union-attr]
            ray.kill(actors[1])
        return steps

    monkeypatch.setattr(Trainer, "_save_checkpoint", save_then_kill_an_actor)
    with pytest.raises(SystemExit) as ended:
        train_and_report(config, out, False, "local")
    monkeypatch.undo()
    assert ended.value.code == 1
    message = capsys.readouterr().err.strip()
    assert "\n" not in message
    assert message.startswith("error: world shard 2 of 2 (worlds 2-3, the Ray actor on ")
    assert f"died (ActorDiedError); its last checkpoint ({out / 'checkpoint.npz'}) is kept" in message
    assert message.endswith(f"--resume {out} continues from it")
    stopped = read_checkpoint(load_model(out / "checkpoint.npz", 2**31)[1], DqnCounters)
    assert stopped.counters.num_timesteps == killed[0] < 40
    assert not (out / "final.npz").exists()
    resumed = Trainer.resume(out, steps=None, progress=False, ray="local").run()
    assert resumed.steps == 40 and not resumed.interrupted
    for name in ("final.npz", "checkpoint.npz"):
        assert_same_arrays(out, on_processes, name)
    assert_ended(actors)


@pytest.mark.slow
def test_ctrl_c_checkpoints_with_the_actors_episodes_and_ends_them(tmp_path):
    """Ctrl-C to the command's process group on a local Ray instance: the learner writes its
    checkpoint (which asks the actors for their worlds' episodes under way), exits 130 without a
    traceback, and leaves no process of its group behind."""
    data = {**SHARDED, "train": {**SHARDED["train"], "steps": 50_000}}
    process, out = started_training(tmp_path, data, 180.0, ("--ray",), start_new_session=True)
    os.killpg(process.pid, signal.SIGINT)
    checkpoint = stopped_with_its_checkpoint(process, out)
    assert len(checkpoint["counters"]["episodes"]) == 4
    deadline = time.monotonic() + 30
    while group_alive(process.pid):
        assert time.monotonic() < deadline, "a process outlived the run"
        time.sleep(0.1)


def invoke(*arguments: str):
    return CliRunner().invoke(app, list(arguments))


def test_ray_without_batched_worlds_is_one_line_before_any_work(tmp_path):
    per_world = ["--set", "train.worlds=null", "--set", "train.replay_ratio=1"]
    result = invoke("train", *per_world, "--ray", "local", "--out", str(tmp_path / "t"), "--no-progress")
    assert result.exit_code == 2
    assert "--ray: steps the shards of batched worlds as Ray actors; give --worlds N" in result.output
    assert not (tmp_path / "t").exists()


def test_a_cluster_with_fewer_cpus_than_shards_is_one_line(tmp_path, monkeypatch):
    import stack.apps.training as training

    monkeypatch.setattr(training, "ray_or_fail", lambda address: None)
    monkeypatch.setattr(ray, "cluster_resources", lambda: {"CPU": 1.0})
    out = tmp_path / "t"
    args = ["train", "--worlds", "16", "--envs", "2", "--ray", "10.0.0.5:6379", "--out", str(out)]
    result = invoke(*args, "--no-progress")
    assert result.exit_code == 2
    assert (
        "--ray 10.0.0.5:6379: 2 world shards (train.envs) take one CPU each, but the cluster has 1"
        in result.output
    )
    assert not out.exists()
