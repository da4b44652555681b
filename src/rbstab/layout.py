"""The table of quantities and the state layouts: the one place for names, symbols, units
and where each quantity lives in a state vector and in a row of outputs.

A plain-data module at the bottom of the layers (no compiled code, no rbstab import):

- :class:`Quantity` and :data:`QUANTITIES`: every quantity rbstab computes, stores or
  shows, with its symbol, CF units, long name, description and, for the outputs of the
  compiled ``outputs`` kernel, its offset in a row of outputs (:data:`OUTPUTS`, in order).
  The file metadata (:mod:`rbstab.io.metadata`), the report's tables and axis labels and
  the kernels' output offsets (:mod:`rbstab.variants.kernels`) are derived from it;
- :data:`SUMMARY_FIGURES`: the summary figures of a run (:mod:`rbstab.summary`), the same
  way, and :data:`SETTLE_E`, :data:`SETTLE_OMEGA`: the bounds of its settling time;
- :func:`is_chain`: whether a configuration is in a chain's spelling (its keys' layout);
- :class:`StateLayout`: where each state block lives in ``y`` (``split``, ``join``: blocks
  along the last axis); :data:`VARIANT_LAYOUTS`: each controller variant's layout and,
  by its order, the variant's code in the compiled kernels (:data:`VARIANT_CODES`);
- :class:`JointKind` and :data:`JOINT_KINDS`: the joint-kind table (a joint's coordinates
  in a tree's reduced state; :data:`JOINT_KIND_OF` each variant's kind).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = [
    "is_index",
    "is_chain",
    "Quantity",
    "QUANTITIES",
    "OUTPUTS",
    "SUMMARY_FIGURES",
    "SETTLE_E",
    "SETTLE_OMEGA",
    "SIGN_LAW_FIGURES",
    "STATE_BLOCKS",
    "BLOCK_UNITS",
    "LYAPUNOV_TERMS",
    "SATURATION_FLAGS",
    "OUTPUT_VECTORS",
    "OUTPUT_SCALARS",
    "N_OUTPUTS",
    "LEFT_OUT",
    "SUMMARY_MAX_SAMPLES",
    "summary_stride",
    "display_units",
    "CONFIG_QUANTITIES",
    "LIMITED",
    "LIMITED_COMPONENTS",
    "parameter_attributes",
    "slide_parts",
    "StateLayout",
    "FULL_BODY",
    "EMBEDDED",
    "REDUCED",
    "VARIANT_LAYOUTS",
    "VARIANT_CODES",
    "STATE_SIZE",
    "JointKind",
    "JOINT_KINDS",
    "JOINT_KIND_OF",
    "joint_kind",
    "JOINT_CODES",
    "REDUCED_STATES",
    "VELOCITIES",
    "AXES",
    "BEYOND_PAPER",
    "POINT_FIXED",
    "point_fixed",
]


def display_units(units: str | None) -> str:
    """CF/UDUNITS units as they read on an axis or in a table: a factor with exponent -1
    goes under a slash (``"rad s-1"`` -> ``"rad/s"``, ``"s-1"`` -> ``"1/s"``); others as
    they are (``"N m"``, ``"1"``); ``""`` for None (no units)."""
    if not units:
        return ""
    factors = units.split()
    under = [f[:-2] for f in factors if re.fullmatch(r"[A-Za-z]+-1", f)]
    if not under:
        return units
    over = [f for f in factors if not re.fullmatch(r"[A-Za-z]+-1", f)]
    return f"{' '.join(over) or '1'}/{' '.join(under)}"


@dataclass(frozen=True)
class Quantity:
    """One quantity rbstab computes, stores or shows (a row of the table).

    Attributes
    ----------
    name : str
        Its name in the outputs, the files (variable or summary figure) and the reports.
    symbol : str
        Plain-text symbol (``"Theta"``, ``"dv/dt"``), as tables and messages write it.
    units : str or None
        CF/UDUNITS units (``"rad s-1"``), the files' ``units`` attribute; ``"1"``
        dimensionless; None: none (text, a coordinate of components).
    long_name : str
        CF ``long_name``: what it is, in a few words.
    description : str
        Its formula and the paper's equation (the files' ``description`` attribute).
    tex : str
        Mathtext symbol of a figure (``r"\\Theta"``); ``component_tex`` that of its
        components where it differs (``r"\\theta"``: theta_1, theta_2, theta_3).
    words : str
        The words a figure's axis says beside the symbol (``"Euler angles"``).
    size : int
        Components: 3 for a vector (inertial or body frame, as ``long_name`` says), 1
        for a scalar.
    offset : int or None
        First column in a row of outputs of the compiled ``outputs`` kernel
        (:data:`OUTPUTS`); None for a quantity that is not one of those outputs.
    member : {"body", "joint"} or None
        Where a tree of several bodies has one value of it per body or per joint (its
        files' ``body`` or ``joint`` dimension, a summary figure's ``<name>_<member>``
        columns); None: one value for the whole tree (v and its terms, the time).
    """

    name: str
    symbol: str
    units: str | None
    long_name: str
    description: str = ""
    tex: str = ""
    words: str = ""
    size: int = 1
    component_tex: str = ""
    offset: int | None = None
    member: str | None = None

    @property
    def display_units(self) -> str:
        """:attr:`units` as a table or an axis writes them (:func:`display_units`)."""
        return display_units(self.units)

    @property
    def columns(self) -> slice:
        """Its columns in a row of outputs: ``slice(offset, offset + size)``.

        Raises
        ------
        ValueError
            If it is not an output of the ``outputs`` kernel (:attr:`offset` None).
        """
        if self.offset is None:
            raise ValueError(f"{self.name!r} is not an output of the outputs kernel")
        return slice(self.offset, self.offset + self.size)


def _in_order(quantities: tuple[Quantity, ...]) -> tuple[Quantity, ...]:
    """The quantities with their offsets: each after the previous one's columns."""
    out, offset = [], 0
    for q in quantities:
        out.append(replace(q, offset=offset))
        offset += q.size
    return tuple(out)


