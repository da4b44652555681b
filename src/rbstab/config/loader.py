"""The validated, frozen run configuration and the functions that build it."""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError
from pydantic_core import PydanticCustomError

from ..model import Gains, RigidBody
from ..variants import VARIANTS, Variant
from .errors import ConfigError, PhysicalPlausibilityWarning, SemiDefiniteGainWarning
from .physics import inertia_warnings, semidefinite_notes, unheld_weight
from .paths import apply_overrides, plain_tree
from .schema import (
    GAIN_NAMES,
    INITIAL_STATE_BLOCKS,
    TOP_LEVEL,
    RunSchema,
    _InitialState,
    _valid_name,
    _zero,
    SimulationSettings,
    _Body,
    _Controller,
    problem_line,
    short_repr,
)
from .yaml_io import dump_yaml_sections, read_yaml_file

__all__ = ["RunConfig", "config_from_mapping", "load_config", "PER_RUN_SECTIONS"]

#: Top-level sections in which most runs of a sweep differ (:meth:`RunConfig.to_yaml` does
#: not cache their YAML).
PER_RUN_SECTIONS = ("name", "initial_state")
#: The dotted keys of every field of ``initial_state`` (:meth:`RunConfig.with_initial_state`).
_INITIAL_STATE_KEYS = tuple(f"initial_state.{key}" for key in _InitialState.model_fields)
#: The sections that :meth:`RunConfig.from_resolved` compares to share a rebuilt config's objects.
_SHARED_SECTIONS = ("body", "controller", "simulation")


