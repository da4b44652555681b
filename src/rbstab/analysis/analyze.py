"""``rbstab.analyze(config)``: every analysis of one configuration, as one result object.

Order of work: the configuration analysed (the pure sign law of ``sliding`` replaced by
a boundary layer, said in the notes), its equilibrium and linearisation
(:mod:`~rbstab.analysis.linearise`), the Lyapunov certificate
(:mod:`~rbstab.analysis.certificate`), one simulation from the configured initial state
for the settling time, the basin map (:mod:`~rbstab.analysis.basin`), the smallest fatal
pushes and the basin stability (:mod:`~rbstab.analysis.push`) if asked for; last, the
certificate's sublevel estimate checked against simulations (:mod:`~rbstab.analysis.evidence`:
runs from {v = c}, and every run above).

Every configuration, one body or a tree of bodies (:class:`rbstab.config.RunConfig`), is
analysed as its compiled tree in the tree's independent coordinates: its rest state and
linearisation (:func:`~rbstab.analysis.linearise.linearise_chain`), the certificate over it
as a :class:`~rbstab.analysis.certificate.ChainModel`, its runs on the same engines. The
paper's one body is written and shown as one body's analysis (:attr:`Analysis.one_body`).
"""

from __future__ import annotations

import math
import os
import time as _time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import simulator
from ..config.schema import limits_violation
from ..convergence import DEFAULT_LYAPUNOV_RATIO
from ..engine.registry import DEFAULT_ENGINE
from ..kinematics import GIMBAL_LOCK_ANGLE
from ..layout import is_chain, joint_kind
from ..variants import VARIANTS
from ..variants.paper import has_paper_form
from .basin import BasinAxis, BasinMap, basin_map, time_to_converge
from .basin import DEFAULT_SAMPLES as DEFAULT_BASIN_SAMPLES
from .certificate import DEFAULT_SAMPLES, SLIDE_REACH, Certificate, ChainModel, certify
from .dataset import analysis_content, analysis_dataset, certificate_record, json_record
from .evidence import FALSIFICATION_RUNS, check_initial_run, check_runs, falsify
from .linearise import Linearisation, TreeCoordinates, coordinates_state, linearise_chain, mode_shapes, undisturbed
from .push import basin_stability as stability_of
from ..diagnostics import unbounded_fall_note
from .push import push_analysis
from .runs import check_axes
from .verify import NotVerifiable, check_verifiable, verify_analysis

__all__ = ["Analysis", "analyze", "DEFAULT_BOUNDARY_LAYER", "analysed_config", "OutsideLimits", "NoEquilibrium"]

#: phi [m] put in place of the pure sign law (boundary_layer 0) of ``sliding``.
DEFAULT_BOUNDARY_LAYER = 1e-3


