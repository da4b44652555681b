"""The unit of work an executor runs: a chunk of runs in, their index rows out.

:func:`run_table_chunk` is the one function every executor (local process pool, Dask)
calls, so a run gives the same bits wherever it executes; :func:`run_chunk` runs tasks
given one by one. Each run is simulated and its result file
written by the worker itself, so a sweep whose parent dies loses no finished run. A
failed run (solver failure, gimbal lock, non-finite state, timeout) is a record with its
status and message; an unexpected exception is a record with status ``"error"``.

Engines
-------
``options.engine`` names an engine of :data:`rbstab.engine.ENGINES`:

- one that integrates every run by ``solve_ivp`` (``scipy``, the reference): the tasks of
  a chunk one after the other through :func:`rbstab.simulator.simulate`; any method,
  per-run ``timeout``.
- a compiled one (``compiled``, ``cuda``): :func:`rbstab.simulator.simulate_blocks`: every
  run of the chunk whose method the engine takes (RK23, RK45, DOP853) is integrated in its
  batches, whatever its variant, body and gains (a tree's runs with the runs of the same
  tree); the others (implicit methods, the pure
  sign law of ``sliding``) go through scipy. The sweep validated every run when it was
  planned: a chunk of a table goes as one batch of arrays (:func:`run_table_chunk`); runs
  given one by one are rebuilt from their resolved configurations.

Layouts
-------
Both engines hand each finished run (the compiled engine a block of runs,
:class:`rbstab.results.RunBlock`) to a sink, ``SINKS[options.layout]``: ``run`` writes
one file per run with :func:`rbstab.io.hdf5.write_run` (``options.store``); ``chunk``
writes the chunk's runs into one file (:class:`rbstab.io.chunk.ChunkWriter`), renamed
into place when the whole chunk is done. Either way a chunk's result
(:class:`ChunkResult`) carries its runs' index rows as the parent would read them back
from the files (a store file's rows are its columns, :meth:`rbstab.io.chunk.ChunkWriter.columns`),
so the parent need not reopen any file, and resume and the index work the same.
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile
import time as _time
import traceback
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import PhysicalPlausibilityWarning, RunConfig
from ..config.loader import config_from_mapping
from ..engine.registry import get_engine
from ..io.chunk import ChunkWriter, StoreRow, StoreRows, chunk_file_name
from ..io.hdf5 import write_run
from ..results import plain
from ..simulator import simulate, simulate_batch, simulate_blocks, uses_compiled_engine
from .folder import NOT_IN_INDEX, index_part, row_from_attributes

__all__ = ["RunTask", "WorkerOptions", "run_chunk", "run_table_chunk", "ChunkResult"]


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
        Key of :data:`rbstab.engine.ENGINES`.
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

    def __init__(self, rows, options: WorkerOptions, templates: Sequence[dict] = (), folder: str = "") -> None:
        self.options = options
        self.folder = folder

    def __enter__(self) -> "_RunFiles":
        return self

    def __exit__(self, *exc) -> None:
        return None

    def add(self, task: RunTask, result) -> dict[str, Any]:
        """Write ``result``'s file (or its bytes); the record of a finished run."""
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
        # the row as the index takes it: the config text stays in the file, not in the parent
        record["attrs"] = index_part(row_from_attributes(attrs, Path(task.path).name))
        record["timing"] = {**result.timing, "config_yaml": t1 - t0, "write": _time.perf_counter() - t1}
        return record

    def add_tasks(self, tasks: Sequence[RunTask], block) -> list[dict[str, Any]]:
        """:meth:`add` of each run of a :class:`rbstab.results.RunBlock` (``tasks[j]`` its run
        j); a file that cannot be written is that run's error."""
        return _each_run(self, tasks, block)

    def error(self, task: RunTask, exc: BaseException) -> dict[str, Any]:
        return _error_record(task, exc)

    def result(self, records: list[dict[str, Any]]) -> "ChunkResult":
        return _chunk_result(records, self.folder)


def _result_record(task: RunTask, path: str, result) -> dict[str, Any]:
    return {"run_id": task.run_id, "path": path, "status": result.status, "message": result.message,
            "wall_time": result.wall_time}


