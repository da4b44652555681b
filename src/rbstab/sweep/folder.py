"""The sweep folder's format: file names, parameter names, index columns, and the reader.

Every part of rbstab that writes or reads a sweep folder goes through this module: the
runner (planning, resume, the index), ``rbstab show DIR``, ``rbstab report`` and
:func:`open_sweep`. ::

    <output>/<name>/
      sweep.yaml           the resolved spec (bases inline, overrides applied) + provenance
      runs/chunk-*.h5      store files, one per chunk of runs (layout "chunk", the default;
                           format: :mod:`rbstab.io.chunk`)
      runs/<run_id>.h5     or one result file per run (layout "run", :mod:`rbstab.io.hdf5`)
      index.arrow          one row per run, the columns of :func:`index_columns`, an
                           Arrow IPC file, which :func:`open_sweep` maps into memory and
                           :func:`read_index` reads
      index.csv            the same table as text, for sweeps of at most
                           :data:`CSV_INDEX_MAX_RUNS` runs, or when asked (``index="csv"``)
      sweep_summary.json   counts per status, converged fraction (overall and per base)

Parameter names
---------------
A varied config key becomes a coordinate (and an ``index.csv`` column) named by
:func:`parameter_name`: the key's field name, with list indices appended by ``_``::

    body.mass -> mass             controller.variant -> variant
    controller.k_c.0 -> k_c_0     controller.k_t.2.2 -> k_t_2_2
    initial_state.omega -> omega_0, omega_1, omega_2 (a whole 3-vector, per component)
    body.mass:scale -> mass_scale (the factor of a scale_uniform draw)
    simulation.limits.theta.1 -> limits_theta_1 (a bound of the admissible region)

Every field name of the config schema is unique across its sections but those of
``simulation.limits`` (:data:`PREFIXED_SUBSECTIONS`), which name the quantities they bound
(``theta`` as ``initial_state.theta``) and keep their subsection's name, so the map is one to
one; each coordinate's ``config_key`` attribute (and ``sweep_summary.json``'s
``parameters``) gives the dotted key back.

Checksums
---------
Store and run files carry checksums (:mod:`rbstab.io.integrity`), and
``sweep_summary.json`` the SHA-256 of the ``index.csv`` and ``index.arrow`` written with it
(``index_sha256``, ``index_arrow_sha256``). Resume verifies every file it counts (:class:`StoredRuns` with
``verify``): a damaged file (checksums that fail, or a file that cannot be opened) is
renamed ``<name>.damaged`` by the runner and its runs are rerun. :func:`read_index` (``rbstab show DIR``, ``rbstab report``, :func:`open_sweep`)
refuses an index that does not match its checksum.
"""

from __future__ import annotations

import functools
import datetime as _dt
import hashlib
import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from itertools import product
from pathlib import Path
from typing import Any

from ..convergence import DEFAULT_LYAPUNOV_RATIO, RULE, converged
from ..diagnostics import OUTCOMES, outcomes
from ..engine.status import fell_mask
from ..io.atomic import atomic_path, write_text_atomic
from ..layout import is_index, parameter_attributes, slide_parts

__all__ = [
    "index_outcomes",
    "SPEC_FILE",
    "INDEX_FILE",
    "INDEX_ARROW_FILE",
    "CSV_INDEX_MAX_RUNS",
    "INDEX_FORMATS",
    "SUMMARY_FILE",
    "RUNS_DIR",
    "LOCK_FILE",
    "CHUNK_GLOB",
    "LAYOUTS",
    "DEFAULT_LAYOUT",
    "STATUSES",
    "parameter_name",
    "PREFIXED_SUBSECTIONS",
    "parameter_columns",
    "coordinate_columns",
    "run_coords",
    "row_from_attributes",
    "index_columns",
    "write_table_index",
    "read_index",
    "summarize_columns",
    "write_summary",
    "is_sweep_folder",
    "read_spec",
    "StoredRuns",
    "resolved_config",
    "resolved_configs",
    "open_sweep",
    "DAMAGED_SUFFIX",
    "verify_index",
    "set_aside_damaged",
]

SPEC_FILE = "sweep.yaml"
INDEX_FILE = "index.csv"
#: Most runs of a sweep whose index is also written as :data:`INDEX_FILE` unless asked
#: (``index="csv"``, ``rbstab sweep --index csv``): above it the text (~600 B a run, a few
#: seconds to write at 10^6 runs) would cost more than it serves; ``index.arrow`` is read
#: by every reader, and ``pandas.read_feather`` turns it into a DataFrame.
CSV_INDEX_MAX_RUNS = 100_000
#: Values of ``index``: the index files of a sweep (None: "csv" up to
#: :data:`CSV_INDEX_MAX_RUNS` runs, "arrow" above).
INDEX_FORMATS = ("csv", "arrow")
#: The index as an Arrow IPC file (uncompressed, text of few values dictionary-encoded):
#: :func:`open_sweep` maps it into memory, numbers without a copy; :func:`read_index` reads
#: it instead of parsing the CSV.
INDEX_ARROW_FILE = "index.arrow"
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
_MIDDLE = ("variant", "status", "converged", "outcome", "message", "wall_time")
_TAIL = (*_SOLVER, "config_hash", "file", "file_row")
#: Values of a stored row that the index leaves out (the config text is most of a row's bytes).
NOT_IN_INDEX = ("config", "created", "store", "template")


# -- names ----------------------------------------------------------------------------------------


#: Subsections whose fields' parameter names start with the subsection's name (their field
#: names repeat those of another section: ``simulation.limits.theta``, ``initial_state.theta``).
PREFIXED_SUBSECTIONS = ("limits",)
#: A chain's sections of named entries: their parameter names start with the entry's name.
CHAIN_ENTRIES = ("bodies", "joints")


