"""Chain configurations: a YAML file with ``bodies`` and ``joints`` -> a validated, frozen
:class:`ChainConfig` holding its :class:`rbstab.chain.Chain`; and :func:`chain_of`, the
chain of any configuration (a one-body config is the one-body chain).

Schema (the keys are public; units in brackets; each block validated as in a one-body
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

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..chain import GROUND, Body, Chain, Joint, single
from ..kinematics import rotation_matrix
from ..model import Saturation
from ..variants import VARIANTS
from .errors import ConfigError, PhysicalPlausibilityWarning, SemiDefiniteGainWarning
from .loader import (
    RunConfig,
    _array,
    _matrix,
    _related,
    _short_override,
    _validated,
    config_from_mapping,
    disturbances_of,
    is_chain,
    load_config,
    resolved_simulation,
    saturation_of,
    simulation_settings,
)
from .paths import apply_overrides, plain_tree
from .physics import angle_warnings, inertia_warnings, semidefinite_notes, unheld_bodies
from .schema import (
    BODY_GAINS,
    CHAIN_TOP_LEVEL,
    GROUND_NAME,
    INITIAL_STATE_BLOCKS,
    JOINT_GAINS,
    ChainSchema,
    SimulationSettings,
    short_repr,
)
from .yaml_io import dump_yaml, read_yaml_file

__all__ = ["ChainConfig", "chain_of", "one_body_config", "chain_config_from_mapping", "any_config_from_mapping", "load_any_config", "ONE_BODY_NAMES",
           "CONSTRAINT_TOLERANCE"]

#: The names of the body and the joint of a one-body config's chain (its sections' names).
ONE_BODY_NAMES = ("body", "controller")
#: How far [m, m/s] a ``permanent`` joint's given initial state may miss its constraint
#: (E_j = 0, dE_j/dt = 0), relative to the lengths and speeds involved (at least 1).
CONSTRAINT_TOLERANCE = 1e-9
_INF3 = np.full(3, math.inf)


@dataclass(frozen=True, eq=False)
class ChainConfig:
    """A validated chain run: everything the integrator needs, read-only.

    Attributes
    ----------
    name : str
        Run name (a file name).
    chain : Chain
        The bodies (topological order, as listed), their joints and gravity.
    initial_state : dict of str to dict of str to ndarray, shape (3,)
        By body name, then by the state blocks of :mod:`rbstab.layout` (``theta``,
        ``omega``, ``position``, ``velocity``, ``controller_state``; the last that of the
        body's joint), all present; positions and velocities left out of the config placed
        from the parent's (module docstring).
    placed : tuple of str
        ``initial_state.<body>.x`` and ``.v`` keys that rbstab placed.
    simulation : SimulationSettings
    resolved : dict
        The configuration as plain Python with every default filled in (the placed x, v
        left out); ``chain_config_from_mapping(resolved)`` rebuilds an identical config.
    warnings : tuple of str
        Physical-plausibility warnings (also emitted as :class:`PhysicalPlausibilityWarning`).
    """

    name: str
    chain: Chain
    initial_state: dict[str, dict[str, np.ndarray]]
    placed: tuple[str, ...]
    simulation: SimulationSettings
    resolved: dict
    warnings: tuple[str, ...] = ()

    def to_yaml(self) -> str:
        """``resolved`` as YAML (keys in schema order, lists in flow style)."""
        return dump_yaml(self.resolved)


def chain_of(config: RunConfig | ChainConfig) -> Chain:
    """The chain a configuration means: a chain config's own, or for a one-body config the
    one-body chain (:func:`rbstab.chain.single`): its body (named ``body``) with the
    ground-anchored feedback K_t, L_t and the limits of H, held by its joint (named
    ``controller``) at C = ``attachment_point`` to the ground point R (where C is at the
    equilibrium X = 0, Theta = 0: E = X + A R - R, eq 4) with the variant's law, K_r, L_r and
    the limits of N and Lambda. Same equations, same numbers."""
    if isinstance(config, ChainConfig):
        return config.chain
    gains, sat = config.gains, config.gains.saturation
    body = Body(
        name=ONE_BODY_NAMES[0], mass=config.body.mass, inertia=config.body.inertia, k_t=gains.k_t, l_t=gains.l_t,
        saturation=None if sat is None else Saturation(_INF3.copy(), sat.force_h, _INF3.copy(), sat.shape),
        disturbances=gains.disturbances)
    joint = Joint(
        name=ONE_BODY_NAMES[1], parent=GROUND, child=0, parent_point=config.body.attachment_point,
        child_point=config.body.attachment_point, variant=config.variant, k_r=gains.k_r, l_r=gains.l_r,
        k_c=gains.k_c, l_c=gains.l_c, k_d=gains.k_d, l_d=gains.l_d, k_s=gains.k_s,
        boundary_layer=gains.boundary_layer,
        saturation=None if sat is None else Saturation(sat.torque_n, _INF3.copy(), sat.constraint_force, sat.shape))
    return single(body, joint, config.body.gravity)


def one_body_config(config: RunConfig | ChainConfig) -> RunConfig | None:
    """The one-body spelling of a configuration: a one-body config itself; a chain that is
    the paper's one-body model (one body held by its joint to the ground at R_p = R_c,
    :func:`rbstab.variants.chain.is_one_body`) with its body's mass, inertia, K_t, L_t and
    limits of H, its joint's point as ``attachment_point``, law, gains and limits as
    ``controller``, gravity, initial state, disturbances and simulation, the inverse of
    :func:`chain_of` (the same model: the same runs, bit for bit); None for any other chain."""
    if not isinstance(config, ChainConfig):
        return config
    r = config.resolved
    if len(r["bodies"]) != 1:
        return None
    (body,), (joint,) = r["bodies"], r["joints"]
    if joint["parent"] != GROUND_NAME or list(joint["parent_point"]) != list(joint["child_point"]):
        return None
    placed = ("name", "parent", "parent_point", "child", "child_point", "saturation")
    controller = {k: v for k, v in joint.items() if k not in placed} | {"k_t": body["k_t"], "l_t": body["l_t"]}
    limits = {**(joint.get("saturation") or {}), **(body.get("saturation") or {})}
    if limits:
        controller["saturation"] = limits
    mapping = {"name": r["name"],
               "body": {"mass": body["mass"], "inertia": body["inertia"], "attachment_point": joint["child_point"],
                        "gravity": r["gravity"]},
               "controller": controller,
               "initial_state": dict(r.get("initial_state", {}).get(body["name"], {})),
               "simulation": r["simulation"]}
    if r.get("disturbances"):
        mapping["disturbances"] = [{k: v for k, v in d.items() if k != "body"} for d in r["disturbances"]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the chain's own warnings were shown
        return config_from_mapping(mapping, source=f"the one-body spelling of {config.name}")


def _gain(value: Any) -> np.ndarray:
    return _matrix(np.zeros(3) if value is None else value)


def _saturation(section: Any, keys: Sequence[str]) -> Saturation | None:
    if section is None:
        return None
    return saturation_of({k: getattr(section, k) for k in keys} | {"shape": section.shape})


def _chain(run: ChainSchema, disturbances: Sequence[Mapping]) -> Chain:
    names = [b.name for b in run.bodies]
    index = {name: i for i, name in enumerate(names)}
    model_disturbances = disturbances_of(disturbances)
    bodies = tuple(
        Body(name=b.name, mass=float(b.mass), inertia=_matrix(b.inertia), k_t=_gain(b.k_t), l_t=_gain(b.l_t),
             saturation=_saturation(b.saturation, ("force_h",)),
             disturbances=tuple(d for d, entry in zip(model_disturbances, disturbances)
                                if entry.get("body", names[0]) == b.name))
        for b in run.bodies)
    joints = []
    for j in sorted(run.joints, key=lambda j: index[j.child]):
        used = VARIANTS[j.variant].required_gains
        joints.append(Joint(
            name=j.name, parent=GROUND if j.parent == GROUND_NAME else index[j.parent], child=index[j.child],
            parent_point=_array(j.parent_point), child_point=_array(j.child_point), variant=j.variant,
            k_r=_gain(j.k_r), l_r=_gain(j.l_r),
            **{g: _matrix(getattr(j, g)) if g in used else None for g in ("k_c", "l_c", "k_d", "l_d")},
            k_s=float(j.k_s) if "k_s" in used else None,
            boundary_layer=float(j.boundary_layer) if "k_s" in used else 0.0,
            saturation=_saturation(j.saturation, ("torque_n", "constraint_force"))))
    return Chain(bodies=bodies, joints=tuple(joints), gravity=_array(run.gravity))


def _initial_state(run: ChainSchema, chain: Chain, source: str | None,
                   overrides: Sequence[str]) -> tuple[dict[str, dict[str, np.ndarray]], tuple[str, ...], list]:
    """(each body's initial state, x and v placed where left out; the keys placed; each
    joint's E_j [m]). ConfigError for a permanent joint whose given x or v misses its
    constraint, or a joint's relative orientation at gimbal lock."""
    states, placed, rotations, errors = {}, [], [], []
    margin = run.simulation.gimbal_margin
    for body, joint in zip(chain.bodies, chain.joints):
        written = run.initial_state.get(body.name)
        given = set() if written is None else written.model_fields_set
        state = {block: np.array(getattr(written, key) if written is not None else np.zeros(3), dtype=float)
                 for key, block in INITIAL_STATE_BLOCKS.items()}
        a_c = rotation_matrix(state["theta"])
        if joint.parent == GROUND:
            x_p, v_p, a_p, omega_p = np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3)
            parent = GROUND_NAME
        else:
            p = chain.bodies[joint.parent].name
            x_p, v_p, omega_p = states[p]["position"], states[p]["velocity"], states[p]["omega"]
            a_p, parent = rotations[joint.parent], p
        r_p, r_c = joint.parent_point, joint.child_point
        point_p = x_p + a_p @ r_p  # the parent's point, inertial frame
        rate_p = v_p + a_p @ np.cross(omega_p, r_p)
        x_placed = point_p - a_c @ r_c
        v_placed = rate_p - a_c @ np.cross(state["omega"], r_c)
        for key, block, target, what in (("x", "position", x_placed, "E_j"), ("v", "velocity", v_placed, "dE_j/dt")):
            if key not in given:
                state[block] = target
                placed.append(f"initial_state.{body.name}.{key}")
            elif joint.variant == "permanent":
                miss = float(np.linalg.norm(state[block] - target))
                scale = max(1.0, float(np.abs(target).max()), float(np.abs(state[block]).max()))
                if miss > CONSTRAINT_TOLERANCE * scale:
                    _refuse(f"initial_state.{body.name}.{key}", short_repr(getattr(written, key)),
                            f"{key} = {short_repr([float(f'{t:.12g}') for t in target])} that holds the permanent "
                            f"joint '{joint.name}' to '{parent}' ({what} = 0)",
                            f"|{what}| = {miss:.6g} {'m' if key == 'x' else 'm/s'}; leave {key} out and rbstab "
                            f"places '{body.name}' from '{parent}'",
                            source, overrides, ("initial_state", "joints", "bodies"))
        relative = a_p.T @ a_c  # A_rel = A_p' A_c; with A = Rx Ry Rz, A_rel[0, 2] = sin(theta_2)
        theta_2 = math.asin(max(-1.0, min(1.0, float(relative[0, 2]))))
        if joint.parent != GROUND and abs(theta_2) >= math.pi / 2 - margin:
            _refuse(f"initial_state.{body.name}.theta", short_repr(state["theta"].tolist()),
                    f"an orientation of '{body.name}' relative to '{parent}' with |theta_2| < pi/2 - gimbal_margin "
                    f"= {math.pi / 2 - margin:.6g}",
                    f"joint '{joint.name}' starts at its gimbal lock, theta_2 = {theta_2:.6g} rad (eq 1)",
                    source, overrides, ("initial_state", "simulation.gimbal_margin"))
        rotations.append(a_c)
        errors.append(state["position"] + a_c @ r_c - point_p)
        for array in state.values():
            array.setflags(write=False)
        states[body.name] = state
    return states, tuple(placed), errors


