"""Where a sweep's chunks of runs execute: processes on this machine, or a Dask cluster.

An executor maps a picklable function over items and yields ``(item, result, exception)``
as each item finishes, in completion order. Both executors call the same function
(:func:`rbstab.sweep.worker.run_chunk`) on the same items, so the result files are the
same bit for bit (up to the ``created`` and ``command_line`` attributes).

- :class:`LocalExecutor`: :class:`concurrent.futures.ProcessPoolExecutor` with the
  ``forkserver`` start method (``spawn`` where that is missing): no worker inherits the
  parent's h5py state or threads. At most ``2 * jobs`` items are in flight, and processes
  start as items need them: never more than the items (chunks), whatever ``jobs``. A
  worker that dies (killed, out of memory) fails only the items in flight, as data, and
  the pool is restarted for the rest. A pool that dies before finishing any item has
  its items taken once more by the next; if that one dies too, the workers cannot run
  at all and :class:`ExecutorError` says so (the usual cause: a script that calls
  ``rbstab.sweep_dataset`` without the ``__main__`` guard, which every new worker runs again,
  :func:`_refuse_in_bootstrap`). Each worker holds the read end of a pipe whose
  write end only the parent holds: when the parent is gone (killed, even while it is a
  zombie nobody reaped) the pipe reads end-of-file, and the worker finishes the run in
  progress (its file is written) and exits, instead of lingering. :meth:`abort` (on
  Ctrl-C or SIGTERM) ends the workers at once, so that nothing is written after it.
- :class:`DaskExecutor`: a ``distributed.Client`` connected to an existing scheduler;
  the workers return each file's bytes and the parent writes them, so no shared
  filesystem is needed. ``distributed`` is imported only here (``pip install
  "rbstab[dask]"``). Connecting gives up after :data:`DASK_CONNECT_TIMEOUT` seconds
  (``rbstab sweep --connect-timeout``) with a message naming the address, whatever
  answers there (nothing, an HTTP server, a wrong scheme), and a sweep whose scheduler has had no worker for
  :data:`DASK_NO_WORKERS_GRACE` seconds stops with a message instead of waiting forever.
"""

from __future__ import annotations

import ast
import multiprocessing
import os
import socket
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import forkserver
from typing import Any
from urllib.parse import urlsplit

__all__ = [
    "Executor",
    "LocalExecutor",
    "ThreadExecutor",
    "DaskExecutor",
    "ExecutorError",
    "default_jobs",
    "make_executor",
    "refuse_at_script_top_level",
    "EXECUTORS",
]

#: Executor names accepted by :func:`make_executor` (the CLI's ``--executor``).
EXECUTORS = ("local", "dask")
#: Seconds to wait for a Dask scheduler to answer.
DASK_CONNECT_TIMEOUT = 5.0
#: Seconds a sweep waits on a Dask scheduler without any worker before it stops.
DASK_NO_WORKERS_GRACE = 30.0


class ExecutorError(RuntimeError):
    """An executor cannot start or run: ``distributed`` missing, scheduler unreachable, bad -j, workers dying."""


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

    def abort(self) -> None:
        """Stop at once (Ctrl-C, SIGTERM): items in flight are dropped, nothing is written
        after this returns. Default: :meth:`close`."""
        self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


# -- local processes ------------------------------------------------------------------------

_idle = threading.Event()
_idle.set()


def _watch_parent(lifeline) -> None:
    """Exit when the parent is gone: ``lifeline`` (the read end of a pipe only the parent
    can write) reads end-of-file once every copy of the write end is closed, which the
    kernel does when the parent exits, reaped or not (``os.kill(ppid, 0)`` succeeds on a
    zombie, and with the forkserver the parent is not even this process's parent)."""
    try:
        while True:
            lifeline.recv_bytes()  # the parent never writes: returns only by raising
    except (EOFError, OSError):
        pass
    _idle.wait()  # let the run in progress finish and write its file
    os._exit(0)


