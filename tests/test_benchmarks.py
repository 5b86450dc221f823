"""`make bench` keeps working: every benchmark script runs to the end on tiny budgets (slow: about
two minutes; `pytest -m slow tests/test_benchmarks.py`)."""

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"


def run(script: str, *arguments: str, cwd: Path = ROOT) -> str:
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *arguments],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


@pytest.mark.slow
def test_every_benchmark_script_runs_on_a_tiny_budget(tmp_path):
    tiny = tmp_path / "tiny.yaml"
    data = yaml.safe_load((ROOT / "configs" / "highway.yaml").read_text())
    data["highway"].update(vehicles_count=10, duration=2)
    tiny.write_text(yaml.safe_dump(data))
    assert "frames/s" in run("sim_speed.py", "--runs", "1", "--frames", "5")
    assert "--help" in run("cli_startup.py", "--runs", "1")
    assert "\n0 of the cases miss a target" in run("hostile_inputs.py")
    assert run("grid_speed.py", "--repeats", "3")
    assert "ticks/s" in run("loop_rate.py", "--episodes", "1", "--config", str(tiny))
    assert "ms per frame" in run("loop_rate.py", "--cpu", "--episodes", "1", "--duration", "1")
    assert "| road act" in run("loop_profile.py", "--episodes", "1", "--duration", "1").replace("&nbsp;", "")
    assert "cheaper" in run("oracle_cost.py", "--seeds", "0", "--duration", "2")
    assert "s CPU per oracle episode" in run(
        "oracle_cost.py", "--seeds", "0", "--duration", "2", "--backends", "vector"
    )
    assert "p95" in run("lookahead_cost.py", "--episodes", "1", "--duration", "2", "--scenarios", "jam")
    assert "| control ticks" in run("oracle_cost.py", "--profile", "--seeds", "0", "--duration", "2")
    assert "| True |" in run("batch_of_one.py", "--episodes", "1", "--repeats", "1", "--duration", "2")
    assert "| batch of one step |" in run(
        "batch_of_one.py", "--traffic-only", "--repeats", "1", "--frames", "5"
    )
    assert "| all |" in run("record_cost.py", "--seeds", "0", "--duration", "2", "--repeats", "1")
    rates = run("train_rate.py", "--steps", "510", "--world-steps", "640")
    assert "| 64 batched worlds |" in rates and "| 64 batched worlds in 2 processes | 0.0625 |" in rates
    parts = run("train_profile.py", *("--steps", "640", "--demonstrations", "2", "--pretrain", "5"))
    assert "| validation episodes |" in parts and "| **total** |" in parts
    assert "bit for bit: True" in run("batched_validation.py", "--episodes", "2")
    assert "| batch 4 |" in run("batched_decisions.py", "--runs", "1", "--duration", "2", "--sizes", "1,4")
    assert "(beyond the readers of the scenarios and the YAML: 0)\n" in run("config_path.py")
    timed = run(
        "benchmark_time.py", *("--agents", "keep-lane", "--episodes", "1", "--duration", "2", "--jobs", "1")
    )
    assert "| keep-lane |" in timed and "extrapolated" in timed
    training = yaml.safe_load((ROOT / "configs" / "train" / "ddqn-stage1.yaml").read_text())
    training |= {"scenario": None, "highway": {"vehicles_count": 10, "duration": 3}}
    training["train"] |= {"envs": 1, "learning_starts": 10, "scenarios": {}, "checkpoint_every": 20}
    training["train"].pop("init_model", None)
    training["train"]["validation"] |= {"short_every": 20, "short_episodes": 1, "long_episodes": 1}
    (tmp_path / "train.yaml").write_text(yaml.safe_dump(training))
    ablation = run(
        "state_ablation.py",
        *("--steps", "40", "--episodes", "1", "--variants", "paper,grid"),
        *("--config", str(tmp_path / "train.yaml"), "--out", str(tmp_path / "ablation")),
    )
    assert "| grid | [] | 1 |" in ablation and "| paper | [] | road |" in ablation
    assert (tmp_path / "ablation" / "ablation.md").read_text().strip() in ablation
    assert "env steps/s" in run("deepcars_speed.py")
    ceiling = run("deepcars_ceiling.py", "--rows", "1,2", "--check-steps", "2000")
    assert "| 2 | 96.000 % | 97.858 % |" in ceiling and "simulated lookahead rule" in ceiling
    assert "| kinematic |" in run("mpc_solve.py", "--repeats", "1")
    ceiling = run(
        "decision_ceiling.py", "--episodes", "1", "--horizon", "2", "--jobs", "1", "--config", str(tiny)
    )
    assert "mean speed" in ceiling
    scaling = run(
        "ray_scaling.py",
        "--agents",
        "rule",
        "--episodes",
        "2",
        "--repeats",
        "1",
        "--set",
        "highway.duration=2",
    )
    assert scaling.count("| yes |") == 3
    track = tmp_path / "track"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "stack",
            "track",
            "--controller",
            "pid",
            "--speeds",
            "20",
            "--out",
            str(track),
            "--no-progress",
        ],
        check=True,
        capture_output=True,
    )
    assert "| straight |" in run("tracking_table.py", str(track))
