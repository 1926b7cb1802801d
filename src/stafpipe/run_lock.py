"""One run per run directory: a lock file that a second run into the same directory finds and is refused by.

Two runs writing one directory corrupt each other (an MCAP log overwritten under a finished `stage.json`, a log
holding the other run's episode). The lock holds `host pid`; a lock whose process is gone on this host is stale
and is taken over (a killed run must not block its own resume); one from another host is respected, since its
process cannot be checked from here.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

from stafpipe.errors import StafpipeError

LOCK = ".stafpipe.lock"


class RunDirInUse(StafpipeError):
    """Another live run holds the run directory."""


def _alive(holder: str) -> bool:
    host, _, pid = holder.partition(" ")
    if host != socket.gethostname() or not pid.isdigit():
        return True  # cannot check another host's process: respect the lock
    try:
        os.kill(int(pid), 0)  # signal 0: only asks whether the process exists (PermissionError: it does)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


class RunDirLock:
    def __init__(self, out_dir: Path) -> None:
        self.path = Path(out_dir) / LOCK
        self.held = False

    def acquire(self) -> None:
        me = f"{socket.gethostname()} {os.getpid()}"
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                try:
                    holder = self.path.read_text().strip()
                except OSError:
                    continue  # released meanwhile: try again
                if holder == me or not _alive(holder):
                    self.path.unlink(missing_ok=True)  # our own leftover, or a killed run's: stale
                    continue
                raise RunDirInUse(
                    f"{self.path.parent}: in use by another run ({holder}); wait for it to finish or "
                    f"choose another hydra.run.dir (if no such run is alive, delete {self.path})"
                ) from None
            with os.fdopen(fd, "w") as f:
                f.write(me)
            self.held = True
            return
        raise RunDirInUse(f"{self.path.parent}: could not take the run lock {self.path}")

    def release(self) -> None:
        if self.held:
            self.path.unlink(missing_ok=True)
            self.held = False
