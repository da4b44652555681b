"""The validated, frozen run configurations and the one loader that builds them.

:func:`load_config` (a YAML file) and :func:`config_from_mapping` (its parsed mapping) take
either spelling of the model, ``body`` and ``controller`` (one body held by its controller) or
``bodies`` and ``joints`` (a tree of bodies), and give one type, a :class:`RunConfig` holding
the tree (:class:`rbstab.chain.Chain`; one body's is the tree of one body held to the ground
at its own point); a mapping that mixes them is refused in one line. Errors and the
``resolved`` configuration keep the keys written.

A tree's schema (the keys are public; units in brackets; each block validated as in a one-body
config, :mod:`rbstab.config`)::

    name: stance                    # optional, default: the file stem
    gravity: [0, 0, -9.81]          # g [m/s^2], inertial frame, default zeros
    bodies:                         # 1-8 bodies, parents before their children
      - name: legs                  # [A-Za-z_][A-Za-z0-9_-]*, at most 64 characters
        mass: 28.0                  # m [kg] > 0
        inertia: [2.6, 2.6, 0.1]    # J [kg m^2] about the centre of mass, SPD
        k_t: [0, 0, 0]              # optional: the ground-anchored feedback H (eq 24),
        l_t: [0, 0, 0]              #   default zero (none)
        saturation: {force_h: 800}  # optional: the limits of H [N]
    joints:                         # exactly one per body
      - name: ankle
        parent: ground              # 'ground' or a body listed before the child
        parent_point: [0, 0, 0]     # R_p [m]: inertial frame (ground), else the parent's body frame
        child: legs
        child_point: [0, 0, -0.45]  # R_c [m]: the point C, the child's body frame
        variant: permanent          # free | permanent | sliding | visco_elastic | embedded
        k_r: [900, 900, 300]        # eq 23 on the relative orientation, default zero (passive)
        l_r: [200, 200, 60]
        # k_c, l_c, k_d, l_d, k_s, boundary_layer: as the variant needs (required as for controller)
        saturation: {torque_n: 150, constraint_force: 2000, shape: clip}  # optional
    initial_state:                  # optional, per body by name; each key 3 numbers
      legs: {theta: [0.05, 0, 0]}   # theta, omega, x, v, d as in a one-body config
    simulation: {t_end: 5.0}        # as in a one-body config
    disturbances:                   # optional, at most 4; as in a one-body config, plus the body
      # it acts on (an impulse's jump: docs/physics.md, "A push on a chain"); a sliding joint
      # needs boundary_layer > 0
      - {kind: pulse, value: [0, 150, 0], point: [0, 0, 0.2], start: 0.3, duration: 0.1, body: trunk}

Where a body's ``x`` (``v``) is left out, rbstab places it from its parent's state so that
its joint's point coincides, E_j = 0 (and moves with it, dE_j/dt = 0):
X_c = X_p + A_p R_p - A_c R_c and V_c = V_p + A_p (Omega_p x R_p) - A_c (Omega_c x R_c)
(ground: X_p = V_p = 0, A_p = I, Omega_p = 0). A ``permanent`` joint whose given x or v
violates its constraint is an error that says by how much.
"""

from __future__ import annotations

import copy
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ValidationError

from ..chain import GROUND, Body, Chain, Joint, Passive, Region, Stop, hinge, slide, universal
from ..kinematics import axis_rotation, euler_angles_of, rotation_matrix, universal_columns, universal_rotation
from ..layout import AXES, JOINT_CODES, is_chain, point_fixed
from ..model import Disturbance, Limits, Saturation
from ..variants import VARIANTS
from ..variants.paper import has_paper_form
from .errors import ConfigError, PhysicalPlausibilityWarning, SemiDefiniteGainWarning
from .physics import angle_warnings, inertia_warnings, semidefinite_notes, unheld_bodies, unheld_weight
from .paths import apply_overrides, plain_tree
from .schema import (
    BODY_GAINS,
    CHAIN_TOP_LEVEL,
    GAIN_NAMES,
    GROUND_NAME,
    AXES_VARIANTS,
    HINGE_STATE,
    INITIAL_STATE_BLOCKS,
    InitialStateSchema,
    JOINT_GAINS,
    TOP_LEVEL,
    ChainSchema,
    RunSchema,
    SimulationSettings,
    clear_of_gimbal_lock,
    limits_violation,
    problem_line,
    short_repr,
    within_range,
)
from .yaml_io import dump_yaml_sections, read_yaml_file

__all__ = ["RunConfig", "config_from_mapping", "load_config",
           "PER_RUN_SECTIONS", "limits_of", "resolved_simulation", "ONE_BODY_NAMES",
           "CONSTRAINT_TOLERANCE", "initial_state_fits", "placed_initial_state", "tree_resolved", "tree_keys"]

#: Top-level sections in which most runs of a sweep differ (:meth:`RunConfig.to_yaml` does
#: not cache their YAML).
PER_RUN_SECTIONS = ("name", "initial_state")
#: The sections that :meth:`RunConfig.from_resolved` compares to share a rebuilt config's objects.
#: By whether the mapping is in one body's spelling.
_SHARED_SECTIONS = {True: ("body", "controller", "simulation", "disturbances"),
                    False: ("gravity", "bodies", "joints", "simulation", "disturbances")}