# -- the config keys a sweep varies (its parameters) ---------------------------------------------
#: Every numeric config key a sweep or a study can vary, by dotted key: its symbol, CF units
#: and long name (the parameter coordinates of :func:`rbstab.open_sweep` carry them).
CONFIG_QUANTITIES: dict[str, Quantity] = {q.name: q for q in (
    Quantity("body.mass", "m", "kg", "mass m of the body"),
    Quantity("body.inertia", "J", "kg m2", "inertia J about the centre of mass (body frame)"),
    Quantity("body.attachment_point", "R", "m", "attachment point R of C (body frame)"),
    Quantity("body.gravity", "g", "m s-2", "gravitational acceleration g (inertial frame)"),
    Quantity("controller.k_t", "K_t", "N m-1", "translational stiffness K_t"),
    Quantity("controller.l_t", "L_t", "N s m-1", "translational damping L_t"),
    Quantity("controller.k_r", "K_r", "N m rad-1", "rotational stiffness K_r"),
    Quantity("controller.l_r", "L_r", "N m s rad-1", "rotational damping L_r"),
    Quantity("controller.k_c", "K_c", "N m-1", "constraint stiffness K_c"),
    Quantity("controller.l_c", "L_c", "N s m-1", "constraint damping L_c"),
    Quantity("controller.k_d", "K_d", "N m-1", "embedded controller stiffness K_d"),
    Quantity("controller.l_d", "L_d", "N s m-1", "embedded controller damping L_d"),
    Quantity("controller.k_s", "K_s", "N", "sign-law force bound K_s"),
    Quantity("controller.boundary_layer", "eps", "m", "boundary layer of the sign law"),
    Quantity("initial_state.theta", "Theta(0)", "rad", "initial Euler angles Theta(0)"),
    Quantity("initial_state.omega", "Omega(0)", "rad s-1", "initial angular velocity Omega(0) (body frame)"),
    Quantity("initial_state.x", "X(0)", "m", "initial centre-of-mass position X(0)"),
    Quantity("initial_state.v", "V(0)", "m s-1", "initial centre-of-mass velocity V(0)"),
    Quantity("initial_state.d", "D(0)", "m", "initial embedded controller state D(0)"),
    Quantity("simulation.t_end", "t_end", "s", "end time of the simulation"),
    Quantity("simulation.n_samples", "n", "1", "number of output samples"),
    Quantity("simulation.rtol", "rtol", "1", "relative tolerance of the solver"),
    Quantity("simulation.atol", "atol", "1", "absolute tolerance of the solver"),
    Quantity("simulation.max_step", "h_max", "s", "largest step of the solver"),
    Quantity("simulation.gimbal_margin", "margin", "rad", "gimbal-lock margin"),
    Quantity("simulation.max_steps", "steps", "1", "most steps of a run"),
    Quantity("simulation.max_wall_time", "t_wall", "s", "wall-time limit of a run"),
    Quantity("simulation.limits.theta", "|theta|max", "rad", "bound of |theta_i| (admissible region)"),
    Quantity("simulation.limits.omega", "|Omega|max", "rad s-1", "bound of |Omega_i| (admissible region)"),
    Quantity("simulation.limits.position", "|X|max", "m", "bound of |X_i| (admissible region)"),
    Quantity("simulation.limits.velocity", "|V|max", "m s-1", "bound of |V_i| (admissible region)"),
    Quantity("simulation.limits.constraint_error", "|E|max", "m", "bound of |E_i| (admissible region)"),
)}

#: The outputs whose components ``simulation.limits`` bounds (|q_i| <= bound), by the
#: config key under ``simulation.limits``, in the order of the rows of the ``limits`` field
#: of :data:`rbstab.model.PARAMETERS` and of the status codes of
#: :mod:`rbstab.engine.status`: Euler angles [rad], Omega [rad/s] (body frame), X [m] and V
#: [m/s] (inertial frame), E [m] (inertial frame).
LIMITED = ("theta", "omega", "position", "velocity", "constraint_error")
#: How a message writes component i of each of :data:`LIMITED` (1-based: ``theta_2``,
#: ``Omega_1``, ``X_3``, as the paper's theta_2).
LIMITED_COMPONENTS = {"theta": "theta", "omega": "Omega", "position": "X", "velocity": "V", "constraint_error": "E"}


def is_index(part: str) -> bool:
    """Whether a segment of a dotted config key is a list index: ASCII digits, no sign, no
    leading zero (``str.isdigit`` also takes '²' and '١', which ``int`` refuses or reads as
    another number). The grammar of keys: :func:`rbstab.config.paths.parse_key`."""
    return part.isascii() and part.isdigit() and (part == "0" or not part.startswith("0"))


def is_chain(data: Any) -> bool:
    """Whether a configuration is in a chain's spelling (``bodies`` and ``joints`` instead of
    ``body`` and ``controller``): a mapping with ``bodies`` and no ``body``, or a validated
    configuration (:class:`rbstab.config.RunConfig`) of such a mapping. The one test of a
    configuration's spelling: the model is the same (a one-body config is its one-body tree,
    :func:`rbstab.config.loader.tree_resolved`)."""
    data = getattr(data, "resolved", data)
    return isinstance(data, Mapping) and "bodies" in data and "body" not in data


