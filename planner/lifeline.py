"""Pool workers that end with the process that started them.

A worker of a process pool blocks on its task queue or runs a job; when its parent is killed
with SIGKILL nothing tells it, and it lives on (about 385 MB each for the planner). Called in a
worker's initializer, `die_with(pid)` ends the worker within a second of `pid`'s death:
prctl(PR_SET_PDEATHSIG, SIGKILL) for its direct parent (Linux), and a daemon thread that polls
`pid` (also the process that started a forkserver pool, which is not the worker's parent).
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
POLL_SECONDS = 0.5


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else (pid reused): not our parent
        return False
    return True


def die_with(pid: int) -> None:
    """End this process (SIGKILL) when process `pid` is gone."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if not _alive(pid):  # died before this worker got here
        os.kill(os.getpid(), signal.SIGKILL)

    def watch() -> None:
        while _alive(pid):
            time.sleep(POLL_SECONDS)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name=f"die-with-{pid}", daemon=True).start()