@dataclass
class Analysis:
    """Everything :func:`analyze` found for one configuration, one body or a tree of bodies,
    in the tree's independent coordinates (:func:`rbstab.variants.chain.independent_coordinates`;
    the paper's one body's are its own state, Theta, Omega[, X, V][, D]).

    Attributes
    ----------
    config : RunConfig
        The configuration as given.
    analysed : RunConfig
        The configuration analysed (``config``, or it with a boundary layer, see notes).
    linearisation : Linearisation
        At the rest state, in the independent coordinates.
    certificate : Certificate or None
        None when not asked for. With disturbances, its Hessians are of the undisturbed
        dynamics (the same equilibrium), its sampled dv/dt of the disturbed ones; its states
        (e.g. ``worst_state``) are the independent coordinates.
    settling : dict or None
        The simulation from the configured initial state: ``status``, ``message``,
        ``time_to_converge`` [s] (NaN when not converged), ``lyapunov_initial`` [J],
        ``lyapunov_final`` [J], ``t_end`` [s], ``ratio``; None when not asked for.
    basin : BasinMap or None
    push : PushAnalysis or None
        The smallest fatal push of each direction (:func:`rbstab.analysis.push.push_analysis`).
    basin_stability : BasinStability or None
        (:func:`rbstab.analysis.push.basin_stability`).
    verification : Verification or None
        The verified sublevel bound (:func:`rbstab.analysis.verify.verify_analysis`); None
        when not asked for.
    notes : list of str
        What the reader must know (a substituted law, an equilibrium outside the
        domain, the configuration's warnings).
    timing : dict of str -> float
        Seconds per part.
    coordinates : list of (str, str, int)
        (body name, block, index into the full state) of each 3 entries of
        ``linearisation.equilibrium``.
    rest_state : ndarray, shape (n_states,)
        The full rest state (:func:`rbstab.variants.chain.full_state` of the equilibrium).
    initial_lyapunov : float
        v [J] at the configured initial state (zero at the rest state).
    one_body : bool
        The paper's one body (:func:`rbstab.variants.paper.has_paper_form`, in either spelling):
        its file, record and text are one body's (its variant's state layout, no body
        names); else a tree's (``variant`` chain, state blocks by body).
    """

    config: Any
    analysed: Any
    linearisation: Linearisation
    certificate: Certificate | None = None
    settling: dict | None = None
    basin: BasinMap | None = None
    push: Any = None
    basin_stability: Any = None
    verification: Any = None
    notes: list[str] = field(default_factory=list)
    timing: dict = field(default_factory=dict)
    coordinates: list = field(default_factory=list)
    rest_state: np.ndarray | None = None
    initial_lyapunov: float = 0.0
    one_body: bool = False

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def kind(self) -> str:
        """Its ``--json`` record's kind: ``configuration`` (one body) or ``chain``."""
        return "configuration" if self.one_body else "chain"

    @property
    def variant(self) -> str:
        """One body's law; a tree's analysis file's ``variant``, as its run file's: ``chain``."""
        return self.config.chain.joints[0].variant if self.one_body else "chain"

    @property
    def domain(self) -> str | None:
        """What bounds the certificate's domain, in its text (None: one body's theta_2)."""
        if self.one_body:
            return None
        variants = {j.variant for j in self.analysed.chain.joints}
        if variants == {"slide"}:
            return f"a slide's |q| = {SLIDE_REACH:g} m: no angle bounds it, the samples reach that far"
        hinged = bool(variants & {"hinge", "universal"})
        return (("|theta_2| of a body or joint, or a joint's |q|," if hinged else "|theta_2| of a body or joint")
                + " = pi/2 - gimbal_margin")

    @property
    def verdict(self) -> str:
        """The linearisation's verdict (:func:`rbstab.analysis.linearise.verdict`)."""
        return self.linearisation.verdict

    @property
    def layout(self):
        """The linearisation's coordinates: one body's variant's
        :class:`~rbstab.layout.StateLayout`, a tree's :class:`TreeCoordinates` by body and block."""
        if self.one_body:
            return VARIANTS[self.analysed.chain.joints[0].variant].layout
        return TreeCoordinates(tuple(self.coordinates), tuple(self.config.chain.body_names))

    @property
    def state_names(self) -> list[str]:
        """The name of each coordinate of the linearisation (``theta_1`` ...; a tree's
        ``<body>.<block>_<i>``, :meth:`TreeCoordinates.state_names`)."""
        return self.layout.state_names()

    @property
    def linear_settling_time(self) -> float:
        """Time [s] the slowest mode alone takes to bring v down by the convergence ratio:
        v ~ exp(-2 t / tau), so tau ln(1/ratio) / 2 (NaN unless asymptotically stable)."""
        return self.linearisation.settling_time(self.settling["ratio"] if self.settling else DEFAULT_LYAPUNOV_RATIO)

    def basin_inside(self) -> dict[str, int] | None:
        """Outcome counts of the basin points inside the sublevel estimate {v <= c}."""
        if self.basin is None or self.certificate is None:
            return None
        return self.basin.counts(self.basin.lyapunov_initial <= self.certificate.sublevel)

    def to_dataset(self):
        """The analysis as an :class:`xarray.Dataset` (the file's content, :mod:`~rbstab.analysis.dataset`)."""
        return analysis_dataset(self)

    def file_content(self, command_line: str | None = None) -> tuple[dict, dict, dict]:
        """(coordinates, variables, global attributes) of its file
        (:func:`~rbstab.analysis.dataset.analysis_content`)."""
        return analysis_content(self, command_line)

    def as_dict(self) -> dict:
        """Plain Python (the ``--json`` form, :func:`rbstab.analysis.dataset.json_record`): the
        verdict, the coordinates ``state`` and the ``equilibrium`` in them, eigenvalues as
        [re, im] [1/s] with each one's natural frequency, damping ratio, time constant and
        e-folding time, ``slowest_time_constant`` [s] (null unless asymptotically stable),
        ``shortest_e_folding_time`` [s] (null unless unstable), the simulation, notes ...; a
        tree's with the rest state per body and block (``rest_state``), each eigenvalue's mode
        shape on the bodies' angles (``modes``: ``{"eigenvalue": [re, im], "shape":
        {"<body>.theta_<i>": [re, im]}}``, largest entry 1), v at the initial state [J]
        and the certificate's ``coordinates`` naming the entries of ``worst_state``."""
        if self.one_body:
            return json_record(self)
        lin = self.linearisation
        rest = {}
        for (body, block, _, size), at in zip(self.coordinates, self.layout.offsets()):
            rest.setdefault(body, {})[block] = lin.equilibrium[at: at + size].tolist()
        return {**json_record(self), "rest_state": rest, "modes": self._modes(),
                "initial_lyapunov": self.initial_lyapunov,
                **({"certificate": self._certificate_dict()} if self.certificate is not None else {})}

    def to_json(self) -> dict:
        """The ``--json`` record: :meth:`as_dict` (one body's: ``name``, ``variant``,
        ``equilibrium``, ``eigenvalues`` ([re, im] pairs, real part descending), ``verdict``
        and the rest of the analysis); a tree's with the basin map's axes' keys and values,
        every point's outcome (rows: the first axis; 0 converged, 1 not converged, 2
        failed), the counts, those inside {v <= c} and the failures' messages."""
        record = self.as_dict()
        if self.basin is not None and not self.one_body:
            b = self.basin
            record["basin"] = {"axes": [{"key": a.key, "values": a.values.tolist()} for a in b.axes],
                               "outcome": b.outcome.tolist(), "counts": b.counts(), "messages": b.messages,
                               "inside_estimate": self.basin_inside(), "t_end": b.t_end, "ratio": b.ratio}
        return record

    def angles(self) -> tuple[list[str], list[int]]:
        """(names ``<body>.theta_<i>``, positions in the linearisation's coordinates) of the
        bodies' Euler angles among the independent coordinates; in a tree with a hinge, the
        joints' angles (a hinge's child's ``<body>.q``, a ball's ``<body>.joint_theta_<i>``)
        and a free body's Euler angles, and a slide's displacement (``<body>.translation``, m):
        the configuration's coordinates that mode shapes are written on."""
        layout = self.layout
        every = layout.state_names()
        rows = [at + i for (_, block, _, size), at in zip(self.coordinates, layout.offsets())
                if block in ("theta", "joint_theta", "q", "translation") for i in range(size)]
        return [every[r] for r in rows], rows

    def _modes(self) -> list[dict]:
        """Each eigenvalue's mode on the bodies' angles (:func:`mode_shapes`), for ``--json``."""
        names, rows = self.angles()
        shapes = mode_shapes(self.linearisation, rows)
        return [{"eigenvalue": [float(s.real), float(s.imag)],
                 "shape": {n: [float(c.real), float(c.imag)] for n, c in zip(names, shape)}}
                for s, shape in zip(self.linearisation.eigenvalues, shapes)]

    def _certificate_dict(self) -> dict:
        names = [f"{body}.{block}.{i}" for body, block, _, size in self.coordinates for i in range(size)]
        return {**certificate_record(self.certificate), "coordinates": names}


