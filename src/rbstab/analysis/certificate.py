"""The Lyapunov certificate of an equilibrium: v there, its Hessian, the Hessian of dv/dt,
dv/dt <= 0 on sampled states, and a sublevel set of v as an inner estimate of the region
of attraction.

v is the configuration's Lyapunov function as the runs record it (eqs 25, 30, 31, 41, 44; zero
at the equilibrium by the constant h), and the analytic dv/dt its ``lyapunov_rate``
(eqs 29, 37, 43, 46). Local part, at the equilibrium y_e:

- v(y_e) = 0 and the Hessian H_v of v positive definite (v has a strict minimum);
- the Hessian H_r of dv/dt: with dv/dt <= 0 and zero at y_e it is negative
  semi-definite. Its generalised eigenvalues mu (H_r w = mu H_v w) [1/s] say how: all
  mu < 0, negative definite (v is a strict Lyapunov function near y_e); some mu = 0,
  semi-definite, and asymptotic stability rests on LaSalle's invariance principle. Its
  local form is checked: no mode of the linearisation A may stay where dv/dt vanishes
  to second order (the Popov-Belevitch-Hautus test, rank [A - sI; H_r] = n for every
  eigenvalue s of A).

Sampled part: states y = y_e + S z around y_e, with S = H_v^(-1/2) (so that v ~ |z|^2/2)
and |z|^2/2 log-uniform over six decades up to 1.5 times the level of the domain
boundary (below). At each, dv/dt is computed twice: the analytic rate, and the rate of v
along the right-hand side f from v alone, d/ds v(y + s f) at s = 0 (central differences,
:func:`rbstab.analysis.derivatives.directional_derivative`), so a sign error in either
formula shows. The sublevel estimate is the largest c such that no sampled state with
v < c has a numerical dv/dt > 0 or lies outside the model's domain, and c is at most the
least v on the domain boundary |theta_2| = pi/2 - gimbal_margin (eq 5; minimised there
over the other coordinates, at rest: the kinetic terms of v are >= 0). By LaSalle,
{v <= c} is then an inner estimate of the region of attraction, valid as far as the search
for dv/dt > 0 is complete. Sampling misses thin regions (where a torque clips, the states
with dv/dt > 0 at low levels are a sliver), so a local search (:class:`_LevelSearch`, scipy's
SLSQP) starts from the samples nearest a violation: the largest dv/dt on a sample's level
set, then the least v where dv/dt > 0. c is computed from the first N/4, N/2 and N samples,
each with its search (the history; :attr:`Certificate.settled`). It stays an *estimate*:
:func:`checked` lowers it where a simulated run contradicts it
(:mod:`rbstab.analysis.evidence`).

The model is anything with the small protocol of :class:`Model` (v, the analytic dv/dt, the
right-hand side f, the domain's angles, the least v on the domain boundary and the map to
the state a run starts from): the compiled tree in its independent coordinates
(:class:`ChainModel`, on the constraint manifold of its permanent joints; one body's are its
own state).

With disturbances (``disturbed``), the local part is of the undisturbed dynamics and the
sampled part of the disturbed ones: each sampled state at a time drawn uniformly in
[0, t_end], its dv/dt with the disturbances' power then (an impulse is a jump of the
velocities, not a rate: the samples do not see it; a basin map's runs do).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from ..kinematics import GIMBAL_LOCK_ANGLE
from .derivatives import directional_derivative, hessian, jacobian

__all__ = ["Certificate", "Model", "ChainModel", "coordinate_boundary_level",
           "constrained_boundary_level", "certify",
           "checked", "level_states", "DEFINITE_RTOL", "RATE_RTOL", "DEFAULT_SAMPLES",
           "RATE_DEFINITENESS", "SETTLED_RTOL"]

#: [m]: a tree without angles (its joints slides) has no domain boundary; its samples reach the
#: least v with a slide's q at +-this (at rest, the other coordinates free).
SLIDE_REACH = 1.0
#: Eigenvalues of a scaled Hessian within this of zero (relative to the largest) are zero.
DEFINITE_RTOL = 1e-8
#: A sampled dv/dt is positive when above this times the state's power scale (and its error).
RATE_RTOL = 1e-8
#: Sampled states of the dv/dt check (single and spec analyses alike).
DEFAULT_SAMPLES = 10_000
#: Local searches from the samples: this many from the positive samples of least v, and as
#: many from the samples below c with the largest relative dv/dt.
REFINE_STARTS = 8
#: The history of c: from the first N / d samples, for each d.
HISTORY_DIVISORS = (4, 2, 1)
#: An estimate is still moving when c from N / 2 samples exceeds c from N by more than this
#: (relative).
SETTLED_RTOL = 0.01
#: The local minimisation of v keeps dv/dt >= this times rho v (rho the spectral radius of
#: the linearisation): a strict inequality, away from the rest states where dv/dt = 0.
_RATE_MARGIN = 1e-7
#: How the Hessian of dv/dt may be, in the order of preference.
RATE_DEFINITENESS = ("negative definite", "negative semi-definite", "indefinite")
#: Decades of v spanned by the samples, below the top level.
_DECADES = 6.0
#: The samples reach this times the level of the domain boundary.
_REACH = 1.5
#: Step of the central differences of a chain's joint angle's gradient [units of its coordinates].
_ANGLE_STEP = 1e-7
#: Bound names of the sublevel estimate.
BOUNDS = ("domain boundary", "dv/dt > 0 at a sampled state", "sampled state outside the domain",
          "non-finite value at a sampled state", "v not positive definite",
          "dv/dt > 0 at a state found by the local search",
          "a simulated run from inside counted against it (see the note)")


class Model(Protocol):
    """What the certificate needs of a model, in its coordinates x (n,; stacks (k, n)).

    ``lyapunov(x)`` -> v (k,) [J]; ``evaluate(x, t)`` -> a mapping with ``"lyapunov"`` and
    ``"lyapunov_rate"`` (the analytic dv/dt [W]) (k,) at the times ``t`` (scalar or (k,));
    ``rhs(t, x)`` -> dx/dt (k, n); ``angles(x)`` -> (k, m) the angles [rad] whose
    |value| must stay below pi/2 - gimbal_margin (the domain); ``angle_matrix``: (m, n) where
    the angles are linear in x (angles = angle_matrix @ x), else None (then
    ``angle_jacobian(x)`` -> (m, n)); ``boundary_level(y_e, hess, limit)`` -> the least v on
    the domain boundary [J]; ``states(x)`` -> the states (k, n_states) a run starts from."""

    angle_matrix: np.ndarray | None

    def lyapunov(self, x: np.ndarray) -> np.ndarray: ...

    def evaluate(self, x: np.ndarray, t=0.0) -> dict: ...

    def rhs(self, t, x: np.ndarray) -> np.ndarray: ...

    def angles(self, x: np.ndarray) -> np.ndarray: ...

    def angle_jacobian(self, x: np.ndarray) -> np.ndarray: ...

    def boundary_level(self, y_e: np.ndarray, hess: np.ndarray, limit: float) -> float: ...

    def states(self, x: np.ndarray) -> np.ndarray: ...


class ChainModel:
    """A compiled chain (:class:`rbstab.variants.chain.CompiledChain`) as a :class:`Model`
    in its linearisation's coordinates z (:func:`rbstab.analysis.linearise.coordinates_of`:
    Theta_i, Omega_i of every body; X_i, V_i of bodies whose joint is not ``permanent``; D of
    embedded joints; a tree with a hinge: its reduced state, every angle of the domain a
    coordinate, a hinge's |q| among them).

    A state is :func:`rbstab.variants.chain.full_state` of z: the children of permanent
    joints placed on their parents (E_j = F_j = 0), so every sample lies on the constraint
    manifold, where the constraint power F_j' Lambda_j of the analytic rate vanishes. v and
    the analytic dv/dt are :func:`rbstab.variants.chain.evaluate`'s at those states
    (docs/physics.md, "v and dv/dt"); f is :func:`rbstab.analysis.linearise.reduced_rates`. The
    domain is |theta_2| < pi/2 - gimbal_margin of every body and of every joint's relative
    orientation Theta_j (the chain's runs stop at either); its boundary level is the least
    v there at rest (:func:`constrained_boundary_level`: a joint's angle is not a
    coordinate).

    Attributes
    ----------
    compiled : CompiledChain
    coordinates : list of (str, str, int)
        :func:`rbstab.variants.chain.independent_coordinates`.
    angle_names : list of str
        The domain's angles, in the order of :meth:`angles`: ``"<body>.theta_2"`` of each
        body, then ``"<joint>.theta_2"`` of each joint whose parent is a body.
    angle_matrix : ndarray or None
        (bodies, n) where every angle is a coordinate (no joint has a body for parent), else None.
    """

    def __init__(self, compiled, coordinates=None) -> None:
        from .linearise import coordinates_of  # heavy: numba

        self.compiled = compiled
        self.coordinates = list(coordinates_of(compiled) if coordinates is None else coordinates)
        self._at = [int(at) for _, _, at, _ in self.coordinates]
        self.n = sum(size for _, _, _, size in self.coordinates)
        names = list(compiled.chain.body_names)
        if compiled.hinged:  # reduced coordinates: every angle of the domain is one of them
            self._theta, self.angle_names, at = [], [], 0
            for i, (body, block, _, size) in enumerate(self.coordinates):
                part = compiled.chain.joint_names[names.index(body)] if block != "theta" else body
                if block in ("theta", "joint_theta"):
                    self._theta.append(at + 1)
                    self.angle_names.append(f"{part}.theta_2")
                elif block == "q":  # a hinge's q, a universal joint's q_1, q_2
                    self._theta += [at + k for k in range(size)]
                    self.angle_names += [f"{part}.q" if size == 1 else f"{part}.q_{k + 1}" for k in range(size)]
                at += size
            self._parented = []
            self.angle_matrix = np.eye(self.n)[self._theta]
            return
        self._theta = [3 * self._at.index(12 * i) + 1 for i in range(compiled.size)]  # theta_2 of each body in z
        self._parented = [j for j in range(compiled.size) if compiled.parents[j] >= 0]
        self.angle_names = [f"{b}.theta_2" for b in names] + [f"{compiled.chain.joint_names[j]}.theta_2"
                                                               for j in self._parented]
        if self._parented:
            self.angle_matrix = None
        else:
            self.angle_matrix = np.eye(self.n)[self._theta]

    def states(self, x) -> np.ndarray:
        """The chain's full states (k, n_states) of the independent coordinates ``x`` (k, n)
        (:func:`rbstab.analysis.linearise.coordinates_state`)."""
        from .linearise import coordinates_state  # heavy: numba

        return coordinates_state(self.compiled, np.atleast_2d(np.asarray(x, dtype=float)))

    # -- v, dv/dt, f ----------------------------------------------------------------------------
    def _outputs(self, x, t=0.0) -> dict:
        from ..variants import chain as C  # heavy: numba

        states = self.states(x)
        if not self.compiled.hinged:
            return C.evaluate(self.compiled, t, states, full=False)  # v, dv/dt and the angles only
        # each state a run of its own: a hinge's angle read in (-pi, pi], not continued from the row before
        t = np.broadcast_to(np.asarray(t, dtype=float), len(states))
        out = C.evaluate(self.compiled, t[:, None], states[:, None], full=False)
        return {key: value[:, 0] for key, value in out.items()}

    def lyapunov(self, x):
        """v [J] at each row of ``x`` (a float for one state (n,))."""
        v = self._outputs(x)["lyapunov"]
        return float(v[0]) if np.ndim(x) == 1 else v

    def evaluate(self, x, t=0.0) -> dict:
        """v [J], the analytic dv/dt [W] and the angles (:meth:`angles`) at each row of ``x``
        at the times ``t`` [s]."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        out = self._outputs(x, t)
        return {"lyapunov": out["lyapunov"], "lyapunov_rate": out["lyapunov_rate"],
                "angles": self._angles_of(x, out)}

    def rhs(self, t, x) -> np.ndarray:
        """dz/dt at each row of ``x`` (:func:`rbstab.analysis.linearise.reduced_rates`)."""
        from .linearise import reduced_rates  # heavy: numba

        return reduced_rates(self.compiled, x, t)

    # -- the domain ----------------------------------------------------------------------------
    def angles(self, x) -> np.ndarray:
        """(k, m) theta_2 [rad] of every body, then of every joint whose parent is a body."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return self._angles_of(x, self._outputs(x) if self._parented else None)

    def _angles_of(self, x: np.ndarray, out) -> np.ndarray:
        body = x[:, self._theta]
        if not self._parented:
            return body
        return np.concatenate([body, out["joint_theta"][:, self._parented, 1]], axis=1)

    def angle_jacobian(self, x) -> np.ndarray:
        """(m, n) d angles / dx at the state ``x`` (n,) (central differences)."""
        if self.angle_matrix is not None:
            return self.angle_matrix
        x = np.asarray(x, dtype=float)
        steps = _ANGLE_STEP * np.eye(self.n)
        values = self.angles(np.concatenate([x + steps, x - steps]))
        return ((values[: self.n] - values[self.n:]) / (2 * _ANGLE_STEP)).T

    def boundary_level(self, y_e, hess, limit) -> float:
        """The least v [J] on the domain boundary (any angle at +-limit), at rest: where every
        angle is a coordinate (no joint has a body for parent), :func:`coordinate_boundary_level`;
        else :func:`constrained_boundary_level`."""
        starts = np.cumsum([0] + [size for _, _, _, size in self.coordinates])
        free = [int(at) + a for (_, block, _, size), at in zip(self.coordinates, starts)
                if block in ("theta", "position", "controller_state", "joint_theta", "q", "translation")
                for a in range(size)]
        y_e = np.asarray(y_e, dtype=float)
        if self.angle_matrix is not None and not self._theta:  # no angle (slides only): no domain boundary;
            slides = [int(at) for (_, block, _, _), at in zip(self.coordinates, starts) if block == "translation"]
            return coordinate_boundary_level(self.lyapunov, y_e, hess, SLIDE_REACH, slides, free)  # sampled to
        if self.angle_matrix is not None:                                                # |q| = SLIDE_REACH
            return coordinate_boundary_level(self.lyapunov, y_e, hess, limit, self._theta, free)
        return constrained_boundary_level(self, y_e, hess, limit, np.array(free))


@dataclass(frozen=True)
class Certificate:
    """The Lyapunov certificate of one equilibrium (module docstring).

    Attributes
    ----------
    lyapunov_equilibrium : float
        v(y_e) [J] (zero up to round-off).
    lyapunov_hessian : ndarray, shape (n, n)
        H_v [J per unit of each state squared].
    hessian_min_eigenvalue : float
        Smallest eigenvalue of H_v as it stands (mixed units).
    positive_definite : bool
        H_v positive definite (decided on the Jacobi-scaled matrix, :data:`DEFINITE_RTOL`).
    rate_hessian : ndarray, shape (n, n)
        H_r, the Hessian of the analytic dv/dt [W per unit squared].
    rate_eigenvalues : ndarray, shape (n,)
        Generalised eigenvalues mu of (H_r, H_v), ascending [1/s] (NaN if H_v is not
        positive definite).
    rate_definiteness : str
        One of :data:`RATE_DEFINITENESS`.
    lasalle_observable : bool
        The PBH test: no mode of the linearisation stays where dv/dt vanishes.
    n_samples : int
        Sampled states.
    sample_lyapunov, sample_rate, sample_rate_analytic : ndarray, shape (n_samples,)
        v [J], numerical and analytic dv/dt [W] at each sample (NaN outside the domain).
    sample_outside : ndarray of bool, shape (n_samples,)
        Samples outside the domain (|theta_2| >= pi/2 - gimbal_margin).
    worst_state : ndarray, shape (n,)
        The sample inside the domain with the largest numerical dv/dt relative to its
        power scale.
    worst_rate : float
        Its numerical dv/dt [W].
    worst_lyapunov : float
        Its v [J].
    rate_mismatch : float
        Largest |numerical - analytic dv/dt| over the samples, relative to each state's
        power scale (|analytic| + rho v, rho the spectral radius of the linearisation).
    boundary_level : float
        The least v on the domain boundary [J].
    sublevel : float
        c of the inner estimate {v <= c} [J] (0 when there is none).
    sublevel_bound : str
        What limits c (one of :data:`BOUNDS`).
    samples_inside : int
        Samples with v <= c.
    sublevel_sampled : float
        c from the samples alone [J].
    history_samples : ndarray of int, shape (3,)
        N / 4, N / 2 and N.
    sublevel_history : ndarray, shape (3,)
        c [J] from the first N / 4, N / 2 and N samples, each with its local search.
    searches : int
        Local searches run (over the whole history).
    search_states : ndarray, shape (k, n)
        Where the local search's climbs ended: the states of largest dv/dt on their level
        sets (the falsification pass starts along their directions).
    runs_checked : int
        Simulated runs c was checked against (0 before :func:`checked`).
    notes : tuple of str
        Where a run lowered c: which run, from what v, and why; where the run from the
        configured initial state was run past its t_end, what it showed.
    """

    lyapunov_equilibrium: float
    lyapunov_hessian: np.ndarray
    hessian_min_eigenvalue: float
    positive_definite: bool
    rate_hessian: np.ndarray
    rate_eigenvalues: np.ndarray
    rate_definiteness: str
    lasalle_observable: bool
    n_samples: int
    sample_lyapunov: np.ndarray
    sample_rate: np.ndarray
    sample_rate_analytic: np.ndarray
    sample_outside: np.ndarray
    worst_state: np.ndarray
    worst_rate: float
    worst_lyapunov: float
    rate_mismatch: float
    boundary_level: float
    sublevel: float
    sublevel_bound: str
    sublevel_sampled: float = np.nan
    history_samples: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    sublevel_history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    searches: int = 0
    search_states: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    runs_checked: int = 0
    notes: tuple = ()

    @property
    def settled(self) -> bool:
        """Whether c stopped moving: c from N / 2 samples within :data:`SETTLED_RTOL` of c
        from N (with their local searches)."""
        h = self.sublevel_history
        if len(h) < 2 or not np.all(np.isfinite(h[-2:])):
            return False
        return bool(h[-2] <= h[-1] * (1.0 + SETTLED_RTOL) + np.finfo(float).tiny)

    @property
    def evidence(self) -> str:
        """What c is, in words: ``"estimate (sampled, 10000 states, checked against 37 runs;
        refined by 24 local searches)"``."""
        refined = f"; refined by {self.searches} local searches" if self.searches else ""
        return f"estimate (sampled, {self.n_samples} states, checked against {self.runs_checked} runs{refined})"

    @property
    def samples_inside(self) -> int:
        return int(np.sum(self.sample_lyapunov <= self.sublevel))

    @property
    def argument(self) -> str:
        """How asymptotic stability follows: ``"strict Lyapunov function"``, ``"LaSalle"``
        or ``"none"`` (the certificate does not hold)."""
        if not self.holds:
            return "none"
        return "strict Lyapunov function" if self.rate_definiteness == RATE_DEFINITENESS[0] else "LaSalle"

    @property
    def holds(self) -> bool:
        """v positive definite, dv/dt negative (semi-)definite with the PBH test passed,
        and a non-empty sublevel estimate."""
        rate_ok = self.rate_definiteness == RATE_DEFINITENESS[0] or (
            self.rate_definiteness == RATE_DEFINITENESS[1] and self.lasalle_observable)
        return bool(self.positive_definite and rate_ok and self.sublevel > 0)