#: A chain's keys as the one-body keys of the same quantity (or a quantity of their own):
#: ``<section>.<name>.<field>`` by section and field (``bodies.trunk.mass`` is a
#: ``body.mass``), and its ``gravity``.
_CHAIN_KEYS = {
    "bodies": {"mass": "body.mass", "inertia": "body.inertia", "k_t": "controller.k_t", "l_t": "controller.l_t"},
    "joints": {"parent_point": Quantity("joints.parent_point", "R_p", "m",
                                        "joint point R_p on the parent (its body frame; inertial for the ground)"),
               "child_point": Quantity("joints.child_point", "R_c", "m", "joint point R_c of C on the child (body frame)"),
               "theta_ref": Quantity("joints.theta_ref", "Theta_ref", "rad",
                                     "reference posture Theta_ref of a joint (relative Euler angles)"),
               "axis": Quantity("joints.axis", "a", "1", "axis a of a hinge (the parent's and the child's frames)"),
               **{g: f"controller.{g}" for g in ("k_r", "l_r", "k_c", "l_c", "k_d", "l_d", "k_s", "boundary_layer")}},
    "initial_state": {**{b: f"initial_state.{b}" for b in ("theta", "omega", "x", "v", "d")},
                      "q": Quantity("initial_state.q", "q(0)", "rad", "initial angle q(0) of a hinge or universal joint"),
                      "u": Quantity("initial_state.u", "u(0)", "rad s-1",
                                    "initial rate u(0) of a hinge or universal joint")},
}


#: A slide's numbers, written as a hinge's keys, in its own units (``joints.<name>.<key>``,
#: ``initial_state.<child>.<q|u>``).
_SLIDE_KEYS = {
    "k_r": Quantity("joints.k_r", "k", "N m-1", "stiffness k of a slide along its axis"),
    "l_r": Quantity("joints.l_r", "l", "N s m-1", "damping l of a slide along its axis"),
    "theta_ref": Quantity("joints.theta_ref", "q_ref", "m", "reference displacement q_ref of a slide"),
    "saturation.torque_n": Quantity("joints.saturation.torque_n", "f_max", "N", "upper force limit of a slide"),
    "saturation.torque_n_lower": Quantity("joints.saturation.torque_n_lower", "f_min", "N",
                                          "lower force limit of a slide"),
    "range.lower": Quantity("joints.range.lower", "q_min", "m", "lower end of a slide's range"),
    "range.upper": Quantity("joints.range.upper", "q_max", "m", "upper end of a slide's range"),
    "range.k_r": Quantity("joints.range.k_r", "K_stop", "N m-1", "stiffness of a slide's stop beyond its range"),
    "range.l_r": Quantity("joints.range.l_r", "L_stop", "N s m-1", "damping of a slide's stop beyond its range"),
    "q": Quantity("initial_state.q", "q(0)", "m", "initial displacement q(0) of a slide"),
    "u": Quantity("initial_state.u", "u(0)", "m s-1", "initial rate u(0) of a slide"),
}


def slide_parts(config: Any) -> frozenset[str]:
    """The names of a configuration's slides and of their children (a chain's resolved or
    written mapping, ``joints`` a list of mappings; a sweep spec's: its bases'; empty for any
    other): the parts whose keys :func:`parameter_attributes` gives a slide's units."""
    if isinstance(config, Mapping) and "base" in config:
        bases = config["base"]
        return frozenset().union(*(slide_parts(b) for b in (bases if isinstance(bases, list) else [bases])))
    joints = config.get("joints") if isinstance(config, Mapping) else None
    if not isinstance(joints, list):
        return frozenset()
    return frozenset(name for j in joints if isinstance(j, Mapping) and j.get("variant") == "slide"
                     for name in (j.get("name"), j.get("child")) if isinstance(name, str))


#: A joint's range keys (``joints.<name>.range.<field>``, a hinge's q or a ball's Euler
#: angles): its ends and its stop's gains.
_RANGE_KEYS = {
    "lower": Quantity("joints.range.lower", "q_min", "rad", "lower end of a joint's range"),
    "upper": Quantity("joints.range.upper", "q_max", "rad", "upper end of a joint's range"),
    "k_r": Quantity("joints.range.k_r", "K_stop", "N m rad-1", "stiffness of a joint's stop beyond its range"),
    "l_r": Quantity("joints.range.l_r", "L_stop", "N m s rad-1", "damping of a joint's stop beyond its range"),
}


def _config_quantity(config_key: str, slides: frozenset[str] = frozenset()) -> tuple[Quantity | None, str]:
    """(the :data:`CONFIG_QUANTITIES` row of a config key without indices, one body's or a
    chain's (:data:`_CHAIN_KEYS`; a slide's own where its joint or child is in ``slides``),
    or None; what the long name adds: `` (body trunk)``)."""
    if config_key in CONFIG_QUANTITIES:
        return CONFIG_QUANTITIES[config_key], ""
    if config_key == "gravity":
        return CONFIG_QUANTITIES["body.gravity"], ""
    parts = config_key.split(".")
    if len(parts) >= 3 and parts[1] in slides and ".".join(parts[2:]) in _SLIDE_KEYS:
        return _SLIDE_KEYS[".".join(parts[2:])], f" ({'joint' if parts[0] == 'joints' else 'body'} {parts[1]})"
    if len(parts) == 4 and parts[1] in slides and parts[2] == "passive" and parts[3] in _SLIDE_KEYS:
        return _SLIDE_KEYS[parts[3]], f" (joint {parts[1]}, passive)"
    passive = len(parts) == 4 and parts[0] == "joints" and parts[2] == "passive"  # a joint's passive torque
    if passive and parts[3] in ("k_r", "l_r", "theta_ref"):
        q = _CHAIN_KEYS["joints"][parts[3]]
        q = q if isinstance(q, Quantity) else CONFIG_QUANTITIES[q]
        return q, f" (joint {parts[1]}, passive)"
    if len(parts) == 4 and parts[0] == "joints" and parts[2] == "range" and parts[3] in _RANGE_KEYS:
        return _RANGE_KEYS[parts[3]], f" (joint {parts[1]})"
    if len(parts) == 3 and parts[2] in _CHAIN_KEYS.get(parts[0], {}):
        kind = "joint" if parts[0] == "joints" else "body"
        q = _CHAIN_KEYS[parts[0]][parts[2]]
        return (q if isinstance(q, Quantity) else CONFIG_QUANTITIES[q]), f" ({kind} {parts[1]})"
    return None, ""


