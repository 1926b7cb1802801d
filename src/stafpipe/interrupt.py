"""Ctrl-C and SIGTERM as a request to stop at the next boundary (an episode's step, an item of a stage's progress
loop), not as an exception raised wherever the signal lands: raised inside a finalizer (pymunk's cffi callbacks) a
KeyboardInterrupt is printed and ignored, and the run goes on. A second signal stops at once."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator
from types import FrameType

INTERRUPTED = 130
"""The exit code of a stage stopped by Ctrl-C or SIGTERM (128 + SIGINT, the shell's convention)."""

_requested = {"signal": 0}


def _request(signum: int, frame: FrameType | None) -> None:
    if _requested["signal"]:
        raise KeyboardInterrupt  # a second Ctrl-C: the user does not want to wait
    _requested["signal"] = signum


def check() -> None:
    """Raise KeyboardInterrupt here, in plain code, if a stop was requested."""
    if _requested["signal"]:
        raise KeyboardInterrupt


@contextlib.contextmanager
def stop_at_boundaries() -> Iterator[None]:
    """While inside, SIGINT and SIGTERM request a stop that `check` raises; the handlers before are restored after.
    Outside the main thread (a sweep's worker) nothing changes."""
    _requested["signal"] = 0
    try:
        before = {s: signal.signal(s, _request) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)
        _requested["signal"] = 0