def analysed_config(config, boundary_layer: float | None = None) -> tuple[Any, list[str]]:
    """The configuration to analyse and the notes that say why it differs from ``config``.

    The pure sign law of ``sliding`` (boundary_layer 0) has no derivative at E = 0: its
    right-hand side has no linearisation and v no Hessian there. Its boundary-layer law,
    sgn(E) -> tanh(E / phi), is analysed instead, with phi = ``boundary_layer`` (default
    :data:`DEFAULT_BOUNDARY_LAYER`), in either spelling of the one body that takes it. For
    every other configuration ``boundary_layer`` must be None or the configured value; a
    tree of several bodies is analysed as given (its sliding joints have their own
    ``boundary_layer`` > 0).

    Raises
    ------
    ValueError
        For a ``boundary_layer`` <= 0, or given for a configuration that is not the sign law.
    """
    if config.chain.size > 1:
        if boundary_layer is not None:
            raise ValueError(f"--boundary-layer: found {boundary_layer:g}; a chain has no pure sign law to replace "
                             "(a sliding joint of a chain has its own boundary_layer > 0)")
        return config, []
    joint = config.chain.joints[0]
    sign_law = joint.variant == "sliding" and not joint.boundary_layer
    if boundary_layer is not None and not (boundary_layer > 0 and math.isfinite(boundary_layer)):
        raise ValueError(f"--boundary-layer: found {boundary_layer}; expected a width phi > 0 [m]")
    key = f"joints.{joint.name}.boundary_layer" if is_chain(config) else "controller.boundary_layer"  # as written
    if not sign_law:
        if boundary_layer is not None and boundary_layer != joint.boundary_layer:
            raise ValueError(f"--boundary-layer: {config.name} is not the pure sign law of sliding "
                             f"(boundary_layer 0); change its law with --set {key}=...")
        return config, []
    phi = DEFAULT_BOUNDARY_LAYER if boundary_layer is None else float(boundary_layer)
    from ..config import PhysicalPlausibilityWarning, config_from_mapping  # heavy: pydantic (the validator)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        analysed = config_from_mapping(config.resolved, overrides=[f"{key}={phi!r}"])
    note = (f"{config.name} uses the pure sign law Lambda = -K_s sgn(E) (boundary_layer 0): the right-hand "
            "side is not differentiable at E = 0, so the linearisation does not exist there (and v = "
            f"... + K_s |E|_1 has no Hessian). Analysed instead: the boundary-layer law tanh(E / phi), phi = "
            f"{phi:g} m, whose stiffness at E = 0 is K_s / phi; every figure below is of that law.")
    return analysed, [note]


