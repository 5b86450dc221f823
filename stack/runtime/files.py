"""Result files written whole or not at all, and finished episodes kept as they finish.

Each result file is written to a temporary file beside it and renamed over it (one atomic step on
POSIX), so a reader never finds half a file whatever stops the writer; the journal appends one line
per finished episode and syncs it to disk, so even a killed run keeps every finished episode."""

from __future__ import annotations

import csv
import errno
import json
import math
import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Protocol, TypeGuard

from stack.runtime.interrupts import deferred

if TYPE_CHECKING:
    from matplotlib.figure import Figure


WRITE_ERRORS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG, errno.EIO}
)
"""Why writing a file fails on a sound system: a full disk or quota, a read-only or forbidden
place, a file too large, a failing device."""


class WriteFailed(OSError):
    """A results file that could not be written (`filename`: the file, `strerror`: why). What it
    would have replaced is left as it was and no temporary file is left behind."""


def write_failure(error: BaseException) -> TypeGuard[OSError]:
    """Whether `error` is a file that could not be written for one of `WRITE_ERRORS`."""
    return isinstance(error, OSError) and (isinstance(error, WriteFailed) or error.errno in WRITE_ERRORS)


def make_folder(folder: Path) -> None:
    """`folder` made with its parents, if missing; `WriteFailed` naming it when a file (or anything
    but a folder) stands in its place, as in a results folder whose sub-folder was replaced."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise WriteFailed(
            errno.ENOTDIR, "something that is not a folder is in its place", str(folder)
        ) from None


@contextmanager
def replacing(path: Path) -> Iterator[Path]:
    """A temporary path beside `path` (same suffix, for writers that go by it) that becomes `path`
    once the block ends without error; on error it is removed and `path` is left as it was (an
    OSError is raised as `WriteFailed` naming `path`)."""
    temporary = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        temporary.unlink(missing_ok=True)
        yield temporary
        os.replace(temporary, path)
    except OSError as error:
        raise WriteFailed(error.errno, error.strerror or str(error), str(path)) from error
    finally:
        temporary.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> None:
    with replacing(path) as temporary:
        temporary.write_text(text)


def write_json(path: Path, data: Any) -> None:
    """`data` as strict JSON (`finite`): every JSON reader takes it."""
    write_text(path, json.dumps(finite(data), indent=2, allow_nan=False) + "\n")


def finite(data: Any) -> Any:
    """`data` with every non-finite number as null; in a mapping, the key `<key>_not_finite`
    beside it says which it was ("inf", "-inf" or "nan": an unbounded time to collision, a
    controller that returned NaN)."""
    if isinstance(data, float) and not math.isfinite(data):
        return None
    if isinstance(data, dict):
        notes = {
            f"{key}_not_finite": str(value)
            for key, value in data.items()
            if isinstance(value, float) and not math.isfinite(value)
        }
        return {key: finite(value) for key, value in data.items()} | notes
    if isinstance(data, list | tuple):
        return [finite(value) for value in data]
    return data


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """One CSV row per dict, the first dict's keys as the header."""
    with replacing(path) as temporary, temporary.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def save_figure(figure: Figure, path: Path, dpi: int) -> None:
    with replacing(path) as temporary:
        figure.savefig(temporary, dpi=dpi)


JOURNAL = "episodes.partial.jsonl"
"""Finished episodes, one JSON line each, as they finish; replaced by the results at the end."""


class JournalEntry(Protocol):
    """What the journal keeps of a finished episode (`stack.results.episode_result.EpisodeResult`): its row
    of plain values (the runtime never imports the loop it keeps the results of)."""

    def row(self) -> dict[str, Any]: ...


class EpisodeJournal:
    """`path` gets one JSON line per finished episode, on disk before the next episode counts;
    a signal arriving meanwhile waits for the line (`stack.runtime.interrupts.deferred`). The ordered
    results replace it at the end (`discard`)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def record(self, episode: JournalEntry) -> None:
        """Append `episode`'s line; a line that cannot be written whole is cut off again, so the
        journal holds the lines before it (`WriteFailed`)."""
        line = (json.dumps(episode.row()) + "\n").encode()
        with deferred():
            try:
                make_folder(self.path.parent)
                with open_appending(self.path) as handle:
                    start = handle.seek(0, os.SEEK_END)
                    try:
                        _write_all(handle, line)
                        os.fsync(handle.fileno())
                    except OSError:
                        with suppress(OSError):
                            os.ftruncate(handle.fileno(), start)
                        raise
            except OSError as error:
                raise WriteFailed(error.errno, error.strerror or str(error), str(self.path)) from error

    def lines(self, max_bytes: int) -> list[dict[str, Any] | None]:
        """Each line journaled so far as its JSON object, or None where a line is not one (not
        UTF-8, not JSON: a run killed in mid-line, a damaged file). Read only; a journal over
        `max_bytes` is refused (ValueError) before it is read."""
        if not self.path.is_file():
            return []
        if (size := self.path.stat().st_size) > max_bytes:
            raise ValueError(
                f"{self.path}: {size} bytes; a journal of these episodes holds at most {max_bytes}"
            )
        return [_json_object(line) for line in self.path.read_bytes().splitlines()]

    def keep(self, episodes: Sequence[JournalEntry]) -> None:
        """Rewrite the journal to hold exactly `episodes` (those a resumed run keeps), so appending
        goes on after them; an empty journal when there are none."""
        with deferred():
            write_text(self.path, "".join(json.dumps(episode.row()) + "\n" for episode in episodes))

    def discard(self) -> None:
        self.path.unlink(missing_ok=True)


def open_appending(path: Path) -> BinaryIO:
    """`path` opened to append, unbuffered; OSError (ELOOP) when it is a symbolic link, so a
    results folder's files never write through a link to a file outside it."""
    descriptor = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    return os.fdopen(descriptor, "ab", buffering=0)


def _write_all(handle: BinaryIO, data: bytes) -> None:
    """All of `data` through the unbuffered `handle`: a write to a filling disk may take part of
    it before the next one fails."""
    while data:
        count = handle.write(data)
        if not count:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        data = data[count:]


def _json_object(line: bytes) -> dict[str, Any] | None:
    """`line` as a JSON object, or None when it is not one (not UTF-8, not JSON, not an object)."""
    try:
        row = json.loads(line.decode("utf-8"))
    except (ValueError, RecursionError):  # not UTF-8, not JSON, an integer over Python's digit limit
        return None
    return row if isinstance(row, dict) else None
