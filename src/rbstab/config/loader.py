"""The validated, frozen run configuration and the functions that build it."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ValidationError

from ..model import Disturbance, Gains, Limits, RigidBody, Saturation
from ..variants import VARIANTS, Variant
from ..variants.base import limited_values
from .errors import ConfigError, PhysicalPlausibilityWarning, SemiDefiniteGainWarning
from .physics import angle_warnings, inertia_warnings, semidefinite_notes, unheld_weight
from .paths import apply_overrides, plain_tree
from .schema import (
    GAIN_NAMES,
    INITIAL_STATE_BLOCKS,
    TOP_LEVEL,
    RunSchema,
    SimulationSettings,
    limits_violation,
    problem_line,
    short_repr,
)
from .yaml_io import dump_yaml_sections, read_yaml_file

__all__ = ["RunConfig", "config_from_mapping", "load_config", "PER_RUN_SECTIONS", "limits_of", "is_chain",
           "simulation_settings", "resolved_simulation"]

#: Top-level sections in which most runs of a sweep differ (:meth:`RunConfig.to_yaml` does
#: not cache their YAML).
PER_RUN_SECTIONS = ("name", "initial_state")
#: The sections that :meth:`RunConfig.from_resolved` compares to share a rebuilt config's objects.
_SHARED_SECTIONS = ("body", "controller", "simulation", "disturbances")


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
        """This configuration with another ``initial_state`` section, validated (what
        :func:`config_from_mapping` gives for ``resolved`` with ``initial_state`` and
        ``name`` replaced).

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
            For an invalid section or name.
        """
        data = {**self.resolved, "name": self.name if name is None else name, "initial_state": initial_state}
        return _build(data, default_name=None, source=source)

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
            if all(resolved.get(key) == other.resolved.get(key) for key in _SHARED_SECTIONS):
                return dataclasses.replace(other, name=resolved["name"], initial_state=initial_state,
                                           resolved=resolved, warnings=())
        ctrl, body, sim = resolved["controller"], resolved["body"], resolved["simulation"]
        used = VARIANTS[ctrl["variant"]].required_gains
        gains = Gains(
            **{g: _matrix(ctrl[g]) for g in GAIN_NAMES if g in used},
            k_s=float(ctrl["k_s"]) if "k_s" in used else None,
            boundary_layer=float(ctrl.get("boundary_layer", 0.0)) if "k_s" in used else 0.0,
            saturation=saturation_of(ctrl.get("saturation")),
            disturbances=disturbances_of(resolved.get("disturbances")),
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
                limits=limits_of(sim.get("limits")),
            ),
            resolved=resolved,
        )

    def make_variant(self) -> Variant:
        """The variant object, ``VARIANTS[variant](body, gains, simulation.limits)``."""
        return VARIANTS[self.variant](self.body, self.gains, self.simulation.limits)


#: The line with which a one-body loader refuses a chain configuration.
_NOT_RUN = ("config key 'bodies': found a chain of bodies; expected a one-body config (body, controller) here: "
            "chains are taken by rbstab validate, run, show, report, animate, sweep, analyze (rest state, linearisation, "
            "--basin, --push, basin stability), sensitivity and tune")

_BOTH = ("config key 'bodies': found both 'body' and 'bodies'; expected either body and controller (one body) or "
         "bodies and joints (a chain)")


def is_chain(data: Any) -> bool:
    """Whether a configuration mapping is a chain's (``bodies`` and ``joints`` instead of
    ``body`` and ``controller``): it has ``bodies`` and no ``body``."""
    return isinstance(data, Mapping) and "bodies" in data and "body" not in data


def saturation_of(section: Mapping | None) -> Saturation | None:
    """The :class:`rbstab.model.Saturation` of a validated ``controller.saturation``
    mapping (a limit missing or null: inf on every axis; a number: on every axis)."""
    if section is None:
        return None

    def limits(key: str) -> np.ndarray:
        value = section.get(key)
        return np.broadcast_to(np.array(math.inf if value is None else value, dtype=float), (3,)).copy()

    return Saturation(limits("torque_n"), limits("force_h"), limits("constraint_force"), section.get("shape", "clip"))


def limits_of(section: Mapping | None) -> Limits | None:
    """The :class:`rbstab.model.Limits` of a validated ``simulation.limits`` mapping (a bound
    missing or null: inf on every axis; a number: on every axis), or None without one."""
    if section is None:
        return None
    return Limits.of(**section)


def disturbances_of(entries: Sequence[Mapping] | None) -> tuple[Disturbance, ...]:
    """The :class:`rbstab.model.Disturbance` of each validated ``disturbances`` entry (a
    missing point: the centre of mass; an RMS as one number: on every axis)."""
    out = []
    for d in entries or ():
        kind = d["kind"]
        value = d.get("rms") if kind == "noise" else d.get("value")
        band = d.get("band") or (0.0, 0.0)
        out.append(Disturbance(
            kind=kind, quantity=d.get("quantity", "force"),
            value=np.broadcast_to(np.array(value, dtype=float), (3,)).copy(),
            point=np.array(d.get("point") or (0.0, 0.0, 0.0), dtype=float),
            start=float(d.get("start", 0.0)), duration=float(d.get("duration") or 0.0),
            frequency=float(d.get("frequency") or 0.0), phase=float(d.get("phase") or 0.0),
            band=(float(band[0]), float(band[1])), seed=int(d.get("seed") or 0)))
    return tuple(out)


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
    if is_chain(data):
        raise ConfigError([_NOT_RUN], source)
    if "bodies" in data:
        raise ConfigError([_BOTH], source)
    run = _validated(plain_tree(data), default_name, source, overrides)
    ctrl = run.controller
    used = VARIANTS[ctrl.variant].required_gains
    gains = Gains(
        **{g: _matrix(getattr(ctrl, g)) for g in GAIN_NAMES if g in used},
        k_s=float(ctrl.k_s) if "k_s" in used else None,
        boundary_layer=float(ctrl.boundary_layer) if "k_s" in used else 0.0,
        saturation=saturation_of(None if ctrl.saturation is None else ctrl.saturation.model_dump()),
    )
    body = RigidBody(
        mass=float(run.body.mass),
        inertia=_matrix(run.body.inertia),
        attachment_point=_array(run.body.attachment_point),
        gravity=_array(run.body.gravity),
    )
    sim = run.simulation
    simulation = simulation_settings(sim)
    used_gains = {g: getattr(gains, g) for g in (*GAIN_NAMES, "k_s") if g in used}
    _check_weight(ctrl, body, gains, used_gains, source, overrides)
    initial_state = {block: _array(getattr(run.initial_state, key)) for key, block in INITIAL_STATE_BLOCKS.items()}
    _check_limits(ctrl.variant, body, initial_state, simulation.limits, sim.limits, source, overrides)
    dump = run.model_dump()
    dump["controller"] = {k: v for k, v in dump["controller"].items() if v is not None}
    if dump.get("disturbances") is None:
        dump.pop("disturbances", None)  # a run without: its resolved form as before
    else:
        dump["disturbances"] = [{k: v for k, v in d.items() if v is not None} for d in dump["disturbances"]]
        gains = dataclasses.replace(gains, disturbances=disturbances_of(dump["disturbances"]))
    resolved_simulation(dump["simulation"], sim)
    definite = VARIANTS[ctrl.variant].definite_gains or tuple(used_gains)
    as_written = {g: getattr(ctrl, g) for g in used_gains if g in definite}  # 3 numbers: no numpy needed
    found_warnings = _emit_notes(body, as_written, source, stacklevel=4, theta=run.initial_state.theta)
    return RunConfig(
        name=run.name,
        variant=ctrl.variant,
        body=body,
        gains=gains,
        initial_state=initial_state,
        simulation=simulation,
        resolved=dump,  # plain dicts, lists, str and numbers (the validators make new lists; tested)
        warnings=found_warnings,
    )


def simulation_settings(sim) -> SimulationSettings:
    """The :class:`SimulationSettings` of a validated ``simulation`` section (the schema's model)."""
    return SimulationSettings(
        t_end=float(sim.t_end),
        n_samples=sim.n_samples,
        method=sim.method,
        rtol=float(sim.rtol),
        atol=float(sim.atol),
        max_step=float(sim.max_step),
        gimbal_margin=float(sim.gimbal_margin),
        max_steps=int(sim.max_steps),
        max_wall_time=float(sim.max_wall_time),
        limits=limits_of(None if sim.limits is None else sim.limits.model_dump()),
    )


def resolved_simulation(dump: dict, sim) -> None:
    """``dump`` (a ``simulation`` section's model_dump) as ``resolved`` writes it, in place:
    inf run limits as None, no ``limits`` key without limits, unset bounds left out."""
    for key in ("max_step", "max_wall_time"):
        if math.isinf(getattr(sim, key)):
            dump[key] = None
    if sim.limits is None:
        dump.pop("limits")  # a run without: its resolved form (and identity) as before
    else:
        dump["limits"] = {k: v for k, v in dump["limits"].items() if v is not None}


def _emit_notes(body: RigidBody, gains_as_written: Mapping[str, Any], source: str | None, *,
                stacklevel: int, theta: Any = (0.0, 0.0, 0.0)) -> tuple[str, ...]:
    """Warn of the physical-plausibility problems of ``body`` and the singular gains of
    ``gains_as_written`` (the gains the variant uses, as validated); returns their lines.
    ``stacklevel``: that of ``warnings.warn``, naming the caller of the public function."""
    notes = [(m, PhysicalPlausibilityWarning) for m in inertia_warnings(body.inertia)]
    notes += [(m, SemiDefiniteGainWarning) for m in semidefinite_notes(gains_as_written)]
    notes += [(m, PhysicalPlausibilityWarning) for m in angle_warnings(theta)]
    for message, category in notes:
        warnings.warn(f"{source}: {message}" if source else message, category, stacklevel=stacklevel)
    return tuple(message for message, _ in notes)


def _validated(data: dict, default_name: str | None, source: str | None, overrides: Sequence[str],
               schema: type[BaseModel] = RunSchema) -> Any:
    """``data`` (a plain tree, ``name`` set from ``default_name`` if absent) through the
    ``schema`` (:class:`RunSchema`, or :class:`ChainSchema` for a chain); ConfigError lists
    every problem, each with the overrides that touch its key."""
    name_defaulted = "name" not in data and default_name is not None
    if name_defaulted:
        data["name"] = default_name
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors(include_url=False):
            key, text = problem_line(err, name_defaulted, root=None if schema is RunSchema else schema)
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


def _check_limits(variant: str, body: RigidBody, initial_state: Mapping[str, np.ndarray], limits: Limits | None,
                  written: Any, source: str | None, overrides: Sequence[str]) -> None:
    """ConfigError when the initial state lies outside the admissible region ``limits``
    (:func:`rbstab.config.schema.inside_limits` of its bounded quantities; ``written``: the
    validated ``simulation.limits`` section, for the message)."""
    if limits is None:
        return
    cls = VARIANTS[variant]
    y0 = cls.layout.join(**{b: initial_state[b] for b in cls.layout.blocks})
    found = limits_violation(limited_values(cls.code, y0[None], body.attachment_point)[0], limits.array)
    if found is None:
        return
    key, detail = found
    bound = short_repr(getattr(written, key.rpartition(".")[2]))
    line = (f"config key '{key}': found {bound}; expected bounds that contain the initial state "
            f"(the initial state lies outside simulation.limits: {detail})")
    inputs = ("simulation.limits", "initial_state", "body.attachment_point")
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
        For a gain v needs definite (the variant's ``definite_gains``, else every gain it
        uses) that is positive semi-definite but singular (zero included): v is then not a
        strict Lyapunov function.
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
