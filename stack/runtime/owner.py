"""One owner per results folder: the command that made it and a hash of its config, recorded in
`MARKER`, and a lock (`LOCK`, an advisory `flock`) held while a command writes the folder.

A second command, a second writer at the same time, or a `--resume` with another config would mix
two runs' files in one folder; they are refused in one line before anything is written. A fresh
command may take an empty folder, or start over in a folder the same command with the same config
made (`restart`); any other non-empty folder is refused. Folders made before markers existed carry
none: `run` and `compare --resume` take one whose config.yaml is exactly theirs, `train --resume`
only with `--adopt` (`stack.apps.adoption`)."""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import stat
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO

from stack.runtime.files import write_json

MARKER = ".drivestack-owner.json"
"""The owner record of a results folder: {"command": ..., "config": ...}."""
LOCK = ".drivestack.lock"
"""The lock file of a results folder: holds the pid of the command writing it."""
BOOKKEEPING = (MARKER, LOCK)


class FolderRefused(ValueError):
    """A results folder this command may not write; the message is one line for the user."""


@dataclass(frozen=True)
class Owner:
    """Who made a results folder: the sub-command (run, compare, train, track, ...) and the
    `fingerprint` of what it was asked to do (its resolved config and arguments)."""

    command: str
    config: str


def fingerprint(text: str) -> str:
    """A short hash of `text` (the resolved config and arguments of a command)."""
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def owner_of(folder: Path) -> Owner | None:
    """The owner `folder` records; None without a marker; an unreadable marker is an unknown
    owner (never equal to a command's)."""
    try:
        data = json.loads((folder / MARKER).read_bytes())
        return Owner(str(data["command"]), str(data["config"]))
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        return Owner("unknown command", "")


def holds_results(folder: Path) -> bool:
    """Whether `folder` holds any file besides this module's bookkeeping."""
    try:
        return folder.is_dir() and any(p.name not in BOOKKEEPING for p in folder.iterdir())
    except OSError:
        return True


def refusal(folder: Path, wanted: Owner, resuming: bool, restart: bool = True) -> str | None:
    """Why the command `wanted` may not write `folder` (one line), or None when it may: a resumed
    command needs the same owner (or none: an older folder), a fresh one an empty folder or, with
    `restart`, one it made itself with the same config."""
    if not plain_or_missing(folder / LOCK):
        return NOT_PLAIN.format(path=folder / LOCK)
    if (link := first_link(folder)) is not None:
        return LINKED.format(path=link)
    found = owner_of(folder)
    if resuming:
        if found is not None and found.command != wanted.command:
            return f"--resume: {folder} holds the results of `{found.command}`, not of `{wanted.command}`"
        if found is not None and found.config != wanted.config:
            return (
                f"--resume: {folder} is another run's (`{found.command}` with other arguments or config); "
                "resume with the arguments that started it"
            )
        return None
    if not holds_results(folder) or (restart and found == wanted):
        return None
    what = f"the results of `{found.command}`" if found is not None else "files drivestack did not write"
    more = ""
    if found is not None and found.command == wanted.command:
        more = " with these arguments and config" if found == wanted else " with other arguments or config"
    hint = " (--resume continues an interrupted one)" if found is not None else ""
    return f"--out: {folder} already holds {what}{more}; choose a new folder{hint}"


def claim(folder: Path, wanted: Owner, resuming: bool, restart: bool = True) -> IO[str]:
    """Take `folder` for `wanted`: create it, lock it (FolderRefused when another command holds
    the lock), check `refusal` under the lock, record the owner. Returns the open lock file: the
    lock lasts until it is closed (at the latest when the process ends)."""
    if why := refusal(folder, wanted, resuming, restart):
        raise FolderRefused(why)
    folder.mkdir(parents=True, exist_ok=True)
    handle = lock_file(folder / LOCK)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip()[:20] or "?"
        handle.close()
        raise FolderRefused(
            f"--out: {folder} is being written by another drivestack command (pid {holder}); "
            "wait for it to end or choose another folder"
        ) from None
    if why := refusal(folder, wanted, resuming, restart):
        handle.close()
        raise FolderRefused(why)
    handle.truncate(0)
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    write_json(folder / MARKER, asdict(wanted))
    return handle


def lock_file(path: Path) -> IO[str]:
    """`path` opened to read and write, created if missing; FolderRefused when it is not a plain
    file of its own (a link, a pipe, a folder): the pid written into it must not land elsewhere."""
    flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK
    try:
        descriptor = os.open(path, flags, 0o644)
    except OSError as error:
        if error.errno not in (errno.ELOOP, errno.EISDIR, errno.ENXIO):
            raise
        raise FolderRefused(NOT_PLAIN.format(path=path)) from None
    if not stat.S_ISREG(os.fstat(descriptor).st_mode):
        os.close(descriptor)
        raise FolderRefused(NOT_PLAIN.format(path=path))
    return os.fdopen(descriptor, "a+")


NOT_PLAIN = "--out: {path} is not a plain file; remove it or choose another folder"
LINKED = (
    "--out: {path} is a link; a results folder holds no links (its files would be written where "
    "it points): remove it or choose another folder"
)


def first_link(folder: Path) -> Path | None:
    """The first entry below `folder` (at any depth, `folder` itself aside) that is a symbolic
    link, or None: a file written below a link lands outside the folder. Links are not followed."""
    pending = [folder]
    while pending:
        try:
            entries = os.scandir(pending.pop())
        except OSError:
            continue
        with entries:
            for entry in entries:
                if entry.is_symlink():
                    return Path(entry.path)
                if entry.is_dir(follow_symlinks=False):
                    pending.append(Path(entry.path))
    return None


def plain_or_missing(path: Path) -> bool:
    """Whether `path` is a plain file (not a link to one) or nothing at all."""
    try:
        return stat.S_ISREG(path.lstat().st_mode)
    except FileNotFoundError:
        return True
    except OSError:
        return False
