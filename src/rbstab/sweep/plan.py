"""A sweep's runs: :func:`expand` turns a :class:`~rbstab.sweep.spec.SweepSpec` into validated runs.

The run list's order and the run ids are defined in :mod:`rbstab.sweep.spec`. Each run's
configuration is its base with the varied values set, validated by the config schema
(:func:`rbstab.config.config_from_mapping`) for the first run of each base; its later runs,
which differ from it only at the varied keys, are checked there only
(:meth:`rbstab.config.RunConfig.with_values`: the same result, the same messages).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import itertools
import json
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import (ConfigError, PhysicalPlausibilityWarning, canonical_config, canonical_configs,
                      config_from_mapping, config_hash, get_dotted, set_dotted)
from .folder import parameter_columns, run_coords
from .schema import numeric_array
from .spec import Base, SweepSpec, SweepSpecError

__all__ = ["PlannedRun", "InvalidRun", "plan_runs", "expand", "invalid_report", "parameter_columns_of", "time_grids_of",
           "run_id",
           "resolved_hash", "warning_digest"]

_MAX_LISTED = 10  # invalid runs listed in an error, the rest counted


def _short(value: Any, limit: int = 80) -> str:
    text = json.dumps(value, default=str) if not isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True, eq=False)
class PlannedRun:
    """One run of a sweep, validated.

    Attributes
    ----------
    index : int
        Position in the run list (see the module docstring for the order).
    run_id : str
        ``r<index>-<hash8>`` (module docstring); also ``config.name`` and the file stem.
    base : str
        Label of its base configuration.
    params : dict of str to Any
        The varied values: dotted key -> value set in the config, in the order of
        :attr:`SweepSpec.varied_keys`; for a ``scale_uniform`` key also ``"<key>:scale"`` ->
        the factor.
    config : RunConfig
        The validated configuration, ``config.name == run_id``.
    """

    index: int
    run_id: str
    base: str
    params: dict
    config: Any

    @property
    def variant(self) -> str:
        """The run's controller variant."""
        return self.config.variant

    @property
    def warnings(self) -> tuple[str, ...]:
        """Physical-plausibility warnings of its config (``config.warnings``)."""
        return self.config.warnings

    def entry(self) -> "RunEntry":
        """What the index needs of this run, without its configuration (a sweep keeps one
        per run until its index is written); made once (the runner asks twice a run)."""
        return self._entry

    @functools.cached_property
    def _entry(self) -> "RunEntry":
        coords = self.coords
        layout = _shared_layout(tuple((name, key) for name, (key, _) in coords.items()))
        return RunEntry(self.index, self.run_id, self.base, layout, tuple(v for _, v in coords.values()),
                        self.variant, self.config_hash, self.warnings)

    @functools.cached_property
    def coords(self) -> dict[str, tuple[str, Any]]:
        """Parameter coordinate name -> (dotted key of the entry, value) of its varied
        values (:func:`rbstab.sweep.folder.run_coords` of ``params``)."""
        return run_coords(self.params)

    @functools.cached_property
    def config_hash(self) -> str:
        """SHA-256 of the resolved config without its name (:func:`resolved_hash`): the
        ``config_hash`` of its stored result."""
        return resolved_hash(self.config.resolved)

    @functools.cached_property
    def config_text(self) -> str:
        """The resolved config without its name, with its run limits, as canonical JSON
        (:func:`rbstab.config.canonical_config`): a store file's ``config`` column."""
        return canonical_config(self.config.resolved, limits=True)


@dataclass(frozen=True, slots=True)
class RunEntry:
    """A planned run without its configuration: index, ``run_id``, ``base``, ``variant``,
    ``config_hash``, ``warnings`` and :attr:`coords` as in :class:`PlannedRun` (slots: a
    sweep keeps one per run; the coordinates as a tuple of values beside their names and
    keys, which the runs that vary the same entries share)."""

    index: int
    run_id: str
    base: str
    layout: tuple  # ((coordinate name, dotted key), ...)
    values: tuple
    variant: str
    config_hash: str
    warnings: tuple = ()

    @property
    def coords(self) -> dict[str, tuple[str, Any]]:
        """Coordinate name -> (dotted key, value), as :attr:`PlannedRun.coords`."""
        return {name: (key, value) for (name, key), value in zip(self.layout, self.values)}