def _init_worker(lifeline) -> None:
    threading.Thread(target=_watch_parent, args=(lifeline,), daemon=True, name="rbstab-parent-watch").start()


def _call(fn: Callable[..., Any], item: Any, *args: Any) -> Any:
    _idle.clear()
    try:
        return fn(item, *args)
    finally:
        _idle.set()


def _refuse_in_bootstrap(task: str = "a sweep") -> None:
    """Exit with one line if this process is a new worker still importing the parent's script.

    A worker started with ``forkserver`` or ``spawn`` first runs the parent's ``__main__``
    script again (as ``__mp_main__``, the standard library's ``prepare`` step); a script
    that starts ``task`` (a sweep, a report) at its top level, outside
    ``if __name__ == "__main__":``, would start another in every worker. ``multiprocessing`` marks that phase with the
    current process's ``_inheriting`` flag (what its own check,
    ``multiprocessing.spawn._check_not_importing_main``, reads).

    Raises
    ------
    SystemExit
        (code 1) in such a worker, after one line on stderr naming the script; the parent
        sees its workers die and stops (:meth:`LocalExecutor.imap_unordered`).
    """
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        script = sys.argv[0] if sys.argv and sys.argv[0] else "the main script"
        sys.stderr.write(
            f"rbstab: {script} starts {task} at its top level, and every worker process runs it again "
            "before it can take work; put the call under if __name__ == \"__main__\": (as for any use of "
            "local worker processes)\n")
        sys.stderr.flush()
        raise SystemExit(1)


def _is_main_guard(node) -> bool:
    """Whether an ``ast.If`` tests ``__name__ == "__main__"`` (either way round)."""
    test = node.test
    if not (isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq)):
        return False
    sides = [test.left, test.comparators[0]]
    return (any(isinstance(x, ast.Name) and x.id == "__name__" for x in sides)
            and any(isinstance(x, ast.Constant) and x.value == "__main__" for x in sides))


def _unguarded_top_level_call() -> tuple[str, int, str] | None:
    """``(script, line, called)`` when this call comes from the top level of the main
    script outside ``if __name__ == "__main__":`` (``called``: the function the script's
    line calls); None otherwise (an interactive session, a notebook, ``python -c``, a
    guarded call, a script whose source cannot be read)."""
    main = sys.modules.get("__main__")
    frame, callee = sys._getframe(1), None
    while frame is not None:
        if frame.f_code.co_name == "<module>" and main is not None and frame.f_globals is vars(main):
            break
        callee, frame = frame, frame.f_back
    if frame is None or callee is None:
        return None
    script = frame.f_code.co_filename
    try:
        with open(script, encoding="utf-8") as f:
            tree = ast.parse(f.read())
    except (OSError, SyntaxError, ValueError):
        return None
    line = frame.f_lineno
    for node in tree.body:
        if node.lineno <= line <= (node.end_lineno or node.lineno):
            if isinstance(node, ast.If) and _is_main_guard(node):
                return None
            break
    module = callee.f_globals.get("__name__", "")
    name = callee.f_code.co_name
    called = f"rbstab.{name}" if module.startswith("rbstab") else name
    return script, line, called


def refuse_at_script_top_level(task: str = "a sweep") -> None:
    """Raise :class:`ExecutorError` before anything starts when this call, which starts
    local worker processes, comes from a script's top level without the ``__main__`` guard.

    Every worker started by ``forkserver`` or ``spawn`` runs the main script again (the
    standard library's ``prepare`` step): a call outside ``if __name__ == "__main__":``
    would run the script's prints, file writes and this very call again in every worker.
    The line names the call (the function the script calls), the script and its line.
    """
    found = _unguarded_top_level_call()
    if found is None:
        return
    script, line, called = found
    raise ExecutorError(
        f"{called}() at the top level of {script} (line {line}) starts local worker processes for {task}, "
        "and each worker runs the script again from its top; put the call (and the script's other work) under "
        "if __name__ == \"__main__\": (or pass jobs=1); nothing was run")