def _settling(config, ratio: float) -> tuple[dict, Any]:
    """Simulate ``config`` from its initial state: (:attr:`Analysis.settling`, with when |v|
    first stays within ratio |v(0)| + 1e-12 J (:data:`rbstab.convergence.SAMPLE_RULE`,
    :func:`~rbstab.analysis.basin.time_to_converge`); the run, a RunResult)."""
    result = simulator.simulate(config)
    v = result.outputs["lyapunov"]
    return {
        "status": result.status,
        "message": result.message,
        "time_to_converge": time_to_converge(result.time, v, ratio) if result.ok else float("nan"),
        "lyapunov_initial": float(v[0]),
        "lyapunov_final": float(v[-1]),
        "t_end": float(config.simulation.t_end),
        "ratio": float(ratio),
    }, result


class NoEquilibrium(ValueError):
    """The configuration has no rest point: its actuators' limits cannot hold the body
    (one line: which control would need more than its limit)."""


class OutsideLimits(ValueError):
    """The equilibrium lies outside the admissible region ``simulation.limits`` (one line
    naming the bound): every run there leaves it, so no push or initial state recovers."""


#: The controls an actuator limits: (output, the record's limit field, units, whose: joint or body).
_CONTROLS = (("torque_n", "torque_limit", "N m", "joint"), ("force_h", "force_limit", "N", "body"),
             ("constraint_force", "constraint_force_limit", "N", "joint"))


def _part(compiled, kind: str, i: int, one_body: bool) -> str:
    """How a message names body or joint ``i`` (nothing for one body)."""
    if one_body:
        return ""
    names = compiled.chain.joint_names if kind == "joint" else compiled.chain.body_names
    return f" of {kind} '{names[i]}'"


def _unlimited(compiled, passive: bool = True):
    """``compiled`` without its actuators' limits (every record's saturation off; without
    ``passive``, its joints' passive torques off too), the same h."""
    from ..variants import chain as C  # heavy: numba

    params = compiled.params.copy()
    params["saturation"] = 0.0
    if not passive:
        params["passive"] = 0.0
    return C.with_records(compiled, params, compiled.ppoints, compiled.offset)


def _commanded(compiled, y: np.ndarray) -> dict[str, np.ndarray]:
    """N_j, H_i, Lambda_j [N m, N, N] (each (n, 3)) that the feedback and point laws of
    ``compiled`` command at its full state ``y`` (before the actuators' limits; N_j without
    the joints' passive torques, which no actuator delivers)."""
    from ..variants import chain as C  # heavy: numba

    out = C.evaluate(_unlimited(compiled, passive=False), np.zeros(1), y[None])
    return {key: np.asarray(out[key], dtype=float)[0] for key, _, _, _ in _CONTROLS}


