"""A model file format that cannot execute code: one `.npz` (numpy, `allow_pickle=False`) holding
float arrays (network weights or a Q-table) and a JSON metadata string.

Metadata says what the arrays mean: `kind` (`mlp` or `qtable`), the algorithm, the observation
size and encoding, the grid the observation came from, the network sizes. A file that is not a
valid npz, lacks metadata, or whose arrays do not match the metadata is refused with one line.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

FORMAT = "drivestack-model/1"


class ModelFileError(ValueError):
    """A model file that cannot be loaded; the message is one line naming the file."""


def save_model(path: Path | str, arrays: dict[str, np.ndarray], metadata: dict) -> Path:
    """Write arrays + metadata atomically (a temporary file renamed over `path`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {f"array/{name}": np.asarray(value) for name, value in arrays.items()}
    payload["metadata"] = np.frombuffer(json.dumps({"format": FORMAT, **metadata}).encode(), dtype=np.uint8)
    temporary = path.with_name(path.name + ".partial")
    with temporary.open("wb") as handle:
        # numpy's stub matches **payload against savez's `allow_pickle: bool` too (no key is named that)
        np.savez(handle, **payload)  # type: ignore[arg-type]
    temporary.replace(path)
    return path


def load_model(path: Path | str) -> tuple[dict[str, np.ndarray], dict]:
    """(arrays, metadata) of a model file; never unpickles."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such model file")
    try:
        with np.load(path, allow_pickle=False) as content:
            data = {name: content[name] for name in content.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as error:
        raise ModelFileError(
            f"{path}: not a drivestack model file ({type(error).__name__}: {error})"
        ) from None
    if "metadata" not in data:
        raise ModelFileError(f"{path}: not a drivestack model file (no metadata)")
    try:
        metadata = json.loads(data.pop("metadata").tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise ModelFileError(f"{path}: model metadata is not valid JSON") from None
    if metadata.get("format") != FORMAT:
        raise ModelFileError(
            f"{path}: unsupported model format {metadata.get('format')!r}; expected {FORMAT}"
        )
    arrays = {name.removeprefix("array/"): value for name, value in data.items()}
    for name, value in arrays.items():
        if value.dtype.kind not in "fiub":
            raise ModelFileError(f"{path}: array {name!r} has dtype {value.dtype}; only numbers are allowed")
    return arrays, metadata