@dataclass(frozen=True, eq=False)
class RunConfig:
    """A validated run: everything the integrator needs, read-only.

    Attributes
    ----------
    name : str
        Run name, ``[A-Za-z0-9_.-]+`` (used as a file name).
    variant : str
        Key of :data:`rbstab.variants.VARIANTS`.
    body : RigidBody
        Mass [kg], inertia [kg m^2] (3x3), attachment point R [m], gravity g [m/s^2].
    gains : Gains
        The gains the variant uses (its ``required_gains``, and ``boundary_layer`` for
        sliding), each 3x3; gains configured but unused are None here (see ``resolved``).
    initial_state : dict of str to ndarray, shape (3,)
        Keyed by the state blocks of :mod:`rbstab.layout` (``theta``, ``omega``,
        ``position``, ``velocity``, ``controller_state``), all five always present.
    simulation : SimulationSettings
    resolved : dict
        The whole configuration as plain Python with every default filled in and gains as
        written; ``config_from_mapping(resolved)`` rebuilds an identical RunConfig.
        ``max_step`` is None when infinite.
    warnings : tuple of str
        Physical-plausibility warnings and notes (also emitted as
        :class:`PhysicalPlausibilityWarning`, :class:`SemiDefiniteGainWarning` for
        singular gains).
    """

    name: str
    variant: str
    body: RigidBody
    gains: Gains
    initial_state: dict[str, np.ndarray]
    simulation: SimulationSettings
    resolved: dict
    warnings: tuple[str, ...] = ()

    def to_yaml(self) -> str:
        """``resolved`` as YAML (keys in schema order, lists in flow style)."""
        return dump_yaml_sections(self.resolved, fresh=PER_RUN_SECTIONS)

    def with_initial_state(self, initial_state: Any, *, name: str | None = None, source: str | None = None) -> "RunConfig":
        """This configuration with another ``initial_state`` section, validated.

        What ``config_from_mapping`` gives for ``resolved`` with ``initial_state`` (and
        ``name``) replaced, at a fraction of the cost: :meth:`with_values` of the new
        section's fields (checked with the gimbal-lock margin of ``simulation``). The basin
        analysis uses it for its samples.

        Parameters
        ----------
        initial_state : Mapping or None
            The ``initial_state`` section as in a YAML file (keys ``theta``, ``omega``,
            ``x``, ``v``, ``d``; absent keys are zero).
        name : str, optional
            New ``name`` (must be valid; default: this config's).
        source : str, optional
            Where the data comes from, for messages.

        Raises
        ------
        ConfigError
            With the lines full validation would give.
        """
        section = {} if initial_state is None else initial_state
        data = {**self.resolved, "name": self.name if name is None else name, "initial_state": initial_state}
        if not isinstance(section, Mapping) or not set(section) <= set(_InitialState.model_fields):
            return _build(data, default_name=None, source=source)  # its message
        # absent keys at the schema's default, so that every field is one with_values checks
        data["initial_state"] = {**{key: _zero() for key in _InitialState.model_fields}, **section}
        return self.with_values(data, _INITIAL_STATE_KEYS, source=source)

    def with_values(self, data: Mapping, keys: Iterable[str], *, source: str | None = None) -> "RunConfig":
        """The configuration of ``data``, a mapping that differs from the one this
        configuration was validated from only at the dotted ``keys`` and ``name``, validated.

        What ``config_from_mapping(data)`` gives, at a fraction of the cost: only the fields
        that hold ``keys`` are checked, each with the schema's own check of that field, and
        the checks that join fields are made again (the weight held, the margin to gimbal
        lock, the physical-plausibility warnings and notes). The basin analysis checks
        its samples this way (:meth:`with_initial_state`).

        Keys in the ``body`` section, the gains of ``controller`` (not ``variant``) and
        ``initial_state`` take this path; any other key, a value that fails its check or
        a gain this configuration leaves unset goes through full validation, with its
        messages. The warnings and notes of the checks made again are emitted; the
        result's ``warnings`` holds them all (those of the sections not checked again are
        this configuration's, not emitted a second time).

        Parameters
        ----------
        data : Mapping
            The whole configuration as in a YAML file, ``name`` included (not modified).
        keys : iterable of str
            The dotted keys at which ``data`` may differ, e.g. ``"body.mass"``,
            ``"controller.k_c.1"`` (a sweep's varied keys).
        source : str, optional
            Where ``data`` comes from, for messages.

        Raises
        ------
        ConfigError
            As :func:`config_from_mapping` raises it.
        """
        fields = _changed_fields(tuple(keys))
        name = data.get("name") if isinstance(data, Mapping) else None
        changes = None if fields is None or not _valid_name(name) else _checked_fields(data, fields, self.resolved)
        if changes is None:
            return _build(data, default_name=None, source=source)
        resolved = {**self.resolved, "name": name}
        for section, values in changes.items():
            resolved[section] = {**self.resolved[section], **values}
        used = VARIANTS[self.variant].required_gains
        body, gains = self.body, self.gains
        if "body" in changes:
            b = resolved["body"]
            body = RigidBody(float(b["mass"]), _matrix(b["inertia"]), _array(b["attachment_point"]), _array(b["gravity"]))
        if "controller" in changes:
            changed = {g: v for g, v in changes["controller"].items() if g in used or ("k_s" in used and g == "boundary_layer")}
            gains = dataclasses.replace(gains, **{g: _matrix(v) if g in GAIN_NAMES else float(v) for g, v in changed.items()})
        initial_state = self.initial_state
        if "initial_state" in changes:
            state = resolved["initial_state"]
            if not abs(state["theta"][1]) < math.pi / 2 - self.simulation.gimbal_margin:
                return _build(data, default_name=None, source=source)  # its message
            initial_state = {block: _array(state[key]) for key, block in INITIAL_STATE_BLOCKS.items()}
        found_warnings = self.warnings
        if "body" in changes or "controller" in changes:
            ctrl = resolved["controller"]
            used_gains = {g: getattr(gains, g) for g in (*GAIN_NAMES, "k_s") if g in used}
            if unheld_weight(self.variant, body.mass, body.gravity, used_gains, gains.boundary_layer) is not None:
                return _build(data, default_name=None, source=source)  # its message
            found_warnings = _emit_notes(body, {g: ctrl[g] for g in used_gains}, source, stacklevel=3)
        return dataclasses.replace(self, name=name, body=body, gains=gains, initial_state=initial_state,
                                   resolved=resolved, warnings=found_warnings)

    @classmethod
    def from_resolved(cls, resolved: Mapping, *, like: Sequence["RunConfig"] = ()) -> "RunConfig":
        """Rebuild the RunConfig of a ``resolved`` mapping without validating it again.

        For a mapping that a validated RunConfig gave (``config.resolved``, e.g. a sweep's
        planned run sent to a worker): "validate once, at the boundary". It gives what
        :func:`config_from_mapping` gives, without the warnings, in a few microseconds.

        ``like``: other rebuilt configs (a sweep's runs before this one). The new config
        shares the ``body``, ``gains`` and ``simulation`` objects of the first of them with
        the same ``body``, ``controller`` and ``simulation`` sections, so that runs that
        differ only in name and initial state share one variant
        (:func:`rbstab.simulator.simulate_many`). "The same" is Python's ``==``: sections
        that differ only in the sign of a zero (-0.0 == 0.0) count as the same.

        Raises
        ------
        KeyError, TypeError, ValueError
            For a mapping of another shape (validate it with :func:`config_from_mapping`).
        """
        initial_state = {block: _array(resolved["initial_state"][key]) for key, block in INITIAL_STATE_BLOCKS.items()}
        for other in like:
            if all(resolved[key] == other.resolved[key] for key in _SHARED_SECTIONS):
                return dataclasses.replace(other, name=resolved["name"], initial_state=initial_state,
                                           resolved=resolved, warnings=())
        ctrl, body, sim = resolved["controller"], resolved["body"], resolved["simulation"]
        used = VARIANTS[ctrl["variant"]].required_gains
        gains = Gains(
            **{g: _matrix(ctrl[g]) for g in GAIN_NAMES if g in used},
            k_s=float(ctrl["k_s"]) if "k_s" in used else None,
            boundary_layer=float(ctrl.get("boundary_layer", 0.0)) if "k_s" in used else 0.0,
        )
        max_step = sim["max_step"]
        wall = sim.get("max_wall_time", SimulationSettings.max_wall_time)  # absent in files of rbstab < 0.2
        return cls(
            name=resolved["name"],
            variant=ctrl["variant"],
            body=RigidBody(float(body["mass"]), _matrix(body["inertia"]), _array(body["attachment_point"]),
                           _array(body["gravity"])),
            gains=gains,
            initial_state=initial_state,
            simulation=SimulationSettings(
                t_end=float(sim["t_end"]), n_samples=int(sim["n_samples"]), method=sim["method"],
                rtol=float(sim["rtol"]), atol=float(sim["atol"]),
                max_step=math.inf if max_step is None else float(max_step), gimbal_margin=float(sim["gimbal_margin"]),
                max_steps=int(sim.get("max_steps", SimulationSettings.max_steps)),
                max_wall_time=math.inf if wall is None else float(wall),
            ),
            resolved=resolved,
        )

    def make_variant(self) -> Variant:
        """The variant object, ``VARIANTS[variant](body, gains)``."""
        return VARIANTS[self.variant](self.body, self.gains)


