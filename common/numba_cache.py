"""Where numba keeps the compiled kernels: one folder per version of the compiled sources.

numba checks a cached kernel against its own file only, while a kernel here compiles the laws of
other files into itself (`numba.extending.register_jitable`: a PID, the safety layer's gap rule,
the grid): after an edit to a law, the kernels of other files would load their old machine code
from `__pycache__` and the batch would silently drive yesterday's law beside today's one world.
So the cache lives in `drivestack_cache()/numba/KEY`, KEY a hash of every source file of the
package that mentions numba: any edit there compiles afresh, every other run loads. Each package
imports this module first (its `__init__`), before numba compiles anything."""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

PACKAGES = ("common", "controllers", "perception", "planner", "stack")
"""The packages whose modules numba compiles."""


def drivestack_cache() -> Path:
    """drivestack's cache folder: `$DRIVESTACK_CACHE`, else `$XDG_CACHE_HOME/drivestack`, else
    `~/.cache/drivestack`."""
    explicit = os.environ.get("DRIVESTACK_CACHE")
    if explicit:
        return Path(explicit)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "drivestack"


def sources_key(root: Path) -> str:
    """A hash of the name and content of every module under `root`'s packages that mentions numba."""
    digest = hashlib.sha256()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            text = path.read_bytes()
            if b"numba" in text:
                digest.update(path.relative_to(root).as_posix().encode() + b"\0" + text)
    return digest.hexdigest()[:20]


def configure() -> Path:
    """Point numba's cache at this version's folder (before numba is imported: its environment
    variable; after: its config, which numba reads when a kernel is first decorated)."""
    folder = drivestack_cache() / "numba" / sources_key(Path(__file__).resolve().parent.parent)
    if "numba" in sys.modules:
        from numba.core import config

        config.CACHE_DIR = str(folder)  # type: ignore[attr-defined]
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    return folder


CACHE_FOLDER = configure()
"""This version's numba cache."""