def _beyond(compiled, y: np.ndarray, one_body: bool, at_limit: bool) -> list[str]:
    """Each control commanded at ``y`` beyond its limit (``at_limit``: at or beyond), in words:
    |u_i| against a symmetric limit; u_i against its upper or its lower limit where the
    lower is its own (N_j's ``torque_floor``)."""
    commanded, out = _commanded(compiled, y), []
    above, below = (">=", "<=") if at_limit else (">", "<")
    limited = (np.asarray(compiled.params["saturation"]) != 0)[:, None]  # a record without limits holds none
    for key, field_name, unit, kind in _CONTROLS:
        upper = np.asarray(compiled.params[field_name], dtype=float)  # (n, 3)
        lower = np.asarray(compiled.params["torque_floor"], dtype=float) if key == "torque_n" else -upper
        value = commanded[key]
        high = limited & ((value >= upper) if at_limit else (value > upper))
        low = limited & ((value <= lower) if at_limit else (value < lower))
        for i, axis in zip(*np.nonzero(high | low)):
            part, u = _part(compiled, kind, i, one_body), value[i, axis]
            if lower[i, axis] == -upper[i, axis]:
                out.append(f"|{key}_{axis + 1}|{part} = {abs(u):.4g} {unit} {above} its limit {upper[i, axis]:g} {unit}")
            elif high[i, axis]:
                out.append(f"{key}_{axis + 1}{part} = {u:.4g} {unit} {above} its upper limit {upper[i, axis]:g} {unit}")
            else:
                out.append(f"{key}_{axis + 1}{part} = {u:.4g} {unit} {below} its lower limit {lower[i, axis]:g} {unit}")
    return out


def _unheld(compiled, one_body: bool) -> str:
    """Why a configuration with actuator limits has no rest point: the controls that its
    rest state without limits commands beyond their limits."""
    from ..variants import chain as C  # heavy: numba

    rest, _ = C.rest_state(_unlimited(compiled))
    beyond = [] if rest is None else _beyond(compiled, rest, one_body, at_limit=False)
    why = ("; without the limits the equilibrium would need " + ", ".join(beyond)) if beyond else ""
    where = "controller.saturation" if one_body else "saturation"
    return (f"no equilibrium: with its actuators' limits ({where}) no state is at rest{why}; "
            "there is nothing to linearise or certify (rbstab run shows where the body goes)")


def _saturated_at_rest(compiled, rest: np.ndarray, linearisation: Linearisation, one_body: bool) -> list[str]:
    """A note naming each control that sits at or beyond its limit at the rest state ``rest``
    (the full state): the linearisation there sees the actuator's slope at its limit (0 for
    clip beyond it)."""
    shapes = {s.shape for s in [*(b.saturation for b in compiled.chain.bodies),
                                *(j.saturation for j in compiled.chain.joints)] if s is not None}
    if not shapes or not linearisation.is_rest_point:
        return []
    at = _beyond(compiled, rest, one_body, at_limit=True)
    if not at:
        return []
    return [f"at the {_REST[one_body]} the actuators saturate ({', '.join(at)}, as commanded): the linearisation "
            f"has the {'/'.join(sorted(shapes))} actuator's slope there"]


#: How the notes name the state analysed: one body's equilibrium, a tree's rest state.
_REST = {True: "equilibrium", False: "rest state"}


