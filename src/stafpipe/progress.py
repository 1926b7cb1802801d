"""Progress of long loops: a tqdm bar on a terminal; without one (a log file, CI, SLURM) a log line at least every
`EVERY` seconds with what is done, the rate and the time left, also while one slow item (an episode, an imitation
round) is still running, so a long stage is never silent."""

from __future__ import annotations

import logging
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

from stafpipe.interrupt import check as check_interrupt

T = TypeVar("T")
EVERY = 10.0
"""Seconds between progress lines when there is no terminal."""
log = logging.getLogger("stafpipe.progress")


def _clock(seconds: float) -> str:
    minutes, sec = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{sec:02d}" if hours else f"{minutes}:{sec:02d}"


class _Heartbeat(threading.Thread):
    """Logs `desc: done/total unit, rate, elapsed, ETA` every EVERY seconds until stopped, then once more."""

    def __init__(self, desc: str, unit: str, total: int, initial: int) -> None:
        super().__init__(daemon=True)
        self.desc, self.unit, self.total, self.initial = desc, unit, total, initial
        self.done = initial
        self.notes = ""
        self.began = time.perf_counter()
        self._stop_event = threading.Event()

    def line(self) -> str:
        elapsed = time.perf_counter() - self.began
        made = self.done - self.initial
        rate = made / elapsed if elapsed > 0 else 0.0
        eta = f", ETA {_clock((self.total - self.done) / rate)}" if rate > 0 and self.done < self.total else ""
        return (
            f"{self.desc}: {self.done}/{self.total} {self.unit}s, {rate:.2f} {self.unit}s/s, "
            f"elapsed {_clock(elapsed)}{eta}" + (f" ({self.notes})" if self.notes else "")
        )

    def run(self) -> None:
        while not self._stop_event.wait(EVERY):
            log.info(self.line())

    def stop(self) -> None:
        self._stop_event.set()
        self.join()
        log.info(self.line())


class progress(Iterable[T]):
    """Iterate `items` showing progress: tqdm on a terminal, periodic log lines otherwise; `set_postfix` adds
    key=value notes (the latest training success rate, ...) to either. `size(item)`: how many units an item is (a
    batch of episodes counts its episodes); 1 by default."""

    def __init__(
        self,
        items: Iterable[T],
        desc: str,
        unit: str,
        total: int | None = None,
        initial: int = 0,
        size: Callable[[T], int] | None = None,
    ) -> None:
        self.items, self.desc, self.unit, self.initial = items, desc, unit, initial
        self.size = size or (lambda _item: 1)
        self.total = initial + len(items) if total is None else total  # type: ignore[arg-type]
        self._bar: tqdm | None = None
        self._beat: _Heartbeat | None = None

    def set_postfix(self, **notes: str) -> None:
        if self._bar is not None:
            self._bar.set_postfix(**notes)
        if self._beat is not None:
            self._beat.notes = ", ".join(f"{k}={v}" for k, v in notes.items())

    def __iter__(self) -> Iterator[T]:
        if sys.stderr.isatty():
            self._bar = tqdm(desc=self.desc, unit=self.unit, total=self.total, initial=self.initial)
            try:
                for item in self.items:
                    check_interrupt()
                    yield item
                    self._bar.update(self.size(item))
            finally:
                self._bar.close()
            return
        self._beat = _Heartbeat(self.desc, self.unit, self.total, self.initial)
        self._beat.start()
        try:
            for item in self.items:
                check_interrupt()
                yield item
                self._beat.done += self.size(item)
        finally:
            self._beat.stop()
