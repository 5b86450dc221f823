"""A model file format that cannot execute code: one `.npz` (a zip of `.npy` members, read with
`allow_pickle=False`) holding numeric arrays (network weights or a Q-table) and a JSON metadata
member.

Metadata says what the arrays mean: `kind` (`mlp` or `qtable`), the algorithm, the observation
size and encoding, the grid the observation came from, the network sizes. Reading is bounded before
anything is inflated or allocated: the zip directory must list only `.npy` members, stored or
deflated, unencrypted, whose declared sizes fit `max_bytes`; each member's `.npy` header (only
its first bytes inflated) must declare a numeric dtype and a shape whose bytes fit its member, and
the metadata's at most `MAX_METADATA_BYTES`; a reader that knows what the file must hold (a
training run its checkpoint) checks every header against that (`ExpectedArray`, `header_check`)
before any array is read. Metadata must be a JSON object. Anything else is refused with one line
naming the file.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

FORMAT = "drivestack-model/1"
MODEL_BYTES = 64 * 2**20
"""Largest model file drivestack loads as an agent, inflated [bytes] (the shipped ones: < 2 MB)."""
CHECKPOINT = "checkpoint.npz"
"""A training run folder's checkpoint file."""
CHECKPOINT_BYTES = 4 * 2**30
"""Largest training checkpoint (weights, optimizer, replay buffer), inflated [bytes]."""
MAX_METADATA_BYTES = 2**20
"""[bytes]"""
MAX_MESSAGE = 200
"""Longest quote of a file's content in an error message [characters]."""


METADATA = "metadata.npy"

HeaderCheck = Callable[[str, tuple[int, ...], np.dtype], str | None]
"""(array name, shape, dtype) as a member's `.npy` header declares them -> why the array cannot be
one of the file's (a phrase, e.g. "is not part of this run's checkpoint"), or None."""


class ModelFileError(ValueError):
    """A model file that cannot be loaded; the message is one line naming the file."""


@dataclass(frozen=True)
class ExpectedArray:
    """What one array of a file must be: its `dtype` (None: any number) and `shape`, whose first
    dimension may be anything up to `shape[0]` when `at_most_rows` (a replay buffer's filled rows)."""

    shape: tuple[int, ...]
    dtype: np.dtype | None = None
    at_most_rows: bool = False

    def admits(self, shape: tuple[int, ...], dtype: np.dtype) -> bool:
        if self.dtype is not None and dtype != self.dtype:
            return False
        if self.at_most_rows:
            return (
                len(shape) == len(self.shape) >= 1
                and shape[0] <= self.shape[0]
                and shape[1:] == self.shape[1:]
            )
        return shape == self.shape

    def __str__(self) -> str:
        shape = (f"<={self.shape[0]}", *self.shape[1:]) if self.at_most_rows else self.shape
        return f"({', '.join(map(str, shape))}{',' if len(shape) == 1 else ''}) {self.dtype or 'numbers'}"


def header_check(layout: dict[str, tuple[ExpectedArray, ...]]) -> HeaderCheck:
    """The `HeaderCheck` of a file holding the arrays `layout` names, each one of its options; a
    name ending in `/*` stands for any last part (`optimizer/0/*`)."""

    def check(name: str, shape: tuple[int, ...], dtype: np.dtype) -> str | None:
        options = layout.get(name) or layout.get(name.rpartition("/")[0] + "/*")
        if options is None:
            return "is not part of this run's checkpoint"
        if any(option.admits(shape, dtype) for option in options):
            return None
        declared = ExpectedArray(shape, dtype)
        return f"declares {declared}; this run's holds {' or '.join(map(str, options))}"

    return check


def save_model(path: Path | str, arrays: dict[str, np.ndarray], metadata: dict) -> Path:
    """Write arrays + metadata atomically (a temporary file renamed over `path`; removed on any
    error, so a full disk keeps no half file; an OSError names `path`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {f"array/{name}": np.asarray(value) for name, value in arrays.items()}
    payload["metadata"] = np.frombuffer(json.dumps({"format": FORMAT, **metadata}).encode(), dtype=np.uint8)
    temporary = path.with_name(path.name + ".partial")
    try:
        with temporary.open("wb") as handle:
            # numpy's stub matches **payload against savez's `allow_pickle: bool` (no key is named that)
            np.savez(handle, **payload)  # type: ignore[arg-type]
        temporary.replace(path)
    except OSError as error:
        raise OSError(error.errno, error.strerror or str(error), str(path)) from error
    finally:
        temporary.unlink(missing_ok=True)
    return path


def with_metadata(source: Path | str, out: Path | str, fields: dict) -> Path:
    """`source` written to `out` (which may be `source`) with `fields` set in its metadata, its
    weights and every other metadata field as they were: how a calibration is written into a model
    file (the gate's threshold, the learned agents' change margin)."""
    arrays, metadata = load_model(source)
    kept = {key: value for key, value in metadata.items() if key != "format"}
    return save_model(out, arrays, {**kept, **fields})


def load_model(
    path: Path | str, max_bytes: int = MODEL_BYTES, arrays: bool = True, expected: HeaderCheck | None = None
) -> tuple[dict[str, np.ndarray], dict]:
    """(arrays, metadata) of a model file of at most `max_bytes` inflated; never unpickles. With
    `arrays=False` only the metadata is read (the whole directory is checked all the same). With
    `expected`, every array's header is checked by it before any array is read."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such model file")
    try:
        with zipfile.ZipFile(path) as archive:
            members = _checked_members(path, archive, max_bytes)
            checked = [name for name in members if arrays or expected is not None or name == METADATA]
            for name in checked:
                _check_header(path, archive, members[name], expected)
            data = {
                name.removesuffix(".npy"): _read_array(archive, members[name])
                for name in checked
                if arrays or name == METADATA
            }
    except ModelFileError:
        raise
    except (
        zipfile.BadZipFile,
        zlib.error,
        NotImplementedError,
        RuntimeError,
        OSError,
        EOFError,
        ValueError,
    ) as error:
        reason = str(error).splitlines()[0][:MAX_MESSAGE] if str(error) else ""
        raise ModelFileError(
            f"{path}: not a drivestack model file ({type(error).__name__}: {reason})"
        ) from None
    if "metadata" not in data:
        raise ModelFileError(f"{path}: not a drivestack model file (no metadata)")
    metadata = _metadata(path, data.pop("metadata"))
    return {name.removeprefix("array/"): value for name, value in data.items()}, metadata


