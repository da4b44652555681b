"""Chunk files: many runs of a sweep in one HDF5 file (``rbstab sweep --layout chunk``).

A run file (:mod:`rbstab.io.hdf5`) costs ~10 ms to write whatever its size (HDF5's cost
per object), more than integrating the run; a sweep of 10,000 runs also makes 10,000
files. With ``--layout chunk`` each unit of work a worker executes (a chunk: up to a few
hundred runs that differ only in their initial state) is written as one file
``runs/chunk-<first run_id>-<random>.h5``:

- dimensions ``run`` (the run ids, a coordinate), ``time`` (samples [s]) and ``axis``
  (``x``, ``y``, ``z``);
- every output variable of a run file as ``(run, time[, axis])`` with the same name,
  ``units`` and ``description`` (for ``store = "summary"`` the same subset and stride);
  rows after a failure are NaN, a run that raised (status ``error``) is NaN throughout;
- per run ``(run,)`` or ``(run, axis)``: ``status``, ``message``, ``config`` (the resolved
  configuration as YAML, as in a run file), ``config_hash``, ``wall_time``,
  ``solver_*`` and ``summary_*`` (the run file's attributes of those names);
- global attributes ``rbstab_format`` (:data:`CHUNK_FORMAT`), ``rbstab_version``,
  ``git_commit``, ``command_line``, ``created``, ``store`` (and ``store_stride``),
  ``n_runs``.

Open with ``xarray.open_dataset(path, engine="h5netcdf")``, a whole sweep with
``xarray.open_mfdataset(sorted(glob("runs/chunk-*.h5")), combine="nested",
concat_dim="run", engine="h5netcdf")``. :func:`read_chunk_rows` gives each run's
attributes in the form :func:`rbstab.io.hdf5.read_attributes` gives a run file's (what
the sweep index and resume use), :func:`read_chunk_series` a run's time series.

A chunk file is written like a run file: to a temporary name, renamed when complete;
rows are written in blocks of :data:`WRITE_BLOCK` runs, so a worker holds at most that
many runs' outputs.
"""

from __future__ import annotations