def _outside_limits(compiled, rest: np.ndarray, limits, one_body: bool) -> str | None:
    """Why the rest state ``rest`` (full state) lies outside ``limits``
    (``simulation.limits``) or a joint's range that is an admissible region, in one line
    ("the equilibrium lies outside simulation.limits: |theta_2| = 0.7 rad > 0.6 rad
    (simulation.limits.theta)"; a tree's names the body or joint), or None where it lies
    inside (or there are no limits)."""
    from ..variants import chain as C  # heavy: numba

    if limits is None and all(joint.region is None for joint in compiled.chain.joints):
        return None
    outputs = C.evaluate(compiled, np.zeros(1), rest[None])
    for j, joint in enumerate(compiled.chain.joints):  # a hinge's q (about its axis) or a ball's Theta_j
        if joint.region is None:
            continue
        theta_j = np.asarray(outputs["joint_theta"], dtype=float)[0, j]
        values = np.atleast_1d(joint.axis @ theta_j if joint.variant == "hinge" else
                               C.slide_coordinates(rest, j, compiled.params, compiled.parents, compiled.ppoints)[0]
                               if joint.variant == "slide" else
                               theta_j[:2] if joint.variant == "universal" else
                               np.linalg.norm(theta_j) if joint.variant == "ball" else theta_j)
        ends = [np.broadcast_to(np.atleast_1d(np.asarray(end, dtype=float))[:values.size], values.shape)
                for end in (joint.region.lower, joint.region.upper)]  # a universal joint's first 2 of 3
        for i, (value, lower, upper) in enumerate(zip(values, *ends)):
            if not lower <= value <= upper:
                what = {"hinge": "q", "universal": f"q_{i + 1}", "ball": "turn", "slide": "q"}.get(
                    joint.variant, f"theta_{i + 1} of Theta_j")
                return (f"the {_REST[one_body]} lies outside joints.{joint.name}.range (an admissible region): its "
                        f"{what} is {'above' if value > upper else 'below'} {upper if value > upper else lower:g} "
                        f"{joint_kind(joint.variant).unit}")
    if limits is None:
        return None
    errors = np.asarray(outputs["constraint_error"], dtype=float)[0]
    n = compiled.size
    for i in range(n):
        fixed = compiled.permanent[i]  # a point-fixed joint (ball, hinge): E_j = 0 by construction
        values = [*rest[12 * i: 12 * i + 12].reshape(4, 3), np.zeros(3) if fixed else errors[i]]
        found = limits_violation(values, limits.array)
        if found is not None:
            key, detail = found
            kind = "joint" if key.endswith("constraint_error") else "body"
            detail = detail.replace("| = ", f"|{_part(compiled, kind, i, one_body)} = ", 1)
            return f"the {_REST[one_body]} lies outside simulation.limits: {detail} ({key})"
    return None


def _domain_notes(compiled, rest: np.ndarray, margin: float, one_body: bool) -> list[str]:
    """A note where the rest state has a body's or joint's |theta_2| outside the model's
    domain pi/2 - ``margin`` (``simulation.gimbal_margin`` [rad])."""
    from ..variants import chain as C  # heavy: numba

    angles, parts = C.gimbal_angles(compiled, rest)
    if not np.size(angles):  # a tree of hinges: no Euler angles, no singular one
        return []
    worst = int(np.argmax(np.abs(angles)))
    limit = GIMBAL_LOCK_ANGLE - margin
    if abs(angles[worst]) < limit:
        return []
    of = "" if one_body else f" of {C.gimbal_part_name(compiled, *parts[worst])}"
    return [f"the {_REST[one_body]} has theta_2 = {angles[worst]:.6g} rad{of}, outside the model's domain "
            f"|theta_2| < pi/2 - gimbal_margin = {limit:.6g} rad (eq 5): the Euler angles are singular on the way "
            "there, and no run reaches it"]


def _rest_point_notes(linearisation: Linearisation) -> list[str]:
    if linearisation.is_rest_point:
        return []
    worst = float(np.abs(linearisation.rest_residual).max())
    return [f"the equilibrium is not a rest point: max |dy/dt| there is {worst:.3g}, above the tolerance "
            f"{linearisation.rest_tolerance:.3g} (the equilibrium search did not converge)"]