def _scaled_eigenvalues(matrix: np.ndarray) -> np.ndarray:
    """Eigenvalues of D^-1/2 M D^-1/2, D = |diag M| (zeros kept), relative to the largest."""
    d = np.sqrt(np.abs(np.diag(matrix)))
    d = np.where(d > 0, d, 1.0)
    w = np.linalg.eigvalsh(matrix / np.outer(d, d))
    return w / max(np.abs(w).max(), np.finfo(float).tiny)


def _rate_definiteness(mu: np.ndarray) -> str:
    scale = max(float(np.abs(mu).max()), np.finfo(float).tiny)
    if np.any(mu > DEFINITE_RTOL * scale):
        return RATE_DEFINITENESS[2]
    if np.all(mu < -DEFINITE_RTOL * scale):
        return RATE_DEFINITENESS[0]
    return RATE_DEFINITENESS[1]


def _pbh_observable(jac: np.ndarray, rate_hessian: np.ndarray, root: np.ndarray, eigenvalues: np.ndarray) -> bool:
    """rank [A_z - sI; Q_z] = n for every eigenvalue s, in the coordinates z = S^-1 (y - y_e)
    where v ~ |z|^2 / 2 (so both blocks are in 1/s)."""
    a_z = np.linalg.solve(root, jac @ root)
    q_z = -0.5 * root.T @ rate_hessian @ root
    scale = max(float(np.abs(eigenvalues).max()), float(np.abs(q_z).max()), np.finfo(float).tiny)
    n = len(jac)
    for s in eigenvalues:
        stacked = np.vstack([a_z - s * np.eye(n), q_z])
        if np.linalg.svd(stacked, compute_uv=False)[-1] <= 1e-7 * scale:
            return False
    return True