def parameter_attributes(entry: str, slides: frozenset[str] = frozenset()) -> dict[str, str]:
    """``units``, ``long_name`` and ``config_key`` (the entry itself, as a store file's
    coordinates give it) of a sweep parameter, from its dotted entry (``controller.k_c.2``,
    ``body.mass:scale``, ``body.inertia.0.0``): the config key's row of
    :data:`CONFIG_QUANTITIES`, the entry's indices in the long name (``constraint stiffness
    K_c [2]``); a scale factor is dimensionless (``"1"``). A key not in the table has no
    units, its key as long name. ``slides``: the names of the slides and their children
    (:func:`slide_parts`), whose numbers have a slide's units (N/m, m, N) under a hinge's keys."""
    scale = entry.endswith(":scale")
    key = entry.removesuffix(":scale")
    parts = key.split(".")
    indices = []
    while parts and is_index(parts[-1]):
        indices.insert(0, parts.pop())
    config_key = ".".join(parts)
    q, whose = _config_quantity(config_key, slides)
    long_name = (q.long_name + whose if q is not None else config_key) + (f" [{', '.join(indices)}]" if indices else "")
    attrs = {"long_name": f"scale factor of the {long_name}" if scale else long_name, "config_key": entry}
    units = "1" if scale else (q.units if q is not None else None)
    if units:
        attrs["units"] = units
    return attrs


# -- the outputs of a run, in the order of a row of the outputs kernel -------------------------
#: The outputs of the compiled ``outputs`` kernel (:mod:`rbstab.variants.kernels`), in the
#: order of a row of outputs: the state blocks, the constraint and feedback vectors, the
#: flags of the controls' axes at their limits (:data:`SATURATION_FLAGS`), then
#: the terms of v in the order they are summed, v and dv/dt.
OUTPUTS: dict[str, Quantity] = {q.name: q for q in _in_order((
    Quantity("theta", "Theta", "rad", "Euler angles Theta",
             "Euler angles Theta, A = Rx(t1) Ry(t2) Rz(t3) (eq 2)",
             r"\Theta", "Euler angles", 3, r"\theta", member="body"),
    Quantity("omega", "Omega", "rad s-1", "angular velocity Omega (body frame)",
             "angular velocity Omega in the body frame (eq 1)", r"\Omega", "angular velocity", 3, member="body"),
    Quantity("position", "X", "m", "centre-of-mass position X (inertial frame)",
             "centre-of-mass position X in the inertial frame (eq 1)", "X", "COM position", 3, member="body"),
    Quantity("velocity", "V", "m s-1", "centre-of-mass velocity V (inertial frame)",
             "centre-of-mass velocity V in the inertial frame (eq 1)", "V", "COM velocity", 3, member="body"),
    Quantity("controller_state", "D", "m", "embedded controller state D (inertial frame)",
             "embedded controller state D in the inertial frame (eq 22)", "D", "controller state", 3, member="joint"),
    Quantity("constraint_error", "E", "m", "constraint error E (inertial frame)",
             "E = X + A R - R, displacement of the point C, inertial frame (eq 4)", "E", "constraint error", 3,
             member="joint"),
    Quantity("constraint_rate", "F", "m s-1", "constraint error rate F = dE/dt (inertial frame)",
             "F = dE/dt = V - A hat(R) Omega, velocity of C, inertial frame (eq 4)", "F", "constraint rate", 3,
             member="joint"),
    Quantity("constraint_force", "Lambda", "N", "constraint force Lambda at C (inertial frame)",
             "Lambda, force applied at C, inertial frame (eqs 20, 22, 39, 40)", r"\Lambda", "constraint force", 3,
             member="joint"),
    Quantity("force_h", "H", "N", "translational feedback force H (inertial frame)",
             "H = -K_t X - L_t V, translational feedback, inertial frame (eq 24)", "H", "feedback force", 3,
             member="body"),
    Quantity("torque_n", "N", "N m", "rotational feedback torque N (body frame)",
             "N = -B' K_r Theta - L_r Omega, rotational feedback, body frame (eq 23; a chain's joint: "
             "-B(Theta_j)' K_r (Theta_j - Theta_ref) - L_r Omega_j through its limits plus its passive torque, child "
             "frame)", "N", "feedback torque", 3,
             member="joint"),
    Quantity("torque_n_saturated", "N saturated", "1", "N_i at or beyond its limit, 1 or 0 (body frame)",
             "1 where the commanded N_i (eq 23) is at or beyond its limit, |N_i| >= controller.saturation.torque_n_i "
             "(clip: N_i is the limit; smooth: at least tanh(1) of it); 0 elsewhere and without limits",
             r"N_{sat}", "torque N saturated", 3, member="joint"),
    Quantity("force_h_saturated", "H saturated", "1", "H_i at or beyond its limit, 1 or 0 (inertial frame)",
             "1 where the commanded H_i (eq 24) is at or beyond its limit, |H_i| >= controller.saturation.force_h_i "
             "(clip: H_i is the limit; smooth: at least tanh(1) of it); 0 elsewhere and without limits",
             r"H_{sat}", "force H saturated", 3, member="body"),
    Quantity("constraint_force_saturated", "Lambda saturated", "1",
             "Lambda_i at or beyond its limit, 1 or 0 (inertial frame)",
             "1 where the commanded Lambda_i (eqs 22, 39, 40) is at or beyond its limit, |Lambda_i| >= "
             "controller.saturation.constraint_force_i (clip: Lambda_i is the limit; smooth: at least tanh(1) of "
             "it); 0 elsewhere, without limits and for permanent's pin", r"\Lambda_{sat}", "constraint force saturated", 3,
             member="joint"),
    Quantity("lyapunov_translational", "v_t", "J", "translational term v_t of the Lyapunov function",
             "v_t = V'MV/2 + X'K_t X/2 (eq 25; a chain's: summed over its bodies)", "v_t", "translational"),
    Quantity("lyapunov_rotational", "v_r", "J", "rotational term v_r of the Lyapunov function",
             "v_r = Omega'J Omega/2 + Theta'K_r Theta/2 (eq 25; a chain's: Omega_i'J_i Omega_i/2 summed over "
             "its bodies and dTheta_j'K_r dTheta_j/2 over its joints, dTheta_j = Theta_j - Theta_ref the relative "
             "angles from the joint's reference posture, and its passive spring's term of that form)", "v_r",
             "rotational"),
    Quantity("lyapunov_constraint", "v_c", "J", "constraint controller term of the Lyapunov function",
             "energy stored in the constraint controller (eqs 41, 44; "
             "K_s |E|_1 or its boundary-layer smoothing for sliding; 0 for free and permanent; a chain's: summed "
             "over its joints)",
             "v_c", "constraint controller"),
    Quantity("lyapunov_gravity", "v_g", "J", "gravity term of the Lyapunov function",
             "-X'G plus the constant h that makes v zero at the equilibrium (eq 30)", "v_g", "gravity"),
    Quantity("lyapunov", "v", "J", "Lyapunov function v",
             "Lyapunov function v, the sum of the lyapunov_* terms (eqs 28-46)", "v", "Lyapunov function"),
    Quantity("lyapunov_rate", "dv/dt", "W", "analytic rate dv/dt of the Lyapunov function",
             "analytic dv/dt (eqs 29, 37, 43, 46)", r"\dot v", "Lyapunov rate"),
    Quantity("disturbance_power", "P_d", "W", "power of the disturbances",
             "P_d = F'V + Omega'T, F the disturbances' force (inertial frame), T their torque about the "
             "centre of mass (body frame; eq 26)", "P_d", "disturbance power"),
    Quantity("disturbance_work", "W", "J", "work of the disturbances",
             "W = integral of P_d dt plus each impulse's jump of kinetic energy (eqs 26-28)",
             "W", "disturbance work"),
    Quantity("disturbance_edges", "edges", "1", "disturbance edges at or before the sample",
             "number of the disturbances' edges (each start, impulses included, and each pulse's end) at or "
             "before the sample time: v or dv/dt may jump between samples where it changes, so the rate check "
             "compares the numerical dv/dt only on stencils where it does not", "n_e", "disturbance edges"),
))}

