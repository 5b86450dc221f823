"""Every hostile input of the hardening issue, run as a user would (a fresh `drivestack` process):
exit code, lines printed, wall time and the process's peak RSS, against the targets (exit 2, one
line <= 300 characters, <= 5 s, <= 400 MB).

    .venv/bin/python benchmarks/hostile_inputs.py

Prints a markdown table and exits 1 if any case misses a target.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from perception.grid import OccupancyGridBuilder  # noqa: E402
from planner.factory import SHIPPED_MODELS  # noqa: E402
from planner.model_file import FORMAT, load_model, save_model  # noqa: E402
from records import GridConfig  # noqa: E402
from stack.apps.options import TRAIN_CONFIG  # noqa: E402
from stack.runtime.owner import MARKER  # noqa: E402
from tests.test_hostile_inputs import BOMB, owned_training_folder  # noqa: E402
from tests.test_hostile_inputs_more import digits_model, oversized_buffer_checkpoint  # noqa: E402
from tests.test_model_files import metadata_bytes, npy, plain_mlp, with_metadata, write  # noqa: E402

LIMIT_S, LIMIT_MB, LIMIT_CHARS = 5.0, 400.0, 300
BUILT_MODEL_CASE = "train --resume a checkpoint whose buffer declares 1.2 M rows of a 1000-row run"
CASE_LIMITS: dict[str, tuple[float, float]] = {BUILT_MODEL_CASE: (60.0, 600.0)}
"""(wall s, peak RSS MB) of the cases refused only once the run's model is built (the model says
what its checkpoint holds): importing torch and building the env and model take about 500 MB and
several seconds; the 248 MB the file inflates to must not be added (before the check: 755 MB)."""


def text(content: str) -> Callable[[Path], None]:
    return lambda path: path.write_text(content)


def nan_weights(path: Path) -> None:
    arrays, metadata = plain_mlp()
    arrays["0.weight"] = arrays["0.weight"].copy()
    arrays["0.weight"][0, 0] = np.nan
    save_model(path, arrays, metadata)


def four_lane_paper_model(path: Path) -> None:
    """A model on the paper's state (every road lane, binary lane code), trained for 4 lanes: its
    observation size depends on the lane count, so a 2-lane road must be refused."""
    arrays, metadata = plain_mlp()
    grid = {**metadata["grid"], "lanes": "absolute", "lane_code": "binary", "features": []}
    size = int(OccupancyGridBuilder(GridConfig(**grid)).space("observation", 4).shape[0])
    arrays["0.weight"] = np.zeros((arrays["0.weight"].shape[0], size), dtype=arrays["0.weight"].dtype)
    save_model(path, arrays, {**metadata, "grid": grid, "observation_size": size})


def header_liar(path: Path) -> None:
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
    write(
        path,
        {"metadata.npy": metadata_bytes({"format": FORMAT}), "array/q.npy": header.getvalue() + b"\0" * 64},
    )


def corrupt_deflate(path: Path) -> None:
    write(path, {"metadata.npy": metadata_bytes({"format": FORMAT}) * 50})
    raw = bytearray(path.read_bytes())
    raw[60:90] = b"\x00" * 30
    path.write_bytes(bytes(raw))


def encrypted(path: Path) -> None:
    with_metadata(path)
    raw = bytearray(path.read_bytes())
    raw[raw.find(b"PK\x03\x04") + 6] |= 0x1
    raw[raw.find(b"PK\x01\x02") + 8] |= 0x1
    path.write_bytes(bytes(raw))


def checkpoint_folder(
    content: bytes, owned: bool = True, config: dict | None = None
) -> Callable[[Path], None]:
    """A training folder of `config` holding `content` as its checkpoint, with its owner record
    or (not `owned`) as made before folders kept one."""

    def build(folder: Path) -> None:
        owned_training_folder(folder, config or {"train": {"steps": 10}})
        (folder / "checkpoint.npz").write_bytes(content)
        if not owned:
            (folder / MARKER).unlink()

    return build


MODEL_FILES: dict[str, Callable[[Path], None]] = {
    "npz member inflating to 96 MB": lambda p: write(
        p, {"metadata.npy": metadata_bytes({"format": FORMAT}), "array/q.npy": npy(np.zeros(12_000_000))}
    ),
    "metadata hidden: [4000000]": lambda p: with_metadata(p, hidden=[4_000_000]),
    "header claiming 8 TB": header_liar,
    "grid with 10^8 cells": lambda p: with_metadata(p, grid={"cells_ahead": 10**8}),
    "metadata a list": lambda p: write(p, {"metadata.npy": metadata_bytes([1, 2])}),
    "metadata null": lambda p: write(p, {"metadata.npy": metadata_bytes(None)}),
    "metadata nested 100k deep": lambda p: write(
        p, {"metadata.npy": npy(np.frombuffer(b"[" * 100_000 + b"]" * 100_000, dtype=np.uint8))}
    ),
    "bare .npy": lambda p: p.write_bytes(npy(np.zeros(3))),
    "zip without members": lambda p: write(p, {"other.txt": b"x"}),
    "corrupt deflate": corrupt_deflate,
    "unknown compression": lambda p: write(p, {"metadata.npy": b"x"}, zipfile.ZIP_BZIP2),
    "encrypted member": encrypted,
    "another observation size": lambda p: with_metadata(p, observation_size=50),
    "unknown encoding": lambda p: with_metadata(p, encoding="telepathy"),
    "5 actions": lambda p: with_metadata(p, actions=5),
    "NaN weights": nan_weights,
    "pickled member": lambda p: write(
        p, {"metadata.npy": metadata_bytes({"format": FORMAT}), "array/q.npy": npy_pickled()}
    ),
}

CONFIGS: dict[str, str] = {
    "billion laughs as seed": BOMB + "seed: *i\n",
    "billion laughs as features": BOMB + "perception: {features: *i}\n",
    "decision_period_s: .inf": "decision_period_s: .inf\n",
    "cells_ahead: 10^8": "perception: {cells_ahead: 100000000}\n",
    "false_positives: 1e12": "perception: {sensor: {false_positives: 1.0e+12}}\n",
    "position noise .inf": "perception: {sensor: {position_noise: .inf}}\n",
    "duration .inf, no traffic": "highway: {duration: .inf, vehicles_count: 0}\n",
    "seed 2^70": "seed: 1180591620717411303424\n",
}


def npy_pickled() -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    return buffer.getvalue()


def cases(folder: Path) -> dict[str, list[str]]:
    """Case name -> the CLI arguments (files built in `folder`)."""
    found: dict[str, list[str]] = {}
    for index, (name, build) in enumerate(MODEL_FILES.items()):
        build(path := folder / f"model{index}.npz")
        found[f"model: {name}"] = ["run", "--agent", "ddqn", "--model", str(path), "--episodes", "1"]
    for index, (name, content) in enumerate(CONFIGS.items()):
        (path := folder / f"config{index}.yaml").write_text(content)
        found[f"config: {name}"] = ["run", "-c", str(path), "--out", str(folder / f"out{index}")]
    (latin := folder / "latin.yaml").write_bytes(b"seed: 1 # caf\xe9\n")
    found["config: not UTF-8"] = ["run", "-c", str(latin)]
    (buffer := folder / "buffer.yaml").write_text("train: {buffer_size: 100000000}\n")
    found["train.buffer_size: 10^8"] = ["train", "-c", str(buffer), "--out", str(folder / "t")]
    (demonstrations := folder / "demonstrations.yaml").write_text(
        "highway: {duration: 3600}\ntrain: {demonstrations: {episodes: 100000}}\n"
    )
    found["train.demonstrations: 10^5 one-hour episodes"] = [
        "train",
        "-c",
        str(demonstrations),
        "--out",
        str(folder / "t4"),
    ]
    found["train --seed 2^70"] = ["train", "--seed", str(2**70), "--out", str(folder / "t2")]
    found["train --envs 0"] = ["train", "--envs", "0", "--out", str(folder / "t3")]
    (existing := folder / "results.txt").write_text("keep")
    found["run --out an existing file"] = ["run", "--out", str(existing)]
    found["train --out an existing file"] = ["train", "--out", str(existing)]
    for name, content in (
        ("a truncated checkpoint", SHIPPED_MODELS["ddqn"].read_bytes()[:5000]),
        ("a model file as checkpoint", SHIPPED_MODELS["ddqn"].read_bytes()),
    ):
        checkpoint_folder(content)(run := folder / name.replace(" ", "-"))
        found[f"train --resume from {name}"] = ["train", "--resume", str(run), "--no-progress"]
    checkpoint_folder(b"", owned=False)(old := folder / "no-owner-record")
    found["train --resume a folder without owner record"] = ["train", "--resume", str(old)]
    found["train --resume --adopt a folder whose checkpoint is empty"] = [
        "train",
        "--resume",
        str(old),
        "--adopt",
    ]
    found["unknown scenario"] = ["run", "--scenario", "moon"]
    four_lane_paper_model(paper := folder / "paper-4-lanes.npz")
    found["a 4-lane paper-state model on a 2-lane road"] = [
        "run",
        "--agent",
        "ddqn",
        "--model",
        str(paper),
        "--set",
        "highway.lanes_count=2",
    ]
    found.update(folder_cases(folder))
    found.update(round_three_cases(folder))
    found.update(coercion_and_resource_cases(folder))
    return found


def coercion_and_resource_cases(folder: Path) -> dict[str, list[str]]:
    """Issue 73: duplicate keys, anchors and deep nesting; crafted model metadata and checkpoints;
    links and missing folders in results folders; what `view` is given; options named as typed."""
    deep = "[" * 500 + "]" * 500
    (deep_config := folder / "deep.yaml").write_text(f"seed: {deep}\n")
    (twice := folder / "twice.yaml").write_text("seed: 1\nseed: 2\n")
    (null_sweep := folder / "null-sweep.yaml").write_text(
        f"config: {TRAIN_CONFIG}\nfixed: {{train.scenarios: null}}\nspace: {{seed: [1, 2]}}\n"
    )
    ensemble = ["ensemble", "--out", str(folder / "ensemble.npz"), str(SHIPPED_MODELS["ddqn"])]
    for name, changes in (("negative-steps", {"trained_steps": -5}), ("string-seed", {"seed": "7"})):
        arrays, metadata = load_model(SHIPPED_MODELS["ddqn"])
        save_model(folder / f"{name}.npz", arrays, {**metadata, **changes})
    digits_model(digits := folder / "digits.npz")
    checkpoint_folder(inflating_checkpoint(), config={"train": {"steps": 10, "buffer_size": 1000}})(
        inflating := folder / "inflating"
    )
    small_run = {"train": {"steps": 10, "buffer_size": 1000}, "highway": {"duration": 2}}
    checkpoint_folder(oversized_buffer_checkpoint((1_203_302, 1, 54), ("observations",)), config=small_run)(
        oversized := folder / "oversized-buffer"
    )
    (linked := folder / "linked-recordings").mkdir()
    (linked / "recordings").symlink_to(folder)
    owned_training_folder(deep_link := folder / "deep-link", {"train": {"steps": 10}})
    (deep_link / "seed-1").mkdir()
    (deep_link / "seed-1" / "tensorboard").symlink_to(folder)
    os.mkfifo(fifo := folder / "fifo.rrd")
    (zero := folder / "zero.rrd").symlink_to("/dev/zero")
    (not_rrd := folder / "zip.rrd").write_bytes(b"PK\x03\x04 not a recording")
    (many := folder / "many" / "recordings").mkdir(parents=True)
    for index in range(1001):
        (many / f"episode-{index:04d}.rrd").write_bytes(b"RRF2")
    (dangling := folder / "dangling").symlink_to(folder / "missing")
    return {
        "--set a mapping with a duplicate key": ["run", "--set", "highway={duration: 3, duration: 5}"],
        "--set an anchor": ["run", "--set", "highway.duration=&a 4"],
        "--set nested 500 deep": ["run", "--set", f"seed={deep}"],
        "a config nested 500 deep": ["run", "-c", str(deep_config)],
        "a sweep file nested 500 deep": ["sweep", "-c", str(deep_config)],
        "a config with a duplicate key": ["run", "-c", str(twice)],
        "a sweep's fixed null where null is not allowed": ["sweep", "-c", str(null_sweep)],
        "--point naming a parameter twice": [
            "safety",
            "--scenario",
            "lead-braking",
            "--point",
            "speed=20,speed=30,time_gap=1,deceleration=4",
        ],
        "ensemble: a member's trained_steps -5": [*ensemble, str(folder / "negative-steps.npz")],
        "ensemble: a member's seed a string": [*ensemble, str(folder / "string-seed.npz")],
        "model metadata with a 4,400-digit integer": ["run", "--agent", "ddqn", "--model", str(digits)],
        "train.init_model with a 4,400-digit integer": ["train", "--set", f"train.init_model={digits}"],
        "train --envs 64": ["train", "--envs", "64", "--out", str(folder / "t64")],
        "train --worlds 5000": ["train", "--worlds", "5000"],
        "train --resume a 320-MB checkpoint of a 1000-transition run": ["train", "--resume", str(inflating)],
        BUILT_MODEL_CASE: ["train", "--resume", str(oversized), "--no-progress"],
        "run --resume with recordings/ a link": ["run", "--out", str(linked), "--resume"],
        "train --resume with seed-1/tensorboard a link": ["train", "--resume", str(deep_link)],
        "view a pipe": ["view", str(fifo)],
        "view a link to the zero device": ["view", str(zero)],
        "view a file that is not a recording": ["view", "--web", str(not_rrd)],
        "view 1,001 recordings": ["view", str(many.parent)],
        "export --sb3 ''": ["export", str(SHIPPED_MODELS["dqn"]), "--sb3", ""],
        "--out a dangling link": ["run", "--out", str(dangling)],
    }


def inflating_checkpoint() -> bytes:
    """A checkpoint whose one array inflates to 320 MB from 0.3 MB."""
    buffer = io.BytesIO()
    counters = {"format": FORMAT, "kind": "checkpoint", "counters": {"num_timesteps": 5}}
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("metadata.npy", metadata_bytes(counters))
        archive.writestr("array/buffer/x.npy", npy(np.zeros(40 * 2**20)))
    return buffer.getvalue()


def round_three_cases(folder: Path) -> dict[str, list[str]]:
    """Issue 52: links in a results folder, over-long integers, empty lists and values, keys a
    --set created, a plug-in that exits at import."""
    (linked := folder / "linked").mkdir()
    (precious := folder / "precious.txt").write_text("keep")
    (linked / ".drivestack.lock").symlink_to(precious)
    (digits := folder / "digits.yaml").write_text("seed: " + "9" * 4400 + "\n")
    (quits := folder / "quits.py").write_text("import sys\nsys.exit(0)\n")
    return {
        "a link as the folder's lock file": ["run", "--out", str(linked)],
        "a config integer of 4,400 digits": ["run", "-c", str(digits)],
        "compare --agents ''": ["compare", "--agents", ""],
        "compare --agents ',,'": ["compare", "--agents", ",,"],
        "track --controller ''": ["track", "--controller", ""],
        "--set highway.duration=": ["run", "--set", "highway.duration="],
        "--set highway.duration=null": ["run", "--set", "highway.duration=null"],
        "--set perception.features=[ttc,ttc,ttc]": ["run", "--set", "perception.features=[ttc,ttc,ttc]"],
        "--set a 60-level key": ["run", "--set", ".".join(["a"] * 60) + "=1"],
        "a plug-in that exits at import": ["run", "--agent", f"{quits}:Agent"],
    }


def folder_cases(folder: Path) -> dict[str, list[str]]:
    """Issue 36: results folders of other commands, other configs, mistyped and unbounded values,
    options without effect, a Ray address where something else listens."""
    (run := folder / "a-run").mkdir()
    (run / ".drivestack-owner.json").write_text('{"command": "run", "config": "0"}')
    (run / "config.yaml").write_text("seed: 0\n")
    (run / "summary.json").write_text("{}\n")
    (mine := folder / "my-files").mkdir()
    (mine / "notes.txt").write_text("keep")
    return {
        "train --resume a run's folder": ["train", "--resume", str(run)],
        "compare --out a run's folder": ["compare", "--out", str(run)],
        "run --out a folder of the user's files": ["run", "--out", str(mine)],
        "run --resume a run with other arguments": ["run", "--seed", "3", "--out", str(run), "--resume"],
        "--set highway.ego_spacing=1e308": ["run", "--set", "highway.ego_spacing=1e308"],
        "--set highway.lanes_count=true": ["run", "--set", "highway.lanes_count=true"],
        "--agent rule --model x.npz": ["run", "--agent", "rule", "--model", "x.npz"],
        "run --out a 300-character name": ["run", "--out", str(folder / ("x" * 300))],
        "export --sb3 a 300-character name": ["export", str(SHIPPED_MODELS["ddqn"]), "--sb3", "x" * 300],
        "--ray at a port nobody answers on": ["run", "--ray", "127.0.0.1:1"],
    }


API_CASES: dict[str, tuple[str, str]] = {
    "DecisionVecEnv(cfg, 10**6)": ("None", "DecisionVecEnv({}, 10**6)"),
    "DecisionVecEnv(cfg, 1.5)": ("None", "DecisionVecEnv({}, 1.5)"),
    "make_vec(num_envs=10**6)": ("None", "vector(10**6)"),
    "make_vec float actions [1.7, 0.2, 1.0, 2.9]": ("vector(4)", "env.step([1.7, 0.2, 1.0, 2.9])"),
    "make_vec boolean actions": ("vector(4)", "env.step([True, False, True, True])"),
    "make_vec a scalar action for 4 worlds": ("vector(4)", "env.step(1)"),
    "make_vec an action of -2^63": ("vector(4)", "env.step([-(2**63)] * 4)"),
    "make_vec reset(seed=1.5)": ("vector(2)", "env.reset(seed=1.5)"),
}
"""Issue 73: the Python API as strict as the CLI. Each case: (what is built first, the call that
must be refused); the refusal is a one-line ValueError, shown as exit 2. Importing the stack and
building the env take seconds and hundreds of MB, so the targets are the call's own: wall time
and the memory it allocates (tracemalloc), `API_LIMIT_S` and `API_LIMIT_MB`."""

API_LIMIT_S, API_LIMIT_MB = 1.0, 50.0

API_PROGRAM = """
import sys, time, tracemalloc
import gymnasium as gym
import stack
from stack.training.gym_vector_env import DecisionVecEnv
def vector(worlds):
    made = gym.make_vec("drivestack/HierarchicalHighway-v0", num_envs=worlds,
        vectorization_mode="vector_entry_point", config={"highway": {"duration": 2, "vehicles_count": 5}})
    made.reset(seed=1)
    return made
