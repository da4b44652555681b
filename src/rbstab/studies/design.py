"""Designs of studies: the varied parameters (``--vary``), the table of runs and its execution.

A study varies config keys with the sweep's distributions (:mod:`rbstab.sweep.spec`,
``uniform``, ``log_uniform``, ``normal``, ``scale_uniform``, ``choice``). Each ``--vary``
entry is a :class:`Varied`: it has one or more **factors** (the inputs of the sensitivity
method or of the optimiser), each on the unit interval, and one or more **columns** of the
design table (the absolute values set in the configuration):

- a number, or bounds of one shape as the value (``uniform: [[10, 20, -30], [12, 40, -20]]``):
  one factor per component, each its own column;
- ``scale_uniform`` (``scale_log_uniform``: the factor log-uniform) with number bounds: one
  factor ``KEY:scale`` that multiplies the whole base value (a vector or a matrix keeps its
  shape, as sweeps scale them); the columns hold ``base * factor``; with list bounds one
  factor per component;
- ``choice``: one factor picking one of the values.

Design tables are :class:`pandas.DataFrame` objects of absolute values, one row per run,
columns named by dotted config keys: a number ``body.mass``, vector components
``controller.k_c[0]`` .. ``[2]``, matrix entries ``body.inertia[0,1]``. :func:`run_design`
runs one as a sweep (resumable: a run whose result exists is skipped) and returns its
summary figures.

A chain's configuration (``bodies`` and ``joints``, :mod:`rbstab.config.loader`) takes the
keys of chain sweeps: a body or a joint by index or name (``bodies.1.mass``,
``joints.hip.k_r.0``), an initial state by body name (``initial_state.trunk.theta.0``).
Its summary figures are those of one body's runs, per body or joint as a sweep's columns
name them (:func:`rbstab.io.chunk.summary_columns`: ``max_abs_constraint_error_hip_z`` [m],
``final_theta_trunk_x`` [rad]); its runs are integrated as one body's, the runs of one
chain together (:func:`rbstab.simulator.simulate_blocks`).
"""

from __future__ import annotations

import difflib
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from pydantic import ValidationError

from ..config import ConfigError, parse_yaml
from ..config.paths import KeyPathError, plain_tree
from ..convergence import DEFAULT_LYAPUNOV_RATIO, converged
from ..engine import ensure_compiled
from ..results import plain
from ..engine.registry import DEFAULT_ENGINE
from ..io.chunk import SUMMARY_FIGURES, figure_attributes, split_figure_column, summary_columns
from ..layout import SIGN_LAW_FIGURES, is_chain
from ..layout import SUMMARY_FIGURES as SUMMARY_QUANTITIES
from ..simulator import simulate_many
from ..sweep.folder import open_sweep
from ..sweep.runner import run_sweep
from ..sweep.schema import DISTRIBUTIONS, DistributionSchema
from ..sweep.spec import Distribution, spec_from_mapping
from ..sweep.validate import key_path

__all__ = ["StudyInputError", "Varied", "parse_vary", "column_names", "design_mappings", "run_design",
           "study_folder", "nominal_figures", "vary_mapping", "METRICS_NOT_FIGURES", "check_metrics", "expand_metrics", "figure_columns",
           "Members", "members_of"]


class StudyInputError(ConfigError):
    """An invalid study option (``--vary``, ``--metric``, ``--subject-to``, ...): ``errors``
    lists one line per problem, each naming the option, the value found and what is allowed."""


#: Per-run values of a sweep that are bookkeeping, not figures a study can take as a metric.
METRICS_NOT_FIGURES = ("lyapunov_rate_check",)

#: Distributions of a factor of the base value, and those searched on a log scale.
SCALES = ("scale_uniform", "scale_log_uniform")
LOG_SCALED = ("log_uniform", "scale_log_uniform")

_COLUMN = re.compile(r"^(?P<key>[^\[\]]+)\[(?P<index>\d+(?:,\d+)*)\]$")


# -- the varied parameters -----------------------------------------------------------------------


def column_names(key: str, shape: tuple[int, ...]) -> list[str]:
    """Design columns of a value of ``shape`` at ``key``: ``key``, ``key[i]`` or ``key[i,j]``."""
    if not shape:
        return [key]
    return [f"{key}[{','.join(map(str, index))}]" for index in np.ndindex(*shape)]