def _array(value: Any) -> np.ndarray:
    """Read-only float array; a 3-list of numbers is a diagonal when ``value`` is a matrix."""
    out = np.array(value, dtype=float)
    out.setflags(write=False)
    return out


def _matrix(value: Any) -> np.ndarray:
    out = np.array(value, dtype=float)
    if out.ndim == 1:  # 3 numbers: a diagonal
        out = np.diag(out)
    out.setflags(write=False)
    return out


def _build(
    data: Any,
    *,
    default_name: str | None,
    source: str | None,
    overrides: Sequence[str] = (),
) -> RunConfig:
    if not isinstance(data, Mapping):
        what = "the configuration is empty" if data is None else f"top level: found {short_repr(data)}"
        raise ConfigError([f"{what}; expected {TOP_LEVEL}"], source)
    run = _validated(plain_tree(data), default_name, source, overrides)
    ctrl = run.controller
    used = VARIANTS[ctrl.variant].required_gains
    gains = Gains(
        **{g: _matrix(getattr(ctrl, g)) for g in GAIN_NAMES if g in used},
        k_s=float(ctrl.k_s) if "k_s" in used else None,
        boundary_layer=float(ctrl.boundary_layer) if "k_s" in used else 0.0,
    )
    body = RigidBody(
        mass=float(run.body.mass),
        inertia=_matrix(run.body.inertia),
        attachment_point=_array(run.body.attachment_point),
        gravity=_array(run.body.gravity),
    )
    sim = run.simulation
    simulation = SimulationSettings(
        t_end=float(sim.t_end),
        n_samples=sim.n_samples,
        method=sim.method,
        rtol=float(sim.rtol),
        atol=float(sim.atol),
        max_step=float(sim.max_step),
        gimbal_margin=float(sim.gimbal_margin),
        max_steps=int(sim.max_steps),
        max_wall_time=float(sim.max_wall_time),
    )
    used_gains = {g: getattr(gains, g) for g in (*GAIN_NAMES, "k_s") if g in used}
    _check_weight(ctrl, body, gains, used_gains, source, overrides)
    dump = run.model_dump()
    dump["controller"] = {k: v for k, v in dump["controller"].items() if v is not None}
    for key in ("max_step", "max_wall_time"):
        if math.isinf(getattr(sim, key)):
            dump["simulation"][key] = None
    as_written = {g: getattr(ctrl, g) for g in used_gains}  # 3 numbers: no numpy needed
    found_warnings = _emit_notes(body, as_written, source, stacklevel=4)
    return RunConfig(
        name=run.name,
        variant=ctrl.variant,
        body=body,
        gains=gains,
        initial_state={
            block: _array(getattr(run.initial_state, key))
            for key, block in INITIAL_STATE_BLOCKS.items()
        },
        simulation=simulation,
        resolved=dump,  # plain dicts, lists, str and numbers (the validators make new lists; tested)
        warnings=found_warnings,
    )