#: The names of the body and the joint of a one-body config's tree (its sections' names).
ONE_BODY_NAMES = ("body", "controller")
#: How far [m, m/s] a ``permanent`` joint's given initial state may miss its constraint
#: (E_j = 0, dE_j/dt = 0), relative to the lengths and speeds involved (at least 1).
CONSTRAINT_TOLERANCE = 1e-9
_INF3 = np.full(3, math.inf)


@dataclass(frozen=True, eq=False)
class RunConfig:
    """A validated run: everything the integrator needs, read-only; either spelling.

    The model is always a tree of bodies (:class:`rbstab.chain.Chain`): a one-body
    configuration (``body``, ``controller``) is the tree of its body (named ``body``) held by
    its joint (named ``controller``) at C = ``attachment_point`` to the same point R of the
    ground (E = X + A R - R, eq 4), with the controller's law, K_r, L_r, point gains and the
    limits of N and Lambda on the joint and K_t, L_t and the limits of H on the body. The
    paper's one-body equations of such a tree: :func:`rbstab.variants.paper.paper_form`.

    Attributes
    ----------
    name : str
        Run name, ``[A-Za-z0-9_.-]+`` (used as a file name).
    chain : Chain
        The bodies (topological order, as listed), their joints and gravity.
    initial_state : dict of str to dict of str to ndarray, shape (3,)
        By body name, then by the state blocks of :mod:`rbstab.layout` (``theta``,
        ``omega``, ``position``, ``velocity``, ``controller_state``; the last that of the
        body's joint), all present. In a tree's spelling, positions and velocities left out
        are placed from the parent's (module docstring); in one body's, blocks left out are
        zero, as written.
    placed : tuple of str
        ``initial_state.<body>.x`` and ``.v`` keys that rbstab placed.
    simulation : SimulationSettings
    resolved : dict
        The whole configuration as plain Python, in the spelling written, with every default
        filled in and gains as written; ``config_from_mapping(resolved)`` rebuilds an
        identical config. ``max_step`` is None when infinite.
    warnings : tuple of str
        Physical-plausibility warnings and notes (also emitted as
        :class:`PhysicalPlausibilityWarning`, :class:`SemiDefiniteGainWarning` for
        singular gains).
    """

    name: str
    chain: Chain
    initial_state: dict[str, dict[str, np.ndarray]]
    simulation: SimulationSettings
    resolved: dict
    placed: tuple[str, ...] = ()
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
            The ``initial_state`` section as in a YAML file (one body's: keys ``theta``,
            ``omega``, ``x``, ``v``, ``d``, absent keys zero; a tree's: by body name).
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
        """Rebuild the RunConfig of a ``resolved`` mapping (either spelling) without validating it again.

        For a mapping that a validated RunConfig gave (``config.resolved``, e.g. a sweep's
        planned run sent to a worker): "validate once, at the boundary". It gives what
        :func:`config_from_mapping` gives, without the warnings, in tens of microseconds for
        one body (its tree placed for a tree's spelling).

        ``like``: other rebuilt configs (a sweep's runs before this one). The new config
        shares the ``chain`` and ``simulation`` objects of the first of them with the same
        model and ``simulation`` sections (one body's ``body``, ``controller``; a tree's
        ``gravity``, ``bodies``, ``joints``; ``disturbances``), so that runs that differ only
        in name and initial state share one model (:func:`rbstab.simulator.simulate_many`).
        "The same" is Python's ``==``: sections that differ only in the sign of a zero
        (-0.0 == 0.0) count as the same.

        Raises
        ------
        KeyError, TypeError, ValueError, ConfigError
            For a mapping of another shape (validate it with :func:`config_from_mapping`).
        """
        one_body = not is_chain(resolved)
        shared = _SHARED_SECTIONS[one_body]
        other = next((c for c in like if all(resolved.get(k) == c.resolved.get(k) for k in shared)), None)
        chain = _chain(_tree_of(resolved) if one_body else resolved) if other is None else other.chain
        simulation = _settings(resolved["simulation"]) if other is None else other.simulation
        if one_body:
            states, placed = _written_state(resolved), ()
        else:
            states, placed, _ = _place_tree(resolved["initial_state"], chain, simulation.gimbal_margin, None, ())
        return cls(name=resolved["name"], chain=chain, initial_state=states, placed=placed, simulation=simulation,
                   resolved=resolved)


def _written_state(resolved: Mapping) -> dict[str, dict[str, np.ndarray]]:
    """:attr:`RunConfig.initial_state` of a one-body resolved mapping: its blocks as written."""
    written = resolved["initial_state"]
    return {ONE_BODY_NAMES[0]: {block: _array(written[key]) for key, block in INITIAL_STATE_BLOCKS.items()}}


def _settings(sim: Mapping) -> SimulationSettings:
    """The :class:`SimulationSettings` of a resolved ``simulation`` section (:attr:`RunConfig.resolved`)."""
    max_step = sim["max_step"]
    wall = sim.get("max_wall_time", SimulationSettings.max_wall_time)  # absent in files of rbstab < 0.2
    return SimulationSettings(
        t_end=float(sim["t_end"]), n_samples=int(sim["n_samples"]), method=sim["method"],
        rtol=float(sim["rtol"]), atol=float(sim["atol"]),
        max_step=math.inf if max_step is None else float(max_step), gimbal_margin=float(sim["gimbal_margin"]),
        max_steps=int(sim.get("max_steps", SimulationSettings.max_steps)),
        max_wall_time=math.inf if wall is None else float(wall),
        limits=limits_of(sim.get("limits")))


def tree_resolved(resolved: Mapping) -> dict:
    """A validated one-body resolved configuration (``body``, ``controller``;
    :attr:`RunConfig.resolved`) written in a tree's spelling (``bodies``, ``joints``): its
    one-body tree (:class:`RunConfig`), the body ``body`` with K_t, L_t and the limit of H,
    held at R to the ground point R by the joint ``controller`` with the law, the other gains
    and the limits of N and Lambda; a ``permanent`` joint's child's x and v left to be placed.
    ``config_from_mapping`` of it is the same tree. Not modified; shares nothing with it.

    Raises
    ------
    KeyError
        For a mapping without the one-body sections (``body``, ``controller``,
        ``initial_state``): validate it with :func:`config_from_mapping` first."""
    return copy.deepcopy(_tree_of(resolved))


def _tree_of(resolved: Mapping) -> dict:
    """:func:`tree_resolved` sharing the values (lists, numbers) of ``resolved``, which it
    does not modify: what the chain is built from (:func:`_chain`)."""
    r = dict(resolved)
    body, controller, state = dict(r.pop("body")), dict(r.pop("controller")), r.pop("initial_state")
    point = body.pop("attachment_point")
    r["gravity"] = body.pop("gravity")
    sat = controller.pop("saturation", None)
    tree_body = {"name": ONE_BODY_NAMES[0], **body, **{g: controller.pop(g) for g in ("k_t", "l_t") if g in controller}}
    if controller["variant"] != "sliding":
        controller.pop("boundary_layer", None)
    joint = {"name": ONE_BODY_NAMES[1], "parent": "ground", "parent_point": point, "child": ONE_BODY_NAMES[0],
             "child_point": point, **controller}
    if sat is not None:
        force_h = sat.get("force_h")
        tree_body["saturation"] = {"force_h": math.inf if force_h is None else force_h, "shape": sat["shape"]}
        joint["saturation"] = {k: sat[k] for k in ("torque_n", "constraint_force") if sat.get(k) is not None}
        joint["saturation"]["shape"] = sat["shape"]
    if point_fixed(controller["variant"]):
        state = {k: state[k] for k in ("theta", "omega")}
    r.update(bodies=[tree_body], joints=[joint], initial_state={ONE_BODY_NAMES[0]: state})
    if r.get("disturbances"):
        r["disturbances"] = [{**d, "body": ONE_BODY_NAMES[0]} for d in r["disturbances"]]
    return r


def tree_keys(key: str) -> tuple[str, ...]:
    """The keys of :func:`tree_resolved`'s mapping that hold the value of a one-body
    configuration's dotted ``key`` (``body.mass`` -> ``bodies.body.mass``,
    ``controller.k_t.0`` -> ``bodies.body.k_t.0``, ``body.attachment_point`` -> the joint's
    ``parent_point`` and ``child_point``, ``initial_state.theta`` ->
    ``initial_state.body.theta``); other sections' keys as they are."""
    section, _, rest = key.partition(".")
    field = rest.partition(".")[0]
    body, joint = (f"{part}.{name}." for part, name in zip(("bodies", "joints"), ONE_BODY_NAMES))
    if section == "body":
        if field == "gravity":
            return ("gravity" + rest[len(field):],)
        if field == "attachment_point":
            return tuple(joint + f"{end}_point" + rest[len(field):] for end in ("parent", "child"))
        return (body + rest,)
    if section == "controller":
        on_body = field in ("k_t", "l_t") or rest.startswith("saturation.force_h")
        return ((body if on_body else joint) + rest,)
    if section == "initial_state":
        return (f"initial_state.{ONE_BODY_NAMES[0]}.{rest}",)
    return (key,)


_BOTH = ("config key 'bodies': found both 'body' and 'bodies'; expected either body and controller (one body) or "
         "bodies and joints (a chain)")


def saturation_of(section: Mapping | None) -> Saturation | None:
    """The :class:`rbstab.model.Saturation` of a validated ``controller.saturation``
    mapping, or of a joint's (a limit missing or null: inf on every axis; a number: on every
    axis; ``torque_n_lower`` missing: None, the symmetric limits)."""
    if section is None:
        return None

    def limits(key: str) -> np.ndarray:
        value = section.get(key)
        return np.broadcast_to(np.array(math.inf if value is None else value, dtype=float), (3,)).copy()

    lower = None if section.get("torque_n_lower") is None else limits("torque_n_lower")
    return Saturation(limits("torque_n"), limits("force_h"), limits("constraint_force"), section.get("shape", "clip"),
                      lower)


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


def _check_weight(chain: Chain, tree: Mapping, one_body: bool, source: str | None, overrides: Sequence[str]) -> None:
    """ConfigError when the gains of one body on a point law to the ground leave its weight
    unheld (no equilibrium, :func:`unheld_weight`), in either spelling (``tree``: the resolved
    mapping in a tree's spelling; ``one_body``: written as one body, the message's keys its)."""
    body, joint = chain.bodies[0], chain.joints[0]
    used = VARIANTS[joint.variant].required_gains
    gains = {g: getattr(body if g in BODY_GAINS else joint, g) for g in (*GAIN_NAMES, "k_s") if g in used}
    unheld = unheld_weight(joint.variant, body.mass, chain.gravity, gains, joint.boundary_layer)
    if unheld is None:
        return
    name, detail = unheld[0].partition(".")[2], unheld[1]
    section = "bodies" if name in BODY_GAINS else "joints"
    entry = tree[section][0]  # the one body, or its joint
    found = short_repr(entry[name])
    key = f"controller.{name}" if one_body else f"{section}.{entry['name']}.{name}"
    inputs = (("body.mass", "body.gravity", "controller.variant", *(f"controller.{g}" for g in gains)) if one_body
              else ("gravity", "bodies", "joints"))
    related = [o for o in overrides if any(_related(o.partition("=")[0].strip(), k) for k in inputs)]
    line = f"config key '{key}': found {found}; expected gains that hold the weight ({detail})"
    raise ConfigError([line + "".join(f" [from override {_short_override(o)}]" for o in related)], source)


def _short_override(override: str, limit: int = 80) -> str:
    text = repr(override)
    return text if len(text) <= limit else text[: limit - 4] + "...'"


def _related(a: str, b: str) -> bool:
    """Whether one dotted key is the other or lies inside it."""
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def config_from_mapping(
    data: Mapping, *, default_name: str | None = None, source: str | None = None, overrides: Sequence[str] = ()
) -> RunConfig:
    """Validate a configuration mapping (the parsed YAML) in either spelling, one body's
    (``body``, ``controller``) or a tree's (``bodies``, ``joints``,
    :func:`rbstab.layout.is_chain`), into a :class:`RunConfig`.

    Parameters
    ----------
    data : Mapping
        The configuration (see the module docstring for the schema). Not modified.
    default_name : str, optional
        Name used when ``data`` has no ``name``.
    source : str, optional
        Where ``data`` comes from, for messages.
    overrides : sequence of str
        ``key.path=value`` lines applied first (:func:`apply_overrides`; a tree's keys name
        its bodies and joints).

    Raises
    ------
    ConfigError
        Listing every problem of the values; for a tree then, one at a time, one line for a
        fault of the tree (a parent that is not ``ground`` or an earlier body, two joints on
        one body, a body without a joint, a loop, duplicate names, more than 8 bodies), an
        unknown body name (``initial_state``, ``disturbances``), a permanent joint whose
        initial state misses its constraint (by how much), a start outside the limits.

    Warns
    -----
    PhysicalPlausibilityWarning
        For a configuration no real body has (inertia violating the triangle inequality,
        angles beyond one turn).
    SemiDefiniteGainWarning
        For a gain v needs definite (the variant's ``definite_gains``, else every gain it
        uses) that is positive semi-definite but singular (zero included): v is then not a
        strict Lyapunov function.
    """
    if overrides and isinstance(data, Mapping):
        data = apply_overrides(data, overrides)
    return _build(data, default_name=default_name, source=source, overrides=overrides)


def load_config(path: str | Path, overrides: Sequence[str] = ()) -> RunConfig:
    """Read a YAML configuration file, apply ``key.path=value`` overrides, validate it
    (:func:`config_from_mapping`: one body's or a tree's).

    Parameters
    ----------
    path : str or Path
        The YAML file; its stem is the default ``name``.
    overrides : sequence of str
        Applied in order with :func:`apply_overrides` before validation (a tree's keys name
        its bodies and joints: ``joints.hip.k_r.0=400``).

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


# -- a tree's spelling (bodies, joints) ---------------------------------------------------------


def placed_initial_state(initial_state: Mapping, chain: Chain, margin: float) -> dict[str, dict[str, np.ndarray]]:
    """:attr:`RunConfig.initial_state` of a validated chain config's ``initial_state``
    section (as resolved: by body name, the blocks written) for ``chain``: each body's
    blocks, the x and v left out placed from the parent's, as :func:`config_from_mapping`
    places them (``margin``: ``simulation.gimbal_margin``).

    Raises
    ------
    ConfigError
        For a section validation would refuse (a permanent joint's point off its parent's, a
        joint at its gimbal lock)."""
    return _place_tree(initial_state, chain, margin, None, ())[0]


def initial_state_fits(config: RunConfig, initial_state: Any) -> bool:
    """Whether ``config`` with ``initial_state`` (a chain config's ``initial_state`` section
    as written) in its place passes every check :func:`config_from_mapping` makes of that
    section: its schema, the bodies it names, each body's and each joint's gimbal lock, the
    points of the permanent joints and ``simulation.limits``. A sweep validates by it a run
    that differs from a validated one only there; where it is False,
    :func:`config_from_mapping` says why."""
    try:
        sections = plain_tree(initial_state)
        if not isinstance(sections, Mapping) or not set(sections) <= {body.name for body in config.chain.bodies}:
            return False
        margin = config.simulation.gimbal_margin
        written = {}
        for name, section in sections.items():
            state = InitialStateSchema.model_validate(section)
            if not clear_of_gimbal_lock(state.theta[1], margin):
                return False
            written[name] = {key: getattr(state, key) for key in INITIAL_STATE_BLOCKS if key in state.model_fields_set}
        states, _, errors = _place_tree(written, config.chain, margin, None, ())
        _check_limits(config.chain, states, errors, config.simulation.limits,
                           config.resolved["simulation"].get("limits") or {}, None, ())
    except (ConfigError, ValidationError, TypeError, ValueError):
        return False
    return True


def _gain(value: Any) -> np.ndarray:
    return _matrix(np.zeros(3) if value is None else value)


def _saturation(section: Mapping | None, keys: Sequence[str]) -> Saturation | None:
    if section is None:
        return None
    return saturation_of({k: section.get(k) for k in keys} | {"shape": section.get("shape", "clip")})


def _chain(tree: Mapping) -> Chain:
    """The :class:`Chain` of a resolved configuration in a tree's spelling (``gravity``,
    ``bodies``, ``joints``, ``disturbances``: validated, as :attr:`RunConfig.resolved` holds
    them, None values left out; one body's through :func:`_tree_of`): the one place a
    configuration's model is built."""
    names = [b["name"] for b in tree["bodies"]]
    index = {name: i for i, name in enumerate(names)}
    entries = tree.get("disturbances") or ()
    model_disturbances = disturbances_of(entries)
    bodies = tuple(
        Body(name=b["name"], mass=float(b["mass"]), inertia=_matrix(b["inertia"]), k_t=_gain(b.get("k_t")),
             l_t=_gain(b.get("l_t")), saturation=_saturation(b.get("saturation"), ("force_h",)),
             disturbances=tuple(d for d, entry in zip(model_disturbances, entries)
                                if entry.get("body", names[0]) == b["name"]))
        for b in tree["bodies"])
    joints = []
    for j in sorted(tree["joints"], key=lambda j: index[j["child"]]):
        parent = GROUND if j["parent"] == GROUND_NAME else index[j["parent"]]
        variant, sat, passive, written = j["variant"], j.get("saturation"), j.get("passive"), j.get("range")
        if variant in AXES_VARIANTS:  # one coordinate a turn about an axis or a translation along it; two turns
            upper = math.inf if sat is None or sat.get("torque_n") is None else sat["torque_n"]
            lower = np.negative(upper) if sat is None or sat.get("torque_n_lower") is None else sat["torque_n_lower"]
            gains = [j.get(key) or 0.0 for key in ("k_r", "l_r", "theta_ref")]
            springs = None if passive is None else tuple(passive.get(key) or 0.0 for key in ("k_r", "l_r", "theta_ref"))
            axes = 2 if variant == "universal" else None
            if axes is None:  # a number each
                upper, lower = float(upper), float(lower)
                gains = [float(g) for g in gains]
                springs = None if springs is None else tuple(float(g) for g in springs)
            make = {"hinge": hinge, "slide": slide, "universal": universal}[variant]
            joints.append(make(j["name"], parent, index[j["child"]], _array(j["parent_point"]),
                               _array(j["child_point"]), _array(j["axis"]), *gains,
                               None if sat is None else (lower, upper), "clip" if sat is None else sat["shape"],
                               springs, _stop(written, axes), _region(written, axes)))
            continue
        used = VARIANTS[variant].required_gains if variant in VARIANTS else ()  # a quaternion ball: no point law
        shape = 1 if variant == "ball" else 3
        joints.append(Joint(
            name=j["name"], parent=parent, child=index[j["child"]],
            parent_point=_array(j["parent_point"]), child_point=_array(j["child_point"]), variant=variant,
            k_r=_gain(j.get("k_r")), l_r=_gain(j.get("l_r")),
            **{g: _matrix(j[g]) if g in used else None for g in ("k_c", "l_c", "k_d", "l_d")},
            k_s=float(j["k_s"]) if "k_s" in used else None,
            boundary_layer=float(j.get("boundary_layer", 0.0)) if "k_s" in used else 0.0,
            saturation=_saturation(sat, ("torque_n", "torque_n_lower", "constraint_force")),
            theta_ref=np.zeros(3) if j.get("theta_ref") is None else _array(j["theta_ref"]),
            passive=None if passive is None else Passive(
                k_r=_gain(passive.get("k_r")), l_r=_gain(passive.get("l_r")),
                theta_ref=np.zeros(3) if passive.get("theta_ref") is None else _array(passive["theta_ref"])),
            stop=_stop(written, shape), region=_region(written, shape)))
    return Chain(bodies=bodies, joints=tuple(joints), gravity=_array(tree["gravity"]))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two vectors (3,), without numpy.cross's overhead for one pair (a sweep validates each run)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _place_tree(written: Mapping[str, Mapping], chain: Chain, margin: float, source: str | None,
                overrides: Sequence[str]) -> tuple[dict[str, dict[str, np.ndarray]], tuple[str, ...], list]:
    """(each body's initial state, x and v placed where left out; the keys placed; each joint's
    E_j [m]) of the blocks each body's resolved ``initial_state`` gives (``written``: by body
    name, its keys as written, each (3,), a hinge's child's q and u numbers): a block left out
    is zero, an x or v left out placed from the parent's; a hinge's child turned by q about its
    axis from its parent, Omega = A_rel' Omega_p + a u; a slide's child turned as its parent,
    its point at the parent's point moved by q a, moving at a u.

    Raises
    ------
    ConfigError
        For a permanent joint whose given x or v misses its constraint, a joint that starts at
        its gimbal lock or outside its range's admissible region."""
    states, placed, errors = {}, [], []
    written_of = [written.get(body.name) or {} for body in chain.bodies]
    given_of = [set(w) for w in written_of]
    blocks = [{block: np.array(w[key], dtype=float) if key in w else np.zeros(3)
               for key, block in INITIAL_STATE_BLOCKS.items()} for w in written_of]
    rotations = rotation_matrix(np.array([state["theta"] for state in blocks]))  # A_i of every body at once
    for body, joint, written, given, state, a_c in zip(chain.bodies, chain.joints, written_of, given_of, blocks,
                                                          rotations):
        if joint.parent == GROUND:
            x_p, v_p, a_p, omega_p = np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3)
            parent = GROUND_NAME
        else:
            p = chain.bodies[joint.parent].name
            x_p, v_p, omega_p = states[p]["position"], states[p]["velocity"], states[p]["omega"]
            a_p, parent = rotations[joint.parent], p
        if joint.variant in AXES_VARIANTS:
            q = np.broadcast_to(np.asarray(written.get("q", 0.0), dtype=float), (AXES[JOINT_CODES[joint.variant]],))
            u = np.broadcast_to(np.asarray(written.get("u", 0.0), dtype=float), q.shape)
            slid = np.zeros(3), np.zeros(3)  # a slide's q a, u a (the parent's frame)
            if joint.variant == "slide":  # turned as its parent, its point moved along the axis
                rel, columns = np.eye(3), np.zeros((1, 3))
                slid = joint.axis * float(q[0]), joint.axis * float(u[0])
            elif joint.variant == "hinge":
                rel, columns = np.array(axis_rotation(tuple(joint.axis), float(q[0]))), joint.axis[None]
            else:
                a_1, a_2 = tuple(joint.axis), tuple(joint.axis_2)
                rel = np.array(universal_rotation(a_1, a_2, float(q[0]), float(q[1])))
                columns = np.array(universal_columns(a_1, a_2, float(q[1])))
            a_c = a_p @ rel
            rotations[joint.child] = a_c
            state["theta"] = euler_angles_of(a_c)
            state["omega"] = rel.T @ omega_p + u @ columns
        r_p, r_c = joint.parent_point, joint.child_point
        if joint.variant == "slide":
            r_p = r_p + slid[0]
        point_p = x_p + a_p @ r_p  # the parent's point, inertial frame (a slide's moved along its axis)
        rate_p = v_p + a_p @ (_cross(omega_p, r_p) + (slid[1] if joint.variant == "slide" else 0.0))
        x_placed = point_p - a_c @ r_c
        v_placed = rate_p - a_c @ _cross(state["omega"], r_c)
        for key, block, target, what in (("x", "position", x_placed, "E_j"), ("v", "velocity", v_placed, "dE_j/dt")):
            if key not in given:
                state[block] = target
                placed.append(f"initial_state.{body.name}.{key}")
            elif point_fixed(joint.variant):
                miss = float(np.linalg.norm(state[block] - target))
                scale = max(1.0, float(np.abs(target).max()), float(np.abs(state[block]).max()))
                if miss > CONSTRAINT_TOLERANCE * scale:
                    _refuse(f"initial_state.{body.name}.{key}", short_repr(written[key]),
                            f"{key} = {short_repr([float(f'{t:.12g}') for t in target])} that holds the permanent "
                            f"joint '{joint.name}' to '{parent}' ({what} = 0)",
                            f"|{what}| = {miss:.6g} {'m' if key == 'x' else 'm/s'}; leave {key} out and rbstab "
                            f"places '{body.name}' from '{parent}'",
                            source, overrides, ("initial_state", "joints", "bodies"))
        relative = a_p.T @ a_c  # A_rel = A_p' A_c; with A = Rx Ry Rz, A_rel[0, 2] = sin(theta_2)
        theta_2 = math.asin(max(-1.0, min(1.0, float(relative[0, 2]))))
        region = joint.region
        if region is not None and joint.variant == "ball":  # a ball's turn inside its cone
            turn = math.acos(max(-1.0, min(1.0, (float(np.trace(a_p.T @ a_c)) - 1.0) / 2.0)))
            if turn > region.upper[0]:
                _refuse(f"initial_state.{body.name}.theta", short_repr(state["theta"].tolist()),
                        f"an orientation of '{body.name}' relative to '{parent}' turned at most "
                        f"{region.upper[0]:g} rad (joints.{joint.name}.range)",
                        f"its turn is {turn:.6g} rad; the range is an admissible region (kind: region), and the run "
                        "would start outside it", source, overrides, ("initial_state", "joints"))
        if region is not None and joint.variant == "permanent":  # a ball's Theta_j inside its range's region
            theta_j = euler_angles_of(relative)
            if not np.all((region.lower <= theta_j) & (theta_j <= region.upper)):
                _refuse(f"initial_state.{body.name}.theta", short_repr(state["theta"].tolist()),
                        f"an orientation of '{body.name}' relative to '{parent}' with joints.{joint.name}.range's "
                        + within_range((region.lower, region.upper)),
                        f"Theta_j = {short_repr([float(f'{x:.6g}') for x in theta_j])} rad; the range is an "
                        "admissible region (kind: region), and the run would start outside it",
                        source, overrides, ("initial_state", "joints"))
        if (joint.parent != GROUND and joint.variant not in (*AXES_VARIANTS, "ball")
                and abs(theta_2) >= math.pi / 2 - margin):
            _refuse(f"initial_state.{body.name}.theta", short_repr(state["theta"].tolist()),
                    f"an orientation of '{body.name}' relative to '{parent}' with |theta_2| < pi/2 - gimbal_margin "
                    f"= {math.pi / 2 - margin:.6g}",
                    f"joint '{joint.name}' starts at its gimbal lock, theta_2 = {theta_2:.6g} rad (eq 1)",
                    source, overrides, ("initial_state", "simulation.gimbal_margin"))
        errors.append(state["position"] + a_c @ r_c - point_p)
        for array in state.values():
            array.setflags(write=False)
        states[body.name] = state
    return states, tuple(placed), errors