def _warm() -> None:
    """A no-op task: submitting one per worker starts the workers."""


#: Modules the fork server imports before it forks the workers: the heavy modules, once, and
#: the compiled kernels (:mod:`rbstab.engine.preload`: ~0.5 s from numba's cache), so that
#: every worker forked from it starts with them. Not scipy: the compiled engine and the
#: post-processing need none of it (its import costs ~0.7 s); the scipy engine imports
#: ``solve_ivp`` when a chunk needs it. Every module a worker of the compiled engine uses
#: (:mod:`rbstab.config` loads its validator lazily). :mod:`rbstab.engine.preload` comes
#: last: it freezes the objects the others made. The standard library ignores a name that
#: fails to import: ``tests/test_layers.py`` imports each.
FORKSERVER_PRELOAD = (
    "rbstab.sweep.worker", "rbstab.sweep.folder", "rbstab.simulator", "rbstab.config.loader",
    "rbstab.io.hdf5", "rbstab.io.chunk", "rbstab.io.integrity", "h5py", "h5netcdf", "rbstab.engine.preload",
)


def _mp_context(preload: tuple[str, ...] = FORKSERVER_PRELOAD):
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    if method == "forkserver":
        ctx.set_forkserver_preload(list(preload))  # no effect if the server already runs
    return ctx


class _LocalWorkers(Executor):
    """``jobs`` workers of this machine (processes or threads), as many started as items."""

    jobs: int
    _workers: int

    def parallelism(self) -> int | None:
        return self.jobs

    def plan(self, n_items: int) -> None:
        """Start no more workers than there are items."""
        self._workers = max(1, min(self.jobs, n_items))


