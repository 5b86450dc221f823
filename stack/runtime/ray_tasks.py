"""Ray Core behind `--ray`: connect once (a local instance started for the run, `auto` for the
cluster `ray start` made, or HOST:PORT), then one task per work item. Ray is an optional extra and
is imported only here, when a command asks for it. Workers import this package by name: on a
cluster, drivestack must be installed on every node. Each task carries this process's import path
(`sys.path`), and the worker appends the entries it lacks before the task runs: a plug-in
(docs/plugins.md) the command imported, from wherever it did, imports on the workers as it does in
`--jobs` processes, on every node where the same folders exist."""

from __future__ import annotations

import logging
import os
import re
import socket
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from types import ModuleType
from typing import Any, TypeVar

from stack.runtime.interrupts import deferred
from stack.runtime.machine import usable_cpus
from stack.runtime.watchdog import watch_descendants

Item = TypeVar("Item")
Result = TypeVar("Result")

INSTALL = "pip install 'drivestack[ray]'"
LOCAL = "local"
ADDRESS = re.compile(r"(?:ray://)?(?P<host>[\w.-]+|\[[0-9a-fA-F:]+\]):(?P<port>\d{1,5})")
AUTH_HINT = "a cluster with token authentication needs RAY_AUTH_MODE=token and its RAY_AUTH_TOKEN here"
PROBE_TIMEOUT_S = 3.0
"""How long an address may take to accept a TCP connection before it counts as unreachable [s]."""


class RayUnavailable(ValueError):
    """Ray cannot run the work: not installed, or no cluster at the address; one line for the user."""


QUIET = {"RAY_DISABLE_FAILURE_SIGNAL_HANDLER": "1", "RAY_IGNORE_UNHANDLED_ERRORS": "1"}
"""Set before Ray is imported (unless already set): Ray's C++ core installs no crash handler in this
process, which would take SIGTERM over from the command (a crash report and SIGABRT instead of the
finished work kept and exit 130), and Ray logs no traceback for the failed tasks whose results the
command no longer reads (it reports the first failure in one line and cancels the rest)."""


def ray_module() -> ModuleType:
    """The `ray` package, or RayUnavailable saying how to install it."""
    for name, value in QUIET.items():
        os.environ.setdefault(name, value)
    try:
        import ray
    except ImportError:
        raise RayUnavailable(f"--ray and sweep need Ray, which is not installed: {INSTALL}") from None
    return ray


def check_address(address: str) -> None:
    """Refuse, in one line and within `PROBE_TIMEOUT_S`, an address that is neither `local`, `auto`
    nor a HOST:PORT accepting connections (Ray itself would retry for minutes). `auto` is checked
    where it points: the cluster `ray start` last recorded on this machine, or RAY_ADDRESS."""
    if address == LOCAL:
        return
    target = started_cluster() if address == "auto" else address
    match = ADDRESS.fullmatch(target)
    if match is None:
        raise RayUnavailable(
            f"--ray: expected local, auto or HOST:PORT (e.g. 10.0.0.5:6379), got {address!r}"
        )
    host, port = match["host"].strip("[]"), int(match["port"])
    try:
        speaks = speaks_grpc(host, port)
    except OSError as error:
        reason = error.strerror or type(error).__name__
        raise RayUnavailable(f"--ray {address}: no Ray cluster reachable at {target} ({reason})") from None
    if not speaks:
        raise RayUnavailable(
            f"--ray {address}: {target} answers, but not as a Ray cluster (no gRPC); check the port"
        )
    if why := not_a_gcs(target):
        raise RayUnavailable(f"--ray {address}: {target} answers gRPC, but not as a Ray cluster ({why})")


def not_a_gcs(target: str) -> str | None:
    """Why the gRPC server at `target` is not a Ray cluster's GCS (the first line of the error its
    client raised at once: a proxy or another service answers 404 or UNIMPLEMENTED), or None
    when it is, or when it refuses only for authentication (`ray.init` then says so). Without
    this `ray.init` retries such a server for ~20 s before failing with a hint about tokens."""
    from ray._raylet import GcsClient  # type: ignore[attr-defined]

    try:
        with _stderr_silenced():
            GcsClient(address=target)
    except Exception as error:  # noqa: BLE001 - Ray raises its own RpcError and others
        message = (str(error).splitlines() or [type(error).__name__])[0][:120]
        return None if "auth" in message.lower() else message
    return None


HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
"""What an HTTP/2 client sends first: the connection preface and an empty SETTINGS frame."""
SETTINGS_FRAME = 4
"""HTTP/2 frame type of SETTINGS, which a server sends first (RFC 9113, 3.4)."""