@dataclass(frozen=True)
class Varied:
    """One varied config key and how unit factors map to its absolute values.

    Attributes
    ----------
    key : str
        Dotted config key.
    kind : str
        One of :data:`rbstab.sweep.spec.DISTRIBUTIONS`.
    args : tuple
        The distribution's arguments (:class:`rbstab.sweep.spec.Distribution`).
    base : ndarray or None
        The base configuration's value at ``key`` (``scale_uniform``, ``scale_log_uniform`` only).
    shape : tuple of int
        Shape of the value set in the config (() for a number).
    """

    key: str
    kind: str
    args: tuple
    base: np.ndarray | None
    shape: tuple[int, ...]

    @property
    def columns(self) -> list[str]:
        """The design table's columns of this key."""
        return column_names(self.key, self.shape)

    @property
    def factor_shape(self) -> tuple[int, ...]:
        """Shape of the factors (() for one factor)."""
        if self.kind == "choice":
            return ()
        return np.broadcast_shapes(*(np.shape(a) for a in self.args))

    @property
    def factors(self) -> list[str]:
        """Factor names: a column name, or ``<key>:scale`` / ``<column>:scale`` for scale factors."""
        names = column_names(self.key, self.factor_shape)
        return [f"{n}:scale" for n in names] if self.kind in SCALES else names

    def bounds(self) -> list[tuple[float, float]]:
        """(lo, hi) of each factor in its own units (a scale factor: the factor); for a
        search range (``uniform``, ``log_uniform``, ``scale_uniform``, ``scale_log_uniform``)."""
        lo, hi = (np.broadcast_to(a, self.factor_shape).ravel() for a in self.args)
        return list(zip(lo.tolist(), hi.tolist()))

    def from_factors(self, f: np.ndarray) -> np.ndarray:
        """Absolute values of the columns, shape (n, len(columns)), from factor values
        ``f`` (n, len(factors)) in the distribution's own units (a scale factor, a value)."""
        f = np.asarray(f, dtype=float).reshape(len(f), *self.factor_shape)
        if self.kind in SCALES:  # one factor for the whole value, or one per entry
            f = f.reshape(len(f), *self.factor_shape, *[1] * (self.base.ndim - len(self.factor_shape)))
            return (self.base[None] * f).reshape(len(f), -1)
        return f.reshape(len(f), -1)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Absolute values, shape (n, len(columns)), from unit factors ``u`` (n,
        len(factors)) in [0, 1]: the inverse of each factor's distribution function."""
        u = np.asarray(u, dtype=float)
        if self.kind == "choice":
            (values,) = self.args
            pick = np.minimum((u[:, 0] * len(values)).astype(int), len(values) - 1)
            return np.array([[values[i]] for i in pick], dtype=object)
        if self.kind == "normal":
            from scipy.stats import norm  # scipy.stats: ~0.3 s to import, only for normal factors

            mean, std = (np.broadcast_to(a, self.factor_shape).ravel() for a in self.args)
            return norm.ppf(np.clip(u, 1e-12, 1 - 1e-12), mean, std)
        lo, hi = (np.broadcast_to(a, self.factor_shape).ravel() for a in self.args)
        if self.kind in LOG_SCALED:
            return self.from_factors(np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))))
        return self.from_factors(lo + u * (hi - lo))


