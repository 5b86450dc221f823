"""`drivestack train` under signals and dead processes (issue 36, defects 5 and 7): any number of
SIGTERM ends with the summary and a resumable checkpoint (exit 130); a finished run is not
resumed; a dead env worker ends the run in one line with its last checkpoint kept."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from planner.ddqn import DoubleDQN
from planner.model_file import load_checkpoint
from stack.apps.cli import app
from stack.settings.run import build_config
from stack.training import demonstrations as demonstrations_module
from stack.training.envs import EnvWorkerDied
from stack.training.trainer import Trainer
from tests.test_hostile_inputs import one_line_refusal
from tests.test_train import TINY


def started_training(
    tmp_path: Path, data: dict, deadline_s: float = 60.0, options: tuple[str, ...] = (), **popen: Any
) -> tuple[subprocess.Popen, Path]:
    """`drivestack train` of config `data` (with more command-line `options`) in a subprocess
    (`popen`: more of Popen's options), once it has written its first checkpoint: the process and
    its folder."""
    config = tmp_path / "long.yaml"
    config.write_text(yaml.safe_dump(data))
    out = tmp_path / "t"
    command = [sys.executable, "-m", "stack", "train", "-c", str(config), "--out", str(out), "--no-progress"]
    process = subprocess.Popen(
        [*command, *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        **popen,
    )
    deadline = time.monotonic() + deadline_s
    while not (out / "checkpoint.npz").is_file():
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.05)
    return process, out


def stopped_with_its_checkpoint(process: subprocess.Popen, out: Path) -> dict:
    """The stopped run's checkpoint metadata, once asserted that it ended with exit 130, no
    traceback, and a summary of the checkpoint's steps."""
    _, errors = process.communicate(timeout=60)
    assert process.returncode == 130, errors.decode()
    assert "Traceback" not in errors.decode(), errors.decode()
    summary = json.loads((out / "summary.json").read_text())
    _, checkpoint = load_checkpoint(out / "checkpoint.npz", arrays=False)
    assert summary["interrupted"] and summary["steps"] == checkpoint["counters"]["num_timesteps"]
    return checkpoint


def test_repeated_signals_end_training_with_its_files_and_exit_130(tmp_path):
    process, out = started_training(tmp_path, {**TINY, "train": {**TINY["train"], "steps": 5_000}})
    for _ in range(6):
        process.send_signal(signal.SIGTERM)
        time.sleep(0.03)
    stopped_with_its_checkpoint(process, out)


def test_a_finished_training_is_not_resumed_and_more_steps_continue_it(tmp_path):
    out = tmp_path / "t"
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(TINY))
    for options in (["-c", str(tmp_path / "tiny.yaml"), "--out"], ["--steps", "50", "--resume"]):
        done = CliRunner().invoke(app, ["train", *options, str(out), "--no-progress"])
        assert done.exit_code == 0, done.output
        finished = f"finished its {json.loads((out / 'summary.json').read_text())['steps']} steps"
        one_line_refusal(["train", "--resume", str(out), "--no-progress"], f"{finished}; nothing to resume")
    assert json.loads((out / "summary.json").read_text())["steps"] == 50


@pytest.mark.skipif(not hasattr(os, "fork"), reason="env workers are processes")
@pytest.mark.parametrize("worker", [0, 1])
def test_a_dead_env_worker_ends_training_in_one_line_with_its_checkpoint_kept(tmp_path, worker):
    """The second worker too (issue 52, 6): the first one's reply is then read, SB3's `close()`
    waited for it again, forever."""
    config = build_config({**TINY, "train": {**TINY["train"], "envs": 2, "steps": 400}})
    trainer = Trainer(config, tmp_path / "t", progress=False)
    real_save = trainer._save_checkpoint

    def save_then_kill_a_worker() -> int:
        steps = real_save()
        os.kill(trainer.env.processes[worker].pid, signal.SIGKILL)
        return steps

    trainer._save_checkpoint = save_then_kill_a_worker
    started = time.monotonic()
    with pytest.raises(EnvWorkerDied, match="a training environment process died .*--resume"):
        trainer.run()
    assert time.monotonic() - started < 60, "no hang"
    assert (tmp_path / "t" / "checkpoint.npz").is_file()
    assert not any(p.is_alive() for p in trainer.env.processes)


@pytest.mark.parametrize("phase", ["recording", "pre-training"])
def test_a_stop_while_learning_from_demonstrations_ends_there_and_a_resume_starts_again(
    tmp_path, monkeypatch, phase
):
    """SIGTERM while the expert's episodes are recorded (or pre-trained on) ends the run at the next
    episode (gradient step), not minutes later: interrupted at step 0, no checkpoint; `--resume`
    records them again and trains to the end."""
    demonstrations = {"expert": "mobil", "episodes": 3, "pretrain_steps": 20}
    config = build_config({**TINY, "train": {**TINY["train"], "demonstrations": demonstrations}})
    trainer = Trainer(config, tmp_path / "t", progress=False)
    if phase == "recording":
        for recorder in ("expert_episode", "batched_expert_episodes"):  # one world, or a batch
            real = getattr(demonstrations_module, recorder)

            def recorded_then_signal(*args, real=real):
                trainer._request_stop(15, None)
                return real(*args)

            monkeypatch.setattr(demonstrations_module, recorder, recorded_then_signal)
    else:
        real_pretrain = DoubleDQN.pretrain

        def pretrain_after_a_signal(self, steps, batch_size, stepped):
            trainer._request_stop(15, None)
            return real_pretrain(self, steps, batch_size, stepped)

        monkeypatch.setattr(DoubleDQN, "pretrain", pretrain_after_a_signal)
    summary = trainer.run()
    assert summary.interrupted and summary.steps == 0
    assert not (tmp_path / "t" / "checkpoint.npz").exists()
    monkeypatch.undo()
    resumed = Trainer.resume(tmp_path / "t", steps=None, progress=False).run()
    assert not resumed.interrupted and resumed.steps == 40