def _check_engine_scope(chain: Chain, resolved: Mapping, source: str | None, overrides: Sequence[str]) -> None:
    """Refuse what no engine integrates: a sliding joint's pure sign law (boundary_layer 0,
    integrated event by event for the paper's one body, :func:`rbstab.variants.paper.paper_form`)
    in any other tree."""
    if has_paper_form(chain):
        return
    for joint in chain.joints:
        if joint.variant == "sliding" and joint.boundary_layer <= 0.0:
            _refuse(f"joints.{joint.name}.boundary_layer", "0", "a boundary layer > 0 [m] in a chain",
                    "the pure sign law is integrated event by event for one body held to the ground at its own "
                    "point only; tanh(E/phi) in a chain", source, overrides, ("joints",))


def _refuse(key: str, found: str, expected: str, detail: str, source: str | None, overrides: Sequence[str],
            inputs: Sequence[str]) -> None:
    line = f"config key '{key}': found {found}; expected {expected} ({detail})"
    related = [o for o in overrides if any(_related(o.partition("=")[0].strip(), k) for k in inputs)]
    raise ConfigError([line + "".join(f" [from override {_short_override(o)}]" for o in related)], source)


def _check_limits(chain: Chain, states: Mapping[str, Mapping[str, np.ndarray]], errors: Sequence[np.ndarray],
                  limits: Limits | None, written: Mapping, source: str | None, overrides: Sequence[str], *,
                  one_body: bool = False) -> None:
    """ConfigError when a body's initial theta, omega, x or v, or E_j of the joint that holds
    it (not a point-fixed joint: E_j = 0 there), lies outside ``limits`` (``simulation.limits``,
    the same bounds for every body and joint; ``states`` each body's placed initial state,
    ``errors`` each joint's E_j [m]; ``written``: the section as validated, for the message).
    ``one_body``: the configuration is written as one body (its words name no body)."""
    if limits is None:
        return
    for body, joint, error in zip(chain.bodies, chain.joints, errors):
        state = states[body.name]
        values = [state["theta"], state["omega"], state["position"], state["velocity"],
                  np.zeros(3) if point_fixed(joint.variant) else error]
        found = limits_violation(values, limits.array)
        if found is None:
            continue
        key, phrase = found
        who = ("the initial state lies outside simulation.limits" if one_body else
               f"joint '{joint.name}' starts outside" if key.endswith("constraint_error") else
               f"body '{body.name}' starts outside")
        inputs = ("simulation.limits", "initial_state", *(("body.attachment_point",) if one_body else ()))
        _refuse(key, short_repr(written.get(key.rpartition(".")[2])), "bounds that contain the initial state",
                f"{who}: {phrase}", source, overrides, inputs)