def parse_vary(texts: Sequence[str] | Mapping[str, Any], base: Mapping, *, option: str = "--vary",
               allowed: Sequence[str] | None = None) -> list[Varied]:
    """``KEY=DISTRIBUTION`` entries (the sweep's ``--random`` syntax) as :class:`Varied`.

    Parameters
    ----------
    texts : sequence of str or Mapping
        ``["body.mass=uniform:[30,50]", "controller.k_c=scale_uniform:[0.5,2]"]``, or a
        mapping key -> distribution mapping (``{"body.mass": {"uniform": [30, 50]}}``).
    base : Mapping
        The resolved base configuration (``RunConfig.resolved``).
    option : str
        The option named in messages.
    allowed : sequence of str, optional
        Distributions allowed (default: all of :data:`rbstab.sweep.spec.DISTRIBUTIONS`).

    Raises
    ------
    StudyInputError
        Listing every entry that is malformed, names no config key of the base, overlaps
        another, has an invalid distribution, one not ``allowed``, or bounds whose shape
        does not fit the value (checked again per run when the runs are planned).
    """
    allowed = tuple(allowed or DISTRIBUTIONS)
    entries: list[tuple[str, str, Any]] = []
    errors: list[str] = []
    items = texts.items() if isinstance(texts, Mapping) else [(None, t) for t in texts]
    for key, text in items:
        if key is None:
            key, sep, rest = str(text).partition("=")
            name, colon, args = rest.partition(":")
            if not sep or not key.strip() or not colon:
                errors.append(f"{option} {text!r}: expected KEY=DISTRIBUTION, e.g. body.mass=uniform:[30,50] "
                              f"({', '.join(allowed)})")
                continue
            try:
                value = {name.strip(): parse_yaml(args)}
            except ConfigError as exc:
                errors.append(f"{option} {text!r}: the distribution's arguments are not valid YAML: {exc.errors[0]}")
                continue
            entries.append((key.strip(), str(text), value))
        else:
            entries.append((key, f"{key}={text}", text))
    varied = [v for v in (_one_varied(key, shown, value, base, option, allowed, errors) for key, shown, value in entries)
              if v is not None]
    keys = [_by_index(v.key, base) for v in varied]  # a chain's body or joint by index, as by name
    for a, shown_a in zip(keys, varied):
        for b, shown_b in zip(keys, varied):
            if a != b and b.startswith(a + "."):
                errors.append(f"{option}: '{shown_a.key}' and '{shown_b.key}' overlap; vary a key or its entries, "
                              "not both")
    for key in sorted({k for k in keys if keys.count(k) > 1}):
        given = [v.key for k, v in zip(keys, varied) if k == key]
        errors.append(f"{option}: a key is given twice ({' and '.join(dict.fromkeys(given))})")
    if not errors and not varied:
        errors.append(f"{option}: nothing varied; give at least one KEY=DISTRIBUTION")
    if errors:
        raise StudyInputError(errors)
    return varied


def _one_varied(key: str, shown: str, value: Any, base: Mapping, option: str, allowed: Sequence[str],
                errors: list[str]) -> Varied | None:
    """One entry of :func:`parse_vary`, or None with its problems appended to ``errors``."""
    try:
        path = key_path(key, base)  # a chain's keys for a chain's configuration
        current = path.get(base, None)
        path.set(plain_tree(base), current)  # a key the base cannot take (an entry of a list it lacks)
    except KeyPathError as exc:
        errors.append(f"{option} {shown!r}: {exc.problem}")
        return None
    if is_chain(base) and path.section == "initial_state":  # a mapping by body name: setting it adds a name
        bodies = [b.get("name") for b in base.get("bodies") or ()]
        if path.entry not in bodies:
            errors.append(f"{option} {shown!r}: 'initial_state' is by body name; found {str(path.entry)!r}, "
                          f"expected one of {', '.join(map(str, bodies))}")
            return None
    kind = next(iter(value)) if isinstance(value, Mapping) and len(value) == 1 else None
    if kind is not None and kind not in allowed:
        errors.append(f"{option} {shown!r}: distribution {kind!r} is not allowed here; expected one of "
                      f"{', '.join(allowed)}")
        return None
    try:
        dist = Distribution.from_schema(key, DistributionSchema.model_validate(value))
    except ValidationError as exc:
        detail = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'value'}: {e['msg']}" for e in exc.errors())
        errors.append(f"{option} {shown!r}: invalid distribution ({detail}); expected one of {', '.join(allowed)}, "
                      "e.g. uniform:[30,50], scale_uniform:[0.5,2], 'normal:{mean: 41, std: 4}', choice:[a,b]")
        return None
    if dist.kind == "choice":
        return Varied(key, dist.kind, dist.args, None, ())
    shape = np.broadcast_shapes(*(np.shape(a) for a in dist.args))
    if dist.kind not in SCALES:
        return Varied(key, dist.kind, dist.args, None, shape)
    base_value = np.asarray(current, dtype=float) if current is not None and _numeric(current) else None
    if base_value is None:
        found = "no value (it is not set)" if current is None else repr(current)
        errors.append(f"{option} {shown!r}: {dist.kind} scales the base value of '{key}', found {found}; "
                      "expected a number or a list of numbers in the base configuration (or vary it with uniform)")
        return None
    if shape and shape != base_value.shape:
        errors.append(f"{option} {shown!r}: {dist.kind} bounds of shape {shape} do not fit '{key}' of shape "
                      f"{base_value.shape}; give numbers (one factor) or lists of its shape")
        return None
    return Varied(key, dist.kind, dist.args, base_value, base_value.shape)


