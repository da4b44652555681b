"""The sweep folder's format: file names, parameter names, index columns, and the reader.

Every part of rbstab that writes or reads a sweep folder goes through this module: the
runner (planning, resume, the index), ``rbstab show DIR``, ``rbstab report`` and
:func:`open_sweep`. ::

    <output>/<name>/
      sweep.yaml           the resolved spec (bases inline, overrides applied) + provenance
      runs/chunk-*.h5      store files, one per chunk of runs (layout "chunk", the default;
                           format: :mod:`rbstab.io.chunk`)
      runs/<run_id>.h5     or one result file per run (layout "run", :mod:`rbstab.io.hdf5`)
      index.csv            one row per run, the columns of :func:`index_columns`
      sweep_summary.json   counts per status, converged fraction (overall and per base)

Parameter names
---------------
A varied config key becomes a coordinate (and an ``index.csv`` column) named by
:func:`parameter_name`: the key's field name, with list indices appended by ``_``::

    body.mass -> mass             controller.variant -> variant
    controller.k_c.0 -> k_c_0     controller.k_t.2.2 -> k_t_2_2
    initial_state.omega -> omega_0, omega_1, omega_2 (a whole 3-vector, per component)
    body.mass:scale -> mass_scale (the factor of a scale_uniform draw)

Every field name of the config schema is unique across its sections, so the map is one to
one; each coordinate's ``config_key`` attribute (and ``sweep_summary.json``'s
``parameters``) gives the dotted key back.

Checksums
---------
Store and run files carry checksums (:mod:`rbstab.io.integrity`), and
``sweep_summary.json`` the SHA-256 of the ``index.csv`` written with it
(``index_sha256``). Resume verifies every file it counts (:func:`current_rows` with
``verify``): a damaged file is renamed ``<name>.damaged`` by the runner and its runs are
rerun. :func:`read_index` (``rbstab show DIR``, ``rbstab report``, :func:`open_sweep`)
refuses an index that does not match its checksum.
"""

from __future__ import annotations

import csv
import functools
import datetime as _dt
import hashlib
import json
import operator
import os
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, MutableMapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..convergence import converged
from ..io.atomic import atomic_path, write_text_atomic
from ..io.integrity import DamagedResultError
from ..io.metadata import LONG_NAMES, variable_attributes

__all__ = [
    "SPEC_FILE",
    "INDEX_FILE",
    "SUMMARY_FILE",
    "RUNS_DIR",
    "LOCK_FILE",
    "CHUNK_GLOB",
    "LAYOUTS",
    "DEFAULT_LAYOUT",
    "STATUSES",
    "parameter_name",
    "parameter_columns",
    "coordinate_columns",
    "run_coords",
    "row_from_attributes",
    "index_rows",
    "index_columns",
    "write_index",
    "read_index",
    "summarize_rows",
    "write_summary",
    "is_sweep_folder",
    "read_spec",
    "current_rows",
    "open_sweep",
    "DAMAGED_SUFFIX",
    "verify_index",
    "set_aside_damaged",
]

SPEC_FILE = "sweep.yaml"
INDEX_FILE = "index.csv"
SUMMARY_FILE = "sweep_summary.json"
RUNS_DIR = "runs"
LOCK_FILE = ".lock"
#: Store files in ``runs/`` (layout "chunk").
CHUNK_GLOB = "chunk-*.h5"
#: How a sweep stores its runs: store files of many runs (default), or one file per run.
LAYOUTS = ("chunk", "run")
DEFAULT_LAYOUT = "chunk"
#: Values of the ``status`` column.
STATUSES = ("success", "failed", "error", "pending")
#: Suffix given to a damaged result file found on resume (it is then no longer read).
DAMAGED_SUFFIX = ".damaged"
_SOLVER = ("solver_nfev", "solver_njev", "solver_nlu", "solver_status")
_HEAD = ("run_id", "run", "base")
_MIDDLE = ("variant", "status", "converged", "message", "wall_time")
_TAIL = (*_SOLVER, "config_hash", "file", "file_row")
#: Values of a stored row that the index leaves out (the config text is most of a row's bytes).
NOT_IN_INDEX = ("config", "created", "store")


# -- names ----------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=4096)  # the same keys for every run of a sweep
def parameter_name(key: str) -> str:
    """Identifier of a dotted config key (module docstring): ``controller.k_c.0`` -> ``k_c_0``."""
    key, scale = (key[: -len(":scale")], True) if key.endswith(":scale") else (key, False)
    parts = key.split(".")
    fields = [i for i, p in enumerate(parts) if not p.isdigit()]
    last = fields[-1] if fields else 0
    name = "_".join(parts[last:])
    name = re.sub(r"\W", "_", name)
    if not name or name[0].isdigit():
        name = f"p_{name}"
    return f"{name}_scale" if scale else name