def _range_value(value: Any, shape: int | None, fill: float = 0.0) -> float | np.ndarray:
    """A range's number as a hinge's float (``shape`` None), or a ball's 3 or a universal
    joint's 2 (``shape``; one broadcast), as 3 entries (a universal joint's third ``fill``)."""
    if shape is None:
        return float(value)
    out = np.concatenate([np.broadcast_to(np.asarray(value, dtype=float), (shape,)), [fill] * (3 - shape)])
    out.setflags(write=False)
    return out


def _stop(written, shape: int | None) -> Stop | None:
    """A hinge's (``shape`` None) or a ball's (3) ``range`` as a stop (``kind: stop``), else None."""
    if written is None or written.get("kind", "stop") != "stop":
        return None
    return Stop(*(_range_value(v, shape, fill) for v, fill in ((written.get("lower"), -math.inf),
                                                              (written.get("upper"), math.inf),
                                                              (written["k_r"], 0.0), (written.get("l_r") or 0.0, 0.0))))


def _region(written, shape: int | None) -> Region | None:
    """A hinge's (``shape`` None) or a ball's (3) ``range`` as an admissible region (``kind:
    region``), else None."""
    if written is None or written.get("kind", "stop") != "region":
        return None
    return Region(_range_value(written.get("lower"), shape, -math.inf),
                  _range_value(written.get("upper"), shape, math.inf))


