"""Run a sweep: plan, skip what is done, execute the rest, rebuild the index from the files.

Output folder ``<output>/<name>/`` (Hydra-like, it describes itself)::

    sweep.yaml           the resolved spec (bases inline, --set applied) + provenance
    runs/chunk-*.h5      store files, one per chunk of runs (layout "chunk", the default,
                         :mod:`rbstab.io.chunk`)
    runs/<run_id>.h5     or one result file per run, the format of ``rbstab run`` (layout "run")
    index.csv            one row per run
    sweep_summary.json   counts, fraction converged

The names and columns are those of :mod:`rbstab.sweep.folder`, which also reads the folder.

The runs are a table (:func:`rbstab.sweep.table.plan_table`, every run validated before
anything is written); the workers receive slices of it and return their runs' index rows
as columns, from which the index is written.

Resume: a run is skipped when a result of it is on disk (a row of a store file or its file
``runs/<run_id>.h5``) with its run id and ``config_hash`` (with ``retry_failed``, only if
its status is also ``success``); of several, the newest counts. Every other run is
executed and written to a new store file (a killed chunk is rerun whole) or its file
replaced (layout "run").

Nothing is lost when the sweep is killed (even with SIGKILL): each worker writes its
run's file to a temporary name and renames it into place when complete, so a final name
always holds a whole file; the index is rebuilt from the files at the end of every
invocation; temporary files of killed writers are removed by the next invocation. Only
one invocation at a time may write a sweep folder (a lock file, ``.lock``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as _dt
import errno
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .. import __version__
from ..config import dump_yaml
from .executors import Executor, default_jobs, make_executor
from ..io.atomic import atomic_path, write_bytes_atomic, write_text_atomic
from .folder import (
    DEFAULT_LAYOUT,
    INDEX_FILE,
    LAYOUTS,
    LOCK_FILE,
    RUNS_DIR,
    SPEC_FILE,
    SUMMARY_FILE,
    StoredRuns,
    read_spec,
    set_aside_damaged,
    wants_csv,
    write_table_index,
)
from .spec import SweepSpec, SweepSpecError
from ..io.chunk import DEFAULT_STORE, STORES
from ..engine.registry import get_engine
from .worker import WorkerOptions, run_table_chunk
from .table import plan_table

#: Runs per store file (and unit of work) by default: a store file costs ~0.1 s to create
#: and close whatever its runs (~60 variables with their attributes, the digest of its
#: structure) and ~0.3 ms a run.
STORE_CHUNK_SIZE = 512

#: Runs per store file of a summary store by default: a file's variables cost ~0.25 MB
#: whatever its runs (their headers, attributes and chunk indexes), ~0.5 KB a run without
#: traces; the runs' outputs are not kept beyond a block of 32.
SUMMARY_CHUNK_SIZE = 8192
#: Runs a GPU launch holds per thread the GPU keeps resident: a thread whose run ends takes
#: the next, so the launch's tail, where its last runs finish, is a small part of it.
RUNS_PER_RESIDENT_THREAD = 8
#: Threads an H100 keeps resident of the CUDA kernel at its 255 registers a thread: 132
#: multiprocessors x 2 blocks of 128 (:func:`rbstab.engine.cuda.occupancy`).
H100_RESIDENT_THREADS = 132 * 2 * 128
#: Runs per chunk of a sweep on the GPU (``--engine cuda``: a chunk is one launch) by store.
#: ``summary``: :data:`RUNS_PER_RESIDENT_THREAD` runs a resident thread of an H100;
#: ``thinned``: about one run a resident thread, ~2 GB of traces at 201 samples (host and
#: device memory bound it); ``full``: the engine's ``chunk_size`` (a trace of every sample).
CUDA_CHUNK_SIZE = {"summary": RUNS_PER_RESIDENT_THREAD * H100_RESIDENT_THREADS, "thinned": 32768}

#: Worker processes of a ``--engine cuda`` sweep by default (at most the CPU count): the
#: GPU integrates a run in ~0.5 us, its worker spends ~11-15 us a run on the host (the
#: batch's records, the store file and its rows), so several workers share one GPU.
CUDA_JOBS = 4

#: Chunks per worker a sweep is cut into at least (when chunks of STORE_CHUNK_SIZE runs
#: would give fewer), so that the workers finish together. (One chunk per worker, fewer
#: store files, measured no better: 1000 Case 3 runs on 2 workers, 5 alternating runs
#: each, initial-state a little faster, parameter a little slower.)
CHUNKS_PER_WORKER = 2

#: Fewest runs per chunk when a sweep is split into CHUNKS_PER_WORKER chunks per worker
#: (a chunk is a store file: more of them cost time to write and to open).
MIN_SPLIT_CHUNK = 64

__all__ = [
    "run_sweep",
    "rebuild_index",
    "SweepOutcome",
    "SweepBusyError",
    "DEFAULT_OUTPUT",
    "SPEC_FILE",
    "INDEX_FILE",
    "SUMMARY_FILE",
    "RUNS_DIR",
    "LAYOUTS",
]

#: Default parent folder of sweep folders.
DEFAULT_OUTPUT = "results/sweeps"


class SweepBusyError(RuntimeError):
    """Another process is writing the same sweep folder."""


@dataclass
class SweepOutcome:
    """What a sweep invocation did and where the sweep stands.

    Attributes
    ----------
    name : str
    directory : Path
        The sweep folder.
    n_runs : int
        Runs in the spec.
    n_skipped : int
        Runs whose result file was already there and current.
    n_executed : int
        Runs executed by this invocation.
    counts : dict of str to int
        Runs per status over the whole sweep (``success``, ``failed``, ``error``,
        ``pending``), from the index.
    n_converged : int
    problems : list of (run_id, status, message)
        Every run of the sweep that did not succeed.
    tracebacks : dict of str to str
        run_id -> traceback for runs with status ``error`` in this invocation.
    stale_files : list of str
        Result files in ``runs/`` that are not runs of this spec (left in place).
    damaged : list of (str, str)
        Result files whose checksums did not match, as (file name, reason): renamed
        ``<name>.damaged`` and their runs rerun.
    executor : str
        Description of the executor used (empty when nothing ran).
    engine : str
        The engine used (see :func:`run_sweep`).
    n_chunks : int
        Units of work sent to the executor.
    timing : dict of str to float
        Seconds summed over the runs executed, as reported by the workers: ``config``
        (building the run's configuration), ``integration``, ``postprocess`` (outputs,
        numerical rate, summary), ``config_yaml`` (``config.to_yaml()`` for the file's
        ``config`` and ``config_hash`` attributes) and ``write`` (the HDF5 file).
    worker_peak_rss : int or None
        Largest peak resident set size of a worker process [bytes], as reported by the
        workers (None when unknown).
    warnings : list of str
        Physical-plausibility warnings of the runs, one line per config key
        (:attr:`rbstab.sweep.table.RunTable.warnings`).
    index_file : str
        The index file the summary names: ``index.csv`` where it is written, else
        ``index.arrow``.
    index_seconds : float
        Seconds spent writing the index and the summary.
    """

    name: str
    directory: Path
    n_runs: int
    n_skipped: int = 0
    n_executed: int = 0
    counts: dict = field(default_factory=dict)
    outcomes: dict = field(default_factory=dict)
    n_converged: int = 0
    n_fell: int = 0
    problems: list = field(default_factory=list)
    tracebacks: dict = field(default_factory=dict)
    stale_files: list = field(default_factory=list)
    damaged: list = field(default_factory=list)
    executor: str = ""
    engine: str = ""
    n_chunks: int = 0
    timing: dict = field(default_factory=dict)
    worker_peak_rss: int | None = None
    warnings: list = field(default_factory=list)
    index_file: str = INDEX_FILE
    index_seconds: float = 0.0

    @property
    def n_failed(self) -> int:
        """Runs that failed (fell or could not be computed) or raised."""
        return self.counts.get("failed", 0) + self.counts.get("error", 0)

    @property
    def n_not_computed(self) -> int:
        """Runs that failed without falling or raised: runs with no result of their physics
        (:func:`rbstab.engine.status.computed`; the CLI's exit status 3)."""
        return self.n_failed - self.n_fell

    @property
    def index_path(self) -> Path:
        return self.directory / self.index_file

    @property
    def summary_path(self) -> Path:
        return self.directory / SUMMARY_FILE


@contextlib.contextmanager
def _lock(directory: Path):
    try:
        import fcntl  # optional: POSIX only
    except ImportError:  # pragma: no cover - Windows: no lock
        yield
        return
    path = directory / LOCK_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise SweepBusyError(
                f"another rbstab sweep (pid {holder}) is writing {directory}; wait for it to finish "
                "or choose another output folder"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock


def _remove_temporaries(*folders: Path) -> int:
    """Remove ``.<name>.<random>.tmp`` files left by killed writers (under the lock)."""
    n = 0
    for folder in folders:
        for path in folder.glob(".*.tmp"):
            with contextlib.suppress(OSError):
                path.unlink()
                n += 1
    return n


def _dump_yaml(data: Any) -> str:
    # flow-style lists, the style of the result files' config
    return dump_yaml(data)


def _spec_document(spec: SweepSpec, command_line: str | None) -> dict:
    doc = spec.to_mapping()
    doc["generated"] = {
        "by": f"rbstab {__version__}",
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command_line": command_line if command_line is not None else " ".join(sys.argv),
        "spec_file": str(Path(spec.source).resolve()) if spec.source else None,
        "base_files": [b.source for b in spec.bases],
        "overrides": list(spec.overrides),
        "n_runs": spec.n_runs,
        "run_id": "r<index>-<first 8 hex of sha256 of the run's resolved config without its name>",
        "note": "re-runnable: rbstab sweep <this file> (the overrides are already applied to base)",
    }
    return doc


def _chunk_length(n_runs: int, size: int, per_worker: int, workers: int | None) -> int:
    """Runs per chunk: at most ``size``, and small enough that each worker gets
    ``per_worker`` chunks (:data:`CHUNKS_PER_WORKER` with the default size: the workers
    start while the later runs are still being planned, and finish together)."""
    if workers and workers > 1:
        split = math.ceil(n_runs / (per_worker * workers))
        # but not below MIN_SPLIT_CHUNK runs, unless the workers would not all get one
        size = min(size, max(split, min(MIN_SPLIT_CHUNK, math.ceil(n_runs / workers))))
    return max(1, size)


def _check_time_grids(grids: set, store: str, layout: str, source=None) -> None:
    """Traces in a store file share one time axis: refuse a sweep whose runs differ in it
    (SweepSpecError, ``source`` the spec file)."""
    if layout != "chunk" or store == "summary":
        return
    if len(grids) > 1:
        raise SweepSpecError([
            f"simulation.t_end, simulation.n_samples: found {len(grids)} different sample grids among the runs; "
            f"a store file with traces (store '{store}') holds one: expected one grid, store 'summary' or layout 'run'"
        ], source)


def resolve_engine(engine: str | None, timeout: float | None = None) -> str:
    """The engine a sweep uses: ``engine``, by default ``compiled`` (the CPU engines take a
    per-run ``timeout``; ``cuda`` takes it as each launch's limit).

    Raises
    ------
    ValueError
        For an unknown engine.
    rbstab.engine.cuda.CudaUnavailable
        For ``cuda`` where no GPU, driver or numba-cuda is found.
    """
    resolved = get_engine(engine)
    resolved.check_available()
    return resolved.name


class _NoBar:
    """What :func:`_progress_bar` returns when the bar is off (tqdm not even imported)."""

    def set_postfix_str(self, *args, **kwargs) -> None:
        pass

    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(total: int, name: str, enabled: bool | None):
    if enabled is False:
        return _NoBar()
    from tqdm.auto import tqdm  # heavy: tqdm

    return tqdm(
        total=total,
        desc=name,
        unit="run",
        file=sys.stderr,
        disable=(None if enabled is None else not enabled),
        dynamic_ncols=True,
        smoothing=0.05,
    )


def run_sweep(
    spec: SweepSpec,
    output: str | os.PathLike = DEFAULT_OUTPUT,
    *,
    table=None,
    executor: str | Executor = "local",
    jobs: int | None = None,
    scheduler: str | None = None,
    timeout: float | None = None,
    retry_failed: bool = False,
    chunk_size: int | None = None,
    engine: str | None = None,
    store: str = DEFAULT_STORE,
    layout: str | None = None,
    progress: bool | None = None,
    command_line: str | None = None,
    log: Callable[[str], None] | None = None,
    index: str | None = None,
) -> SweepOutcome:
    """Run every run of ``spec`` that has no current result file, then rebuild the index.

    Parameters
    ----------
    spec : SweepSpec
        From :func:`rbstab.sweep.load_spec`.
    output : path-like
        Parent folder; the sweep writes ``<output>/<spec.name>/``.
    table : rbstab.sweep.table.RunTable, optional
        ``plan_table(spec)`` if already computed (every run validated).
    executor : {"local", "dask"} or Executor
        Where the runs execute (see :mod:`rbstab.sweep.executors`). An executor made
        from a name is closed when the sweep ends; an :class:`Executor` passed in is
        not (the caller closes it, e.g. ``with LocalExecutor(2) as ex:``), so several
        sweeps can share its started workers.
    jobs : int, optional
        Local processes (default: all CPUs); ignored by Dask.
    scheduler : str, optional
        Dask scheduler address (``tcp://HOST:PORT``), required for ``"dask"``.
    timeout : float, optional
        Per-run wall-time limit [s], instead of each run's ``simulation.max_wall_time``; a
        run past it is recorded as failed.
    retry_failed : bool
        Also re-execute runs whose current result file has status ``failed``.
    chunk_size : int, optional
        Most runs per unit of work sent to a worker (and per store file): default
        :data:`STORE_CHUNK_SIZE` with ``layout="chunk"``, else
        the engine's ``chunk_size`` (:data:`rbstab.engine.ENGINES`: 1 for scipy, 256 for compiled);
        by default a sweep is cut into at least :data:`CHUNKS_PER_WORKER` chunks per worker.
    engine : {"compiled", "scipy"}, optional
        Key of :data:`rbstab.engine.ENGINES`; default ``compiled``
        (:func:`resolve_engine`). ``compiled`` integrates
        every run with scipy's RK23/RK45/DOP853 compiled with the model (other methods
        and the pure sign law go through scipy), taking the steps scipy takes.
    store : {"thinned", "full", "summary"}
        What the files hold besides the per-run values (:data:`rbstab.io.chunk.STORES`):
        the variables a report draws at <= 201 samples (default), every variable at every
        sample, or no traces (summary figures from every sample in each case).
    layout : {"chunk", "run"}
        One store file per chunk of runs (default: ``runs/chunk-*.h5``,
        :mod:`rbstab.io.chunk`; a chunk killed midway is rerun whole), or one result file
        per run (``runs/<run_id>.h5``, the format of ``rbstab run``).
    progress : bool, optional
        Progress bar on stderr (done / failed / remaining, ETA); default: when stderr is a
        terminal.
    command_line : str, optional
        Recorded in ``sweep.yaml`` and in every result file (default: ``sys.argv``).
    log : callable, optional
        Receives one-line status messages (the CLI prints them).
    index : {"csv", "arrow"}, optional
        The index files: ``index.arrow`` and ``index.csv`` ("csv"), or ``index.arrow``
        alone ("arrow"); default "csv" up to
        :data:`rbstab.sweep.folder.CSV_INDEX_MAX_RUNS` runs, "arrow" above.

    Returns
    -------
    SweepOutcome

    Raises
    ------
    SweepSpecError
        If a run's configuration is invalid (nothing is run or written).
    SweepBusyError
        If another process is writing the same sweep folder.
    ExecutorError
        If the executor cannot start (``distributed`` missing, scheduler unreachable).
    OSError
        When a file cannot be written for want of space or of a writable disk (ENOSPC,
        EDQUOT, EROFS): the workers are stopped and the index written for what finished
        (if it can be); rerunning resumes.
    KeyboardInterrupt
        Re-raised (SIGTERM too, as the CLI handles it) after the workers were stopped
        and the index written for exactly the files on disk.
    """

    engine = resolve_engine(engine, timeout)
    layout = sweep_layout(spec, layout, store)
    chunking = _chunking(chunk_size, engine, store, layout)
    wants_csv(index, 0)  # a value not allowed: ValueError before anything runs
    table = plan_table(spec) if table is None else table
    _check_time_grids(table.time_grids(), store, layout, spec.source)
    options = WorkerOptions(timeout=timeout, command_line=" ".join(sys.argv) if command_line is None else command_line,
                            engine=engine, store=store, layout=layout, parameters=table.parameters(),
                            sweep=spec.name)
    outcome = SweepOutcome(spec.name, Path(output) / spec.name, spec.n_runs, engine=engine)
    jobs = cuda_jobs(jobs) if get_engine(engine).gpu else jobs
    with _executor(executor, jobs, scheduler) as ex:
        (outcome.directory / RUNS_DIR).mkdir(parents=True, exist_ok=True)
        _run_locked(spec, table, ex, outcome, retry_failed=retry_failed, chunk_size=chunking, progress=progress,
                    say=log or (lambda message: None), options=options, index=index)
    return outcome


def sweep_layout(spec: SweepSpec, layout: str | None = None, store: str = DEFAULT_STORE) -> str:
    """The layout a sweep of ``spec`` with the store ``store`` writes: ``layout``, by
    default ``"chunk"`` (store files); for a sweep of chains whose bases differ in their
    bodies or joints (their names) and a store with traces, ``"run"`` (a result file per
    run: a store file's traces share their ``body`` and ``joint`` dimensions).

    Raises
    ------
    SweepSpecError
        For ``layout="chunk"`` with such bases and a store with traces.
    """
    mixed = spec.is_chain and store != "summary" and len({_chain_names(b.data) for b in spec.bases}) > 1
    if layout is None:
        return "run" if mixed else DEFAULT_LAYOUT
    if layout == "chunk" and mixed:
        raise SweepSpecError([f"layout: found 'chunk' with store '{store}'; the bases are chains with different "
                              "bodies or joints, whose traces a store file cannot share (its body and joint "
                              "dimensions); expected layout 'run' (their default) or store 'summary'"], spec.source)
    return layout


def _chain_names(data: dict) -> tuple:
    """A chain config's body names and joint names (what a store file's dimensions take)."""
    return (tuple(str(b.get("name")) for b in data.get("bodies") or ()),
            tuple(str(j.get("name")) for j in data.get("joints") or ()))


def cuda_jobs(jobs: int | None = None) -> int | None:
    """Worker processes of a ``--engine cuda`` sweep: ``jobs``, by default :data:`CUDA_JOBS`
    at most the CPU count (:func:`rbstab.sweep.executors.default_jobs`); one where the GPU
    is in exclusive-process compute mode (one process at a time may use it)."""
    from ..engine.cuda import compute_mode  # heavy: numba-cuda (--engine cuda only)

    if compute_mode() == "exclusive-process":
        return 1
    return jobs if jobs is not None else min(CUDA_JOBS, default_jobs())


def _executor(executor: str | Executor, jobs: int | None, scheduler: str | None):
    """A context manager giving the sweep's executor: one made from a name (made first: a
    missing package or an unreachable scheduler writes nothing) is closed when it ends;
    one passed in belongs to the caller, whose next sweep finds its workers started."""
    if isinstance(executor, str):
        return make_executor(executor, jobs=jobs, scheduler=scheduler)
    return contextlib.nullcontext(executor)


def _chunking(chunk_size: int | None, engine: str, store: str, layout: str) -> tuple[int, int]:
    """(most runs per chunk, chunks per worker at least) of :func:`run_sweep`'s arguments,
    which it checks; ValueError names the one not allowed."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout: found {layout!r}; expected one of {', '.join(LAYOUTS)}")
    if store not in STORES:
        raise ValueError(f"store: found {store!r}; expected one of {', '.join(STORES)}")
    if chunk_size is None:
        default = STORE_CHUNK_SIZE if layout == "chunk" else get_engine(engine).chunk_size
        if layout == "chunk" and store == "summary":
            default = SUMMARY_CHUNK_SIZE
        if get_engine(engine).gpu:  # a launch fills the GPU with one chunk's runs
            default = CUDA_CHUNK_SIZE.get(store, get_engine(engine).chunk_size)
        return default, CHUNKS_PER_WORKER
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    return chunk_size, 1


def _run_locked(spec, table, ex, outcome, *, retry_failed, chunk_size, progress, say, options, index=None) -> None:
    """Skip what is done, execute the rest and write the index, holding the lock."""
    directory = outcome.directory
    runs_dir = directory / RUNS_DIR
    with _lock(directory):
        stored, current = _resume(spec, table, outcome, options, retry_failed, say)
        results, errors = [] if current is None else [current], {}
        stopped = False
        try:
            _execute(spec, table, _remaining(table, current), runs_dir, results, errors, outcome, ex,
                     chunk_size=chunk_size, progress=progress, say=say, options=options)
        except BaseException:
            # Ctrl-C, SIGTERM, a full disk: stop every worker first, so that the index
            # written below lists exactly the files on disk (nothing is written after it)
            ex.abort()
            _remove_temporaries(runs_dir, directory)
            stopped = True
            raise
        finally:
            if errors or stopped:  # files finished while the pool shut down, or by a worker that then raised
                _take_late(stored, table, runs_dir, results, errors)
            outcome.stale_files = stored.stale(table)
            outcome.warnings = list(table.warnings)
            _finish(spec, table, results, errors, outcome, index)


def _resume(spec, table, outcome, options, retry_failed: bool, say):
    """(the folder's StoredRuns, the current rows of the table's runs or None where the
    folder holds no result file) after removing the
    temporaries of killed writers, writing ``sweep.yaml`` and setting damaged files aside."""
    directory = outcome.directory
    runs_dir = directory / RUNS_DIR
    removed = _remove_temporaries(runs_dir, directory)
    if removed:
        say(f"removed {removed} temporary file(s) left by an interrupted invocation")
    _write_spec_document(spec, directory, options.command_line, say)
    stored = StoredRuns(runs_dir, verify=True, damaged=outcome.damaged)
    for (name, reason), new in zip(outcome.damaged, set_aside_damaged(runs_dir, outcome.damaged)):
        say(f"{reason}; renamed to {RUNS_DIR}/{new}, its runs are rerun")
    # a new sweep's folder holds no file: no table of its rows (pandas, first needed for
    # the workers' rows, after the sweep's first line)
    current = stored.current(table, success_only=retry_failed) if stored.files else None
    outcome.n_skipped = 0 if current is None else len(current)
    return stored, current


def _remaining(table, current):
    """Positions in ``table`` of the runs without a current row (``current``: a DataFrame
    with their ``run``, or None for none), increasing."""
    import numpy as np  # heavy: numpy

    done = np.zeros(table.n, dtype=bool)
    if current is not None:
        done[current["run"].to_numpy()] = True
    return np.flatnonzero(~done)


def _take_late(stored, table, runs_dir: Path, results: list, errors: dict) -> None:
    """The rows of files written after the scan (a pool shutting down, a worker that then
    raised) into ``results``, their runs out of ``errors``."""
    late = StoredRuns(runs_dir, damaged=[], skip=set(stored.files)).current(table)
    results.append(late)
    for rid in late["run_id"]:
        errors.pop(rid, None)


def _write_spec_document(spec: SweepSpec, directory: Path, command_line: str | None, say) -> None:
    doc = _spec_document(spec, command_line)
    if spec.table is not None and spec.table.source is None:  # given in memory: kept beside the spec
        import pandas as pd  # heavy: pandas

        with atomic_path(directory / DESIGN_FILE) as tmp:
            pd.DataFrame(spec.table.columns).to_csv(tmp, index=False)
        doc["table"] = DESIGN_FILE
    spec_path = directory / SPEC_FILE
    if spec_path.exists():
        with contextlib.suppress(Exception):
            old = read_spec(directory)  # within the YAML limits
            old.pop("generated", None)
            new = {k: v for k, v in doc.items() if k != "generated"}
            if yaml.safe_load(_dump_yaml(new)) != old:
                say(f"note: the spec differs from the one in {spec_path}; runs whose config changed are rerun")
    write_text_atomic(spec_path, _dump_yaml(doc))


def _execute(spec, table, todo, runs_dir, results, errors, outcome, ex: Executor, *, chunk_size, progress, say,
             options) -> None:
    """Run the runs at positions ``todo`` of ``table`` in chunks on ``ex``; append each
    chunk's rows to ``results`` (a list of DataFrames) or its runs' messages to ``errors``."""
    folder = str(runs_dir.resolve())
    bar = _progress_bar(spec.n_runs, spec.name, progress)
    bar.update(outcome.n_skipped)
    size = _chunk_length(spec.n_runs, *chunk_size, ex.parallelism())
    if ex.return_bytes:
        options = dataclasses.replace(options, return_bytes=True)
    n_chunks = math.ceil(len(todo) / size)
    ex.plan(n_chunks)  # the caller closes the executor
    outcome.executor = ex.describe()
    per_chunk = "" if size == 1 else f", chunks of up to {size} runs"
    say(f"{outcome.name}: {outcome.n_runs} runs on {outcome.executor} ({options.engine} engine{per_chunk}); "
        "runs with a current result are skipped")
    _import_index_writers()
    parts = (table.slice(todo[lo:lo + size]) for lo in range(0, len(todo), size))
    counts = {"ok": 0, "bad": 0}
    try:
        for part, result, exc in ex.imap_unordered(run_table_chunk, parts, options, folder):
            outcome.n_chunks += 1
            outcome.n_executed += len(part)
            if exc is not None:
                errors.update({rid: f"{type(exc).__name__}: {exc}" for rid in part.run_id})
                counts["bad"] += len(part)
            else:
                _take(result, part, results, errors, outcome, counts)
            bar.set_postfix_str(f"done {counts['ok']}, failed {counts['bad']}", refresh=False)
            bar.update(len(part))
    finally:
        bar.close()
    if outcome.n_executed == 0 and outcome.n_skipped == outcome.n_runs:
        say(f"{spec.name}: all {outcome.n_runs} runs already done; rebuilding the index")


def _import_index_writers() -> None:
    """Import what the rows and the index are written with (pandas, pyarrow; ~0.3 s) before
    the first run: a Ctrl-C or SIGTERM that lands inside an import leaves the module half
    made, and the index written after the interrupt would then fail on it (an
    AttributeError of pandas' C API, exit 1 instead of 130 / 143)."""
    import pandas  # noqa: F401  (heavy: pandas)
    import pyarrow.compute  # noqa: F401  (heavy: pyarrow)
    import pyarrow.csv  # noqa: F401  (heavy: pyarrow)


def _take(result, part, results: list, errors: dict, outcome: SweepOutcome, counts: dict) -> None:
    """A worker's :class:`~rbstab.sweep.worker.ChunkResult` of ``part``: its files written
    (bytes from a remote worker), its rows into ``results``, its runs that raised into ``errors``."""
    if result.errno in _MACHINE_FAULTS:
        raise OSError(result.errno, os.strerror(result.errno), result.path)
    for path, data in result.data.items():
        write_bytes_atomic(path, data)
    frame = result.frame
    if "run" not in frame:  # rows of run files: their position from the run ids
        frame["run"] = frame["run_id"].map(dict(zip(part.run_id.tolist(), part.index.tolist())))
    raised = (frame["status"] == "error").to_numpy()
    errors.update(zip(frame["run_id"][raised], frame["message"][raised].fillna("").replace("", "no result file was written")))
    results.append(frame[~raised])
    outcome.tracebacks.update(result.tracebacks)
    for key, seconds in result.timing.items():
        outcome.timing[key] = outcome.timing.get(key, 0.0) + seconds
    if result.worker_peak_rss:
        outcome.worker_peak_rss = max(outcome.worker_peak_rss or 0, result.worker_peak_rss)
    ok = int((frame["status"] == "success").sum())
    counts["ok"] += ok
    counts["bad"] += len(frame) - ok


#: errno of a result that stops the sweep: every later write would fail the same way.
_MACHINE_FAULTS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS)

#: An in-memory design table is written beside ``sweep.yaml`` under this name.
DESIGN_FILE = "table.csv"


def _finish(spec: SweepSpec, table, results: list, errors: dict, outcome: SweepOutcome,
            index: str | None = None) -> None:
    start = time.perf_counter()
    summary, outcome.problems = write_table_index(outcome.directory, table, _rows_of(results), errors,
                                                  name=spec.name, ratio=spec.lyapunov_ratio, index=index)
    outcome.index_seconds = time.perf_counter() - start
    outcome.index_file = summary["index"]
    outcome.counts = dict(summary["status"])
    outcome.outcomes = dict(summary["outcomes"])
    outcome.n_converged = summary["n_converged"]
    outcome.n_fell = summary["n_fell"]


def _rows_of(results: list):
    """The rows of ``results`` (DataFrames with a ``run`` column) as one DataFrame, the list
    emptied: the chunks' rows are then held once, by the index's writer, which lets them go
    as it builds the index (at 10^6 runs ~0.5 GB less at its peak).

    Chunks finish in any order; where no run has two rows (else the last one counts) the
    frames go in the order of their first run, so that a sweep's rows are usually in the
    order of its runs and the index takes its columns as they are
    (:func:`rbstab.sweep.folder.write_table_index`: no gather of every column)."""
    import pandas as pd  # heavy: pandas

    frames = [f for f in results if len(f)]
    results.clear()
    if not frames:
        return pd.DataFrame()
    if len(frames) > 1 and pd.concat([f["run"] for f in frames], ignore_index=True).is_unique:
        frames.sort(key=lambda f: f["run"].iat[0])
    return pd.concat(frames, ignore_index=True)


def rebuild_index(spec: SweepSpec, output: str | os.PathLike = DEFAULT_OUTPUT, *, table=None,
                  index: str | None = None) -> SweepOutcome:
    """Rewrite the index and ``sweep_summary.json`` from the result files, running nothing.

    Files whose config does not match the run's current config count as ``pending``.
    ``index``: the index files, as for :func:`run_sweep`.
    """

    table = plan_table(spec) if table is None else table
    directory = Path(output) / spec.name
    if not directory.is_dir():
        raise FileNotFoundError(f"no sweep folder {directory}")
    outcome = SweepOutcome(spec.name, directory, table.n)
    with _lock(directory):
        current = StoredRuns(directory / RUNS_DIR).current(table)
        outcome.n_skipped = len(current)
        _finish(spec, table, [current], {}, outcome, index)
    return outcome