class LocalExecutor(_LocalWorkers):
    """``jobs`` worker processes on this machine.

    Parameters
    ----------
    jobs : int, optional
        Number of processes, >= 1 (default :func:`default_jobs`).
    max_in_flight : int, optional
        Items submitted ahead (default ``2 * jobs``): bounds memory for large sweeps and
        keeps Ctrl-C responsive.
    preload : tuple of str, optional
        Modules the fork server imports before it forks the workers (default
        :data:`FORKSERVER_PRELOAD`, what a sweep's workers use); no effect when this
        process's fork server already runs.
    task : str, optional
        What the workers do, as the messages name it (default ``"a sweep"``; the report
        says ``"a report"``).

    Raises
    ------
    ExecutorError
        If ``jobs < 1``.
    """

    name = "local"
    return_bytes = False

    def __init__(self, jobs: int | None = None, *, max_in_flight: int | None = None,
                 preload: tuple[str, ...] = FORKSERVER_PRELOAD, task: str = "a sweep") -> None:
        _refuse_in_bootstrap(task)
        refuse_at_script_top_level(task)
        jobs = default_jobs() if jobs is None else int(jobs)
        if jobs < 1:
            raise ExecutorError(f"-j/--jobs: found {jobs}; expected a number of processes >= 1")
        self.jobs = jobs
        self.max_in_flight = max_in_flight or 2 * jobs
        self.preload = tuple(preload)
        self.task = task
        self._pool: ProcessPoolExecutor | None = None
        self._workers = jobs
        self._starter: threading.Thread | None = None
        # the workers' lifeline: they hold the read end, only this process the write end
        self._lifeline, self._lifeline_w = multiprocessing.Pipe(duplex=False)

    def describe(self) -> str:
        return f"{self._workers} local process{'es' if self._workers != 1 else ''}"

    def start(self) -> None:
        """Start the fork server now, in a background thread, and return at once.

        The fork server imports numpy, h5py and rbstab and loads the compiled kernels while
        the caller goes on (e.g. validating the sweep's runs), instead of after it; the
        workers fork from it in a few milliseconds when items need them (never more than
        the items in flight). Where there is no fork server (``spawn``), one worker is
        started instead.
        """
        if self._pool is not None or self._starter is not None:
            return

        def spawn() -> None:
            ctx = _mp_context(self.preload)
            pool = self._new_pool()
            if ctx.get_start_method() == "forkserver":
                forkserver.ensure_running()
            else:  # pragma: no cover - platforms without forkserver
                pool.submit(_warm)
            self._pool = pool

        self._starter = threading.Thread(target=spawn, daemon=True, name="rbstab-pool-start")
        self._starter.start()

    def _join_starter(self) -> None:
        if self._starter is not None:
            self._starter.join()
            self._starter = None

    def _new_pool(self) -> ProcessPoolExecutor:
        # processes start on demand (forkserver), one per item in flight at most
        return ProcessPoolExecutor(
            max_workers=self._workers,
            mp_context=_mp_context(self.preload),
            initializer=_init_worker,
            initargs=(self._lifeline,),
        )

    def imap_unordered(self, fn, items, *args):
        """See :meth:`Executor.imap_unordered`.

        A pool that dies (a worker killed or crashed) fails the items in flight, as data,
        and a new pool takes the rest; if it died before finishing any item, the new pool
        takes its items in flight once more instead.

        Raises
        ------
        ExecutorError
            When two pools in a row die before finishing any item (the items not finished
            are not yielded: for a sweep they stay pending).
        """
        pending = iter(items)
        again: list = []  # the items of a pool that died before finishing any, to submit first
        in_flight: dict = {}
        exhausted = False
        self._join_starter()
        if self._pool is None:
            self._pool = self._new_pool()
        finished = False  # whether an item of the current pool finished
        retried = False  # whether the current pool took the items of one that finished none
        while True:
            while len(in_flight) < self.max_in_flight and (again or not exhausted):
                if again:
                    item = again.pop(0)
                else:
                    try:
                        item = next(pending)
                    except StopIteration:
                        exhausted = True
                        break
                in_flight[self._pool.submit(_call, fn, item, *args)] = item
            if not in_flight:
                return
            done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
            broken = []
            for future in done:
                item = in_flight.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:
                    broken.append(item)
                    continue
                except Exception as exc:  # pickling problems and the like
                    result, error = None, exc
                else:
                    error = None
                finished = True
                yield item, result, error
            if broken:
                lost = broken + list(in_flight.values())
                in_flight.clear()
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = None
                if not finished and retried:
                    raise ExecutorError(
                        "the local worker processes died twice in a row before finishing anything (see the "
                        f"messages above); from a Python script, start {self.task} under "
                        "if __name__ == \"__main__\": (each new worker runs the script again)")
                if not finished:
                    again[:0] = lost  # a pool that finished nothing: its items once more
                else:
                    for item in lost:
                        yield item, None, BrokenProcessPool(
                            "a worker process died (killed or crashed) while this run was in flight")
                retried = not finished
                self._pool = self._new_pool()
                finished = False

    def close(self) -> None:
        self._join_starter()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def abort(self) -> None:
        """End the workers now (SIGTERM to each; their partial files are temporaries, which
        the caller removes), then shut the pool down."""
        self._join_starter()
        pool, self._pool = self._pool, None
        if pool is None:
            return
        processes = list((getattr(pool, "_processes", None) or {}).values())
        for process in processes:
            try:
                process.terminate()
            except (OSError, AttributeError):  # pragma: no cover - already gone
                pass
        for process in processes:
            process.join(timeout=5)
        pool.shutdown(wait=True, cancel_futures=True)


# -- local threads --------------------------------------------------------------------------


