"""The unit of work an executor runs: a chunk of runs in, a list of records out.

:func:`run_chunk` is the one function every executor (local process pool, Dask) calls, so
a run gives the same bits wherever it executes. Each run is simulated and its result file
written by the worker itself, so a sweep whose parent dies loses no finished run. A
failed run (solver failure, gimbal lock, non-finite state, timeout) is a record with its
status and message; an unexpected exception is a record with status ``"error"``.

Engines
-------
``ENGINES`` maps an engine name to a function ``(tasks, options, sink) -> records``:

- ``scipy`` (the reference): the tasks of a chunk one after the other through
  :func:`rbstab.simulator.simulate`, one ``solve_ivp`` call each; any method, per-run
  ``timeout``.
- ``compiled``: :func:`rbstab.simulator.simulate_blocks` (:mod:`rbstab.engine`): every run
  of the chunk that uses RK23, RK45 or DOP853 is integrated by the compiled engine,
  whatever its variant, body and gains; the others (implicit methods, the pure sign law
  of ``sliding``) go through scipy. Configurations are validated once per group of runs
  that differ only in name and initial state: the sweep validated every run when it was
  planned, and the other runs of a group take the group's validated config with their
  own name and initial state.

Layouts
-------
Both engines hand each finished run (the compiled engine a block of runs,
:class:`rbstab.simulator.RunBlock`) to a sink, ``SINKS[options.layout]``: ``run`` writes
one file per run with :func:`rbstab.io.hdf5.write_run` (``options.store``); ``chunk``
writes the chunk's runs into one file (:class:`rbstab.io.chunk.ChunkWriter`), renamed
into place when the whole chunk is done. Either way the record carries the run's
attributes as the parent would read them back (``record["attrs"]``), so the parent need
not reopen any file, and resume and the index work the same.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import tempfile
import time as _time
import traceback
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["RunTask", "WorkerOptions", "run_chunk", "run_table_chunk", "ChunkResult", "ENGINES", "DEFAULT_CHUNK_SIZE"]


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
    index : int
        Position in the sweep's run list (the ``run`` coordinate of the store).
    base : str
        Label of its base configuration.
    coords : dict
        Parameter coordinate name -> value (:func:`rbstab.sweep.folder.run_coords`).
    config_hash : str
        The run's identity as the plan computed it ("": the hash of its config).
    template : int
        Its template among the chunk's (:class:`rbstab.sweep.table.TableSlice`), -1 for none.
    """

    run_id: str
    config: dict
    path: str
    index: int = 0
    base: str = ""
    coords: dict = field(default_factory=dict)
    config_hash: str = ""
    template: int = -1


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
        ``"full"``, ``"thinned"`` or ``"summary"`` (:data:`rbstab.io.chunk.STORES`).
    layout : str
        ``"chunk"``: one store file for the runs of a chunk (:mod:`rbstab.io.chunk`);
        ``"run"``: one result file per run (``task.path``). Key of :data:`SINKS`.
    parameters : dict
        Parameter coordinate name -> dotted config key (the store's ``config_key``).
    sweep : str
        The sweep's name (an attribute of each store file).
    """

    timeout: float | None = None
    command_line: str | None = None
    engine: str = "scipy"
    return_bytes: bool = False
    store: str = "thinned"
    layout: str = "chunk"
    parameters: dict = field(default_factory=dict)
    sweep: str = ""


def _config(task: RunTask):
    from ..config import PhysicalPlausibilityWarning, config_from_mapping  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    with warnings.catch_warnings():
        # shown once, as a digest, when the sweep was planned
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        return config_from_mapping(task.config)


def _error_record(task: RunTask, exc: BaseException) -> dict[str, Any]:
    """The record of a run that raised; an I/O failure (a full disk) carries its ``errno``
    and no traceback (it is the machine's fault, not a bug)."""
    record = {
        "run_id": task.run_id,
        "path": task.path,
        "status": "error",
        "message": f"{type(exc).__name__}: {exc}",
        "wall_time": 0.0,
    }
    if isinstance(exc, OSError) and exc.errno is not None:
        record["errno"] = exc.errno
    else:
        record["traceback"] = traceback.format_exc()
    return record


class _RunFiles:
    """Where finished runs go with ``layout="run"``: one file per run (``task.path``)."""

    def __init__(self, tasks: Sequence[RunTask], options: WorkerOptions, templates: Sequence[dict] = ()) -> None:
        self.options = options

    def __enter__(self) -> "_RunFiles":
        return self

    def __exit__(self, *exc) -> None:
        return None

    def add(self, task: RunTask, result) -> dict[str, Any]:
        """Write ``result``'s file (or its bytes); the record of a finished run."""
        from ..io.hdf5 import write_run  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)
        from .folder import row_from_attributes  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

        options = self.options
        record = _result_record(task, task.path, result)
        t0 = _time.perf_counter()
        config_yaml = result.config.to_yaml()  # the config attribute and its hash
        t1 = _time.perf_counter()
        if options.return_bytes:
            with tempfile.TemporaryDirectory(prefix="rbstab-") as tmp:
                path = Path(tmp) / Path(task.path).name
                attrs = write_run(result, path, command_line=options.command_line, store=options.store,
                                  config_yaml=config_yaml, config_hash=task.config_hash or None)
                record["data"] = path.read_bytes()
        else:
            attrs = write_run(result, task.path, command_line=options.command_line, store=options.store,
                              config_yaml=config_yaml, config_hash=task.config_hash or None)
        row = row_from_attributes(attrs, Path(task.path).name)
        return _finished(record, result.timing, row, t1 - t0, _time.perf_counter() - t1)

    def add_block(self, tasks: Sequence[RunTask], block) -> list[dict[str, Any]]:
        """:meth:`add` of each run of a :class:`rbstab.simulator.RunBlock` (``tasks[j]`` its run
        j); a file that cannot be written is that run's error."""
        return _each_run(self, tasks, block)

    def error(self, task: RunTask, exc: BaseException) -> dict[str, Any]:
        return _error_record(task, exc)


def _finished(record: dict[str, Any], timing: dict, row: dict, yaml_time: float, write_time: float) -> dict[str, Any]:
    """``record`` (``run_id``, ``path``, ``status``, ``message``, ``wall_time``) of a
    written run, with its row as the index takes it and its ``timing``."""
    from .folder import index_part  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    timing = dict(timing)
    timing["config_yaml"] = yaml_time
    timing["write"] = write_time
    # the row as the index takes it: the config text stays in the file, not in the parent
    record.update(attrs=index_part(row), timing=timing)
    return record


def _result_record(task: RunTask, path: str, result) -> dict[str, Any]:
    return {"run_id": task.run_id, "path": path, "status": result.status, "message": result.message,
            "wall_time": result.wall_time}


class _ChunkFile:
    """Where finished runs go with ``layout="chunk"``: one store file for the chunk
    (:class:`rbstab.io.chunk.ChunkWriter`), ``runs/chunk-<first run id>-<random>.h5`` in
    the folder of the tasks' paths. Records name the store file as their ``path``; their
    ``attrs`` are the run's row (:func:`rbstab.io.chunk.read_chunk_rows`)."""

    def __init__(self, tasks: Sequence[RunTask], options: WorkerOptions, templates: Sequence[dict] = ()) -> None:
        from ..io.chunk import ChunkWriter, StoreRow, chunk_file_name  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

        self.options = options
        first = min(tasks, key=lambda t: t.index)
        name = chunk_file_name(first.run_id)
        self.final = str(Path(first.path).parent / name)
        self._tmp = tempfile.TemporaryDirectory(prefix="rbstab-") if options.return_bytes else None
        where = Path(self._tmp.name) / name if self._tmp else Path(self.final)
        rows = [StoreRow(t.index, t.run_id, t.base, t.coords, t.template) for t in tasks]
        self.writer = ChunkWriter(where, rows, store=options.store, parameters=options.parameters,
                                  command_line=options.command_line, sweep=options.sweep, templates=templates)
        self.records: list[dict[str, Any]] = []

    def __enter__(self) -> "_ChunkFile":
        self.writer.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.writer.__exit__(exc_type, exc, tb)
            if self._tmp is not None and exc_type is None and self.records:
                self.records[0]["data"] = self.writer.path.read_bytes()
        finally:
            if self._tmp is not None:
                self._tmp.cleanup()

    def add(self, task: RunTask, result) -> dict[str, Any]:
        t0 = _time.perf_counter()
        row = self.writer.add(task.run_id, result, config_hash=task.config_hash or None)
        record = _finished(_result_record(task, self.final, result), result.timing, row, 0.0,
                           _time.perf_counter() - t0)
        self.records.append(record)
        return record

    def add_block(self, tasks: Sequence[RunTask], block) -> list[dict[str, Any]]:
        """The runs of a :class:`rbstab.simulator.RunBlock` (``tasks[j]`` its run j) into the
        file at once (:meth:`rbstab.io.chunk.ChunkWriter.add_block`); their records."""
        t0 = _time.perf_counter()
        rows = self.writer.add_block([t.run_id for t in tasks], block,
                                     config_hashes=[t.config_hash for t in tasks])
        share = (_time.perf_counter() - t0) / len(tasks)
        records = []
        for j, (task, row) in enumerate(zip(tasks, rows)):
            record = {"run_id": task.run_id, "path": self.final, "status": block.status[j],
                      "message": block.message[j], "wall_time": block.wall_time[j]}
            records.append(_finished(record, block.timing[j], row, 0.0, share))
        self.records += records
        return records

    def error(self, task: RunTask, exc: BaseException) -> dict[str, Any]:
        record = _error_record(task, exc)
        self.writer.add_error(task.run_id, record["message"])
        return record


#: ``layout`` -> how a worker stores the runs of a chunk.
SINKS = {"run": _RunFiles, "chunk": _ChunkFile}


def _run_one(task: RunTask, options: WorkerOptions, sink) -> dict[str, Any]:
    from ..simulator import simulate  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    try:
        t0 = _time.perf_counter()
        config = _config(task)
        config_time = _time.perf_counter() - t0
        result = simulate(config, timeout=options.timeout)
    except Exception as exc:  # a bug: data, not a crash of the sweep
        return sink.error(task, exc)
    try:
        record = sink.add(task, result)
    except Exception as exc:  # an I/O problem: this run's error
        return sink.error(task, exc)
    record["timing"]["config"] = config_time
    return record


def _scipy_engine(tasks: Sequence[RunTask], options: WorkerOptions, sink) -> list[dict[str, Any]]:
    return [_run_one(task, options, sink) for task in tasks]


#: Distinct configs a worker compares each run's config with, to share their objects.
SHARED_CONFIGS = 8


def _group_configs(tasks: Sequence[RunTask], sink=None) -> tuple[list, list[dict[str, Any]]]:
    """RunConfigs of ``tasks`` (None where it failed) and error records (``sink.error``).

    The sweep validated every run when it planned it: each task's resolved config is
    rebuilt without a second validation (:meth:`rbstab.config.RunConfig.from_resolved`,
    sharing the body, gains and settings of one of the last :data:`SHARED_CONFIGS` distinct
    configs where they are the same: a grid's inner axis); one that does not rebuild is
    validated, for the message of what is wrong with it.
    """
    from ..config import RunConfig  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    configs: list = []
    errors: list[dict[str, Any]] = []
    recent: list = []  # distinct rebuilt configs, the latest first
    for task in tasks:
        try:
            try:
                config = RunConfig.from_resolved(task.config, like=recent)
                if not recent or config.body is not recent[0].body:
                    recent = [config, *[c for c in recent if c.body is not config.body][: SHARED_CONFIGS - 1]]
            except Exception:
                config = _config(task)
            configs.append(config)
        except Exception as exc:
            configs.append(None)
            errors.append(sink.error(task, exc) if sink is not None else _error_record(task, exc))
    return configs, errors


#: Store -> the samples a ``cuda`` run brings back for it (one of :data:`rbstab.simulator.KEEP`).
KEEP_OF_STORE = {"full": "all", "thinned": "thinned", "summary": "none"}


def _compiled_engine(tasks: Sequence[RunTask], options: WorkerOptions, sink) -> list[dict[str, Any]]:
    """Integrate the runs of the chunk with the compiled engine (see the module docstring),
    on the CPU or, for ``options.engine == "cuda"``, on the GPU."""
    from ..simulator import simulate_blocks, uses_compiled_engine  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    t0 = _time.perf_counter()
    configs, records = _group_configs(tasks, sink)
    batch = [i for i, c in enumerate(configs) if c is not None and uses_compiled_engine(c)]
    others = [i for i, c in enumerate(configs) if c is not None and not uses_compiled_engine(c)]
    config_time = (_time.perf_counter() - t0) / max(len(tasks), 1)
    done: set[int] = set()
    try:
        # a thinned or summary store keeps none of the outputs LEFT_OUT: not computed
        full = options.store == "full"
        for members, block in simulate_blocks([configs[i] for i in batch], engine=options.engine,
                                              timeout=options.timeout, full=full, keep=KEEP_OF_STORE[options.store]):
            chunk = [batch[j] for j in members]
            done.update(chunk)
            records += _add_block(sink, [tasks[i] for i in chunk], block, config_time)
    except Exception:
        # an exception of the batch as a whole (a bug): every run it had not finished
        # goes through the scipy engine alone, so no run is lost to another's problem
        others += [i for i in batch if i not in done]
    records += _scipy_engine([tasks[i] for i in sorted(others)], options, sink)
    return records


def _each_run(sink, tasks: Sequence[RunTask], block) -> list[dict[str, Any]]:
    """``sink.add`` of each run of a block (``tasks[j]`` its run j); one that cannot be
    written is that run's error (``sink.error``)."""
    records = []
    for j, task in enumerate(tasks):
        try:
            records.append(sink.add(task, block.result(j)))
        except Exception as exc:
            records.append(sink.error(task, exc))
    return records


def _add_block(sink, tasks: Sequence[RunTask], block, config_time: float) -> list[dict[str, Any]]:
    """The records of a block's runs, stored by ``sink``; if the block cannot be stored at
    once, each run alone (one that cannot be written is that run's error)."""
    try:
        records = sink.add_block(tasks, block)
    except Exception:  # the sink added none of them (ChunkWriter.add_block checks first)
        records = _each_run(sink, tasks, block)
    for record in records:
        if "timing" in record:
            record["timing"]["config"] = config_time
    return records


#: engine name -> ``(tasks, options) -> list of records`` (one record per task, any order).
ENGINES: dict[str, Callable[[Sequence[RunTask], WorkerOptions], list[dict[str, Any]]]] = {
    "scipy": _scipy_engine,
    "compiled": _compiled_engine,
    "cuda": _compiled_engine,
}

#: Default runs per chunk of each engine: one run per unit of work for scipy; for the
#: compiled engine enough runs that the per-chunk costs (a task's round trip, opening a
#: file) are small, and few enough that both workers get work early (the engine holds
#: the trajectories of 32 runs at a time, whatever the chunk).
DEFAULT_CHUNK_SIZE = {"scipy": 1, "compiled": 256, "cuda": 8192}


def run_chunk(tasks: Sequence[RunTask], options: WorkerOptions, templates: Sequence[dict] = (), *,
              batch=None, part=None) -> list[dict[str, Any]]:
    """Execute a chunk of runs; the function every executor submits.

    Parameters
    ----------
    tasks : sequence of RunTask
    options : WorkerOptions
    templates : sequence of dict
        The configurations the tasks start from (``RunTask.template``), stored once in a
        store file instead of each run's configuration.

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

    With ``batch`` (``(RunBatch, rows, seconds a run to build it)``, from
    :func:`run_table_chunk`), the tasks at those rows are integrated from the batch (their
    ``config`` unused) and the others by ``options.engine``; ``part``, the table slice
    of the tasks, builds the configuration of a batch run that has to go alone.
    """
    try:
        with SINKS[options.layout](tasks, options, templates) as sink:
            records, alone = _batch_records(tasks, *batch, options, sink, part) if batch is not None else ([], [])
            fast = set(map(int, batch[1])) - set(alone) if batch is not None else set()
            rest = [task if j not in alone else dataclasses.replace(task, config=part.resolved(j))
                    for j, task in enumerate(tasks) if j not in fast]
            records += ENGINES[options.engine](rest, options, sink)
    except Exception as exc:  # the chunk's file could not be written: each of its runs is an error
        records = [_error_record(task, exc) for task in tasks]
    rss = _peak_rss()
    for record in records:
        record["worker_peak_rss"] = rss
    return records


def _peak_rss() -> int | None:
    """Peak resident set size of this process [bytes], or None where unknown."""
    try:
        import resource  # optional: POSIX only
    except ImportError:  # pragma: no cover - Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024


@dataclass
class ChunkResult:
    """What a worker returns for a slice of a sweep's run table (:func:`run_table_chunk`).

    Attributes
    ----------
    frame : pandas.DataFrame
        A row per run, its index row as stored: ``run_id``, ``status``, ``message``,
        ``wall_time``, the summary columns, ``solver_*``, ``config_hash``, ``created``,
        ``file`` and ``file_row`` (None where no file was written).
    data : dict of str to bytes
        Final path -> the file's bytes (``WorkerOptions.return_bytes``).
    tracebacks : dict of str to str
        run_id -> traceback of a run that raised.
    errno : int or None
        An I/O error's errno that stops the sweep (a full disk), else None.
    path : str
        The folder's path of a written file, for a run without one.
    timing : dict of str to float
        Seconds summed over the runs (see :class:`rbstab.sweep.SweepOutcome`).
    worker_peak_rss : int or None
    """

    frame: Any
    data: dict
    tracebacks: dict
    errno: int | None
    path: str
    timing: dict
    worker_peak_rss: int | None


def run_table_chunk(part, options: WorkerOptions, folder: str = "") -> ChunkResult:
    """Run the runs of a :class:`rbstab.sweep.table.TableSlice` and return their index rows
    as columns.

    With the compiled or cuda engine and store files (``layout="chunk"``), the slice becomes one
    :class:`rbstab.engine.RunBatch` (:meth:`~rbstab.sweep.table.TableSlice.batch`: the
    parameter records, initial states and settings of every run at once) integrated by
    :func:`rbstab.simulator.simulate_batch`; the runs it does not take (implicit methods,
    the pure sign law), and every run with the scipy engine or one file per run, are built
    as configurations one by one (from their template and row) and run as :func:`run_chunk`
    runs them.

    ``folder``: the sweep's ``runs/`` folder (store files and run files go there).
    """
    import numpy as np  # heavy: numpy

    t0 = _time.perf_counter()
    batch = _table_batch(part, options)
    fast = np.flatnonzero(batch.compiled) if batch is not None else np.empty(0, dtype=np.int64)
    build = (_time.perf_counter() - t0) / max(len(fast), 1)
    slow = np.ones(len(part), dtype=bool)
    slow[fast] = False
    tasks = [RunTask(rid, part.resolved(j) if slow[j] else {}, os.path.join(folder, f"{rid}.h5"),
                     int(part.index[j]), str(part.base[j]),
                     {name: _scalar(values[j]) for name, values in part.coords.items()}, str(part.config_hash[j]),
                     int(part.template[j]))
             for j, rid in enumerate(part.run_id.tolist())]
    records = run_chunk(tasks, options, part.templates, batch=(batch, fast, build) if len(fast) else None, part=part)
    return _chunk_result(records, folder)


def _table_batch(part, options: WorkerOptions):
    """The slice's :class:`~rbstab.engine.RunBatch` where the worker integrates it as one
    (compiled or cuda engine, store files), else None; None also for a slice the batch cannot be
    built from, whose runs then go one by one (each run's problem, if any, its own record)."""
    if options.engine not in ("compiled", "cuda") or options.layout != "chunk" or not len(part):
        return None
    try:
        return part.batch(options.timeout)
    except Exception:  # a configuration the sweep's validation let through but the batch does not take
        return None


def _batch_records(tasks: Sequence[RunTask], batch, fast, build: float, options: WorkerOptions, sink, part
                   ) -> tuple[list[dict[str, Any]], list[int]]:
    """The records of the runs ``fast`` of ``batch`` (``tasks[j]`` run j), integrated by
    :func:`rbstab.simulator.simulate_batch` and stored by ``sink``; and the runs it did not
    finish (an exception of the batch as a whole, a bug: they go one by one)."""
    from ..simulator import simulate_batch  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    records: list[dict[str, Any]] = []
    done: set[int] = set()
    try:
        for rows, block in simulate_batch(batch, fast, full=options.store == "full", engine=options.engine,
                                          keep=KEEP_OF_STORE[options.store]):
            done.update(rows)
            records += _add_block(sink, [tasks[j] for j in rows], block, build)
    except Exception:
        return records, [int(j) for j in fast if j not in done]
    return records, []


def _chunk_result(records: list[dict[str, Any]], folder: str) -> ChunkResult:
    """The :class:`ChunkResult` of a chunk's records."""
    import pandas as pd  # heavy: pandas

    from ..sweep.folder import NOT_IN_INDEX  # heavy: numba, h5py (this module is imported at the CLI's start-up for ENGINES)

    rows, data, tracebacks, timing, errno = [], {}, {}, {}, None
    for rec in records:
        row = {k: v for k, v in (rec.get("attrs") or {}).items() if k not in NOT_IN_INDEX and k != "created"}
        row.update(run_id=rec["run_id"], status=rec["status"], message=rec.get("message") or "")
        if rec.get("attrs") is None:
            row.update(file=None, file_row=None)
        row["created"] = (rec.get("attrs") or {}).get("created")
        rows.append(row)
        if rec.get("data") is not None:
            data[rec["path"]] = rec["data"]
        if "traceback" in rec:
            tracebacks[rec["run_id"]] = rec["traceback"]
        errno = errno or rec.get("errno")
        for key, seconds in (rec.get("timing") or {}).items():
            timing[key] = timing.get(key, 0.0) + seconds
    frame = pd.DataFrame.from_records(rows)
    rss = records[0].get("worker_peak_rss") if records else None
    return ChunkResult(frame, data, tracebacks, errno, folder, timing, rss)


def _scalar(value: Any) -> Any:
    return value.item() if hasattr(value, "item") else value
