"""Result files written whole or not at all, and finished episodes kept as they finish.

Each result file is written to a temporary file beside it and renamed over it (one atomic step on
POSIX), so a reader never finds half a file whatever stops the writer; the journal appends one line
per finished episode and syncs it to disk, so even a killed run keeps every finished episode."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure


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


def save_figure(figure: Figure, path: Path, dpi: int) -> None:
    with replacing(path) as temporary:
        figure.savefig(temporary, dpi=dpi)


class EpisodeJournal:
    """`path` gets one JSON line per finished episode, on disk before the next episode counts.
    The ordered results replace it at the end (`close(remove=True)`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.handle: IO[str] | None = None

    def record(self, row: dict[str, Any]) -> None:
        if self.handle is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.handle = self.path.open("a")
        self.handle.write(json.dumps(row) + "\n")
        self.handle.flush()
        os.fsync(self.handle.fileno())

    def close(self, remove: bool) -> None:
        if self.handle is not None:
            self.handle.close()
            self.handle = None
        if remove:
            self.path.unlink(missing_ok=True)
