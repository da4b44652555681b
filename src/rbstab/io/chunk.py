"""Sweep store files: many runs of a sweep in one netCDF-4 file with a ``run`` dimension.

The default store of ``rbstab sweep`` (``--layout chunk``). Each unit of work a worker
executes (a chunk of up to a few hundred runs, any runs) is written as one file
``runs/chunk-<first run_id>-<random>.h5`` (the file, its dimensions and coordinates by
h5netcdf, the variables by h5py with the dimension scales attached), a netCDF-4 file (HDF5
with dimension scales) that ``ncdump``, ``xarray.open_dataset(p, engine="h5netcdf")``
and ``xarray.open_mfdataset(paths, engine="h5netcdf", join="outer", compat="no_conflicts")``
read (the files of a sweep of several variants hold different variables):

- dimension ``run``, its coordinate the run's position in the sweep's run list (int,
  increasing within a file, so ``open_mfdataset`` orders files by it); coordinates along
  ``run``: ``run_id``, ``base``, ``variant`` and every varied parameter under its
  identifier name (``k_c_0`` for ``controller.k_c.0``, see
  :func:`rbstab.sweep.folder.parameter_name`; attribute ``config_key`` gives the key);
- per run ``(run,)``: ``status``, ``message``, ``wall_time``, ``solver_nfev`` ...,
  ``config_hash`` (the run's identity) and the summary figures of
  :func:`rbstab.summary.summarize`, 3-vectors as ``<name>_x``, ``_y``, ``_z``, each with
  ``long_name`` and (numbers) ``units`` (:mod:`rbstab.io.metadata`); the configurations
  once, as the ``run_templates`` attribute (canonical JSON), with each run's ``template``
  (a sweep's files; :func:`resolved_config` rebuilds a run's), or, for a writer given no
  templates, ``config`` (each run's resolved configuration, canonical JSON);
- traces per :data:`STORES`: ``full`` every output variable at every sample as ``(run,
  time[, axis])``, a chain's per body and per joint as ``(run, time, body|joint[, axis])``
  with the names as the ``body`` and ``joint`` coordinates (:func:`trace_dimensions`: one
  chain's runs a file); ``thinned`` the variables a report draws (:data:`THINNED_VARIABLES`;
  a chain's :data:`rbstab.io.hdf5.CHAIN_SUMMARY_VARIABLES`) at
  every ``store_stride``-th sample (at most 201); ``summary`` none (no ``time``
  dimension). A run that failed has NaN after its last sample; one that raised is NaN.
- global attributes ``rbstab_format`` (:data:`CHUNK_FORMAT`), the provenance
  (:func:`rbstab.io.metadata.provenance_attributes`: ``Conventions``, ``title``,
  ``history``, ``command_line``, ``created``, ``rbstab_version``, ``git_commit``,
  ``git_dirty``, library versions), ``store`` (``store_stride``), ``sweep``.

A file is written to a temporary name and renamed when complete; trace rows are written
in blocks of about :data:`WRITE_BYTES`, so a writer holds at most that much of its traces.
Every numeric variable carries a Fletcher-32 checksum and the file the SHA-256 of its
attributes and text (``rbstab_digest``); :func:`read_chunk_rows` verifies the digest and
the per-run values, :func:`rbstab.io.integrity.verify_file` everything.
:func:`read_chunk_rows` gives each run's per-run values (what resume and the index use),
:func:`read_chunk_series` one run's traces (or all runs').
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import math
import os
import re
import sys
import uuid
from collections.abc import Iterable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import canonical_config, config_hash
from ..layout import SUMMARY_FIGURES as SUMMARY_QUANTITIES
from ..results import RunBlock, RunResult
from .atomic import as_os_error, atomic_path, check_free_space
from .hdf5 import (BODY_VARIABLES, CHAIN_SUMMARY_VARIABLES, SUMMARY_VARIABLES, TREE_VARIABLES, NotAResultFile,
                   attribute_value, summary_stride)
from .integrity import (DATA_DIGEST_ATTR, DIGEST_ATTR, DamagedResultError, content_digest, data_digest, data_digest_of,
                        fletcher32_chunks, open_result, reading, verify_open_file)
from .metadata import PER_RUN, SUMMARY_FIGURES, provenance_attributes, variable_attributes

__all__ = [
    "CHUNK_FORMAT",
    "READ_FORMATS",
    "STORES",
    "DEFAULT_STORE",
    "THINNED_VARIABLES",
    "StoreRow",
    "StoreRows",
    "ChunkWriter",
    "chunk_file_name",
    "is_chunk_file",
    "read_chunk_rows",
    "read_chunk_series",
    "read_chunk_columns",
    "resolved_config",
    "resolved_configs",
    "StoreTrace",
    "store_trace_shapes",
    "store_trace_dimensions",
    "trace_dimensions",
    "summary_columns",
    "summary_from_columns",
    "summary_table_columns",
    "store_bytes_per_run",
    "SUMMARY_FIGURES",
    "split_figure_column",
    "WRITE_BLOCK",
]

#: Value of the ``rbstab_format`` attribute of a store file this version writes.
CHUNK_FORMAT = "rbstab-sweep-3"
#: Store formats this version reads: ``rbstab-sweep-2`` held text as variable-length
#: strings, ``rbstab-sweep-3`` as compressed characters.
READ_FORMATS = ("rbstab-sweep-2", CHUNK_FORMAT)
#: What a store file holds per run besides the per-run values (``rbstab sweep --store``).
STORES = ("full", "thinned", "summary")
#: ``--store`` default: the traces a report draws at <= 201 samples (see docs/sweeps.md).
DEFAULT_STORE = "thinned"
#: Variables of a ``thinned`` store (the state blocks, E, v and its rates).
THINNED_VARIABLES = SUMMARY_VARIABLES
#: Bytes of traces buffered before they are written (bounds a writer's memory; writing
#: few large blocks is what makes a store file cheap per run).
WRITE_BYTES = 32 * 2**20
#: Fewest runs per written block (and HDF5 chunk along ``run``).
WRITE_BLOCK = 32
#: Free space [bytes] a writer keeps beyond what it is about to hand to HDF5 (its metadata,
#: another writer on the same disk): HDF5 must never meet a full disk, see :meth:`ChunkWriter._room`.
SPACE_MARGIN = 8 * 2**20
_AXES = ("x", "y", "z")

_COORDS = ("run_id", "base", "variant")
_TEXT = {"run_id", "base", "variant", "status", "message", "config", "config_hash", "lyapunov_rate_check"}
_SOLVER = ("nfev", "njev", "nlu", "status")
_NUMBERS = {float, int, type(None)}
#: Names of the character dimensions of text variables.
_STRING_DIM = re.compile(r"string\d+")


def _put_attributes(obj_id, attrs: Mapping[str, Any], written: dict | None = None) -> None:
    """Add attributes to an HDF5 group or dataset (its h5py id: ``obj.id``) that does not
    have them yet, as ``h5py``'s ``attrs[key] = value`` stores them: str as
    variable-length UTF-8, int and float as 64-bit scalars, anything else through
    ``attrs``. Through h5py's low-level API: ``attrs[...] =`` writes a temporary attribute
    and renames it, several times the cost (~55 against ~8 us an attribute; a store file
    has ~200).

    ``written``: key -> the array written, for the str, int and float values (what
    :func:`rbstab.io.integrity.content_digest` would read back).
    """
    import h5py  # heavy: h5py

    str_type, scalar = _h5_constants()
    for key, value in attrs.items():
        if isinstance(value, str):
            tid, data = str_type, np.array(value, dtype=h5py.string_dtype())
        elif type(value) in (int, float):
            data = np.array(value, dtype=np.int64 if type(value) is int else np.float64)
            tid = h5py.h5t.py_create(data.dtype)
        else:
            h5py.AttributeManager(h5py.Group(obj_id) if isinstance(obj_id, h5py.h5g.GroupID) else
                                  h5py.Dataset(obj_id))[key] = value
            continue
        aid = h5py.h5a.create(obj_id, key.encode(), tid, scalar)
        try:
            aid.write(data)
        finally:
            aid.close()
        if written is not None:
            written[key] = data


@functools.cache
def _h5_constants() -> tuple:
    """(variable-length UTF-8 string type, scalar space) of :func:`_put_attributes`, made once."""
    import h5py  # heavy: h5py

    return h5py.h5t.py_create(h5py.string_dtype(), logical=True), h5py.h5s.create(h5py.h5s.SCALAR)


#: Bytes a run takes in a store file beside its traces (its per-run values, the index's
#: columns; measured on Case 3 parameter sweeps, benchmarks/sweep_store.py).
VALUE_BYTES = 350
#: Trace values a sample of a thinned store holds (the 5 state blocks, E: 3 each; v, dv/dt
#: analytic and numerical) and of a full store (every output variable).
_THINNED_VALUES, _FULL_VALUES = 18, 40


def store_bytes_per_run(store: str, n_samples):
    """Bytes a run takes in a store file of kind ``store`` (:data:`STORES`) with
    ``n_samples`` output samples (a number or an array of them), roughly."""
    samples = np.asarray(n_samples, dtype=float)
    if store == "summary":
        return VALUE_BYTES + 0 * samples
    if store == "thinned":
        return VALUE_BYTES + 8 * _THINNED_VALUES * np.minimum(samples, 201)
    return VALUE_BYTES + 8 * _FULL_VALUES * samples


def summary_columns(summary: Mapping[str, Any], joints: Sequence[str] | None = None,
                    bodies: Sequence[str] | None = None) -> dict[str, Any]:
    """Summary figures as flat columns: one body's 3-vectors as ``<name>_x``, ``_y``, ``_z``;
    a tree's (``joints``, ``bodies``: its joint and body names) per joint or per body
    (the figure's member, :data:`rbstab.layout.SUMMARY_FIGURES`) as ``<name>_<member>``,
    their 3-vectors as ``<name>_<member>_<axis>`` (``final_theta_trunk_x``)."""
    out: dict[str, Any] = {}
    for key, value in summary.items():
        if isinstance(value, (list, tuple, np.ndarray)):
            values = np.asarray(value, dtype=float)
            for column, at in _figure_columns(key, values.ndim, joints, bodies):
                out[column] = float(values[at])
        else:
            out[key] = value
    return out


def summary_from_columns(row: Mapping[str, Any], joints: Sequence[str] | None = None,
                         bodies: Sequence[str] | None = None) -> dict[str, Any]:
    """The summary figures a row of :func:`summary_columns`' columns holds, as the run's
    summary gives them (its inverse): a scalar as it is, one body's 3-vector as 3 floats, a
    tree's (``joints``, ``bodies``: its joint and body names) per member as a float or 3 a
    member; NaN for an entry the row lacks (None) of a figure it has; figures with no
    column left out."""
    out: dict[str, Any] = {}
    for key in SUMMARY_QUANTITIES:
        if key in row:
            out[key] = math.nan if row[key] is None else row[key]
            continue
        for ndim in (1,) if joints is None else (2, 1):
            columns = _figure_columns(key, ndim, joints, bodies)
            if any(row.get(column) is not None for column, _ in columns):
                value = np.full([max(at[d] for _, at in columns) + 1 for d in range(ndim)], math.nan)
                for column, at in columns:
                    if row.get(column) is not None:
                        value[at] = row[column]
                out[key] = value.tolist()
                break
    return out


def split_figure_column(column: str, bodies: Sequence[str] = (), joints: Sequence[str] = ()
                        ) -> tuple[str, str | None, str | None] | None:
    """(figure, member, axis) of a summary column as :func:`summary_columns` names it:
    ``<figure>``, ``<figure>_<axis>``, and a tree's (its ``bodies`` and ``joints`` names,
    by the figure's member, :data:`rbstab.layout.SUMMARY_FIGURES`) ``<figure>_<member>``
    and ``<figure>_<member>_<axis>``; member and axis None where absent. None for a name
    that is none of these (an unknown figure, a member the tree lacks)."""
    if column in SUMMARY_QUANTITIES:
        return column, None, None
    for figure in sorted((f for f in SUMMARY_QUANTITIES if column.startswith(f"{f}_")), key=len, reverse=True):
        rest = column[len(figure) + 1:]
        if rest in _AXES:
            return figure, None, rest
        members = bodies if SUMMARY_QUANTITIES[figure].member == "body" else joints
        member, _, axis = rest.rpartition("_")
        if rest in members:
            return figure, rest, None
        if axis in _AXES and member in members:
            return figure, member, axis
    return None


def summary_table_columns(table: Mapping[str, Sequence], joints: Sequence[str] | None = None,
                          bodies: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """:func:`summary_columns` of k runs at once, from :func:`rbstab.summary.summary_table`
    (figure -> k values, shape (k,), (k, 3), or a tree's (k, n_members[, 3])): column -> its
    k values, shape (k,)."""
    out: dict[str, np.ndarray] = {}
    for key, values in table.items():
        values = np.asarray(values)
        if values.ndim >= 2:
            for column, at in _figure_columns(key, values.ndim - 1, joints, bodies):
                out[column] = values[(slice(None), *at)]
        else:
            out[key] = values
    return out


def _figure_columns(key: str, ndim: int, joints: Sequence[str] | None, bodies: Sequence[str] | None):
    """(column name, index into one run's value) of each entry of the figure ``key`` whose
    value a run has ``ndim`` dimensions: one body's axes, or a tree's members (and axes).

    Raises
    ------
    ValueError
        For a tree's figure per body without the body names ``bodies``."""
    if joints is None:
        return [(f"{key}_{axis}", (a,)) for a, axis in enumerate(_AXES)]
    quantity = SUMMARY_QUANTITIES.get(key)
    members = bodies if quantity is not None and quantity.member == "body" else joints
    if members is None:
        raise ValueError(f"summary figure {key!r} is one per body: its columns need the chain's body names")
    if ndim == 1:
        return [(f"{key}_{m}", (i,)) for i, m in enumerate(members)]
    return [(f"{key}_{m}_{axis}", (i, a)) for i, m in enumerate(members) for a, axis in enumerate(_AXES)]


def _has_text(values: np.ndarray) -> bool:
    """Whether a ``(run,)`` column holds a str (its types looked at once: most hold numbers)."""
    if values.dtype.kind in "US":
        return True
    return values.dtype.kind == "O" and any(issubclass(t, str) for t in set(map(type, values.tolist())) - _NUMBERS)


def figure_attributes(column: str) -> tuple[str, str]:
    """(units, long name) of a per-run column (:data:`PER_RUN`, or a summary figure, its
    component ``<name>_<axis>`` or a tree's ``<name>_<member>[_<axis>]``,
    :func:`summary_columns`)."""
    if column in PER_RUN:
        return PER_RUN[column]
    if column in SUMMARY_FIGURES:
        return SUMMARY_FIGURES[column]
    bases = [f for f in SUMMARY_FIGURES if column.startswith(f"{f}_")]
    if not bases:
        return "", column
    base = max(bases, key=len)
    units, name = SUMMARY_FIGURES[base]
    member, _, axis = column[len(base) + 1:].rpartition("_")
    if axis not in _AXES:
        member, axis = column[len(base) + 1:], ""
    return units, ", ".join(w for w in (name, member, axis and f"{axis} component") if w)


@dataclass(frozen=True)
class StoreRow:
    """Identity of one run in a store file.

    Attributes
    ----------
    index : int
        Position in the sweep's run list (the ``run`` coordinate).
    run_id : str
    base : str
    coords : dict
        Parameter coordinate name -> value (a number or a string).
    template : int
        Its configuration's template among the writer's ``templates`` (-1: none).
    """

    index: int
    run_id: str
    base: str = ""
    coords: dict = field(default_factory=dict)
    template: int = -1


@dataclass(frozen=True)
class StoreRows:
    """Identity of the runs of a store file, as columns (k runs, any order).

    Attributes
    ----------
    index : ndarray of int, shape (k,)
        Position of each run in the sweep's run list (the ``run`` coordinate).
    run_id, base : ndarray of object (str), shape (k,)
    coords : dict of str to ndarray, shape (k,)
        Parameter coordinate name -> each run's value (a number or a string; None or NaN
        where a run has none).
    template : ndarray of int, shape (k,)
        Each run's template among the writer's ``templates`` (-1: none).
    """

    index: np.ndarray
    run_id: np.ndarray
    base: np.ndarray
    coords: dict
    template: np.ndarray

    def __len__(self) -> int:
        return len(self.index)

    @classmethod
    def of(cls, rows: Sequence[StoreRow]) -> "StoreRows":
        """The columns of ``rows``."""
        names = dict.fromkeys(name for r in rows for name in r.coords)
        return cls(np.array([r.index for r in rows], dtype=np.int64), _objects([r.run_id for r in rows]),
                   _objects([r.base for r in rows]),
                   {name: _objects([r.coords.get(name) for r in rows]) for name in names},
                   np.array([r.template for r in rows], dtype=np.int64))

    def ordered(self) -> "StoreRows":
        """The same runs by increasing ``index`` (a file's row order)."""
        order = np.argsort(self.index, kind="stable")
        if np.all(order == np.arange(len(order))):
            return self
        return StoreRows(self.index[order], self.run_id[order], self.base[order],
                         {name: values[order] for name, values in self.coords.items()}, self.template[order])


def _objects(values: Sequence) -> np.ndarray:
    """``values`` as a 1-d object array (whatever they are: str, numbers, None)."""
    out = np.empty(len(values), dtype=object)
    out[:] = values
    return out


def _merged(n: int, parts: Sequence[tuple[Any, np.ndarray]]) -> np.ndarray:
    """A column of n rows from ``parts`` (rows, their values), later parts winning: an
    object array (None where no part gives a value) if any part holds text, else float
    (NaN where none does)."""
    text = any(_has_text(np.asarray(values)) for _, values in parts)
    column = np.full(n, None, dtype=object) if text else np.full(n, np.nan)
    for rows, values in parts:
        column[rows] = values if text else np.asarray(values, dtype=float)
    return column


def _as_stored(name: str, values: np.ndarray) -> np.ndarray:
    """A ``(run,)`` column as a store file holds it: text as str (an object array, "" for
    None), numbers as float (None -> NaN), solver counts as int where every run has one."""
    if name in _TEXT or _has_text(values):
        text = np.asarray(values, dtype=object)
        return np.where(text == None, "", text)  # noqa: E711
    data = np.asarray(values, dtype=float)
    if name.startswith("solver_") and np.all(np.isfinite(data)):
        data = data.astype(np.int64)
    return data


def trace_dimensions(block) -> tuple[dict[str, tuple[str, ...]], dict[str, tuple[str, ...]]]:
    """(output name -> its dimensions after ``run``, a chain's dimension -> its names) of
    the traces of a :class:`rbstab.results.RunBlock`: ``("time",)`` for a scalar a
    sample, ``("time", "axis")`` for a vector; a chain's per-body outputs ``("time",
    "body", "axis")`` (:data:`rbstab.io.hdf5.BODY_VARIABLES`), its per-joint ones ``("time",
    "joint"[, "axis"])``, as in a chain's run file; labels ``body`` and ``joint`` with the
    chain's names (none for one body)."""
    chain = block.joints is not None
    dims: dict[str, tuple[str, ...]] = {}
    for name, value in block.outputs.items():
        extra = np.ndim(value) - 2  # the dimensions after (run, time)
        if chain and extra >= 1 and name not in TREE_VARIABLES:
            dims[name] = ("time", "body" if name in BODY_VARIABLES else "joint", "axis")[: extra + 1]
        else:
            dims[name] = ("time", "axis")[: extra + 1]
    labels = {"body": tuple(block.bodies), "joint": tuple(block.joints)} if chain else {}
    return dims, labels


def chunk_file_name(first_run_id: str) -> str:
    """``chunk-<first_run_id>-<8 random hex>.h5``: unique, sorted by run order."""
    return f"chunk-{first_run_id}-{uuid.uuid4().hex[:8]}.h5"


class ChunkWriter:
    """Write the runs of one chunk into one store file (module docstring), atomically.

    Use as a context manager: :meth:`add` a finished run (any status), :meth:`add_block`
    finished runs that share their sample times (:class:`rbstab.results.RunBlock`: their
    traces copied at once, their values kept as columns) or :meth:`add_error` a run that
    raised, once per row; leaving the block without an
    exception writes the per-run values and renames the file into place; an exception
    removes the temporary file.

    Parameters
    ----------
    path : path-like
        Final file name (:func:`chunk_file_name` in the sweep's ``runs/`` folder).
    rows : sequence of StoreRow
        The chunk's runs, any order (the file holds them by increasing ``index``).
    store : {"full", "thinned", "summary"}
        See :data:`STORES`.
    parameters : mapping, optional
        Coordinate name -> dotted config key, for the ``config_key`` attributes.
    command_line : str, optional
        The ``command_line`` attribute (default: this process's argv).
    sweep : str, optional
        The ``sweep`` attribute (the sweep's name).
    templates : sequence of dict, optional
        Resolved configurations (without ``name``) the rows' configurations start from:
        stored once, as the ``run_templates`` attribute (canonical JSON), with a
        ``template`` variable; a run's configuration is its template with its numeric
        parameter coordinates set at their ``config_key`` (:func:`resolved_config`).
    """

    def __init__(self, path: str | os.PathLike, rows: Sequence[StoreRow] | StoreRows, *, store: str = DEFAULT_STORE,
                 parameters: Mapping[str, str] | None = None, command_line: str | None = None,
                 sweep: str = "", templates: Sequence[Mapping] = ()) -> None:
        if store not in STORES:
            raise ValueError(f"store: found {store!r}; expected one of {', '.join(STORES)}")
        self.path = Path(path)
        self.store = store
        self.parameters = dict(parameters or {})
        self.identity = (rows if isinstance(rows, StoreRows) else StoreRows.of(rows)).ordered()
        self.ids = self.identity.run_id
        self.position = dict(zip(self.ids.tolist(), range(len(self.ids))))
        n = len(self.ids)
        self._blocks: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []  # (rows, column -> a value a row) added
        self._block_of = np.full(n, -1, dtype=np.int64)  # row -> its block once added
        self._stored: dict[str, np.ndarray] | None = None  # the per-run columns as written, once finished
        self._place = np.zeros(n, dtype=np.int64)  # row -> its position in its block
        self._pending: list[int] = []  # rows whose traces are in the buffer's first rows, in that order
        self._buffer: dict[str, np.ndarray] = {}  # variable -> (rows, *trace shape), written at each flush
        self._stack = ExitStack()
        self._file = None
        self._time: np.ndarray | None = None
        self._checked_time: np.ndarray | None = None  # a read-only time array found equal to _time
        self._stride = 1
        self._traces: dict[str, tuple[int, ...]] = {}
        self._datasets: dict[str, Any] = {}
        self._numbers: dict[str, np.ndarray] = {}  # numeric variables written whole, for the digest
        self._texts: dict[str, np.ndarray] = {}  # text variables as written, for the digest
        self._written: dict[str, dict] = {}  # object path -> attributes as written, for the digest
        self._kinds: dict[str, tuple] = {}  # dtype kind -> (HDF5 type, creation properties) of a column
        self._block = WRITE_BLOCK
        created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="microseconds")
        self.attrs: dict[str, Any] = {
            "rbstab_format": CHUNK_FORMAT,
            **provenance_attributes(f"rbstab sweep {sweep or '(unnamed)'}: store file of its runs",
                                    command_line=command_line, created=created),
            "store": store,
            "sweep": sweep,
        }
        if templates:
            self.attrs["run_templates"] = "[" + ",".join(canonical_config(t, limits=True) for t in templates) + "]"

    def __enter__(self) -> "ChunkWriter":
        import h5netcdf  # heavy: h5netcdf

        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._room(0)
        tmp = self._stack.enter_context(atomic_path(self.path))
        self._file = self._stack.enter_context(h5netcdf.File(tmp, "w"))
        import h5py  # heavy: h5py

        self._str = h5py.string_dtype()
        f = self._file
        f.dimensions["run"] = len(self.ids)
        f.dimensions["axis"] = 3
        # coordinates first: a variable created later attaches to them once (h5netcdf
        # re-attaches every variable of a dimension whose coordinate comes after them)
        self._numbers["run"] = self.identity.index
        run = f.create_variable("run", ("run",), data=self._numbers["run"], fletcher32=True)
        run.attrs.update(variable_attributes("run"))
        self._texts["axis"] = np.array(_AXES, dtype=object)
        axis = f.create_variable("axis", ("axis",), data=self._texts["axis"], dtype=self._str)
        axis.attrs.update(variable_attributes("axis"))
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if exc_type is None:
                self._finish()
        except BaseException:
            self._datasets.clear()
            self._stack.__exit__(*sys.exc_info())
            raise
        self._datasets.clear()
        try:
            return self._stack.__exit__(exc_type, exc, tb)
        except RuntimeError as error:  # HDF5's close failed: an I/O error with its errno
            raise as_os_error(error, self.path) from None

    def _room(self, n_bytes: int) -> None:
        """Raise OSError(ENOSPC) before handing ``n_bytes`` to HDF5 unless the disk has room.

        HDF5 that meets a full disk leaves the file half-open inside the library, which then
        crashes the process at exit (a segmentation fault): a writer checks first, keeping
        :data:`SPACE_MARGIN` for the file's metadata and for other writers.
        """
        check_free_space(self.path.parent, n_bytes + SPACE_MARGIN, f"the store file {self.path.name}")

    # -- rows ---------------------------------------------------------------------------------

    def add(self, run_id: str, result: "RunResult", *, config_hash: str | None = None) -> dict[str, Any]:
        """Add a finished run (any status); returns its row (as :func:`read_chunk_rows` gives it).

        ``config_hash``: the run's :func:`rbstab.config.config_hash` of its canonical config,
        if the caller has it (a sweep's plan computed it); else computed here. A writer
        without templates stores the run's configuration text (the ``config`` column).
        """
        self.add_block([run_id], RunBlock.of(result), config_hashes=[config_hash])
        return self.row(self.position[run_id])

    def add_block(self, run_ids: Sequence[str], block, *, config_hashes: Sequence[str | None] | None = None) -> None:
        """Add finished runs that share their sample times (a :class:`rbstab.results.RunBlock`,
        ``run_ids[j]`` its run j), as :meth:`add` adds each; :meth:`columns` gives their rows.

        ``config_hashes``: as :meth:`add`'s, a value a run (None or "" where the caller
        has none). Raises ValueError, with no run added, for a run that is
        not a row of the file or was added already, or traces of another shape or sample
        times than the file's.
        """
        rows = self._rows_of(run_ids)
        values = self._block_values(block, config_hashes)
        if self.store != "summary":
            if self._time is None:
                self._start(block.time, *trace_dimensions(block), block.stride)
            self._keep_traces(run_ids, rows.tolist(), block)
        self._add(rows, values)

    def _block_values(self, block, config_hashes) -> dict[str, np.ndarray]:
        """The per-run values of a block's runs, as columns; without templates, each run's
        configuration as text (the ``config`` column)."""
        k = len(block)
        hashes = _objects(list(config_hashes) if config_hashes is not None else [None] * k)
        texts = _objects([None] * k)
        templates = "run_templates" in self.attrs
        for j in [j for j, h in enumerate(hashes.tolist()) if not h] if templates else range(k):
            resolved = block.configs[j].resolved
            if not templates:
                texts[j] = canonical_config(resolved, limits=True)
            if not hashes[j]:
                hashes[j] = config_hash(canonical_config(resolved))
        values: dict[str, np.ndarray] = {
            "variant": _objects(block.variants),
            "status": _objects(block.status),
            "message": _objects(block.message),
            "wall_time": np.asarray(block.wall_time, dtype=float),
        }
        for key in _SOLVER[:-1]:
            values[f"solver_{key}"] = np.asarray(block.solver.get(key, [None] * k), dtype=float)
        values["solver_status"] = np.asarray(block.solver.get("solver_status", [-1] * k), dtype=np.int64)
        if "run_templates" not in self.attrs:
            values["config"] = texts
        values["config_hash"] = hashes
        values.update(summary_table_columns(block.summaries, block.joints, block.bodies))
        return values

    def add_error(self, run_id: str, message: str) -> dict[str, Any]:
        """Add a run that raised before it had a result (status ``error``, no values)."""
        rows = self._rows_of([run_id])
        if self._traces:  # its traces are NaN (before the first result: the fill value)
            self._keep_traces([run_id], rows.tolist(), None)
        self._add(rows, {"status": _objects(["error"]), "message": _objects([message]), "wall_time": np.zeros(1)})
        return self.row(int(rows[0]))

    def _rows_of(self, run_ids: Sequence[str]) -> np.ndarray:
        """The rows of ``run_ids``; ValueError for one not a row, added already or given twice."""
        try:
            rows = np.fromiter((self.position[r] for r in run_ids), dtype=np.int64, count=len(run_ids))
        except KeyError as exc:
            raise ValueError(f"{self.path.name}: run {exc.args[0]!r} is not a row of this file") from None
        added = rows[self._block_of[rows] >= 0]
        if len(added):
            raise ValueError(f"{self.path.name}: run {self.ids[added[0]]!r} was added twice")
        if len(np.unique(rows)) != len(rows):
            raise ValueError(f"{self.path.name}: a run is given twice in one block: {list(run_ids)}")
        return rows

    def _add(self, rows: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """Rows ``rows`` take ``values`` (column -> a value a row); their traces, if any,
        are in the buffer already."""
        self._block_of[rows] = len(self._blocks)
        self._place[rows] = np.arange(len(rows))
        self._blocks.append((rows, values))

    def row(self, i: int) -> dict[str, Any]:
        """Row ``i`` as :func:`read_chunk_rows` reads it back."""
        ident = self.identity
        out = {"run": int(ident.index[i]), "run_id": ident.run_id[i], "base": ident.base[i],
               **{name: attribute_value(values[i]) for name, values in ident.coords.items()}}
        b = self._block_of[i]
        if b >= 0:
            for name, values in self._blocks[b][1].items():
                out[name] = attribute_value(values[self._place[i]])
        out["store"] = self.store
        out["created"] = self.attrs["created"]
        out["file"] = self.path.name
        out["file_row"] = i
        return out

    def columns(self) -> dict[str, np.ndarray]:
        """The rows added so far as columns (a value a row of the file, in row order; NaN or
        None where a row has none yet): what :func:`read_chunk_columns` reads back (``run``,
        ``run_id``, ``base``, the coordinates, the per-run values but ``config``,
        ``created``, ``file``, ``file_row``)."""
        stored = self._stored if self._stored is not None else self._stored_columns()
        columns = {"run": self.identity.index}
        columns.update((k, v) for k, v in stored.items() if k != "config")
        n = len(self.ids)
        columns["created"] = np.full(n, self.attrs["created"], dtype=object)
        columns["file"] = np.full(n, self.path.name, dtype=object)
        columns["file_row"] = np.arange(n)
        return columns

    # -- traces -------------------------------------------------------------------------------

    def _start(self, time, dims: Mapping[str, tuple[str, ...]], labels: Mapping[str, Sequence[str]],
               grid_stride: int = 1) -> None:
        """Create the trace variables: ``time`` the runs' sample times (every
        ``grid_stride``-th of their grid), ``dims`` output name -> its dimensions after
        ``run`` (:func:`trace_dimensions`), ``labels`` a chain's ``body`` and ``joint``
        names (its coordinates)."""
        time = np.asarray(time, dtype=float)
        thinned = CHAIN_SUMMARY_VARIABLES if labels else THINNED_VARIABLES  # a chain's, or one body's
        names = [k for k in dims if self.store == "full" or k in thinned]
        if self.store == "thinned":
            self._stride = summary_stride(len(time))
            self.attrs["store_stride"] = self._stride * grid_stride
        self._time = self._numbers["time"] = time[:: self._stride]
        f = self._file
        f.dimensions["time"] = len(self._time)
        t = f.create_variable("time", ("time",), data=self._time, fletcher32=bool(len(self._time)))
        t.attrs.update(variable_attributes("time"))
        sizes = {"run": len(self.ids), "time": len(self._time), "axis": 3}
        for dim, values in labels.items():  # a chain's body and joint names
            if any(dim in dims[name] for name in names):
                f.dimensions[dim] = sizes[dim] = len(values)
                self._texts[dim] = np.array(values, dtype=object)
                label = f.create_variable(dim, (dim,), data=self._texts[dim], dtype=self._str)
                label.attrs.update(variable_attributes(dim))
        block = min(WRITE_BLOCK, len(self.ids))
        h5 = f._h5file
        for name in names:
            axes = ("run", *dims[name])
            shape = tuple(sizes[d] for d in axes)
            # through h5py with the dimension scales attached (what netCDF-4 reads as a
            # variable of those dimensions): h5netcdf's create_variable costs ~5 ms each;
            # track_order: netCDF-C lists attributes in HDF5's creation order (as written)
            var = h5.create_dataset(name, shape=shape, dtype=float, fillvalue=np.nan, chunks=(block, *shape[1:]),
                                    fletcher32=True, track_order=True)
            for axis, dim in enumerate(axes):
                var.dims[axis].attach_scale(h5[dim])
            _put_attributes(var.id, variable_attributes(name), self._written.setdefault(f"/{name}", {}))
            self._traces[name] = shape[1:]
            self._datasets[name] = var
        per_run = 8 * sum(int(np.prod(shape)) for shape in self._traces.values()) or 1
        self._block = max(WRITE_BLOCK, WRITE_BYTES // per_run)
        rows = min(self._block, len(self.ids))
        self._buffer = {name: np.empty((rows, *shape)) for name, shape in self._traces.items()}

    def _keep_traces(self, run_ids: Sequence[str], rows: list[int], block) -> None:
        """Copy runs' traces (every ``store_stride``-th sample; NaN for a None block or a
        variable it lacks) into the buffer's next rows, written at a flush (checked first:
        ValueError, nothing copied, for traces of another shape or sample times).

        Copied, not held: a result's outputs are views of its post-processing block (36
        outputs of 32 runs, ~18 MB), which a view held until the flush would keep alive (a
        512-run file's pending rows pinned ~300 MB instead of the WRITE_BYTES of their
        traces); and copied once, a block of runs at a time, into the block that is written.
        """
        if block is not None and block.time is not self._checked_time:  # a chunk's runs share their times
            self._check_time(run_ids[0], block.time)
        traces: dict[str, np.ndarray | None] = {}
        for name, shape in self._traces.items():
            value = block.outputs.get(name) if block is not None else None
            if value is not None:
                value = np.asarray(value)[:, :: self._stride]
                if value.shape[1:] != shape:
                    raise ValueError(f"run {run_ids[0]}: '{name}' has shape {value.shape[1:]}; "
                                     f"the other runs of {self.path.name} have {shape}")
            traces[name] = value
        capacity = len(next(iter(self._buffer.values())))
        for lo in range(0, len(rows), capacity):
            hi = min(lo + capacity, len(rows))
            if len(self._pending) + hi - lo > capacity:
                self._flush()
            slot = len(self._pending)
            for name, value in traces.items():
                into = self._buffer[name][slot : slot + hi - lo]
                if value is None:
                    into[...] = np.nan
                else:
                    into[...] = value[lo:hi]
            self._pending.extend(rows[lo:hi])

    def _check_time(self, run_id: str, time) -> None:
        time = np.asarray(time, dtype=float)
        sampled = time[:: self._stride]
        if len(sampled) != len(self._time) or not np.array_equal(sampled, self._time):
            raise ValueError(
                f"run {run_id}: its sample times differ from the other runs of {self.path.name}; "
                "a sweep that varies simulation.t_end or n_samples needs --store summary or --layout run"
            )
        # a read-only array (simulate_many's runs of a block share one, never changed) is
        # not compared again for the next run that has it
        if not time.flags.writeable:
            self._checked_time = time

    def _flush(self) -> None:
        if not self._pending or not self._traces:
            self._pending = []
            return
        order = sorted(range(len(self._pending)), key=self._pending.__getitem__)
        rows = [self._pending[slot] for slot in order]
        self._room(len(rows) * 8 * sum(int(np.prod(shape)) for shape in self._traces.values()))
        in_order = order == list(range(len(order)))  # the runs came in row order (as a rule)
        for name in self._traces:
            # C-contiguous: HDF5 and the data digest take the block as it is
            block = self._buffer[name][: len(rows)] if in_order else self._buffer[name][order]
            var = self._datasets[name]
            if rows == list(range(rows[0], rows[-1] + 1)):
                var[rows[0] : rows[-1] + 1] = block
            else:
                var[rows] = block
            if len(rows) == len(self.ids):  # the whole variable: its digest needs no reading back
                self._numbers[name] = block
        self._pending = []

    # -- the per-run values -------------------------------------------------------------------

    def _finish(self) -> None:
        missing = np.flatnonzero(self._block_of < 0)
        if len(missing):
            raise ValueError(f"{self.path.name}: no result for {len(missing)} run(s), e.g. {self.ids[missing[0]]}")
        self._flush()
        f = self._file
        self._stored = self._stored_columns()  # kept for columns()
        columns = {name: self._variable(name, values) for name, values in self._stored.items()}
        self._room(sum(data.nbytes for data, _ in columns.values()))
        self._coordinates = " ".join(n for n in columns if n in _COORDS or n in self.parameters)
        self._run_scale = f._h5file["run"].id
        for name, (data, chars) in columns.items():
            self._write_column(name, data, chars)
        for name in self._traces:
            _put_attributes(self._datasets[name].id, {"coordinates": self._coordinates}, self._written[f"/{name}"])
        h5 = f._h5file
        _put_attributes(h5["/"].id, self.attrs, self._written.setdefault("/", {}))

        f.flush()
        _put_attributes(h5["/"].id, {DIGEST_ATTR: content_digest(h5, self._texts, self._written),
                                     DATA_DIGEST_ATTR: self._data_digest()})

    def _data_digest(self) -> str:
        """:func:`rbstab.io.integrity.data_digest` of the file: from the arrays written when
        every numeric variable was written whole (one block: a ``thinned`` or ``summary``
        store), else by reading the file back."""
        if all(name in self._numbers for name in self._traces):  # every numeric variable is there
            return data_digest_of(self._numbers)
        return data_digest(self._file._h5file, self.path)

    def _columns(self) -> dict[str, np.ndarray]:
        """Name -> a value per row: ``run_id``, ``base``, the coordinates, then the values
        (a value of the same name as a coordinate wins; None or NaN where a row has neither)."""
        ident = self.identity
        names: dict[str, None] = dict.fromkeys(_COORDS)
        names.update(dict.fromkeys(self.parameters))
        names.update(dict.fromkeys(ident.coords))
        first_row = [int(rows.min()) if len(rows) else 0 for rows, _ in self._blocks]
        for b in sorted(range(len(self._blocks)), key=first_row.__getitem__):  # the values' names in row order
            names.update(dict.fromkeys(self._blocks[b][1]))
        columns: dict[str, np.ndarray] = {"run_id": ident.run_id, "base": ident.base}
        if "run_templates" in self.attrs:
            columns["template"] = ident.template
            names["template"] = None
        n = len(self.ids)
        for name in names:
            if name in columns:
                continue
            parts = [(slice(None), ident.coords[name])] if name in ident.coords else []
            parts += [(rows, values[name]) for rows, values in self._blocks if name in values]
            columns[name] = _merged(n, parts)
        return {name: columns[name] for name in names}

    def _stored_columns(self) -> dict[str, np.ndarray]:
        """:meth:`_columns` as the file holds them (:func:`_as_stored`)."""
        return {name: _as_stored(name, values) for name, values in self._columns().items()}

    def _variable(self, name: str, data: np.ndarray) -> tuple[np.ndarray, str | None]:
        """The data of a ``(run,)`` variable from its column as stored (:func:`_as_stored`;
        text as characters, :meth:`_characters`) and the name of its character dimension
        (None for numbers)."""
        if data.dtype == object:
            data, chars = self._characters(data)
            self._texts[name] = data
            return data, chars
        self._numbers[name] = data
        return data, None

    def _column_kind(self, dtype: np.dtype) -> tuple:
        """(HDF5 type, dataset creation properties) of a ``(run,)`` variable of ``dtype``,
        made once a file for each kind (text, float, int): chunked with Fletcher-32 for
        numbers, NaN the fill value of floats; attributes in creation order (netCDF-C lists
        them in HDF5's creation order, as written)."""
        import h5py  # heavy: h5py

        kind = dtype.kind
        if kind not in self._kinds:
            dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
            dcpl.set_attr_creation_order(h5py.h5p.CRT_ORDER_TRACKED | h5py.h5p.CRT_ORDER_INDEXED)
            if kind == "O":
                tid = h5py.h5t.py_create(self._str, logical=True)
            else:
                tid = h5py.h5t.py_create(dtype)
                dcpl.set_chunk(fletcher32_chunks((len(self.ids),)))
                # numbers a store's runs share (run order, solver counts, t_final, the
                # templates) take next to no room: a summary store's bytes a run
                dcpl.set_shuffle()
                dcpl.set_deflate(1)
                dcpl.set_fletcher32()
                if kind == "f":
                    dcpl.set_fill_value(np.array(np.nan))
            self._kinds[kind] = tid, dcpl
        return self._kinds[kind]

    def _characters(self, values: np.ndarray) -> tuple[np.ndarray, str]:
        """Text values (str) as characters: an array (run, width) of ``S1`` (UTF-8, NUL-padded,
        what netCDF calls ``char`` and xarray decodes to str by ``_Encoding``), and the name
        of its second dimension ``string<width>``, created if new."""
        text = np.asarray(values, dtype=object).astype(str)
        try:
            encoded = text.astype(bytes)  # ASCII (as a rule): numpy's cast, many times faster
        except UnicodeEncodeError:
            encoded = np.char.encode(text, "utf-8")
        width = max(1, encoded.dtype.itemsize)
        data = encoded.astype(f"S{width}").view("S1").reshape(len(encoded), width)
        dim = f"string{width}"
        if dim not in self._file.dimensions:
            self._file.dimensions[dim] = width
            self._numbers[dim] = np.zeros(width, dtype=self._file._h5file[dim].dtype)  # the scale's own values
        return data, dim

    def _character_kind(self, shape: tuple[int, int]) -> tuple:
        """(HDF5 type, dataset creation properties) of a (run, string) character variable:
        chunked along ``run``, deflated, with Fletcher-32 (text that runs share takes next
        to no room)."""
        import h5py  # heavy: h5py

        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_attr_creation_order(h5py.h5p.CRT_ORDER_TRACKED | h5py.h5p.CRT_ORDER_INDEXED)
        dcpl.set_chunk(fletcher32_chunks(shape, itemsize=1))
        dcpl.set_deflate(1)
        dcpl.set_fletcher32()
        return h5py.h5t.py_create(np.dtype("S1")), dcpl

    def _write_column(self, name: str, data: np.ndarray, chars: str | None) -> None:
        """A ``(run,)`` variable (``data`` from :meth:`_variable`): a dataset with the ``run``
        dimension scale attached, which is what netCDF-4 and h5netcdf read as a variable of
        dimension ``run`` (tests/test_netcdf_c.py). Through h5py's low-level API: ~0.5 ms a
        variable, its attributes included, against ~1.1 ms with ``create_dataset`` and
        ``attrs`` and ~3 ms with h5netcdf's ``create_variable``."""
        import h5py  # heavy: h5py

        h5 = self._file._h5file
        tid, dcpl = self._column_kind(data.dtype) if chars is None else self._character_kind(data.shape)
        dsid = h5py.h5d.create(h5.id, name.encode(), tid, h5py.h5s.create_simple(data.shape), dcpl=dcpl)
        dsid.write(h5py.h5s.ALL, h5py.h5s.ALL, data)
        h5py.h5ds.attach_scale(dsid, self._run_scale, 0)
        if chars is not None:
            h5py.h5ds.attach_scale(dsid, h5[chars].id, 1)
        units, long_name = figure_attributes(name)
        attrs: dict[str, str] = {"_Encoding": "utf-8"} if chars is not None else {}
        if name in self.parameters:
            attrs["config_key"] = long_name = self.parameters[name]
        attrs["long_name"] = long_name
        if units:
            attrs["units"] = units
        if name not in _COORDS and name not in self.parameters:
            attrs["coordinates"] = self._coordinates
        _put_attributes(dsid, attrs, self._written.setdefault(f"/{name}", {}))


def is_chunk_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a readable store file (``rbstab_format`` one of :data:`READ_FORMATS`)."""
    import h5py  # heavy: h5py

    try:
        with h5py.File(path, "r") as f:
            return attribute_value(f.attrs.get("rbstab_format")) in READ_FORMATS
    except (OSError, ValueError):
        return False


def read_chunk_rows(path: str | os.PathLike, *, data: bool = False) -> list[dict[str, Any]]:
    """Each run's per-run values, in row order, from a verified store file.

    ``data``: also verify the checksums of every trace (reads the whole file).

    Returns
    -------
    list of dict
        ``run`` (index), ``run_id``, ``base``, the parameter coordinates, ``variant``,
        ``status``, ``message``, ``wall_time``, ``solver_*``, ``config``, ``config_hash``,
        the summary columns (:func:`summary_columns`), ``store``, ``created``, ``file``
        (the file name) and ``file_row``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotAResultFile
        If it is not an rbstab store file.
    rbstab.io.integrity.DamagedResultError
        If its checksums do not match (the digest of its text and attributes, the
        Fletcher-32 checksums of the per-run values; ``data``: of the traces too).
    """
    path = Path(path)
    with open_result(path) as f:
        if attribute_value(f.attrs.get("rbstab_format")) not in READ_FORMATS:
            raise NotAResultFile(f"{path}: not an rbstab sweep store file (no rbstab_format = {CHUNK_FORMAT!r})")
        verify_open_file(f, path, data=data)
        store, created = attribute_value(f.attrs.get("store")), attribute_value(f.attrs.get("created"))
        text = attribute_value(f.attrs.get("run_templates"))
        templates = json.loads(text) if text else None
        try:
            n_runs = f["run"].shape[0] if "run" in f else -1
            datasets = {k: f[k] for k in f if k not in ("axis", "time")}
            columns = {k: _column(d) for k, d in datasets.items() if _per_run(d, n_runs)}
            keys = {k: attribute_value(d.attrs["config_key"]) for k, d in datasets.items()
                    if k in columns and "config_key" in d.attrs}
        except OSError as exc:  # a Fletcher-32 checksum that does not match
            raise DamagedResultError(f"{path}: damaged: its per-run values fail their checksum ({exc})") from None
    if "run" not in columns or "run_id" not in columns:
        raise NotAResultFile(f"{path}: a sweep store file without its 'run' and 'run_id' variables")
    n = len(columns["run"])
    if templates is not None and "config" not in columns:
        columns["config"] = [_config_text(templates, columns, keys, i) for i in range(n)]
    rows = []
    for i in range(n):
        row = {k: v[i] for k, v in columns.items()}
        row.update(store=store, created=created, file=path.name, file_row=i)
        rows.append(row)
    return rows


def read_chunk_columns(path: str | os.PathLike, *, data: bool = False):
    """The per-run values of a verified store file as a pandas DataFrame, a row a run in
    file order: the columns of :func:`read_chunk_rows` (but ``config`` and ``store``),
    read as whole columns (what resume and the index read of many files).

    Raises
    ------
    As :func:`read_chunk_rows`.
    """
    import pandas as pd  # heavy: pandas


    path = Path(path)
    with open_result(path) as f:
        if attribute_value(f.attrs.get("rbstab_format")) not in READ_FORMATS:
            raise NotAResultFile(f"{path}: not an rbstab sweep store file (no rbstab_format = {CHUNK_FORMAT!r})")
        verify_open_file(f, path, data=data)
        created = attribute_value(f.attrs.get("created"))
        try:
            n_runs = f["run"].shape[0] if "run" in f else -1
            columns = {}
            for k in f:
                d = f[k]
                if k in ("axis", "time", "config") or not _per_run(d, n_runs):
                    continue
                columns[k] = _text_values(d) if d.dtype.kind in "OS" else d[...]
        except OSError as exc:  # a Fletcher-32 checksum that does not match
            raise DamagedResultError(f"{path}: damaged: its per-run values fail their checksum ({exc})") from None
    if "run" not in columns or "run_id" not in columns:
        raise NotAResultFile(f"{path}: a sweep store file without its 'run' and 'run_id' variables")
    frame = pd.DataFrame(columns)
    frame["created"] = created
    frame["file"] = path.name
    frame["file_row"] = np.arange(n_runs)
    return frame


def _config_text(templates: list, columns: Mapping[str, list], keys: Mapping[str, str], i: int) -> str:
    """Canonical JSON of row ``i``'s configuration without its name (:func:`resolved_config`)."""
    return canonical_config(_resolved(templates, columns, keys, i), limits=True)


def _resolved(templates: list, columns: Mapping[str, list], keys: Mapping[str, str], i: int) -> dict:
    from ..config.paths import parse_key, schema_of  # heavy: pydantic (rbstab.config's schema); reading a store stays light

    template = json.loads(json.dumps(templates[int(columns["template"][i])]))
    schema = schema_of(template)  # a chain's keys name its bodies and joints
    for name, key in keys.items():
        value = columns[name][i]
        if not key.endswith(":scale") and not isinstance(value, str) and value is not None:
            parse_key(key, schema).set(template, value)
    template["name"] = columns["run_id"][i]
    return template


def resolved_config(path: str | os.PathLike, row: int) -> dict:
    """The resolved configuration of row ``row`` of a store file (``name``: its run id):
    the file's template of the run (``run_templates``) with its numeric parameter
    coordinates set at their ``config_key``; ``RunConfig.from_resolved`` or
    :func:`rbstab.config.config_from_mapping` make it a run configuration again.

    Raises
    ------
    FileNotFoundError, NotAResultFile, DamagedResultError
        As :func:`read_chunk_rows`; IndexError for a row the file does not have.
    """
    return resolved_configs(path, [row])[0]


def resolved_configs(path: str | os.PathLike, rows: Sequence[int]) -> list[dict]:
    """:func:`resolved_config` of each of ``rows``, in that order, the file read once.

    Raises
    ------
    As :func:`resolved_config`.
    """
    found = read_chunk_rows(path)
    return [json.loads(found[k]["config"]) | {"name": found[k]["run_id"]} for k in rows]


def _per_run(dataset, n_runs: int) -> bool:
    """Whether ``dataset`` holds a value a run: shape (run,), or (run, string) characters
    (not the ``string<width>`` dimensions of those)."""
    if _STRING_DIM.fullmatch(dataset.name.lstrip("/")):
        return False
    chars = dataset.ndim == 2 and dataset.dtype == np.dtype("S1")
    return (dataset.ndim == 1 or chars) and dataset.shape[0] == n_runs


def _text_values(dataset) -> np.ndarray:
    """A text variable's values as str (objects): variable-length strings, or characters
    (run, string) of UTF-8."""
    if dataset.ndim == 2:
        chars = dataset[...]
        fixed = np.ascontiguousarray(chars).view(f"S{max(chars.shape[1], 1)}").ravel() if chars.size else (
            np.zeros(chars.shape[0], dtype="S1"))
        return np.array([x.decode("utf-8") for x in fixed.tolist()], dtype=object)
    return dataset.asstr()[...]


def _column(dataset) -> list:
    if dataset.dtype.kind in "OS":
        return _text_values(dataset).tolist()
    values = dataset[...]
    out = values.tolist()
    if values.dtype.kind == "f":
        return [None if isinstance(x, float) and math.isnan(x) else x for x in out]
    return out


def read_chunk_series(path: str | os.PathLike, row: int | None, names) -> dict[str, np.ndarray | None]:
    """The traces of one run of a store file, or of all its runs.

    Parameters
    ----------
    path : path-like
    row : int or None
        The run's row (``file_row`` in the sweep's ``index.csv``); None: every row, read
        at once (what a reader of many runs of the file wants).
    names : iterable of str
        Output variables (:data:`rbstab.io.hdf5.VARIABLE_UNITS` keys).

    Returns
    -------
    dict
        ``time`` [s], shape (n,) (None for a summary store); each name: shape (n,) or
        (n, 3) (row None: (runs, n) or (runs, n, 3)), or None when the file does not hold
        it; ``units:<name>`` for each held.
    """
    import h5py  # heavy: h5py

    out: dict[str, Any] = {}
    with h5py.File(path, "r") as f:
        out["time"] = np.asarray(f["time"][...], dtype=float) if "time" in f else None
        for name in names:
            if name in f and name != "time" and f[name].ndim >= 2 and (row is None or f[name].shape[0] > row):
                out[name] = np.asarray(f[name][...] if row is None else f[name][row], dtype=float)
                units = f[name].attrs.get("units", "")
                out[f"units:{name}"] = units.decode() if isinstance(units, bytes) else str(units)
            else:
                out[name] = None
    return out


#: Store files whose text, attributes and structure this process verified, by (path,
#: modification time, size): :class:`StoreTrace` checks each file once, on its first read.
_VERIFIED: set[tuple[str, int, int]] = set()


def _verified_once(f, path: str) -> None:
    stat = os.stat(path)
    key = (path, stat.st_mtime_ns, stat.st_size)
    if key not in _VERIFIED:
        verify_open_file(f, path, data=False)  # the numbers: Fletcher-32, as they are read
        _VERIFIED.add(key)


class StoreTrace:
    """One trace variable over the rows of many store files, read on demand.

    What :func:`dask.array.from_array` needs (``shape``, ``dtype``, ``ndim``,
    ``__getitem__``); it holds only file names and row numbers, so it pickles to other
    processes. Run ``i`` along the first axis is row ``rows[j]`` of segment ``(path,
    rows)`` number s, where ``i = sum of the earlier segments' lengths + j``. A file's
    checksums of text, attributes and structure are verified on its first read in a
    process, its numbers (Fletcher-32) on every read; a file without the variable (the
    ``controller_state`` of a variant without one) gives NaN.

    Parameters
    ----------
    name : str
        The variable.
    segments : sequence of (str, ndarray of int)
        Store file path and the file rows (``file_row``) it contributes, in order.
    tail : tuple of int
        The shape of one run's trace: ``(n_time,)`` or ``(n_time, 3)``.

    Raises (on a read)
    ------------------
    rbstab.io.integrity.DamagedResultError
        When a file's checksums do not match.
    """

    dtype = np.dtype(float)

    def __init__(self, name: str, segments: Sequence[tuple[str, np.ndarray]], tail: tuple[int, ...]) -> None:
        self.name = name
        self.segments = [(str(path), np.asarray(rows, dtype=np.int64)) for path, rows in segments]
        self.bounds = np.cumsum([0] + [len(rows) for _, rows in self.segments])
        self.shape = (int(self.bounds[-1]), *tail)
        self.ndim = len(self.shape)

    @property
    def chunks(self) -> tuple[tuple[int, ...], ...]:
        """One dask chunk per segment along the runs, whole traces."""
        return (tuple(len(rows) for _, rows in self.segments), *((n,) for n in self.shape[1:]))

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        positions = np.arange(self.shape[0])[key[0]]
        scalar = np.ndim(positions) == 0
        positions = np.atleast_1d(positions)
        out = np.full((len(positions), *self.shape[1:]), np.nan)
        segment = np.searchsorted(self.bounds, positions, side="right") - 1
        for s in np.unique(segment):
            at = np.flatnonzero(segment == s)
            path, rows = self.segments[s]
            out[at] = self._read(path, rows[positions[at] - self.bounds[s]])
        out = out[(slice(None), *key[1:])]
        return out[0] if scalar else out

    def _read(self, path: str, rows: np.ndarray) -> np.ndarray:
        import h5py  # heavy: h5py

        order = np.argsort(rows, kind="stable")
        wanted, inverse = np.unique(rows[order], return_inverse=True)
        with reading(path), h5py.File(path, "r") as f:
            _verified_once(f, path)
            if self.name not in f:
                return np.full((len(rows), *self.shape[1:]), np.nan)
            dataset = f[self.name]
            try:
                if wanted[-1] - wanted[0] + 1 == len(wanted):  # a contiguous block
                    block = dataset[int(wanted[0]) : int(wanted[-1]) + 1]
                else:
                    block = dataset[wanted]
            except OSError as exc:  # a Fletcher-32 checksum that does not match
                raise DamagedResultError(
                    f"{path}: damaged: the data of '{self.name}' fail their checksum ({exc}); rerun the "
                    "sweep to redo its runs"
                ) from None
        out = np.empty((len(rows), *self.shape[1:]))
        out[order] = block[inverse]
        return out


def store_trace_shapes(paths: Iterable[str | os.PathLike]) -> tuple[dict[str, tuple[int, ...]], np.ndarray | None]:
    """(trace variable -> shape of one run's trace, ``time`` or None) of store files, the
    variables of any of them, from their structure only (nothing verified:
    :class:`StoreTrace` checks a file when it reads it). A variable's shape is probed in the
    first file that has it; the others are only listed. :func:`store_trace_dimensions`
    names their dimensions.

    Raises
    ------
    FileNotFoundError, rbstab.io.hdf5.NotAResultFile, rbstab.io.integrity.DamagedResultError
        For a missing file, one that is not HDF5, or one whose structure cannot be read
        (:func:`rbstab.io.integrity.open_result`).
    """
    shapes, time, _, _ = store_trace_dimensions(paths)
    return shapes, time


def store_trace_dimensions(paths: Iterable[str | os.PathLike]):
    """:func:`store_trace_shapes` with each variable's dimensions after ``run`` (``time``,
    and ``axis``, a chain's ``body`` or ``joint``: the names of its dimension scales) and
    the labels of a chain's ``body`` and ``joint`` dimensions: (shapes, time, dims,
    labels)."""
    shapes: dict[str, tuple[int, ...]] = {}
    dims: dict[str, tuple[str, ...]] = {}
    labels: dict[str, list[str]] = {}
    probed = {"run", "time", "axis"}
    time = None
    for path in paths:
        with open_result(path) as f:
            if time is None and "time" in f:
                time = np.asarray(f["time"][...], dtype=float)
            for name in f:
                if name in probed:
                    continue
                probed.add(name)
                data = f[name]
                if name in ("body", "joint") and data.ndim == 1:
                    labels[name] = [v.decode() if isinstance(v, bytes) else str(v) for v in data[...]]
                    continue
                shape = data.shape
                if len(shape) >= 2 and time is not None and shape[1] == len(time) and data.dtype.kind == "f":
                    shapes[name] = tuple(shape[1:])
                    dims[name] = tuple(scale[0].name.rsplit("/", 1)[-1] if len(scale) else "axis"
                                       for scale in list(data.dims)[1:])
    return shapes, time, dims, labels