@functools.lru_cache(maxsize=4096)
def _entries(key: str, n: int, suffix: str) -> tuple[tuple[str, str], ...]:
    """(coordinate name, dotted key) of each entry of a list of ``n`` numbers at ``key``."""
    return tuple((parameter_name(f"{key}.{i}{suffix}"), f"{key}.{i}{suffix}") for i in range(n))


def _flat_values(key: str, value: Any, suffix: str, out: dict[str, tuple[str, Any]]) -> None:
    if isinstance(value, (list, tuple)):
        if not any(isinstance(v, (list, tuple)) for v in value):  # a vector: names cached
            for (name, entry), v in zip(_entries(key, len(value), suffix), value):
                out[name] = (entry, v)
            return
        for i, v in enumerate(value):
            _flat_values(f"{key}.{i}", v, suffix, out)
    else:
        out[parameter_name(key + suffix)] = (key + suffix, value)


def run_coords(params: Mapping[str, Any]) -> dict[str, tuple[str, Any]]:
    """Coordinate name -> (dotted key of the entry, value) of a run's varied values.

    Lists are split per entry (``controller.k_c`` -> ``k_c_0`` .. ``k_c_2``); a
    ``scale_uniform`` factor ``body.mass:scale`` is ``mass_scale``, per entry for list
    bounds (``body.inertia.0:scale`` -> ``inertia_0_scale``).
    """
    out: dict[str, tuple[str, Any]] = {}
    for key, value in params.items():
        base, scale = (key[: -len(":scale")], ":scale") if key.endswith(":scale") else (key, "")
        _flat_values(base, value, scale, out)
    return out


def parameter_columns(params: Iterable[Mapping[str, Any]]) -> dict[str, str]:
    """Coordinate name -> dotted config key (of the entry) of every varied value in
    ``params``, the varied values of runs (``PlannedRun.params``: dotted key -> value).

    Raises
    ------
    ValueError
        If two different keys would get one name (not possible with the config schema's
        field names, whose names are unique across sections; checked all the same).
    """
    return coordinate_columns(run_coords(values) for values in params)


def coordinate_columns(coords: Iterable[Mapping[str, tuple[str, Any]]]) -> dict[str, str]:
    """:func:`parameter_columns` of runs' coordinates (:func:`run_coords` of each, e.g.
    ``PlannedRun.coords``); ValueError as there."""
    names: dict[str, str] = {}
    for run in coords:
        for name, (key, _) in run.items():
            if names.setdefault(name, key) != key:
                raise ValueError(f"parameters {names[name]!r} and {key!r} would both be named {name!r}")
    return names


def config_key_of(entry: str) -> str:
    """The config key of a parameter entry: ``controller.k_c.2`` -> ``controller.k_c``,
    ``body.inertia.0:scale`` -> ``body.inertia``."""
    return re.sub(r"(\.\d+)+$", "", entry.removesuffix(":scale"))


def read_parameters(folder: str | os.PathLike, index=None) -> dict[str, str]:
    """Parameter column -> dotted config key (of the entry) of a sweep folder, from
    ``sweep_summary.json`` (the columns between ``base`` and ``variant`` of the index,
    mapped to themselves, when it is missing)."""
    try:
        data = json.loads((Path(folder) / SUMMARY_FILE).read_text(encoding="utf-8"))
        parameters = data.get("parameters")
        if isinstance(parameters, dict):
            return {str(k): str(v) for k, v in parameters.items()}
    except (OSError, ValueError):
        pass
    index = read_index(folder) if index is None else index
    return {c: c for c in _parameter_set(index)}


# -- rows and the index ---------------------------------------------------------------------------