#: Steps of the Richardson tables of a Newton step (its direction need not be exact: the
#: value it reaches is evaluated as it is).
_NEWTON_LEVELS = 10


def _newton_minimum(f, q: np.ndarray, iterations: int = 30) -> float:
    """Least value of a smooth scalar ``f`` (vectorised, (k, n) -> (k,)) near ``q``: Newton
    steps on the extrapolated gradient and Hessian, halved until ``f`` decreases."""
    value = float(f(q[None])[0])
    for _ in range(iterations):
        gradient = jacobian(lambda x: f(x)[:, None], q, 0.1, _NEWTON_LEVELS)[0][0]
        curvature = hessian(f, q, 0.1, _NEWTON_LEVELS)[0]
        try:
            step = -np.linalg.solve(curvature, gradient)
            if gradient @ step >= 0:  # not a descent direction: the Hessian is not positive definite
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:
            step = -gradient / max(float(np.abs(np.diag(curvature)).max()), 1.0)
        for _ in range(40):
            trial = float(f((q + step)[None])[0])
            if trial < value:
                break
            step = step / 2
        else:
            return value
        converged = value - trial <= 1e-12 * max(abs(value), 1.0)
        q, value = q + step, trial
        if converged:
            break
    return value


def coordinate_boundary_level(lyapunov, y_e: np.ndarray, hess: np.ndarray, limit: float, angles,
                              configuration) -> float:
    """The least v [J] on the domain boundary of a model whose angles are coordinates (the
    indices ``angles`` into y): for each angle and side, v (``lyapunov``, (k, n) -> (k,)) at
    rest with that angle at +-limit, minimised over the other ``configuration`` coordinates
    (Newton steps from the quadratic model's minimiser; the rest at y_e); inf where there is
    no angle."""
    levels = []
    for a in angles:
        free = np.array([i for i in configuration if i != a], dtype=int)
        for side in (limit, -limit):

            def v_on_boundary(q, side=side, a=a, free=free):
                y = np.tile(y_e, (len(q), 1))
                y[:, a] = side
                y[:, free] = q
                return lyapunov(y)

            if not len(free):
                levels.append(float(v_on_boundary(np.zeros((1, 0)))[0]))
                continue
            start = y_e[free] - np.linalg.solve(hess[np.ix_(free, free)], hess[free, a] * (side - y_e[a]))
            with np.errstate(all="ignore"):
                levels.append(_newton_minimum(v_on_boundary, start))
    return min(levels) if levels else np.inf  # no angle (a tree of slides): the domain has no boundary