def _by_index(key: str, base: Mapping) -> str:
    """``key`` with a chain's body or joint named by its index (``joints.hip.k_r`` ->
    ``joints.1.k_r``): two keys of one value read alike."""
    parts = key.split(".")
    if is_chain(base) and len(parts) > 1 and parts[0] in ("bodies", "joints"):
        names = [e.get("name") if isinstance(e, Mapping) else None for e in base.get(parts[0]) or ()]
        if parts[1] in names:
            parts[1] = str(names.index(parts[1]))
    return ".".join(parts)


def vary_mapping(varied: Sequence[Varied]) -> dict[str, dict]:
    """The varied keys as a sweep spec writes random parameters: key -> ``{kind: args}``."""
    return {v.key: Distribution(v.key, v.kind, v.args).to_mapping() for v in varied}


def _numeric(value: Any) -> bool:
    try:
        return np.asarray(value, dtype=float).size > 0
    except (TypeError, ValueError):
        return False


_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


def study_folder(output: str | os.PathLike, name: str | None, config, *, option: str = "--name") -> Path:
    """``<output>/<name>`` of a study (``name`` default: the config's name).

    Raises
    ------
    StudyInputError
        For a name that is not letters, digits, ``_``, ``.`` and ``-`` (it names a folder).
    """
    name = config.name if name is None else name
    if not isinstance(name, str) or not _NAME.match(name) or name in (".", ".."):
        raise StudyInputError([f"{option} {name!r}: expected a name of letters, digits, '_', '.' and '-' "
                               "(it names the study's folder)"])
    return Path(output) / name


# -- metrics ---------------------------------------------------------------------------------------

class Members(NamedTuple):
    """The names of a tree's bodies and joints, in order: its figures' columns are named by
    them (:func:`rbstab.io.chunk.summary_columns`)."""

    bodies: tuple[str, ...]
    joints: tuple[str, ...]


def members_of(config) -> Members | None:
    """The body and joint names of a chain's configuration (a
    :class:`rbstab.config.RunConfig` or its resolved mapping); None for a one-body
    configuration."""
    data = config if isinstance(config, Mapping) else getattr(config, "resolved", None)
    if not is_chain(data):
        return None
    return Members(tuple(str(b["name"]) for b in data.get("bodies") or ()),
                   tuple(str(j["name"]) for j in data.get("joints") or ()))


def _figure_names() -> dict[str, tuple[str, str]]:
    return {k: v for k, v in SUMMARY_FIGURES.items() if k not in METRICS_NOT_FIGURES}


def _metric_parts(name: str, members: Members | None) -> tuple[str, str | None, str | None] | None:
    """(figure, member, axis) of a metric name (:func:`rbstab.io.chunk.split_figure_column`),
    None for a name that is no figure of these runs (``converged``: ``("converged", None, None)``)."""
    if name == "converged":
        return name, None, None
    parts = split_figure_column(name, *(members or ((), ())))
    left_out = METRICS_NOT_FIGURES + (SIGN_LAW_FIGURES if members is not None else ())  # a tree has no sign law
    return parts if parts is not None and parts[0] not in left_out else None


def _allowed_words(members: Members | None) -> tuple[list[str], str]:
    """(the whole metric names, the sentence listing what is allowed) of one body's runs,
    or of a tree's with ``members``."""
    known = ["converged", *_figure_names()]
    if members is None:
        return known, f"allowed: {', '.join(known)} (3-vectors also as <name>_x, _y, _z)"
    known = [k for k in known if k not in SIGN_LAW_FIGURES]
    return known, (f"allowed for a chain: {', '.join(known)}, each of every body or joint, or of one as "
                   f"<name>_<body or joint> (3-vectors also _x, _y, _z after it; bodies: {', '.join(members.bodies)}; "
                   f"joints: {', '.join(members.joints)})")