class ThreadExecutor(_LocalWorkers):
    """``jobs`` threads of this process.

    For work whose time is spent in the compiled engine's kernels, which release the GIL
    (``nogil``): nothing is started, pickled or imported again, so a script needs no
    ``if __name__ == "__main__":`` guard. Python code in ``fn`` still runs one thread at a
    time.

    Parameters
    ----------
    jobs : int, optional
        Number of threads, >= 1 (default :func:`default_jobs`).
    max_in_flight : int, optional
        Items submitted ahead (default ``2 * jobs``).

    Raises
    ------
    ExecutorError
        If ``jobs < 1``.
    """

    name = "threads"
    return_bytes = False

    def __init__(self, jobs: int | None = None, *, max_in_flight: int | None = None) -> None:
        jobs = default_jobs() if jobs is None else int(jobs)
        if jobs < 1:
            raise ExecutorError(f"-j/--jobs: found {jobs}; expected a number of threads >= 1")
        self.jobs = jobs
        self.max_in_flight = max_in_flight or 2 * jobs
        self._workers = jobs
        self._pool: ThreadPoolExecutor | None = None

    def describe(self) -> str:
        return f"{self._workers} thread{'s' if self._workers != 1 else ''}"

    def imap_unordered(self, fn, items, *args):
        """See :meth:`Executor.imap_unordered`."""
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self._workers, thread_name_prefix="rbstab")
        pending = iter(items)
        in_flight: dict = {}
        exhausted = False
        while True:
            while len(in_flight) < self.max_in_flight and not exhausted:
                try:
                    item = next(pending)
                except StopIteration:
                    exhausted = True
                    break
                in_flight[self._pool.submit(fn, item, *args)] = item
            if not in_flight:
                return
            done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
            for future in done:
                item = in_flight.pop(future)
                try:
                    result, error = future.result(), None
                except Exception as exc:
                    result, error = None, exc
                yield item, result, error

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


# -- Dask -----------------------------------------------------------------------------------


