"""Compiled (numba) functions that Python calls, and that a stop (Ctrl-C, SIGTERM) interrupts as it
interrupts Python code."""

from __future__ import annotations

from collections.abc import Callable
from functools import update_wrapper
from typing import Any

from numba import njit
from numba.extending import register_jitable

from records import clip as _clip

clip = register_jitable(_clip)
"""`records.clip` (numpy's rule for one number), which per-tick laws call as plain Python for one
world and numba compiles where a batch kernel calls such a law."""


class Kernel:
    """`function` compiled by numba (cached on disk, without the GIL), called from Python. numba's
    dispatcher runs Python code around a call; a KeyboardInterrupt that the stop's signal handler
    raises there comes out of the call as a SystemError ("returned a result with an exception set")
    caused by it (through another such SystemError when it lands in numba's own unpickling), which
    no `except KeyboardInterrupt` sees: the call raises the KeyboardInterrupt itself instead.
    Kernels called only by other kernels stay plain `njit` functions."""

    def __init__(self, function: Callable[..., Any]) -> None:
        self.compiled = njit(cache=True, nogil=True)(function)
        update_wrapper(self, function)

    def __call__(self, *args: Any) -> Any:
        try:
            return self.compiled(*args)
        except SystemError as error:
            cause = error.__cause__
            while cause is not None and not isinstance(cause, KeyboardInterrupt):
                cause = cause.__cause__
            if cause is None:
                raise
            raise cause from None
