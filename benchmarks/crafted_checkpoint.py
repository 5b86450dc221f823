"""A training folder whose `checkpoint.npz` declares more replay-buffer rows than its run holds,
within the run's own size bound: what `train --resume DIR` must refuse from the `.npy` headers
before inflating anything.

    PYTHONPATH=. .venv/bin/python benchmarks/crafted_checkpoint.py DIR shipped   # 2.5 MB -> 2,580 MB
    PYTHONPATH=. .venv/bin/python benchmarks/crafted_checkpoint.py DIR small     # 0.2 MB -> 248 MB
    /usr/bin/time -f '%e s %M KB' .venv/bin/drivestack train --resume DIR --no-progress

`shipped`: configs/train/ddqn.yaml with one member and one env process (its 64 batched worlds
kept); `small`: a 1,000-transition run. Prints what the file holds.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from stack.apps.options import TRAIN_CONFIG  # noqa: E402
from stack.settings.run import build_config, load_config  # noqa: E402
from stack.training.checks import checkpoint_bytes, transition_bytes  # noqa: E402
from tests.test_hostile_inputs import owned_training_folder  # noqa: E402
from tests.test_hostile_inputs_more import oversized_buffer_checkpoint  # noqa: E402

SHARE_OF_BOUND = 0.97
"""The share of the run's checkpoint bound the crafted buffer fills."""


def main(folder: Path, kind: str) -> None:
    if kind == "small":
        data = {"train": {"steps": 10, "buffer_size": 1000}, "highway": {"duration": 2}}
        fields: tuple[str, ...] = ("observations",)
    else:
        data = load_config(TRAIN_CONFIG, train__envs=1, train__members=1).model_dump(mode="json")
        fields = ("observations", "next_observations")
    config = build_config(data)
    size = (transition_bytes(config) - 20) // 8 + (3 if config.train.action_mask else 0)
    envs = config.train.worlds if kind == "shipped" else 1
    bound = checkpoint_bytes(config)
    rows = int(SHARE_OF_BOUND * (bound - 2**20) / len(fields) / (4 * size * envs))
    owned_training_folder(folder, data)
    crafted = oversized_buffer_checkpoint((rows, envs, size), fields)
    (folder / "checkpoint.npz").write_bytes(crafted)
    inflated = len(fields) * rows * envs * size * 4
    print(
        f"{kind}: buffer_size {config.train.buffer_size}, bound {bound / 2**20:.0f} MB; "
        f"{len(fields)} x ({rows}, {envs}, {size}) float32 = {inflated / 2**20:.0f} MB inflated "
        f"from {len(crafted) / 2**20:.2f} MB"
    )


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[2] not in ("shipped", "small"):
        print("usage: crafted_checkpoint.py DIR shipped|small", file=sys.stderr)
        sys.exit(2)
    main(Path(sys.argv[1]), sys.argv[2])