def _tree_resolved(run: ChainSchema) -> dict:
    """The validated configuration as plain Python: defaults filled in, None values and the
    x, v left out to be placed omitted (so that a rebuilt config places them again)."""
    dump = run.model_dump()
    for section in ("bodies", "joints"):
        dump[section] = [{k: v for k, v in entry.items() if v is not None} for entry in dump[section]]
        for entry in dump[section]:
            for part in ("saturation", "passive", "range"):
                if part in entry:
                    entry[part] = {k: v for k, v in entry[part].items() if v is not None}
    states = {}
    hinged = {j.child for j in run.joints if j.variant in AXES_VARIANTS}
    for body in run.bodies:  # every body, in order; a state's x, v only where written; a hinge's child's q, u
        state = run.initial_state.get(body.name)
        written = dump["initial_state"].get(body.name) or {"theta": [0.0] * 3, "omega": [0.0] * 3, "d": [0.0] * 3}
        if body.name in hinged:
            states[body.name] = {k: written.get(k) or 0.0 for k in HINGE_STATE}
            continue
        states[body.name] = {k: v for k, v in written.items()
                             if k not in ("x", "v", *HINGE_STATE) or (state is not None and k in state.model_fields_set)}
    dump["initial_state"] = states
    return _resolved_sections(dump, run)