import datetime as _dt
import os
import sys
import uuid
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import __version__
from .atomic import atomic_path
from .hdf5 import (
    STORE_MODES,
    SUMMARY_VARIABLES,
    VARIABLE_DESCRIPTIONS,
    VARIABLE_UNITS,
    NotAResultFile,
    _git_commit,
    _plain,
    result_attributes,
    summary_stride,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..simulate import RunResult

__all__ = [
    "CHUNK_FORMAT",
    "ChunkWriter",
    "chunk_file_name",
    "is_chunk_file",
    "read_chunk_rows",
    "read_chunk_series",
    "WRITE_BLOCK",
]

#: Value of the ``rbstab_format`` attribute of a chunk file.
CHUNK_FORMAT = "rbstab-chunk-1"
#: Runs buffered before their rows are written (bounds a writer's memory).
WRITE_BLOCK = 32
#: Per-run attributes of a run file stored as ``(run,)`` variables of text (with
#: ``wall_time``, ``solver_*`` and ``summary_*``: :func:`_is_per_run`).
_TEXT = ("variant", "status", "message", "config", "config_hash", "solver_message")
_PER_RUN_DESCRIPTIONS = {
    "variant": "controller variant (controller.variant)",
    "status": "success, failed (gimbal lock, solver failure, non-finite state) or error (the worker raised)",
    "message": "the solver's message, or why the run failed",
    "config": "the run's resolved configuration (YAML), as in a run file",
    "config_hash": "SHA-256 of config",
    "wall_time": "integration plus post-processing time (s)",
}


def chunk_file_name(first_run_id: str) -> str:
    """``chunk-<first_run_id>-<8 random hex>.h5``: unique, sorted by run order."""
    return f"chunk-{first_run_id}-{uuid.uuid4().hex[:8]}.h5"


class ChunkWriter:
    """Write the runs of one chunk into one file (module docstring), atomically.

    Use as a context manager: rows are added with :meth:`add` (a finished run) or
    :meth:`add_error` (a run that raised); leaving the block without an exception
    writes the per-run variables and renames the file into place; an exception removes
    the temporary file and leaves ``path`` untouched.

    Parameters
    ----------
    path : path-like
        Final file name (:func:`chunk_file_name` in the sweep's ``runs/`` folder).
    n_runs : int
        Rows of the file (the chunk's runs); every row must be added.
    store : {"full", "summary"}
        What each row holds (:data:`rbstab.io.hdf5.STORE_MODES`).
    command_line : str, optional
        The ``command_line`` attribute (default: this process's argv).
    """

    def __init__(self, path: str | os.PathLike, n_runs: int, *, store: str = "full",
                 command_line: str | None = None) -> None:
        if store not in STORE_MODES:
            raise ValueError(f"store: found {store!r}; expected one of {', '.join(STORE_MODES)}")
        self.path = Path(path)
        self.n_runs = int(n_runs)
        self.store = store
        self.command_line = command_line if command_line is not None else " ".join(sys.argv)
        self.rows: list[dict[str, Any]] = []  # per-row attributes, in row order
        self._pending: list[dict[str, np.ndarray] | None] = []  # outputs not yet written
        self._stack = ExitStack()
        self._file = None
        self._time: np.ndarray | None = None
        self._stride = 1
        self._variables: dict[str, tuple[int, ...]] = {}
        self._datasets: dict[str, Any] = {}
        self._written = 0
        self.attrs: dict[str, Any] = {  # the file's global attributes
            "rbstab_format": CHUNK_FORMAT,
            "rbstab_version": __version__,
            "git_commit": _git_commit(),
            "command_line": self.command_line,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="microseconds"),
            "store": store,
            "n_runs": self.n_runs,
        }

    # -- context manager ------------------------------------------------------------------------

    def __enter__(self) -> "ChunkWriter":
        import h5py

        tmp = self._stack.enter_context(atomic_path(self.path))
        self._file = self._stack.enter_context(h5py.File(tmp, "w", track_order=True))
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if exc_type is None:
                self._finish()
        except BaseException:
            self._stack.__exit__(*sys.exc_info())
            raise
        return self._stack.__exit__(exc_type, exc, tb)

    # -- rows -----------------------------------------------------------------------------------

    def add(self, result: "RunResult", config_yaml: str | None = None) -> dict[str, Any]:
        """Add a finished run (any status); returns its row attributes (:func:`read_chunk_rows`)."""
        attrs = result_attributes(result, command_line=self.command_line, store=self.store,
                                  config_yaml=config_yaml)
        if self._time is None:
            self._start(result)
        outputs = {k: result.outputs[k][:: self._stride] for k in self._variables if k in result.outputs}
        return self._add_row(attrs, outputs)

    def add_error(self, run_id: str, message: str, config_yaml: str = "", config_hash: str = "") -> dict[str, Any]:
        """Add a run that raised before it had a result (status ``error``, NaN data)."""
        attrs = {"name": run_id, "status": "error", "message": message, "config": config_yaml,
                 "config_hash": config_hash, "wall_time": 0.0}
        return self._add_row(attrs, None)

    def _add_row(self, attrs: dict[str, Any], outputs: dict[str, np.ndarray] | None) -> dict[str, Any]:
        if len(self.rows) >= self.n_runs:
            raise ValueError(f"{self.path.name}: more than the {self.n_runs} rows announced")
        row = {k: _plain(np.asarray(v)) if isinstance(v, (list, tuple, np.ndarray)) else v for k, v in attrs.items()}
        row.update(self.attrs)  # as read_chunk_rows gives it back
        row["row"] = len(self.rows)
        row["file"] = self.path.name
        self.rows.append(row)
        self._pending.append(outputs)
        if len(self._pending) >= WRITE_BLOCK:
            self._flush()
        return dict(row)

    def _start(self, result: "RunResult") -> None:
        """Create the dimensions and the (run, time[, axis]) variables from the first result."""
        time = np.asarray(result.time, dtype=float)
        keys = [k for k in result.outputs if self.store == "full" or k in SUMMARY_VARIABLES]
        if self.store == "summary":
            self._stride = summary_stride(len(time))
        self._time = time[:: self._stride]
        if self.store == "summary":
            self.attrs["store_stride"] = self._stride
        nt = len(self._time)
        for key in keys:
            shape = (self.n_runs, nt, *np.shape(result.outputs[key])[1:])
            self._variables[key] = shape
            # HDF5 chunks of WRITE_BLOCK runs: each flush writes whole chunks
            self._datasets[key] = self._file.create_dataset(
                key, shape=shape, dtype=float, fillvalue=np.nan, chunks=(min(WRITE_BLOCK, self.n_runs), *shape[1:]))

    def _flush(self) -> None:
        if not self._pending:
            return
        lo, hi = self._written, self._written + len(self._pending)
        for key, shape in self._variables.items():
            missing = np.full(shape[1:], np.nan)
            block = np.stack([missing if o is None or key not in o else o[key] for o in self._pending])
            self._datasets[key][lo:hi] = block
        self._written = hi
        self._pending = []

    def _finish(self) -> None:
        import h5py

        if len(self.rows) != self.n_runs:
            raise ValueError(f"{self.path.name}: {len(self.rows)} rows added, {self.n_runs} announced")
        self._flush()
        f = self._file
        text = h5py.string_dtype()
        run = f.create_dataset("run", data=np.array([r["name"] for r in self.rows], dtype=object), dtype=text)
        run.make_scale("run")
        run.attrs["description"] = "run id (the run's name; the file stem of a run file)"
        time = f.create_dataset("time", data=self._time if self._time is not None else np.zeros(0))
        time.make_scale("time")
        time.attrs["units"] = "s"
        time.attrs["description"] = "sample time, evenly spaced dense output of the solver"
        axis = f.create_dataset("axis", data=np.array(["x", "y", "z"], dtype=object), dtype=text)
        axis.make_scale("axis")
        axis.attrs["description"] = "vector component; frame given by each variable"
        for key in self._variables:
            var = f[key]
            var.dims[0].attach_scale(run)
            var.dims[1].attach_scale(time)
            if var.ndim == 3:
                var.dims[2].attach_scale(axis)
            var.attrs["units"] = VARIABLE_UNITS[key]
            var.attrs["description"] = VARIABLE_DESCRIPTIONS[key]
        for key in self._per_run_keys():
            values = [r.get(key) for r in self.rows]
            if key in _TEXT or any(isinstance(v, str) for v in values):
                data = np.array(["" if v is None else str(v) for v in values], dtype=object)
                var = f.create_dataset(key, data=data, dtype=text)
            else:
                width = max((len(v) for v in values if isinstance(v, list)), default=0)
                fill = [np.nan] * width if width else np.nan
                data = np.array([fill if v is None else v for v in values], dtype=float)
                if key.startswith("solver_") and np.all(np.isfinite(data)):
                    data = data.astype(np.int64)
                var = f.create_dataset(key, data=data)
                if var.ndim == 2 and var.shape[1] == 3:
                    var.dims[1].attach_scale(axis)
            var.dims[0].attach_scale(run)
            if key in _PER_RUN_DESCRIPTIONS:
                var.attrs["description"] = _PER_RUN_DESCRIPTIONS[key]
        for key, value in self.attrs.items():
            f.attrs[key] = value

    def _per_run_keys(self) -> list[str]:
        keys: dict[str, None] = {}
        for row in self.rows:
            keys.update(dict.fromkeys(k for k in row if _is_per_run(k)))
        return list(keys)


