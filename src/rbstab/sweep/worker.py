"""The unit of work an executor runs: a chunk of runs in, a list of records out.

:func:`run_chunk` is the one function every executor (local process pool, Dask) calls, so
a run gives the same bits wherever it executes. Each run is simulated and its result file
written by the worker itself, so a sweep whose parent dies loses no finished run. A
failed run (solver failure, gimbal lock, non-finite state, timeout) is a record with its
status and message; an unexpected exception is a record with status ``"error"``.

Engines
-------
``ENGINES`` maps an engine name to a function ``(tasks, options) -> records``. The scipy
engine runs the tasks of a chunk one after the other through
:func:`rbstab.simulate.simulate`. A vectorised engine (e.g. one built on
:mod:`rbstab.batch`) registers here under its own name and is selected with
``run_sweep(..., engine=name, chunk_size=...)``; the runner already sends chunks (runs in
run-list order, so a random sweep over initial states from one base gives chunks that
share variant, body, gains and settings). Such an engine should group the tasks of a chunk
by (variant, body, gains, settings) itself, hand what it cannot batch (e.g. implicit
methods) to ``_scipy_engine``, and write one file per run with
:func:`rbstab.io.hdf5.write_result` as here, so that resume and the index work unchanged.
"""

from __future__ import annotations

import os
import tempfile
import traceback
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["RunTask", "WorkerOptions", "run_chunk", "ENGINES", "write_bytes_atomic"]


@dataclass(frozen=True)
class RunTask:
    """One run to execute (small: it travels to the worker process).

    Attributes
    ----------
    run_id : str
    config : dict
        The resolved configuration (``RunConfig.resolved``, ``name == run_id``).
    path : str
        Final result file (``<sweep>/runs/<run_id>.h5``).
    """

    run_id: str
    config: dict
    path: str


@dataclass(frozen=True)
class WorkerOptions:
    """Settings shared by every task of a sweep invocation.

    Attributes
    ----------
    timeout : float or None
        Per-run wall-time budget [s] (``simulate(config, timeout=...)``).
    command_line : str or None
        Recorded in each file's ``command_line`` attribute.
    engine : str
        Key of :data:`ENGINES`.
    return_bytes : bool
        Write each file in a private temporary folder and return its bytes in the record
        (``record["data"]``) instead of writing ``task.path``: for workers that do not
        share the sweep's filesystem (Dask). The parent writes them with
        :func:`write_bytes_atomic`.
    """

    timeout: float | None = None
    command_line: str | None = None
    engine: str = "scipy"
    return_bytes: bool = False


def _run_one(task: RunTask, options: WorkerOptions) -> dict[str, Any]:
    from ..config import PhysicalPlausibilityWarning, config_from_mapping
    from ..io.hdf5 import write_result
    from ..simulate import simulate

    record: dict[str, Any] = {"run_id": task.run_id, "path": task.path}
    try:
        with warnings.catch_warnings():
            # shown once, as a digest, when the sweep was planned
            warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
            config = config_from_mapping(task.config)
        result = simulate(config, timeout=options.timeout)
        if options.return_bytes:
            with tempfile.TemporaryDirectory(prefix="rbstab-") as tmp:
                path = write_result(result, Path(tmp) / Path(task.path).name, command_line=options.command_line)
                record["data"] = path.read_bytes()
        else:
            write_result(result, task.path, command_line=options.command_line)
        record.update(status=result.status, message=result.message, wall_time=result.wall_time)
    except Exception as exc:  # a bug or an I/O problem: data, not a crash of the sweep
        record.update(
            status="error",
            message=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(),
            wall_time=0.0,
        )
    return record


def _scipy_engine(tasks: Sequence[RunTask], options: WorkerOptions) -> list[dict[str, Any]]:
    return [_run_one(task, options) for task in tasks]


#: engine name -> ``(tasks, options) -> list of records`` (one record per task, any order).
ENGINES: dict[str, Callable[[Sequence[RunTask], WorkerOptions], list[dict[str, Any]]]] = {
    "scipy": _scipy_engine,
}


def run_chunk(tasks: Sequence[RunTask], options: WorkerOptions) -> list[dict[str, Any]]:
    """Execute a chunk of runs; the function every executor submits.

    Parameters
    ----------
    tasks : sequence of RunTask
    options : WorkerOptions

    Returns
    -------
    list of dict
        One record per task: ``run_id``, ``path``, ``status`` (``"success"``,
        ``"failed"`` or ``"error"``), ``message``, ``wall_time`` [s], and ``data`` (the
        file's bytes) when ``options.return_bytes``; ``traceback`` for an error.
    """
    return ENGINES[options.engine](tasks, options)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in its folder and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
