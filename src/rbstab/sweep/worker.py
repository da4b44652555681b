"""The unit of work an executor runs: a chunk of runs in, a list of records out.

:func:`run_chunk` is the one function every executor (local process pool, Dask) calls, so
a run gives the same bits wherever it executes. Each run is simulated and its result file
written by the worker itself, so a sweep whose parent dies loses no finished run. A
failed run (solver failure, gimbal lock, non-finite state, timeout) is a record with its
status and message; an unexpected exception is a record with status ``"error"``.

Engines
-------
``ENGINES`` maps an engine name to a function ``(tasks, options) -> records``:

- ``scipy`` (the reference): the tasks of a chunk one after the other through
  :func:`rbstab.simulate.simulate`, one ``solve_ivp`` call each; any method, per-run
  ``timeout``.
- ``batch``: :func:`rbstab.simulate.simulate_many` (:mod:`rbstab.batch`): the runs of a
  chunk that share variant, body, gains and settings (they differ only in name and
  initial state) and use RK23, RK45 or DOP853 are integrated together, each with the
  steps scipy would take alone; the other tasks of the chunk (implicit methods) go
  through the scipy engine. Configurations are validated once per group: the sweep
  validated every run when it was planned, and the other runs of a group take the
  group's validated config with their own name and initial state. No ``timeout``.

Both write one file per run with :func:`rbstab.io.hdf5.write_run` (``options.store``), so
resume and the index work the same, and both return the file's attributes in the record
(``record["attrs"]``), so the parent need not reopen every file.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time as _time
import traceback
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["RunTask", "WorkerOptions", "run_chunk", "ENGINES", "DEFAULT_CHUNK_SIZE"]


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
        :func:`rbstab.io.atomic.write_bytes_atomic`.
    store : str
        ``"full"`` or ``"summary"`` (:data:`rbstab.io.hdf5.STORE_MODES`).
    """

    timeout: float | None = None
    command_line: str | None = None
    engine: str = "scipy"
    return_bytes: bool = False
    store: str = "full"


def _config(task: RunTask):
    from ..config import PhysicalPlausibilityWarning, config_from_mapping

    with warnings.catch_warnings():
        # shown once, as a digest, when the sweep was planned
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        return config_from_mapping(task.config)


def _error_record(task: RunTask, exc: BaseException) -> dict[str, Any]:
    return {
        "run_id": task.run_id,
        "path": task.path,
        "status": "error",
        "message": f"{type(exc).__name__}: {exc}",
        "traceback": traceback.format_exc(),
        "wall_time": 0.0,
    }


def _write(task: RunTask, result, options: WorkerOptions) -> dict[str, Any]:
    """Write ``result``'s file (or its bytes); the record of a finished run."""
    from ..io.hdf5 import write_run

    record: dict[str, Any] = {"run_id": task.run_id, "path": task.path}
    t0 = _time.perf_counter()
    config_yaml = result.config.to_yaml()  # the config attribute and its hash
    t1 = _time.perf_counter()
    if options.return_bytes:
        with tempfile.TemporaryDirectory(prefix="rbstab-") as tmp:
            path = Path(tmp) / Path(task.path).name
            attrs = write_run(result, path, command_line=options.command_line, store=options.store,
                              config_yaml=config_yaml)
            record["data"] = path.read_bytes()
    else:
        attrs = write_run(result, task.path, command_line=options.command_line, store=options.store,
                          config_yaml=config_yaml)
    timing = dict(result.timing)
    timing["config_yaml"] = t1 - t0
    timing["write"] = _time.perf_counter() - t1
    record.update(status=result.status, message=result.message, wall_time=result.wall_time, attrs=attrs,
                  timing=timing)
    return record


def _run_one(task: RunTask, options: WorkerOptions) -> dict[str, Any]:
    from ..simulate import simulate

    try:
        t0 = _time.perf_counter()
        config = _config(task)
        config_time = _time.perf_counter() - t0
        result = simulate(config, timeout=options.timeout)
        record = _write(task, result, options)
        record["timing"]["config"] = config_time
        return record
    except Exception as exc:  # a bug or an I/O problem: data, not a crash of the sweep
        return _error_record(task, exc)


def _scipy_engine(tasks: Sequence[RunTask], options: WorkerOptions) -> list[dict[str, Any]]:
    return [_run_one(task, options) for task in tasks]