def load_checkpoint(
    path: Path | str,
    arrays: bool = True,
    max_bytes: int = CHECKPOINT_BYTES,
    expected: HeaderCheck | None = None,
) -> tuple[dict[str, np.ndarray], dict]:
    """A training checkpoint (`load_model` of at most `max_bytes`, the run's own bound, at most
    CHECKPOINT_BYTES, each array as `expected`: what the run's own model holds), refused in one
    line unless it is one; `arrays=False` reads its metadata only."""
    found, metadata = load_model(path, min(max_bytes, CHECKPOINT_BYTES), arrays, expected)
    if metadata.get("kind") != "checkpoint" or not isinstance(metadata.get("counters"), dict):
        raise ModelFileError(f"{path}: not a training checkpoint")
    return found, metadata


def _checked_members(path: Path, archive: zipfile.ZipFile, max_bytes: int) -> dict[str, zipfile.ZipInfo]:
    """The zip's members by name, after checking the directory alone (nothing inflated yet)."""
    members = {info.filename: info for info in archive.infolist()}
    total = 0
    for name, info in members.items():
        if not name.endswith(".npy") or not (name == METADATA or name.startswith("array/")):
            raise ModelFileError(
                f"{path}: unexpected member {name[:MAX_MESSAGE]!r}; expected metadata and arrays"
            )
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED) or info.flag_bits & 0x1:
            raise ModelFileError(f"{path}: member {name!r} is encrypted or compressed in an unknown way")
        total += info.file_size
    if total > max_bytes:
        raise ModelFileError(
            f"{path}: {total / 2**20:.0f} MB when unpacked; at most {max_bytes / 2**20:.0f} MB"
        )
    return members


def _check_header(
    path: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo, expected: HeaderCheck | None
) -> None:
    """One member's `.npy` header (only its first bytes inflated), before any array is allocated:
    a numeric dtype, a shape that fits the member (the metadata's: `MAX_METADATA_BYTES`) and, for
    an array, what `expected` says the file holds."""
    with archive.open(info) as stream:
        shape, dtype = _header(stream)
    if dtype.hasobject or dtype.kind not in "fiub":
        raise ModelFileError(f"{path}: {info.filename!r} holds {dtype} values; only numbers are allowed")
    declared = float(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    if declared > info.file_size:
        raise ModelFileError(f"{path}: {info.filename!r} declares {shape} values, more than it holds")
    if info.filename == METADATA:
        if declared > MAX_METADATA_BYTES:
            raise ModelFileError(f"{path}: metadata of {declared:.0f} bytes; at most {MAX_METADATA_BYTES}")
    elif expected is not None:
        name = info.filename.removeprefix("array/").removesuffix(".npy")
        if (why := expected(name, shape, dtype)) is not None:
            raise ModelFileError(f"{path}: {name[:MAX_MESSAGE]!r} {why}")


def _read_array(archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    """One member whose header `_check_header` checked."""
    with archive.open(info) as stream:
        return np.lib.format.read_array(stream, allow_pickle=False)


def _header(stream: IO[bytes]) -> tuple[tuple[int, ...], np.dtype]:
    """(shape, dtype) from a `.npy` header, read without touching the data."""
    version = np.lib.format.read_magic(stream)
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, _, dtype = read(stream)
    return shape, dtype


def _metadata(path: Path, raw: np.ndarray) -> dict:
    """The metadata member (its size checked with its header) as a JSON object."""
    try:
        metadata = json.loads(raw.tobytes().decode())
    except (ValueError, RecursionError):  # not UTF-8, not JSON, an integer over Python's digit limit
        raise ModelFileError(
            f"{path}: model metadata is not valid JSON (or holds an integer too long to read)"
        ) from None
    if not isinstance(metadata, dict):
        raise ModelFileError(f"{path}: model metadata must be a JSON object, got {type(metadata).__name__}")
    if metadata.get("format") != FORMAT:
        raise ModelFileError(
            f"{path}: unsupported model format {str(metadata.get('format'))[:80]!r}; expected {FORMAT}"
        )
    return metadata