#: Every quantity a run or store file holds as a variable (:data:`OUTPUTS` and the rest).
QUANTITIES: dict[str, Quantity] = {q.name: q for q in (
    Quantity("time", "t", "s", "time", "sample time, evenly spaced dense output of the solver", "t", "time"),
    Quantity("axis", "axis", None, "vector component", "vector component; frame given by each variable"),
    Quantity("run", "run", "1", "position of the run in the sweep's run list",
             "index of the run in the sweep's run list (increasing within a store file)"),
    *OUTPUTS.values(),
    Quantity("body", "body", None, "body of a chain", "name of the body (a chain's file: its bodies in order)"),
    Quantity("joint", "joint", None, "joint of a chain",
             "name of the joint (a chain's file: joint j holds body j to its parent)"),
    Quantity("joint_theta", "Theta_j", "rad", "relative Euler angles Theta_j of a joint",
             "Euler angles of A_rel = A_parent' A_child (the ground's: the child's Theta) (docs/physics.md, chains)",
             r"\Theta_j", "joint angles", 3, member="joint"),
    Quantity("joint_omega", "Omega_j", "rad s-1", "relative angular velocity Omega_j of a joint (child frame)",
             "Omega_j = Omega_child - A_rel' Omega_parent, child frame (docs/physics.md, chains)",
             r"\Omega_j", "joint angular velocity", 3, member="joint"),
    Quantity("com_position", "X_com", "m", "whole-body centre of mass (inertial frame)",
             "X_com = sum m_i X_i / sum m_i over a tree's bodies, inertial frame", r"X_{com}", "whole-body COM", 3),
    Quantity("com_velocity", "V_com", "m s-1", "velocity of the whole-body centre of mass (inertial frame)",
             "V_com = sum m_i V_i / sum m_i over a tree's bodies, inertial frame", r"V_{com}",
             "whole-body COM velocity", 3),
    Quantity("centre_of_pressure", "P_cop", "m", "centre of pressure of a joint to the ground (inertial frame)",
             "the point of the ground plane (through the origin, perpendicular to gravity) about which the ground's "
             "force Lambda_j and moment on the bodies the joint carries have no moment along the plane: "
             "P = C - (Lambda h - n x M) / (n . Lambda), n the plane's upward normal, h the height of the joint's "
             "point C, M the moment about C (docs/physics.md); NaN for other joints, without gravity, or where "
             "the ground does not push up", r"P_{cop}", "centre of pressure", 3, member="joint"),
    Quantity("net_centre_of_pressure", "P_net", "m",
             "net centre of pressure of the joints to the ground (inertial frame)",
             "the centre of pressure of the point-fixed joints to the ground together (their forces and moments "
             "summed, as one force plate under both feet reads them): P = n x M_O / (n . F), F the summed force, "
             "M_O the summed moment about the origin, n the ground plane's upward normal (docs/physics.md); "
             "for one such joint its centre_of_pressure; NaN without one, without gravity, or where the ground "
             "does not push up", r"P_{net}", "net centre of pressure", 3),
    Quantity("lyapunov_rate_numerical", "dv/dt", "W", "numerical derivative dv/dt of the sampled Lyapunov function",
             "dv/dt by differentiating v along the dense-output samples "
             "(7-point finite differences; for the pure sign law on each smooth piece between switchings); "
             "compare with lyapunov_rate", r"\dot v", "Lyapunov rate"),
    Quantity("sliding_mode", "sigma", "1", "sign-law mode sigma of each component of E",
             "pure sign law: sigma standing for sgn(E) on the sample's piece, +-1 the side of E_i = 0, "
             "0 where C slides on it (equivalent force)", r"\sigma", "sign-law mode", 3),
    Quantity("switching", "switching", "1", "switching event number",
             "number of the located event of the pure sign law, in time order"),
    Quantity("switching_time", "t", "s", "time of the switching event",
             "time of the event, located to the solver's resolution"),
    Quantity("switching_axis", "i", "1", "component of E that switched",
             "component i of E (0, 1, 2: inertial x, y, z)"),
    Quantity("switching_kind", "kind", "1", "kind of switching event",
             "0 crossing of E_i = 0, 1 sliding on it starts, 2 sliding ends"),
    Quantity("switching_constraint_rate", "F_i", "m s-1", "constraint error rate F_i at the switching event",
             "F_i at the event (before the impulse of a sliding start)"),
)}