def analyze(
    config,
    *,
    boundary_layer: float | None = None,
    certificate: bool = True,
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    simulate: bool = True,
    basin: Sequence[str | BasinAxis] | None = None,
    basin_samples: int = DEFAULT_BASIN_SAMPLES,
    ratio: float = DEFAULT_LYAPUNOV_RATIO,
    jobs: int = 1,
    engine: str = DEFAULT_ENGINE,
    push: Mapping[str, Any] | None = None,
    basin_stability: Mapping[str, Any] | None = None,
    executor: Any = None,
    falsification_runs: int = FALSIFICATION_RUNS,
    verify: bool = False,
) -> Analysis:
    """Analyse the stability of one configuration's equilibrium.

    Parameters
    ----------
    config : RunConfig or path-like
        A validated configuration, or a YAML file (:func:`rbstab.config.load_config`).
        Analysed as its compiled tree in the tree's independent coordinates (its rest state
        and linearisation by :func:`~rbstab.analysis.linearise.linearise_chain`, the
        certificate over it as a :class:`~rbstab.analysis.certificate.ChainModel`), its
        basin map, pushes (on the body ``push["body"]``) and basin stability on ``engine``,
        on the CPU in ``jobs`` threads; ``boundary_layer`` is one body's.
    boundary_layer : float, optional
        phi [m] analysed in place of the pure sign law of ``sliding`` (default
        :data:`DEFAULT_BOUNDARY_LAYER`); see :func:`analysed_config`.
    certificate : bool
        Compute the Lyapunov certificate (:func:`rbstab.analysis.certificate.certify`).
    samples : int
        States sampled for the certificate's dv/dt check (>= 1).
    seed : int
        Of that sampling.
    simulate : bool
        Simulate from the configured initial state for the settling time.
    basin : two str or BasinAxis, optional
        The slice of the basin map, e.g. ``["initial_state.omega.0=-60:60:41",
        "initial_state.omega.1=-60:60:41"]`` (:meth:`BasinAxis.parse`).
    basin_samples : int
        Samples per basin run.
    ratio : float
        Convergence: |v(t)| <= ratio |v(0)| + 1e-12 J from then on
        (:data:`rbstab.convergence.SAMPLE_RULE`), 0 < ratio < 1.
    jobs : int
        Threads that integrate the runs of the basin map, the pushes, the basin stability
        and the certificate's falsification (the compiled driver releases Python's lock).
    engine : {"compiled", "cuda"}
        The engine of the basin map (:func:`rbstab.analysis.basin.basin_map`), the pushes
        and the basin stability.
    push : mapping, optional
        Keyword arguments of :func:`rbstab.analysis.push.push_analysis` (``kind``,
        ``directions``, ``point``, ``at``, ``push_max``, ``tol``, ``rungs``, ``refine``):
        the smallest fatal push of each direction.
    basin_stability : mapping, optional
        Keyword arguments of :func:`rbstab.analysis.push.basin_stability` (``ranges`` or
        ``push`` and ``push_range``, ``draws``, ``confidence`` ...).
    executor : rbstab.sweep.executors.Executor, optional
        Workers of the pushes and the basin stability (default: none, ``jobs`` threads).
    falsification_runs : int
        Runs of the certificate's falsification pass from states on {v = c}
        (:func:`rbstab.analysis.evidence.falsify`; 0: none). Whatever it is, c is checked
        against every run of the analysis (:func:`rbstab.analysis.evidence.check_initial_run`,
        :func:`rbstab.analysis.evidence.check_runs`).
    verify : bool
        Prove a sublevel bound by interval arithmetic (:func:`rbstab.analysis.verify.verify_analysis`;
        the reduced 6-state model of ``permanent``, checked before anything runs).

    Returns
    -------
    Analysis

    Raises
    ------
    ConfigError
        For an invalid configuration file.
    OutsideLimits
        When the equilibrium lies outside ``simulation.limits``.
    NotVerifiable
        With ``verify``, for a configuration the verification does not cover.
    ValueError
        For an invalid option (the message names it, the value found and what is allowed).
    """
    if isinstance(config, (str, os.PathLike)):
        from ..config.loader import load_config  # heavy: pydantic (the validator)

        config = load_config(config)
    _check_options(samples, basin_samples, ratio, jobs)
    if verify:
        check_verifiable(config)
    t0 = _time.perf_counter()
    analysed, notes = analysed_config(config, boundary_layer)

    axes = [a if isinstance(a, BasinAxis) else BasinAxis.parse(a) for a in basin or ()]
    if basin is not None:
        check_axes(analysed, axes)
    result, model, disturbed = _findings(config, analysed, notes)
    notes, timing = result.notes, result.timing
    lin = result.linearisation
    t1 = _time.perf_counter()
    timing["linearisation"] = t1 - t0
    if certificate:
        result.certificate = certify(model, lin, gimbal_margin=analysed.simulation.gimbal_margin,
                                     n_samples=samples, seed=seed, disturbed=disturbed,
                                     t_end=analysed.simulation.t_end)
        timing["certificate"] = _time.perf_counter() - t1
    first = None
    if simulate:
        t2 = _time.perf_counter()
        result.settling, first = _settling(analysed, ratio)
        timing["simulation"] = _time.perf_counter() - t2
    if axes:
        t3 = _time.perf_counter()
        result.basin = basin_map(analysed, axes, ratio=ratio, n_samples=basin_samples, jobs=jobs, engine=engine)
        timing["basin"] = _time.perf_counter() - t3
    if push or basin_stability or axes:
        fall = unbounded_fall_note(analysed)
        if fall is not None:
            notes.append(fall)
    if push:
        t4 = _time.perf_counter()
        result.push = push_analysis(analysed, **push, ratio=ratio, engine=engine, executor=executor, jobs=jobs)
        timing["push"] = _time.perf_counter() - t4
    if basin_stability:
        t5 = _time.perf_counter()
        result.basin_stability = stability_of(analysed, **basin_stability, ratio=ratio, engine=engine,
                                              executor=executor, jobs=jobs)
        timing["basin_stability"] = _time.perf_counter() - t5
    if result.certificate is not None:
        t6 = _time.perf_counter()
        # 32 runs a level on the CPU's engine (a GPU gains nothing there, and --engine is the maps')
        checked = falsify(analysed, model, lin, result.certificate, runs=falsification_runs, seed=seed, jobs=jobs)
        if first is not None:
            checked = check_initial_run(checked, analysed, simulator.simulate, lin, ratio=ratio, first=first,
                                        impulses=_impulse_times(analysed))
        result.certificate = check_runs(checked, result)
        timing["checks"] = _time.perf_counter() - t6
    if verify:
        t7 = _time.perf_counter()
        try:
            result.verification = verify_analysis(result)
        except NotVerifiable as exc:  # a covered configuration whose proof reached no c > 0
            notes.append(f"verification: {exc}")
        timing["verification"] = _time.perf_counter() - t7
    return result