#: Columns of a store file's rows that the index takes from the table of runs instead.
_FROM_TABLE = ("base", "template", "config", "store")


class _ChunkFile:
    """Where finished runs go with ``layout="chunk"``: one store file for the chunk
    (:class:`rbstab.io.chunk.ChunkWriter`), ``chunk-<first run id>-<random>.h5`` in
    ``folder``. Its index rows are the file's columns (:meth:`ChunkWriter.columns`), so a
    block of runs goes in and out as columns; the records of runs added one by one carry
    only their timing, a traceback or an errno."""

    def __init__(self, rows, options: WorkerOptions, templates: Sequence[dict] = (), folder: str = "") -> None:
        self.options = options
        self.rows = rows
        self.folder = folder
        name = chunk_file_name(str(rows.run_id[int(np.argmin(rows.index))]))
        self.final = str(Path(folder) / name)
        self._tmp = tempfile.TemporaryDirectory(prefix="rbstab-") if options.return_bytes else None
        where = Path(self._tmp.name) / name if self._tmp else Path(self.final)
        self.writer = ChunkWriter(where, rows, store=options.store, parameters=options.parameters,
                                  command_line=options.command_line, sweep=options.sweep, templates=templates)
        self.timing: dict[str, float] = {}
        self.data: dict[str, bytes] = {}

    def __enter__(self) -> "_ChunkFile":
        self.writer.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            self.writer.__exit__(exc_type, exc, tb)
            if self._tmp is not None and exc_type is None:
                self.data[self.final] = self.writer.path.read_bytes()
        finally:
            if self._tmp is not None:
                self._tmp.cleanup()

    def add(self, task: RunTask, result) -> dict[str, Any]:
        t0 = _time.perf_counter()
        self.writer.add(task.run_id, result, config_hash=task.config_hash or None)
        record = _result_record(task, self.final, result)
        record["timing"] = {**result.timing, "config_yaml": 0.0, "write": _time.perf_counter() - t0}
        return record

    def add_block(self, run_ids: Sequence[str], block, config_hashes: Sequence[str], config_time: float) -> None:
        """The runs of a :class:`rbstab.results.RunBlock` (``run_ids[j]`` its run j) into
        the file at once (:meth:`rbstab.io.chunk.ChunkWriter.add_block`); ``config_time``:
        seconds a run spent on its configuration."""
        t0 = _time.perf_counter()
        self.writer.add_block(run_ids, block, config_hashes=config_hashes)
        timing = {key: float(np.sum(values)) for key, values in block.timing.items()}
        timing.update(config=config_time * len(block), config_yaml=0.0, write=_time.perf_counter() - t0)
        for key, seconds in timing.items():
            self.timing[key] = self.timing.get(key, 0.0) + seconds

    def add_tasks(self, tasks: Sequence[RunTask], block) -> list[dict[str, Any]]:
        """:meth:`add_block` of a block's runs, ``tasks[j]`` its run j."""
        self.add_block([t.run_id for t in tasks], block, [t.config_hash for t in tasks], 0.0)
        return []

    def error(self, task: RunTask, exc: BaseException) -> dict[str, Any]:
        record = _error_record(task, exc)
        self.writer.add_error(task.run_id, record["message"])
        return record

    def result(self, records: list[dict[str, Any]]) -> "ChunkResult":
        """The chunk's :class:`ChunkResult` once the file is written: its rows from the file's
        columns; tracebacks, errnos and timing from ``records``."""
        columns = self.writer.columns()
        out = _chunk_result(records, self.folder, columns={
            name: values for name, values in columns.items() if name not in _FROM_TABLE and name not in self.rows.coords})
        for key, seconds in self.timing.items():
            out.timing[key] = out.timing.get(key, 0.0) + seconds
        out.data.update(self.data)
        return out


#: ``layout`` -> how a worker stores the runs of a chunk.
SINKS = {"run": _RunFiles, "chunk": _ChunkFile}


