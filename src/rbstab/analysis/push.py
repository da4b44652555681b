"""Push recovery: the smallest fatal push of each direction (the minimal fatal shock) and the
fraction of random perturbations a body recovers from (basin stability), on the batch engine.

A *push* is an impulse (docs/disturbances.md) given to the body at rest at its equilibrium
at time t0 (``at``): a force impulse P [N s] at a point R_p of the body (``point``, body
frame from the centre of mass; P in the inertial frame), or a torque impulse L [N m s]
(body frame). A pushed run *recovers* (:data:`RECOVERY_RULE`) when it reaches t_end (it
did not leave the admissible region ``simulation.limits`` nor meet gimbal lock) and
|v(t_end)| <= ratio dT + 1e-12 J, with dT the kinetic energy the push gave the body at
rest: the sweeps' convergence rule (:mod:`rbstab.convergence`) with v just after the push
in place of v(0), which it is when t0 = 0.

The smallest fatal magnitude of a direction u (:func:`push_thresholds`):

1. the top of its ladder: ``push_max``, or found by doubling (from 1 N s or 1 N m s:
   doubled while the push recovers, halved while it is fatal, until two magnitudes a
   factor 2 apart bracket the first fatal one);
2. a ladder of ``rungs`` magnitudes top * i / rungs, i = 1 ... rungs;
3. bisection between the last recovering rung below the first fatal rung (or 0) and
   that rung, until hi - lo <= tol hi. The threshold is hi: a fatal magnitude with a
   recovering one within ``tol`` below it.

Where a recovering rung lies above the first fatal rung, recovery is not monotone in the
magnitude (resonance islands): the threshold is still the first fatal magnitude seen from
below, at the ladder's resolution, and ``monotone`` is False for that direction. Every
direction advances together: each step (a doubling, the ladder, one bisection) is one
batch of runs (:func:`rbstab.simulator.simulate_batch`, ``engine`` compiled or cuda, on an
executor with ``jobs`` > 1). With ``n`` quasi-uniform directions, a local search around
the weakest ones then refines the minimum (:func:`push_analysis`).
"""

from __future__ import annotations

import dataclasses
import math
import time as _time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO, ROUND_OFF, converged
from ..layout import VARIANT_LAYOUTS, is_chain, point_fixed
from .runs import Runs, check_entries

__all__ = ["PUSH_KINDS", "RECOVERY_RULE", "STATE_RULE", "PushAnalysis", "Pushes", "Thresholds", "BasinStability",
           "push_directions", "push_thresholds", "push_analysis", "basin_stability", "check_push_options",
           "parse_ranges", "parse_push_range", "runs_from_states",
]

#: Quantity of a push -> the units of its magnitude.
PUSH_KINDS = {"force": "N s", "torque": "N m s"}
#: When a pushed run recovers, as text.
RECOVERY_RULE = (f"recovered = status == 'success' (t_end reached inside simulation.limits) and "
                 f"|v(t_end)| <= ratio * dT + {ROUND_OFF:g} J, dT the kinetic energy the push gave the body at rest; "
                 "a run still settling at t_end (0 <= v(t_end) <= dT) judged at a longer t_end")
#: Default ladder rungs and relative tolerance of a threshold.
DEFAULT_RUNGS = 16
DEFAULT_TOL = 1e-3
#: The doubling's first magnitude [N s or N m s] and its range: beyond it a direction
#: counts as never fatal (above) or fatal for any push (below).
FIRST_PUSH = 1.0
LARGEST_PUSH = 2.0 ** 30
SMALLEST_PUSH = 2.0 ** -30
#: Refinement: the weakest directions searched around, new directions per round and
#: each, and rounds (each round halves the cone).
REFINE_WORST, REFINE_AROUND, REFINE_ROUNDS = 4, 6, 3


def push_directions(n: int, seed: int = 0) -> np.ndarray:
    """n unit vectors quasi-uniform on the sphere: the Fibonacci lattice (equal areas, the
    golden angle between neighbours), turned by a random rotation drawn from ``seed``.
    Shape (n, 3)."""
    from scipy.spatial.transform import Rotation  # heavy: scipy

    if n < 1:
        raise ValueError(f"--push-directions: found {n}; expected an integer >= 1")
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    lattice = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return Rotation.random(random_state=seed).apply(lattice)