def _notes(chain: Chain, inertia_keys: Sequence[str], angles: Sequence[tuple[str, Any]],
           gains: Sequence[tuple[str, Mapping[str, Any]]], source: str | None) -> tuple[str, ...]:
    """Warn of each body's physical-plausibility problems (its inertia, under the key
    ``inertia_keys[i]``; its initial angles in ``angles``: (key, theta)), the singular gains
    written (W002, once per (key prefix, gains by name) of ``gains``; a gain left out is
    zero by intent: a passive joint, no ground-anchored feedback) and the groups of bodies
    nothing holds (W007); returns the lines. Warned at the level of the caller of the
    public function that built the configuration."""
    lines = []
    for body, key in zip(chain.bodies, inertia_keys):
        lines += [m.replace(" body.inertia:", f" {key}:", 1) for m in inertia_warnings(body.inertia)]
    for key, theta in angles:
        lines += [m.replace(" initial_state.theta:", f" {key}:", 1) for m in angle_warnings(theta)]
    for prefix, written in gains:
        lines += [m.replace("controller.", prefix) for m in semidefinite_notes(written)]
    lines += unheld_bodies([b.name for b in chain.bodies], [b.mass for b in chain.bodies], [b.k_t for b in chain.bodies],
                           [(None if j.parent == GROUND else j.parent, j.child, j.variant) for j in chain.joints],
                           chain.gravity)
    for line in lines:
        category = SemiDefiniteGainWarning if line.startswith("W002") else PhysicalPlausibilityWarning
        warnings.warn(f"{source}: {line}" if source else line, category, stacklevel=4)
    return tuple(lines)


