"""Where a sweep's chunks of runs execute: processes on this machine, or a Dask cluster.

An executor maps a picklable function over items and yields ``(item, result, exception)``
as each item finishes, in completion order. Both executors call the same function
(:func:`rbstab.sweep.worker.run_chunk`) on the same items, so the result files are the
same bit for bit (up to the ``created`` and ``command_line`` attributes).

- :class:`LocalExecutor`: :class:`concurrent.futures.ProcessPoolExecutor` with the
  ``forkserver`` start method (``spawn`` where that is missing): no worker inherits the
  parent's h5py state or threads. At most ``2 * jobs`` items are in flight. A worker that
  dies (killed, out of memory) fails only the items in flight, as data, and the pool is
  restarted for the rest. Workers whose parent was killed finish the run in progress
  (its file is written) and exit, instead of lingering.
- :class:`DaskExecutor`: a ``distributed.Client`` connected to an existing scheduler;
  the workers return each file's bytes and the parent writes them, so no shared
  filesystem is needed. ``distributed`` is imported only here (``pip install
  "rbstab[dask]"``).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

__all__ = [
    "Executor",
    "LocalExecutor",
    "DaskExecutor",
    "ExecutorError",
    "default_jobs",
    "make_executor",
    "EXECUTORS",
]

#: Executor names accepted by :func:`make_executor` (the CLI's ``--executor``).
EXECUTORS = ("local", "dask")


class ExecutorError(RuntimeError):
    """An executor cannot start: ``distributed`` missing, scheduler unreachable, bad -j."""


def default_jobs() -> int:
    """Number of CPUs this process may use (``os.sched_getaffinity``, else ``os.cpu_count``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


class Executor:
    """Protocol of the sweep executors (a context manager).

    Attributes
    ----------
    name : str
    return_bytes : bool
        True when workers cannot write the sweep's folder and return file bytes instead.
    """

    name = "executor"
    return_bytes = False

    def describe(self) -> str:  # pragma: no cover - overridden
        return self.name

    def plan(self, n_items: int) -> None:
        """Told how many items will come before the first :meth:`imap_unordered`."""

    def parallelism(self) -> int | None:
        """How many items run at once, if known (the runner sizes batched chunks by it)."""
        return None

    def imap_unordered(
        self, fn: Callable[..., Any], items: Iterable[Any], *args: Any
    ) -> Iterator[tuple[Any, Any, BaseException | None]]:  # pragma: no cover - overridden
        """Yield ``(item, fn(item, *args), None)`` or ``(item, None, exception)`` per item."""
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


# -- local processes ------------------------------------------------------------------------

_busy = False


def _parent_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - pid reused by another user's process
        return False
    return True


def _watch_parent(pid: int) -> None:
    while True:
        time.sleep(0.5)
        if not _parent_alive(pid):
            while _busy:  # let the run in progress finish and write its file
                time.sleep(0.05)
            os._exit(0)


def _init_worker(parent_pid: int) -> None:
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True, name="rbstab-parent-watch").start()


def _call(fn: Callable[..., Any], item: Any, *args: Any) -> Any:
    global _busy
    _busy = True
    try:
        return fn(item, *args)
    finally:
        _busy = False


def _warm() -> None:
    """A no-op task: submitting one per worker starts the workers."""


def _mp_context():
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    if method == "forkserver":
        # Import the heavy modules once in the fork server (no effect if it already runs),
        # and load the compiled kernels there (rbstab.engine.preload: ~0.5 s from numba's
        # cache), so that every worker forked from it starts with them. Not scipy: the
        # compiled engine and the post-processing need none of it (its import costs
        # ~0.7 s); the scipy engine imports solve_ivp when a chunk needs it.
        ctx.set_forkserver_preload([
            "rbstab.sweep.worker", "rbstab.simulate", "rbstab.config", "rbstab.io.hdf5", "rbstab.io.chunk",
            "h5py", "rbstab.engine.preload",
        ])
    return ctx


