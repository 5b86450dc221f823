"""CasADi functions compiled to C once per machine, with the interpreted function as the fallback.

`compiled(function)` generates C for `function` (CasADi's `CodeGenerator`), compiles it with the
system C compiler into a shared library cached under `cache_directory()` by a hash of the source,
and loads it (`ca.external`); the next build with the same source loads the cached library
without compiling. Without a compiler, with `DRIVESTACK_COMPILE=0`, or when compiling fails, it
returns `function` itself. Both give the same numbers bit for bit: the generated code performs
the same double-precision operations in the same order as CasADi's virtual machine, and
`-ffp-contract=off` forbids the compiler to fuse them; so whether a machine has a compiler never
changes a result, only the time (the MPC's linearisation 0.19 -> 0.05 ms on the dynamic model).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca

from common.numba_cache import drivestack_cache

FLAGS = ("-O1", "-ffp-contract=off", "-fPIC", "-shared")
"""-O1: a dynamic-model linearisation compiles in 4 s (-O2: 9 s, 15 % faster to run)."""
COMPILE_TIMEOUT_S = 300
"""A compiler slower than this is treated as missing (the interpreted function is used)."""


def cache_directory() -> Path:
    """Where compiled libraries are kept: drivestack's cache folder's `casadi`
    (`common.numba_cache.drivestack_cache`)."""
    return drivestack_cache() / "casadi"


def compiler() -> str | None:
    """The C compiler to use (`$CC`, else cc or gcc on the PATH), or None: compiling is off
    (`DRIVESTACK_COMPILE=0`) or there is none."""
    if os.environ.get("DRIVESTACK_COMPILE", "1") == "0":
        return None
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


def _build(source: str, library: Path, cc: str) -> bool:
    """Compile `source` into `library` (atomically: parallel processes may race); success."""
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent) as folder:
        c_file, built = Path(folder) / "function.c", Path(folder) / library.name
        c_file.write_text(source)
        command = [cc, *FLAGS, str(c_file), "-o", str(built), "-lm"]
        try:
            subprocess.run(command, check=True, capture_output=True, timeout=COMPILE_TIMEOUT_S)
        except (OSError, subprocess.SubprocessError):
            return False
        os.replace(built, library)
    return True


def compiled(function: ca.Function) -> ca.Function:
    """`function` compiled and loaded, or `function` itself when it cannot be (same results)."""
    cc = compiler()
    if cc is None:
        return function
    name = function.name()
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    generator.add(function)
    source = generator.dump()
    key = hashlib.sha256(f"{ca.CasadiMeta.version()} {cc} {FLAGS}\n{source}".encode()).hexdigest()[:24]
    try:
        library = cache_directory() / f"{name}_{key}.so"
        if library.exists() or _build(source, library, cc):
            return ca.external(name, str(library))
    except (OSError, RuntimeError):
        pass
    return function