def _one_body_resolved(run: RunSchema) -> dict:
    """The validated one-body configuration as plain Python (:attr:`RunConfig.resolved`): defaults
    filled in, the gains and limits left out omitted, no ``disturbances`` or ``simulation.limits``
    key without them."""
    dump = run.model_dump()
    dump["controller"] = {k: v for k, v in dump["controller"].items() if v is not None}
    return _resolved_sections(dump, run)


def _resolved_sections(dump: dict, run: RunSchema | ChainSchema) -> dict:
    """``dump`` (``run``'s model_dump) with the sections either spelling resolves alike, in
    place: no ``disturbances`` key without them, each one's unset keys left out, and
    ``simulation`` as :func:`resolved_simulation` writes it."""
    if dump.get("disturbances") is None:
        dump.pop("disturbances", None)
    else:
        dump["disturbances"] = [{k: v for k, v in d.items() if v is not None} for d in dump["disturbances"]]
    resolved_simulation(dump["simulation"], run.simulation)
    return dump


def _build(data: Any, *, default_name: str | None, source: str | None, overrides: Sequence[str] = ()) -> RunConfig:
    """The one builder of a :class:`RunConfig`, either spelling: its schema (messages in the keys
    written), the resolved mapping, the tree (:func:`_chain`), its placed initial state, limits and
    notes."""
    one_body = not is_chain(data)
    if not isinstance(data, Mapping):
        what = "the configuration is empty" if data is None else f"top level: found {short_repr(data)}"
        raise ConfigError([f"{what}; expected {TOP_LEVEL if one_body else CHAIN_TOP_LEVEL}"], source)
    if one_body and "bodies" in data:
        raise ConfigError([_BOTH], source)
    run = _validated(plain_tree(data), default_name, source, overrides, RunSchema if one_body else ChainSchema)
    resolved = _one_body_resolved(run) if one_body else _tree_resolved(run)
    tree = _tree_of(resolved) if one_body else resolved
    chain = _chain(tree)
    if chain.size == 1 and chain.joints[0].variant in VARIANTS:  # one body on a point law to the ground
        _check_weight(chain, tree, one_body, source, overrides)
    if not one_body:
        _check_engine_scope(chain, resolved, source, overrides)
    simulation = _settings(resolved["simulation"])
    if not one_body or simulation.limits is not None:  # one body's x, v as written, or placed where point-fixed
        states, placed, errors = _place_tree(tree["initial_state"], chain, simulation.gimbal_margin, source,
                                             overrides)
        _check_limits(chain, states, errors, simulation.limits, resolved["simulation"].get("limits") or {}, source,
                      overrides, one_body=one_body)
    if one_body:
        ctrl = run.controller
        used = [g for g in (*GAIN_NAMES, "k_s") if g in VARIANTS[ctrl.variant].required_gains]
        definite = VARIANTS[ctrl.variant].definite_gains or tuple(used)
        notes = _notes(chain, ["body.inertia"], [("initial_state.theta", run.initial_state.theta)],
                       [("controller.", {g: getattr(ctrl, g) for g in used if g in definite})], source)
        return RunConfig(name=run.name, chain=chain, initial_state=_written_state(resolved), simulation=simulation,
                         resolved=resolved, warnings=notes)
    gains = [(f"bodies.{i}.", {g: getattr(b, g) for g in BODY_GAINS}) for i, b in enumerate(run.bodies)]
    gains += [(f"joints.{i}.", {g: getattr(j, g) for g in (*JOINT_GAINS, "k_s")
                                if g in ("k_r", "l_r")
                                or j.variant in VARIANTS and g in VARIANTS[j.variant].required_gains})
              for i, j in enumerate(run.joints) if j.variant not in AXES_VARIANTS]  # numbers >= 0 per coordinate
    hinged = {j.child for j in run.joints if j.variant in AXES_VARIANTS}
    angles = [(f"initial_state.{b.name}.theta", run.initial_state[b.name].theta) for b in chain.bodies
              if b.name in run.initial_state and b.name not in hinged]
    notes = _notes(chain, [f"bodies.{i}.inertia ('{b.name}')" for i, b in enumerate(chain.bodies)], angles, gains,
                   source)
    return RunConfig(name=run.name, chain=chain, initial_state=states, placed=placed,
                     simulation=simulation, resolved=resolved, warnings=notes)