def _unit(vectors: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return vectors / norm


def check_push_options(kind: str, *, point: Sequence[float] | None = None, directions: Any = None,
                       push_max: float | None = None, tol: float = DEFAULT_TOL, rungs: int = DEFAULT_RUNGS,
                       at: float = 0.0) -> None:
    """Refuse bad push options in one line each (ValueError naming the option, the value
    found and what is allowed)."""
    problems = []
    if kind not in PUSH_KINDS:
        problems.append(f"--push: found {kind!r}; expected one of {', '.join(PUSH_KINDS)}")
    if point is not None and kind == "torque":
        problems.append("--push-point: a torque has no point of application; give it with --push force")
    if point is not None and (len(point) != 3 or not np.all(np.isfinite(point))):
        problems.append(f"--push-point: found {list(point)}; expected three finite numbers X,Y,Z [m]")
    if directions is not None and not np.isscalar(directions):
        d = np.asarray(directions, dtype=float).reshape(-1, 3)
        norms = np.linalg.norm(d, axis=1)
        for row, norm in zip(d, norms):
            if not (np.isfinite(norm) and norm > 0):
                problems.append(f"--push-direction: found {','.join(f'{x:g}' for x in row)}; expected a non-zero "
                                "finite vector X,Y,Z")
    elif directions is not None and int(directions) < 1:
        problems.append(f"--push-directions: found {directions}; expected an integer >= 1")
    if push_max is not None and not (math.isfinite(push_max) and push_max > 0):
        problems.append(f"--push-max: found {push_max}; expected a magnitude > 0 [{PUSH_KINDS.get(kind, '')}]")
    if not 0 < tol < 1:
        problems.append(f"--push-tol: found {tol}; expected 0 < tol < 1 (relative)")
    if int(rungs) < 2:
        problems.append(f"--push-rungs: found {rungs}; expected an integer >= 2")
    if not (math.isfinite(at) and at >= 0):
        problems.append(f"--push-at: found {at}; expected a time >= 0 [s] before simulation.t_end")
    if problems:
        raise ValueError("; ".join(problems))


class Pushes:
    """One configuration's pushes as batches of runs: its bodies at rest (one body at its
    equilibrium, a tree at its rest state), then body ``body`` pushed at ``at`` by the
    impulse of each of a (k, 3) array of vectors (:meth:`recovered`). The push is one more
    impulse entry of the configuration's disturbances, so a run keeps its own disturbances
    and the push's exact bookkeeping (docs/disturbances.md; a tree's jump: docs/physics.md,
    "A push on a chain"). The runs are a :class:`rbstab.engine.RunBatch` on ``engine``
    (:class:`rbstab.analysis.runs.Runs`: in slices over ``executor``, or ``jobs`` threads).

    Parameters
    ----------
    config : RunConfig
        Validated; its own disturbances stay (the push is one more entry).
    kind : {"force", "torque"}
    body : str, optional
        The body pushed: one of a tree's bodies (required for a tree of several; a tree of one
        body: that body by default), None for one body.
    point : (3,) float, optional
        R_p [m], the pushed body's frame, from its centre of mass (force only; default 0).
    at : float
        t0 [s], in [0, t_end).
    ratio : float
        Of :data:`RECOVERY_RULE`.
    engine : {"compiled", "cuda"}
        The engine of the runs (:func:`rbstab.simulator.simulate_batch`).
    executor : rbstab.sweep.executors.Executor, optional
        Takes the batch in slices (None: this process).
    jobs : int
        Without an executor, the threads integrating the batch's slices (the compiled
        driver releases Python's lock).

    Attributes
    ----------
    equilibrium : ndarray, shape (n_states,)
        Where every run starts (before the push): the bodies at rest, as the maximal state of
        the tree (one body: of its one-body tree, :attr:`rbstab.config.RunConfig.chain`).
    config : RunConfig
        The pushed configuration (its initial state at rest, the push one more impulse).

    Raises
    ------
    ValueError
        One line, for a configuration that cannot take the push: no equilibrium at rest,
        the pure sign law, four disturbances already, ``at`` beyond t_end, an unknown body,
        a force at the pin of a body a permanent joint holds to the ground.
    """

    def __init__(self, config, kind: str, *, body: str | None = None, point=None, at: float = 0.0,
                 ratio: float = DEFAULT_LYAPUNOV_RATIO, engine: str = "compiled", executor=None, jobs: int = 1) -> None:
        from ..model import MAX_DISTURBANCES  # heavy: numba
        from ..variants import chain as C  # heavy: numba
        from ..variants.tree import reduce_state, tree_layout  # heavy: numba

        self.kind, self.at, self.ratio = kind, float(at), float(ratio)
        self.point = np.zeros(3) if point is None or kind == "torque" else np.asarray(point, dtype=float)
        self.units = PUSH_KINDS[kind]
        tree = is_chain(config)
        chain = config.chain  # one body: its one-body chain (the same model)
        names = list(chain.body_names)
        if tree and body is None and len(names) == 1:  # a tree of one body: that body
            body = names[0]
        self.body = body
        if tree and body not in names:
            found = "none" if body is None else f"'{body}'"
            raise ValueError(f"--push-body: found {found}; expected the body of the chain that is pushed "
                             f"({', '.join(names)})")
        self._member = names.index(body) if tree else 0
        resolved = config.resolved
        t_end = float(resolved["simulation"]["t_end"])
        if not self.at < t_end:
            raise ValueError(f"--push-at: found {self.at:g}; expected a time in [0, simulation.t_end) = [0, {t_end:g}) s")
        own = list(resolved.get("disturbances") or [])
        if len(own) >= MAX_DISTURBANCES:
            raise ValueError(f"{config.name}: disturbances: found {len(own)} entries; a push needs one more and at most "
                             f"{MAX_DISTURBANCES} are allowed")
        joint = chain.joints[self._member]
        if (kind == "force" and point_fixed(joint.variant) and joint.variant != "slide" and joint.parent < 0
                and np.allclose(self.point, joint.child_point)):  # a slide's point moves along its axis
            what = f"'{body}' (joint '{joint.name}' holds it to the ground)" if tree else \
                "this permanent body (body.attachment_point)"
            raise ValueError(f"--push-point: found {','.join(f'{x:g}' for x in self.point)}, the pin of {what}: a force "
                             "there moves nothing; push elsewhere or with --push torque")
        if joint.variant == "sliding" and not joint.boundary_layer:  # one body's (a tree's is refused at load)
            raise ValueError(f"{config.name}: the pure sign law (controller.boundary_layer 0) takes no disturbances; "
                             "analyse a boundary-layer law (--boundary-layer PHI)")
        entry = {"kind": "impulse", "quantity": kind, "value": [1.0, 0.0, 0.0], "start": self.at}
        if kind == "force":
            entry["point"] = self.point.tolist()
        self._compiled = C.compile_chain(chain, offset=0.0)  # dT does not depend on v's offset
        self.equilibrium, initial = _rest(config, tree)
        self._layout = tree_layout(self._compiled)
        self._rest_reduced = reduce_state(self._compiled, self._layout, self.equilibrium)
        if tree:
            entry["body"] = body
        self.config = self._pushed_config(config, {**resolved, "initial_state": initial, "disturbances": own + [entry]})
        self.index = sum(1 for d in own if d.get("body") == body)  # the push's entry among its body's disturbances
        self._runs = Runs(self.config, engine=engine, executor=executor, jobs=jobs)
        self.engine = self._runs.engine
        self.runs = 0
        self.batches = 0

    @property
    def continued(self) -> int:
        """Runs still settling at t_end that were run again to a longer t_end."""
        return self._runs.continued_runs

    @property
    def continued_to(self) -> float:
        """The longest t_end [s] such runs were run to (0: none)."""
        return self._runs.continued_to

    def _pushed_config(self, config, data: dict):
        """The configuration ``data`` (the pushed one, resolved) validated, its warnings
        already shown with ``config``; a ValueError naming what is wrong."""
        from ..config import ConfigError, PhysicalPlausibilityWarning  # heavy: pydantic
        from ..config.loader import config_from_mapping  # heavy: pydantic

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
                return config_from_mapping(data, source=f"{config.name} pushed")
        except ConfigError as exc:
            raise ValueError(f"{config.name}: " + "; ".join(exc.errors)) from None

    def energy(self, vectors: np.ndarray) -> np.ndarray:
        """dT [J] of each push of ``vectors`` (k, 3) on the bodies at rest: the kinetic
        energy of the jump of the generalised velocities (:func:`rbstab.variants.tree.tree_push`;
        quadratic in the push)."""
        from ..variants.tree import tree_push, tree_work  # heavy: numba

        vectors = np.asarray(vectors, dtype=float).reshape(-1, 3)
        work = tree_work(self._compiled.size, self._compiled.n_states)
        return np.array([tree_push(self._rest_reduced.copy(), *self._compiled.args, *self._layout.args, self._member,
                                   self.point, p, self.kind == "torque", work) for p in vectors], dtype=float)

    def recovered(self, vectors: np.ndarray, energy: np.ndarray | None = None) -> np.ndarray:
        """Whether the runs pushed by ``vectors`` (k, 3) recover (:data:`RECOVERY_RULE`);
        ``energy``: their dT [J] where known. One batch."""
        vectors = np.asarray(vectors, dtype=float).reshape(-1, 3)
        k = len(vectors)
        if k == 0:
            return np.zeros(0, dtype=bool)
        energy = self.energy(vectors) if energy is None else np.asarray(energy, dtype=float)

        def rule(ok, v0, v, rows):
            with np.errstate(invalid="ignore"):
                return (ok == 1) & np.isfinite(v) & (np.abs(v) <= self.ratio * energy[rows] + ROUND_OFF)

        self.runs += k
        self.batches += 1
        return self._runs.recoveries(np.repeat(self._runs.initial_state[None], k, axis=0), rule, energy,
                                     (self._member, self.index, vectors), self.ratio)[0]


def _rest(config, tree: bool) -> tuple[np.ndarray, dict]:
    """(the full state of the configuration's tree at rest, the ``initial_state`` section that
    starts it there as the configuration writes it: by body name where ``tree``, else one
    body's keys, those its variant's state lacks as configured): the rest state of the
    undisturbed tree (its own disturbances act on the runs;
    :func:`rbstab.analysis.linearise.linearise_chain`)."""
    from ..config import INITIAL_STATE_BLOCKS  # heavy: pydantic
    from ..variants import chain as C  # heavy: numba
    from .linearise import TreeCoordinates, coordinates_of, coordinates_state, linearise_chain, undisturbed  # heavy

    calm = C.compile_chain(undisturbed(config).chain, offset=0.0)
    try:
        lin, _ = linearise_chain(calm)
    except ValueError:
        raise ValueError(f"{config.name}: the chain has no rest state near its reference configuration (its "
                         "potential falls without bound): a push from rest cannot be analysed") from None
    if not lin.is_rest_point:
        raise ValueError(f"{config.name}: the body has no equilibrium at rest (dy/dt = "
                         f"{np.max(np.abs(lin.rest_residual)):.3g} there): a push from rest cannot be analysed")
    rest = coordinates_state(calm, lin.equilibrium)
    states = {}
    reduced = TreeCoordinates(tuple(coordinates_of(calm)), tuple(calm.chain.body_names)).split(lin.equilibrium)
    for i, name in enumerate(calm.chain.body_names):
        if calm.codes[i] in (C.HINGE, C.UNIVERSAL):  # a hinge's (a universal joint's) child starts from its q, u
            m = 1 if calm.codes[i] == C.HINGE else 2
            states[name] = {key: float(reduced[key][i, 0]) if m == 1 else reduced[key][i, :m].tolist()
                            for key in ("q", "u")}
            continue
        if calm.codes[i] == C.SLIDE:  # a slide's child from its displacement and rate
            states[name] = {"q": float(reduced["translation"][i, 0]), "u": float(reduced["translation_rate"][i, 0])}
            continue
        state = dict(zip(("theta", "omega", "x", "v"), np.split(rest[12 * i: 12 * i + 12], 4)))
        if calm.d_at[i] >= 0:
            state["d"] = rest[calm.d_at[i]: calm.d_at[i] + 3]
        states[name] = {key: value.tolist() for key, value in state.items()}
    if tree:
        return rest, states
    blocks = VARIANT_LAYOUTS[config.chain.joints[0].variant].blocks
    section, (state,) = config.resolved["initial_state"], states.values()
    return rest, {key: state[key] if b in blocks else list(section[key]) for key, b in INITIAL_STATE_BLOCKS.items()}


@dataclass
class Thresholds:
    """The smallest fatal push of each of d directions (:func:`push_thresholds`).

    Attributes
    ----------
    threshold : ndarray, shape (d,)
        The smallest fatal magnitude found [N s or N m s] (inf: every rung up to the
        ladder's top recovered).
    recovering : ndarray, shape (d,)
        The largest recovering magnitude below it (its bracket's low end).
    monotone : ndarray of bool, shape (d,)
        False where a rung above the first fatal rung recovered.
    ladder : ndarray, shape (d, rungs)
        The ladder's magnitudes.
    ladder_recovered : ndarray of bool, shape (d, rungs)
    unit_energy : ndarray, shape (d,)
        dT [J] of a push of magnitude 1 along each direction.
    """

    threshold: np.ndarray
    recovering: np.ndarray
    monotone: np.ndarray
    ladder: np.ndarray
    ladder_recovered: np.ndarray
    unit_energy: np.ndarray


def _bracket_by_doubling(pushes: Pushes, u: np.ndarray, unit_energy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(top, floor) of each direction's ladder: ``top`` the first fatal magnitude of a
    doubling from :data:`FIRST_PUSH` (halving while fatal), inf where none is fatal up to
    :data:`LARGEST_PUSH`; ``floor`` the smallest magnitude the doubling saw recover (every
    floor 2^k below top recovered)."""
    d = len(u)
    s = np.full(d, FIRST_PUSH)
    lo = np.zeros(d)
    floor = np.full(d, np.inf)
    hi = np.full(d, np.inf)
    active = np.ones(d, dtype=bool)
    while active.any():
        rows = np.flatnonzero(active)
        rec = pushes.recovered(s[rows, None] * u[rows], s[rows] ** 2 * unit_energy[rows])
        lo[rows[rec]] = s[rows[rec]]
        floor[rows[rec]] = np.minimum(floor[rows[rec]], s[rows[rec]])
        hi[rows[~rec]] = s[rows[~rec]]
        s[rows] = np.where(rec, 2.0 * s[rows], 0.5 * s[rows])
        active = ((lo == 0) | np.isinf(hi)) & (s <= LARGEST_PUSH) & (s >= SMALLEST_PUSH)
    return hi, floor


def _known_recovering(ladder: np.ndarray, top: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Which rungs of ``ladder`` (d, rungs) the doubling saw recover: floor 2^k < top."""
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.log2(ladder / floor[:, None])
    return np.isfinite(k) & (k >= 0) & (k == np.round(k)) & (ladder < top[:, None])


def push_thresholds(pushes: Pushes, directions: np.ndarray, *, push_max: float | np.ndarray | None = None,
                    tol: float = DEFAULT_TOL, rungs: int = DEFAULT_RUNGS) -> Thresholds:
    """The smallest fatal push of each direction (module docstring): a ladder to
    ``push_max`` (per direction, or found by doubling), then bisection to ``tol``. The
    rungs the doubling already ran are not run again."""
    u = _unit(np.asarray(directions, dtype=float).reshape(-1, 3))
    d = len(u)
    unit_energy = pushes.energy(u)
    if push_max is None:
        top, floor = _bracket_by_doubling(pushes, u, unit_energy)
    else:
        top, floor = np.broadcast_to(np.asarray(push_max, dtype=float), (d,)).copy(), np.full(d, np.inf)
    finite_top = np.where(np.isfinite(top), top, LARGEST_PUSH)
    ladder = finite_top[:, None] * (np.arange(1, rungs + 1) / rungs)[None, :]
    recovered = np.ones((d, rungs), dtype=bool)
    if push_max is None:  # the top itself was fatal in the doubling
        recovered[:, -1] = ~np.isfinite(top)
    known = _known_recovering(ladder, top, floor)
    known[:, -1] |= push_max is None
    run = np.isfinite(top)[:, None] & ~known
    rows, cols = np.nonzero(run)
    if len(rows):
        mags = ladder[rows, cols]
        recovered[rows, cols] = pushes.recovered(u[rows] * mags[:, None], unit_energy[rows] * mags ** 2)
    fatal = ~recovered
    first = np.where(fatal.any(axis=1), fatal.argmax(axis=1), rungs)
    monotone = np.array([not recovered[i, first[i] + 1:].any() for i in range(d)])
    hi = np.where(first < rungs, ladder[np.arange(d), np.minimum(first, rungs - 1)], np.inf)
    lo = np.where(first > 0, ladder[np.arange(d), np.maximum(first - 1, 0)], 0.0)
    lo = np.where(first < rungs, lo, ladder[:, -1])
    while True:
        active = np.flatnonzero(np.isfinite(hi) & (hi - lo > tol * hi))
        if not len(active):
            break
        mid = 0.5 * (lo[active] + hi[active])
        rec = pushes.recovered(mid[:, None] * u[active], unit_energy[active] * mid ** 2)
        lo[active[rec]] = mid[rec]
        hi[active[~rec]] = mid[~rec]
    return Thresholds(threshold=hi, recovering=lo, monotone=monotone, ladder=ladder, ladder_recovered=recovered,
                      unit_energy=unit_energy)


def _around(u: np.ndarray, angle: float, m: int, rng: np.random.Generator) -> np.ndarray:
    """m unit vectors at ``angle`` [rad] from the unit vector u, evenly around it (a random
    start), shape (m, 3)."""
    helper = np.eye(3)[np.argmin(np.abs(u))]
    e1 = _unit(np.cross(u, helper))
    e2 = np.cross(u, e1)
    psi = rng.uniform(0, 2 * math.pi) + 2 * math.pi * np.arange(m) / m
    return _unit(math.cos(angle) * u[None] + math.sin(angle) * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2))


@dataclass
class PushAnalysis:
    """The push-recovery analysis of one configuration (:func:`push_analysis`).

    Attributes
    ----------
    kind : {"force", "torque"}
        Force impulse P at ``point`` (inertial frame), or torque impulse L (body frame).
    units : str
        Of every magnitude: "N s" or "N m s".
    point : ndarray, shape (3,)
        R_p [m], body frame, from the centre of mass (zeros for a torque).
    at, tol, ratio : float
        t0 [s]; the thresholds' relative tolerance; the recovery rule's ratio.
    rungs : int
    directions : ndarray, shape (d, 3)
        Unit vectors (force: inertial frame; torque: body frame).
    thresholds : Thresholds
        Per direction.
    unit_energy : ndarray, shape (d,)
        dT [J] of a push of magnitude 1 along each direction (dT grows with its square).
    refined_directions : ndarray, shape (m, 3)
        The local search's directions (none with given directions or refine=False).
    refined_thresholds : ndarray, shape (m,)
        NaN for a direction that recovered at the minimum found before it (its threshold
        is not below it, and was not computed).
    refined_unit_energy : ndarray, shape (m,)
        dT [J] of a push of magnitude 1 along each refined direction.
    engine : str
    runs, batches : int
        Runs integrated and batches they took.
    seconds : float
        Wall time [s].
    body : str or None
        A chain's body pushed (``point`` and a torque in its frame); None for one body.
    continued : int
        Runs still settling at t_end run again to a longer t_end (:meth:`Runs.recoveries`).
    continued_to : float
        The longest t_end [s] they were run to (0: none).
    """

    name: str
    kind: str
    units: str
    point: np.ndarray
    at: float
    tol: float
    ratio: float
    rungs: int
    directions: np.ndarray
    thresholds: Thresholds
    unit_energy: np.ndarray
    refined_directions: np.ndarray
    refined_thresholds: np.ndarray
    engine: str
    runs: int = 0
    batches: int = 0
    seconds: float = 0.0
    refined_unit_energy: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    body: str | None = None
    continued: int = 0
    continued_to: float = 0.0

    def fatal_starts(self) -> tuple[np.ndarray, Callable[[int], str]]:
        """(v [J] just after the smallest fatal push of each direction, the grid's then the
        local search's, NaN where none was fatal; the name of each such run)."""
        t = np.concatenate([self.threshold, self.refined_thresholds])
        e = np.concatenate([self.unit_energy, self.refined_unit_energy[:len(self.refined_thresholds)]])
        e = np.pad(e, (0, len(t) - len(e)), constant_values=np.nan)
        u = np.concatenate([self.directions, self.refined_directions])
        with np.errstate(invalid="ignore"):
            v = np.where(np.isfinite(t), e * t ** 2, np.nan)

        def name(i: int) -> str:
            return (f"the {self.kind} push of {t[i]:.4g} {self.units} along "
                    f"({', '.join(f'{x:+.3f}' for x in u[i])})")

        return v, name

    def estimate(self, sublevel: float) -> float:
        """The smallest push the sublevel set {v <= c} holds (c = ``sublevel`` [J]): the
        minimum over the directions of sqrt(c / dT(u)) [N s or N m s] (NaN without c)."""
        if not (sublevel >= 0):
            return math.nan
        e = np.concatenate([self.unit_energy, self.refined_unit_energy])
        e = e[np.isfinite(e) & (e > 0)]
        return float(np.min(np.sqrt(sublevel / e))) if len(e) else math.inf

    @property
    def rule_text(self) -> str:
        """:data:`RECOVERY_RULE` with this analysis's ratio."""
        return RECOVERY_RULE.replace("ratio", f"{self.ratio:g}", 1)

    @property
    def threshold(self) -> np.ndarray:
        """The smallest fatal magnitude per direction, shape (d,) (inf: none found)."""
        return self.thresholds.threshold

    @property
    def grid_minimum(self) -> float:
        """The smallest threshold over :attr:`directions`."""
        return float(np.min(self.threshold))

    @property
    def minimum(self) -> float:
        """The smallest threshold found, the local search included."""
        found = np.concatenate([self.threshold, self.refined_thresholds])
        return float(np.nanmin(found))

    @property
    def minimum_direction(self) -> np.ndarray:
        """Its direction, shape (3,)."""
        found = np.concatenate([self.threshold, self.refined_thresholds])
        return np.concatenate([self.directions, self.refined_directions])[int(np.nanargmin(found))]

    @property
    def weakest(self) -> int:
        """The index of the direction of :attr:`directions` with the smallest threshold."""
        return int(np.argmin(self.threshold))

    @property
    def refinement_gain(self) -> float:
        """How much the local search lowered the minimum, relative (0: not at all)."""
        g = self.grid_minimum
        return float((g - self.minimum) / g) if math.isfinite(g) and g > 0 else 0.0

    @property
    def monotone(self) -> bool:
        """Whether recovery was monotone in the magnitude along every direction's ladder."""
        return bool(np.all(self.thresholds.monotone))

    def to_json(self) -> dict[str, Any]:
        """The ``push`` record of ``--json`` (inf as null)."""

        def num(x):
            return float(x) if math.isfinite(x) else None

        return {
            "kind": self.kind,
            "units": self.units,
            **({"body": self.body} if self.body is not None else {}),
            "point": self.point.tolist(),
            "at": self.at,
            "tol": self.tol,
            "rule": self.rule_text,
            "ratio": self.ratio,
            "directions": self.directions.tolist(),
            "threshold": [num(x) for x in self.threshold],
            "monotone": self.thresholds.monotone.tolist(),
            "minimum": {"threshold": num(self.minimum), "direction": self.minimum_direction.tolist(),
                        "before_refinement": num(self.grid_minimum), "lowered_by": self.refinement_gain},
            "runs": self.runs,
            "continued": {"runs": self.continued, "to": self.continued_to},
            "engine": self.engine,
        }


def push_analysis(config, kind: str, *, directions: int | np.ndarray = 64, point=None, at: float = 0.0,
                  push_max: float | None = None, tol: float = DEFAULT_TOL, rungs: int = DEFAULT_RUNGS,
                  seed: int = 0, ratio: float = DEFAULT_LYAPUNOV_RATIO, engine: str = "compiled", executor=None,
                  refine: bool | None = None, say: Callable[[str], None] | None = None, body: str | None = None,
                  jobs: int = 1) -> PushAnalysis:
    """The smallest fatal push of each direction, and its minimum over directions.

    Parameters
    ----------
    config : RunConfig
        Validated. The runs use its body, controller, saturation, limits and simulation
        settings; they start at rest at its equilibrium (:class:`Pushes`). A chain is
        pushed on ``body``.
    kind : {"force", "torque"}
    directions : int or array_like, shape (d, 3)
        n quasi-uniform directions (:func:`push_directions` with ``seed``), or the
        directions themselves (not normalised needed).
    point : (3,) float, optional
        Force only: R_p [m], body frame, from the centre of mass (default 0).
    at : float
        t0 [s] of the push.
    push_max : float, optional
        The ladder's top [N s or N m s] (default: found by doubling, per direction).
    tol : float
        Relative tolerance of a threshold (0 < tol < 1).
    rungs : int
        Rungs of the ladder (>= 2).
    seed : int
        Of the directions and the local search.
    ratio : float
        Of :data:`RECOVERY_RULE`.
    engine : {"compiled", "cuda"}
    executor : rbstab.sweep.executors.Executor, optional
    refine : bool, optional
        Search around the weakest directions (default: with n directions, not with
        given ones).
    say : callable, optional
        Progress lines.

    Returns
    -------
    PushAnalysis

    Raises
    ------
    ValueError
        For a bad option or a configuration that cannot be pushed (one line each).
    """
    start = _time.perf_counter()
    given = not np.isscalar(directions)
    check_push_options(kind, point=point, directions=directions, push_max=push_max, tol=tol, rungs=rungs, at=at)
    u = _unit(np.asarray(directions, dtype=float).reshape(-1, 3)) if given else push_directions(int(directions), seed)
    pushes = Pushes(config, kind, body=body, point=point, at=at, ratio=ratio, engine=engine, executor=executor,
                    jobs=jobs)
    found = push_thresholds(pushes, u, push_max=push_max, tol=tol, rungs=rungs)
    refined_u = np.zeros((0, 3))
    refined_t = np.zeros(0)
    if (not given if refine is None else refine) and np.isfinite(found.threshold).any():
        refined_u, refined_t = _refine(pushes, u, found.threshold, tol=tol, rungs=rungs, seed=seed)
    if say is not None:
        say(f"  push: {pushes.runs} runs in {pushes.batches} batches")
    return PushAnalysis(name=config.name, kind=kind, units=PUSH_KINDS[kind],
                        point=pushes.point if kind == "force" else np.zeros(3), at=float(at), tol=float(tol),
                        ratio=float(ratio), rungs=int(rungs), directions=u, thresholds=found,
                        unit_energy=found.unit_energy,
                        refined_directions=refined_u, refined_thresholds=refined_t,
                        refined_unit_energy=pushes.energy(refined_u) if len(refined_u) else np.zeros(0),
                        engine=pushes.engine, runs=pushes.runs, batches=pushes.batches,
                        seconds=_time.perf_counter() - start, body=pushes.body,
                        continued=pushes.continued, continued_to=pushes.continued_to)


def _refine(pushes: Pushes, u: np.ndarray, threshold: np.ndarray, *, tol: float, rungs: int,
            seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A local search around the weakest directions: :data:`REFINE_ROUNDS` rounds of
    :data:`REFINE_AROUND` directions at an angle around each of the :data:`REFINE_WORST`
    weakest found so far, the angle halved each round (from half the directions' mean
    spacing). A new direction is first pushed at the minimum so far, m (1 - tol): only if
    that is fatal is its threshold found (a ladder to there, then bisection). Returns the
    directions tried and their thresholds (NaN: it recovered at m (1 - tol), so its
    threshold is not below the minimum)."""
    rng = np.random.default_rng(seed)
    angle = 0.5 * math.sqrt(4 * math.pi / len(u))
    all_u, all_t = u, threshold
    tried_u, tried_t = [np.zeros((0, 3))], [np.zeros(0)]
    for _ in range(REFINE_ROUNDS):
        known = np.where(np.isnan(all_t), np.inf, all_t)
        worst = np.argsort(known, kind="stable")[:REFINE_WORST]
        worst = worst[np.isfinite(known[worst])]
        if not len(worst):
            break
        new = np.concatenate([_around(all_u[i], angle, REFINE_AROUND, rng) for i in worst])
        screen = (1.0 - tol) * float(known[worst[0]])
        found = np.full(len(new), np.nan)
        weaker = ~pushes.recovered(screen * new)
        if weaker.any():
            found[weaker] = push_thresholds(pushes, new[weaker], push_max=screen, tol=tol, rungs=rungs).threshold
        tried_u.append(new)
        tried_t.append(found)
        all_u = np.concatenate([all_u, new])
        all_t = np.concatenate([all_t, found])
        angle *= 0.5
    return np.concatenate(tried_u), np.concatenate(tried_t)


# -- basin stability ---------------------------------------------------------------------------

#: The recovery rule of drawn initial states: the sweeps' convergence rule.
STATE_RULE = ("recovered = converged by the sweeps' rule (docs/sweeps.md), inside simulation.limits; a run still "
              "settling at t_end (0 <= v(t_end) <= v(0)) judged at a longer t_end")


@dataclass
class BasinStability:
    """The fraction of N random perturbations a configuration recovers from (Menck et al.
    2013), :func:`basin_stability`.

    Attributes
    ----------
    name : str
    perturbation : {"initial_state", "push"}
        Drawn initial-state entries (the other entries as configured), or pushes of a
        uniform random direction and a magnitude uniform in a range, from rest at the
        equilibrium.
    keys : list of str
        What was drawn: ``initial_state.omega.0`` ..., or ``push_magnitude``,
        ``push_direction_x`` ... ``_z``.
    units : list of str
    low, high : ndarray, shape (n_keys,)
        The box drawn from (uniform).
    values : ndarray, shape (N, n_keys)
        The draws.
    recovered : ndarray of bool, shape (N,)
    lyapunov_start : ndarray, shape (N,)
        v [J] where each draw starts: v of the drawn state, or dT of the drawn push (v just
        after it).
    confidence : float
    interval : (float, float)
        Wilson score interval of the fraction at ``confidence``.
    separations : list of Separation
        Per key, how it separates recovering from failing draws, where both occur: its
        ``rule`` (:func:`rbstab.analysis.thresholds.split_rule`: recovered below, above,
        inside or outside thresholds, with its balanced accuracy and whether it explains the
        outcome) and its AUC.
    rule : str
    seed, runs : int
    seconds : float
    """

    name: str
    perturbation: str
    keys: list
    units: list
    low: np.ndarray
    high: np.ndarray
    values: np.ndarray
    recovered: np.ndarray
    lyapunov_start: np.ndarray
    confidence: float
    interval: tuple
    separations: list
    rule: str
    seed: int
    engine: str
    kind: str | None = None
    seconds: float = 0.0

    @property
    def draws(self) -> int:
        return len(self.recovered)

    @property
    def fraction(self) -> float:
        """Recovering draws / draws."""
        return float(self.recovered.mean()) if self.draws else math.nan

    def to_json(self) -> dict[str, Any]:
        """The ``basin_stability`` record of ``--json`` (a threshold the rule has not as null)."""

        def num(x):
            return float(x) if math.isfinite(x) else None

        return {
            "perturbation": self.perturbation, "kind": self.kind, "keys": list(self.keys), "units": list(self.units),
            "low": self.low.tolist(), "high": self.high.tolist(), "draws": self.draws, "seed": self.seed,
            "recovered": int(self.recovered.sum()), "fraction": self.fraction, "interval": list(self.interval),
            "confidence": self.confidence, "rule": self.rule,
            "separations": [{"key": s.parameter, "recovered_side": s.rule.side,
                             "threshold_low": num(s.rule.low), "threshold_high": num(s.rule.high),
                             "balanced_accuracy": s.rule.balanced_accuracy, "explains": s.rule.explains,
                             "auc": s.auc} for s in self.separations],
            "engine": self.engine,
        }


def parse_ranges(texts: Sequence[str]) -> list[tuple[Any, float, float]]:
    """(BasinAxis of the entry, lo, hi) of each ``KEY=LO:HI`` (an initial-state entry; a
    configuration's state has it where :func:`rbstab.analysis.runs.check_entries` says so);
    ValueError naming the text otherwise."""
    from .basin import BasinAxis  # heavy: numba (the basin map's engine)

    out = []
    for text in texts:
        key, _, bounds = text.partition("=")
        parts = bounds.split(":")
        if not key or len(parts) != 2:
            raise ValueError(f"--basin-stability {text!r}: expected KEY=LO:HI, e.g. initial_state.omega.0=-3:3")
        try:
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise ValueError(f"--basin-stability {text!r}: LO and HI must be numbers") from None
        try:
            axis = BasinAxis.parse(f"{key}={lo!r}:{hi!r}:2")
        except ValueError as exc:
            raise ValueError(str(exc).replace("--basin", "--basin-stability").replace(":2", "")
                             .replace("KEY=lo:hi:n", "KEY=LO:HI")) from None
        out.append((axis, lo, hi))
    keys = [a.key for a, _, _ in out]
    if len(set(keys)) != len(keys):
        raise ValueError(f"--basin-stability: an entry is given twice ({', '.join(keys)})")
    return out


def parse_push_range(text: str) -> tuple[float, float]:
    """(lo, hi) of ``--push-distribution LO:HI`` (0 <= LO < HI, finite)."""
    parts = str(text).split(":")
    try:
        lo, hi = (float(parts[0]), float(parts[1])) if len(parts) == 2 else (math.nan, math.nan)
    except ValueError:
        lo = hi = math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
        raise ValueError(f"--push-distribution: found {text!r}; expected LO:HI, magnitudes with 0 <= LO < HI")
    return lo, hi


def basin_stability(config, *, ranges: Sequence[str] = (), push: str | None = None, push_range=None, point=None,
                    at: float = 0.0, draws: int = 1000, seed: int = 0, ratio: float = DEFAULT_LYAPUNOV_RATIO,
                    confidence: float = 0.95, engine: str = "compiled", executor=None, body: str | None = None,
                    jobs: int = 1) -> BasinStability:
    """The fraction of ``draws`` random perturbations that recover, with its Wilson interval.

    Parameters
    ----------
    config : RunConfig
        Validated. A chain's entries are ``initial_state.<body>.<block>.<i>`` (the bodies
        the configuration places re-placed on their joints), its pushes act on ``body``
        (:class:`Pushes`).
    ranges : sequence of str
        ``KEY=LO:HI`` initial-state entries drawn uniformly (the other entries as
        configured); a draw recovers when it converges by the sweeps' rule
        (:mod:`rbstab.convergence`) without leaving ``simulation.limits``.
    push : {"force", "torque"}, optional
        With ``push_range`` (lo, hi) instead of ``ranges``: pushes from rest at the
        equilibrium, a direction uniform on the sphere and a magnitude uniform in
        [lo, hi] [N s or N m s], recovering by :data:`RECOVERY_RULE`; ``point`` and ``at``
        as :class:`Pushes` takes them.
    draws : int
        N >= 1.
    seed : int
    ratio, confidence : float
    engine, executor
        As :func:`push_analysis`.

    Raises
    ------
    ValueError
        For a bad option (one line naming it).
    """
    from .robustness import separation, wilson_interval  # heavy: scipy.stats

    start = _time.perf_counter()
    if int(draws) < 1:
        raise ValueError(f"-n: found {draws}; expected an integer >= 1 (draws)")
    if bool(ranges) == (push_range is not None):
        raise ValueError("--basin-stability: give initial-state entries KEY=LO:HI or --push-distribution LO:HI "
                         "(with --push force|torque), one of the two")
    rng = np.random.default_rng(seed)
    if push_range is not None:
        if push is None:
            raise ValueError("--push-distribution: give the quantity pushed with --push force|torque")
        lo, hi = parse_push_range(push_range) if isinstance(push_range, str) else map(float, push_range)
        check_push_options(push, point=point, at=at)
        pushes = Pushes(config, push, body=body, point=point, at=at, ratio=ratio, engine=engine, executor=executor,
                        jobs=jobs)
        u = _unit(rng.normal(size=(int(draws), 3)))
        magnitude = rng.uniform(lo, hi, size=int(draws))
        start_v = pushes.energy(magnitude[:, None] * u)
        recovered = pushes.recovered(magnitude[:, None] * u, start_v)
        keys = ["push_magnitude", "push_direction_x", "push_direction_y", "push_direction_z"]
        units = [PUSH_KINDS[push], "1", "1", "1"]
        values = np.column_stack([magnitude, u])
        low, high = np.array([lo, -1.0, -1.0, -1.0]), np.array([hi, 1.0, 1.0, 1.0])
        perturbation, rule, engine = "push", RECOVERY_RULE, pushes.engine
    else:
        axes = parse_ranges(ranges)
        low = np.array([lo for _, lo, _ in axes])
        high = np.array([hi for _, _, hi in axes])
        values = rng.uniform(low, high, size=(int(draws), len(axes)))
        runs = Runs(config, engine=engine, executor=executor, jobs=jobs)
        recovered, start_v = runs.recoveries(_drawn_states(config, runs, axes, values),
                                             lambda ok, v0, v1, rows: converged(ok == 1, v0, v1, ratio), ratio=ratio)
        keys = [a.key for a, _, _ in axes]
        units = [a.units for a, _, _ in axes]
        perturbation, rule, engine = "initial_state", STATE_RULE, runs.engine
    k, n = int(recovered.sum()), len(recovered)
    found = [separation(key, values[:, i], recovered) for i, key in enumerate(keys)]
    return BasinStability(name=config.name, perturbation=perturbation, keys=keys, units=units, low=low, high=high,
                          values=values, recovered=recovered, lyapunov_start=start_v, confidence=float(confidence),
                          interval=wilson_interval(k, n, confidence), separations=[s for s in found if s is not None],
                          rule=rule, seed=int(seed), engine=engine, kind=push if push_range is not None else None,
                          seconds=_time.perf_counter() - start)


def _drawn_states(config, runs: Runs, axes, values: np.ndarray) -> np.ndarray:
    """The initial states (N, n_states) of the runs of ``runs`` with the drawn entries
    ``values`` (N, n_axes) of ``axes`` (:func:`parse_ranges`;
    :meth:`rbstab.analysis.runs.Runs.states`). ValueError (one line) for an entry the state
    lacks, or one body's box that reaches gimbal lock."""
    entries = [a for a, _, _ in axes]
    try:
        check_entries(config, entries)
    except ValueError as exc:
        raise ValueError(str(exc).replace("--basin ", "--basin-stability ", 1)) from None
    for axis, lo, hi in axes if runs.compiled.one_body else ():  # the paper's body, in either spelling
        if axis.block == "theta" and axis.index == 1:
            from ..kinematics import GIMBAL_LOCK_ANGLE  # heavy: numba
            from .basin import OUTSIDE  # heavy: numba

            limit = GIMBAL_LOCK_ANGLE - config.simulation.gimbal_margin
            if max(abs(lo), abs(hi)) >= limit:
                raise ValueError(f"--basin-stability {axis.key}={lo:g}:{hi:g}: the box reaches |theta_2| >= "
                                 f"{limit:.4g} rad: {OUTSIDE.split(': ', 1)[1]}")
    return runs.states(entries, values)


def runs_from_states(config, states: np.ndarray, *, engine: str = "compiled", executor=None,
                     jobs: int = 1) -> np.ndarray:
    """The outcomes of the runs of ``config`` (one body or a tree) from ``states`` (k,
    n_states; :attr:`rbstab.analysis.runs.Runs.initial_state`'s layout, the full state): shape (3, k),
    success (1 or 0), v(0) and v(t_end) [J] (NaN for a run that stopped early). One batch
    (:meth:`rbstab.analysis.runs.Runs.outcomes`)."""
    return Runs(config, engine=engine, executor=executor, jobs=jobs).outcomes(states)