def speaks_grpc(host: str, port: int) -> bool:
    """Whether `host:port` answers the HTTP/2 preface with a SETTINGS frame within
    `PROBE_TIMEOUT_S`, as the gRPC servers of Ray (GCS and Ray Client) do; OSError when it does
    not accept the connection."""
    with socket.create_connection((host, port), timeout=PROBE_TIMEOUT_S) as connection:
        try:
            connection.sendall(HTTP2_PREFACE)
            header = b""
            while len(header) < 9 and (chunk := connection.recv(9 - len(header))):
                header += chunk
        except OSError:
            return False
    return len(header) == 9 and header[3] == SETTINGS_FRAME


def started_cluster() -> str:
    """The HOST:PORT `--ray auto` means, as Ray resolves it; RayUnavailable when there is none."""
    from ray._private.services import canonicalize_bootstrap_address

    try:
        found = canonicalize_bootstrap_address("auto")
    except (ConnectionError, ValueError):
        found = None
    if found is None:
        raise RayUnavailable(
            "--ray auto: no Ray cluster started on this machine (ray start --head) nor RAY_ADDRESS"
        )
    return found


def connect(address: str) -> ModuleType:
    """Ray, initialised for `address` (see module doc); an instance already initialised in this
    process is reused. Raises RayUnavailable before any work. A stop while Ray starts waits for
    its start (`_no_ray_sigterm_handler`), then raises KeyboardInterrupt."""
    ray = ray_module()
    check_address(address)
    if ray.is_initialized():
        return ray
    options: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": False,
        "logging_level": logging.ERROR,
    }
    if address == LOCAL:
        options["num_cpus"] = usable_cpus()
        watch_descendants()
    else:
        options["address"] = address
    try:
        with _stderr_silenced(), deferred(), _no_ray_sigterm_handler(ray):
            ray.init(**options)
    except (
        ConnectionError,
        TimeoutError,
        getattr(ray.exceptions, "AuthenticationError", ConnectionError),
    ) as error:
        message = str(error).splitlines()[0][:160]
        hint = "" if address == LOCAL else f"; {AUTH_HINT}"
        raise RayUnavailable(f"--ray {address}: {message}{hint}") from None
    return ray


@contextmanager
def _no_ray_sigterm_handler(ray: ModuleType) -> Iterator[None]:
    """Inside the block Ray installs no SIGTERM handler: `ray.init` installs two, which exit (with
    code 15, or 1 after killing Ray's processes) wherever the signal finds the command, and a start
    cut short leaves Ray's core worker running, which crashes the exit. So the command's handlers
    stay (`stack.runtime.interrupts`) and Ray's own exit handler ends its processes."""
    utils = ray._private.utils
    install = utils.set_sigterm_handler
    utils.set_sigterm_handler = lambda handler: None
    try:
        yield
    finally:
        utils.set_sigterm_handler = install


@contextmanager
def _stderr_silenced() -> Iterator[None]:
    """File descriptor 2 to /dev/null inside the block: Ray's C++ core logs every connection retry
    there for up to a minute, which would bury the one-line error."""
    sys.stderr.flush()
    saved = os.dup(2)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def worker_call(task: Callable[[Item], Result], item: Item, path: Sequence[str]) -> Result:
    """The Ray task: `task` (shared once through the object store) on one item, after appending to
    this worker's `sys.path` the entries of the driver's `path` it lacks (`import_path`). Ray gives
    its workers the driver's working directory and, on this machine, its environment (PYTHONPATH),
    but not folders a program added to sys.path; the entries a worker has keep their precedence."""
    extend_path(path)
    return task(item)


def extend_path(path: Sequence[str]) -> None:
    """Append to this worker's `sys.path` the entries of the driver's `path` it lacks, in order."""
    sys.path.extend([entry for entry in dict.fromkeys(path) if entry not in sys.path])


def import_path() -> list[str]:
    """This process's `sys.path`, each entry absolute (`""`, the working directory, included)."""
    return [os.path.abspath(entry) for entry in sys.path]


def ray_completed(
    task: Callable[[Item], Result], items: Sequence[Item], address: str
) -> Iterator[tuple[int, Result]]:
    """(index, task(item)) as the Ray tasks finish, one CPU each; the tasks not finished when the
    iterator is closed (Ctrl-C) are cancelled."""
    ray = connect(address)
    remote = ray.remote(num_cpus=1, max_retries=0)(worker_call)
    shared, path = ray.put(task), ray.put(import_path())
    indices = {remote.remote(shared, item, path): index for index, item in enumerate(items)}
    pending = list(indices)
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield indices[ref], task_result(ray, ref)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def task_result(ray: ModuleType, ref: Any) -> Any:
    """The result of the finished task `ref`; the exception it raised as itself, as from a `--jobs`
    process (a plug-in that fails on the worker is then one line: `PluginError`). Ray's
    RayTaskError, whose message is the worker's traceback, is its cause (`--debug` shows it)."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as error:
        cause = error.cause
        if isinstance(cause, Exception) and not isinstance(cause, ray.exceptions.RayError):
            raise cause from error
        raise