#: The state blocks (3-vectors) a layout may hold, in the order of the outputs.
STATE_BLOCKS = ("theta", "omega", "position", "velocity", "controller_state")
#: Units of each state block (CF spelling; the files' ``units`` attribute).
BLOCK_UNITS = {**{b: OUTPUTS[b].units for b in STATE_BLOCKS},  # and the joints' blocks of a tree's reduced state
               "joint_theta": "rad", "joint_omega": "rad s-1", "q": "rad", "u": "rad s-1", "quaternion": "1",
               "joint_phi": "rad", "translation": "m", "translation_rate": "m s-1"}
#: The controls an actuator delivers (:class:`rbstab.model.Saturation`'s limits) -> the output
#: that flags their axes at or beyond the limit and the summary figure of the fraction of the
#: samples so flagged.
SATURATION_FLAGS = {control: (f"{control}_saturated", f"fraction_saturated_{control}")
                    for control in ("torque_n", "force_h", "constraint_force")}
#: Names of the terms of v, in the order they are summed.
LYAPUNOV_TERMS = ("lyapunov_translational", "lyapunov_rotational", "lyapunov_constraint", "lyapunov_gravity")
#: The vector outputs (3 columns each), in order.
OUTPUT_VECTORS = tuple(q.name for q in OUTPUTS.values() if q.size == 3)
#: The scalar outputs after the vectors, one column each, in order.
OUTPUT_SCALARS = tuple(q.name for q in OUTPUTS.values() if q.size == 1)
#: Columns of one row of outputs.
N_OUTPUTS = sum(q.size for q in OUTPUTS.values())
#: The outputs that neither the summary figures nor a ``thinned`` store read: left out of
#: the outputs of a sweep that stores no more (``full`` False in
#: :func:`rbstab.variants.kernels.run_outputs`; a pinned body's Lambda and N are computed
#: and written still: its centre of pressure reads them).
LEFT_OUT = ("constraint_rate", "constraint_force", "force_h", "torque_n")
#: Most samples a ``thinned`` trace keeps (a thinned store, :mod:`rbstab.io.chunk`).
SUMMARY_MAX_SAMPLES = 201