def _findings(config, analysed, notes: list[str]) -> tuple[Analysis, Any, Any]:
    """(the :class:`Analysis` of the rest state and linearisation in the tree's independent
    coordinates with its notes, the certificate's model: the tree without its bodies'
    disturbances (the same h), the tree with them or None)."""
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    one_body = has_paper_form(analysed.chain)
    compiled = C.compile_chain(analysed.chain)
    quiet = undisturbed(analysed)
    calm = compiled if quiet is analysed else C.compile_chain(quiet.chain, offset=compiled.offset)  # the same h
    lin, coordinates = linearise_chain(calm)
    saturated = any(p.saturation is not None for p in (*analysed.chain.bodies, *analysed.chain.joints))
    if not lin.is_rest_point and saturated:
        raise NoEquilibrium(_unheld(calm, one_body))
    rest = coordinates_state(calm, lin.equilibrium)
    sim = analysed.simulation
    outside = _outside_limits(calm, rest, sim.limits, one_body)
    if outside is not None:
        raise OutsideLimits(outside)
    notes = notes + _domain_notes(calm, rest, sim.gimbal_margin, one_body) + _rest_point_notes(lin)
    notes += _saturated_at_rest(calm, rest, lin, one_body)
    model, disturbed = ChainModel(calm, coordinates), None
    if quiet is not analysed:
        disturbed = ChainModel(compiled, coordinates)
        kinds = ", ".join(dict.fromkeys(d.kind for b in analysed.chain.bodies for d in b.disturbances))
        notes.append(f"disturbances ({kinds}): the {_REST[one_body]}, the linearisation and the certificate's "
                     "Hessians are of the undisturbed dynamics; the certificate's sampled dv/dt (each state at a "
                     "time drawn in [0, t_end], impulses not seen) and the simulations integrate the disturbed "
                     "dynamics")
    v0 = C.lyapunov(compiled, C.initial_state(analysed))[0]
    return Analysis(config=config, analysed=analysed, linearisation=lin, notes=notes + list(config.warnings),
                    coordinates=coordinates, rest_state=rest, initial_lyapunov=float(v0), one_body=one_body), \
        model, disturbed


def _impulse_times(config) -> list[float]:
    """Times [s] of the configuration's impulse disturbances (every body's)."""
    return [d.start for b in config.chain.bodies for d in b.disturbances if d.kind == "impulse"]


def _check_options(samples: int, basin_samples: int, ratio: float, jobs: int) -> None:
    problems = []
    if int(samples) < 1:
        problems.append(f"--samples: found {samples}; expected an integer >= 1")
    if int(basin_samples) < 2:
        problems.append(f"--basin-samples: found {basin_samples}; expected an integer >= 2")
    if not 0 < ratio < 1:
        problems.append(f"--ratio: found {ratio}; expected 0 < ratio < 1")
    if int(jobs) < 1:
        problems.append(f"--jobs: found {jobs}; expected an integer >= 1")
    if problems:
        raise ValueError("; ".join(problems))