def row_from_attributes(attrs: Mapping[str, Any], file: str) -> dict[str, Any]:
    """A run file's global attributes (:func:`rbstab.io.hdf5.read_attributes`) as an index row."""
    from ..io.chunk import summary_columns  # heavy: numpy

    row = {k: attrs.get(k) for k in ("variant", "status", "message", "wall_time")}
    row.update(summary_columns({k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")}))
    row.update({k: attrs.get(k) for k in _SOLVER})
    row.update(config_hash=attrs.get("config_hash"), created=attrs.get("created"), file=file, file_row=None)
    row["run_id"] = attrs.get("name")
    return row


class IndexRows(MutableMapping):
    """run_id -> the run's row as the index takes it (:func:`index_part`), held compactly.

    What a sweep keeps of each finished run until it writes the index: the row's values as
    a tuple, its column names shared by every row that has the same (a dict per row costs
    ~10 KB with its ~60 entries; this ~2 KB). Reading a row gives a new dict.
    """

    def __init__(self) -> None:
        self._columns: dict[tuple, tuple] = {}
        self._rows: dict[str, tuple[tuple, tuple]] = {}

    def __setitem__(self, run_id: str, row: Mapping[str, Any]) -> None:
        if any(key in row for key in NOT_IN_INDEX):  # most rows come without (a worker's record)
            row = index_part(row)
        names = tuple(row)
        # the values end with a None: the value of a column the row does not have
        self._rows[run_id] = (self._columns.setdefault(names, names), (*row.values(), None))

    def __getitem__(self, run_id: str) -> dict[str, Any]:
        names, values = self._rows[run_id]
        return dict(zip(names, values))

    def parts(self, run_id: str) -> tuple[tuple, tuple] | None:
        """(column names, values ending with a None) of a row as held, or None: what
        :func:`write_sweep_index` reads without making the row's dict."""
        return self._rows.get(run_id)

    def __delitem__(self, run_id: str) -> None:
        del self._rows[run_id]

    def __iter__(self):
        return iter(self._rows)

    def __len__(self) -> int:
        return len(self._rows)

    def __contains__(self, run_id: object) -> bool:
        return run_id in self._rows


def index_part(row: Mapping[str, Any]) -> dict[str, Any]:
    """A stored row without what the index leaves out (:data:`NOT_IN_INDEX`): what a sweep
    keeps of each finished run until it writes the index (~1.5 KB a run less)."""
    return {k: v for k, v in row.items() if k not in NOT_IN_INDEX}


def index_rows(runs: Sequence[Any], rows: Mapping[str, Mapping[str, Any]], errors: Mapping[str, str],
               ratio: float) -> list[dict[str, Any]]:
    """One index row per run of ``runs`` (:class:`~rbstab.sweep.spec.PlannedRun`), in run order.

    A row is the run's ``run_id``, ``run`` (its index), ``base``, coordinates and
    ``variant``, then its stored row's values but those the index leaves out
    (:data:`NOT_IN_INDEX`), then ``file`` (under ``runs/``) and ``converged``
    (:func:`rbstab.convergence.converged`); a run without a stored row has ``status`` ``error`` (its
    message from ``errors``) or ``pending``, and is not converged.

    Parameters
    ----------
    rows : mapping run_id -> its current stored row (:func:`current_rows`, or a worker's record)
    errors : mapping run_id -> message
        Runs whose worker raised (no result): status ``error``.
    ratio : float
        ``convergence.lyapunov_ratio`` (:func:`rbstab.convergence.converged`).
    """
    return list(iter_index_rows(runs, rows, errors, ratio))


def iter_index_rows(runs: Iterable[Any], rows: Mapping[str, Mapping[str, Any]], errors: Mapping[str, str],
                    ratio: float) -> Iterator[dict[str, Any]]:
    """:func:`index_rows`, one at a time."""
    made = _IndexRowMaker(ratio)
    for run in runs:
        names, values = made.row(run, rows, errors)
        yield dict(zip(names, values))


#: ``message`` of a run not run yet.
_PENDING = "not run yet (rerun the sweep to finish it)"


class _IndexRowMaker:
    """Index rows (:func:`index_rows`) as (column names, values ending with a None), the
    names shared by the rows of a kind (coordinate layout x stored columns), each row's
    values taken by position: no dict per row (a 10,000-run sweep's index took ~0.8 s
    through a dict per row, ~0.55 s this way, 0.36 s of it csv's formatting)."""

    def __init__(self, ratio: float) -> None:
        self.ratio = ratio
        self._kinds: dict[tuple, tuple] = {}
        self._names: dict[tuple, tuple] = {}
        self._pickers: dict[tuple, Callable[[tuple], tuple]] = {}

    def row(self, run: Any, rows: Mapping[str, Any], errors: Mapping[str, str]) -> tuple[tuple, tuple]:
        """(column names, values) of the row of ``run`` (a RunEntry, or a PlannedRun: its entry)."""
        if not hasattr(run, "layout"):
            run = run.entry()
        head = (run.run_id, run.index, run.base, *run.values, run.variant)
        if isinstance(rows, IndexRows):
            held = rows.parts(run.run_id)
        else:
            stored = rows.get(run.run_id)
            held = None if stored is None else (tuple(stored), (*stored.values(), None))
        if held is None:
            status, message = ("error", errors[run.run_id]) if run.run_id in errors else ("pending", _PENDING)
            return self._kind(run.layout, None)[0], (*head, status, False, message, None)
        stored_names, stored = held
        names, keep, file, status, initial, final = self._kind(run.layout, stored_names)
        reached = converged(status is not None and stored[status] == "success", stored[initial], stored[final],
                            self.ratio)
        return names, (*head, *keep(stored), f"{RUNS_DIR}/{stored[file]}" if stored[file] else None, reached, None)

    def _kind(self, layout: tuple, stored_names: tuple | None) -> tuple:
        """(column names, getter of the stored values kept, positions of the stored file,
        status, lyapunov_initial and lyapunov_final: the values' trailing None's where
        absent, None for status) of the rows of ``layout`` and ``stored_names`` (None: no
        stored row)."""
        kind = self._kinds.get((layout, stored_names))
        if kind is not None:
            return kind
        head = ("run_id", "run", "base", *(name for name, _ in layout), "variant")
        if stored_names is None:
            names = (*head, "status", "converged", "message")
            kind = (self._names.setdefault(names, names),)
        else:
            left = {*head, *NOT_IN_INDEX, "file", "converged"}
            keep = [i for i, key in enumerate(stored_names) if key not in left]
            names = (*head, *(stored_names[i] for i in keep), "file", "converged")
            where = {key: i for i, key in enumerate(stored_names)}
            missing = len(stored_names)  # the values' trailing None
            kind = (self._names.setdefault(names, names), _getter(keep), where.get("file", missing),
                    where.get("status"), where.get("lyapunov_initial", missing), where.get("lyapunov_final", missing))
        self._kinds[layout, stored_names] = kind
        return kind

    def column_sets(self) -> list[tuple]:
        """The distinct column-name tuples of the rows made."""
        return list(self._names)

    def picker(self, names: tuple, columns: tuple) -> Callable[[tuple], tuple]:
        """A getter of a row's values in the order of ``columns`` (None where it has none)."""
        got = self._pickers.get((names, columns))
        if got is None:
            where = {name: i for i, name in enumerate(names)}
            got = self._pickers[names, columns] = _getter([where.get(c, len(names)) for c in columns])
        return got


def _getter(positions: Sequence[int]) -> Callable[[tuple], tuple]:
    """``lambda values: tuple(values[i] for i in positions)``, as one itemgetter."""
    if len(positions) > 1:
        return operator.itemgetter(*positions)
    if positions:
        get = operator.itemgetter(positions[0])
        return lambda values: (get(values),)
    return lambda values: ()


def index_columns(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Column order of ``index.csv``: run_id, run, base, the parameters, variant, status,
    converged, message, wall_time, the summary columns, solver_*, config_hash, file, file_row."""
    fixed = set(_HEAD + _MIDDLE + _TAIL)
    params: dict[str, None] = {}
    summary: dict[str, None] = {}
    for row in rows:
        in_params = True
        for key in row:
            if key == "status":
                in_params = False
            if key not in fixed:
                (params if in_params else summary)[key] = None
    from ..io.chunk import SUMMARY_FIGURES  # heavy: numpy

    order = {name: i for i, name in enumerate(SUMMARY_FIGURES)}
    ranked = sorted(summary, key=lambda c: (order.get(re.sub(r"_[xyz]$", "", c), len(order)), c))
    return [*_HEAD, *params, *_MIDDLE, *ranked, *_TAIL]


_PLAIN_CELLS = frozenset({str, float, int, bool, type(None)})


def _cell(value: Any) -> Any:
    return json.dumps(value) if isinstance(value, (list, dict)) else value


def write_index(path: Path, rows: Iterable[Mapping[str, Any]], columns: Sequence[str] | None = None) -> Path:
    """Write ``rows`` as ``index.csv``, row by row, atomically; ``columns`` default to
    :func:`index_columns` of the rows."""
    if columns is None:
        rows = list(rows)
        columns = index_columns(rows)
    return _write_cells(path, columns, ([row.get(c) for c in columns] for row in rows))


def _write_cells(path: Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """``index.csv`` of rows given as their values in the order of ``columns``; a list or a
    dict is written as its JSON."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(columns)
        plain = _PLAIN_CELLS
        for cells in rows:
            if plain.issuperset(map(type, cells)):
                writer.writerow(cells)
            else:
                writer.writerow([_cell(v) for v in cells])
    return Path(path)


#: What :func:`summarize_rows` reads of a row.
_SLIM = ("base", "status", "converged", "wall_time")


def write_sweep_index(directory: Path, runs: Sequence[Any], rows: MutableMapping[str, Mapping[str, Any]],
                      errors: Mapping[str, str], *, name: str, ratio: float,
                      parameters: Mapping[str, str]) -> tuple[dict[str, Any], list[tuple[str, str, str]]]:
    """Write ``index.csv`` and ``sweep_summary.json`` of ``runs`` (in run order), atomically.

    Each index row is made as a tuple of values beside column names its kind of row shares
    (:class:`_IndexRowMaker`, the rows of :func:`index_rows` without a dict per row) and
    streamed to the file: a sweep's memory at its end stays ~2 KB a run.

    Parameters
    ----------
    directory : Path
        The sweep folder.
    runs : sequence of PlannedRun or RunEntry
        Every run of the run list, in order.
    rows : mutable mapping run_id -> stored row
        As :func:`index_rows` takes it; **emptied** as the index is made (each row is
        removed once its index row exists).
    errors : mapping run_id -> message
        Runs whose worker raised (status ``error``).
    name, ratio, parameters
        The sweep's name, ``convergence.lyapunov_ratio`` and parameter columns (name ->
        config key), for the summary (:func:`summarize_rows`).

    Returns
    -------
    summary : dict
        What ``sweep_summary.json`` holds.
    problems : list of (run_id, status, message)
        Every run that did not succeed.

    Raises
    ------
    OSError
        If a file cannot be written (the old files are left as they were).
    """
    made = _IndexRowMaker(ratio)
    parts: list[tuple[tuple, tuple]] = []  # each run's (column names, values), in run order
    slim: list[dict[str, Any]] = []
    problems = []
    for run in runs:
        names, values = made.row(run, rows, errors)
        if run.run_id in rows:  # (not pop: IndexRows would make the row's dict to return it)
            del rows[run.run_id]
        parts.append((names, values))
        slim.append(dict(zip(_SLIM, made.picker(names, _SLIM)(values))))
        status = slim[-1]["status"]
        if status != "success":
            problems.append((run.run_id, status, made.picker(names, ("message",))(values)[0]))
    columns = tuple(index_columns(made.column_sets()))
    _write_cells(directory / INDEX_FILE, columns, (made.picker(names, columns)(values) for names, values in parts))
    summary = summarize_rows(slim, name=name, ratio=ratio, parameters=parameters)
    write_summary(directory / SUMMARY_FILE, summary)
    return summary, problems


def verify_index(folder: str | os.PathLike) -> bool:
    """Check ``index.csv`` against ``index_sha256`` of ``sweep_summary.json``.

    Returns
    -------
    bool
        True when checked; False when the summary has no checksum (written before they
        existed) or is missing.

    Raises
    ------
    rbstab.io.integrity.DamagedResultError
        If the index does not match (damaged, or an invocation killed between writing the
        two files: rerunning the sweep rebuilds both).
    """
    folder = Path(folder)
    try:
        expected = json.loads((folder / SUMMARY_FILE).read_text(encoding="utf-8")).get("index_sha256")
    except (OSError, ValueError, AttributeError):
        return False
    if not isinstance(expected, str):
        return False
    try:
        actual = hashlib.sha256((folder / INDEX_FILE).read_bytes()).hexdigest()
    except OSError:
        return False  # reported by the reader
    if actual != expected:
        raise DamagedResultError(
            f"{folder / INDEX_FILE}: does not match its checksum in {SUMMARY_FILE} (damaged, or an "
            f"invocation was killed between writing the two); rebuild both with: rbstab sweep "
            f"{folder / SPEC_FILE} -o {folder.parent}"
        )
    return True


def read_index(folder: str | os.PathLike, *, verify: bool = True):
    """``index.csv`` of a sweep folder as a pandas DataFrame (``message`` as text).

    Raises
    ------
    FileNotFoundError
        If the folder has no index.
    ValueError
        If it cannot be parsed or lacks ``run_id``/``status``.
    rbstab.io.integrity.DamagedResultError
        If ``verify`` and it does not match its checksum (:func:`verify_index`; a
        ValueError).
    """
    import pandas as pd  # heavy: pandas

    path = Path(folder) / INDEX_FILE
    if verify:
        verify_index(folder)
    try:
        index = pd.read_csv(path, keep_default_na=True)
    except pd.errors.ParserError as exc:
        raise ValueError(f"{path}: cannot read ({exc})") from None
    except pd.errors.EmptyDataError:
        raise ValueError(f"{path}: empty") from None
    missing = [c for c in ("run_id", "status") if c not in index.columns]
    if missing:
        raise ValueError(f"{path}: no column {', '.join(missing)} (columns: {', '.join(map(str, index.columns))})")
    index["message"] = index["message"].fillna("").astype(str) if "message" in index else ""
    index["run_id"] = index["run_id"].astype(str)
    return index


def _counts(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    status = {s: 0 for s in STATUSES}
    for row in rows:
        status[row["status"]] = status.get(row["status"], 0) + 1
    n = len(rows)
    converged = sum(1 for r in rows if r.get("converged"))
    return {"n_runs": n, "status": status, "n_converged": converged,
            "fraction_converged": converged / n if n else 0.0}


def summarize_rows(rows: Sequence[Mapping[str, Any]], *, name: str, ratio: float,
                   parameters: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The content of ``sweep_summary.json``: counts, converged fraction, per base, parameters."""
    out: dict[str, Any] = {"name": name, **_counts(rows)}
    out["convergence"] = {
        "lyapunov_ratio": ratio,
        "definition": "converged = status == 'success' and lyapunov_final <= lyapunov_ratio * lyapunov_initial",
    }
    bases = list(dict.fromkeys(r["base"] for r in rows))
    if len(bases) > 1:
        out["by_base"] = {b: _counts([r for r in rows if r["base"] == b]) for b in bases}
    out["parameters"] = dict(parameters or {})
    out["wall_time_total"] = sum(float(r["wall_time"]) for r in rows if r.get("wall_time") is not None)
    out["updated"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out["index"] = INDEX_FILE
    out["spec"] = SPEC_FILE
    return out


def write_summary(path: Path, summary: Mapping[str, Any]) -> Path:
    """Write ``summary`` as indented JSON, atomically, with the SHA-256 of the ``index.csv``
    beside it (``index_sha256``, :func:`verify_index`)."""
    summary = dict(summary)
    index = Path(path).parent / INDEX_FILE
    if index.is_file():
        summary["index_sha256"] = hashlib.sha256(index.read_bytes()).hexdigest()
    return write_text_atomic(path, json.dumps(summary, indent=2) + "\n")


# -- reading a folder -----------------------------------------------------------------------------


def is_sweep_folder(path: str | os.PathLike) -> bool:
    """True when ``path`` is a folder with ``sweep.yaml`` and ``index.csv``."""
    p = Path(path)
    return p.is_dir() and (p / SPEC_FILE).is_file() and (p / INDEX_FILE).is_file()


def read_spec(folder: str | os.PathLike) -> dict:
    """``sweep.yaml`` of a sweep folder, parsed (the resolved spec and its ``generated`` block).

    Raises
    ------
    OSError, ValueError
        If it is missing, not YAML or not a mapping.
    """
    from ..config import ConfigError  # heavy: yaml
    from ..config.yaml_io import parse_yaml, read_text_limited  # heavy: yaml

    path = Path(folder) / SPEC_FILE
    try:
        data = parse_yaml(read_text_limited(path, "sweep spec")) or {}
    except ConfigError as exc:
        raise ValueError(f"{path}: {'; '.join(exc.errors)}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: not a YAML mapping")
    return data


def _chunk_rows(runs_dir: Path, verify: bool = False, damaged: list | None = None) -> dict[str, list[dict]]:
    """run_id -> its rows in the store files of ``runs_dir`` (unreadable files are ignored;
    damaged ones are listed in ``damaged`` as (file name, reason))."""
    from ..io.chunk import read_chunk_rows  # heavy: numpy
    from ..io.hdf5 import NotAResultFile  # heavy: numpy

    rows: dict[str, list[dict]] = {}
    for path in sorted(runs_dir.glob(CHUNK_GLOB)):
        try:
            for row in read_chunk_rows(path, data=verify):
                rows.setdefault(row["run_id"], []).append(row)
        except DamagedResultError as exc:
            if damaged is not None:
                damaged.append((path.name, str(exc)))
        except (FileNotFoundError, NotAResultFile, OSError, KeyError):
            continue
    return rows


def _run_file_row(path: Path, verify: bool = False, damaged: list | None = None) -> dict | None:
    from ..io.hdf5 import NotAResultFile, read_attributes  # heavy: numpy

    try:
        return row_from_attributes(read_attributes(path, data=verify), path.name)
    except DamagedResultError as exc:
        if damaged is not None:
            damaged.append((path.name, str(exc)))
        return None
    except (FileNotFoundError, NotAResultFile, OSError, KeyError):
        return None


class StoredRows:
    """What a sweep's ``runs/`` folder holds, read once: the rows of its store files (run
    files are read per run, when asked for).

    A file's digest of its text and attributes is always checked; with ``verify`` every
    checksum of its numbers too (the whole file is read). A damaged file counts for
    nothing and is appended to ``damaged`` as (file name, reason).
    """

    def __init__(self, runs_dir: Path, *, verify: bool = False, damaged: list | None = None) -> None:
        self.runs_dir = runs_dir
        self.verify = verify
        self.damaged = damaged if damaged is not None else []
        self.files = sorted(p.name for p in runs_dir.glob("*.h5"))  # what was there before this invocation
        self._names = frozenset(self.files)
        self.chunk_rows = _chunk_rows(runs_dir, verify, self.damaged)

    def current(self, run: Any) -> dict | None:
        """The newest stored row made from ``run``'s current config (its ``config_hash``,
        :attr:`PlannedRun.config_hash`) with a status other than ``error``, or None."""
        candidates = list(self.chunk_rows.get(run.run_id, ()))
        name = f"{run.run_id}.h5"
        if name in self._names:  # the folder listed once, not a path and a stat a run
            row = _run_file_row(self.runs_dir / name, self.verify, self.damaged)
            if row is not None:
                candidates.append(row)
        good = [r for r in candidates if r.get("config_hash") == run.config_hash and r.get("status") != "error"]
        return max(good, key=lambda r: str(r.get("created", ""))) if good else None

    def stale(self, ids: set[str]) -> list[str]:
        """Result files found when this was made that hold no run of ``ids`` and are not
        damaged (left in place by the caller)."""
        used = {row["file"] for rows in self.chunk_rows.values() for row in rows if row["run_id"] in ids}
        bad = {name for name, _ in self.damaged}
        return [name for name in self.files if name not in bad
                and (name not in used if name.startswith("chunk-") else Path(name).stem not in ids)]


def current_rows(runs: Sequence[Any], runs_dir: Path, *, verify: bool = False,
                 damaged: list | None = None) -> tuple[dict[str, dict], list[str]]:
    """(run_id -> the newest stored row made from the run's current config, stale file names).

    A row counts when its ``config_hash`` is the run's (:attr:`PlannedRun.config_hash`) and
    its status is not ``error``; store files are read once, run files only for runs of
    ``runs``. Stale files hold no run of ``runs`` (left in place by the caller). Checks as
    :class:`StoredRows`.
    """
    stored = StoredRows(runs_dir, verify=verify, damaged=damaged)
    current = {run.run_id: row for run in runs if (row := stored.current(run)) is not None}
    return current, stored.stale({r.run_id for r in runs})


def set_aside_damaged(runs_dir: Path, damaged: Sequence[tuple[str, str]]) -> list[str]:
    """Rename each damaged file of ``runs_dir`` to ``<name>.damaged`` (no reader counts it
    then); returns the new names. Call it holding the sweep's lock."""
    out = []
    for name, _ in damaged:
        target = runs_dir / (name + DAMAGED_SUFFIX)
        try:
            os.replace(runs_dir / name, target)
        except OSError:
            continue
        out.append(target.name)
    return out


# -- the sweep as one dataset ---------------------------------------------------------------------


def open_sweep(path: str | os.PathLike, grid: bool = False):
    """Open a sweep folder as one :class:`xarray.Dataset` over its runs.

    Parameters
    ----------
    path : path-like
        A sweep folder (``sweep.yaml`` and ``index.csv``).
    grid : bool
        Reshape the ``run`` dimension to the sweep's axes, in run-list order: ``sample``
        (random samples), ``base`` (several bases), one per grid key (named by the first
        entry whose values tell its levels apart, e.g. ``k_c_0`` for a grid over
        ``controller.k_c`` lists, the other entries staying as coordinates; else by the
        key's :func:`parameter_name` with the grid level as value) and ``zip``; axes of length 1 are dropped. Runs without
        a result are NaN with their ``status`` (``pending``, ``error``).

    Returns
    -------
    xarray.Dataset
        Every run of the index along ``run`` (the run's position in the run list), with
        coordinates ``run_id``, ``base``, ``variant`` and the varied parameters
        (:func:`parameter_name`); the per-run values and summary figures of the store
        (``units``, ``long_name``), ``converged`` and, for a store with traces,
        ``(run, time[, axis])`` variables. Store files are read lazily (dask arrays, a
        chunk per stretch of runs from one file, :class:`rbstab.io.chunk.StoreTrace`); a
        sweep with layout "run" gives the summaries of ``index.csv``.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a sweep folder.
    rbstab.io.integrity.DamagedResultError
        If the index does not match its checksum; a store file's checksums (its text,
        attributes and structure, then each chunk of the traces) are checked when its
        traces are first read: computing traces of a damaged file raises it.
    """
    folder = Path(path)
    if not is_sweep_folder(folder):
        raise FileNotFoundError(f"{folder}: not a sweep folder (no {SPEC_FILE} and {INDEX_FILE})")
    index = read_index(folder)
    ds = _from_index(index)
    stored = _from_store(folder, index)
    if stored is not None:
        ds = stored.reindex(run=ds["run"].values).assign(
            {k: ds[k] for k in ds.data_vars if k not in stored.data_vars or k in ("status", "message", "converged")}
        ).assign_coords({k: ds[k] for k in ds.coords if k != "run"})
    spec = read_spec(folder)
    ds.attrs.update(sweep=spec.get("name", folder.name), lyapunov_ratio=(spec.get("convergence") or {}).get(
        "lyapunov_ratio"), folder=str(folder))
    return _as_grid(ds, spec) if grid else ds


def _from_index(index):
    """The index as a Dataset over ``run``: per-run values with units and long names
    (built column by column: ``DataFrame.to_xarray`` costs ~1 s for 10,000 runs)."""
    import xarray as xr  # heavy: xarray

    from ..io.chunk import figure_attributes  # heavy: numpy

    table = index.drop(columns=[c for c in ("file", "file_row") if c in index.columns])
    coords = {c for c in table.columns if c in ("run_id", "base", "variant") or c in _parameter_set(index)}
    variables = {}
    for name in table.columns:
        if name == "run":
            continue
        values = table[name].to_numpy()
        if name == "converged":
            values = table[name].astype(str).eq("True").to_numpy()
        elif values.dtype == object:
            values = table[name].fillna("").astype(str).to_numpy(dtype=object) if name in (
                "status", "message", "run_id", "base", "variant", "lyapunov_rate_check", "config_hash") else values
        units, long_name = figure_attributes(name)
        variables[name] = xr.Variable(("run",), values, {"long_name": long_name, **({"units": units} if units else {})})
    run = table["run"].to_numpy()
    return xr.Dataset({k: v for k, v in variables.items() if k not in coords},
                      coords={"run": run, **{k: v for k, v in variables.items() if k in coords}})


def _parameter_set(index) -> list[str]:
    """Parameter columns of an index: those between ``base`` and ``variant``."""
    columns = list(index.columns)
    start = columns.index("base") + 1 if "base" in columns else 0
    stop = columns.index("variant") if "variant" in columns else start
    return columns[start:stop]


def _from_store(folder: Path, index):
    """The traces of the current rows of the store files, lazily (dask arrays, a chunk per
    stretch of runs from one file), over ``run``; None for a store without traces or layout
    "run".

    The per-run values come from the index (the same names), the units and long names from
    :mod:`rbstab.io.metadata`; the store files are only listed here (names and shapes) and
    verified when their traces are read (:class:`rbstab.io.chunk.StoreTrace`).
    """
    import dask.array as da  # optional: dask
    import xarray as xr  # heavy: xarray

    from ..io.chunk import StoreTrace, store_trace_shapes  # heavy: numpy

    if "file_row" not in index.columns:
        return None
    rows = index.dropna(subset=["file_row"])
    rows = rows[rows["file"].astype(str).str.contains("chunk-", regex=False)].sort_values("run", kind="stable")
    if rows.empty:
        return None
    files = rows["file"].astype(str).to_numpy()
    file_rows = rows["file_row"].astype(np.int64).to_numpy()
    cuts = np.flatnonzero(files[1:] != files[:-1]) + 1
    segments = [(str(folder / files[lo]), file_rows[lo:hi]) for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(files)])]
    shapes, time = store_trace_shapes(folder / name for name in sorted(set(files)))
    if not shapes:
        return None
    data = {}
    for name, tail in shapes.items():
        trace = StoreTrace(name, segments, tail)
        array = da.from_array(trace, chunks=trace.chunks, name=False, asarray=True, meta=np.empty((0,) * trace.ndim))
        attrs = variable_attributes(name) if name in LONG_NAMES else {}
        data[name] = xr.Variable(("run", "time", "axis")[: trace.ndim], array, attrs)
    coords = {"run": rows["run"].to_numpy(), "axis": ["x", "y", "z"]}
    if time is not None:
        coords["time"] = xr.Variable(("time",), time, {"units": "s", "long_name": "time"})
    return xr.Dataset(data, coords=coords)


def _grid_level(key: str, values: Sequence[Any]) -> tuple[str, list]:
    """(axis name, label per level) of a grid key (see :func:`open_sweep`)."""
    flat = [run_coords({key: v}) for v in values]
    names = list(flat[0]) if all(f.keys() == flat[0].keys() for f in flat) else []
    varying = [n for n in names if len({repr(f[n][1]) for f in flat}) > 1]
    for name in varying:  # the first entry that tells the levels apart names the axis
        labels = [f[name][1] for f in flat]
        if len(set(map(repr, labels))) == len(labels):
            return name, labels
    if not isinstance(values[0], (list, tuple, dict)) and len(set(map(repr, values))) == len(values):
        return parameter_name(key), list(values)
    return parameter_name(key), list(range(len(values)))


def _grid_axes(spec: Mapping[str, Any]) -> list[tuple[str, list]]:
    """(dimension, labels) of the sweep's axes in run-list order (slowest first)."""
    axes: list[tuple[str, list]] = []
    n = int((spec.get("random") or {}).get("n") or 0)
    if n:
        axes.append(("sample", list(range(n))))
    bases = spec.get("base")
    if isinstance(bases, list) and len(bases) > 1:
        axes.append(("base", [str((b or {}).get("name", i)) for i, b in enumerate(bases)]))
    for key, values in (spec.get("grid") or {}).items():
        axes.append(_grid_level(key, values))
    zipped = spec.get("zip") or {}
    if zipped:
        axes.append(("zip", list(range(len(next(iter(zipped.values())))))))
    return axes


def _as_grid(ds, spec: Mapping[str, Any]):
    import pandas as pd  # heavy: pandas
    import xarray as xr  # heavy: xarray

    axes = _grid_axes(spec)
    shape = [len(labels) for _, labels in axes]
    n = int(np.prod(shape)) if shape else 1
    if ds.sizes["run"] != n:
        raise ValueError(f"the sweep has {ds.sizes['run']} runs, its spec's axes {n}")
    position = np.unravel_index(ds["run"].to_numpy(), shape) if shape else ()
    levels = {name: np.asarray(labels, dtype=object)[pos] for (name, labels), pos in zip(axes, position)}
    keep = [(name, labels) for name, labels in axes if len(labels) > 1]
    if not keep:
        return ds
    dims = [name for name, _ in keep]
    clash = [d for d in dims if d in ds.coords or d in ds.data_vars]
    ds = ds.drop_vars(clash)
    midx = pd.MultiIndex.from_arrays([pd.Index(list(levels[d])) for d in dims], names=dims)
    ds = ds.assign_coords(run_index=("run", ds["run"].to_numpy()))
    ds = ds.assign_coords(xr.Coordinates.from_pandas_multiindex(midx, "run"))
    out = ds.unstack("run")
    for name, labels in keep:  # the spec's order of levels, not sorted
        out = out.reindex({name: [x for x in labels]})
    out["status"] = out["status"].fillna("pending")
    return out