def summary_stride(n_samples: int) -> int:
    """Sample stride of a ``thinned`` trace: it keeps ``time[::stride]``, at most
    :data:`SUMMARY_MAX_SAMPLES` samples (for 2001 samples, every 10th: t = 0, 0.01, ... 2 s)."""
    return max(1, -(-(int(n_samples) - 1) // (SUMMARY_MAX_SAMPLES - 1)))


# -- the summary figures of a run (rbstab.summary computes them) --------------------------------
#: Thresholds of the summary figure ``settling_time`` (:func:`rbstab.summary.settling_times`):
#: on |E| [m], the Euclidean norm of each joint's constraint error, and on |Omega| [rad/s],
#: that of each body's angular velocity (also ``rbstab report``'s defaults, ``--settle-e``,
#: ``--settle-omega``).
SETTLE_E = 0.005
SETTLE_OMEGA = 0.05


def _final(block: str, long_name: str) -> Quantity:
    """The summary figure ``final_<block>``: the state block at the last finite sample."""
    q = OUTPUTS[block]
    return Quantity(f"final_{block}", f"final {q.symbol}", q.units, long_name, size=3, member=q.member)


#: The summary figures (:func:`rbstab.summary.summarize` and, for runs of the pure sign law,
#: :func:`rbstab.engine.switching.switching_summary`), in the order files list them; units
#: None: a text figure. A run file holds them as ``summary_<name>`` attributes, a store
#: file as variables along ``run`` (3-vectors as ``<name>_x``, ``_y``, ``_z``).
SUMMARY_FIGURES: dict[str, Quantity] = {q.name: q for q in (
    Quantity("t_final", "t_final", "s", "time of the last finite sample"),
    _final("theta", "Euler angles Theta at t_final"),
    _final("omega", "angular velocity Omega at t_final (body frame)"),
    _final("position", "position X of C at t_final"),
    _final("velocity", "velocity V of C at t_final"),
    _final("controller_state", "controller state D at t_final"),
    Quantity("max_abs_constraint_error", "max |E|", "m", "max |E_i| over the samples", size=3, member="joint"),
    Quantity("lyapunov_initial", "v(0)", "J", "v(0)"),
    Quantity("lyapunov_final", "v(t_end)", "J", "v(t_end)"),
    Quantity("max_lyapunov_rate", "max dv/dt", "W", "max dv/dt"),
    Quantity("max_lyapunov_increase", "max rise of v", "J", "largest rise of v above its running minimum"),
    Quantity("time_lyapunov_rising", "time with dv/dt > 0", "s",
             "time with analytic dv/dt > 0 (samples times their spacing)"),
    Quantity("settling_time", "settling time", "s",
             f"first sample time from which every |E_j| <= {SETTLE_E:g} m and every |Omega_i| <= {SETTLE_OMEGA:g} "
             "rad/s until t_end (NaN: not settled at t_end, or stopped early)"),
    Quantity("com_excursion", "COM excursion", "m",
             "largest distance of the whole-body centre of mass from its initial position"),
    Quantity("peak_sway", "peak sway", "m",
             "largest horizontal distance (perpendicular to gravity) of the whole-body centre of mass from its "
             "initial position (NaN without gravity)"),
    Quantity("cop_excursion", "CoP excursion", "m",
             "largest distance of the net centre of pressure of the joints to the ground from its initial position "
             "(NaN: no point-fixed joint to the ground, no gravity, or the ground does not push up at a sample)"),
    Quantity("fraction_saturated_torque_n", "fraction of time N_i saturated", "1",
             "fraction of the samples with N_i commanded at or beyond its limit (body frame)", size=3, member="joint"),
    Quantity("fraction_saturated_force_h", "fraction of time H_i saturated", "1",
             "fraction of the samples with H_i commanded at or beyond its limit (inertial frame)", size=3,
             member="body"),
    Quantity("fraction_saturated_constraint_force", "fraction of time Lambda_i saturated", "1",
             "fraction of the samples with Lambda_i commanded at or beyond its limit (inertial frame)", size=3,
             member="joint"),
    Quantity("lyapunov_rate_mismatch", "max |dv/dt analytic - numerical|", "W", "max |analytic - numerical dv/dt|"),
    Quantity("lyapunov_rate_mismatch_relative", "relative dv/dt mismatch", "1",
             "max |analytic - numerical dv/dt| / max |analytic dv/dt|"),
    Quantity("lyapunov_rate_check", "rate check", None,
             "pass, fail or n/a: analytic dv/dt agrees with the numerical derivative"),
    Quantity("lyapunov_rate_checked", "fraction of samples rate-checked", "1",
             "fraction of the samples the rate check compares (pure sign law: on one smooth piece)"),
    # runs of the pure sign law of sliding (its joint's E_i)
    Quantity("switching_count", "crossings of E_i = 0", "1", "crossings of E_i = 0 located", size=3, member="joint"),
    Quantity("sliding_time", "sliding time", "s", "time C slid on E_i = 0 (equivalent force)", size=3,
             member="joint"),
    Quantity("sliding_starts", "sliding starts", "1", "times sliding on E_i = 0 started", size=3, member="joint"),
    Quantity("min_switching_interval", "shortest interval between crossings", "s",
             "shortest time between two crossings of E_i = 0", size=3, member="joint"),
    Quantity("chattering", "chattering (total variation of Lambda_i)", "N s-1",
             "total variation of Lambda_i from its jumps, per second", size=3, member="joint"),
    Quantity("switching_resolution", "switching resolution", "m",
             "switching resolution: excursions smaller than this start sliding"),
)}
#: The figures of the pure sign law's runs alone (:func:`rbstab.engine.switching.switching_summary`).
SIGN_LAW_FIGURES = ("switching_count", "sliding_time", "sliding_starts", "min_switching_interval", "chattering",
                    "switching_resolution")


@dataclass(frozen=True)
class StateLayout:
    """Ordered 3-vector blocks of a state vector.

    Parameters
    ----------
    blocks : tuple of str
        Block names, each one of :data:`STATE_BLOCKS`.
    """

    blocks: tuple[str, ...]

    def __post_init__(self) -> None:
        unknown = [b for b in self.blocks if b not in STATE_BLOCKS]
        if unknown:
            raise ValueError(f"unknown state blocks {unknown}")

    @property
    def size(self) -> int:
        """Number of scalar states."""
        return 3 * len(self.blocks)

    def slice(self, block: str) -> slice:
        """Slice of ``block`` in the last axis of a state array."""
        i = self.blocks.index(block)
        return slice(3 * i, 3 * i + 3)

    def split(self, y: np.ndarray) -> dict[str, np.ndarray]:
        """Views of each block: y shape (..., size) -> {name: shape (..., 3)}."""
        return {b: y[..., 3 * i : 3 * i + 3] for i, b in enumerate(self.blocks)}

    def join(self, **blocks: np.ndarray) -> np.ndarray:
        """Concatenate blocks (each shape (..., 3)) into shape (..., size), in layout order.

        Raises
        ------
        KeyError
            If a block of the layout is missing.
        """
        return np.concatenate([np.asarray(blocks[b], dtype=float) for b in self.blocks], axis=-1)

    def state_names(self) -> list[str]:
        """Scalar state names such as ``theta_1`` ... in layout order."""
        return [f"{b}_{k}" for b in self.blocks for k in (1, 2, 3)]

    def state_units(self) -> list[str]:
        """The units of each scalar state (:data:`BLOCK_UNITS`), in layout order."""
        return [BLOCK_UNITS[b] for b in self.blocks for _ in range(3)]


FULL_BODY = StateLayout(("theta", "omega", "position", "velocity"))
EMBEDDED = StateLayout(("theta", "omega", "position", "velocity", "controller_state"))
REDUCED = StateLayout(("theta", "omega"))

#: Each controller variant (the config value ``controller.variant``) and the layout of its
#: state; a variant's code in the compiled kernels is its position here (:data:`VARIANT_CODES`).
VARIANT_LAYOUTS = {
    "free": FULL_BODY,
    "permanent": REDUCED,
    "sliding": FULL_BODY,
    "visco_elastic": FULL_BODY,
    "embedded": EMBEDDED,
}
#: Variant name -> its code in the compiled kernels (:mod:`rbstab.variants.kernels`).
VARIANT_CODES = {name: code for code, name in enumerate(VARIANT_LAYOUTS)}
#: Scalar states of each variant, by code.
STATE_SIZE = tuple(layout.size for layout in VARIANT_LAYOUTS.values())


@dataclass(frozen=True)
class JointKind:
    """A joint kind: the coordinates that carry a child relative to its parent in a tree's
    reduced state (a row of the joint-kind table, docs/physics.md "Joint kinds").

    Attributes
    ----------
    name : str
        The kind's name.
    n_q, n_v : int
        Sizes of its coordinates q and of its velocities u (the columns of its motion
        subspace S); the child's reduced states are q, then u (n_q + n_v).
    point_fixed : bool
        Whether the joint places the child from its parent by construction: its point C held
        to the parent's point (E_j = F_j = 0), or moved along an axis by the joint's own
        coordinate (a slide); no point law, its Lambda_j the reaction. Else the child keeps
        its own X, V and a point law pulls C.
    coordinates : str
        What q and u are, with units and frames.
    domain : str
        Where the coordinates are valid (the run fails at its edge).
    blocks : tuple of (str, int)
        The child's reduced states as named blocks (name, entries), in order: what a tree's
        linearisation calls them (:data:`BLOCK_UNITS` gives their units).
    axes : int
        Its coordinates along fixed axes (turns about them, a slide's translation; 0 for the
        balls and the free body): its gains, reference, limits and range are numbers per
        coordinate, its child's initial state q, u.
    unit : str
        The unit of its coordinates q, of its reference and of its range's ends.
    """

    name: str
    n_q: int
    n_v: int
    point_fixed: bool
    coordinates: str
    domain: str
    blocks: tuple
    axes: int = 0
    unit: str = "rad"

    @property
    def size(self) -> int:
        """n_q + n_v: the child's reduced states."""
        return self.n_q + self.n_v


#: The joint kinds by name (docs/physics.md, "Joint kinds"): the one place that says how
#: many reduced states and generalised velocities a joint's child has.
JOINT_KINDS = {
    "euler_ball": JointKind("euler_ball", 3, 3, True,
                      "Theta_j [rad], the Euler angles of A_rel = A_p' A_c (eq 2); Omega_j [rad/s], child frame",
                      "|theta_2| < pi/2 - simulation.gimbal_margin", (("joint_theta", 3), ("joint_omega", 3))),
    "free": JointKind("free", 6, 6, False,
                      "Theta [rad], X [m] (inertial); Omega [rad/s] (body frame), V [m/s] (inertial)",
                      "the body's |theta_2| < pi/2 - simulation.gimbal_margin",
                      (("theta", 3), ("omega", 3), ("position", 3), ("velocity", 3))),
    "hinge": JointKind("hinge", 1, 1, True,
                       "q [rad], the angle of A_rel = exp(q [a]x) about the joint's unit axis a (the parent's and "
                       "the child's frames, which it leaves fixed); u = dq/dt [rad/s]",
                       "every q (a hinge has no singular angle)", (("q", 1), ("u", 1)), axes=1),
    "ball": JointKind("ball", 4, 3, True,
                      "the unit quaternion of A_rel = A_p' A_c (w, x, y, z); Omega_j [rad/s], child frame",
                      "every orientation (no singular one)", (("quaternion", 4), ("joint_omega", 3))),
    "universal": JointKind("universal", 2, 2, True,
                           "q = (q_1, q_2) [rad], A_rel = exp(q_1 [a_1]x) exp(q_2 [a_2]x): a turn about the unit axis "
                           "a_1 (the parent's frame), then about the unit axis a_2 (the child's frame); u = dq/dt "
                           "[rad/s]",
                           "every q (a_1 and a_2 not parallel: the joint has no singular angle)",
                           (("q", 2), ("u", 2)), axes=2),
    "slide": JointKind("slide", 1, 1, True,
                       "q [m], the displacement of the child's point C from the parent's point along the joint's "
                       "unit axis a (the parent's frame; A_rel = I: the child keeps its parent's orientation); u = "
                       "dq/dt [m/s]",
                       "every q (a slide has no singular place)", (("translation", 1), ("translation_rate", 1)),
                       axes=1, unit="m"),
}
#: Each joint's ``variant`` -> its joint kind: the paper's ``permanent`` joint is the ball in
#: Euler angles, the four point laws pull a free body, ``hinge`` turns the child about an axis.
JOINT_KIND_OF = {"free": "free", "permanent": "euler_ball", "sliding": "free", "visco_elastic": "free",
                 "embedded": "free", "hinge": "hinge", "universal": "universal", "ball": "ball",
                 "slide": "slide"}
#: Each joint's ``variant`` -> its code in the compiled kernels: the paper's laws by their
#: :data:`VARIANT_CODES`, then the kinds that have no one-body form of the paper (``hinge``).
JOINT_CODES = {**VARIANT_CODES, "hinge": len(VARIANT_CODES), "universal": len(VARIANT_CODES) + 1,
               "ball": len(VARIANT_CODES) + 2, "slide": len(VARIANT_CODES) + 3}
#: Each joint code's reduced states and generalised velocities (the compiled kernels read
#: these; an embedded joint's D comes after the bodies).
REDUCED_STATES = np.array([JOINT_KINDS[JOINT_KIND_OF[v]].size for v in JOINT_CODES], dtype=np.int64)
VELOCITIES = np.array([JOINT_KINDS[JOINT_KIND_OF[v]].n_v for v in JOINT_CODES], dtype=np.int64)
#: Whether each joint code's kind holds its child's point by construction (:attr:`JointKind.point_fixed`).
POINT_FIXED = np.array([JOINT_KINDS[JOINT_KIND_OF[v]].point_fixed for v in JOINT_CODES], dtype=np.bool_)
#: Each joint code's coordinates along fixed axes, each with dq/dt = u: the turns about
#: them (a hinge's 1, a universal's 2), a slide's translation (1); 0 for the balls and the
#: free body.
AXES = np.array([JOINT_KINDS[JOINT_KIND_OF[v]].axes for v in JOINT_CODES], dtype=np.int64)
#: Whether each joint code is a kind beyond the paper's laws (a hinge, a universal joint, the
#: quaternion ball): a tree with one runs and is linearised in its reduced state only.
BEYOND_PAPER = np.array([v not in VARIANT_CODES for v in JOINT_CODES], dtype=np.bool_)


def joint_kind(variant: str) -> JointKind:
    """The joint-kind table's row of a joint's ``variant`` (KeyError for a name that is no
    joint's)."""
    return JOINT_KINDS[JOINT_KIND_OF[variant]]


def point_fixed(variant: str) -> bool:
    """Whether a joint of law ``variant`` holds its child's point by construction (its kind's
    :attr:`JointKind.point_fixed`: ``permanent``); False for a name that is no law (a value
    validation refuses elsewhere)."""
    kind = JOINT_KIND_OF.get(variant) if isinstance(variant, str) else None
    return kind is not None and JOINT_KINDS[kind].point_fixed