@functools.lru_cache(maxsize=4096)  # the same keys for every run of a sweep
def parameter_name(key: str) -> str:
    """Identifier of a dotted config key (module docstring): ``controller.k_c.0`` -> ``k_c_0``;
    a key of a chain's body or joint starts with its entry (``joints.hip.k_c.0`` ->
    ``hip_k_c_0``, ``bodies.1.mass`` -> ``bodies_1_mass``, ``initial_state.trunk.theta.0``
    -> ``trunk_theta_0``)."""
    key, scale = (key[: -len(":scale")], True) if key.endswith(":scale") else (key, False)
    parts = key.split(".")
    fields = [i for i, p in enumerate(parts) if not is_index(p)]
    last = fields[-1] if fields else 0
    if last >= 2 and parts[last - 1] in PREFIXED_SUBSECTIONS:
        last -= 1
    name = "_".join(parts[last:])
    if len(parts) > 2 and last > 1 and (parts[0] in CHAIN_ENTRIES or (
            parts[0] == "initial_state" and not is_index(parts[2]))):  # not one body's initial_state.theta.0
        name = "_".join([parts[1] if not is_index(parts[1]) else f"{parts[0]}_{parts[1]}", name])
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
    from ..io.chunk import summary_columns  # heavy: numba, pydantic or h5py

    row = {k: attrs.get(k) for k in ("variant", "status", "message", "wall_time")}
    joints = attrs["joints"].split(",") if attrs.get("joints") else None  # a chain's file
    bodies = attrs["bodies"].split(",") if attrs.get("bodies") else None
    row.update(summary_columns({k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")}, joints,
                               bodies))
    row.update({k: attrs.get(k) for k in _SOLVER})
    row.update(config_hash=attrs.get("config_hash"), created=attrs.get("created"), file=file, file_row=None)
    row["run_id"] = attrs.get("name")
    return row


def index_part(row: Mapping[str, Any]) -> dict[str, Any]:
    """A stored row without what the index leaves out (:data:`NOT_IN_INDEX`): what a sweep
    keeps of each finished run until it writes the index (~1.5 KB a run less)."""
    return {k: v for k, v in row.items() if k not in NOT_IN_INDEX}




#: ``message`` of a run not run yet.
_PENDING = "not run yet (rerun the sweep to finish it)"


def index_columns(rows: Sequence[Mapping[str, Any]], parameters: Sequence[str] | None = None) -> list[str]:
    """Column order of ``index.csv``: run_id, run, base, the parameters, variant, status,
    converged, message, wall_time, the summary columns, solver_*, config_hash, file, file_row.

    ``parameters``: the parameter columns (default: the keys of a row before ``status``)."""
    fixed = set(_HEAD + _MIDDLE + _TAIL)
    params: dict[str, None] = dict.fromkeys(parameters or ())
    summary: dict[str, None] = {}
    for row in rows:
        in_params = parameters is None
        for key in row:
            if key == "status":
                in_params = False
            if key not in fixed and key not in params:
                (params if in_params else summary)[key] = None
    from ..io.chunk import SUMMARY_FIGURES  # heavy: numba, pydantic or h5py

    order = {name: i for i, name in enumerate(SUMMARY_FIGURES)}
    ranked = sorted(summary, key=lambda c: (order.get(re.sub(r"_[xyz]$", "", c), len(order)), c))
    return [*_HEAD, *params, *_MIDDLE, *ranked, *_TAIL]


#: Index columns of integers (written without a decimal point; empty where absent).
_INTEGERS = ("run", "file_row", "solver_nfev", "solver_njev", "solver_nlu", "solver_status")


def write_table_index(directory: Path, table, results, errors: Mapping[str, str], *, name: str,
                      ratio: float, index: str | None = None) -> tuple[dict[str, Any], list[tuple[str, str, str]]]:
    """Write the index (``index.arrow``, ``index.csv``) and ``sweep_summary.json`` of a
    sweep's runs, atomically, from columns.

    Parameters
    ----------
    directory : Path
        The sweep folder.
    table : rbstab.sweep.table.RunTable
        Every run of the run list: ``run_id``, ``run``, ``base``, the parameters and
        ``variant`` come from it.
    results : pandas.DataFrame
        The stored rows of the runs that have one (a worker's :class:`ChunkResult` frames
        and the current rows found on disk), with a ``run`` column (position in the run
        list; the last row of a run counts).
    errors : mapping run_id -> message
        Runs whose worker raised and left no row: status ``error``; the other runs without
        a row are ``pending``.
    name, ratio
        The sweep's name and ``convergence.lyapunov_ratio``.
    index : {"csv", "arrow"}, optional
        ``index.csv`` beside ``index.arrow`` ("csv") or not ("arrow", an earlier
        ``index.csv`` removed); default "csv" up to :data:`CSV_INDEX_MAX_RUNS` runs.

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
    import numpy as np  # heavy: numpy
    import pandas as pd  # heavy: pandas
    import pyarrow as pa  # heavy: pyarrow
    import pyarrow.compute as pc  # heavy: pyarrow

    n = table.n
    coords = table.coords()
    head = {"run_id": pa.array(table.run_id).cast(pa.large_string()), "run": np.arange(n),  # ids: ASCII bytes
            "base": _text(table.base_labels),
            **{c: pd.Series(v, copy=False) if v.dtype == object else v for c, (_, v) in coords.items()},
            "variant": _text(table.variant)}  # object arrays typed as a DataFrame's columns: text as str
    if len(results):
        kept = [c for c in results.columns if c not in head and c not in NOT_IN_INDEX and c != "converged"]
        done = _reindexed(results, kept, n)
    else:
        done = {"status": pa.nulls(n, pa.large_string()), "message": pa.nulls(n, pa.large_string())}
    del results  # freed here when the caller handed over its only reference
    status, message = _text(done["status"]), _text(done["message"])
    missing = status.is_null().to_numpy(zero_copy_only=False)
    failed = np.zeros(n, dtype=bool)
    if missing.any():
        where = np.flatnonzero(missing)
        failed[where[np.isin(table.run_id[where].astype(str), list(errors))]] = True
        status = pc.if_else(missing, pc.if_else(failed, _text_scalar("error"), _text_scalar("pending")), status)
        message = pc.if_else(missing, _text_scalar(_PENDING), message)
        if failed.any():
            raised = [errors[i] for i in table.run_id[failed].astype(str)]
            message = pc.replace_with_mask(message, failed, pa.array(raised, pa.large_string()))
    done["status"] = status
    done["message"] = message if message.null_count < n else pa.nulls(n)  # no text at all: as pandas infers it
    v0, v1, rise = (pd.to_numeric(pd.Series(done[c], copy=False), errors="coerce").to_numpy(dtype=float)
                    if c in done else np.full(n, np.nan)
                    for c in ("lyapunov_initial", "lyapunov_final", "max_lyapunov_increase"))
    success = pc.equal(status, "success").to_numpy(zero_copy_only=False)
    done["converged"] = np.asarray(converged(success, v0, v1, ratio, rise), dtype=bool)
    templates = getattr(table, "templates", None)
    disturbed = (np.array([bool(t.get("disturbances")) for t in templates])[np.asarray(table.template)]
                 if templates is not None else None)
    done["outcome"] = pa.array(outcomes(status.to_numpy(zero_copy_only=False), message.to_numpy(zero_copy_only=False),
                                        v0, v1, rise, ratio, disturbed=disturbed).tolist(), pa.large_string())
    if "file" in done:
        file = _arrow_array(done["file"])
        if pa.types.is_large_string(file.type) or pa.types.is_string(file.type):
            file = pc.binary_join_element_wise(pa.scalar(RUNS_DIR + "/", file.type), file, pa.scalar("", file.type))
        done["file"] = file
    for column in _INTEGERS:
        if column in done and done[column].dtype.kind != "i":
            done[column] = pd.to_numeric(pd.Series(done[column], copy=False), errors="coerce").round().astype("Int64")
    fixed = {*_HEAD, *_MIDDLE, *_TAIL}
    order = index_columns([dict.fromkeys([*head, *done])], parameters=[c for c in coords if c not in fixed])
    columns = {**head, **done}
    columns = {c: columns[c] for c in order if c in columns}
    written, digests = _write_index_files(directory, columns, csv=wants_csv(index, n))
    statuses = status.dictionary_encode().to_pandas()
    counted = pd.DataFrame({"base": head["base"].dictionary_encode().to_pandas(),
                            "status": statuses, "converged": done["converged"],
                            "outcome": done["outcome"].to_pandas(),
                            "fell": fell_mask(statuses, message.to_numpy(zero_copy_only=False)),
                            **({"wall_time": done["wall_time"]} if "wall_time" in done else {})})
    summary = summarize_columns(counted, name=name, ratio=ratio, parameters=table.parameters())
    summary["index"] = written
    write_summary(directory / SUMMARY_FILE, summary, sha256=digests)
    bad = np.flatnonzero(~success)
    told = [np.nan if m is None else m for m in pc.take(message, bad).to_pylist()]
    return summary, list(zip(table.run_id[bad].astype(str).tolist(), pc.take(status, bad).to_pylist(), told))


def _text(values):
    """Text values (an object array of str, a pandas or pyarrow array; absent values None or
    NaN) as a pyarrow ``large_string`` array, as pandas' ``str`` columns hold them."""
    import pyarrow as pa  # heavy: pyarrow

    if isinstance(values, pa.Array):
        return values.cast(pa.large_string())
    out = pa.array(values, pa.large_string(), from_pandas=True)
    return out.combine_chunks() if isinstance(out, pa.ChunkedArray) else out


def _text_scalar(text: str):
    """``text`` as a pyarrow ``large_string`` scalar."""
    import pyarrow as pa  # heavy: pyarrow

    return pa.scalar(text, pa.large_string())


def _arrow_array(values):
    """One index column (a numpy array, a pandas array or Series, a pyarrow array) as
    ``pyarrow.Table.from_pandas`` converts a DataFrame's column (NaN absent)."""
    import numpy as np  # heavy: numpy
    import pyarrow as pa  # heavy: pyarrow

    if isinstance(values, pa.Array):
        return values
    if isinstance(values, np.ndarray) and values.dtype.kind == "f" and not np.isnan(values).any():
        return pa.array(values)  # the same array: no NaN to look for one by one
    out = pa.array(values, from_pandas=True)
    return out.combine_chunks() if isinstance(out, pa.ChunkedArray) else out


def _reindexed(results, columns: Sequence[str], n: int) -> dict:
    """``columns`` of ``results`` (a DataFrame with a ``run`` column) over the runs 0..n-1,
    the last row of a run counting: as ``results.drop_duplicates("run", keep="last")
    .set_index("run")[columns].reindex(range(n))`` gives them (NaN, integers as floats and
    booleans as objects where a run has no row), each as a numpy or pandas array: the
    columns themselves (no copy) where the rows are every run once, in order."""
    import numpy as np  # heavy: numpy
    import pandas as pd  # heavy: pandas

    runs = results["run"].to_numpy()
    in_order = len(runs) == n and np.array_equal(runs, np.arange(n))  # every run once, in order: no gather
    if not in_order:
        last = ~results["run"].duplicated(keep="last").to_numpy() & (runs >= 0) & (runs < n)
        rows = np.full(n, -1, dtype=np.intp)
        rows[runs[last].astype(np.intp)] = np.flatnonzero(last)
    out = {}
    for c in columns:
        values = results[c]
        values = values.array if isinstance(values.dtype, pd.api.extensions.ExtensionDtype) else values.to_numpy()
        out[c] = values if in_order else pd.api.extensions.take(values, rows, allow_fill=True)
    return out


def wants_csv(index: str | None, n: int) -> bool:
    """Whether a sweep of ``n`` runs writes ``index.csv`` (``index``: :data:`INDEX_FORMATS`
    or None); ValueError names a value not allowed."""
    if index is None:
        return n <= CSV_INDEX_MAX_RUNS
    if index not in INDEX_FORMATS:
        raise ValueError(f"index: found {index!r}; expected one of {', '.join(INDEX_FORMATS)} (or None: csv up to "
                         f"{CSV_INDEX_MAX_RUNS} runs)")
    return index == "csv"


def _write_index_files(directory: Path, columns: Mapping[str, Any], *, csv: bool = True) -> tuple[str, dict]:
    """The index's ``columns`` (name -> numpy, pandas or pyarrow array, in order) as
    :data:`INDEX_ARROW_FILE` and, if ``csv``, as :data:`INDEX_FILE` (else an earlier one is
    removed), atomically, from one Arrow table (each column as ``pyarrow.Table.from_pandas``
    converts it); returns the name of the file that holds the index (the CSV's where both
    are written) and the SHA-256 of ``index.arrow`` (:func:`_write_arrow`) by file name.
    The CSV by pyarrow's writer (numbers formatted in C, ~10x pandas' speed; they read back
    as the same floats), booleans as ``True``/``False``, absent values empty. An index
    Arrow does not take (lists in a column) is written by pandas as the CSV, whatever
    ``csv`` says, and has no Arrow file (:func:`read_index` and :func:`open_sweep` then
    read the CSV)."""
    import pandas as pd  # heavy: pandas
    import pyarrow as pa  # heavy: pyarrow
    import pyarrow.compute as pc  # heavy: pyarrow
    import pyarrow.csv as pa_csv  # heavy: pyarrow

    try:
        arrays = [_arrow_array(values) for values in columns.values()]
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        frame = pd.DataFrame({c: v.to_pandas() if isinstance(v, pa.Array) else v for c, v in columns.items()})
        with atomic_path(directory / INDEX_FILE) as tmp:
            frame.to_csv(tmp, index=False, lineterminator="\n")
        (directory / INDEX_ARROW_FILE).unlink(missing_ok=True)
        return INDEX_FILE, {}
    names = list(columns)
    digests = {INDEX_ARROW_FILE: _write_arrow(directory / INDEX_ARROW_FILE, pa.table(arrays, names=names))}
    if not csv:
        (directory / INDEX_FILE).unlink(missing_ok=True)  # of an earlier invocation: it would not match
        return INDEX_ARROW_FILE, digests
    as_text = [pc.if_else(a, "True", "False") if pa.types.is_boolean(a.type) else a for a in arrays]
    with atomic_path(directory / INDEX_FILE) as tmp:
        pa_csv.write_csv(pa.table(as_text, names=names), tmp, write_options=pa_csv.WriteOptions(quoting_style="needed"))
    return INDEX_FILE, digests


#: Text columns of an index that :func:`open_sweep` gives as text ("" where absent).
_TEXT_COLUMNS = ("status", "message", "run_id", "base", "variant", "lyapunov_rate_check", "config_hash")
#: Text columns of an index with a value a run (not dictionary-encoded in ``index.arrow``).
_UNIQUE_TEXT = ("run_id", "config_hash")


def _write_arrow(path: Path, table) -> str:
    """``table`` (the index as a pyarrow Table) as :data:`INDEX_ARROW_FILE`, atomically:
    uncompressed, the text columns but :data:`_UNIQUE_TEXT` dictionary-encoded; returns
    the file's SHA-256, read back by a thread while the file is flushed to the disk."""
    import pyarrow as pa  # heavy: pyarrow
    import pyarrow.ipc as ipc  # heavy: pyarrow

    text = (pa.types.is_string, pa.types.is_large_string)
    columns = [c.dictionary_encode() if any(t(c.type) for t in text) and name not in _UNIQUE_TEXT else c
               for name, c in zip(table.column_names, table.columns)]
    table = pa.table(columns, names=table.column_names)
    with ThreadPoolExecutor(1) as hasher:
        with atomic_path(path) as tmp:
            with ipc.new_file(str(tmp), table.schema) as writer:
                writer.write_table(table)
            written = open(tmp, "rb", buffering=0)  # opened before atomic_path renames it
            digest = hasher.submit(_sha256, written)
        return digest.result()


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
    from ..io.integrity import DamagedResultError  # heavy: numba, pydantic or h5py

    folder = Path(folder)
    try:
        expected = json.loads((folder / SUMMARY_FILE).read_text(encoding="utf-8")).get("index_sha256")
    except (OSError, ValueError, AttributeError):
        return False
    if not isinstance(expected, str):
        return False
    try:
        actual = _sha256(folder / INDEX_FILE)
    except OSError:
        return False  # reported by the reader
    if actual != expected:
        raise DamagedResultError(
            f"{folder / INDEX_FILE}: does not match its checksum in {SUMMARY_FILE} (damaged, or an "
            f"invocation was killed between writing the two); rebuild both with: rbstab sweep "
            f"{folder / SPEC_FILE} -o {folder.parent}"
        )
    return True


def index_outcomes(index, ratio: float = DEFAULT_LYAPUNOV_RATIO):
    """Each run's outcome (:data:`rbstab.diagnostics.OUTCOMES`) from an index (a DataFrame
    as :func:`read_index` gives it): its ``outcome`` column, and for a row without one (an
    index written before the column, a row added by hand) :func:`rbstab.diagnostics.outcomes`
    of its status, message and v with the sweep's ``ratio``. An object array of str, shape (runs,)."""
    import numpy as np  # heavy: numpy

    n = len(index)
    column = {c: (index[c].to_numpy() if c in index.columns else np.full(n, None, dtype=object))
              for c in ("message", "lyapunov_initial", "lyapunov_final", "max_lyapunov_increase", "outcome")}
    found = outcomes(index["status"].astype(str).to_numpy(), column["message"], column["lyapunov_initial"],
                     column["lyapunov_final"], column["max_lyapunov_increase"], ratio)
    given = np.array([isinstance(v, str) and v != "" for v in column["outcome"]], dtype=bool)
    found[given] = column["outcome"][given]
    return found


def read_index(folder: str | os.PathLike, *, verify: bool = True):
    """The index of a sweep folder as a pandas DataFrame, one row per run, the columns of
    :func:`index_columns`.

    Read from :data:`INDEX_ARROW_FILE` when ``sweep_summary.json`` records its checksum
    and the file is there (:func:`_arrow_index`), else from :data:`INDEX_FILE` (a folder
    written before the Arrow file, or an index Arrow does not take). Both give the same
    frame: ``run_id`` and ``message`` as text (``message`` ``""`` where absent), other
    text as ``str`` with NaN where absent (an empty field; ``n/a`` or ``NA`` are text),
    integers without an absent value as int64, with one as float64 (NaN), ``converged``
    as bool. One difference: a float column whose values are all whole numbers
    (``3000.0``) is int64 from the CSV (it holds ``3000``), float64 from the Arrow file
    (as written).

    Raises
    ------
    FileNotFoundError
        If the folder has no index.
    ValueError
        If it cannot be parsed or lacks ``run_id``/``status``.
    rbstab.io.integrity.DamagedResultError
        If ``verify`` and the file read does not match its checksum
        (:func:`_arrow_index`, :func:`verify_index`; a ValueError).
    """
    folder = Path(folder)
    table = _arrow_index(folder, verify=verify)
    if table is not None:
        path, index = folder / INDEX_ARROW_FILE, _arrow_frame(table)
    else:
        path, index = folder / INDEX_FILE, _csv_frame(folder, verify)
    missing = [c for c in ("run_id", "status") if c not in index.columns]
    if missing:
        raise ValueError(f"{path}: no column {', '.join(missing)} (columns: {', '.join(map(str, index.columns))})")
    index["message"] = index["message"].astype(str).fillna("") if "message" in index else ""
    index["run_id"] = index["run_id"].astype(str)
    return index


def _csv_frame(folder: Path, verify: bool):
    """:data:`INDEX_FILE` as a DataFrame (``run_id``, ``config_hash`` and ``message`` as
    text, NaN where empty); its checksum checked first if ``verify``. FileNotFoundError,
    ValueError, DamagedResultError as :func:`read_index`."""
    import pandas as pd  # heavy: pandas

    path = folder / INDEX_FILE
    if verify:
        verify_index(folder)
    try:
        return pd.read_csv(path, keep_default_na=False, na_values=[""],
                           dtype={"run_id": str, "config_hash": str, "message": str})
    except pd.errors.ParserError as exc:
        raise ValueError(f"{path}: cannot read ({exc})") from None
    except pd.errors.EmptyDataError:
        raise ValueError(f"{path}: empty") from None


def _arrow_frame(table):
    """The index as a pyarrow Table (:func:`_arrow_index`) as the DataFrame
    :func:`_csv_frame` gives: dictionary-encoded text as ``str``, empty text as NaN (an
    empty CSV field), a column of absent values only as float64 NaN; integers with an
    absent value become float64 with NaN (pyarrow's conversion, as the CSV's)."""
    import pyarrow as pa  # heavy: pyarrow
    import pyarrow.compute as pc  # heavy: pyarrow

    columns = []
    for column in table.columns:
        if pa.types.is_dictionary(column.type):
            column = column.cast(column.type.value_type)
        elif pa.types.is_null(column.type):
            column = pa.nulls(len(column), pa.float64())
        if pa.types.is_string(column.type) or pa.types.is_large_string(column.type):
            empty = pc.equal(column, "")
            if pc.any(empty).as_py():
                column = pc.if_else(empty, pa.scalar(None, column.type), column)
        columns.append(column)
    return pa.table(columns, names=table.column_names).to_pandas()


def summarize_columns(index, *, name: str, ratio: float, parameters: Mapping[str, str] | None = None) -> dict:
    """The content of ``sweep_summary.json`` of an index (a DataFrame with ``base``,
    ``status``, ``converged``, ``outcome``, ``fell`` and ``wall_time`` columns): counts (per
    status and per outcome, :data:`rbstab.diagnostics.OUTCOMES`), converged fraction, the failed runs that fell (``n_fell``: :func:`rbstab.engine.status.fell`),
    per base, parameters (name -> config key)."""
    import pandas as pd  # heavy: pandas

    def counts(frame) -> dict[str, Any]:
        status = {s: 0 for s in STATUSES}
        status.update({str(k): int(v) for k, v in frame["status"].value_counts().items()})
        n, converged = len(frame), int(frame["converged"].sum())
        n_fell = int(frame["fell"].sum()) if "fell" in frame else 0
        ended = {word: 0 for word in OUTCOMES}
        if "outcome" in frame:
            ended.update({str(k): int(v) for k, v in frame["outcome"].value_counts().items()})
        return {"n_runs": n, "status": status, "outcomes": ended, "n_converged": converged, "n_fell": n_fell,
                "fraction_converged": converged / n if n else 0.0}

    out: dict[str, Any] = {"name": name, **counts(index)}
    out["convergence"] = {
        "lyapunov_ratio": ratio,
        "definition": RULE,
    }
    out["outcome_definitions"] = dict(OUTCOMES)
    bases = pd.unique(index["base"]).tolist()
    if len(bases) > 1:
        out["by_base"] = {b: counts(index[index["base"] == b]) for b in bases}
    out["parameters"] = dict(parameters or {})
    wall = pd.to_numeric(index["wall_time"], errors="coerce") if "wall_time" in index else pd.Series([], dtype=float)
    out["wall_time_total"] = float(wall.sum())
    out["updated"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out["index"] = INDEX_FILE
    out["spec"] = SPEC_FILE
    return out


def write_summary(path: Path, summary: Mapping[str, Any], *, sha256: Mapping[str, str] | None = None) -> Path:
    """Write ``summary`` as indented JSON, atomically, with the SHA-256 of the ``index.csv``
    and ``index.arrow`` beside it (``index_sha256``, ``index_arrow_sha256``,
    :func:`verify_index`): read from the files, or from ``sha256`` (file name -> hex digest)
    for those just written."""
    summary = dict(summary)
    for name, key in ((INDEX_FILE, "index_sha256"), (INDEX_ARROW_FILE, "index_arrow_sha256")):
        index = Path(path).parent / name
        if index.is_file():
            summary[key] = (sha256 or {}).get(name) or _sha256(index)
    return write_text_atomic(path, json.dumps(summary, indent=2) + "\n")


def _sha256(file) -> str:
    """SHA-256 (hex) of a file: a path, or a file open for binary reading from its position
    (closed after); read a block at a time by ``hashlib.file_digest``."""
    with open(file, "rb", buffering=0) if isinstance(file, (str, os.PathLike)) else file as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


# -- reading a folder -----------------------------------------------------------------------------


def is_sweep_folder(path: str | os.PathLike) -> bool:
    """True when ``path`` is a folder with ``sweep.yaml`` and an index (``index.arrow`` or
    ``index.csv``)."""
    p = Path(path)
    return p.is_dir() and (p / SPEC_FILE).is_file() and has_index(p)


def has_index(folder: Path) -> bool:
    """Whether ``folder`` holds an index file (``index.arrow`` or ``index.csv``)."""
    return (folder / INDEX_ARROW_FILE).is_file() or (folder / INDEX_FILE).is_file()


def read_spec(folder: str | os.PathLike) -> dict:
    """``sweep.yaml`` of a sweep folder, parsed (the resolved spec and its ``generated`` block).

    Raises
    ------
    OSError, ValueError
        If it is missing, not YAML or not a mapping.
    """
    from ..config import ConfigError  # heavy: numba, pydantic or h5py
    from ..config.yaml_io import parse_yaml, read_text_limited  # heavy: numba, pydantic or h5py

    path = Path(folder) / SPEC_FILE
    try:
        data = parse_yaml(read_text_limited(path, "sweep spec")) or {}
    except ConfigError as exc:
        raise ValueError(f"{path}: {'; '.join(exc.errors)}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: not a YAML mapping")
    return data


def _run_file_row(path: Path, verify: bool = False, damaged: list | None = None) -> dict | None:
    from ..io.hdf5 import NotAResultFile, read_attributes  # heavy: numba, pydantic or h5py
    from ..io.integrity import DamagedResultError  # heavy: numba, pydantic or h5py

    try:
        return row_from_attributes(read_attributes(path, data=verify), path.name)
    except DamagedResultError as exc:
        if damaged is not None:
            damaged.append((path.name, str(exc)))
        return None
    except (FileNotFoundError, KeyError):
        return None
    except (NotAResultFile, OSError, ValueError) as exc:
        if damaged is not None and _unopenable(path):
            damaged.append((path.name, f"{path}: cannot be read as a result file ({exc})"))
        return None  # else an HDF5 file that is not rbstab's: left alone


def _unopenable(path: Path) -> bool:
    """Whether ``path`` cannot be opened as an HDF5 file (truncated, emptied, overwritten):
    a damaged result, where an HDF5 file of another program is not one."""
    import h5py  # heavy: h5py

    try:
        with h5py.File(path, "r"):
            return False
    except FileNotFoundError:
        return False
    except (OSError, ValueError):
        return True


def _store_frames(runs_dir: Path, names: Sequence[str], verify: bool, damaged: list) -> list:
    """The rows of the store files ``names`` of ``runs_dir`` as DataFrames; a file that
    fails its checksums, or that cannot be opened as one (truncated, emptied), is listed in
    ``damaged`` as (file name, reason)."""
    from ..io.chunk import read_chunk_columns  # heavy: numba, pydantic or h5py
    from ..io.hdf5 import NotAResultFile  # heavy: numba, pydantic or h5py
    from ..io.integrity import DamagedResultError  # heavy: numba, pydantic or h5py

    frames = []
    for name in names:
        try:
            frames.append(read_chunk_columns(runs_dir / name, data=verify))
        except DamagedResultError as exc:
            damaged.append((name, str(exc)))
        except FileNotFoundError:
            continue
        except (NotAResultFile, OSError, KeyError, ValueError) as exc:
            if _unopenable(runs_dir / name):  # truncated, emptied: damaged; else not rbstab's: left alone
                damaged.append((name, f"{runs_dir / name}: cannot be read as a store file ({exc})"))
    return frames


class StoredRuns:
    """What a sweep's ``runs/`` folder holds, read once as columns (:attr:`frame`).

    A file's digest of its text and attributes is always checked; with ``verify`` every
    checksum of its numbers too (the whole file is read). A damaged store file (checksums
    that fail, or a file that cannot be opened at all: truncated, emptied) counts for
    nothing and is appended to ``damaged`` as (file name, reason).
    """

    def __init__(self, runs_dir: Path, *, verify: bool = False, damaged: list | None = None,
                 skip: set | frozenset = frozenset()) -> None:
        self.runs_dir = runs_dir
        self.damaged = damaged if damaged is not None else []
        # what was there before this invocation (but the files of ``skip``, read before)
        self.files = sorted(p.name for p in runs_dir.glob("*.h5") if p.name not in skip)
        chunks = [n for n in self.files if n.startswith("chunk-")]
        self._frames = _store_frames(runs_dir, chunks, verify, self.damaged)
        self._singles = [r for n in self.files if not n.startswith("chunk-")
                         if (r := _run_file_row(runs_dir / n, verify, self.damaged)) is not None]

    @functools.cached_property
    def frame(self):
        """The stored rows, a DataFrame (made when first read: a folder without files needs
        no pandas)."""
        import pandas as pd  # heavy: pandas (~0.25 s, which a new sweep spends after its first line)

        frames = [*self._frames, *([pd.DataFrame.from_records(self._singles)] if self._singles else [])]
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(
            {"run_id": [], "config_hash": [], "status": [], "created": [], "file": []})

    def current(self, table, *, success_only: bool = False):
        """The newest stored row of each run of ``table`` made from its current
        configuration (its ``config_hash``) with a status other than ``error``
        (``success_only``: ``success``), with a ``run`` column (its position); a DataFrame."""
        import numpy as np  # heavy: numpy
        import pandas as pd  # heavy: pandas

        frame = self.frame
        if frame.empty:
            return frame.assign(run=pd.Series([], dtype=np.int64))
        position = pd.Index(table.run_id.astype(str)).get_indexer(frame["run_id"].astype(str))
        hashes = table.config_hash.astype(str)
        ok = (position >= 0) & (frame["status"].to_numpy() != "error")
        if success_only:
            ok &= frame["status"].to_numpy() == "success"
        ok[ok] = hashes[position[ok]] == frame["config_hash"].astype(str).to_numpy()[ok]
        found = frame[ok].assign(run=position[ok])
        return found.sort_values("created", kind="stable").drop_duplicates("run", keep="last")

    def stale(self, table) -> list[str]:
        """Result files found when this was made that hold no run of ``table`` and are not
        damaged (left in place by the caller)."""
        import pandas as pd  # heavy: pandas

        ids = pd.Index(table.run_id.astype(str))
        frame = self.frame
        used = set(frame.loc[ids.get_indexer(frame["run_id"].astype(str)) >= 0, "file"]) if len(frame) else set()
        bad = {name for name, _ in self.damaged}
        return [name for name in self.files if name not in bad and name not in used]


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


def resolved_config(folder: str | os.PathLike, run_id: str) -> dict:
    """The resolved configuration of run ``run_id`` of a sweep folder (``name``: the run id),
    rebuilt from its result: a store file's template of the run with its parameters set
    (:func:`rbstab.io.chunk.resolved_config`), or a run file's ``config`` attribute.
    ``rbstab.config.config_from_mapping`` makes it a run configuration again (``rbstab run``
    of it repeats the run). Many runs: :func:`resolved_configs`.

    Raises
    ------
    KeyError
        If the index has no run ``run_id``, or the run has no result on disk.
    FileNotFoundError, ValueError
        As :func:`read_index`; a damaged store file as :func:`rbstab.io.chunk.read_chunk_rows`.
    """
    return resolved_configs(folder, [run_id])[run_id]


def resolved_configs(folder: str | os.PathLike, run_ids: Sequence[str]) -> dict[str, dict]:
    """:func:`resolved_config` of each of ``run_ids``, {run id: configuration}, reading the
    index once and each result file once (a store file is verified and read whole: one read
    serves all its runs).

    Raises
    ------
    As :func:`resolved_config`.
    """
    import yaml  # heavy: yaml

    from ..io.chunk import resolved_configs as from_store  # heavy: numba, pydantic or h5py
    from ..io.hdf5 import read_attributes  # heavy: numba, pydantic or h5py

    folder = Path(folder)
    index = read_index(folder).set_index("run_id", drop=False)
    by_file: dict[str, list[tuple[str, int | None]]] = {}
    for run_id in dict.fromkeys(run_ids):
        if run_id not in index.index:
            raise KeyError(f"{folder}: no run {run_id!r} in its index")
        row = index.loc[run_id]
        file, file_row = row["file"], row["file_row"] if "file_row" in index.columns else None
        if not isinstance(file, str) or not file:
            raise KeyError(f"{folder}: run {run_id!r} has no result on disk (status {row['status']})")
        by_file.setdefault(file, []).append((run_id, None if file_row is None or file_row != file_row
                                             else int(file_row)))
    out = {}
    for file, runs in by_file.items():
        if runs[0][1] is not None:  # rows of a store file
            out.update(zip((r for r, _ in runs), from_store(folder / file, [k for _, k in runs])))
            continue
        for run_id, _ in runs:
            config = yaml.safe_load(read_attributes(folder / file)["config"])
            config["name"] = run_id
            out[run_id] = config
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
        ``(run, time[, axis])`` variables (a chain's ``(run, time, body|joint[, axis])``,
        with the ``body`` and ``joint`` names as coordinates). Store files are read lazily (dask arrays, a
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
    columns = _arrow_columns(folder)
    if columns is None:  # written before index.arrow, or an index Arrow does not take
        columns = _frame_columns(read_index(folder))
    ds = _dataset_of(columns)
    stored = _from_store(folder, columns)
    if stored is not None:
        ds = stored.reindex(run=ds["run"].values).assign(
            {k: ds[k] for k in ds.data_vars if k not in stored.data_vars or k in ("status", "message", "converged")}
        ).assign_coords({k: ds[k] for k in ds.coords if k != "run"})
    spec = read_spec(folder)
    ds.attrs.update(sweep=spec.get("name", folder.name), lyapunov_ratio=(spec.get("convergence") or {}).get(
        "lyapunov_ratio"), folder=str(folder))
    parameters = read_parameters(folder, list(columns))
    out = _as_grid(ds, spec) if grid else ds
    return _describe_parameters(out, parameters, spec)


def _describe_parameters(ds, parameters: Mapping[str, str], spec: Mapping[str, Any]):
    """Every parameter coordinate (and grid axis) with ``units``, ``long_name`` and
    ``config_key`` from :data:`rbstab.layout.CONFIG_QUANTITIES`; a grid axis of a list-valued
    key numbered by level has the key's ``config_key`` and a long name saying so."""
    slides = slide_parts(spec)
    for name, entry in parameters.items():
        if name in ds.coords:
            ds[name].attrs.update(parameter_attributes(entry, slides))
    for key in (spec.get("grid") or {}):
        name = parameter_name(key)
        if name in ds.coords and name not in parameters:
            ds[name].attrs.update(long_name=f"level of {key} in the grid (0, 1, ...)", config_key=key)
    return ds


def _arrow_columns(folder: Path) -> dict | None:
    """The columns of :data:`INDEX_ARROW_FILE` as numpy arrays (numbers are views of the
    memory-mapped file), as :func:`_frame_columns` gives those of ``index.csv``; None when
    there is none to read (:func:`_arrow_index`). DamagedResultError if the file does not
    match its checksum."""
    table = _arrow_index(folder)
    if table is None:
        return None
    return {name: _arrow_numpy(name, column) for name, column in zip(table.column_names, table.columns)}


def _arrow_index(folder: Path, verify: bool = True):
    """:data:`INDEX_ARROW_FILE` of a sweep folder as a pyarrow Table over the memory-mapped
    file (numbers are not copied), checked against ``index_arrow_sha256`` of
    ``sweep_summary.json`` first if ``verify``; what :func:`read_index` and
    :func:`open_sweep` read.

    Returns
    -------
    pyarrow.Table or None
        None when the summary records no checksum of the file (a folder written before
        it, or an index Arrow does not take), or is missing, or the file is missing: the
        reader then takes ``index.csv``.

    Raises
    ------
    rbstab.io.integrity.DamagedResultError
        If ``verify`` and the file does not match its checksum (damaged, or an invocation
        killed between writing it and the summary: rerunning the sweep rebuilds both);
        the message names the file and the command that rebuilds it.
    ValueError
        If the file matches but is not an Arrow IPC file.
    """
    import pyarrow as pa  # heavy: pyarrow
    import pyarrow.ipc as ipc  # heavy: pyarrow

    from ..io.integrity import DamagedResultError  # heavy: numba, pydantic or h5py

    try:
        expected = json.loads((folder / SUMMARY_FILE).read_text(encoding="utf-8")).get("index_arrow_sha256")
    except (OSError, ValueError, AttributeError):
        return None
    path = folder / INDEX_ARROW_FILE
    if not isinstance(expected, str) or not path.is_file():
        return None
    mapped = pa.memory_map(str(path)).read_buffer()  # the file's pages, hashed and read without a copy
    if verify and hashlib.sha256(mapped).hexdigest() != expected:
        raise DamagedResultError(
            f"{path}: does not match its checksum in {SUMMARY_FILE} (damaged, or an invocation was killed "
            f"between writing the two); rebuild both with: rbstab sweep {folder / SPEC_FILE} -o {folder.parent}")
    try:
        return ipc.open_file(mapped).read_all()
    except (pa.ArrowInvalid, OSError) as exc:
        raise ValueError(f"{path}: cannot read ({exc})") from None


def _arrow_numpy(name: str, column):
    """One column of ``index.arrow`` as numpy: text as objects (``""`` for an absent value
    of :data:`_TEXT_COLUMNS`, else NaN), numbers without nulls as views, with nulls as
    floats with NaN."""
    import numpy as np  # heavy: numpy
    import pyarrow as pa  # heavy: pyarrow

    column = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    absent = "" if name in _TEXT_COLUMNS else np.nan
    if pa.types.is_dictionary(column.type):
        values = np.array([*column.dictionary.to_pylist(), absent], dtype=object)
        return values[column.indices.fill_null(-1).to_numpy(zero_copy_only=False)]
    if pa.types.is_null(column.type):
        return np.full(len(column), absent, dtype=object if name in _TEXT_COLUMNS else float)
    values = column.to_numpy(zero_copy_only=False)
    if values.dtype == object and column.null_count:
        values[np.equal(values, None)] = absent
    return values


def _frame_columns(index) -> dict:
    """The columns of an index (a DataFrame of ``index.csv``) as numpy arrays: text of
    :data:`_TEXT_COLUMNS` as str objects ("" where absent), ``converged`` as bool."""
    out = {}
    for name in index.columns:
        values = index[name].to_numpy()
        if name == "converged":
            values = index[name].astype(str).eq("True").to_numpy()
        elif values.dtype == object and name in _TEXT_COLUMNS:
            values = index[name].fillna("").astype(str).to_numpy(dtype=object)
        out[name] = values
    return out


def _dataset_of(columns):
    """The index's columns (:func:`_frame_columns`) as a Dataset over ``run``: per-run values
    with units and long names, the parameters, ``run_id``, ``base`` and ``variant`` as
    coordinates; the arrays as they are (no conversion by xarray)."""
    import xarray as xr  # heavy: xarray

    from ..io.chunk import figure_attributes  # heavy: numba, pydantic or h5py

    names = [c for c in columns if c not in ("file", "file_row")]
    coords = {c for c in names if c in ("run_id", "base", "variant") or c in _parameter_set(names)}
    variables = {}
    for name in names:
        if name == "run":
            continue
        units, long_name = figure_attributes(name)
        variables[name] = xr.Variable(("run",), columns[name], {"long_name": long_name, **({"units": units} if units else {})},
                                      fastpath=True)
    return xr.Dataset({k: v for k, v in variables.items() if k not in coords},
                      coords={"run": columns["run"], **{k: v for k, v in variables.items() if k in coords}})


def _parameter_set(columns: Sequence[str]) -> list[str]:
    """Parameter columns of an index: those between ``base`` and ``variant``."""
    columns = list(columns)
    start = columns.index("base") + 1 if "base" in columns else 0
    stop = columns.index("variant") if "variant" in columns else start
    return columns[start:stop]


def _from_store(folder: Path, columns):
    """The traces of the current rows of the store files, lazily (dask arrays, a chunk per
    stretch of runs from one file), over ``run``; None for a store without traces or layout
    "run". ``columns``: the index's (:func:`_frame_columns`).

    The per-run values come from the index (the same names), the units and long names from
    :mod:`rbstab.io.metadata`; the store files are only listed here (names and shapes) and
    verified when their traces are read (:class:`rbstab.io.chunk.StoreTrace`).
    """
    import dask.array as da  # heavy: dask
    import numpy as np  # heavy: numpy
    import pandas as pd  # heavy: pandas
    import xarray as xr  # heavy: xarray

    from ..io.chunk import StoreTrace, store_trace_dimensions  # heavy: numba, pydantic or h5py
    from ..io.metadata import LONG_NAMES, variable_attributes  # heavy: numba, pydantic or h5py

    if "file_row" not in columns or "file" not in columns:
        return None
    file_row, file = columns["file_row"], columns["file"]
    has = ~pd.isna(file_row) & ~pd.isna(file)
    names = [str(f) for f in pd.unique(file[has]) if "chunk-" in str(f)]
    if not names:
        return None
    shapes, time, dims, labels = store_trace_dimensions(folder / name for name in sorted(names))
    if not shapes:
        return None
    keep = np.flatnonzero(has & np.isin(file, names))
    keep = keep[np.argsort(columns["run"][keep], kind="stable")]
    files = file[keep].astype(str)
    file_rows = file_row[keep].astype(np.int64)
    cuts = np.flatnonzero(files[1:] != files[:-1]) + 1
    segments = [(str(folder / files[lo]), file_rows[lo:hi]) for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(files)])]
    data = {}
    for name, tail in shapes.items():
        trace = StoreTrace(name, segments, tail)
        array = da.from_array(trace, chunks=trace.chunks, name=False, asarray=True, meta=np.empty((0,) * trace.ndim))
        attrs = variable_attributes(name) if name in LONG_NAMES else {}
        data[name] = xr.Variable(("run", *dims[name]), array, attrs)
    coords = {"run": columns["run"][keep], "axis": ["x", "y", "z"], **labels}
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
    import numpy as np  # heavy: numpy
    import pandas as pd  # heavy: pandas
    import xarray as xr  # heavy: xarray

    if spec.get("table") is not None and not (spec.get("grid") or spec.get("zip") or (spec.get("random") or {}).get("n")) \
            and not (isinstance(spec.get("base"), list) and len(spec["base"]) > 1):
        return _table_as_grid(ds)
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


def _table_as_grid(ds):
    """A table sweep whose rows are every combination of its columns' levels, once each, as a
    grid over its columns (columns that vary together, e.g. the entries of one vector, are one
    axis, named by the first; the others stay as its coordinates), in the table's order of
    levels. ValueError in one line naming a combination missing or repeated otherwise."""
    import numpy as np  # heavy: numpy
    import pandas as pd  # heavy: pandas
    import xarray as xr  # heavy: xarray

    names = [c for c in ds.coords if ds[c].dims == ("run",) and c not in ("run", "run_id", "base", "variant")]
    axes: dict[str, list[str]] = {}  # axis -> the columns it stands for
    codes: dict[str, np.ndarray] = {}
    for name in names:
        code, _ = pd.factorize(pd.Series(ds[name].to_numpy()).map(repr))
        same = next((a for a, c in codes.items() if np.array_equal(c, code)), None)
        if same is None:
            codes[name], axes[name] = code, [name]
        else:
            axes[same].append(name)
    levels = {a: list(pd.unique(ds[a].to_numpy())) for a in axes}
    axes_with_levels = [a for a in axes if len(levels[a]) > 1]
    if not axes_with_levels:
        return ds
    n = ds.sizes["run"]
    combos = pd.Series(list(zip(*(ds[a].to_numpy().tolist() for a in axes_with_levels))))
    counts = combos.value_counts(sort=False)
    where = ", ".join(axes_with_levels)
    if (counts > 1).any():
        combo = counts.index[int(np.argmax(counts.to_numpy() > 1))]
        raise ValueError(f"sweep {ds.attrs.get('sweep', '')!r}: its table is not a grid over {where}: the combination "
                         f"({_combination(axes_with_levels, combo)}) appears {int(counts.max())} times")
    total = int(np.prod([len(levels[a]) for a in axes_with_levels]))
    if total != n:
        present = set(counts.index)
        combo = next(c for c in product(*(levels[a] for a in axes_with_levels)) if c not in present)
        raise ValueError(f"sweep {ds.attrs.get('sweep', '')!r}: its table is not a grid over {where}: the combination "
                         f"({_combination(axes_with_levels, combo)}) is missing ({n} rows, {total} combinations)")
    dependent = {name: a for a in axes_with_levels for name in axes[a][1:]}
    kept = {name: ds[name] for name in dependent}
    ds = ds.drop_vars(list(dependent))
    midx = pd.MultiIndex.from_arrays([pd.Index(ds[a].to_numpy()) for a in axes_with_levels], names=axes_with_levels)
    ds = ds.drop_vars(axes_with_levels).assign_coords(run_index=("run", ds["run"].to_numpy()))
    ds = ds.assign_coords(xr.Coordinates.from_pandas_multiindex(midx, "run"))
    out = ds.unstack("run")
    for a in axes_with_levels:
        out = out.reindex({a: levels[a]})
    for name, a in dependent.items():  # a column that varies with an axis: a coordinate along it
        first = {}
        for level, value in zip(midx.get_level_values(a), kept[name].to_numpy()):
            first.setdefault(level, value)
        out = out.assign_coords({name: (a, [first[level] for level in levels[a]], kept[name].attrs)})
    out["status"] = out["status"].fillna("pending")
    return out


def _combination(names, values) -> str:
    return ", ".join(f"{n}={v!r}" if isinstance(v, str) else f"{n}={v:g}" if isinstance(v, float) else f"{n}={v}"
                     for n, v in zip(names, values))