def _emit_notes(body: RigidBody, gains_as_written: Mapping[str, Any], source: str | None, *,
                stacklevel: int) -> tuple[str, ...]:
    """Warn of the physical-plausibility problems of ``body`` and the singular gains of
    ``gains_as_written`` (the gains the variant uses, as validated); returns their lines.
    ``stacklevel``: that of ``warnings.warn``, naming the caller of the public function."""
    notes = [(m, PhysicalPlausibilityWarning) for m in inertia_warnings(body.inertia)]
    notes += [(m, SemiDefiniteGainWarning) for m in semidefinite_notes(gains_as_written)]
    for message, category in notes:
        warnings.warn(f"{source}: {message}" if source else message, category, stacklevel=stacklevel)
    return tuple(message for message, _ in notes)


#: (section, field) -> the schema's check of the field (its ``BeforeValidator``), for the
#: sections whose fields :meth:`RunConfig.with_values` checks one at a time.
_FIELD_CHECKS = {(section, name): field.metadata[0].func
                 for section, model in (("body", _Body), ("controller", _Controller), ("initial_state", _InitialState))
                 for name, field in model.model_fields.items() if name != "variant"}


@functools.lru_cache(maxsize=64)
def _changed_fields(keys: tuple[str, ...]) -> dict[str, tuple[str, ...]] | None:
    """Section -> its fields that hold the dotted ``keys``; None when a key lies elsewhere:
    another section, a whole section, an unknown field, or ``controller.variant``."""
    fields: dict[str, dict[str, None]] = {}
    for key in keys:
        section, _, rest = key.partition(".")
        field = rest.partition(".")[0]
        if (section, field) not in _FIELD_CHECKS:
            return None
        fields.setdefault(section, {})[field] = None
    return {section: tuple(names) for section, names in fields.items()}


def _checked_fields(data: Mapping, fields: Mapping[str, Sequence[str]], resolved: Mapping) -> dict[str, dict] | None:
    """Section -> field -> the field's value in ``data`` through its schema check (the
    schema's ``BeforeValidator``); None when a check fails, or for a field ``resolved``
    does not hold (a gain left unset) or that becomes unset: full validation decides those."""
    out: dict[str, dict] = {}
    for section, names in fields.items():
        given = data.get(section)
        if not isinstance(given, Mapping):
            return None
        values = {}
        for name in names:
            if name not in given or name not in resolved[section]:
                return None
            try:
                value = _FIELD_CHECKS[section, name](plain_tree(given[name]))
            except PydanticCustomError:  # its message comes from full validation
                return None
            if value is None:
                return None
            values[name] = value
        out[section] = values
    return out


