"""Run result files: netCDF-4 flavoured HDF5 (h5py dimension scales), read by xarray.

Layout of ``<name>.h5``
-----------------------
- dimensions ``time`` (samples, coordinate in s) and ``axis`` (``x``, ``y``, ``z``);
- one variable per output quantity (``theta``, ``omega``, ``position``, ``velocity``,
  ``controller_state`` (embedded only), ``constraint_error``, ``constraint_rate``,
  ``constraint_force``, ``force_h``, ``torque_n``, ``lyapunov``, ``lyapunov_rate``,
  ``lyapunov_rate_numerical`` and the terms of v), each with ``units``, ``long_name``
  and ``description`` attributes (:mod:`rbstab.io.metadata`);
- for a run of the pure sign law of ``sliding``: the variable ``sliding_mode`` (sigma of
  each sample) and, on a dimension ``switching`` (the located events in time order),
  ``switching_time`` [s], ``switching_axis`` (0, 1, 2: the component of E),
  ``switching_kind`` (0 crossing, 1 sliding starts, 2 sliding ends) and
  ``switching_constraint_rate`` (F_i at the event) [m/s] (:mod:`rbstab.engine.switching`);
- global attributes: ``rbstab_format``, ``name``, ``variant``, ``status``, ``message``,
  ``config`` (the resolved configuration as YAML text), ``config_hash``, the provenance
  (:func:`rbstab.io.metadata.provenance_attributes`: ``Conventions = "CF-1.10"``,
  ``title``, ``history``, ``command_line``, ``created``, ``rbstab_version``,
  ``git_commit``, ``git_dirty``, the versions of Python, numpy, scipy, h5py, HDF5, numba
  ...), ``wall_time``, ``solver_*`` statistics, ``summary_*`` figures
  (:func:`rbstab.summary.summarize`) and ``units_of_summary`` (their units, JSON).

A chain run's file (:func:`write_result` of a tree's run, ``rbstab_format`` :data:`CHAIN_FORMAT`,
``variant`` ``chain``) has the same layout with two more dimensions, ``body`` and ``joint``
(their names as coordinates): the state blocks and ``force_h`` along (``time``, ``body``,
``axis``); ``constraint_error``, ``constraint_rate``, ``constraint_force``, ``torque_n``,
``controller_state``, ``joint_theta``, ``joint_omega`` along (``time``, ``joint``,
``axis``); v, its terms
(``lyapunov_translational``, ``lyapunov_rotational``, ``lyapunov_constraint``,
``lyapunov_gravity``, each summed over the bodies and joints) and
rates along ``time``; the global attributes ``bodies`` and ``joints`` list the names.
Its summary figures of one 3-vector per body or joint (shape ``(n_bodies, 3)`` or
``(n_joints, 3)``, rows in the order of ``bodies`` or ``joints``) are stored flattened
(row-major: ``legs_x, legs_y, legs_z, trunk_x, ...``), as netCDF-4 allows only 1-D
attributes; the global attribute ``shape_of_summary`` (JSON, :data:`SUMMARY_SHAPES`) gives
each one's shape, ``{"final_theta": [2, 3], ...}``. :func:`read_attributes` and
:func:`read_dataset` give them back in their shape, as they read the files written before
(whose 2-D attributes netCDF-C does not open).

Open with ``xarray.open_dataset(path)`` (either of xarray's netCDF engines, ``netcdf4``
or ``h5netcdf``), or :func:`read_dataset`
(checksums verified first); :func:`result_dataset` gives the same Dataset for a run in
memory, from the same tables (:func:`variable_attributes`, :data:`COORDINATE_ATTRIBUTES`,
:func:`result_attributes`). Files are written to a
temporary name in the target folder and renamed into place, so an interrupted write
never leaves a half-written result under the final name. Every numeric variable carries a
Fletcher-32 checksum and the file the SHA-256 of its attributes and text
(``rbstab_digest``), verified by :func:`read_summary` (:mod:`rbstab.io.integrity`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..config import canonical_config, config_hash
from ..layout import LYAPUNOV_TERMS, QUANTITIES, is_chain, summary_stride
from ..results import RunResult, plain
from .atomic import write_bytes_atomic
from .integrity import (DATA_DIGEST_ATTR, DIGEST_ATTR, NotAResultFile, content_digest, data_digest_of,
                        fletcher32_chunks, open_result, reading, verify_open_file)
from .metadata import (
    VARIABLE_DESCRIPTIONS,
    VARIABLE_UNITS,
    provenance_attributes,
    summary_units,
    variable_attributes,
)

__all__ = [
    "FORMAT",
    "VARIABLE_UNITS",
    "VARIABLE_DESCRIPTIONS",
    "write_result",
    "write_run",
    "result_dataset",
    "read_dataset",
    "variable_attributes",
    "COORDINATE_ATTRIBUTES",
    "AXIS_LABELS",
    "result_attributes",
    "STORE_MODES",
    "SUMMARY_VARIABLES",
    "CHAIN_SUMMARY_VARIABLES",
    "SWITCHING_VARIABLES",
    "summary_stride",
    "read_attributes",
    "read_summary",
    "read_format",
    "is_run_file",
    "is_chain_run_file",
    "CHAIN_FORMAT",
    "SUMMARY_SHAPES",
    "NotAResultFile",
]

#: Value of the ``rbstab_format`` global attribute of every result file.
FORMAT = "rbstab-run-1"
#: Value of the ``rbstab_format`` global attribute of a chain run's file (:func:`write_result` of a tree's run).
CHAIN_FORMAT = "rbstab-chain-run-1"
#: The formats :func:`read_attributes` and :func:`read_summary` read.
RUN_FORMATS = (FORMAT, CHAIN_FORMAT)

#: Labels of the ``axis`` dimension (vector components).
AXIS_LABELS = ("x", "y", "z")

#: Variables of the ``switching`` dimension (the located events of a pure-sign-law run):
#: name -> ``Switchings`` field (units and names in :mod:`rbstab.io.metadata`).
SWITCHING_VARIABLES = {
    "switching_time": "time",
    "switching_axis": "axis",
    "switching_kind": "kind",
    "switching_constraint_rate": "rate",
}


#: Attributes of the dimension coordinates (HDF5 dimension scales) of a result file.
COORDINATE_ATTRIBUTES = {name: variable_attributes(name) for name in ("time", "axis", "switching", "body", "joint")}


def _attr_value(value: Any) -> Any:
    if isinstance(value, (list, tuple)):
        return np.asarray(value, dtype=float)
    return value


#: Global attribute of a chain run's file: the shape of each summary figure of more than one
#: dimension, stored flattened (row-major), as JSON: ``{"final_theta": [2, 3], ...}``.
SUMMARY_SHAPES = "shape_of_summary"


def _netcdf_attributes(attrs: dict[str, Any]) -> dict[str, Any]:
    """``attrs`` as a netCDF-4 file can hold them: every summary figure of more than one
    dimension (a chain's per body or joint 3-vectors, shape (n_members, 3)) flattened in
    row-major order, and their shapes in :data:`SUMMARY_SHAPES` after ``units_of_summary``.
    Any other attribute as it is (1-D at most)."""
    shapes = {key[len("summary_"):]: list(np.shape(value)) for key, value in attrs.items()
              if key.startswith("summary_") and np.ndim(value) > 1}
    if not shapes:
        return attrs
    text = json.dumps(shapes, separators=(",", ":"))
    out = {}
    for key, value in attrs.items():
        out[key] = np.ravel(value) if key.startswith("summary_") and key[len("summary_"):] in shapes else value
        if key == "units_of_summary":
            out[SUMMARY_SHAPES] = text
    out.setdefault(SUMMARY_SHAPES, text)
    return out


def _summary_in_shape(attrs: dict[str, Any], path: str | os.PathLike) -> dict[str, Any]:
    """Global attributes as read (numpy values) with the summary figures that
    :func:`_netcdf_attributes` flattened back in their shape (row-major) and
    :data:`SUMMARY_SHAPES` left out: a file of either layout reads the same (one whose
    figures are 2-D attributes, as written before, has no :data:`SUMMARY_SHAPES`).

    Raises
    ------
    NotAResultFile
        If :data:`SUMMARY_SHAPES` is not JSON of shapes that fit the figures.
    """
    text = attrs.pop(SUMMARY_SHAPES, None)
    if text is None:
        return attrs
    try:
        for name, shape in json.loads(attribute_value(text)).items():
            key = f"summary_{name}"
            if key in attrs:
                attrs[key] = np.reshape(np.asarray(attrs[key]), [int(n) for n in shape])
    except (ValueError, TypeError, AttributeError) as exc:
        raise NotAResultFile(f"{path}: the {SUMMARY_SHAPES} attribute does not fit the summary figures ({exc})"
                             ) from None
    return attrs


#: What a result file stores (``rbstab sweep --store``): ``full``, every variable at every
#: sample (``rbstab run`` always writes this); ``thinned``, the same format with the
#: variables a report draws (:data:`SUMMARY_VARIABLES`) at every ``store_stride``-th sample
#: (at most :data:`SUMMARY_MAX_SAMPLES`); ``summary``, the attributes only (no time
#: series). The summary figures are computed from every sample in each case.
STORE_MODES = ("full", "thinned", "summary")
#: Variables of a ``thinned`` file (those the run has): the state blocks, E and v with its rates.
SUMMARY_VARIABLES = (
    "theta", "omega", "position", "velocity", "controller_state",
    "constraint_error", "lyapunov", "lyapunov_rate", "lyapunov_rate_numerical",
)
#: Variables of a chain's ``thinned`` file: :data:`SUMMARY_VARIABLES` and what its report
#: draws besides (each joint's Theta_j, N_j with its saturation flags and Lambda_j, and v's terms).
CHAIN_SUMMARY_VARIABLES = SUMMARY_VARIABLES + (
    "joint_theta", "torque_n", "torque_n_saturated", "constraint_force", *LYAPUNOV_TERMS,
)


def result_attributes(
    result: "RunResult", *, command_line: str | None = None, store: str = "full", config_yaml: str | None = None
) -> dict[str, Any]:
    """The global attributes of ``result``'s file, as written (see the module docstring; a
    chain run's: :data:`CHAIN_FORMAT`, ``variant`` ``chain``, its ``bodies`` and ``joints``).

    ``config_yaml`` is ``result.config.to_yaml()`` when the caller already has it.
    """
    config_yaml = result.config.to_yaml() if config_yaml is None else config_yaml
    chain = result.config.chain if is_chain(result.config) else None
    if chain is None:
        variant = result.config.chain.joints[0].variant  # one body's spelling: its controller's law
        identity = {"rbstab_format": FORMAT, "name": result.name, "variant": variant}
        title = f"rbstab run {result.name} ({variant} controller)"
    else:
        identity = {"rbstab_format": CHAIN_FORMAT, "name": result.name, "variant": "chain",
                    "bodies": ",".join(chain.body_names), "joints": ",".join(chain.joint_names)}
        title = f"rbstab run {result.name} (a chain of {chain.size} bod{'y' if chain.size == 1 else 'ies'})"
    attrs = {
        **identity,
        "status": result.status,
        "message": result.message,
        "config": config_yaml,
        "config_hash": config_hash(canonical_config(result.config.resolved)),
        **provenance_attributes(title, command_line=command_line),
        "wall_time": float(result.wall_time),
    }
    attrs.update({f"solver_{k}": v for k, v in result.solver.items() if not k.startswith("solver_")})
    attrs["solver_status"] = int(result.solver.get("solver_status", -1))
    attrs["solver_message"] = result.message
    attrs.update({f"summary_{k}": _attr_value(v) for k, v in result.summary.items()})
    attrs["units_of_summary"] = summary_units(result.summary)
    if store != "full":
        attrs["store"] = store
    if store == "thinned":
        attrs["store_stride"] = summary_stride(len(result.time))
    return attrs


class _Writer:
    """The HDF5 calls of :func:`write_result` through h5py's low-level API.

    Exactly what ``h5py.File(path, "w", track_order=True)``, ``create_dataset(name,
    data=...)``, ``make_scale``, ``dims[i].attach_scale`` and ``attrs[key] = value`` write
    (same types, dataspaces and property lists), without the high-level layer's
    per-call bookkeeping, which cost most of the ~25 ms a file took.
    """

    _types: dict = {}

    def __init__(self, h5py) -> None:
        self.h5py = h5py

    def types(self, dtype: np.dtype):
        """(file type, memory type) as h5py's ``attrs.create`` makes them for ``dtype``."""
        h5t = self.h5py.h5t
        key = dtype.str if dtype.kind != "O" else "vlen-str"
        if key not in self._types:
            self._types[key] = (h5t.py_create(dtype, logical=True), h5t.py_create(dtype))
        return self._types[key]

    def attr(self, oid, name: str, value: Any) -> None:
        h5py = self.h5py
        if isinstance(value, str):
            data = np.array(value, dtype=h5py.string_dtype())
        else:
            data = np.asarray(value)
            if data.dtype.kind in "US":
                data = data.astype(h5py.string_dtype())
        htype, mtype = self.types(data.dtype)
        attr = h5py.h5a.create(oid, name.encode(), htype, h5py.h5s.create_simple(data.shape))
        attr.write(data, mtype=mtype)
        attr.close()

    def dataset(self, parent, name: str, data: np.ndarray, dtype=None):
        """A dataset of ``data``; numeric ones chunked with a Fletcher-32 checksum."""
        h5py = self.h5py
        h5p = h5py.h5p
        dcpl = h5p.create(h5p.DATASET_CREATE)
        dcpl.set_obj_track_times(False)
        dcpl.set_attr_creation_order(0)
        chunks = fletcher32_chunks(data.shape, data.dtype.itemsize) if data.dtype.kind in "fiu" else None
        if chunks is not None:
            dcpl.set_chunk(chunks)
            dcpl.set_fletcher32()
        htype = self.types(np.dtype(dtype) if dtype is not None else data.dtype)[0]
        dset = h5py.h5d.create(parent, name.encode(), htype, h5py.h5s.create_simple(data.shape), dcpl=dcpl)
        dset.write(h5py.h5s.ALL, h5py.h5s.ALL, data)
        return dset


def _describe(w, var, name: str) -> None:
    """The ``units``, ``long_name`` and ``description`` attributes of variable ``name``."""
    for key, value in variable_attributes(name).items():
        w.attr(var, key, value)


def _event_arrays(switching) -> dict[str, np.ndarray]:
    """The ``switching`` dimension's arrays as stored: the event numbers and each variable
    of :data:`SWITCHING_VARIABLES` (integers as they are, the rest as floats)."""
    out = {"switching": np.arange(len(switching.time), dtype=np.int64)}
    for key, name in SWITCHING_VARIABLES.items():
        data = np.ascontiguousarray(getattr(switching, name))
        out[key] = data if data.dtype.kind == "i" else data.astype(float)
    return out


def _write_events(w, root, switching) -> None:
    """The ``switching`` dimension (event number) and its variables (:data:`SWITCHING_VARIABLES`)."""
    h5ds = w.h5py.h5ds
    arrays = _event_arrays(switching)
    scale = w.dataset(root, "switching", arrays["switching"])
    h5ds.set_scale(scale, b"switching")
    _describe(w, scale, "switching")
    for key in SWITCHING_VARIABLES:
        var = w.dataset(root, key, arrays[key])
        h5ds.attach_scale(var, scale, 0)
        _describe(w, var, key)
        var.close()
    scale.close()


def _file_image(time: np.ndarray, outputs: dict[str, np.ndarray], attrs: dict[str, Any],
                switching=None, labels: dict[str, tuple[str, ...]] | None = None,
                dims: dict[str, str] | None = None) -> bytes:
    """The bytes of a result file, built in memory (HDF5's ``core`` driver).

    ``labels``: further dimensions with their names as coordinates (a chain's ``body`` and
    ``joint``); ``dims``: the variables that have one, by name, as their second dimension
    (then ``axis`` third where they are vectors).

    HDF5 never writes to the disk itself: a full disk or a failing device then shows up
    as an ordinary ``OSError`` of the caller's write, with nothing half-open inside HDF5
    (whose clean-up at exit crashes the process after a failed write to a file).
    """
    import h5py  # heavy: h5py

    w = _Writer(h5py)
    h5ds = h5py.h5ds
    # netCDF-4 conventions through HDF5 dimension scales: the file h5netcdf would write
    with h5py.File(f"rbstab-{id(attrs)}.h5", "w", driver="core", backing_store=False, track_order=True) as f:
        root = f.id
        t = w.dataset(root, "time", np.ascontiguousarray(time, dtype=float))
        h5ds.set_scale(t, b"time")
        _describe(w, t, "time")
        axis = w.dataset(root, "axis", np.array(AXIS_LABELS, dtype=object), dtype=h5py.string_dtype())
        h5ds.set_scale(axis, b"axis")
        _describe(w, axis, "axis")
        scales = {}
        for dim, names in (labels or {}).items():
            scales[dim] = w.dataset(root, dim, np.array(names, dtype=object), dtype=h5py.string_dtype())
            h5ds.set_scale(scales[dim], dim.encode())
            _describe(w, scales[dim], dim)
        dims = dims or {}
        for key, values in outputs.items():
            var = w.dataset(root, key, np.ascontiguousarray(values, dtype=float))
            h5ds.attach_scale(var, t, 0)
            if key in dims:
                h5ds.attach_scale(var, scales[dims[key]], 1)
            if var.rank == 2 + (key in dims):
                h5ds.attach_scale(var, axis, var.rank - 1)
            _describe(w, var, key)
            var.close()
        t.close()
        axis.close()
        for scale in scales.values():
            scale.close()
        if switching is not None:
            _write_events(w, root, switching)
        for key, value in _netcdf_attributes(attrs).items():
            w.attr(root, key, value)
        f.flush()
        w.attr(root, DIGEST_ATTR, content_digest(f))
        numbers = {"time": np.ascontiguousarray(time, dtype=float)}
        numbers.update({k: np.ascontiguousarray(v, dtype=float) for k, v in outputs.items()})
        if switching is not None:
            numbers.update(_event_arrays(switching))
        w.attr(root, DATA_DIGEST_ATTR, data_digest_of(numbers))
        f.flush()
        return f.id.get_file_image()


def _chain_dimensions(result: "RunResult", outputs: dict[str, np.ndarray]) -> tuple[dict | None, dict | None]:
    """(labels, dims) of :func:`_file_image` for a chain run's ``outputs``: ``body`` and
    ``joint`` with their names; (None, None) for one body's run."""
    if not is_chain(result.config):
        return None, None
    chain = result.config.chain
    dims = {key: "body" if key in BODY_VARIABLES else "joint" for key, values in outputs.items()
            if values.ndim >= 2 and key not in TREE_VARIABLES}
    return {"body": chain.body_names, "joint": chain.joint_names}, dims


#: A chain file's variables along ``body`` (the others with a second dimension are along
#: ``joint``, but for :data:`TREE_VARIABLES`).
BODY_VARIABLES = tuple(q.name for q in QUANTITIES.values() if q.member == "body")
#: A chain file's vectors of the whole tree: (time, axis).
TREE_VARIABLES = ("com_position", "com_velocity", "net_centre_of_pressure")


def write_run(
    result: "RunResult",
    path: str | os.PathLike,
    *,
    command_line: str | None = None,
    store: str = "full",
    config_yaml: str | None = None,
    config_hash: str | None = None,
) -> dict[str, Any]:
    """:func:`write_result`, returning the file's global attributes as
    :func:`read_attributes` would read them back (so a caller need not reopen the file).
    ``config_hash``: the run's identity in a sweep (default: the hash of its config)."""
    if store not in STORE_MODES:
        raise ValueError(f"store: found {store!r}; expected one of {', '.join(STORE_MODES)}")
    attrs = result_attributes(result, command_line=command_line, store=store, config_yaml=config_yaml)
    if config_hash:
        attrs["config_hash"] = config_hash
    time, outputs = result.time, result.outputs
    switching = getattr(result, "switching", None) if store != "summary" else None
    if store == "thinned":
        stride = attrs["store_stride"]
        time = time[::stride]
        kept = CHAIN_SUMMARY_VARIABLES if is_chain(result.config) else SUMMARY_VARIABLES
        outputs = {k: v[::stride] for k, v in outputs.items() if k in kept}
    elif store == "summary":
        time, outputs = time[:0], {}
    labels, dims = _chain_dimensions(result, outputs)
    write_bytes_atomic(path, _file_image(time, outputs, attrs, switching, labels, dims))
    return {k: attribute_value(np.asarray(v) if isinstance(v, np.ndarray) else v) for k, v in attrs.items()}


def write_result(
    result: "RunResult", path: str | os.PathLike, *, command_line: str | None = None, store: str = "full"
) -> Path:
    """Write one run to ``path`` atomically (temporary file + rename).

    Parameters
    ----------
    result : RunResult
        The run (:func:`rbstab.simulator.simulate`).
    path : path-like
        Final file name; its folder is created if missing.
    command_line : str, optional
        Recorded in the ``command_line`` attribute (default: this process's argv).
    store : {"full", "thinned", "summary"}
        See :data:`STORE_MODES`.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OSError
        If the folder cannot be created or written (a full disk, a read-only folder, a
        name too long): one message with the errno; the final name is then untouched and
        no temporary file is left.
    """
    write_run(result, path, command_line=command_line, store=store)
    return Path(path)


def result_dataset(result: "RunResult", *, command_line: str | None = None):
    """What ``result``'s file holds (store ``full``), as an in-memory :class:`xarray.Dataset`.

    The variables, dimensions, coordinates and attributes of the file :func:`write_result`
    writes (the same tables: :func:`variable_attributes`, :data:`COORDINATE_ATTRIBUTES`,
    :func:`result_attributes`), without writing it and without the checksums of a file.

    Returns
    -------
    xarray.Dataset
        Dimensions ``time`` (coordinate [s]) and ``axis`` (``x``, ``y``, ``z``); vectors
        ``(time, axis)``, scalars ``(time,)``, each with ``units``, ``long_name`` and
        ``description`` (:mod:`rbstab.io.metadata`); a chain's run also has ``body`` and
        ``joint`` (their names as coordinates), its per-body and per-joint variables
        ``(time, body[, axis])`` and ``(time, joint[, axis])``, as in its file; a
        pure-sign-law run also has the ``switching`` dimension and its variables.
    """
    import xarray as xr  # heavy: xarray

    coords = {
        "time": ("time", np.asarray(result.time, dtype=float), dict(COORDINATE_ATTRIBUTES["time"])),
        "axis": ("axis", np.array(AXIS_LABELS), dict(COORDINATE_ATTRIBUTES["axis"])),
    }
    labels, dims = _chain_dimensions(result, result.outputs)
    for dim, names in (labels or {}).items():
        coords[dim] = (dim, np.array(names), dict(COORDINATE_ATTRIBUTES[dim]))
    dims = dims or {}
    variables = {
        key: ((("time", dims[key], "axis") if key in dims else ("time", "axis"))[: np.ndim(values)],
              np.asarray(values, dtype=float), variable_attributes(key))
        for key, values in result.outputs.items()
    }
    if getattr(result, "switching", None) is not None:
        arrays = _event_arrays(result.switching)
        coords["switching"] = ("switching", arrays.pop("switching"), dict(COORDINATE_ATTRIBUTES["switching"]))
        variables.update({key: ("switching", data, variable_attributes(key)) for key, data in arrays.items()})
    return xr.Dataset(variables, coords, attrs=result_attributes(result, command_line=command_line))


def read_dataset(path: str | os.PathLike):
    """A verified result file as an in-memory :class:`xarray.Dataset` (the file is closed).

    Every checksum is checked first (:func:`read_attributes` with ``data``); the file's
    own checksum attributes are left out (what :func:`result_dataset` gives for its run).

    Raises
    ------
    FileNotFoundError, NotAResultFile, DamagedResultError
        See :func:`read_attributes`.
    """
    import xarray as xr  # heavy: xarray

    read_attributes(path, data=True)
    with reading(path), xr.open_dataset(path, engine="h5netcdf") as ds:
        ds = ds.load()
    for key in (DIGEST_ATTR, DATA_DIGEST_ATTR):
        ds.attrs.pop(key, None)
    ds.attrs = _summary_in_shape(dict(ds.attrs), path)
    return ds


def attribute_value(value: Any) -> Any:
    """An HDF5 attribute's value as plain Python (:func:`rbstab.results.plain`): text
    decoded, an array of one element that element."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray) and value.shape in ((), (1,)):
        return value.item()
    return plain(value)


def read_format(path: str | os.PathLike) -> str | None:
    """The ``rbstab_format`` attribute of an HDF5 file (every file rbstab writes has one:
    :data:`FORMAT`, a store file's :data:`rbstab.io.chunk.CHUNK_FORMAT`, an analysis
    file's :data:`rbstab.analysis.dataset.FORMAT`); None for an HDF5 file without it.

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file.
    NotAResultFile
        If it is not an HDF5 file.
    rbstab.io.integrity.DamagedResultError
        If its attributes cannot be read (a damaged file).
    """
    with open_result(path) as f:
        value = attribute_value(f.attrs.get("rbstab_format"))
    return value if value is None else str(value)


def is_chain_run_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a chain run's result file (``rbstab_format`` = :data:`CHAIN_FORMAT`);
    False for anything else."""
    try:
        return read_format(path) == CHAIN_FORMAT
    except (OSError, ValueError):
        return False


def is_run_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a run's result file (``rbstab_format`` = :data:`FORMAT`);
    False for anything else, a folder or a file that cannot be read included."""
    try:
        return read_format(path) == FORMAT
    except (OSError, ValueError):
        return False


#: Attributes every result file has (:func:`read_summary` refuses a file without one).
REQUIRED_ATTRIBUTES = ("name", "variant", "status", "message", "config_hash", "wall_time", "created")


def read_attributes(path: str | os.PathLike, *, verify: bool = True, data: bool = False) -> dict[str, Any]:
    """Global attributes of a result file as plain Python values (without its checksum).

    Parameters
    ----------
    path : path-like
    verify : bool
        Check the file's digest of its attributes and text (:mod:`rbstab.io.integrity`).
    data : bool
        Also check the Fletcher-32 checksums of every variable (reads the whole file).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotAResultFile
        If it is not an HDF5 file written by rbstab.
    rbstab.io.integrity.DamagedResultError
        If ``verify`` and its checksums do not match (a subclass of NotAResultFile).
    """
    path = Path(path)
    with open_result(path) as f:
        raw = {k: v for k, v in f.attrs.items() if k not in (DIGEST_ATTR, DATA_DIGEST_ATTR)}
        run = attribute_value(raw.get("rbstab_format")) in RUN_FORMATS
        if run and verify:
            verify_open_file(f, path, data=data)
    if not run:
        raise NotAResultFile(f"{path}: not an rbstab run result (no rbstab_format = {FORMAT!r} attribute)")
    return {k: attribute_value(v) for k, v in _summary_in_shape(raw, path).items()}


def read_summary(path: str | os.PathLike) -> dict[str, Any]:
    """Identity, status, solver statistics and summary figures of a verified result file
    (every checksum checked, :mod:`rbstab.io.integrity`).

    Returns
    -------
    dict
        ``name``, ``variant``, ``status``, ``message``, ``config_hash``, ``wall_time``,
        ``solver`` (dict) and ``summary`` (dict, keys of
        :func:`rbstab.summary.summarize`).

    Raises
    ------
    FileNotFoundError, NotAResultFile, DamagedResultError
        See :func:`read_attributes`; NotAResultFile also for a file without one of
        :data:`REQUIRED_ATTRIBUTES`.
    """
    attrs = read_attributes(path, data=True)
    missing = [k for k in REQUIRED_ATTRIBUTES if k not in attrs]
    if missing:
        raise NotAResultFile(f"{path}: an rbstab result without the attributes {', '.join(missing)}")
    return {
        "name": attrs["name"],
        "variant": attrs["variant"],
        "status": attrs["status"],
        "message": attrs["message"],
        "config_hash": attrs["config_hash"],
        "wall_time": attrs["wall_time"],
        "created": attrs["created"],
        "solver": {k[len("solver_"):]: v for k, v in attrs.items() if k.startswith("solver_")},
        "summary": {k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")},
    }