@functools.lru_cache(maxsize=1024)
def _shared_layout(layout: tuple) -> tuple:
    """One object for equal coordinate layouts (the runs of a sweep have a few)."""
    return layout


def resolved_hash(resolved: Mapping) -> str:
    """SHA-256 hex digest of a resolved configuration without its ``name`` (canonical JSON,
    :func:`rbstab.config.canonical_config`)."""
    return config_hash(canonical_config(resolved))


def run_id(index: int, n_runs: int, digest: str) -> str:
    """``r<index>-<digest[:8]>``, the index zero-padded to max(4, digits of n_runs - 1)."""
    width = max(4, len(str(max(n_runs - 1, 0))))
    return f"r{index:0{width}d}-{digest[:8]}"


def _base_value(base: Base, key: str, resolved_base: dict | None) -> Any:
    try:
        return get_dotted(base.data, key)
    except KeyError:
        if resolved_base is None:
            raise
        return get_dotted(resolved_base, key)


def _resolved_base(base: Base) -> tuple[dict | None, list[str]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        try:
            return config_from_mapping(base.data, default_name=base.label).resolved, []
        except ConfigError as exc:
            return None, exc.errors


def _set_varied(data: dict, key: str, value: Any, base: Base, cache: dict) -> None:
    """``set_dotted``; a list index into a list the base leaves at its default first copies
    the default list in (e.g. ``initial_state.omega.1`` with no ``omega`` in the base)."""
    try:
        set_dotted(data, key, value)
        return
    except ConfigError:
        parts = key.split(".")
        if base.label not in cache:
            cache[base.label] = _resolved_base(base)
        resolved, _ = cache[base.label]
        if resolved is None or not any(p.isdigit() for p in parts):
            raise
        for depth in range(1, len(parts)):
            prefix = ".".join(parts[:depth])
            try:
                get_dotted(data, prefix)
            except KeyError:
                try:
                    set_dotted(data, prefix, copy.deepcopy(get_dotted(resolved, prefix)))
                except (KeyError, ConfigError):
                    raise ConfigError([f"cannot set {key!r}: '{prefix}' is not set"]) from None
                break
        set_dotted(data, key, value)


def _describe(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={_short(v, 40)}" for k, v in params.items())


def _scale_base(base: Base, key: str, cache: dict) -> tuple[np.ndarray | None, str | None]:
    """(base value of ``key`` as an array, None) or (None, problem); once per base and key."""
    if (base.label, key) in cache:
        return cache[base.label, key]
    if base.label not in cache:
        cache[base.label] = _resolved_base(base)
    try:
        original = _base_value(base, key, cache[base.label][0])
    except KeyError:
        found = None, (
            f"random.params.{key}: scale_uniform needs a base value, but '{key}' is not set in "
            f"base '{base.label}' and has no default"
        )
    else:
        arr = numeric_array(original)
        found = (arr, None) if arr is not None else (None, (
            f"random.params.{key}: scale_uniform needs a number or a list of numbers to scale, but "
            f"base '{base.label}' has {_short(original)}"
        ))
    cache[base.label, key] = found
    return found


def _scaled(base: Base, key: str, factor: Any, cache: dict) -> tuple[Any, str | None]:
    """(base value of ``key`` times ``factor``, None) or (None, problem)."""
    arr, problem = _scale_base(base, key, cache)
    if problem:
        return None, problem
    if type(factor) is float:  # one factor (the common case): it scales any base value
        return (arr * factor).tolist(), None
    f = np.asarray(factor, dtype=float)
    try:
        np.broadcast_shapes(arr.shape, f.shape)
    except ValueError:
        return None, (
            f"random.params.{key}: scale_uniform factors of shape {f.shape} cannot scale the base "
            f"value {_short(arr.tolist())} of base '{base.label}'"
        )
    return (arr * f).tolist(), None


def _own_path(data: dict, key: str, fresh: set) -> None:
    """Copy the containers on ``key``'s path in ``data`` (once each, ids in ``fresh``), so
    that setting ``key`` leaves the base configuration they came from intact."""
    node: Any = data
    for part in key.split(".")[:-1]:
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            where: Any = int(part)
        elif isinstance(node, dict) and part in node:
            where = part
        else:
            return  # set_dotted creates (or refuses) the rest
        child = node[where]
        if not isinstance(child, (dict, list)):
            return
        if id(child) not in fresh:
            child = dict(child) if isinstance(child, dict) else list(child)
            node[where] = child
            fresh.add(id(child))
        node = child


def _plan_run(
    spec: SweepSpec, base: Base, params: dict, factors: dict, index: int, cache: dict, validated: dict,
    texts: dict,
) -> tuple["PlannedRun | None", list[str]]:
    """Set the varied values on a copy of ``base``, validate, name the run by its id.

    ``validated`` maps a base's label to the validated config of its first valid run; the
    base's other runs differ from it only at the varied keys and are validated by
    :meth:`RunConfig.with_values` (the same result; only the fields of the varied keys
    checked). ``texts``: the :func:`rbstab.config.canonical_configs` memo of the
    planning pass (the runs of a base share the sections no varied key is in).
    """
    data = dict(base.data)
    fresh: set = set()
    problems: list[str] = []
    try:
        for key, value in params.items():
            _own_path(data, key, fresh)
            _set_varied(data, key, value, base, cache)
        for key, factor in factors.items():
            value, problem = _scaled(base, key, factor, cache)
            if problem:
                problems.append(problem)
                continue
            params[key] = value
            params[f"{key}:scale"] = factor
            _own_path(data, key, fresh)
            _set_varied(data, key, value, base, cache)
    except ConfigError as exc:
        problems += exc.errors
    if problems:
        return None, problems
    data["name"] = "sweep-run"  # replaced by the run id below
    source = f"base '{base.label}'"
    try:
        with warnings.catch_warnings():
            # kept in config.warnings; the CLI prints a digest instead of one per run
            warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
            known = validated.get(base.label)
            if known is None:
                first = validated[base.label] = config_from_mapping(data, source=source)
            else:
                first = known.with_values(data, spec.varied_keys, source=source)
    except ConfigError as exc:
        return None, exc.errors
    # the runs of a base share the sections no varied key is in (the same objects): each
    # is encoded once
    identity, text = canonical_configs(first.resolved, texts)
    digest = config_hash(identity)
    rid = run_id(index, spec.n_runs, digest)
    # only the name changes: no need to validate again
    config = dataclasses.replace(first, name=rid, resolved={**first.resolved, "name": rid})
    ordered = {k: params[k] for k in spec.varied_keys if k in params}
    ordered.update({k: v for k, v in params.items() if k not in ordered})
    run = PlannedRun(index, rid, base.label, ordered, config)
    run.__dict__["config_hash"] = digest  # the name is not part of them
    run.__dict__["config_text"] = text
    return run, []


@dataclass(frozen=True)
class InvalidRun:
    """A run of the run list whose configuration is invalid (see :func:`plan_runs`)."""

    index: int
    base: str
    params: dict
    problems: list


def plan_runs(spec: SweepSpec) -> Iterator["PlannedRun | InvalidRun"]:
    """Every run of ``spec`` in run-list order, validated one after the other: a
    :class:`PlannedRun`, or an :class:`InvalidRun` naming its problems.

    Lazy: a sweep can start running its first runs while later ones are planned.
    """
    samples = spec.random.iter_samples() if spec.random.n else iter([{}])
    scaled = {d.key for d in spec.random.params if d.kind == "scale_uniform"}
    grid_points = list(itertools.product(*spec.grid.values())) if spec.grid else [()]
    n_zip = len(next(iter(spec.zip.values()))) if spec.zip else 1
    cache: dict = {}
    validated: dict = {}  # base label -> its first valid run's config, which the others start from
    texts: dict = {}  # canonical JSON of the shared sections (rbstab.config.canonical_configs)
    index = 0
    for sample in samples:
        for base, point, z in itertools.product(spec.bases, grid_points, range(n_zip)):
            params: dict[str, Any] = dict(zip(spec.grid, copy.deepcopy(point)))
            params.update({k: copy.deepcopy(v[z]) for k, v in spec.zip.items()})
            params.update({k: v for k, v in sample.items() if k not in scaled})
            factors = {k: v for k, v in sample.items() if k in scaled}
            shown = dict(params)  # what the user varied, for a message
            run, problems = _plan_run(spec, base, params, factors, index, cache, validated, texts)
            yield run if run is not None else InvalidRun(index, base.label, shown, problems)
            index += 1


def invalid_report(spec: SweepSpec, invalid: Sequence[InvalidRun], outcome: str = "nothing was run") -> list[str]:
    """The lines of the :class:`SweepSpecError` for ``invalid`` runs: a header, then each run
    (index, base, varied values) with its problems; at most ten runs are listed."""
    width = max(4, len(str(max(spec.n_runs - 1, 0))))
    lines = [f"{len(invalid)} of {spec.n_runs} runs have an invalid configuration; {outcome}"]
    for bad in invalid[:_MAX_LISTED]:
        head = f"run r{bad.index:0{width}d} (base {bad.base}" + (f"; {_describe(bad.params)})" if bad.params else ")")
        lines += [f"{head}: {line}" for line in bad.problems]
    if len(invalid) > _MAX_LISTED:
        lines.append(f"... and {len(invalid) - _MAX_LISTED} more invalid runs")
    return lines


def expand(spec: SweepSpec) -> list["PlannedRun"]:
    """Every run of ``spec``, each configuration validated.

    Returns
    -------
    list of PlannedRun
        In run-list order (module docstring); ``len == spec.n_runs``.

    Raises
    ------
    SweepSpecError
        If any run's configuration is invalid: one line per problem, naming the run (index,
        base and varied values) and the config key. Nothing is run for an invalid sweep.

    Notes
    -----
    Physical-plausibility warnings are not emitted here; each run's ``config.warnings``
    holds them (:func:`warning_digest` summarises them).
    """
    runs: list[PlannedRun] = []
    invalid: list[InvalidRun] = []
    for run in plan_runs(spec):
        (invalid if isinstance(run, InvalidRun) else runs).append(run)
    if invalid:
        raise SweepSpecError(invalid_report(spec, invalid), spec.source)
    return runs


def _representatives(spec: SweepSpec, key: str) -> list[Any]:
    """Values of ``key`` of every shape the sweep may give it (for the parameter columns)."""
    if key in spec.grid:
        return spec.grid[key]
    if key in spec.zip:
        return spec.zip[key]
    d = next(d for d in spec.random.params if d.key == key)
    if d.kind == "choice":
        return list(d.args[0])
    return [d.draw(np.random.default_rng(0))]


def parameter_columns_of(spec: SweepSpec) -> dict[str, str]:
    """Coordinate name -> dotted config key of every value ``spec`` varies, from the spec
    alone (the names :func:`rbstab.sweep.folder.parameter_columns` gives for its runs), so
    that every store file of a sweep has the same columns however its runs are planned.
    """
    cache: dict = {}
    params_list: list[dict] = []
    scaled = [d.key for d in spec.random.params if d.kind == "scale_uniform"] if spec.random.n else []
    for key in spec.varied_keys:
        for value in _representatives(spec, key):
            if key in scaled:
                for base in spec.bases:
                    scaled_value, _ = _scaled(base, key, value, cache)
                    params_list.append({key: scaled_value if scaled_value is not None else value})
            else:
                params_list.append({key: value})
    for key in scaled:
        for value in _representatives(spec, key):
            params_list.append({f"{key}:scale": value})
    return parameter_columns(params_list)


_TIME_GRID_KEYS = ("simulation.t_end", "simulation.n_samples")


def time_grids_of(spec: SweepSpec) -> set:
    """The distinct sample grids ``(t_end, n_samples)`` the runs of ``spec`` may have, from
    the spec alone: each base's, and a marker per value of a varied key that sets either
    (more than one element: the runs do not share one time axis)."""
    grids: set = set()
    for base in spec.bases:
        resolved, _ = _resolved_base(base)
        if resolved is not None:
            grids.add((resolved["simulation"]["t_end"], resolved["simulation"]["n_samples"]))
    for key in spec.varied_keys:
        if any(key == k or k.startswith(key + ".") or key.startswith(k + ".") for k in _TIME_GRID_KEYS):
            values = _representatives(spec, key)
            random = key not in spec.grid and key not in spec.zip
            grids.update((key, i) for i in range(2 if random else len({repr(v) for v in values})))
    return grids


def warning_digest(runs: Sequence[PlannedRun]) -> list[str]:
    """Physical-plausibility warnings of ``runs``, one line per config key.

    E.g. ``"200 of 200 runs: body.inertia: principal moments (10, 8, 0.4) ..."`` (the
    message of the first run with that key).
    """
    first: dict[str, str] = {}
    count: dict[str, int] = {}
    for run in runs:
        for message in run.warnings:
            key = message.partition(":")[0]
            first.setdefault(key, message)
            count[key] = count.get(key, 0) + 1
    return [f"{count[k]} of {len(runs)} runs: {first[k]}" for k in first]