def _run_one(task: RunTask, options: WorkerOptions, sink) -> dict[str, Any]:
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
    sharing the tree and settings of one of the last :data:`SHARED_CONFIGS` distinct
    configs where they are the same: a grid's inner axis); one that does not rebuild is
    validated, for the message of what is wrong with it.
    """
    configs: list = []
    errors: list[dict[str, Any]] = []
    recent: list = []  # distinct rebuilt configs, the latest first
    for task in tasks:
        try:
            try:
                config = RunConfig.from_resolved(task.config, like=recent)
                if not recent or config.chain is not recent[0].chain:
                    recent = [config, *[c for c in recent if c.chain is not config.chain][: SHARED_CONFIGS - 1]]
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
    """Integrate the runs of the chunk with the compiled engine ``options.engine`` (see the
    module docstring), on the CPU or on the GPU."""
    t0 = _time.perf_counter()
    configs, records = _group_configs(tasks, sink)
    batch = [i for i, c in enumerate(configs) if c is not None and uses_compiled_engine(c, options.engine)]
    others = [i for i, c in enumerate(configs) if c is not None and not uses_compiled_engine(c, options.engine)]
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
        records = sink.add_tasks(tasks, block)
    except Exception:  # the sink added none of them (ChunkWriter.add_block checks first)
        records = _each_run(sink, tasks, block)
    for record in records:
        if "timing" in record:
            record["timing"]["config"] = config_time
    return records


def _run_tasks(tasks: Sequence[RunTask], options: WorkerOptions, sink) -> list[dict[str, Any]]:
    """The records of ``tasks`` run by ``options.engine`` (what a run's row does not carry:
    its timing, a traceback, an errno; any order)."""
    engine = _compiled_engine if get_engine(options.engine).compiled else _scipy_engine
    return engine(tasks, options, sink)


def run_chunk(tasks: Sequence[RunTask], options: WorkerOptions, templates: Sequence[dict] = ()) -> "ChunkResult":
    """Execute a chunk of runs given one by one (see :func:`run_table_chunk` for a slice
    of a sweep's table of runs, what the executors run).

    Parameters
    ----------
    tasks : sequence of RunTask
        Their files go into the folder of ``tasks[0].path``.
    options : WorkerOptions
    templates : sequence of dict
        The configurations the tasks start from (``RunTask.template``), stored once in a
        store file instead of each run's configuration.

    Returns
    -------
    ChunkResult
        A row per task, any order.
    """
    rows = StoreRows.of([StoreRow(t.index, t.run_id, t.base, t.coords, t.template) for t in tasks])
    folder = str(Path(tasks[0].path).parent) if tasks else ""
    return _execute(rows, tasks, options, templates, folder)


def _execute(rows, tasks: Sequence[RunTask], options: WorkerOptions, templates: Sequence[dict], folder: str,
             batch=None, part=None) -> "ChunkResult":
    """The runs of a chunk (``rows``, :class:`rbstab.io.chunk.StoreRows`) into ``folder``:
    ``tasks`` by ``options.engine``; with ``batch`` (``(RunBatch, rows of the slice ``part``,
    seconds a run to build it)``), those rows from the batch first."""
    try:
        with SINKS[options.layout](rows, options, templates, folder) as sink:
            records: list[dict[str, Any]] = []
            if batch is not None:
                alone = _batch_into(sink, *batch, options, part)
                tasks = [*tasks, *(_task(part, j, folder) for j in alone)]
            records += _run_tasks(tasks, options, sink)
        result = sink.result(records)
    except Exception as exc:  # the chunk's file could not be written: each of its runs is an error
        records = [_error_record(RunTask(rid, {}, os.path.join(folder, f"{rid}.h5")), exc) for rid in rows.run_id]
        result = _chunk_result(records, folder)
    result.worker_peak_rss = _peak_rss()
    return result


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
    rows : dict of str to array-like, or list of dict
        A row per run, its index row as stored: ``run_id``, ``status``, ``message``,
        ``wall_time``, the summary columns, ``solver_*``, ``config_hash``, ``created``,
        ``file`` and ``file_row`` (None where no file was written); as columns (a store
        file's) or as records (one per run file). :attr:`frame` is the same as a table.
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

    rows: Any
    data: dict
    tracebacks: dict
    errno: int | None
    path: str
    timing: dict
    worker_peak_rss: int | None

    @functools.cached_property
    def frame(self):
        """:attr:`rows` as a pandas DataFrame, a row per run, built where it is read (the
        parent): a worker never imports pandas."""
        import pandas as pd  # heavy: ~0.25 s, which the workers' fork server would spend before the first run

        return pd.DataFrame(self.rows) if isinstance(self.rows, dict) else pd.DataFrame.from_records(self.rows)


def run_table_chunk(part, options: WorkerOptions, folder: str = "") -> ChunkResult:
    """Run the runs of a :class:`rbstab.sweep.table.TableSlice` and return their index rows
    as columns: the function every executor submits, so a run gives the same bits wherever
    it executes.

    With the compiled or cuda engine and store files (``layout="chunk"``), the slice becomes one
    :class:`rbstab.engine.RunBatch` (:meth:`~rbstab.sweep.table.TableSlice.batch`: the
    parameter records, initial states and settings of every run at once) integrated by
    :func:`rbstab.simulator.simulate_batch` and written as columns: nothing is made per run.
    The runs it does not take (implicit methods, the pure sign law), and every run with the
    scipy engine or one file per run, are built as configurations one by one (from their
    template and row) and run as :func:`run_chunk` runs them.

    ``folder``: the sweep's ``runs/`` folder (store files and run files go there).
    """
    t0 = _time.perf_counter()
    batch = _table_batch(part, options)
    fast = np.flatnonzero(batch.compiled) if batch is not None else np.empty(0, dtype=np.int64)
    build = (_time.perf_counter() - t0) / max(len(fast), 1)
    slow = np.ones(len(part), dtype=bool)
    slow[fast] = False
    tasks = [_task(part, j, folder) for j in np.flatnonzero(slow).tolist()]
    rows = StoreRows(np.asarray(part.index, dtype=np.int64), np.asarray(part.run_id, dtype=object),
                     np.asarray(part.base, dtype=object), dict(part.coords), np.asarray(part.template, dtype=np.int64))
    return _execute(rows, tasks, options, part.templates, folder, (batch, fast, build) if len(fast) else None, part)


def _task(part, j: int, folder: str) -> RunTask:
    """Run ``j`` of a table slice as a :class:`RunTask`, its configuration built."""
    rid = str(part.run_id[j])
    return RunTask(rid, part.resolved(j), os.path.join(folder, f"{rid}.h5"), int(part.index[j]),
                   str(part.base[j]), {name: plain(values[j]) for name, values in part.coords.items()},
                   str(part.config_hash[j]), int(part.template[j]))


def _table_batch(part, options: WorkerOptions):
    """The slice's :class:`~rbstab.engine.RunBatch` where the worker integrates it as one
    (compiled or cuda engine, store files), else None; None also for a slice the batch cannot be
    built from, whose runs then go one by one (each run's problem, if any, its own record)."""
    if not get_engine(options.engine).compiled or options.layout != "chunk" or not len(part):
        return None
    try:
        return part.batch(options.timeout)
    except Exception:  # a configuration the sweep's validation let through but the batch does not take
        return None


def _batch_into(sink, batch, fast, build: float, options: WorkerOptions, part) -> list[int]:
    """The runs ``fast`` of ``batch`` (rows of the slice ``part``), integrated by
    :func:`rbstab.simulator.simulate_batch` and stored by ``sink`` (a :class:`_ChunkFile`)
    as blocks; returns the runs it did not finish (an exception of the batch as a whole, a
    bug: they go one by one)."""
    done = np.zeros(len(part), dtype=bool)
    try:
        for rows, block in simulate_batch(batch, fast, full=options.store == "full", engine=options.engine,
                                          keep=KEEP_OF_STORE[options.store]):
            sink.add_block(part.run_id[rows], block, part.config_hash[rows], build)
            done[rows] = True
    except Exception:
        return [int(j) for j in fast if not done[j]]
    return []


def _chunk_result(records: list[dict[str, Any]], folder: str, columns: dict | None = None) -> ChunkResult:
    """The :class:`ChunkResult` of a chunk's records (its rows from their ``attrs``, unless
    ``columns`` gives them)."""
    rows, data, tracebacks, timing, errno = [], {}, {}, {}, None
    for rec in records:
        if columns is None:
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
    return ChunkResult(rows if columns is None else columns, data, tracebacks, errno, folder, timing, None)

