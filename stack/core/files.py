"""Result files written whole or not at all, and finished episodes kept as they finish.

Each result file is written to a temporary file beside it and renamed over it (one atomic step on
POSIX), so a reader never finds half a file whatever stops the writer; the journal appends one line
per finished episode and syncs it to disk, so even a killed run keeps every finished episode."""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from stack.core.interrupts import deferred

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from stack.core.metrics import EpisodeResult


@contextmanager
def replacing(path: Path) -> Iterator[Path]:
    """A temporary path beside `path` (same suffix, for writers that go by it) that becomes `path`
    once the block ends without error; on error it is removed and `path` is left as it was."""
    temporary = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> None:
    with replacing(path) as temporary:
        temporary.write_text(text)


def write_json(path: Path, data: Any) -> None:
    write_text(path, json.dumps(data, indent=2) + "\n")


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


class EpisodeJournal:
    """`path` gets one JSON line per finished episode, on disk before the next episode counts;
    a signal arriving meanwhile waits for the line (`stack.core.interrupts.deferred`). The ordered
    results replace it at the end (`discard`)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def record(self, episode: EpisodeResult) -> None:
        row = episode.row()
        with deferred():
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self.path.open("a") as handle:
                handle.write(json.dumps(row) + "\n")
                handle.flush()
                os.fsync(handle.fileno())

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

    def keep(self, episodes: list[EpisodeResult]) -> None:
        """Rewrite the journal to hold exactly `episodes` (those a resumed run keeps), so appending
        goes on after them; an empty journal when there are none."""
        with deferred():
            write_text(self.path, "".join(json.dumps(episode.row()) + "\n" for episode in episodes))

    def discard(self) -> None:
        self.path.unlink(missing_ok=True)


def _json_object(line: bytes) -> dict[str, Any] | None:
    """`line` as a JSON object, or None when it is not one (not UTF-8, not JSON, not an object)."""
    try:
        row = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return None
    return row if isinstance(row, dict) else None