def constrained_boundary_level(model, y_e: np.ndarray, hess: np.ndarray, limit: float, free: np.ndarray) -> float:
    """The least v [J] on the domain boundary of a :class:`Model` whose angles need not be
    coordinates: for each angle k and side, v at rest (the coordinates outside ``free`` at
    y_e) minimised over the configuration coordinates ``free`` subject to angle_k = +-limit
    (scipy's SLSQP from the quadratic model's minimiser on the linearised constraint,
    central-difference gradients). The kinetic terms of v are >= 0, so the least v on the
    boundary is at rest. A search that ends off the boundary (|angle_k -+ limit| > 1e-6 rad)
    counts with the quadratic model's value there, the least v of the quadratic model on the
    linearised boundary."""
    from scipy.optimize import minimize  # heavy: scipy

    free = np.asarray(free, dtype=int)
    h_ff = hess[np.ix_(free, free)]
    scale = max(float(np.abs(np.diag(h_ff)).max()) * limit * limit, np.finfo(float).tiny)
    step = 1e-7

    def states(q):
        x = np.tile(y_e, (len(q), 1))
        x[:, free] = q
        return x

    def value_and_gradient(fun, q):
        points = np.concatenate([q[None], q + step * np.eye(len(q)), q - step * np.eye(len(q))])
        values = fun(states(points))
        m = len(q)
        return values[0], (values[1:m + 1] - values[m + 1:]) / (2 * step)

    a0 = model.angles(y_e[None])[0]
    grad_a = model.angle_jacobian(y_e)[:, free]
    levels = []
    for k in range(len(a0)):
        g = grad_a[k]
        if not np.any(g):
            continue
        solved = np.linalg.solve(h_ff, g)
        for side in (limit, -limit):
            start = y_e[free] + solved * (side - a0[k]) / float(g @ solved)
            quadratic = 0.5 * float((start - y_e[free]) @ h_ff @ (start - y_e[free]))
            v_of = lambda x: np.asarray(model.lyapunov(x), dtype=float) / scale  # noqa: E731
            a_of = lambda x, k=k, side=side: (model.angles(x)[:, k] - side) / limit  # noqa: E731
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    res = minimize(lambda q: value_and_gradient(v_of, q)[0], start,
                                   jac=lambda q: value_and_gradient(v_of, q)[1], method="SLSQP",
                                   constraints=[{"type": "eq", "fun": lambda q: value_and_gradient(a_of, q)[0],
                                                 "jac": lambda q: value_and_gradient(a_of, q)[1]}],
                                   options={"maxiter": 200, "ftol": 1e-14})
                    on = abs(float(model.angles(states(res.x[None]))[0, k]) - side) <= 1e-6
                    found = float(model.lyapunov(states(res.x[None]))[0]) if on else np.nan
                except (ValueError, np.linalg.LinAlgError):
                    found = np.nan
            levels.append(found if np.isfinite(found) else quadratic)
    return min(levels) if levels else np.inf


