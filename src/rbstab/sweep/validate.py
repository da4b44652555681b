"""Validation of a sweep's runs as columns (see :mod:`rbstab.sweep.table`).

Each template (the first run of a base and combination of non-numeric values) is
validated by the config schema. Every numeric field the varied keys touch is then
assembled as an array over the runs and checked at once against the constraint the
schema declares for it (:attr:`rbstab.config.paths.KeyPath.rule`), with the joint checks
made on the columns: the rules are the schema's own functions
(:func:`~rbstab.config.schema.within_bounds`,
:func:`~rbstab.config.schema.clear_of_gimbal_lock`,
:func:`~rbstab.config.schema.samples_apart`, :func:`~rbstab.config.schema.steps_suffice`),
applied to a column instead of a value. The runs these checks flag are validated one by one by the schema,
whose messages name the run, the key, the value and what is allowed.

A chain's sweep checks its parameters' columns (masses, inertias, gains, limits, gravity)
so, and where the other varied keys are initial-state entries, its initial states as
columns too (:func:`_tree_state_flags`); its other runs are validated by the chain's
schema and tree checks, a run that differs from one validated before only in its
parameters and initial state by its initial state's checks (:func:`_validate_trees`).
"""

from __future__ import annotations

import copy
import json
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .spec import Base, SweepSpec, SweepSpecError
from .schema import numeric_array
from ..results import plain
from ..config import ConfigError, PhysicalPlausibilityWarning
from ..config.loader import config_from_mapping, initial_state_fits
from ..config.paths import KeyPath, parse_any_key, parse_key, schema_of
from ..config.schema import (AXES_VARIANTS, INITIAL_STATE_BLOCKS, MAX_MAGNITUDE, MIN_INVERTED, clear_of_gimbal_lock,
                             inside_limits, samples_apart, starts_in_run, steps_suffice, within_bounds)
from ..layout import LIMITED, VARIANT_LAYOUTS, point_fixed
from ..variants import VARIANTS
from ..variants.base import limited_values
from ..config.physics import SINGULAR_RTOL
from ..config.physics import inertia_warnings
from ..engine.batch import TableFields

__all__ = ["validate_columns", "row_mapping", "base_value", "invalid_report", "key_path"]

_MAX_LISTED = 10  # invalid runs listed in an error, the rest counted
#: Flagged runs validated one by one (for the count of invalid runs); beyond it, the runs
#: the column checks flag are counted as invalid when every one validated so far was.
_MAX_CONFIRMED = 2000
#: Validated runs of a chain's sweep that a later run is compared with (a grid's inner axes).
_RECENT_TREES = 8


def _short(value: Any, limit: int = 40) -> str:
    if isinstance(value, np.ndarray | np.generic):
        value = value.tolist()
    text = json.dumps(value, default=str) if not isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def row_mapping(base: Base, keys: Sequence[str], values: Sequence[Any], name: str) -> dict:
    """The configuration mapping of one run as written: ``base`` with the varied values set
    by :meth:`rbstab.config.paths.KeyPath.set` (a list index into a list the base leaves at
    its default starts from the default; an entry of a matrix written as 3 numbers, or of a
    limit written as one, sets it in the 3x3 or the 3 numbers it stands for).

    Raises
    ------
    ConfigError
        If a key cannot be set (it indexes into a value that is not a list).
    """

    paths = [key_path(key, base.data) for key in keys]
    data = dict(base.data)  # a section no key sets is the base's own object (read, never written)
    for section in {path.steps[0] for path in paths} & set(data):
        data[section] = copy.deepcopy(data[section])
    for path, value in zip(paths, values):
        path.set(data, plain(value))
    data["name"] = name
    return data


def key_path(key: str, data: Mapping) -> KeyPath:
    """``key`` read against the schema of the configuration ``data`` is written in: a
    chain's (:class:`rbstab.config.schema.ChainSchema`) or one body's.

    Raises
    ------
    rbstab.config.paths.KeyPathError
        If it names nothing of that schema.
    """
    return parse_key(key, schema_of(data))


def base_value(base: Base, key: str) -> tuple[np.ndarray | None, str | None]:
    """(the value of ``key`` in ``base`` as a float array, None) or (None, problem): what a
    ``scale_uniform`` factor scales (the schema's default where the base leaves it unset)."""

    value = key_path(key, base.data).get(base.data, None)
    if value is None:
        value = _default(base, key)
        if value is None:
            return None, (f"random.params.{key}: scale_uniform needs a base value, but '{key}' is not set in "
                          f"base '{base.label}' and has no default")
    arr = numeric_array(value)
    if arr is None:
        return None, (f"random.params.{key}: scale_uniform needs a number or a list of numbers to scale, but "
                      f"base '{base.label}' has {_short(value, 80)}")
    return arr, None


