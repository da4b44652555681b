"""Quick exit of the sweep workers' fork server.

:func:`rbstab.sweep.executors._mp_context` has the fork server import this module first.
The fork server lives until its parent exits and then leaves through Python's teardown,
which with numpy, h5py and pydantic loaded takes ~0.1 s, during which it still holds the
parent's stdout and stderr: a caller that waits for the output to end (``subprocess.run``
with ``capture_output``, a pipe) waits for that too. Imported there, this module
registers an exit hook that ends the process at once (the fork server keeps no state:
the workers, forked from it, have exited by then and write their own files). Imported
anywhere else it does nothing.
"""

from __future__ import annotations

import atexit
import os
import sys


def _exit_now() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed pipe: nothing to flush
            pass
    os._exit(0)


def in_fork_server() -> bool:
    """Whether this import runs inside ``multiprocessing.forkserver.main`` (the preload)."""
    forkserver = sys.modules.get("multiprocessing.forkserver")
    if forkserver is None:
        return False
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code is forkserver.main.__code__:
            return True
        frame = frame.f_back
    return False


if in_fork_server():
    atexit.register(_exit_now)