def _check_engine_scope(chain: Chain, resolved: Mapping, source: str | None, overrides: Sequence[str]) -> None:
    """Refuse what the chain engine does not integrate: a sliding joint's pure sign law
    (boundary_layer 0: integrated event by event for one body only)."""
    for joint in chain.joints:
        if joint.variant == "sliding" and joint.boundary_layer <= 0.0:
            _refuse(f"joints.{joint.name}.boundary_layer", "0", "a boundary layer > 0 [m] in a chain",
                    "the pure sign law is integrated event by event for one body only; tanh(E/phi) in a chain",
                    source, overrides, ("joints",))


def _refuse(key: str, found: str, expected: str, detail: str, source: str | None, overrides: Sequence[str],
            inputs: Sequence[str]) -> None:
    line = f"config key '{key}': found {found}; expected {expected} ({detail})"
    related = [o for o in overrides if any(_related(o.partition("=")[0].strip(), k) for k in inputs)]
    raise ConfigError([line + "".join(f" [from override {_short_override(o)}]" for o in related)], source)


def _check_limits(chain: Chain, states: Mapping[str, Mapping[str, np.ndarray]], errors: Sequence[np.ndarray],
                  run: ChainSchema, source: str | None, overrides: Sequence[str]) -> None:
    """ConfigError when a body's initial theta, omega, x or v, or the E_j of a joint that is
    not ``permanent``, lies outside ``simulation.limits`` (the same bounds for every body and
    joint)."""
    limits = simulation_settings(run.simulation).limits
    if limits is None:
        return
    for joint, error in zip(chain.joints, errors):
        outside = np.flatnonzero(~(np.abs(error) <= limits.constraint_error))
        if joint.variant != "permanent" and outside.size:
            i = int(outside[0])
            _refuse("simulation.limits.constraint_error", short_repr(run.simulation.limits.constraint_error),
                    "bounds that contain the initial state",
                    f"joint '{joint.name}' starts outside: |E_{i + 1}| = {abs(error[i]):.6g} m > "
                    f"{limits.constraint_error[i]:g} m", source, overrides, ("simulation.limits", "initial_state"))
    for name, bound in (("theta", limits.theta), ("omega", limits.omega), ("position", limits.position),
                        ("velocity", limits.velocity)):
        for body in chain.bodies:
            value = states[body.name][name]
            outside = np.flatnonzero(~(np.abs(value) <= bound))
            if outside.size:
                i = int(outside[0])
                _refuse(f"simulation.limits.{name}", short_repr(getattr(run.simulation.limits, name)),
                        "bounds that contain the initial state",
                        f"body '{body.name}' starts outside: |{name}_{i + 1}| = {abs(value[i]):.6g} > {bound[i]:g}",
                        source, overrides, ("simulation.limits", "initial_state"))