def _default(base: Base, key: str) -> Any:

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        try:
            return key_path(key, base.data).get(config_from_mapping(base.data, default_name=base.label).resolved)
        except ConfigError:  # KeyPathError included
            return None


def _validate_row(spec: SweepSpec, columns: Mapping[str, np.ndarray], base_index: np.ndarray, i: int):
    """(RunConfig, []) or (None, problems) of run ``i`` validated by the config schema."""

    base = spec.bases[int(base_index[i])]
    try:
        data = row_mapping(base, list(columns), [columns[k][i] for k in columns], "sweep-run")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
            return config_from_mapping(data, source=f"base '{base.label}'"), []
    except ConfigError as exc:
        return None, exc.errors


class _Fields:
    """Numeric config fields over the runs, ``(n, *shape)``: the templates' values with the
    varied entries set (built when first asked for)."""

    def __init__(self, columns: Mapping[str, np.ndarray], templates: Sequence[Mapping], template: np.ndarray) -> None:
        self.columns, self.templates, self.template = columns, templates, template
        self._cache: dict[tuple[str, str], tuple[np.ndarray, np.ndarray] | None] = {}

    def varied(self, section: str, name: str) -> bool:
        prefix = f"{section}.{name}"
        return any(k == prefix or k.startswith(prefix + ".") for k in self.columns)

    def get(self, section: str, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """(values (n, *shape), mask of the runs that have the field) or None."""
        if (section, name) not in self._cache:
            self._cache[section, name] = self._build(section, name)
        return self._cache[section, name]

    def _build(self, section: str, name: str):
        per_template, has = [], []
        path = parse_key(f"{section}.{name}")
        matrix = len(path.shape) == 2
        if matrix and self._diagonal(section, name):
            return self._build_diagonal(section, name)

        rule = path.rule or ("number",)
        shape = path.shape
        for t in self.templates:
            value = path.get(t, None)
            has.append(value is not None)
            try:
                arr = np.asarray(value if value is not None else np.nan, dtype=float)
            except (TypeError, ValueError):  # not numbers: the schema refuses it
                return None
            if matrix and arr.ndim == 1:
                arr = np.diag(arr)
            if arr.shape not in (shape, ()):
                return None
            per_template.append(np.broadcast_to(arr, shape))
        stacked = np.stack(per_template)
        values = stacked[self.template].copy()
        present = np.asarray(has)[self.template]
        prefix = f"{section}.{name}"
        for key, col in self.columns.items():
            if not (key == prefix or key.startswith(prefix + ".")) or col.dtype == object:
                continue
            if section == "disturbances":  # an entry's field set by the sweep (its default, e.g. start 0, unwritten)
                entry = parse_key(f"{section}.{name.partition('.')[0]}")
                present = np.asarray([isinstance(entry.get(t, None), Mapping) for t in self.templates])[self.template]
            idx = parse_key(key).index
            col = col.astype(float)
            if rule[0] == "limits" and len(idx) == 0 and col.ndim == 1:
                col = col[:, None]  # one limit for every axis
            if matrix and len(idx) == 0 and col.ndim == 2:
                col = col[:, :, None] * np.eye(3)
            elif matrix and len(idx) == 1 and col.ndim == 1:
                idx = (idx[0], idx[0])  # an entry of a diagonal written as 3 numbers
            try:
                values[(slice(None), *idx)] = col
            except (ValueError, IndexError):
                return None
        return values, present

    def _diagonal(self, section: str, name: str) -> bool:
        """Whether a matrix field is a diagonal (3 numbers) in every template and every
        varied value of it: then held as (n, 3)."""
        if any(isinstance(t.get(section, {}).get(name), list) and any(isinstance(r, list) for r in
               t[section][name]) for t in self.templates):
            return False
        prefix = f"{section}.{name}"
        for key, col in self.columns.items():
            if key == prefix and (col.dtype == object or col.ndim != 2):
                return False
            if key.startswith(prefix + ".") and (col.dtype == object or col.ndim != 1 or len(parse_key(key).index) != 1):
                return False
        return True

    def _build_diagonal(self, section: str, name: str):
        values = [t.get(section, {}).get(name) for t in self.templates]
        stacked = np.array([v if v is not None else [np.nan] * 3 for v in values], dtype=float)
        out = stacked[self.template]
        prefix = f"{section}.{name}"
        for key, col in self.columns.items():
            if key == prefix:
                out = col.astype(float)
            elif key.startswith(prefix + "."):
                (entry,) = parse_key(key).index
                out = out.copy() if out.base is not None else out
                out[:, entry] = col
        return out, np.array([v is not None for v in values])[self.template]


def full_matrices(values: np.ndarray) -> np.ndarray:
    """Matrices (n, 3, 3) of a field held as diagonals (n, 3) or as matrices."""
    return values[:, :, None] * np.eye(3) if values.ndim == 2 else values


def _number_bad(values: np.ndarray, bounds: Mapping[str, Any], integer_column: bool) -> np.ndarray:

    v = values.reshape(len(values), -1)
    with np.errstate(invalid="ignore"):
        bad = np.isnan(v) | (np.abs(v) > MAX_MAGNITUDE) & np.isfinite(v)
        if not bounds["allow_inf"]:
            bad |= np.isinf(v)
        bad |= ~within_bounds(v, bounds["gt"], bounds["ge"], bounds["lt"], bounds["le"])
    bad = bad.any(axis=1)
    if bounds["integer"] and not integer_column:
        bad[:] = True
    return bad


def _matrix_bad(values: np.ndarray, kind: str) -> np.ndarray:

    flat = values.reshape(len(values), -1)
    bad = ~np.isfinite(flat).all(axis=1) | (np.abs(flat) > MAX_MAGNITUDE).any(axis=1)
    if values.ndim == 1:  # a number a run: a gain on a joint's coordinate
        return bad | ((values < MIN_INVERTED) if kind == "definite" else (values < 0))
    if values.ndim == 2:  # diagonals
        smallest = values.min(axis=1)
        return bad | ((smallest < MIN_INVERTED) if kind == "definite" else (smallest < 0))
    good = np.where(bad[:, None, None], np.eye(3), values)
    scale = np.abs(good).max(axis=(1, 2))
    bad |= (np.abs(good - good.transpose(0, 2, 1)).max(axis=(1, 2)) > 1e-12 * scale)
    smallest = np.linalg.eigvalsh((good + good.transpose(0, 2, 1)) / 2)[:, 0]
    bad |= (smallest < MIN_INVERTED) if kind == "definite" else (smallest < 0)
    return bad


def _rule_bad(rule: tuple, values: np.ndarray, integer_column: bool) -> np.ndarray:
    """The runs whose values break the schema's constraint ``rule`` (:attr:`KeyPath.rule`)."""

    if rule[0] in ("number", "limits"):
        return _number_bad(values, rule[1], integer_column)
    if rule[0] == "matrix":
        return _matrix_bad(values, rule[1])
    flat = values.reshape(len(values), -1)
    bad = ~np.isfinite(flat).all(axis=1) | (np.abs(flat) > MAX_MAGNITUDE).any(axis=1)
    if rule[0] == "theta":
        with np.errstate(invalid="ignore"):
            bad |= ~clear_of_gimbal_lock(values[:, 1])
    return bad


def _field_flags(fields: _Fields, n: int) -> np.ndarray:
    """Runs a varied numeric field's own constraint flags."""

    flagged = np.zeros(n, dtype=bool)
    touched = {(p.section, p.name) for p in (parse_key(k) for k, v in fields.columns.items()
                                                 if v.dtype != object and "." in k)}
    for section, name in touched:
        rule = parse_key(f"{section}.{name}").rule
        got = fields.get(section, name)
        if got is None:  # entries that do not fit the field's shape: the schema decides
            flagged[:] = True
            continue
        if rule is None:
            continue
        values, present = got
        integer = all(v.dtype.kind == "i" for k, v in fields.columns.items() if k.startswith(f"{section}.{name}"))
        flagged |= present & _rule_bad(rule, values, integer)
    return flagged


def _stiffness(variant: str, get) -> np.ndarray | None:
    k_t = get("k_t")
    if variant in ("free", "sliding"):
        return k_t
    if variant == "visco_elastic":
        return k_t + get("k_c")
    if variant == "embedded":
        k_c, k_d = get("k_c"), get("k_d")
        return np.block([[k_t + k_c, -k_c], [-k_c, k_c + k_d]])
    return None


def _joint_flags(fields: _Fields, variants: Sequence[str], n: int) -> np.ndarray:
    """Runs the schema's joint checks may refuse (gimbal-lock margin, samples and steps
    that let a run end, a disturbance's start after t_end, the weight held); the schema
    decides."""

    flagged = np.zeros(n, dtype=bool)
    if fields.varied("initial_state", "theta") or fields.varied("simulation", "gimbal_margin"):
        theta, margin = fields.get("initial_state", "theta"), fields.get("simulation", "gimbal_margin")
        if theta is None or margin is None:
            return np.ones(n, dtype=bool)
        with np.errstate(invalid="ignore"):
            flagged |= ~clear_of_gimbal_lock(theta[0][:, 1], margin[0])
    if any(fields.varied("simulation", k) for k in ("t_end", "n_samples", "max_step", "max_steps")):
        got = [fields.get("simulation", k) for k in ("t_end", "n_samples", "max_step", "max_steps")]
        if any(g is None for g in got):
            return np.ones(n, dtype=bool)
        (t_end, _), (samples, _), (step, _), (steps, _) = got
        with np.errstate(invalid="ignore", divide="ignore"):
            flagged |= ~samples_apart(t_end, samples) | ~steps_suffice(t_end, np.where(np.isnan(step), np.inf, step), steps)
    flagged |= _limit_flags(fields, variants, n)
    starts = sorted({parse_key(k).name for k in fields.columns if k.startswith("disturbances.") and k.endswith(".start")})
    if fields.varied("simulation", "t_end"):  # every entry's start against each run's t_end
        starts = [f"{i}.start" for i in range(max((len(t.get("disturbances") or ()) for t in fields.templates),
                                                  default=0))]
    for name in starts:
        start, t_end = fields.get("disturbances", name), fields.get("simulation", "t_end")
        if start is None or t_end is None:
            return np.ones(n, dtype=bool)
        with np.errstate(invalid="ignore"):
            flagged |= start[1] & ~starts_in_run(start[0], t_end[0])
    weight_keys = ("k_t", "k_c", "k_d", "k_s", "boundary_layer")
    if any(fields.varied("body", k) for k in ("mass", "gravity")) or any(fields.varied("controller", k) for k in weight_keys):
        gravity = fields.get("body", "gravity")
        pulls = np.ones(n, dtype=bool) if gravity is None else np.any(gravity[0] != 0, axis=1)
        for variant in sorted(set(variants)):
            rows = np.isin(fields.template, [t for t, v in enumerate(variants) if v == variant]) & pulls
            if point_fixed(variant) or not rows.any():
                continue

            k_t = fields.get("controller", "k_t")
            if k_t is not None and k_t[0].ndim == 2:
                rows &= ~(k_t[0] > 0).all(axis=1)  # K_t alone holds any weight (unheld_weight's shortcut)
                if not rows.any():
                    continue

            def get(name, rows=rows):
                got = fields.get("controller", name)
                return np.full((rows.sum(), 3, 3), np.nan) if got is None else full_matrices(got[0][rows])

            stiffness = _stiffness(str(variant), get)
            if stiffness is None:
                flagged |= rows
                continue
            good = np.nan_to_num(stiffness)
            eig = np.linalg.eigvalsh((good + good.transpose(0, 2, 1)) / 2)
            held = eig[:, 0] > SINGULAR_RTOL * np.abs(eig).max(axis=1)
            flagged[np.flatnonzero(rows)[~held]] = True
    return flagged


def _limit_flags(fields: _Fields, variants: Sequence[str], n: int) -> np.ndarray:
    """Runs whose initial state the schema may find outside ``simulation.limits``
    (:func:`~rbstab.config.schema.inside_limits` of the bounded quantities of each run's
    initial state, computed as the loader does), where a bound, the initial state or R is varied."""
    flagged = np.zeros(n, dtype=bool)
    bounded = [bool(t.get("simulation", {}).get("limits")) for t in fields.templates]
    keys = [("simulation", "limits"), ("body", "attachment_point"), *(("initial_state", k) for k in INITIAL_STATE_BLOCKS)]
    if not any(bounded) or not any(fields.varied(*k) for k in keys):
        return flagged
    got = {key: fields.get("initial_state", key) for key in INITIAL_STATE_BLOCKS}
    got["R"] = fields.get("body", "attachment_point")
    bounds = [fields.get("simulation", f"limits.{name}") for name in LIMITED]
    if any(g is None for g in (*got.values(), *bounds)):
        return np.ones(n, dtype=bool)
    blocks = {block: np.nan_to_num(got[key][0], nan=0.0) for key, block in INITIAL_STATE_BLOCKS.items()}
    limits = np.stack([np.where(present[:, None], values, np.inf) for values, present in bounds], axis=1)
    for variant in sorted({v for v, b in zip(variants, bounded) if b and v}):
        rows = np.flatnonzero(np.isin(fields.template, [t for t, v in enumerate(variants) if v == variant and bounded[t]]))
        layout = VARIANT_LAYOUTS[variant]
        y0 = np.concatenate([blocks[b][rows] for b in layout.blocks], axis=1)
        values = limited_values(VARIANTS[variant].code, y0, got["R"][0][rows])
        flagged[rows] = ~inside_limits(values, limits[rows])
    return flagged


def _templates(spec: SweepSpec, columns, base_index, template, first_of) -> tuple[list, list, dict, np.ndarray]:
    """(resolved template configs (None for an invalid one), their warnings, invalid run ->
    its problems, the runs counted invalid). A template is the first run of its kind that
    the schema accepts; a kind none of whose first :data:`_MAX_CONFIRMED` runs is valid
    counts every run invalid."""
    out, notes, invalid = [], [], {}
    counted = np.zeros(len(template), dtype=bool)
    for t in range(len(first_of)):
        rows = np.flatnonzero(template == t)
        config = None
        for i in rows[:_MAX_CONFIRMED]:
            config, problems = _validate_row(spec, columns, base_index, int(i))
            if config is not None:
                break
            invalid[int(i)] = problems
            counted[i] = True
        if config is None:
            counted[rows] = True
            out.append(None), notes.append(())
            continue
        out.append({k: v for k, v in config.resolved.items() if k != "name"}), notes.append(config.warnings)
    return out, notes, invalid, counted


#: A chain's fields whose only check is their own rule (the schema's constraint of the field,
#: :attr:`rbstab.config.paths.KeyPath.rule`): a body's mass, inertia, K_t, L_t and limits of
#: H, a joint's gains and limits, gravity. No other check reads their values (the joints'
#: points, laws and boundary layers, the initial state, the settings and the disturbances
#: are read by the tree's checks and by each other's).
_TREE_PARAMETERS = {"bodies": {"mass", "inertia", "k_t", "l_t", "saturation"},
                    "joints": {"k_r", "l_r", "k_c", "l_c", "k_d", "l_d", "k_s", "saturation"}}


def _tree_parameter(key: str, column: np.ndarray) -> bool:
    """Whether ``key`` (a chain's) sets numbers of a field of :data:`_TREE_PARAMETERS` or
    gravity."""
    if column.dtype == object:
        return False
    path = parse_any_key(key)
    field = path.name.split(".")[1] if path.name.count(".") else ""
    return path.section == "gravity" or field in _TREE_PARAMETERS.get(path.section, ())


def _tree_parameter_flags(keys: Sequence[str], columns: Mapping[str, np.ndarray], templates: Sequence,
                          template: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The runs among ``rows`` (of valid templates) whose value of a field the parameter
    ``keys`` set breaks the field's rule, checked on the columns (each field whole: a
    template's matrix with the varied entries set); every run where a field cannot be
    assembled (the schema decides)."""
    flagged = np.zeros(len(template), dtype=bool)
    if not keys or not len(rows):
        return flagged
    fields = TableFields(templates, keys, {k: columns[k][rows] for k in keys}, template[rows])
    shapes = {("matrix",): (3, 3), ("limits",): (3,), ("vector",): (3,)}
    for section, name in {(p.section, p.name) for p in map(parse_any_key, keys)}:
        rule = parse_any_key(f"{section}.{name}" if name else section).rule
        try:
            with np.errstate(invalid="ignore"):  # an infinite entry of a diagonal: NaN off it, flagged below
                values = fields.get(section, name, shape=shapes.get(rule[:1]))
        except (ValueError, TypeError, IndexError):
            flagged[rows] = True
            continue
        integer = all(columns[k].dtype.kind == "i" for k in keys if parse_any_key(k).name == name)
        flagged[rows] |= _rule_bad(rule, values, integer)
    return flagged


#: A one-body tree's numbers that decide whether its weight is held (:func:`_unheld_flags`).
_WEIGHT_FIELDS = {"bodies": {"mass", "k_t"}, "joints": {"k_c", "k_d", "k_s"}}


def _unheld_flags(keys: Sequence[str], columns: Mapping[str, np.ndarray], templates: Sequence,
                  template: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The runs among ``rows`` of one body on a point law to the ground (either spelling's
    model) whose weight the parameter ``keys`` may leave unheld under gravity, which
    validation refuses (:func:`rbstab.config.physics.unheld_weight`): every one whose K_t is
    not positive on its diagonal and zero off it (then K_t alone holds any weight); the
    schema decides."""
    flagged = np.zeros(len(template), dtype=bool)
    weighty = [p.section == "gravity" or p.steps[2:3] and p.steps[2] in _WEIGHT_FIELDS.get(p.section, ())
               for p in map(parse_any_key, keys)]
    if not len(rows) or not any(weighty):
        return flagged
    fields = TableFields(templates, keys, {k: columns[k][rows] for k in keys}, template[rows])
    for t in np.unique(template[rows]).tolist():
        tree = templates[t]
        joint = tree["joints"][0]
        if len(tree["bodies"]) != 1 or joint["variant"] not in VARIANTS or point_fixed(joint["variant"]):
            continue
        mine = rows[template[rows] == t]
        k_t = fields.get("bodies", f"{tree['bodies'][0]['name']}.k_t", [0.0] * 3, shape=(3, 3), only=t)
        gravity = fields.get("gravity", "", shape=(3,), only=t)
        with np.errstate(invalid="ignore"):
            held = (np.diagonal(k_t, axis1=1, axis2=2) > 0).all(axis=1) & (np.count_nonzero(k_t, axis=(1, 2)) == 3)
        flagged[mine[~held & np.any(gravity != 0, axis=1)]] = True
    return flagged


#: How close to the gimbal lock [rad] a run's |theta_2| (a body's or a joint's) may come
#: before the columns' check of its initial state leaves it to the schema (which computes
#: the same angle in another order).
_LOCK_SLACK = 1e-9


def _tree_state_flags(keys: Sequence[str], columns: Mapping[str, np.ndarray], templates: Sequence,
                      template: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The runs among ``rows`` (of valid templates, which differ from their template only
    in the parameters :func:`_tree_parameter_flags` checks and the ``initial_state``
    entries ``keys``) that a check of :func:`rbstab.config.loader.initial_state_fits` may
    refuse, checked on the columns: each varied entry a finite number of magnitude at most
    MAX_MAGNITUDE; each body's |theta_2| and each joint's relative |theta_2| (the placed
    state's, :func:`rbstab.engine.batch.tree_initial_states`) below pi/2 - gimbal_margin
    by :data:`_LOCK_SLACK`. Every run of a template whose checks read more (its
    ``simulation.limits``; a written x or v of a permanent joint's child, held to its
    parent's point; a key of a body or D it lacks) is flagged: the schema decides."""
    from ..chain import GROUND  # heavy: numba (with the compiled tree below)
    from ..engine.batch import tree_initial_states  # heavy: numba
    from ..kinematics import rotation_matrix  # heavy: numba
    from ..variants import chain as C  # heavy: numba

    flagged = np.zeros(len(template), dtype=bool)
    if not len(rows):
        return flagged
    paths = [parse_any_key(k) for k in keys]
    for k, path in zip(keys, paths):
        values = columns[k][rows]
        if values.dtype == object or (len(path.steps) == 3 and values.reshape(len(rows), -1).shape[1] != 3):
            flagged[rows] = True  # not numbers of the entry's shape: the schema says what they are
            return flagged
        flagged[rows] |= _rule_bad(("vector",), values, False)  # finite, magnitude: each entry's own rule
    given = {(p.steps[1], p.steps[2]) for p in paths}  # (body, block) of each varied entry
    for t in np.unique(template[rows]).tolist():
        mine = rows[template[rows] == t]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the sweep reports each template's warnings
            config = config_from_mapping({**templates[t], "name": "template"})
        chain, names = config.chain, list(config.chain.body_names)
        tree = C.compile_chain(chain, offset=0.0)
        if (config.simulation.limits is not None or not {body for body, _ in given} <= set(names)
                or any(block == "d" and tree.d_at[names.index(body)] < 0 for body, block in given)
                or any(point_fixed(j.variant) and ((b.name, key) in given or f"initial_state.{b.name}.{key}"
                                                     not in config.placed)
                       for b, j in zip(chain.bodies, chain.joints) for key in ("x", "v"))):
            flagged[mine] = True
            continue
        with np.errstate(invalid="ignore"):
            y = tree_initial_states(config, tree, keys, columns, mine, tree.params[None], tree.ppoints[None])
            bound = np.pi / 2 - config.simulation.gimbal_margin - _LOCK_SLACK
            n = len(names)
            rotation = rotation_matrix(y[:, : 12 * n].reshape(len(mine), n, 12)[:, :, :3])  # A_i (k, n, 3, 3)
            bad = ~(np.abs(y[:, 12 * np.arange(n) + 1]) < bound).all(axis=1)
            for i, joint in enumerate(chain.joints):
                if joint.parent != GROUND:  # A_rel = A_p' A_c; A_rel[0, 2] = sin(theta_2)
                    sine = np.einsum("km,km->k", rotation[:, joint.parent, :, 0], rotation[:, i, :, 2])
                    bad |= ~(np.abs(np.arcsin(np.clip(sine, -1.0, 1.0))) < bound)
        flagged[mine] |= bad
    return flagged


def _validate_trees(spec: SweepSpec, columns: Mapping[str, np.ndarray], base_index: np.ndarray, counted: np.ndarray,
                    invalid_rows: dict, templates: Sequence, template: np.ndarray) -> None:
    """Validate each run of a chain's sweep not yet ``counted`` invalid (those the schema
    refuses into ``invalid_rows``, and counted). The parameters' columns
    (:data:`_TREE_PARAMETERS`) are checked against their fields' rules at once (a hinge's,
    numbers about its axis, by the schema); a run they flag is validated by the schema. Where every other varied key is an ``initial_state``
    entry, the initial states are checked as columns too (:func:`_tree_state_flags`) and
    only the runs either check flags are validated by the schema. Otherwise a run that
    differs from one of the last :data:`_RECENT_TREES` validated ones only in its
    parameters and ``initial_state`` passes where
    :func:`rbstab.config.loader.initial_state_fits` takes its initial state (the checks of
    that section); the others are validated by the schema."""
    keys = list(columns)
    hinges = {j.get("name") for t in templates if t for j in t.get("joints") or ()
              if j.get("variant") in AXES_VARIANTS}
    params = [k for k in keys if _tree_parameter(k, columns[k])
              and not (parse_any_key(k).section == "joints" and parse_any_key(k).steps[1] in hinges)]
    others = [k for k in keys if k not in params]
    valid = np.array([t is not None for t in templates], dtype=bool)[template] & ~counted
    flagged = _tree_parameter_flags(params, columns, [t or {} for t in templates], template, np.flatnonzero(valid))
    flagged |= _unheld_flags(params, columns, templates, template, np.flatnonzero(valid))
    states = [k for k in others if parse_any_key(k).section == "initial_state"]
    if others and states == others:  # parameters and initial states: both checked as columns
        flagged |= _tree_state_flags(states, columns, templates, template, np.flatnonzero(valid))
        for i in np.flatnonzero(flagged & ~counted):
            config, problems = _validate_row(spec, columns, base_index, int(i))
            if config is None:
                invalid_rows[int(i)] = problems
                counted[i] = True
        return
    # (a validated run's mapping but its parameters, name and initial state; its config; the
    # initial_state section last found to fit it, as written)
    recent: list[list] = []
    for i in np.flatnonzero(~counted):
        base = spec.bases[int(base_index[i])]
        data = None
        if not flagged[i]:
            try:
                data = row_mapping(base, others, [columns[k][i] for k in others], "sweep-run")
            except ConfigError:
                data = None
        if data is not None:
            rest = {k: v for k, v in data.items() if k not in ("name", "initial_state")}
            initial = data.get("initial_state")
            match = next((entry for entry in recent if entry[0] == rest
                          and (entry[2] == initial or initial_state_fits(entry[1], initial))), None)
            if match is not None:
                match[2] = initial
                continue
        config, problems = _validate_row(spec, columns, base_index, int(i))
        if config is None:
            invalid_rows[int(i)] = problems
            counted[i] = True
        elif data is not None:
            recent = [[rest, config, initial], *recent[: _RECENT_TREES - 1]]


def validate_columns(spec: SweepSpec, columns: Mapping[str, np.ndarray], base_index: np.ndarray,
                     template: np.ndarray, first_of: np.ndarray) -> tuple[tuple, list[str]]:
    """Validate every run (module docstring); (templates, warning lines).

    Raises
    ------
    SweepSpecError
        Listing the invalid runs (:func:`invalid_report`).
    """
    n = len(base_index)
    templates, notes, invalid_rows, counted = _templates(spec, columns, base_index, template, first_of)
    if spec.is_chain:  # its parameters' columns at once, the rest by its schema's and its tree's checks
        _validate_trees(spec, columns, base_index, counted, invalid_rows, templates, template)
        _refuse_invalid(spec, columns, base_index, invalid_rows, counted)
        return tuple(templates), _tree_warning_lines(columns, templates, notes, template, n)
    valid = [t if t is not None else {} for t in templates]
    fields = _Fields(columns, valid, template)
    variants = [t.get("controller", {}).get("variant", "") for t in valid]  # per template
    flagged = (_field_flags(fields, n) | _joint_flags(fields, variants, n)) & ~counted
    candidates = np.flatnonzero(flagged)
    exact = True  # whether every run the checks flagged so far is invalid
    for k, i in enumerate(candidates):
        if k >= _MAX_CONFIRMED and exact:  # the checks flag invalid runs only: count the rest
            counted[candidates[k:]] = True
            break
        config, problems = _validate_row(spec, columns, base_index, int(i))
        if config is None:
            invalid_rows[int(i)] = problems
            counted[i] = True
        exact = exact and config is None
    _refuse_invalid(spec, columns, base_index, invalid_rows, counted)
    return tuple(templates), _warning_lines(spec, fields, notes, template, n)


def _refuse_invalid(spec: SweepSpec, columns, base_index, invalid_rows: dict, counted: np.ndarray) -> None:
    """Raise SweepSpecError listing the invalid runs (:func:`invalid_report`), if any."""
    n_invalid = int(counted.sum())
    if n_invalid:
        listed = sorted(invalid_rows)[:_MAX_LISTED]
        raise SweepSpecError(invalid_report(spec, columns, base_index, n_invalid,
                                            [(i, invalid_rows[i]) for i in listed]), spec.source)


def _warning_lines(spec: SweepSpec, fields: _Fields, notes: Sequence[Sequence[str]], template: np.ndarray,
                   n: int) -> list[str]:
    """Physical-plausibility warnings, one line per config key: ``"k of n runs: <the
    message of the first run with it>"``; the triangle inequality of a varied inertia is
    checked on the column."""

    varied_inertia = fields.varied("body", "inertia")
    first, count = _template_lines(notes, template, lambda key: varied_inertia and "body.inertia" in key)
    got = fields.get("body", "inertia") if varied_inertia else None
    if got is not None:
        _add_inertia_line(first, count, full_matrices(got[0]), "")
    return [f"{count[k]} of {n} runs: {first[k]}" for k in first]


def _template_lines(notes: Sequence[Sequence[str]], template: np.ndarray, skip) -> tuple[dict, dict]:
    """(key -> the first message, key -> its runs) of the templates' warnings ``notes`` over
    their runs (a message's key: its text before the first colon), those of a key ``skip``
    says checked on the columns left out."""
    counts = np.bincount(template, minlength=len(notes))
    first: dict[str, str] = {}
    count: dict[str, int] = {}
    for t, lines in enumerate(notes):
        for message in lines:
            key = message.partition(":")[0]
            if skip(key):
                continue
            first.setdefault(key, message)
            count[key] = count.get(key, 0) + int(counts[t])
    return first, count


def _add_inertia_line(first: dict, count: dict, values: np.ndarray, label: str) -> None:
    """The triangle inequality of each run's inertia ``values`` (n, 3, 3) [kg m^2]: the first
    violating run's warning (:func:`rbstab.config.physics.inertia_warnings`; ``label`` for
    its key instead of ``body.inertia``, a chain's body) and their count into ``first`` and
    ``count``."""
    with np.errstate(invalid="ignore"):
        j = np.linalg.eigvalsh(np.nan_to_num(values))
    violate = j[:, 2] > (j[:, 0] + j[:, 1]) * (1 + 1e-12)
    if violate.any():
        (message,) = inertia_warnings(values[int(np.flatnonzero(violate)[0])])
        if label:
            message = message.replace(" body.inertia:", f" {label}:", 1)
        key = message.partition(":")[0]
        first[key], count[key] = message, int(violate.sum())


def _tree_warning_lines(columns: Mapping[str, np.ndarray], templates: Sequence, notes: Sequence[Sequence[str]],
                        template: np.ndarray, n: int) -> list[str]:
    """:func:`_warning_lines` of a chain's sweep: its templates' warnings over their runs,
    the triangle inequality of a body's varied inertia checked on the columns, run by run."""
    bodies = [b.get("name") for b in (templates[0] or {}).get("bodies", [])]
    varied = set()
    for key, column in columns.items():
        path = parse_any_key(key)
        entry, _, field = path.name.partition(".")
        if column.dtype != object and path.section == "bodies" and field.partition(".")[0] == "inertia":
            varied.add(bodies[int(entry)] if entry.isdigit() and int(entry) < len(bodies) else entry)
    labels = {name: f"bodies.{i}.inertia ('{name}')" for i, name in enumerate(bodies) if name in varied}
    first, count = _template_lines(notes, template, lambda key: any(label in key for label in labels.values()))
    fields = TableFields([t or {} for t in templates], list(columns), columns, template)
    for name, label in labels.items():
        try:
            values = fields.get("bodies", f"{name}.inertia", shape=(3, 3))
        except (ValueError, TypeError, IndexError):
            continue
        _add_inertia_line(first, count, values, label)
    return [f"{count[k]} of {n} runs: {first[k]}" for k in first]


def invalid_report(spec: SweepSpec, columns: Mapping[str, np.ndarray], base_index: np.ndarray, n_invalid: int,
                   listed: Sequence[tuple[int, Sequence[str]]], outcome: str = "nothing was run") -> list[str]:
    """The lines of the :class:`SweepSpecError` for invalid runs: a header, then each listed
    run (index, base, varied values) with its problems, the rest counted."""
    n = len(base_index)
    width = max(4, len(str(max(n - 1, 0))))
    lines = [f"{n_invalid} of {n} runs have an invalid configuration; {outcome}"]
    for i, problems in listed:
        shown = ", ".join(f"{k}={_short(v[i])}" for k, v in columns.items())
        head = f"run r{i:0{width}d} (base {spec.bases[int(base_index[i])].label}" + (f"; {shown})" if shown else ")")
        lines += [f"{head}: {line}" for line in problems]
    if n_invalid > len(listed):
        lines.append(f"... and {n_invalid - len(listed)} more invalid runs")
    return lines