def _samples(y_e: np.ndarray, root: np.ndarray, top: float, n: int, rng) -> np.ndarray:
    """n states y_e + S z, |z|^2/2 log-uniform over :data:`_DECADES` decades below ``top``."""
    u = rng.standard_normal((n, len(y_e)))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    level = top * 10.0 ** (-_DECADES * rng.random(n))
    z = np.sqrt(2.0 * level)[:, None] * u
    return y_e + z @ root.T


def certify(
    model,
    linearisation,
    *,
    gimbal_margin: float,
    n_samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    disturbed=None,
    t_end: float = 0.0,
) -> Certificate:
    """The certificate of ``model``'s equilibrium (module docstring).

    Parameters
    ----------
    model : Model
        Smooth (no pure sign law), in its coordinates (:class:`ChainModel`).
    linearisation : rbstab.analysis.linearise.Linearisation
        Of ``model`` (its equilibrium, Jacobian and eigenvalues, in the model's coordinates).
    gimbal_margin : float
        [rad]: the domain is |theta_2| < pi/2 - gimbal_margin (eq 5).
    n_samples : int
        States sampled for the dv/dt check (>= 1).
    seed : int
        Of the sampling (numpy's default generator).
    disturbed : Model, optional
        ``model`` with its disturbances, whose dv/dt the samples check, each at a time
        drawn uniformly in [0, ``t_end``] [s] (default: ``model`` itself, at t = 0).
    """
    y_e = linearisation.equilibrium
    h_v, _ = hessian(model.lyapunov, y_e)
    h_r, _ = hessian(lambda y: model.evaluate(y)["lyapunov_rate"], y_e)
    positive = bool(np.all(np.diag(h_v) > 0) and _scaled_eigenvalues(h_v)[0] > DEFINITE_RTOL)
    v_e = float(model.lyapunov(y_e))
    limit = GIMBAL_LOCK_ANGLE - gimbal_margin
    nan = np.full(0, np.nan)
    common = dict(lyapunov_equilibrium=v_e, lyapunov_hessian=h_v, hessian_min_eigenvalue=float(np.linalg.eigvalsh(h_v)[0]),
                  positive_definite=positive, rate_hessian=h_r)
    if not positive:
        return Certificate(**common, rate_eigenvalues=np.full(len(y_e), np.nan),
                           rate_definiteness=_rate_definiteness(np.linalg.eigvalsh(h_r)), lasalle_observable=False,
                           n_samples=0, sample_lyapunov=nan, sample_rate=nan, sample_rate_analytic=nan,
                           sample_outside=np.zeros(0, bool), worst_state=np.full(len(y_e), np.nan),
                           worst_rate=np.nan, worst_lyapunov=np.nan, rate_mismatch=np.nan,
                           boundary_level=np.nan, sublevel=0.0, sublevel_bound=BOUNDS[4])
    w, q = np.linalg.eigh(h_v)
    root = q @ np.diag(1.0 / np.sqrt(w)) @ q.T  # S = H_v^(-1/2)
    mu = np.linalg.eigvalsh(root @ h_r @ root)  # H_r w = mu H_v w
    observable = _pbh_observable(linearisation.jacobian, h_r, root, linearisation.eigenvalues)
    level = model.boundary_level(y_e, h_v, limit)
    rng = np.random.default_rng(seed)
    states = _samples(y_e, root, _REACH * level, n_samples, rng)
    times = rng.uniform(0.0, t_end, n_samples) if disturbed is not None else np.zeros(n_samples)
    dynamics = disturbed if disturbed is not None else model
    sampled = _sampled_rates(dynamics, linearisation, states, limit, times)
    sampled_c, bound = _sublevel(level, sampled)
    search = _LevelSearch(dynamics, linearisation, root, limit, _REACH * level * 10.0 ** -_DECADES)
    sizes = np.array(sorted({max(1, n_samples // d) for d in HISTORY_DIVISORS}), dtype=int)
    history, sublevel, searches = [], np.inf, 0
    for m in sizes:
        prefix = {k: (v[:m] if isinstance(v, np.ndarray) and v.shape[:1] == (n_samples,) else v)
                  for k, v in sampled.items()}
        c_m, bound_m = _sublevel(level, prefix)
        found, runs = search.refine(c_m, states[:m], times[:m], prefix)
        searches += runs
        if found < c_m:
            c_m, bound_m = found, BOUNDS[5]
        if c_m < sublevel:
            sublevel, bound = c_m, bound_m
        history.append(sublevel)  # every state found so far bounds c
    return Certificate(**common, rate_eigenvalues=mu, rate_definiteness=_rate_definiteness(mu),
                       lasalle_observable=observable, n_samples=n_samples, boundary_level=level,
                       sublevel=sublevel, sublevel_bound=bound, sublevel_sampled=sampled_c,
                       history_samples=sizes, sublevel_history=np.array(history), searches=searches,
                       search_states=np.array(search.climbed).reshape(-1, len(y_e)),
                       **{k: v for k, v in sampled.items() if not k.startswith("_")})


class _LevelSearch:
    """The local search where sampling misses (:func:`certify`), in the coordinates z of
    y = y_e + S z (v ~ |z|^2 / 2), with scipy's SLSQP and central-difference gradients:

    - from a sample below c with a large relative dv/dt: the largest dv/dt on its level set
      {v = v(sample)} (an equality constraint); if positive there, on to the next step;
    - from a state with dv/dt > 0: the least v subject to dv/dt >= 1e-7 rho v (rho the
      spectral radius of the linearisation: away from the rest states, where dv/dt = 0).

    Both keep the model's angles within pi/2 - gimbal_margin (for one body |theta_2|, linear
    in z), and v above the least sampled level. Every state the searches end at is checked
    as a sample is (the numerical dv/dt of :func:`_sampled_rates`, above its error): only a
    confirmed dv/dt > 0 lowers c."""

    def __init__(self, model, linearisation, root: np.ndarray, limit: float, floor: float) -> None:
        self.model, self.linearisation, self.root, self.limit = model, linearisation, root, limit
        self.floor = floor  # the least level sampled: below it v and dv/dt are round-off
        self.seen: set = set()  # the samples searched from (the history's prefixes share them)
        self.climbed: list = []  # where the climbs ended (states)
        self.y_e = linearisation.equilibrium
        self.rho = max(float(np.abs(linearisation.eigenvalues).max()), 1e-3)

    def _states(self, z: np.ndarray) -> np.ndarray:
        return self.y_e + np.atleast_2d(z) @ self.root.T

    def _values(self, z: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        return self._outputs(z, t)[:2]

    def _outputs(self, z: np.ndarray, t: float) -> tuple:
        """(v, dv/dt, the angles or None) at the states z (k, n): the angles where the model's
        ``evaluate`` gives them (``"angles"``) and they are not linear in the state."""
        with np.errstate(all="ignore"):
            out = self.model.evaluate(self._states(z), t)
        angles = out.get("angles") if self.model.angle_matrix is None else None
        return (np.asarray(out["lyapunov"], dtype=float), np.asarray(out["lyapunov_rate"], dtype=float),
                None if angles is None else np.asarray(angles, dtype=float))

    def _gradients(self, z: np.ndarray, t: float) -> tuple:
        """v, dv/dt and their gradients in z at z (central differences, one call; the last
        point's kept: SLSQP asks for the objective, the constraints and their gradients
        at the same point), then the angles and their Jacobian in z (None where the model's
        angles are linear or its ``evaluate`` does not give them)."""
        key = (np.asarray(z, dtype=float).tobytes(), float(t))
        if getattr(self, "_last", (None,))[0] == key:
            return self._last[1]
        self._last = (key, self._evaluate_gradients(np.asarray(z, dtype=float), t))
        return self._last[1]

    def _evaluate_gradients(self, z: np.ndarray, t: float) -> tuple:
        m = len(z)
        h = 1e-7 * (1.0 + np.abs(z))
        points = np.concatenate([z[None], z + np.diag(h), z - np.diag(h)])
        v, r, a = self._outputs(points, t)
        angles = (None, None) if a is None else (a[0], ((a[1:m + 1] - a[m + 1:]) / (2 * h)[:, None]).T)
        return (v[0], r[0], (v[1:m + 1] - v[m + 1:]) / (2 * h), (r[1:m + 1] - r[m + 1:]) / (2 * h), *angles)

    def _domain(self, t: float) -> list[dict]:
        """|angle| <= limit for each of the model's angles: linear constraints in z where the
        angles are linear in the state, else with their Jacobian."""
        lim = self.limit
        matrix = self.model.angle_matrix
        out = []
        if matrix is not None:
            for row_y in matrix:
                row, y1 = row_y @ self.root, float(row_y @ self.y_e)
                out += [{"type": "ineq", "fun": lambda z, row=row, y1=y1: (lim - y1 - row @ z) / lim,
                         "jac": lambda z, row=row: -row / lim},
                        {"type": "ineq", "fun": lambda z, row=row, y1=y1: (lim + y1 + row @ z) / lim,
                         "jac": lambda z, row=row: row / lim}]
            return out
        def angles(z):
            found = self._gradients(z, t)[4]
            return self.model.angles(self._states(z))[0] if found is None else found

        def jac(z):
            found = self._gradients(z, t)[5]
            return self.model.angle_jacobian(self._states(z)[0]) @ self.root if found is None else found

        return [{"type": "ineq", "fun": lambda z: (lim - angles(z)) / lim, "jac": lambda z: -jac(z) / lim},
                {"type": "ineq", "fun": lambda z: (lim + angles(z)) / lim, "jac": lambda z: jac(z) / lim}]

    def _climb(self, z0: np.ndarray, level: float, t: float) -> np.ndarray:
        """The largest dv/dt on {v = level} near z0."""
        from scipy.optimize import minimize  # heavy: scipy

        scale = self.rho * level
        cons = [{"type": "eq", "fun": lambda z: self._gradients(z, t)[0] / level - 1.0,
                 "jac": lambda z: self._gradients(z, t)[2] / level}] + self._domain(t)
        res = minimize(lambda z: -self._gradients(z, t)[1] / scale, z0, jac=lambda z: -self._gradients(z, t)[3] / scale,
                       method="SLSQP", constraints=cons, options={"maxiter": 60, "ftol": 1e-12})
        return res.x

    def _descend(self, z0: np.ndarray, t: float) -> np.ndarray:
        """The least v near z0 subject to dv/dt >= margin rho v."""
        from scipy.optimize import minimize  # heavy: scipy

        level = max(float(self._values(z0, t)[0][0]), np.finfo(float).tiny)

        def rate_margin(z):  # dv/dt / (rho v) - margin: negative at and near y_e
            v, r = self._gradients(z, t)[:2]
            return r / (self.rho * v) - _RATE_MARGIN

        def rate_margin_jac(z):
            v, r, gv, gr = self._gradients(z, t)[:4]
            return (gr * v - r * gv) / (self.rho * v * v)

        cons = [{"type": "ineq", "fun": rate_margin, "jac": rate_margin_jac},
                {"type": "ineq", "fun": lambda z: self._gradients(z, t)[0] / self.floor - 1.0,
                 "jac": lambda z: self._gradients(z, t)[2] / self.floor}] + self._domain(t)
        res = minimize(lambda z: self._gradients(z, t)[0] / level, z0, jac=lambda z: self._gradients(z, t)[2] / level,
                       method="SLSQP", constraints=cons, options={"maxiter": 400, "ftol": 1e-12})
        return res.x

    def _confirmed(self, z: np.ndarray, t: np.ndarray) -> np.ndarray:
        """v at the states z (k, n) whose numerical dv/dt is positive (the samples' test), inf elsewhere."""
        if not len(z):
            return np.zeros(0)
        checked = _sampled_rates(self.model, self.linearisation, self._states(z), self.limit, t)
        v = checked["sample_lyapunov"]
        return np.where(checked["_positive"] & np.isfinite(v) & (v >= self.floor), v, np.inf)

    def refine(self, c: float, states: np.ndarray, times: np.ndarray, sampled: dict) -> tuple[float, int]:
        """(the least v of a confirmed dv/dt > 0 the searches found, inf if none; searches run)
        from the samples ``states`` (their ``times`` and :func:`_sampled_rates` ``sampled``)."""
        v = sampled["sample_lyapunov"]
        positive = sampled["_positive"] & np.isfinite(v)
        rate = sampled["sample_rate"]
        power = np.abs(sampled["sample_rate_analytic"]) + self.rho * np.abs(v)
        with np.errstate(all="ignore"):
            relative = np.where(~positive & np.isfinite(rate) & (v < c) & (v > 0), rate / power, -np.inf)
        climb = np.argsort(-relative, kind="stable")[:REFINE_STARTS]
        climb = [i for i in climb[np.isfinite(relative[climb])] if ("climb", i) not in self.seen]
        least = np.where(positive, v, np.inf)
        first = np.argsort(least, kind="stable")[:REFINE_STARTS]
        first = [i for i in first[np.isfinite(least[first])] if ("descend", i) not in self.seen]
        self.seen.update([("climb", i) for i in climb] + [("descend", i) for i in first])  # a prefix's starts: once
        z_of = lambda i: np.linalg.solve(self.root, states[i] - self.y_e)  # noqa: E731
        descend = [(z_of(i), float(times[i])) for i in first]
        found_z, found_t, runs = [], [], 0
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for i in climb:
                runs += 1
                try:
                    z = self._climb(z_of(i), float(v[i]), float(times[i]))
                except (ValueError, np.linalg.LinAlgError):
                    continue
                found_z.append(z)
                found_t.append(times[i])
                self.climbed.append(self._states(z)[0])
                if np.isfinite(self._confirmed(z[None], times[i:i + 1])[0]):
                    descend.append((z, float(times[i])))
            for z0, t in descend:
                runs += 1
                try:
                    z = self._descend(z0, t)
                except (ValueError, np.linalg.LinAlgError):
                    continue
                found_z.append(z)
                found_t.append(t)
        if not found_z:
            return np.inf, runs
        levels = self._confirmed(np.array(found_z), np.array(found_t, dtype=float))
        return float(levels.min()), runs


def _sampled_rates(model, linearisation, y: np.ndarray, limit: float, t: np.ndarray) -> dict:
    """v, numerical and analytic dv/dt at the states ``y`` (NaN outside the domain) at the
    times ``t`` [s] (1, or one a state), the worst state and the rate mismatch (fields of
    :class:`Certificate`)."""
    with np.errstate(invalid="ignore"):
        outside = np.any(np.abs(model.angles(y)) >= limit, axis=1)
    inside = ~outside
    t = np.broadcast_to(t, len(y))
    with np.errstate(all="ignore"):
        out = model.evaluate(y, t)
        v = np.array(out["lyapunov"])
        analytic = np.where(inside, out["lyapunov_rate"], np.nan)
        rate = np.full(len(y), np.nan)
        error = np.full(len(y), np.nan)
        rho = max(float(np.abs(linearisation.eigenvalues).max()), 1e-3)
        if inside.any():
            f = model.rhs(t[inside], y[inside])
            rate[inside], error[inside] = directional_derivative(model.lyapunov, y[inside], f, 1.0 / rho)
        power = np.abs(analytic) + rho * np.abs(v)
        relative = rate / np.where(power > 0, power, 1.0)
    positive = inside & (rate > np.maximum(10.0 * error, RATE_RTOL * power))
    invalid = inside & ~(np.isfinite(rate) & np.isfinite(v))
    finite = inside & np.isfinite(relative)
    worst = int(np.argmax(np.where(finite, relative, -np.inf))) if finite.any() else 0
    return {
        "sample_lyapunov": v,
        "sample_rate": rate,
        "sample_rate_analytic": analytic,
        "sample_outside": outside,
        "worst_state": y[worst] if finite.any() else np.full(y.shape[1], np.nan),
        "worst_rate": float(rate[worst]) if finite.any() else np.nan,
        "worst_lyapunov": float(v[worst]) if finite.any() else np.nan,
        "rate_mismatch": float(np.nanmax(np.abs(rate - analytic)[finite] / np.where(power > 0, power, 1.0)[finite]))
        if finite.any() else np.nan,
        "_positive": positive,
        "_invalid": invalid,
    }


def _sublevel(level: float, sampled: dict) -> tuple[float, str]:
    """(c, what bounds it): the least v of the states that bound the estimate."""
    v = sampled["sample_lyapunov"]
    candidates = [(level, BOUNDS[0])]
    for mask, name in ((sampled["_positive"], BOUNDS[1]), (sampled["sample_outside"], BOUNDS[2]),
                       (sampled["_invalid"], BOUNDS[3])):
        values = v[mask & np.isfinite(v)]
        if values.size:
            candidates.append((float(values.min()), name))
        elif np.any(mask & ~np.isfinite(v)):
            candidates.append((0.0, name))
    c, bound = min(candidates, key=lambda item: item[0])
    return max(c, 0.0), bound


def checked(certificate: Certificate, lyapunov_start, recovered, name, reasons=None) -> Certificate:
    """``certificate`` with c checked against simulated runs: a run that starts inside
    {v <= c} and does not recover lowers c below its starting v (the next float down),
    with a note naming the run and why it counts.

    Parameters
    ----------
    certificate : Certificate
    lyapunov_start : array_like, shape (k,)
        v [J] where each run starts (v of its initial state, or v just after a push);
        NaN: not a run (not counted).
    recovered : array_like of bool, shape (k,)
        Whether each run recovered: False where it counts against c (by the rule of the
        analysis that ran it, :mod:`rbstab.analysis.evidence`).
    name : callable
        ``name(i)`` -> the run's description, for the note.
    reasons : sequence of str, shape (k,), optional
        Why each run that did not recover counts against c, for the note ("v rose above
        c = ... (to ... at t = ... s)", "failed: <message>"; default "did not recover").

    Returns
    -------
    Certificate
        With ``runs_checked`` grown by the runs counted, and where a run contradicts c, c,
        ``sublevel_bound`` and ``notes`` changed.
    """
    v0 = np.asarray(lyapunov_start, dtype=float).ravel()
    ok = np.asarray(recovered, dtype=bool).ravel()
    counted = np.isfinite(v0)
    bad = counted & ~ok & (v0 <= certificate.sublevel)
    out = replace(certificate, runs_checked=certificate.runs_checked + int(counted.sum()))
    if not bad.any() or not certificate.positive_definite:
        return out
    i = int(np.argmin(np.where(bad, v0, np.inf)))
    c = max(float(np.nextafter(v0[i], -np.inf)), 0.0)
    others = int(bad.sum()) - 1
    why = "did not recover" if reasons is None else reasons[i]
    digits = 4  # enough to tell the two levels apart
    while digits < 17 and f"{certificate.sublevel:.{digits}g}" == f"{c:.{digits}g}":
        digits += 1
    note = (f"c lowered from {certificate.sublevel:.{digits}g} J to {c:.{digits}g} J: {name(i)} started inside {{v <= c}} at "
            f"v = {v0[i]:.4g} J and {why}" + (f" (and {others} more such runs)" if others else ""))
    return replace(out, sublevel=c, sublevel_bound=BOUNDS[6], notes=certificate.notes + (note,))


def level_states(model, linearisation, certificate: Certificate, n: int, seed: int = 0) -> np.ndarray:
    """n states on the level set {v = c} (c the certificate's sublevel) of ``model`` (a
    :class:`Model`, in its coordinates: map them with ``Model.states``): along the
    directions from y_e of the states where the local search's climbs ended (dv/dt largest on
    their level sets; up to n / 2 of them), of the worst sampled state, and random ones, in
    the coordinates z of y = y_e + S z, each at the first radius where v reaches c
    (bisection). Shape (n, n_state); empty where c is not positive."""
    c = certificate.sublevel
    if not (c > 0 and np.isfinite(c)) or n < 1:
        return np.zeros((0, len(linearisation.equilibrium)))
    y_e = linearisation.equilibrium
    w, q = np.linalg.eigh(certificate.lyapunov_hessian)
    root = q @ np.diag(1.0 / np.sqrt(w)) @ q.T
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, len(y_e)))
    known = [y for y in (*certificate.search_states[: n // 2], certificate.worst_state)
             if len(y) == len(y_e) and np.all(np.isfinite(y)) and np.any(y != y_e)][:n]
    for i, y in enumerate(known):
        u[i] = np.linalg.solve(root, y - y_e)
    u /= np.linalg.norm(u, axis=1, keepdims=True)

    def v_at(r):
        with np.errstate(all="ignore"):
            return np.asarray(model.lyapunov(y_e + (r[:, None] * u) @ root.T), dtype=float)

    lo = np.zeros(n)
    hi = np.full(n, np.sqrt(2.0 * c))
    for _ in range(60):  # hi: a radius beyond the level (v ~ |z|^2 / 2 near y_e)
        above = v_at(hi) >= c
        if above.all():
            break
        hi = np.where(above, hi, 2.0 * hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = v_at(mid) >= c
        lo, hi = np.where(above, lo, mid), np.where(above, mid, hi)
    return y_e + (lo[:, None] * u) @ root.T