def is_chunk_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a readable chunk file (``rbstab_format`` = :data:`CHUNK_FORMAT`)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return _plain(f.attrs.get("rbstab_format")) == CHUNK_FORMAT
    except (OSError, ValueError):
        return False


def read_chunk_rows(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Each run's attributes, as :func:`rbstab.io.hdf5.read_attributes` reads a run file's.

    Returns
    -------
    list of dict
        In row order: ``name`` (the run id), ``status``, ``message``, ``config``,
        ``config_hash``, ``wall_time``, ``solver_*``, ``summary_*`` (3-vectors as lists),
        the file's global attributes, and ``file`` (the file name) and ``row``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotAResultFile
        If it is not an rbstab chunk file.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such result file: {path}")
    try:
        with h5py.File(path, "r") as f:
            glob = {k: _plain(v) for k, v in f.attrs.items()}
            if glob.get("rbstab_format") != CHUNK_FORMAT:
                raise NotAResultFile(f"{path}: not an rbstab chunk file (no rbstab_format = {CHUNK_FORMAT!r})")
            ids = [_plain(x) for x in f["run"][...]]
            columns: dict[str, list] = {}
            for key in f:
                if _is_per_run(key):
                    values = f[key][...]
                    columns[key] = values.tolist() if values.ndim == 2 else [_plain(x) for x in values]
    except OSError as exc:
        raise NotAResultFile(f"{path}: not an HDF5 file ({exc})") from None
    rows = []
    for i, run_id in enumerate(ids):
        row = dict(glob)
        row.update({k: v[i] for k, v in columns.items()})
        row.update(name=run_id, row=i, file=path.name)
        rows.append(row)
    return rows


def _is_per_run(key: str) -> bool:
    """Whether variable ``key`` of a chunk file is a per-run attribute (not a time series)."""
    return key in _TEXT or key == "wall_time" or key.startswith(("solver_", "summary_"))


def read_chunk_series(path: str | os.PathLike, row: int, names) -> dict[str, np.ndarray | None]:
    """The time series of one run of a chunk file.

    Parameters
    ----------
    path : path-like
        A chunk file (:func:`is_chunk_file`).
    row : int
        The run's row (``file_row`` in the sweep's ``index.csv``).
    names : iterable of str
        Output variables (:data:`rbstab.io.hdf5.VARIABLE_UNITS` keys).

    Returns
    -------
    dict
        ``time``: sample times [s], shape (n,); each name: its values, shape (n,) or
        (n, 3) in the variable's frame, or None when the file does not hold it (e.g.
        ``store = "summary"``); ``units:<name>``: its units (str) for each name held.

    Raises
    ------
    OSError
        If ``path`` cannot be opened as HDF5.
    """
    import h5py

    out: dict[str, Any] = {}
    with h5py.File(path, "r") as f:
        out["time"] = np.asarray(f["time"][...], dtype=float)
        for name in names:
            if name in f and f[name].ndim >= 2 and f[name].shape[0] > row and name != "time":
                out[name] = np.asarray(f[name][row], dtype=float)
                units = f[name].attrs.get("units", "")
                out[f"units:{name}"] = units.decode() if isinstance(units, bytes) else str(units)
            else:
                out[name] = None
    return out