def _import_distributed():
    try:
        import distributed  # optional: distributed
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
        Seconds to wait for the scheduler (:data:`DASK_CONNECT_TIMEOUT`).
    client : distributed.Client, optional
        Use this client instead of connecting (it is not closed by :meth:`close`).
    no_workers_grace : float
        Seconds without any worker after which :meth:`imap_unordered` gives up
        (:data:`DASK_NO_WORKERS_GRACE`).

    Raises
    ------
    ExecutorError
        If ``distributed`` is not installed, or no Dask scheduler answers at ``address``
        within ``connect_timeout`` (nothing listens, another protocol answers, a wrong
        scheme): one message naming the address.
    """

    name = "dask"
    return_bytes = True

    def __init__(self, address: str | None = None, *, connect_timeout: float = DASK_CONNECT_TIMEOUT, client=None,
                 no_workers_grace: float = DASK_NO_WORKERS_GRACE) -> None:
        self._distributed = _import_distributed()
        self._own_client = client is None
        self.no_workers_grace = no_workers_grace
        if client is None:
            if not address:
                raise ExecutorError("the dask executor needs a scheduler address: --scheduler tcp://HOST:PORT")
            client = _connect(self._distributed, address, connect_timeout)
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

    def _n_workers(self) -> int | None:
        try:
            return len(self.client.scheduler_info().get("workers", {}))
        except Exception:  # the scheduler itself is gone: as_completed raises soon
            return None

    def imap_unordered(self, fn, items, *args):
        """See :meth:`Executor.imap_unordered`.

        Raises
        ------
        ExecutorError
            When the scheduler has had no worker for ``no_workers_grace`` seconds (all
            died, or none ever came) with items still to do.
        """
        distributed = self._distributed
        by_future = {}
        token = uuid.uuid4().hex[:8]
        for i, item in enumerate(items):
            key = f"rbstab-sweep-{token}-{i}"
            future = self.client.submit(fn, item, *args, key=key, pure=False, retries=0)
            by_future[future] = item
        self._futures = list(by_future)
        pending = distributed.as_completed(list(by_future), loop=self.client.loop)
        idle_since = None
        while not pending.is_empty():
            batch = pending.next_batch(block=False)
            if not batch:
                idle_since = self._check_workers(idle_since)
                time.sleep(0.2)
                continue
            idle_since = None
            for future in batch:
                item = by_future.pop(future)
                try:
                    result = future.result()
                except Exception as exc:  # KilledWorker, CommClosedError, ...
                    yield item, None, exc
                else:
                    yield item, result, None
                finally:
                    future.release()

    def _check_workers(self, idle_since: float | None) -> float | None:
        """Track how long the scheduler has had no worker; raise past the grace period."""
        if self._n_workers() != 0:
            return None
        now = time.monotonic()
        if idle_since is None:
            return now
        if now - idle_since > self.no_workers_grace:
            raise ExecutorError(
                f"no workers left on the Dask scheduler at {self.address}: none for "
                f"{self.no_workers_grace:g} s with runs still to do; start workers (dask worker {self.address}) "
                "and run the same command again to resume"
            )
        return idle_since

    def close(self) -> None:
        if self._futures:
            try:
                self.client.cancel(self._futures)
            except Exception:  # pragma: no cover - best effort on shutdown
                pass
            self._futures = []
        if self._own_client:
            self.client.close()


def _probe_tcp(address: str, timeout: float) -> None:
    """For ``tcp://HOST:PORT``: one plain connection first, so that a refused port or an
    unknown host is reported at once (the client retries those until its timeout)."""
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        return  # malformed: the client says what is wrong
    if parts.scheme != "tcp" or not host or port is None:
        return
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except (ConnectionRefusedError, socket.gaierror, TimeoutError) as exc:
        reason = ("connection refused (no scheduler listens there)" if isinstance(exc, ConnectionRefusedError) else
                  f"no answer within {timeout:g} s (the host is unreachable, or a firewall drops the connection)"
                  if isinstance(exc, TimeoutError) else f"unknown host ({exc.strerror or exc})")
        raise ExecutorError(f"cannot connect to the Dask scheduler at {address}: {reason}") from None
    except OSError:
        return  # another failure: the client's attempt reports it


def _connect(distributed, address: str, timeout: float):
    """A ``distributed.Client`` of ``address``, or ExecutorError within ``timeout`` s.

    ``Client(timeout=...)`` bounds the TCP connection only: a server of another protocol
    (an HTTP dashboard) accepts it and never answers the handshake, so the client is made
    in a daemon thread that is abandoned past the deadline. The probe's time counts
    against the same deadline.
    """
    hint = "a Dask scheduler address is tcp://HOST:PORT (port 8786 by default, not the dashboard's http port)"
    deadline = time.monotonic() + timeout
    _probe_tcp(address, timeout)
    left = max(deadline - time.monotonic(), 0.1)
    box: dict = {}

    def connect() -> None:
        try:
            box["client"] = distributed.Client(address, timeout=left, set_as_default=False)
        except BaseException as exc:  # reported below
            box["error"] = exc

    thread = threading.Thread(target=connect, daemon=True, name="rbstab-dask-connect")
    thread.start()
    thread.join(left)
    if "client" in box:
        return box["client"]
    error = box.get("error")
    if error is None:
        raise ExecutorError(f"cannot connect to the Dask scheduler at {address}: no Dask scheduler answered "
                            f"within {timeout:g} s ({hint})")
    if isinstance(error, (ValueError, TypeError)):  # an unknown scheme, a malformed address
        raise ExecutorError(f"cannot connect to the Dask scheduler at {address}: not a valid address ({error}); "
                            f"{hint}")
    raise ExecutorError(f"cannot connect to the Dask scheduler at {address}: {error}")


def make_executor(name: str = "local", *, jobs: int | None = None, scheduler: str | None = None,
                  connect_timeout: float = DASK_CONNECT_TIMEOUT) -> Executor:
    """An executor by name (``"local"`` or ``"dask"``); ``connect_timeout`` [s] bounds the
    wait for the Dask scheduler (``rbstab sweep --connect-timeout``).

    Raises
    ------
    ExecutorError
        For an unknown name, ``jobs < 1``, or a Dask problem (see :class:`DaskExecutor`).
    """
    if name == "local":
        return LocalExecutor(jobs)
    if name == "dask":
        return DaskExecutor(scheduler, connect_timeout=connect_timeout)
    raise ExecutorError(f"--executor: found {name!r}; expected one of {', '.join(EXECUTORS)}")