def _group_configs(tasks: Sequence[RunTask]) -> tuple[list, list[dict[str, Any]]]:
    """RunConfigs of ``tasks`` (None where it failed) and error records.

    One ``config_from_mapping`` per group of tasks whose resolved configs differ only in
    ``name`` and ``initial_state``; the others of the group are that config with their
    own name, initial state and resolved mapping (``dataclasses.replace``, as
    :func:`rbstab.sweep.spec.expand` names its runs). Each task's config was validated
    when the sweep was planned.
    """
    from ..config import INITIAL_STATE_BLOCKS

    validated: dict[str, Any] = {}
    configs: list = []
    errors: list[dict[str, Any]] = []
    for task in tasks:
        key = repr({k: v for k, v in task.config.items() if k not in ("name", "initial_state")})
        try:
            first = validated.get(key)
            if first is None:
                config = validated[key] = _config(task)
            else:
                initial = task.config["initial_state"]
                state = {}
                for name, block in INITIAL_STATE_BLOCKS.items():
                    value = np.array(initial[name], dtype=float)
                    value.setflags(write=False)
                    state[block] = value
                config = dataclasses.replace(first, name=task.config["name"], initial_state=state,
                                             resolved=task.config)
            configs.append(config)
        except Exception as exc:
            configs.append(None)
            errors.append(_error_record(task, exc))
    return configs, errors


def _batch_engine(tasks: Sequence[RunTask], options: WorkerOptions) -> list[dict[str, Any]]:
    """Integrate the batchable runs of the chunk together (see the module docstring)."""
    from ..batch import SUPPORTED_METHODS
    from ..simulate import simulate_many

    if options.timeout is not None:
        raise ValueError("the batch engine has no per-run timeout; use the scipy engine for --timeout")
    t0 = _time.perf_counter()
    configs, records = _group_configs(tasks)
    batch = [i for i, c in enumerate(configs) if c is not None and c.simulation.method in SUPPORTED_METHODS]
    others = [i for i, c in enumerate(configs) if c is not None and c.simulation.method not in SUPPORTED_METHODS]
    config_time = (_time.perf_counter() - t0) / max(len(tasks), 1)
    done: set[int] = set()
    try:
        for j, result in simulate_many([configs[i] for i in batch], engine="batch", chunk_size=max(len(batch), 1)):
            i = batch[j]
            done.add(i)
            try:
                record = _write(tasks[i], result, options)
                record["timing"]["config"] = config_time
            except Exception as exc:  # one file that cannot be written is that run's error
                record = _error_record(tasks[i], exc)
            records.append(record)
    except Exception:
        # an exception of the batch as a whole (a bug): every run it had not finished
        # goes through the scipy engine alone, so no run is lost to another's problem
        others += [i for i in batch if i not in done]
    records += _scipy_engine([tasks[i] for i in sorted(others)], options)
    return records


#: engine name -> ``(tasks, options) -> list of records`` (one record per task, any order).
ENGINES: dict[str, Callable[[Sequence[RunTask], WorkerOptions], list[dict[str, Any]]]] = {
    "scipy": _scipy_engine,
    "batch": _batch_engine,
}

#: Default runs per chunk of each engine: one run per unit of work for scipy; batches of
#: a few hundred amortise numpy's per-call overhead (Case 3: ~4 ms per run at 256, ~3 at
#: 512, little gain beyond) while keeping a chunk's trajectories (512 x 2001 x 15 floats,
#: 120 MB) small.
DEFAULT_CHUNK_SIZE = {"scipy": 1, "batch": 512}


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
        file's bytes) when ``options.return_bytes``; ``traceback`` for an error;
        for a written file ``attrs`` (its global attributes, as
        :func:`rbstab.io.hdf5.read_attributes` returns them) and ``timing`` (seconds
        spent on ``config``, ``integration``, ``postprocess``, ``config_yaml`` (the
        config's YAML text for the file) and ``write`` (the HDF5 file));
        ``worker_peak_rss``, the worker process's peak resident set size [bytes].
    """
    records = ENGINES[options.engine](tasks, options)
    rss = _peak_rss()
    for record in records:
        record["worker_peak_rss"] = rss
    return records


def _peak_rss() -> int | None:
    """Peak resident set size of this process [bytes], or None where unknown."""
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024
