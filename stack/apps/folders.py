"""Where a command writes: `--out` checked without creating anything, then taken for the command
(`stack.runtime.owner`) as the last check before any work, the lock held until the command ends."""

from __future__ import annotations

import errno
import os
from datetime import datetime
from pathlib import Path
from typing import IO, TYPE_CHECKING

from stack.apps.options import fail
from stack.runtime.owner import FolderRefused, Owner, claim, fingerprint

if TYPE_CHECKING:
    from stack.results.episode_result import EpisodeResult
    from stack.settings.run import RunConfig


def fresh_run_dir(prefix: str) -> Path:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    return Path("runs") / f"{prefix}-{stamp}"


def location(out: Path | None, prefix: str) -> Path:
    """`out` (or a fresh `runs/<prefix>-<time>`) once it is a folder, or can become one, that this
    user may write; a one-line error (exit 2) otherwise. Nothing is created."""
    folder = out or fresh_run_dir(prefix)
    try:
        if folder.is_symlink() and not folder.exists():
            fail(
                f"--out: {folder} is a link to a missing folder ({os.readlink(folder)[:80]}); "
                "make that folder or choose another"
            )
        if folder.exists() and not folder.is_dir():
            fail(f"--out: {folder} is a file; expected a folder for the results")
    except OSError as error:
        fail(f"--out: cannot create {str(folder)[:80]}... ({error.strerror})")
    parent = folder.absolute()
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        fail(f"--out: cannot create {folder} ({parent} is a file)")
    if not os.access(parent, os.W_OK | os.X_OK):
        fail(f"--out: {parent} is not writable")
    if too_long := _too_long(folder):
        fail(f"--out: cannot create {str(folder)[:80]}... ({too_long})")
    return folder


def _too_long(folder: Path) -> str | None:
    """Why the system would refuse `folder` as a name (None when it would not)."""
    limit = os.pathconf(folder.absolute().anchor, "PC_NAME_MAX")
    if any(len(part.encode()) > limit for part in folder.parts):
        return os.strerror(errno.ENAMETOOLONG)
    return None


_held: list[IO[str]] = []
"""The lock this process holds, until the process ends or its next command (commands run one at a
time in a process: a test runs several in one)."""


def claimed(
    out: Path | None, prefix: str, owner: Owner, resuming: bool = False, restart: bool = True
) -> Path:
    """`location(out, prefix)` taken for `owner` (`stack.runtime.owner.claim`): the folder exists,
    is locked until the command ends and records its owner; a one-line error otherwise."""
    folder = location(out, prefix)
    while _held:
        _held.pop().close()
    try:
        handle = claim(folder, owner, resuming, restart)
    except FolderRefused as error:
        fail(str(error))
    except OSError as error:
        fail(f"--out: cannot write {folder} ({error.strerror})")
    _held.append(handle)
    return folder


def claimed_for(command: str, out: Path | None, arguments: str, config: RunConfig | None = None) -> Path:
    """`claimed` for a command without `--resume`, owned by the hash of its `arguments` and
    resolved `config`; its folder's default name is the command's last word."""
    from stack.settings.run import config_text

    asked = fingerprint(arguments + (config_text(config) if config is not None else ""))
    prefix = command.split()[-1]
    return claimed(location(out, prefix), prefix, Owner(command, asked))


def written_file(out: Path, suffix: str = ".zip") -> Path:
    """The file a writer that appends `suffix` to a name without one (stable-baselines3's `save`)
    writes for `out`."""
    return out.with_name(out.name + suffix) if not out.suffix else out


def check_destination(out: Path, option: str = "--sb3", suffix: str = ".zip") -> None:
    """Refuse (ValueError, one line naming `option`) an `out` that is no file name, exists (with or
    without the `suffix` its writer appends to a name without one; "": none), lies in no writable
    folder or has a name the system refuses, before any work."""
    if out.name in ("", ".", "..") or str(out).endswith(os.sep):
        raise ValueError(f"{option}: expected a file name, got {str(out)[:80]!r}")
    written = written_file(out, suffix)
    if len(written.name.encode()) > os.pathconf(written.absolute().anchor, "PC_NAME_MAX"):
        raise ValueError(f"{option}: {str(written)[:80]}...: {os.strerror(errno.ENAMETOOLONG)}")
    if out.exists() or written.exists():
        raise ValueError(f"{option}: {out} exists; choose a new file")
    if not out.parent.is_dir():
        raise ValueError(f"{option}: no folder {out.parent}")
    if not os.access(out.parent, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: {out.parent} is not writable")


def episodes_kept(folder: Path) -> str:
    """What a run or comparison in `folder` kept when a results file could not be written (a full
    disk, a folder made read-only), and how to go on."""
    from stack.apps.options import AGAIN
    from stack.runtime.files import JOURNAL

    journals = sorted(path.name for path in folder.glob(f"*.{JOURNAL}"))
    if not journals or not (folder / "config.yaml").is_file():
        return AGAIN
    return (
        f"the episodes finished are kept in {', '.join(journals)}: free space, then the same "
        "command with --resume finishes the run"
    )


def resumed(configs: list[RunConfig], out: Path | None, command: str) -> dict[str, list[EpisodeResult]]:
    """`--resume`: the episodes the interrupted run in `out` finished, per agent (`resumable`)."""
    from stack.apps.resume import resumable

    if out is None:
        fail("--resume: name the folder of the interrupted run with --out")
    try:
        return resumable(configs, out, command)
    except ValueError as error:
        fail(str(error))
