"""`drivestack view`: opens rerun's viewer on recordings (`--record`): one `.rrd` file, every
recording of a results folder, or with `--worst` the folder's worst episode by its own ranking (a
collision, else the lowest mean speed, read from its episodes.csv). `--web` serves rerun's web
viewer on this machine only (127.0.0.1) and prints its address.

The viewer is rerun's own program (shipped with rerun-sdk), started with its anonymous usage data
off: rerun 0.41 reads no switch for it but `CI` (`re_analytics` skips analytics when it is set), so
the viewer's environment has it and drops `FORCE_RERUN_ANALYTICS`.
"""

from __future__ import annotations

import contextlib
import csv
import importlib.util
import os
import shlex
import signal
import socket
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

from stack.loop.recording import RECORDINGS, agent_folders

LOOPBACK = "127.0.0.1"
RRD_MAGIC = (b"RRF0", b"RRF1", b"RRF2")
"""The first bytes of a rerun recording file (its stream header), by format version."""
MAX_RECORDING_BYTES = 4 * 2**30
"""Most bytes of recordings the viewer is given at once (it holds them in memory, and more)."""
MAX_RECORDINGS = 1000
"""Most recordings the viewer is given at once (their paths go on its command line)."""


def shell_words(*words: str | Path) -> str:
    """`words` as one shell command line, each quoted where the shell would split or expand it."""
    return " ".join(shlex.quote(str(word)) for word in words)


def view_command_line(*arguments: str | Path) -> str:
    """The `drivestack view` command to paste into a shell, with `arguments` quoted."""
    return shell_words("drivestack", "view", *arguments)


def checked_recordings(paths: list[Path], where: Path) -> list[Path]:
    """`paths`, each a regular file that starts as a rerun recording does, at most
    `MAX_RECORDINGS` of them and `MAX_RECORDING_BYTES` in all; ValueError (one line) otherwise,
    before the viewer starts (it would serve an empty viewer or read a huge file whole)."""
    if len(paths) > MAX_RECORDINGS:
        raise ValueError(
            f"{where}: holds {len(paths)} recordings; the viewer opens at most {MAX_RECORDINGS} at once: "
            "open a sub-folder, one file, or --worst"
        )
    total = 0
    for path in paths:
        try:
            found = path.stat()
            if not stat.S_ISREG(found.st_mode):  # a pipe would block the read below
                raise ValueError(f"{path}: not a regular file; expected a rerun recording (.rrd)")
            total += found.st_size
            with path.open("rb") as handle:
                header = handle.read(len(RRD_MAGIC[0]))
        except OSError as error:
            raise ValueError(f"{path}: cannot be read ({error.strerror or error})") from None
        if header not in RRD_MAGIC:
            raise ValueError(f"{path}: not a rerun recording (it does not start with rerun's header)")
        if total > MAX_RECORDING_BYTES:
            raise ValueError(
                f"{where}: recordings of more than {MAX_RECORDING_BYTES / 2**30:.0f} GB; "
                "the viewer holds them in memory: open fewer"
            )
    return paths


def display_problem(web: bool) -> str | None:
    """Why the native viewer cannot open a window here (one line suggesting `--web`), or None."""
    if web or not sys.platform.startswith("linux"):
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    return "view: no display to open the viewer on (DISPLAY is not set); --web serves it to a browser instead"


def worst_episode(folder: Path, agent: str | None = None) -> Path:
    """The recording of the worst episode of the results folder `folder` (of `agent` in a
    comparison): a collision first (at fault before not, then the earliest episode), else the
    lowest mean speed. ValueError (one line) for a folder without episodes.csv or recordings."""
    table = folder / "episodes.csv"
    if not table.is_file():
        raise ValueError(f"{folder}: not a results folder of drivestack run or compare (no episodes.csv)")
    with table.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    needed = {"episode", "crashed", "mean_speed"}
    if not rows or not needed <= set(rows[0]):
        raise ValueError(f"{table}: expected rows with the columns {', '.join(sorted(needed))}")
    recordings = folder / RECORDINGS
    if "agent" in rows[0]:
        folders = agent_folders(list(dict.fromkeys(row["agent"] for row in rows)))
        if agent is not None:
            if agent not in folders and agent not in folders.values():
                raise ValueError(f"--agent: expected one of {', '.join(folders.values())}, got {agent!r}")
            rows = [row for row in rows if agent in (row["agent"], folders[row["agent"]])]
    elif agent is not None:
        raise ValueError(f"--agent: {folder} holds one agent's run (it chooses among a comparison's agents)")
    try:
        ranked = sorted(
            rows,
            key=lambda row: (
                row["crashed"] != "True",
                row.get("at_fault_collision") != "True",
                float(row["mean_speed"]) if row["crashed"] != "True" else 0.0,
                int(row["episode"]),
            ),
        )
    except ValueError:
        raise ValueError(f"{table}: expected numbers in episode and mean_speed") from None
    for row in ranked:
        where = recordings / folders[row["agent"]] if "agent" in row else recordings
        path = where / f"episode-{int(row['episode']):04d}.rrd"
        if path.is_file():
            return path
    raise ValueError(f"{folder}: no recording of its episodes (run it with --record)")