env = SETUP
tracemalloc.start()
start = time.perf_counter()
try:
    CALL
    code = 0
except ValueError as error:
    print(f"error: {error}")
    code = 2
with open(sys.argv[1], "w") as report:
    report.write(f"{time.perf_counter() - start} {tracemalloc.get_traced_memory()[1] / 2**20}")
sys.exit(code)
"""


def measure_call(setup: str, call: str, scratch: Path) -> tuple[int, str, float, float]:
    """(exit code, output, the call's wall s, MB it allocated) of one API case in a fresh process."""
    report = scratch / "call.txt"
    program = API_PROGRAM.replace("SETUP", setup).replace("CALL", call)
    result = subprocess.run(
        [sys.executable, "-c", program, str(report)], capture_output=True, text=True, cwd=ROOT
    )
    wall, megabytes = report.read_text().split() if report.is_file() else ("nan", "nan")
    report.unlink(missing_ok=True)
    return result.returncode, result.stdout + result.stderr, float(wall), float(megabytes)


def measure(arguments: list[str], scratch: Path) -> tuple[int, str, float, float]:
    """(exit code, output, wall s, peak RSS MB) of one fresh CLI process, measured by GNU time.
    No display: `view` must say so."""
    report = scratch / "time.txt"
    result = subprocess.run(
        ["/usr/bin/time", "-o", str(report), "-f", "%e %M", sys.executable, "-m", "stack", *arguments],
        capture_output=True,
        text=True,
        env={key: value for key, value in os.environ.items() if key not in ("DISPLAY", "WAYLAND_DISPLAY")},
        cwd=ROOT,
    )
    wall, kilobytes = report.read_text().split()[-2:]
    return result.returncode, result.stdout + result.stderr, float(wall), float(kilobytes) / 1024


def main() -> None:
    print("| case | exit | lines | longest line | wall s | peak RSS MB | ok |\n|---|---|---|---|---|---|---|")
    failures = 0
    with tempfile.TemporaryDirectory() as scratch:
        for name, arguments in cases(Path(scratch)).items():
            limits = CASE_LIMITS.get(name, (LIMIT_S, LIMIT_MB))
            failures += not report(name, *measure(arguments, Path(scratch)), *limits)
        print(
            f"\nThe Python API (wall s and MB: the refused call's own; targets {API_LIMIT_S:g} s, "
            f"{API_LIMIT_MB:g} MB)\n\n| case | exit | lines | longest line | wall s | MB allocated | ok |"
            "\n|---|---|---|---|---|---|---|"
        )
        for name, (setup, call) in API_CASES.items():
            measured = measure_call(setup, call, Path(scratch))
            failures += not report(name, *measured, API_LIMIT_S, API_LIMIT_MB)
    print(f"\n{failures} of the cases miss a target")
    sys.exit(1 if failures else 0)


def report(
    name: str, code: int, output: str, wall: float, memory: float, wall_limit: float, memory_limit: float
) -> bool:
    """Print one case's row; whether it is on target (exit 2, one line of at most `LIMIT_CHARS`,
    within `limits`: wall s and MB)."""
    lines = output.strip().splitlines()
    longest = max((len(line) for line in lines), default=0)
    ok = (
        code == 2
        and len(lines) == 1
        and longest <= LIMIT_CHARS
        and wall <= wall_limit
        and memory <= memory_limit
    )
    verdict = "yes" if ok else "NO: " + output.strip()[:120]
    print(f"| {name} | {code} | {len(lines)} | {longest} | {wall:.2f} | {memory:.0f} | {verdict} |")
    return ok


if __name__ == "__main__":
    main()