def _resolved(run: ChainSchema) -> dict:
    """The validated configuration as plain Python: defaults filled in, None values and the
    x, v left out to be placed omitted (so that a rebuilt config places them again)."""
    dump = run.model_dump()
    for section in ("bodies", "joints"):
        dump[section] = [{k: v for k, v in entry.items() if v is not None} for entry in dump[section]]
        for entry in dump[section]:
            if "saturation" in entry:
                entry["saturation"] = {k: v for k, v in entry["saturation"].items() if v is not None}
    states = {}
    for body in run.bodies:  # every body, in order; a state's x, v only where written
        state = run.initial_state.get(body.name)
        written = dump["initial_state"].get(body.name) or {"theta": [0.0] * 3, "omega": [0.0] * 3, "d": [0.0] * 3}
        states[body.name] = {k: v for k, v in written.items()
                             if k not in ("x", "v") or (state is not None and k in state.model_fields_set)}
    dump["initial_state"] = states
    if dump.get("disturbances") is None:
        dump.pop("disturbances", None)
    else:
        dump["disturbances"] = [{k: v for k, v in d.items() if v is not None} for d in dump["disturbances"]]
    resolved_simulation(dump["simulation"], run.simulation)
    return dump


def _notes(chain: Chain, run: ChainSchema, source: str | None) -> tuple[str, ...]:
    """Warn of each body's physical-plausibility problems (its inertia, its angles in degrees)
    and note the singular gains written (W002; a gain left out is zero by intent: a passive
    joint, no ground-anchored feedback)."""
    lines = []
    for i, (body, written) in enumerate(zip(chain.bodies, run.bodies)):  # the one-body lines, this body's keys
        lines += [m.replace(" body.inertia:", f" bodies.{i}.inertia ('{body.name}'):", 1)
                  for m in inertia_warnings(body.inertia)]
        state = run.initial_state.get(body.name)
        if state is not None:
            lines += [m.replace(" initial_state.theta:", f" initial_state.{body.name}.theta:", 1)
                      for m in angle_warnings(state.theta)]
        lines += [m.replace("controller.", f"bodies.{i}.") for m in semidefinite_notes(
            {g: getattr(written, g) for g in BODY_GAINS})]
    for i, joint in enumerate(run.joints):
        used = VARIANTS[joint.variant].required_gains
        lines += [m.replace("controller.", f"joints.{i}.") for m in semidefinite_notes(
            {g: getattr(joint, g) for g in (*JOINT_GAINS, "k_s") if g in used or g in ("k_r", "l_r")})]
    lines += unheld_bodies([b.name for b in chain.bodies], [b.mass for b in chain.bodies], [b.k_t for b in chain.bodies],
                           [(None if j.parent == GROUND else j.parent, j.child, j.variant) for j in chain.joints],
                           chain.gravity)
    for line in lines:
        category = SemiDefiniteGainWarning if line.startswith("W002") else PhysicalPlausibilityWarning
        warnings.warn(f"{source}: {line}" if source else line, category, stacklevel=4)
    return tuple(lines)