def recordings_in(path: Path, worst: bool, agent: str | None) -> list[Path]:
    """The recordings `drivestack view PATH` opens; ValueError (one line) when there are none."""
    if worst:
        if not path.is_dir():
            raise ValueError(f"--worst: expected a results folder, got {path}")
        return checked_recordings([worst_episode(path, agent)], path)
    if agent is not None:
        raise ValueError("--agent: chooses whose worst episode --worst opens; add --worst")
    if path.is_file():
        if path.suffix != ".rrd":
            raise ValueError(f"{path}: expected a rerun recording (.rrd) or a results folder")
        return checked_recordings([path], path)
    if not path.is_dir():
        if path.exists():
            raise ValueError(
                f"{path}: not a regular file; expected a rerun recording (.rrd) or a results folder"
            )
        raise ValueError(f"{path}: no such file or folder")
    found = sorted((path / RECORDINGS).rglob("*.rrd")) or sorted(path.glob("*.rrd"))
    if not found:
        raise ValueError(f"{path}: holds no recordings (.rrd; run with --record)")
    return checked_recordings(found, path)


def rerun_program() -> Path:
    """rerun's viewer program, shipped in rerun-sdk's `rerun_cli` package."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is None or not spec.submodule_search_locations:
        raise ValueError("rerun's viewer is not installed: pip install 'drivestack[viz]'")
    program = Path(next(iter(spec.submodule_search_locations))) / (
        "rerun.exe" if os.name == "nt" else "rerun"
    )
    if not program.is_file():
        raise ValueError(
            f"rerun's viewer program is missing ({program}): pip install --force-reinstall rerun-sdk"
        )
    return program


def free_port() -> int:
    """A TCP port free on the loopback interface now."""
    with socket.socket() as probe:
        probe.bind((LOOPBACK, 0))
        return int(probe.getsockname()[1])


def viewer_environment() -> dict[str, str]:
    """This process's environment with rerun's analytics off (see the module docstring)."""
    environment = {key: value for key, value in os.environ.items() if key != "FORCE_RERUN_ANALYTICS"}
    return environment | {"CI": "1"}


def viewer_command(recordings: list[Path], web: bool) -> tuple[list[str], str | None]:
    """The viewer's command line and, with `web`, the address to open in a browser."""
    program = str(rerun_program())
    files = [str(path) for path in recordings]
    if not web:
        return [program, "--bind", LOOPBACK, *files], None
    grpc, http = free_port(), free_port()
    command = [
        program,
        "--web-viewer",
        "--bind",
        LOOPBACK,
        "--port",
        str(grpc),
        "--web-viewer-port",
        str(http),
    ]
    address = f"http://{LOOPBACK}:{http}/?url=rerun%2Bhttp%3A%2F%2F{LOOPBACK}%3A{grpc}%2Fproxy"
    return [*command, *files], address


def _end_with_parent() -> None:  # pragma: no cover - runs in the child before exec
    """The viewer ends when drivestack does, even killed (Linux: the kernel tells it)."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)


def view(recordings: list[Path], web: bool) -> int:
    """Run the viewer on `recordings` until it closes or Ctrl-C; its exit code (0 on Ctrl-C). The
    native viewer's log goes to a file: when it fails (no window can open), one line names the
    file and suggests `--web` instead of rerun's raw log."""
    command, address = viewer_command(recordings, web)
    shown = ", ".join(str(path) for path in recordings[:3]) + (" ..." if len(recordings) > 3 else "")
    print(f"opening {len(recordings)} recording(s): {shown}", flush=True)
    log = (
        None
        if web
        else tempfile.NamedTemporaryFile("wb", prefix="drivestack-viewer-", suffix=".log", delete=False)
    )
    with log or contextlib.nullcontext():
        process = subprocess.Popen(command, env=viewer_environment(), preexec_fn=_end_with_parent, stderr=log)
        if address is not None:
            print(f"web viewer (this machine only): {address}", flush=True)
            print("Ctrl-C stops it", flush=True)
        try:
            code = process.wait()
        except KeyboardInterrupt:
            stop(process)
            return 0
    if code and log is not None:
        print(
            f"error: rerun's viewer ended with exit code {code} (its log: {log.name}); "
            "where no window can open, --web serves it to a browser",
            file=sys.stderr,
        )
    elif log is not None:
        Path(log.name).unlink(missing_ok=True)
    return code


def stop(process: subprocess.Popen, grace_s: float = 5.0) -> None:
    """End `process`: asked to (SIGTERM), then killed if it is still running after `grace_s` [s]."""
    process.terminate()
    try:
        process.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