class LocalExecutor(Executor):
    """``jobs`` worker processes on this machine.

    Parameters
    ----------
    jobs : int, optional
        Number of processes, >= 1 (default :func:`default_jobs`).
    max_in_flight : int, optional
        Items submitted ahead (default ``2 * jobs``): bounds memory for large sweeps and
        keeps Ctrl-C responsive.

    Raises
    ------
    ExecutorError
        If ``jobs < 1``.
    """

    name = "local"
    return_bytes = False

    def __init__(self, jobs: int | None = None, *, max_in_flight: int | None = None) -> None:
        jobs = default_jobs() if jobs is None else int(jobs)
        if jobs < 1:
            raise ExecutorError(f"-j/--jobs: found {jobs}; expected a number of processes >= 1")
        self.jobs = jobs
        self.max_in_flight = max_in_flight or 2 * jobs
        self._pool: ProcessPoolExecutor | None = None
        self._workers = jobs
        self._starter: threading.Thread | None = None

    def describe(self) -> str:
        return f"{self._workers} local process{'es' if self._workers != 1 else ''}"

    def parallelism(self) -> int | None:
        return self.jobs

    def plan(self, n_items: int) -> None:
        """Start no more processes than there are items."""
        self._workers = max(1, min(self.jobs, n_items))

    def start(self) -> None:
        """Start the worker processes now, in a background thread, and return at once.

        The fork server imports numpy, h5py and rbstab and the workers start while
        the caller goes on (e.g. validating the sweep's runs), instead of after it.
        """
        if self._pool is not None or self._starter is not None:
            return

        def spawn() -> None:
            pool = self._new_pool()
            for _ in range(self.jobs):
                pool.submit(_warm)
            self._pool = pool

        self._starter = threading.Thread(target=spawn, daemon=True, name="rbstab-pool-start")
        self._starter.start()

    def _join_starter(self) -> None:
        if self._starter is not None:
            self._starter.join()
            self._starter = None

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            max_workers=self._workers,
            mp_context=_mp_context(),
            initializer=_init_worker,
            initargs=(os.getpid(),),
        )

    def imap_unordered(self, fn, items, *args):
        pending = iter(items)
        in_flight: dict = {}
        exhausted = False
        self._join_starter()
        if self._pool is None:
            self._pool = self._new_pool()
        while True:
            while not exhausted and len(in_flight) < self.max_in_flight:
                try:
                    item = next(pending)
                except StopIteration:
                    exhausted = True
                    break
                in_flight[self._pool.submit(_call, fn, item, *args)] = item
            if not in_flight:
                return
            done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
            broken = False
            for future in done:
                item = in_flight.pop(future)
                try:
                    yield item, future.result(), None
                except BrokenProcessPool as exc:
                    broken = True
                    yield item, None, exc
                except Exception as exc:  # pickling problems and the like
                    yield item, None, exc
            if broken:
                # every item in flight died with the pool: report them, start a new pool
                for future, item in list(in_flight.items()):
                    yield item, None, BrokenProcessPool(
                        "a worker process died (killed or crashed) while this run was in flight"
                    )
                in_flight.clear()
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()

    def close(self) -> None:
        self._join_starter()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


# -- Dask -----------------------------------------------------------------------------------


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ExecutorError(
            'the dask executor needs the "distributed" package: pip install "rbstab[dask]" '
            '(or pip install ".[dask]" in a checkout)'
        ) from None
    return distributed


class DaskExecutor(Executor):
    """Runs items on an existing Dask ``distributed`` cluster.

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``.
    connect_timeout : float
        Seconds to wait for the scheduler.
    client : distributed.Client, optional
        Use this client instead of connecting (it is not closed by :meth:`close`).

    Raises
    ------
    ExecutorError
        If ``distributed`` is not installed or the scheduler cannot be reached.
    """

    name = "dask"
    return_bytes = True

    def __init__(self, address: str | None = None, *, connect_timeout: float = 30.0, client=None) -> None:
        self._distributed = _import_distributed()
        self._own_client = client is None
        if client is None:
            if not address:
                raise ExecutorError("the dask executor needs a scheduler address: --scheduler tcp://HOST:PORT")
            try:
                client = self._distributed.Client(address, timeout=connect_timeout, set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise ExecutorError(f"cannot connect to the Dask scheduler at {address}: {exc}") from None
        self.client = client
        self.address = address or getattr(client, "scheduler", None) and client.scheduler.address
        self._futures: list = []

    def describe(self) -> str:
        try:
            info = self.client.scheduler_info()
            workers = info.get("workers", {})
            threads = sum(w.get("nthreads", 1) for w in workers.values())
            return f"Dask scheduler {self.address} ({len(workers)} workers, {threads} threads)"
        except Exception:  # pragma: no cover - informative only
            return f"Dask scheduler {self.address}"

    def plan(self, n_items: int) -> None:
        pass

    def parallelism(self) -> int | None:
        try:
            workers = self.client.scheduler_info().get("workers", {})
            return sum(w.get("nthreads", 1) for w in workers.values()) or None
        except Exception:  # pragma: no cover - a hint only
            return None

    def imap_unordered(self, fn, items, *args):
        distributed = self._distributed
        by_future = {}
        token = uuid.uuid4().hex[:8]
        for i, item in enumerate(items):
            key = f"rbstab-sweep-{token}-{i}"
            future = self.client.submit(fn, item, *args, key=key, pure=False, retries=0)
            by_future[future] = item
        self._futures = list(by_future)
        for future in distributed.as_completed(list(by_future), loop=self.client.loop):
            item = by_future.pop(future)
            try:
                result = future.result()
            except Exception as exc:  # KilledWorker, CommClosedError, ...
                yield item, None, exc
            else:
                yield item, result, None
            finally:
                future.release()

    def close(self) -> None:
        if self._futures:
            try:
                self.client.cancel(self._futures)
            except Exception:  # pragma: no cover - best effort on shutdown
                pass
            self._futures = []
        if self._own_client:
            self.client.close()


def make_executor(name: str = "local", *, jobs: int | None = None, scheduler: str | None = None) -> Executor:
    """An executor by name (``"local"`` or ``"dask"``).

    Raises
    ------
    ExecutorError
        For an unknown name, ``jobs < 1``, or a Dask problem (see :class:`DaskExecutor`).
    """
    if name == "local":
        return LocalExecutor(jobs)
    if name == "dask":
        return DaskExecutor(scheduler)
    raise ExecutorError(f"--executor: found {name!r}; expected one of {', '.join(EXECUTORS)}")
