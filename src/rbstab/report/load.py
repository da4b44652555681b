"""Read and validate the inputs of a report: run files and sweep folders.

Everything a report needs is read here, before anything is written:

- a **run file** is an HDF5 result of ``rbstab run`` (``rbstab_format`` attribute, see
  :mod:`rbstab.io.hdf5`); its identity, status, solver statistics and summary figures
  come from :func:`rbstab.io.hdf5.read_summary`, its resolved configuration from the
  ``config`` attribute, and its time series are read on demand (:meth:`RunData.series`);
- a **sweep folder** holds ``sweep.yaml`` (the sweep specification) and ``index.csv``
  (one row per run: ``run_id``, the varied parameters, ``status``, ``message``,
  ``wall_time``, flattened summary figures, ``converged``) beside one result file per run;
- any other **folder** is read as a set of run files (its ``*.h5``, not recursive);
- a **chunk file** (``rbstab sweep --layout chunk``, :mod:`rbstab.io.chunk`) holds many
  runs; each is read as a run (:func:`load_chunk_runs`), given directly, in a folder or
  through a sweep's ``index.csv`` (its ``file`` and ``file_row`` columns).

Which kind an input is, :mod:`rbstab.kinds` says (the registry of input kinds).

:func:`load_inputs` checks every input and raises one :class:`ReportInputError` listing
every problem, so the caller can refuse the whole report before creating anything.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..io.chunk import read_chunk_rows, summary_from_columns
from ..io.hdf5 import NotAResultFile, read_attributes
from ..io.integrity import reading
from ..kinds import CHAIN_RUN, RUN, STORE, SWEEP, inputs_in, is_plain_folder, kind_of
from ..sweep.folder import config_key_of, read_index, read_parameters, read_spec

__all__ = [
    "ReportInputError",
    "RunData",
    "SweepData",
    "ReportInputs",
    "load_inputs",
    "load_run",
    "load_chunk_runs",
    "load_sweep",
    "flatten_config",
]

class ReportInputError(ValueError):
    """Raised when inputs of a report are missing or unreadable.

    Attributes
    ----------
    problems : list of str
        One line per bad input (the message joins them).
    """

    def __init__(self, problems: Sequence[str]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


def flatten_config(config: Any, prefix: str = "") -> dict[str, Any]:
    """Flatten nested mappings into dotted keys, the keys of ``--set`` and of sweeps: a
    list of mappings by its entries' names where each has one (a tree's ``bodies`` and
    ``joints``), else by position (``disturbances``); other lists (vectors, matrices)
    stay leaves.

    Parameters
    ----------
    config : dict or scalar
        A resolved configuration as parsed by ``yaml.safe_load``.
    prefix : str
        Dotted prefix of ``config`` (used by the recursion).

    Returns
    -------
    dict
        ``{"controller.k_t": [[...]], "simulation.t_end": 2.0, ...}``; a tree's
        ``{"bodies.trunk.mass": 46.2, "joints.hip.k_r": [[...]], ...}``;
        ``"disturbances.0.value"``.
    """
    if isinstance(config, list) and config and all(isinstance(e, dict) for e in config):
        named = all(isinstance(e.get("name"), str) for e in config)
        config = {(entry["name"] if named else str(i)): entry for i, entry in enumerate(config)}
    if isinstance(config, dict):
        out: dict[str, Any] = {}
        for key, value in config.items():
            out.update(flatten_config(value, f"{prefix}.{key}" if prefix else str(key)))
        return out
    return {prefix: config}


@dataclass
class RunData:
    """One run result file, as the report sees it.

    Attributes
    ----------
    path : Path
        The HDF5 file.
    label : str
        Name shown in tables and legends: the run's ``name`` attribute, made unique
        among the report's runs (:func:`load_inputs`).
    name, variant, status, message : str
        The file's global attributes.
    wall_time : float
        Integration plus post-processing time [s].
    solver : dict
        ``solver_*`` attributes without the prefix (``nfev``, ``njev``, ``nlu``,
        ``status``, ``message``).
    summary : dict
        ``summary_*`` attributes without the prefix (:func:`rbstab.summary.summarize`);
        vectors are lists of 3 floats.
    config : dict
        The resolved configuration (``config`` attribute parsed as YAML).
    attrs : dict
        Every global attribute as a plain Python value.
    sweep : str or None
        Name of the sweep folder the run belongs to, None for a run given directly.
    row : int or None
        The run's row in a chunk file (:mod:`rbstab.io.chunk`); None for a run file.
    """

    path: Path
    label: str
    name: str
    variant: str
    status: str
    message: str
    wall_time: float
    solver: dict
    summary: dict
    config: dict
    attrs: dict
    sweep: str | None = None
    row: int | None = None
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def ok(self) -> bool:
        """True when the run reached its end time (status ``"success"``)."""
        return self.status == "success"

    @property
    def members(self) -> dict[str, tuple[str, ...]] | None:
        """A tree's bodies and joints, ``{"body": names, "joint": names}`` in the order of
        its file's ``body`` and ``joint`` dimensions (the ``bodies`` and ``joints``
        attributes); None for one body."""
        if self.variant != "chain":
            return None
        return {kind: tuple(n for n in str(self.attrs.get(name) or "").split(",") if n)
                for kind, name in (("body", "bodies"), ("joint", "joints"))}

    @property
    def flat_config(self) -> dict[str, Any]:
        """:func:`flatten_config` of :attr:`config`."""
        if "flat" not in self._cache:
            self._cache["flat"] = flatten_config(self.config)
        return self._cache["flat"]

    def series(self, *names: str) -> dict[str, np.ndarray]:
        """Time series of the run, read from the file (and cached).

        Parameters
        ----------
        *names : str
            Variable names (``theta``, ``omega``, ``position``, ``velocity``,
            ``controller_state``, ``constraint_error``, ``lyapunov``, ``lyapunov_rate``,
            ``lyapunov_rate_numerical``, ...). ``time`` is always included.

        Returns
        -------
        dict of str -> ndarray
            ``time`` shape (n,) [s], 3-vectors shape (n, 3), scalars shape (n,), in the
            units of :meth:`units`; NaN rows after a failure. A name the file does not
            hold (e.g. ``controller_state`` outside ``embedded``) is left out.
        """
        import h5py  # heavy: h5py

        wanted = ["time", *names]
        missing = [n for n in wanted if n not in self._cache]
        if missing:
            with h5py.File(self.path, "r") as f:
                for n in missing:
                    if n in f:
                        whole = self.row is None or n == "time"
                        self._cache[n] = np.asarray(f[n][...] if whole else f[n][self.row], dtype=float)
                        units = f[n].attrs.get("units", "")
                        self._cache[f"units:{n}"] = units.decode() if isinstance(units, bytes) else str(units)
                    else:
                        self._cache[n] = None
        return {n: self._cache[n] for n in wanted if self._cache[n] is not None}

    def drop_series(self) -> None:
        """Forget the time series read so far (other cached values stay)."""
        for key in [k for k in self._cache if isinstance(k, str) and k != "flat"]:
            del self._cache[key]

    def units(self, name: str) -> str:
        """Units attribute of variable ``name`` as stored in the file (e.g. ``"rad s-1"``)."""
        self.series(name)
        return self._cache.get(f"units:{name}", "")


@dataclass
class SweepData:
    """One sweep folder.

    Attributes
    ----------
    path : Path
        The folder (holds ``sweep.yaml`` and ``index.csv``).
    name : str
        The folder's name.
    spec : dict
        ``sweep.yaml`` parsed.
    index : pandas.DataFrame
        ``index.csv``, one row per run, in file order.
    runs : list of (RunData or None)
        The result file of each row of ``index`` (same order); None where the row's file
        is missing (e.g. a run that crashed before writing).
    parameters : list of str
        Swept parameters (see :func:`load_sweep`): a column of ``index``, or a list-valued
        key whose entries were split into columns.
    varied : list of str
        The parameters that take more than one value.
    axes : dict of str -> pandas.Series
        Value of each parameter for each row of ``index`` (numbers, or text for a list).
    entries : dict of str -> str
        The dotted config entry each parameter of :attr:`axes` sets, as ``--grid`` names it
        (``joints.ankle.k_r.0``, ``body.mass:scale``, ``controller.k_c`` for a list;
        ``variant`` and ``base`` themselves).
    """

    path: Path
    name: str
    spec: dict
    index: Any
    runs: list
    parameters: list[str]
    varied: list[str]
    axes: dict = field(default_factory=dict)
    entries: dict = field(default_factory=dict)

    @property
    def run_ids(self) -> list[str]:
        """``run_id`` of each row of :attr:`index`."""
        return [str(r) for r in self.index["run_id"]]


@dataclass
class ReportInputs:
    """Everything a report is built from.

    Attributes
    ----------
    runs : list of RunData
        Runs given directly (files, or the ``*.h5`` of a plain folder), in input order.
    sweeps : list of SweepData
        Sweep folders, in input order.
    paths : list of Path
        The inputs as given (resolved), for the record.
    """

    runs: list[RunData]
    sweeps: list[SweepData]
    paths: list[Path]

    @property
    def all_runs(self) -> list[RunData]:
        """Direct runs followed by the runs of every sweep (files present only)."""
        return self.runs + [r for s in self.sweeps for r in s.runs if r is not None]


def load_run(path: str | os.PathLike, sweep: str | None = None) -> RunData:
    """Read identity, summary and configuration of one result file (no time series).

    Parameters
    ----------
    path : path-like
        An HDF5 result written by ``rbstab run`` or a sweep.
    sweep : str, optional
        Name of the sweep the run belongs to.

    Returns
    -------
    RunData
        With ``label`` = the run's ``name`` attribute.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    rbstab.io.hdf5.NotAResultFile
        If it is not an rbstab run result, or its ``config`` attribute is not YAML, or it
        lacks the time series a report draws.
    """
    import h5py  # heavy: h5py

    path = Path(path)

    attrs = read_attributes(path, data=True)  # every checksum verified
    with reading(path), h5py.File(path, "r") as f:
        absent = [n for n in _REQUIRED_SERIES if n not in f]
    return _run_data(path, attrs, absent, sweep)


#: Time series a report draws; a result file without one of them is refused.
_REQUIRED_SERIES = ("time", "theta", "omega", "constraint_error", "lyapunov", "lyapunov_rate")


def load_chunk_runs(path: str | os.PathLike, sweep: str | None = None) -> list[RunData]:
    """Every run of a sweep store file (:mod:`rbstab.io.chunk`), in row order (no time series).

    A store without traces (``--store summary``) gives runs whose :meth:`RunData.series`
    is empty: their figures and settling times are not drawn.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    rbstab.io.hdf5.NotAResultFile
        If it is not a store file, or a run's ``config`` is not YAML.
    """
    path = Path(path)
    rows = read_chunk_rows(path, data=True)  # every checksum verified
    return [_run_data(path, _store_attributes(row), [], sweep, row=row["file_row"]) for row in rows]


def _store_attributes(row: dict) -> dict:
    """A store file's row in the form of a run file's attributes (``name``, ``summary_*``...):
    one body's figures per axis, a chain's per body or joint (the figure's member) and axis
    (:func:`rbstab.io.chunk.summary_from_columns`)."""
    attrs = {k: v for k, v in row.items()}
    attrs["name"] = row["run_id"]
    members = _member_names(row)
    figures = summary_from_columns(row, members.get("joint"), members.get("body"))
    attrs.update({f"summary_{key}": value for key, value in figures.items()})
    attrs.update({name: ",".join(members[kind]) for kind, name in (("body", "bodies"), ("joint", "joints"))
                  if kind in members})  # as a run file's attributes name them
    return attrs


def _member_names(row: dict) -> dict[str, tuple[str, ...]]:
    """The body and joint names of a store row's chain (its ``config``, canonical JSON):
    ``{"body": ..., "joint": ...}``; {} for one body's row."""
    text = row.get("config") or ""
    if '"joints"' not in text:
        return {}
    try:
        config = json.loads(text)
        return {kind: tuple(str(m["name"]) for m in config.get(section) or ())
                for kind, section in (("body", "bodies"), ("joint", "joints"))}
    except (ValueError, TypeError, KeyError, AttributeError):
        return {}


def _run_data(path: Path, attrs: dict, absent: list[str], sweep: str | None, row: int | None = None) -> RunData:
    where = f"{path}" if row is None else f"{path} (run {attrs.get('name')})"
    text = attrs.get("config", "") or ""
    try:  # a store file's config is JSON (rbstab.config.canonical_config), a run file's YAML
        config = (json.loads(text) if text.lstrip().startswith("{") else yaml.safe_load(text)) or {}
    except (ValueError, yaml.YAMLError) as exc:
        raise NotAResultFile(f"{where}: the config attribute is not valid YAML ({exc})") from None
    if not isinstance(config, dict):
        raise NotAResultFile(f"{where}: the config attribute is not a YAML mapping")
    if absent:
        raise NotAResultFile(f"{path}: rbstab result without the variables {absent}")
    missing_attrs = [k for k in ("name", "status") if k not in attrs]
    if missing_attrs:
        raise NotAResultFile(f"{where}: rbstab result without the attributes {missing_attrs}")
    variant = attrs.get("variant") or (config.get("controller") or {}).get("variant", "")
    return RunData(
        path=path,
        label=str(attrs["name"]),
        name=str(attrs["name"]),
        variant=str(variant),
        status=str(attrs["status"]),
        message=str(attrs.get("message", "")),
        wall_time=float(attrs.get("wall_time", float("nan"))),
        solver={k[len("solver_"):]: v for k, v in attrs.items() if k.startswith("solver_")},
        summary={k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")},
        config=config,
        attrs=attrs,
        sweep=sweep,
        row=row,
    )


def _parameter_axes(index, parameters: dict[str, str], random_keys: set[str]) -> dict[str, Any]:
    """One value per run for each swept parameter (list entries grouped back together).

    ``parameters`` maps the index's parameter columns to their dotted config keys
    (:func:`rbstab.sweep.folder.read_parameters`). The entries of one list-valued key
    (``k_c_0`` .. ``k_c_2`` of ``controller.k_c``) are one parameter: the single varying
    entry if only one varies, the whole list as text (``[4100, 4100, 3280]``) for a grid
    or zip over lists, each varying entry on its own for a random draw. A scale factor
    column (``mass_scale``) stands for its key.
    """
    import pandas as pd  # heavy: pandas

    groups: dict[str, list[str]] = {}
    for column, key in parameters.items():
        if column in index.columns:
            groups.setdefault(config_key_of(key), []).append(column)
    axes: dict[str, Any] = {}
    for key, cols in groups.items():
        scale = [c for c in cols if parameters[c].endswith(":scale")]
        if scale:
            for c in scale:
                axes[c] = index[c]
            continue
        varying = [c for c in cols if index[c].astype(str).nunique(dropna=False) > 1]
        if len(cols) == 1 or len(varying) <= 1:
            name = varying[0] if varying else cols[0]
            axes[name] = index[name]
        elif key in random_keys:
            for c in varying:  # entries drawn independently: one parameter each
                axes[c] = index[c]
        else:
            text = ["[" + ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in row) + "]"
                    for row in index[cols].itertuples(index=False)]
            axes[key] = pd.Series(text, index=index.index, name=key)
    for name in ("variant", "base"):
        if name in index.columns and name not in axes and index[name].astype(str).nunique() > 1:
            axes[name] = index[name]
    return axes


def load_sweep(path: str | os.PathLike) -> SweepData:
    """Read a sweep folder through :mod:`rbstab.sweep.folder`: ``sweep.yaml``, ``index.csv``
    and the stored result of each row.

    The result of a row is the file its ``file`` column names (relative to the folder) at
    its ``file_row`` (a store file) or the whole file (layout "run"); an empty cell (a run
    whose worker raised, or that is pending) keeps ``None``, its status and message coming
    from ``index.csv``. The parameters are the index's parameter columns
    (``sweep_summary.json``'s ``parameters``), grouped by config key
    (:func:`_parameter_axes`), plus ``variant`` and ``base`` where they vary.

    Raises
    ------
    ReportInputError
        If ``sweep.yaml`` or ``index.csv`` is missing or unreadable, ``index.csv`` has no
        ``run_id`` or ``status`` column or no row, or a result file is not an rbstab
        result.
    """
    folder = Path(path)
    try:
        spec = read_spec(folder)
        index = read_index(folder)
    except (OSError, ValueError) as exc:
        raise ReportInputError([f"{folder}: {exc}"]) from None
    if len(index) == 0:
        raise ReportInputError([f"{folder}/index.csv: no runs"])
    problems: list[str] = []
    runs: list[RunData | None] = []
    files: dict[Path, list[RunData] | None] = {}
    for row in index.to_dict("records"):
        file, file_row = row.get("file"), row.get("file_row")
        if not isinstance(file, str) or not file.strip():
            runs.append(None)
            continue
        p = folder / file
        try:
            if file_row is None or (isinstance(file_row, float) and math.isnan(file_row)):
                runs.append(load_run(p, sweep=folder.name))
                continue
            if p not in files:
                files[p] = None
                files[p] = load_chunk_runs(p, sweep=folder.name)
        except (FileNotFoundError, NotAResultFile) as exc:
            problems.append(str(exc))
            continue
        in_file, i = files[p], int(file_row)
        if in_file is None:
            continue  # the file's problem is listed once
        if not (0 <= i < len(in_file)) or in_file[i].name != row["run_id"]:
            problems.append(f"{p}: row {i} is not run {row['run_id']} (index.csv and the store file disagree)")
            continue
        runs.append(in_file[i])
    if problems:
        raise ReportInputError(problems)
    random = spec.get("random") if isinstance(spec.get("random"), dict) else {}
    parameters = read_parameters(folder, index)
    axes = _parameter_axes(index, parameters, set((random or {}).get("params") or {}))
    varied = [c for c, v in axes.items() if v.astype(str).nunique(dropna=False) > 1]
    return SweepData(folder, folder.name, spec, index, runs, list(axes), varied, axes,
                     {name: parameters.get(name, name) for name in axes})


def _unique_labels(runs: Iterable[RunData]) -> None:
    """Make ``label`` unique: repeated names get their parent folder, then a counter."""
    runs = list(runs)
    names = Counter(r.name for r in runs)  # (not list.count: quadratic in a sweep's runs)
    for run in runs:
        if names[run.name] > 1:
            run.label = f"{run.path.parent.name}/{run.name}" if run.sweep is None else f"{run.sweep}/{run.name}"
    seen: dict[str, int] = {}
    for run in runs:
        n = seen.get(run.label, 0)
        seen[run.label] = n + 1
        if n:
            run.label = f"{run.label}#{n + 1}"


def load_inputs(paths: Sequence[str | os.PathLike]) -> ReportInputs:
    """Validate and read every input of a report; nothing is written.

    Parameters
    ----------
    paths : sequence of path-like
        Run files (``*.h5``), sweep folders (``sweep.yaml`` + ``index.csv``) and plain
        folders of run files, in any mix. Repeated paths are read once.

    Returns
    -------
    ReportInputs

    Raises
    ------
    ReportInputError
        Listing every input that does not exist, is not an rbstab result, is an empty
        folder or an unreadable sweep; raised only after all inputs were checked.
    """
    if not paths:
        raise ReportInputError(["no input given: pass run files (*.h5) and/or sweep folders"])
    problems: list[str] = []
    runs: list[RunData] = []
    sweeps: list[SweepData] = []
    seen: set[Path] = set()
    resolved: list[Path] = []
    for raw in paths:
        p = Path(raw)
        key = p.resolve()
        if key in seen:
            continue
        seen.add(key)
        resolved.append(key)
        if not p.exists():
            problems.append(f"{p}: no such file or folder")
        elif is_plain_folder(p):
            files = inputs_in(p, (RUN, CHAIN_RUN, STORE))
            if not files:
                inner = [q.name for q in inputs_in(p, (SWEEP,))]
                if inner:
                    problems.append(
                        f"{p}: not a sweep folder and no result files (*.h5) in it; it holds the "
                        f"sweep folders {', '.join(inner)}: pass those"
                    )
                else:
                    problems.append(
                        f"{p}: empty folder: it holds no result files (*.h5) and is not a sweep "
                        "folder (sweep.yaml + index.csv)"
                    )
            for file in files:
                if file.resolve() in seen:
                    continue
                seen.add(file.resolve())
                try:
                    runs.extend(_load_file(file, kind_of(file, (RUN, CHAIN_RUN, STORE))))
                except (FileNotFoundError, NotAResultFile) as exc:
                    problems.append(str(exc))
        else:
            try:
                kind = kind_of(p, (RUN, CHAIN_RUN, STORE, SWEEP))
                if kind is SWEEP:
                    sweeps.append(load_sweep(p))
                else:
                    runs.extend(_load_file(p, kind))
            except (FileNotFoundError, NotAResultFile) as exc:
                problems.append(str(exc))
            except ReportInputError as exc:
                problems.extend(exc.problems)
    if problems:
        raise ReportInputError(problems)
    _unique_labels(runs)
    for sweep in sweeps:
        _unique_labels([r for r in sweep.runs if r is not None])
    return ReportInputs(runs, sweeps, resolved)


def _load_file(path: Path, kind) -> list[RunData]:
    """The run of a run file, or every run of a store file (``kind``: :data:`rbstab.kinds.RUN`
    or :data:`~rbstab.kinds.STORE`)."""
    return load_chunk_runs(path) if kind is STORE else [load_run(path)]


def safe_filename(text: str) -> str:
    """``text`` reduced to ``[A-Za-z0-9_.-]`` for use in a file name."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "run"