def _validated(data: dict, default_name: str | None, source: str | None, overrides: Sequence[str]) -> RunSchema:
    """``data`` (a plain tree, ``name`` set from ``default_name`` if absent) through the
    schema; ConfigError lists every problem, each with the overrides that touch its key."""
    name_defaulted = "name" not in data and default_name is not None
    if name_defaulted:
        data["name"] = default_name
    try:
        return RunSchema.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors(include_url=False):
            key, text = problem_line(err, name_defaulted)
            related = [o for o in overrides if _related(o.partition("=")[0].strip(), key)]
            lines.append(text + "".join(f" [from override {_short_override(o)}]" for o in related))
        raise ConfigError(lines, source) from None


def _check_weight(ctrl, body: RigidBody, gains: Gains, used_gains: dict, source: str | None,
                  overrides: Sequence[str]) -> None:
    """ConfigError when the gains leave the weight unheld (no equilibrium, :func:`unheld_weight`)."""
    unheld = unheld_weight(ctrl.variant, body.mass, body.gravity, used_gains, gains.boundary_layer)
    if unheld is None:
        return
    key, detail = unheld
    found = short_repr(getattr(ctrl, key.partition(".")[2]))
    line = f"config key '{key}': found {found}; expected gains that hold the weight ({detail})"
    inputs = ("body.mass", "body.gravity", "controller.variant", *(f"controller.{g}" for g in used_gains))
    related = [o for o in overrides if any(_related(o.partition("=")[0].strip(), k) for k in inputs)]
    raise ConfigError([line + "".join(f" [from override {_short_override(o)}]" for o in related)], source)


def _short_override(override: str, limit: int = 80) -> str:
    text = repr(override)
    return text if len(text) <= limit else text[: limit - 4] + "...'"


def _related(a: str, b: str) -> bool:
    """Whether one dotted key is the other or lies inside it."""
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def config_from_mapping(
    data: Mapping, *, default_name: str | None = None, source: str | None = None
) -> RunConfig:
    """Validate a configuration mapping (the parsed YAML) into a :class:`RunConfig`.

    Parameters
    ----------
    data : Mapping
        The configuration (see the module docstring for the schema). Not modified.
    default_name : str, optional
        Name used when ``data`` has no ``name``.
    source : str, optional
        Where ``data`` comes from, for messages.

    Raises
    ------
    ConfigError
        Listing every problem found.

    Warns
    -----
    PhysicalPlausibilityWarning
        For a configuration no real body has (inertia violating the triangle inequality).
    SemiDefiniteGainWarning
        For a gain the variant uses that is positive semi-definite but singular (zero
        included): v is then not a strict Lyapunov function.
    """
    return _build(data, default_name=default_name, source=source)


def load_config(path: str | Path, overrides: Sequence[str] = ()) -> RunConfig:
    """Read a YAML configuration file, apply ``key.path=value`` overrides, validate it.

    Parameters
    ----------
    path : str or Path
        The YAML file; its stem is the default ``name``.
    overrides : sequence of str
        Applied in order with :func:`apply_overrides` before validation.

    Raises
    ------
    ConfigError
        For a missing or unreadable file, a YAML syntax error, a top level that is not a
        mapping, a malformed override, or any invalid value (all listed at once; lines
        about an overridden key name the override).

    Warns
    -----
    PhysicalPlausibilityWarning, SemiDefiniteGainWarning
        See :func:`config_from_mapping`.
    """
    path = Path(path)
    source = str(path)
    data = read_yaml_file(path, "config file")
    try:
        if isinstance(data, Mapping):
            data = apply_overrides(data, overrides)
    except ConfigError as exc:
        raise ConfigError(exc.errors, source) from None
    return _build(data, default_name=path.stem, source=source, overrides=overrides)