def _build(data: Any, *, default_name: str | None, source: str | None, overrides: Sequence[str] = ()) -> ChainConfig:
    if not isinstance(data, Mapping):
        what = "the configuration is empty" if data is None else f"top level: found {short_repr(data)}"
        raise ConfigError([f"{what}; expected {CHAIN_TOP_LEVEL}"], source)
    run = _validated(plain_tree(data), default_name, source, overrides, schema=ChainSchema)
    resolved = _resolved(run)
    chain = _chain(run, resolved.get("disturbances") or ())
    _check_engine_scope(chain, resolved, source, overrides)
    states, placed, errors = _initial_state(run, chain, source, overrides)
    _check_limits(chain, states, errors, run, source, overrides)
    return ChainConfig(name=run.name, chain=chain, initial_state=states, placed=placed,
                       simulation=simulation_settings(run.simulation), resolved=resolved,
                       warnings=_notes(chain, run, source))


def chain_config_from_mapping(data: Mapping, *, default_name: str | None = None,
                              source: str | None = None) -> ChainConfig:
    """Validate a chain configuration mapping (the parsed YAML) into a :class:`ChainConfig`.

    Raises
    ------
    ConfigError
        Listing every problem of the values; then, one at a time, one line for a fault of
        the tree (a parent that is not ``ground`` or an earlier body, two joints on one
        body, a body without a joint, a loop, duplicate names, more than 8 bodies), an
        unknown body name (``initial_state``, ``disturbances``), a permanent joint whose
        initial state misses its constraint (by how much), a start outside the limits.

    Warns
    -----
    PhysicalPlausibilityWarning
        For a body no real body is (inertia violating the triangle inequality), angles
        beyond one turn.
    """
    return _build(data, default_name=default_name, source=source)