def check_metrics(names: Sequence[str], *, option: str = "--metric", members: Members | None = None) -> None:
    """Raise :class:`StudyInputError` for a name that is no summary figure of a run.

    Allowed: ``converged`` (1 when the run succeeded and v(t_end) <= lyapunov_ratio v(0),
    else 0) and the summary figures of :data:`rbstab.io.chunk.SUMMARY_FIGURES` but the
    text ``lyapunov_rate_check``: as a whole, a 3-vector's component ``<name>_x``, ``_y``,
    ``_z``, and with ``members`` (a tree's body and joint names) one body's or joint's
    ``<name>_<member>[_<axis>]``, as a sweep's columns are named.
    """
    allowed, words = _allowed_words(members)
    errors = []
    for name in names:
        if _metric_parts(name, members) is not None:
            continue
        close = difflib.get_close_matches(name, allowed, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        what = "not a summary figure"
        stem = max((f for f in _figure_names() if name.startswith(f"{f}_")), key=len, default=None)
        if stem is not None and members is not None:
            kind = SUMMARY_QUANTITIES[stem].member or "member"
            what, hint = f"this chain has no {kind} {name[len(stem) + 1:].rpartition('_')[0] or name[len(stem) + 1:]!r}", ""
        errors.append(f"{option} {name!r}: {what}{hint}; {words}")
    if errors:
        raise StudyInputError(errors)


def expand_metrics(names: Sequence[str], available: Sequence[str], *, option: str = "--metric",
                   members: Members | None = None) -> list[str]:
    """The columns of ``available`` that ``names`` select: a name itself, or every column
    of it (:func:`rbstab.io.chunk.split_figure_column`: a 3-vector's components, with
    ``members`` a tree's members and their components; ``<name>_<member>`` that member's,
    ``<name>_<axis>`` that component of every member).

    Raises
    ------
    StudyInputError
        For a name with no column (a figure the variant does not have, e.g.
        ``final_controller_state`` of a variant without controller state).
    """
    split = {c: _metric_parts(c, members) for c in available}
    rank = {m: i for i, m in enumerate((*members.bodies, *members.joints) if members else ())}
    out, errors = [], []
    for name in names:
        want = _metric_parts(name, members)
        parts = [name] if name in available else sorted((
            c for c, got in split.items() if want is not None and got is not None and got[0] == want[0]
            and want[1] in (None, got[1]) and want[2] in (None, got[2])),
            key=lambda c: (rank.get(split[c][1], -1), "xyz".find(split[c][2] or "")))  # the tree's order
        if not parts:
            errors.append(f"{option} {name!r}: these runs have no such figure; they have "
                          f"{', '.join(c for c in available)}")
        out += [p for p in parts if p not in out]
    if errors:
        raise StudyInputError(errors)
    return out


def nominal_figures(config, engine: str | None = None) -> dict[str, float]:
    """The figures of the base configuration (one body's or a chain's; one run in this
    process, :func:`figure_columns`): the columns a study's metrics are chosen from."""
    (_, result), = simulate_many([config], engine=engine or DEFAULT_ENGINE, full=False)
    return figure_columns(result.summary, result.status, DEFAULT_LYAPUNOV_RATIO, members_of(config))


def figure_columns(summary: Mapping[str, Any], status: str, ratio: float,
                   members: Members | None = None) -> dict[str, float]:
    """A run's numeric summary figures as flat columns, as a sweep's index has them (a
    tree's, with ``members`` its body and joint names, per body or joint), and
    ``converged`` (0 or 1)."""
    names = members or Members(None, None)
    columns = {k: float(v) for k, v in summary_columns(summary, names.joints, names.bodies).items()
               if k not in METRICS_NOT_FIGURES and isinstance(v, (int, float, np.number))}
    columns["converged"] = float(converged(status == "success", summary.get("lyapunov_initial"),
                                              summary.get("lyapunov_final"), ratio,
                                              summary.get("max_lyapunov_increase")))
    return columns


# -- design tables -------------------------------------------------------------------------------------


def design_mappings(design) -> dict[str, list]:
    """Dotted config key -> one value per row of a design table (``key[i]`` columns are
    gathered into vectors, ``key[i,j]`` into nested lists).

    Raises
    ------
    StudyInputError
        If the components of a key do not fill a whole vector or matrix.
    """
    groups: dict[str, dict[tuple[int, ...], str]] = {}
    whole: dict[str, str] = {}
    for column in design.columns:
        m = _COLUMN.match(str(column))
        if m:
            index = tuple(int(i) for i in m["index"].split(","))
            groups.setdefault(m["key"], {})[index] = column
        else:
            whole[str(column)] = column
    out: dict[str, list] = {k: [plain(v) for v in design[c].tolist()] for k, c in whole.items()}
    for key, entries in groups.items():
        shape = tuple(max(i[d] for i in entries) + 1 for d in range(len(next(iter(entries)))))
        if len(entries) != int(np.prod(shape)) or len({len(i) for i in entries}) != 1:
            raise StudyInputError([f"design columns of '{key}': {sorted(entries.values())} do not fill a "
                                   f"{'x'.join(map(str, shape))} value"])
        stacked = np.stack([design[entries[i]].to_numpy(dtype=float) for i in np.ndindex(*shape)], axis=1)
        out[key] = stacked.reshape(len(design), *shape).tolist()
    return out


def run_design(base: Mapping, design, folder: str | os.PathLike, *, jobs: int | None = None,
               executor: Any = None, scheduler: str | None = None, engine: str | None = None, store: str = "summary",
               log=None, progress: bool | None = None, command_line: str | None = None):
    """Run every row of a design table as one run of a sweep; return their summary figures.

    Parameters
    ----------
    base : Mapping
        The base configuration (``RunConfig.resolved``, or a chain's
        ``RunConfig.resolved``: its runs go into store files, as a chain sweep's);
        each row's values are set on it.
    design : pandas.DataFrame
        Absolute values, one row per run, columns as in the module docstring.
    folder : path-like
        The sweep folder (written as by ``rbstab sweep``: ``sweep.yaml``, ``runs/``,
        ``index.csv``); its name is the sweep's. Running the same design again skips
        the runs whose result is there (a resume).
    jobs, executor, scheduler, engine, store, log, progress, command_line
        As for :func:`rbstab.sweep.run_sweep` (``executor``: "local", "dask" with a
        ``scheduler`` address, or an Executor object, not closed here).

    Returns
    -------
    xarray.Dataset
        Along ``run`` (row i of ``design`` is run i): ``status``, ``converged`` (float 0/1)
        and the numeric summary figures (units, long names; a chain's per joint,
        ``<figure>_<joint>``), loaded in memory.

    Raises
    ------
    rbstab.sweep.SweepSpecError
        If a row gives an invalid configuration (every one listed; nothing is run).
    rbstab.sweep.SweepBusyError, rbstab.sweep.ExecutorError
        As :func:`rbstab.sweep.run_sweep`.
    """
    folder = Path(folder)
    mapping = {"name": folder.name, "base": dict(base), "table": design}
    spec = spec_from_mapping(mapping)
    members = members_of(base)
    one_body = spec.may_run_one_body
    ensure_compiled(say=log, one_body=one_body, sign_law=one_body, chain=spec.may_run_tree,
                    solve_ivp=spec.may_run_scipy(engine))
    run_sweep(spec, folder.parent, executor=executor or "local", jobs=jobs, scheduler=scheduler, log=log,
              engine=engine, store=store,
              progress=progress, command_line=command_line)
    ds = open_sweep(folder)
    keep = [k for k, v in ds.data_vars.items() if v.dims == ("run",) and (k in ("status", "converged") or (
            v.dtype.kind in "fiub" and _metric_parts(k, members) is not None))]
    out = ds[keep].load()
    out["converged"] = out["converged"].astype(float)
    for k in keep:  # units and names where the sweep's columns lack them
        units, long_name = figure_attributes(k)
        if units and not out[k].attrs.get("units"):
            out[k].attrs.update(units=units, long_name=long_name)
    return out