def any_config_from_mapping(data: Mapping, *, default_name: str | None = None,
                            source: str | None = None) -> RunConfig | ChainConfig:
    """Validate a configuration mapping: a :class:`ChainConfig` for a chain's (``bodies``,
    :func:`chain_config_from_mapping`), else a :class:`rbstab.config.RunConfig`
    (:func:`rbstab.config.config_from_mapping`).

    Raises
    ------
    ConfigError
        As those two.
    """
    build = chain_config_from_mapping if is_chain(data) else config_from_mapping
    return build(data, default_name=default_name, source=source)


def load_any_config(path: str | Path, overrides: Sequence[str] = ()) -> RunConfig | ChainConfig:
    """Read a YAML configuration file, apply ``key.path=value`` overrides, validate it: a
    :class:`ChainConfig` for a chain (a file with ``bodies``), else what
    :func:`rbstab.config.load_config` gives.

    Raises
    ------
    ConfigError
        As :func:`rbstab.config.load_config` and :func:`chain_config_from_mapping`.
    """
    path = Path(path)
    source = str(path)
    data = read_yaml_file(path, "config file")
    if not is_chain(data):
        return load_config(path, overrides)
    try:
        data = apply_overrides(data, overrides, ChainSchema)
    except ConfigError as exc:
        raise ConfigError(exc.errors, source) from None
    return _build(data, default_name=path.stem, source=source, overrides=overrides)
