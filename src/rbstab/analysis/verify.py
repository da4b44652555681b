"""A verified inner bound of the region of attraction: a sublevel set {v <= c} of the
reduced (6-state, ``permanent``) model proven positively invariant and attracted to the
equilibrium, with outward-rounded interval arithmetic (python-flint's ``arb`` balls) and
branch and bound over boxes of the Euler angles Theta.

The argument (docs/analysis.md, "verified"). For the pinned body (eqs 21, 31, 32, 34; its
point C at R_c in its frame, held at the ground point R_p), v = 0.5 Omega' J_p Omega + P(Theta)
with the potential

    P(Theta) = 0.5 dTheta' K_r dTheta + 0.5 dTheta_p' K_p dTheta_p + 0.5 X' K_t X - X' G + h,
    X = R_p - A(Theta) R_c,  dTheta = Theta - Theta_ref,  dTheta_p = Theta - Theta_p

(the paper's one body: R_p = R_c = R, Theta_ref = 0, no passive spring K_p, damper L_p),

and along the flow, with N the torque the actuators deliver and tau = -B' K_r dTheta the
static part of the commanded torque (eq 23), and L_r diagonal,

    dv/dt = sum_i Omega_i (sat_i(tau_i - l_i Omega_i) - tau_i) - Omega' L_p Omega - V' L_t V   (eq 37)

(H unlimited; the passive torque is never limited, so it adds its damping alone). Where |tau_i| < limit_i, sat_i(tau_i) = tau_i, and since a clip is
monotone each term is -l_i Omega_i^2 when axis i does not saturate and negative for
Omega_i != 0 when it does: the saturation deficit power is never positive, and dv/dt < 0
wherever Omega != 0. The proof at a level c therefore needs, on every Theta of a box
domain D (|theta_2| < pi/2 - gimbal margin and ``simulation.limits``) with P(Theta) <= c:

1. Theta is not on the boundary of D (so {v <= c} n D is compact and a union of
   components of {v <= c}: a run cannot leave it without v rising above c);
2. |tau_i(Theta)| < limit_i on every limited axis (so dv/dt <= 0 on it);
3. grad P(Theta) != 0, except in a small box E around the equilibrium on which the
   interval Hessian of P is positive definite (P strictly convex there: one rest point).

Then {v <= c} n D is positively invariant, dv/dt = 0 only where Omega = 0, and the
largest invariant set there consists of rest points (grad P = 0 with Omega = 0): only the
equilibrium. By LaSalle's invariance principle every run from the set converges to it.

A tree of hinges, slides, universal joints and balls of at most 6 states (:class:`_TreeModel`)
is proven the same way over boxes of their coordinates q (a hinge's angle [rad], a slide's
displacement [m], a universal joint's two angles, a ball's rotation vector phi of its turn
from its reference, inside its chart |phi| < :data:`BALL_CHART`): v =
1/2 u' M(q) u + P(q), P the joints' springs and stops, gravity on X_i(q) and h; tau_j =
-k_j (q_j - q_ref_j) (a slide's force) between the servo's own lower and upper limits; the
domain half a turn (a slide's :data:`SLIDE_SEARCH`) either side of each reference, and every
body's Euler angles inside ``simulation.limits.theta`` (docs/analysis.md, "The verified
bound").

The largest such c is found at once: c is a lower bound of P over the set of Theta that
fail 1-3, computed by best-first branch and bound (boxes ordered by their lower bound of
P, bisected along their widest side scaled by sqrt(K_r)) to a relative tolerance; the box
that stops the search, and why, is :attr:`Verification.reason`.
"""

from __future__ import annotations

import heapq
import math
import os
import time as _time
from dataclasses import dataclass, field

import numpy as np

from ..kinematics import GIMBAL_LOCK_ANGLE
from ..layout import is_chain

__all__ = ["Verification", "NotVerifiable", "verify_sublevel", "verify_analysis", "check_verifiable",
           "potential", "DEFAULT_RTOL"]

#: The verified c is within this (relative) of the least P over the failing set of the
#: sufficient conditions (the search stops there).
DEFAULT_RTOL = 0.01
#: Boxes no smaller than this (relative to the domain's scaled size) are bisected further.
_MIN_WIDTH = 1e-6
#: The most boxes of one search.
MAX_BOXES = 400_000
#: [m]: the search domain of a slide's q, either side of its reference (a hinge's: half a
#: turn), within its range where that is an admissible region.
SLIDE_SEARCH = 1.0
#: [rad]: the largest turn |phi| of a ball's rotation vector phi = log(A(Theta_ref)' A_rel) the
#: proof's domain holds (the chart: exp is a diffeomorphism onto its image for |phi| < pi).
BALL_CHART = math.pi - 0.05


class NotVerifiable(ValueError):
    """The configuration or level cannot be verified here; the message says why."""


@dataclass(frozen=True)
class Verification:
    """A verified sublevel bound (module docstring).

    Attributes
    ----------
    level : float
        c [J]: {v <= c} (the component of the equilibrium, inside the domain) is proven
        positively invariant and inside the region of attraction.
    boxes : int
        Theta boxes the branch and bound evaluated.
    seconds : float
        Wall time of the proof [s].
    reason : str
        What stops c from being larger: the box and the condition that failed there.
    box : ndarray, shape (3, 2)
        That box, [theta_i low, high] [rad].
    equilibrium_box : float
        Half-width [rad] of the box around the equilibrium where P is proven strictly convex.
    method : str
        ``"interval arithmetic"``.
    coordinates : str
        What the boxes are of: ``"theta"`` (one body's Euler angles) or ``"q"`` (a tree's
        joint coordinates in the joints' order; ``box`` then has a row each).
    names : tuple of str
        A tree's coordinates, a row of ``box`` each: a hinge's or a slide's joint name, a
        universal joint's ``<joint>.q_1``, ``.q_2``, a ball's ``<joint>.phi_1`` .. ``.phi_3``
        (empty for ``"theta"``).
    """

    level: float
    boxes: int
    seconds: float
    reason: str
    box: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))
    equilibrium_box: float = 0.0
    method: str = "interval arithmetic"
    coordinates: str = "theta"
    names: tuple = ()

    @property
    def summary(self) -> str:
        """``"verified c = 0.0375 J (interval arithmetic, 1234 boxes, 0.8 s)"``."""
        return (f"verified c = {self.level:.4g} J ({self.method}, {self.boxes} boxes, {self.seconds:.2g} s)")


# -- what is covered ----------------------------------------------------------------------------
#: The joints on coordinates along axes that the proof of a tree covers, by their coordinates.
_COVERED = {"hinge": 1, "slide": 1, "universal": 2, "ball": 3}


def _hinged(config) -> bool:
    """Whether the tree has a joint on coordinates of its own (a hinge, a slide, a universal
    joint, a quaternion ball): the proof of a tree of those."""
    return any(j.variant in _COVERED for j in config.chain.joints)


def verified_model(config):
    """The configuration the proof is of: ``config`` where its tree is one body held to the
    ground by its joint (in either spelling, the ground point anywhere), or a tree of
    hinges, slides, universal joints and balls of at most 6 states.

    Raises
    ------
    NotVerifiable
        For another tree of several bodies (one line: why)."""
    bodies = config.chain.size
    if _hinged(config):
        others = [j for j in config.chain.joints if j.variant not in _COVERED]
        if others:
            raise NotVerifiable(f"joints.{others[0].name}.variant: found {others[0].variant!r} in a tree with a "
                                "hinge, a slide, a universal joint or a ball; --verify covers a tree whose every joint "
                                "is one of those")
        states = sum(2 * _COVERED[j.variant] for j in config.chain.joints)
        if states > 6:
            raise NotVerifiable(f"this tree has {states} states; --verify covers at most 6 (3 hinges or slides, a "
                                "universal joint counting 2, a ball 3: interval arithmetic over boxes of their "
                                "coordinates)")
        return config
    if bodies > 1:
        raise NotVerifiable("the proof covers one body held to the ground by a permanent joint, the reduced "
                            "6-state model of 'permanent' (eq 21), or a tree of hinges, slides, universal joints and "
                            f"balls of at most 6 states; this chain has {bodies} bodies")
    return config


def _key(config, owner: str, name: str) -> str:
    """The key of the joint's (``owner`` ``"joint"``) or the body's gain or limit ``name`` as
    the configuration writes it (one body's: ``controller.<name>``)."""
    if not is_chain(config):
        return f"controller.{name}"
    chain = config.chain
    return f"joints.{chain.joint_names[0]}.{name}" if owner == "joint" else f"bodies.{chain.body_names[0]}.{name}"


def check_verifiable(config) -> None:
    """Raise :class:`NotVerifiable` (one line: the key, the value found, what is covered)
    unless the configuration is one body on a permanent joint to the ground, the reduced
    6-state model (:func:`verified_model`), with what the proof covers: symmetric clipped torque
    limits, diagonal positive L_r, H unlimited, no disturbances, no bounds of X, V or E in
    ``simulation.limits``."""
    chain = verified_model(config).chain
    if _hinged(config):
        _check_hinges(config)
        return
    body, joint = chain.bodies[0], chain.joints[0]
    if joint.variant != "permanent":
        raise NotVerifiable(f"{_key(config, 'joint', 'variant')}: found {joint.variant!r} (its analysis runs on more "
                            "than 6 states); --verify covers the reduced 6-state model of 'permanent'")
    if joint.stop is not None or joint.region is not None:
        raise NotVerifiable(f"{_key(config, 'joint', 'range')}: found a range of the ball's Euler angles; --verify "
                            "of one body covers the paper's joint (its bounds of theta in simulation.limits)")
    if joint.saturation is not None and joint.saturation.torque_n_lower is not None and not np.array_equal(
            joint.saturation.torque_n_lower, -np.asarray(joint.saturation.torque_n)):
        raise NotVerifiable(f"{_key(config, 'joint', 'saturation.torque_n_lower')}: found "
                            f"{np.asarray(joint.saturation.torque_n_lower).tolist()}; --verify covers symmetric limits "
                            "of N (|N_i| <= torque_n_i)")
    l_r = np.asarray(joint.l_r, dtype=float)
    if np.any(l_r - np.diag(np.diag(l_r))):
        raise NotVerifiable(f"{_key(config, 'joint', 'l_r')}: found a non-diagonal L_r {l_r.tolist()}; --verify needs "
                            "a diagonal L_r (the saturation deficit power is bounded axis by axis)")
    if np.any(np.diag(l_r) <= 0.0):
        raise NotVerifiable(f"{_key(config, 'joint', 'l_r')}: found {np.diag(l_r).tolist()}; --verify needs every "
                            "L_r_i > 0 (LaSalle's argument: dv/dt = 0 only where Omega = 0)")
    sat = joint.saturation or body.saturation
    if sat is not None:
        if sat.shape != "clip":
            raise NotVerifiable(f"{_key(config, 'joint', 'saturation.shape')}: found {sat.shape!r}; --verify covers "
                                "'clip' (a smooth saturation delivers less than the commanded torque at every state, "
                                "so its deficit power is not zero where no limit is reached)")
        force_h = np.full(3, np.inf) if body.saturation is None else np.asarray(body.saturation.force_h, dtype=float)
        if np.any(np.isfinite(force_h)) and (np.any(body.k_t) or np.any(body.l_t)):
            raise NotVerifiable(f"{_key(config, 'body', 'saturation.force_h')}: found {force_h.tolist()}; "
                                "--verify covers unlimited H (or K_t = L_t = 0)")
    if body.disturbances:
        raise NotVerifiable(f"disturbances: found {len(body.disturbances)}; --verify covers the undisturbed "
                            "body (a disturbance is not a property of a sublevel set)")
    limits = config.simulation.limits
    if limits is not None:
        bounds = np.asarray(limits.array, dtype=float)
        if np.any(np.isfinite(bounds[2:])):
            raise NotVerifiable("simulation.limits: found bounds of x, v or e; --verify covers bounds of "
                                "theta and omega")


def _check_hinges(config) -> None:
    """:func:`check_verifiable` of a tree of hinges: every hinge's l_r > 0, clipped limits
    (either side its own), no body feedback, no disturbances, bounds of theta alone (below
    pi/2) in ``simulation.limits``."""
    chain = config.chain
    for joint in chain.joints:
        if joint.variant == "ball":
            _check_ball(joint)
            continue
        axis = np.asarray(joint.axis, dtype=float)
        axis = axis / np.linalg.norm(axis)
        l_r = float(np.asarray(joint.l_r, dtype=float)[0, 0] if joint.variant == "slide"  # along its axis
                    else min(np.diag(joint.l_r)[:2]) if joint.variant == "universal"  # per coordinate
                    else axis @ np.asarray(joint.l_r, dtype=float) @ axis)
        if not l_r > 0.0:
            raise NotVerifiable(f"joints.{joint.name}.l_r: found {l_r:g}; --verify needs every {joint.variant}'s "
                                "l_r > 0 (LaSalle's argument: dv/dt = 0 only where every dq/dt = 0)")
        if joint.saturation is not None and joint.saturation.shape != "clip":
            raise NotVerifiable(f"joints.{joint.name}.saturation.shape: found {joint.saturation.shape!r}; --verify "
                                "covers 'clip' (a smooth saturation delivers less than the commanded torque at every "
                                "state)")
    for body in chain.bodies:
        if np.any(body.k_t) or np.any(body.l_t):
            raise NotVerifiable(f"bodies.{body.name}.k_t: found body feedback H; --verify of a tree of hinges "
                                "covers joint torques alone")
        if body.disturbances:
            raise NotVerifiable(f"bodies.{body.name}.disturbances: found {len(body.disturbances)}; --verify covers "
                                "the undisturbed tree (a disturbance is not a property of a sublevel set)")
    limits = config.simulation.limits
    if limits is not None:
        bounds = np.asarray(limits.array, dtype=float)
        if np.any(np.isfinite(bounds[1:])):
            raise NotVerifiable("simulation.limits: found bounds of omega, x, v or e; --verify of a tree of hinges "
                                "covers bounds of theta")
        if np.any(np.isfinite(bounds[0]) & (bounds[0] >= GIMBAL_LOCK_ANGLE)):
            raise NotVerifiable(f"simulation.limits.theta: found {bounds[0].tolist()}; --verify of a tree of hinges "
                                "covers bounds below pi/2")


def _check_ball(joint) -> None:
    """What the proof of a ball covers: diagonal K_r, L_r (every L_r_i > 0) and passive
    gains, its passive spring relaxed at its spring's reference (one rotation vector phi
    for both), no stop (its cone as an admissible region is covered), clipped limits."""
    key = f"joints.{joint.name}"
    gains = [("k_r", joint.k_r), ("l_r", joint.l_r)]
    if joint.passive is not None:
        gains += [("passive.k_r", joint.passive.k_r), ("passive.l_r", joint.passive.l_r)]
    for name, gain in gains:
        gain = np.asarray(gain, dtype=float)
        if np.any(gain - np.diag(np.diag(gain))):
            raise NotVerifiable(f"{key}.{name}: found a non-diagonal matrix {gain.tolist()}; --verify of a ball "
                                "covers diagonal gains (its springs axis by axis on the rotation vector)")
    if not np.all(np.diag(np.asarray(joint.l_r, dtype=float)) > 0.0):
        raise NotVerifiable(f"{key}.l_r: found {np.diag(joint.l_r).tolist()}; --verify needs every l_r_i > 0 "
                            "(LaSalle's argument: dv/dt = 0 only where Omega_j = 0)")
    if joint.passive is not None and not np.array_equal(joint.passive.theta_ref, joint.theta_ref):
        raise NotVerifiable(f"{key}.passive.theta_ref: found {np.asarray(joint.passive.theta_ref).tolist()}; "
                            f"--verify of a ball covers a passive spring relaxed at theta_ref "
                            f"{np.asarray(joint.theta_ref).tolist()} (one rotation vector for both)")
    if joint.stop is not None:
        raise NotVerifiable(f"{key}.range: found a stop; --verify of a ball covers its range as an admissible region "
                            "(kind: region), not a stop")
    if joint.saturation is not None and joint.saturation.shape != "clip":
        raise NotVerifiable(f"{key}.saturation.shape: found {joint.saturation.shape!r}; --verify covers 'clip' (a "
                            "smooth saturation delivers less than the commanded torque at every state)")


# -- interval kernels (3-vectors and 3x3 matrices as lists of arb) -----------------------------
def _arb():
    try:
        from flint import arb  # optional: the verify extra (python-flint)
    except ImportError as exc:  # pragma: no cover - the extra is a test dependency
        raise NotVerifiable("--verify needs python-flint (pip install \"rbstab[verify]\")") from exc
    return arb


def _ball(arb, lo: float, hi: float):
    """An arb ball containing [lo, hi] (outward)."""
    mid = 0.5 * (lo + hi)
    rad = max(hi - mid, mid - lo)
    rad = math.nextafter(rad * (1.0 + 4e-16), math.inf) + 1e-300
    return arb(mid, rad)


def _rot(axis: int, c, s, zero, one):
    """R_axis(t) from its cosine and sine (A = Rx Ry Rz, eq 1)."""
    if axis == 0:
        return [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    if axis == 1:
        return [[c, zero, s], [zero, one, zero], [-s, zero, c]]
    return [[c, -s, zero], [s, c, zero], [zero, zero, one]]


def _drot(axis: int, c, s, zero):
    """dR_axis/dt."""
    if axis == 0:
        return [[zero, zero, zero], [zero, -s, -c], [zero, c, -s]]
    if axis == 1:
        return [[-s, zero, c], [zero, zero, zero], [-c, zero, -s]]
    return [[-s, -c, zero], [c, -s, zero], [zero, zero, zero]]


def _ddrot(axis: int, c, s, zero):
    """d^2 R_axis/dt^2."""
    if axis == 0:
        return [[zero, zero, zero], [zero, -c, s], [zero, -s, -c]]
    if axis == 1:
        return [[-c, zero, -s], [zero, zero, zero], [s, zero, -c]]
    return [[-c, s, zero], [-s, -c, zero], [zero, zero, zero]]


def _mv(m, v):
    return [m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
            m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
            m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]]


def _mm(a, b):
    """The product of two 3x3 matrices (lists of rows)."""
    return [[a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c] for c in range(3)] for r in range(3)]


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


# -- a ball's rotation vector: exp([phi]x) and J_r(phi)^-T as power series in s = |phi|^2 --------------------
#: Terms of the series below summed by Horner's rule; the rest is bounded by twice its first term.
_TERMS = 30


def _factorial_series(offset: int, derivative: int) -> list:
    """Coefficients (exact rationals) of the ``derivative``-th derivative in s of
    sum_k (-1)^k s^k / (2k + offset)!: cos t (offset 0), sin t / t (1), (1 - cos t) / t^2 (2),
    t = sqrt(s)."""
    from flint import fmpq  # optional: the verify extra (python-flint)

    out = []
    for k in range(_TERMS + 1):
        m = k + derivative
        factor = math.prod(range(k + 1, m + 1))  # d^n/ds^n s^m = m!/k! s^k
        out.append(fmpq((-1) ** m * factor, math.factorial(2 * m + offset)))
    return out


def _bernoulli_series() -> list:
    """Coefficients of c(s) = 1/t^2 - (1 + cos t) / (2 t sin t) = sum_n |B_2n+2| s^n / (2n + 2)!
    (t = sqrt(s) < 2 pi), the J_r(phi)^-1 coefficient of [phi]x^2
    (:func:`rbstab.kinematics.right_jacobian_inverse`)."""
    from flint import fmpq  # optional: the verify extra (python-flint)

    return [abs(fmpq.bernoulli(2 * n + 2)) / math.factorial(2 * n + 2) for n in range(_TERMS + 1)]


_SERIES: dict = {}


def _series(arb, kind, s):
    """The power series ``kind`` ((offset, derivative) of :func:`_factorial_series`, or
    "c" of :func:`_bernoulli_series`) over the arb ball s: Horner's sum of its first
    :data:`_TERMS` terms and a ball of twice the next term's size at S = sup |s| (each later
    term at most half the one before: checked, else the whole real line)."""
    if kind not in _SERIES:
        coefficients = _bernoulli_series() if kind == "c" else _factorial_series(*kind)
        _SERIES[kind] = [arb(c) for c in coefficients]
    c = _SERIES[kind]
    big = abs(s).upper()
    ratio = float(abs(c[_TERMS]).upper()) * float(big) / float(abs(c[_TERMS - 1]).lower())
    limit = 1.1 / (4.0 * math.pi ** 2) if kind == "c" else 0.0  # the c series: ratio s / (2 pi)^2 at most
    if ratio > 0.5 or limit * float(big) > 0.5:
        return arb(0, 1e300)
    total = c[_TERMS - 1]
    for k in range(_TERMS - 2, -1, -1):
        total = total * s + c[k]
    rest = 2 * abs(c[_TERMS]) * big ** _TERMS
    return total + arb(0, math.nextafter(float(rest.upper()), math.inf) * (1.0 + 1e-15) + 1e-300)


def _rodrigues_values(arb, phi, square):
    """exp([phi]x) = cos t I + (1 - cos t)/t^2 phi phi' + sin t / t [phi]x (t = |phi|) of a
    rotation vector ``phi`` (3 arb balls) whose squared size is the arb ball ``square``."""
    c0, c1, c2 = (_series(arb, (offset, 0), square) for offset in (0, 1, 2))
    x, y, z = phi
    return [[c0 + c2 * x * x, c2 * x * y - c1 * z, c2 * x * z + c1 * y],
            [c2 * x * y + c1 * z, c0 + c2 * y * y, c2 * y * z - c1 * x],
            [c2 * x * z - c1 * y, c2 * y * z + c1 * x, c0 + c2 * z * z]]


class _Model:
    """P, grad P, the Hessian of P and tau = -B' K_r (Theta - Theta_ref) (the feedback's
    spring alone: what the actuator delivers) over a box of Theta, in arb, of the body of
    record ``p`` (:data:`rbstab.model.PARAMETERS`: C at R_c = ``attachment_point`` in its
    frame; the joint's springs, its feedback's about ``theta_ref`` and its passive one about
    ``passive_theta_ref``) on its joint at the ground point ``ground`` R_p (3,) [m], X = R_p
    - A R_c, with h = ``offset`` [J]. ``k_r`` and ``reference`` are the springs' sum: K =
    K_r + K_p and the Theta where it is relaxed, K^-1 (K_r Theta_ref + K_p Theta_p) (their
    sum is 1/2 (Theta - that)' K (Theta - that) plus a constant >= 0)."""

    def __init__(self, p, ground, offset: float, arb) -> None:
        self.arb = arb
        self.zero, self.one = arb(0), arb(1)
        self.springs = [self._spring_of(p["k_r"], p["theta_ref"], arb)]  # the feedback's first
        if p["passive"] > 0.0:
            self.springs.append(self._spring_of(p["passive_k_r"], p["passive_theta_ref"], arb))
        self.k_r = sum(k for k, _, _, _, _ in self.springs)
        moment = sum(k @ r for k, r, _, _, _ in self.springs)
        self.reference = np.linalg.lstsq(self.k_r, moment, rcond=None)[0] if len(self.springs) > 1 else self.springs[0][1]
        self.diag_kr = not np.any(self.k_r - np.diag(np.diag(self.k_r)))
        self.k_t = np.asarray(p["k_t"], dtype=float)
        self.R = [arb(float(x)) for x in p["attachment_point"]]
        self.ground = [arb(float(x)) for x in ground]
        self.G = [arb(float(x)) for x in p["weight"]]
        self.h = arb(float(offset))
        self.reach = float(np.linalg.norm(p["attachment_point"]) + np.linalg.norm(ground))  # |X| at most
        self.weight, self.offset = float(np.linalg.norm(p["weight"])), float(offset)
        self.pivot_inertia = np.asarray(p["pivot_inertia"], dtype=float)
        self.K_t = [[arb(float(x)) for x in row] for row in self.k_t]
        self.has_kt = bool(np.any(self.k_t))
        self.limit = np.asarray(p["torque_limit"], dtype=float) if p["saturation"] > 0 else np.full(3, np.inf)
        self.limit_arb = [arb(float(x)) if np.isfinite(x) else None for x in self.limit]

    def _trig(self, theta):
        return [t.cos() for t in theta], [t.sin() for t in theta]

    def _w(self, rots, vec):
        """Rx Ry Rz vec with the given factors."""
        return _mv(rots[0], _mv(rots[1], _mv(rots[2], vec)))

    @staticmethod
    def _spring_of(k, reference, arb):
        """(K (3, 3), Theta_ref (3,), K in arb, Theta_ref in arb, whether K is diagonal) of a spring."""
        k, reference = np.array(k, dtype=float), np.array(reference, dtype=float)
        return (k, reference, [[arb(float(x)) for x in row] for row in k], [arb(float(x)) for x in reference],
                not np.any(k - np.diag(np.diag(k))))

    def _spring(self, theta, lo, hi):
        """The springs' 0.5 dTheta' K dTheta, dTheta = Theta - their reference, summed; tight
        for a diagonal K (squares of intervals)."""
        arb = self.arb
        total = self.zero
        for k, reference, k_arb, reference_arb, diagonal in self.springs:
            if not diagonal:
                strain = [theta[i] - reference_arb[i] for i in range(3)]
                total = total + 0.5 * _dot(strain, _mv(k_arb, strain))
                continue
            for i in range(3):
                a, b = lo[i] - reference[i], hi[i] - reference[i]  # their signs exact, as the difference's
                sq_hi = max(a * a, b * b)
                sq_lo = 0.0 if a <= 0.0 <= b else min(a * a, b * b)
                sq = arb(sq_lo).union(arb(sq_hi)) if sq_lo != sq_hi else arb(sq_lo)
                # a, b and their squares were rounded (3 roundings, relative 3.3e-16): widen by that
                sq = sq + arb(0, 4e-16 * sq_hi + 1e-300)
                total = total + 0.5 * k_arb[i][i] * sq
        return total

    def _stiffness(self, theta):
        """Each spring's K dTheta (arb balls), the feedback's first."""
        return [_mv(k_arb, [theta[i] - reference_arb[i] for i in range(3)]) for _, _, k_arb, reference_arb, _ in
                self.springs]

    def evaluate(self, lo, hi, hessian: bool = False):
        """(P, grad P, tau) over the box [lo, hi] (arb balls); with ``hessian`` also the
        3x3 Hessian of P."""
        arb, zero, one = self.arb, self.zero, self.one
        theta = [_ball(arb, lo[i], hi[i]) for i in range(3)]
        cos, sin = self._trig(theta)
        rots = [_rot(a, cos[a], sin[a], zero, one) for a in range(3)]
        drots = [_drot(a, cos[a], sin[a], zero) for a in range(3)]
        w = self._w(rots, self.R)
        x = [self.ground[i] - w[i] for i in range(3)]
        kx = _mv(self.K_t, x) if self.has_kt else [zero, zero, zero]
        force = [self.G[i] - kx[i] for i in range(3)]  # G - K_t X
        p_val = self._spring(theta, lo, hi) - _dot(x, self.G) + self.h
        if self.has_kt:
            p_val = p_val + 0.5 * _dot(x, kx)
        dw = []
        for a in range(3):
            f = [drots[b] if b == a else rots[b] for b in range(3)]
            dw.append(self._w(f, self.R))
        springs = self._stiffness(theta)
        kth = springs[0]  # the feedback's: the actuator's torque at rest
        grad = [sum((s[a] for s in springs[1:]), kth[a]) + _dot(force, dw[a]) for a in range(3)]
        # tau = -B' K_r (Theta - Theta_ref), B of eq 1 (physics notes)
        c2, s2, c3, s3 = cos[1], sin[1], cos[2], sin[2]
        tau = [-(c3 / c2 * kth[0] + s3 * kth[1] - s2 * c3 / c2 * kth[2]),
               -(-s3 / c2 * kth[0] + c3 * kth[1] + s2 * s3 / c2 * kth[2]),
               -kth[2]]
        if not hessian:
            return p_val, grad, tau
        ddrots = [_ddrot(a, cos[a], sin[a], zero) for a in range(3)]
        hess = [[None] * 3 for _ in range(3)]
        for a in range(3):
            for b in range(a, 3):
                f = list(rots)
                if a == b:
                    f[a] = ddrots[a]
                else:
                    f[a], f[b] = drots[a], drots[b]
                dd = self._w(f, self.R)
                kdw = _mv(self.K_t, dw[b]) if self.has_kt else [zero, zero, zero]
                spring = sum((k_arb[a][b] for _, _, k_arb, _, _ in self.springs[1:]), self.springs[0][2][a][b])
                hess[a][b] = hess[b][a] = spring + _dot(dw[a], kdw) + _dot(force, dd)
        return p_val, grad, tau, hess

    def point(self, theta: np.ndarray) -> float:
        """P at a point (float, for the search's ordering only)."""
        p_val = self.evaluate(theta, theta)[0]
        return float(p_val.mid())

    # the search's view of the model (shared with :class:`_TreeModel`)
    dim = 3
    coordinates = "theta"

    def torque_fails(self, tau, i: int) -> bool:
        """Whether the commanded torque tau_i (arb) may reach its limit."""
        lim = self.limit_arb[i]
        return lim is not None and not (abs(tau[i]) < lim)

    def torque_reached(self, tau, i: int) -> bool:
        """Whether it reaches its limit for certain (at a point)."""
        lim = self.limit_arb[i]
        return lim is not None and bool(abs(tau[i]) > lim)

    def torque_text(self, i: int) -> str:
        return f"the commanded torque |N_{i + 1}| (at Omega = 0) reaches its limit {self.limit[i]:g} N m"

    def scale(self) -> np.ndarray:
        """The boxes' sides are compared in these units per rad (the springs' sqrt(J))."""
        return np.sqrt(np.diag(self.k_r))

    def region(self, lo, hi):
        """One body's bounds of theta are the domain's faces: (inside, outside, text) = (True, False, "")."""
        return True, False, ""

    def level_cap(self, config) -> float:
        """An upper bound of the least P on the faces |theta_2| = gimbal: no c above it can be proven."""
        gimbal = GIMBAL_LOCK_ANGLE - config.simulation.gimbal_margin
        return min(self.point(np.array([self.reference[0] + s1, sg * gimbal, self.reference[2]]))
                   for s1 in (-1.0, 0.0, 1.0) for sg in (-1.0, 1.0))

    def domain(self, config, level_cap: float) -> np.ndarray:
        return _domain(config, self, level_cap)

    def boundary(self, config, a: int, edge: float) -> str:
        """The domain's face theta_a = edge [rad] in words, with what makes it one."""
        gimbal = GIMBAL_LOCK_ANGLE - config.simulation.gimbal_margin
        limits = config.simulation.limits
        theta_limit = np.full(3, np.inf) if limits is None else np.asarray(limits.array, dtype=float)[0]
        edge = abs(edge)
        what = ("the gimbal-lock margin" if a == 1 and edge >= gimbal
                else "simulation.limits.theta" if edge >= theta_limit[a] else "the search domain")
        return f"|theta_{a + 1}| = {edge:.4g} rad ({what})"


class _Jet:
    """A function of the box's coordinates as its value, gradient and (optionally) Hessian,
    each in arb, with +, - and * (forward-mode differentiation over interval arithmetic)."""

    __slots__ = ("v", "g", "h")

    def __init__(self, v, g, h=None) -> None:
        self.v, self.g, self.h = v, g, h

    def __add__(self, o):
        if not isinstance(o, _Jet):
            return _Jet(self.v + o, self.g, self.h)
        h = None if self.h is None else [[a + b for a, b in zip(r, q)] for r, q in zip(self.h, o.h)]
        return _Jet(self.v + o.v, [a + b for a, b in zip(self.g, o.g)], h)

    __radd__ = __add__

    def __neg__(self):
        return _Jet(-self.v, [-a for a in self.g], None if self.h is None else [[-a for a in r] for r in self.h])

    def __sub__(self, o):
        return self + (-o)

    def __rsub__(self, o):
        return (-self) + o

    def __mul__(self, o):
        if not isinstance(o, _Jet):
            return _Jet(self.v * o, [a * o for a in self.g], None if self.h is None else [[a * o for a in r]
                                                                                          for r in self.h])
        g = [self.v * b + o.v * a for a, b in zip(self.g, o.g)]
        h = None
        if self.h is not None:
            n = len(self.g)
            h = [[self.v * o.h[k][m] + o.v * self.h[k][m] + self.g[k] * o.g[m] + self.g[m] * o.g[k]
                  for m in range(n)] for k in range(n)]
        return _Jet(self.v * o.v, g, h)

    __rmul__ = __mul__


class _TreeModel:
    """P, grad P, its Hessian and each coordinate's static commanded torque (a slide's force)
    tau_j = -k_j (q_j - q_ref_j) over a box of the joints' coordinates q (a hinge's or a
    slide's one, a universal joint's two: a tree of those), in arb: v
    at rest is P(q) = sum_j [1/2 k_j (q_j - q_ref_j)^2 + 1/2 kp_j (q_j - qp_j)^2 + the range's
    stop, 1/2 k_s (q_j - end)^2 beyond either end] - sum_i G_i' X_i(q) + h (docs/physics.md,
    "Joint kinds"), X_i from the hinges' rotations exp(q_j [a_j]x) (a universal joint's
    exp(q_1 [a_1]x) exp(q_2 [a_2]x)) and the slides' offsets q_j a_j (a slide's q [m], its
    force [N]) parents first
    (:func:`rbstab.variants.tree.tree_expand`), differentiated forward (:class:`_Jet`). ``compiled``: the chain
    (:class:`rbstab.variants.chain.CompiledChain`), h = its offset."""

    coordinates = "q"

    def __init__(self, compiled, arb) -> None:
        self.arb, self.zero, self.one = arb, arb(0), arb(1)
        params = compiled.params
        self.bodies = list(compiled.chain.body_names)
        self.parents = [int(q) for q in compiled.parents]
        self.kinds = [compiled.chain.joints[j].variant for j in range(compiled.size)]
        # each coordinate's joint and entry (a universal joint's two), and each joint's first coordinate
        self.joint_of = [(j, k) for j, kind in enumerate(self.kinds) for k in range(_COVERED[kind])]
        self.first = [next(c for c, (i, _) in enumerate(self.joint_of) if i == j) for j in range(compiled.size)]
        self.dim = n = len(self.joint_of)
        names = list(compiled.chain.joint_names)
        self.joint_names = [names[j] for j, _ in self.joint_of]
        self.names = [f"{names[j]}.q_{k + 1}" if self.kinds[j] == "universal" else
                      f"{names[j]}.phi_{k + 1}" if self.kinds[j] == "ball" else names[j] for j, k in self.joint_of]
        self.slides = [self.kinds[j] == "slide" for j, _ in self.joint_of]
        # a ball's coordinates: the rotation vector phi of its turn from its reference, A_rel = A(Theta_ref) exp(phi)
        self.frames = [_rodrigues_values(arb, [arb(float(x)) for x in p["theta_ref"]],
                                         sum(arb(float(x)) ** 2 for x in p["theta_ref"])) for p in params]
        self.cones = [float(p["range_upper"][0]) if kind == "ball" and p["region"] > 0 else None
                      for kind, p in zip(self.kinds, params)]
        self.axes = [[arb(float(x)) for x in p["axis"]] for p in params]
        self.axes_2 = [[arb(float(x)) for x in p["axis_2"]] for p in params]
        # a hinge's numbers about its axis (its records' 3-vectors q a), a slide's in entry 0, a universal joint's
        # in entries 0 and 1
        along = [np.asarray(params[j]["axis"], dtype=float) if self.kinds[j] == "hinge" else np.eye(3)[k]
                 for j, k in self.joint_of]
        coordinate_params = [params[j] for j, _ in self.joint_of]
        ball = [self.kinds[j] == "ball" for j, _ in self.joint_of]  # its springs' references: phi = 0
        quad = [(float(a @ p["k_r"] @ a), 0.0 if b else float(a @ p["theta_ref"]))
                for a, p, b in zip(along, coordinate_params, ball)]
        passive = [(float(a @ p["passive_k_r"] @ a), 0.0 if b else float(a @ p["passive_theta_ref"]))
                   if p["passive"] > 0 else (0.0, 0.0) for a, p, b in zip(along, coordinate_params, ball)]
        self.springs = [(k, r, kp, rp) for (k, r), (kp, rp) in zip(quad, passive)]
        total = np.array([k + kp for k, _, kp, _ in self.springs])
        self.k_r = np.diag(total)
        self.reference = np.array([(k * r + kp * rp) / (k + kp) if k + kp > 0 else r
                                   for k, r, kp, rp in self.springs])
        self.stops = [(float(params[j]["range_lower"][k]), float(params[j]["range_upper"][k]),
                       float(params[j]["stop_k"][k])) if params[j]["stop"] > 0 else None for j, k in self.joint_of]
        # a range that is an admissible region: the domain's faces there (a run that reaches one fell)
        self.ranges = np.array([(params[j]["range_lower"][k], params[j]["range_upper"][k])
                                if params[j]["region"] > 0 and self.kinds[j] != "ball"  # a ball's cone: region()
                                else (-np.inf, np.inf) for j, k in self.joint_of], dtype=float)
        self.R_c = [[arb(float(x)) for x in p["attachment_point"]] for p in params]
        self.R_p = [[arb(float(x)) for x in r] for r in compiled.ppoints]
        self.G = [[arb(float(x)) for x in p["weight"]] for p in params]
        self.h = arb(float(compiled.offset))
        limits = compiled.params[0]["limits"][0] if compiled.params[0]["limited"] > 0 else np.full(3, np.inf)
        self.theta_limit = np.asarray(limits, dtype=float)  # |theta_i| of each body's Euler angles (eq 2)
        self.upper, self.lower = np.full(n, np.inf), np.full(n, -np.inf)
        for j, (a, p) in enumerate(zip(along, coordinate_params)):
            if p["saturation"] > 0:  # the per-axis limits a_i [lower, upper] back as numbers about a
                i = int(np.argmax(np.abs(a)))
                high, low = float(p["torque_limit"][i]) / a[i], float(p["torque_floor"][i]) / a[i]
                self.lower[j], self.upper[j] = min(high, low), max(high, low)

    def torque_fails(self, tau, i: int) -> bool:
        ok = (not np.isfinite(self.upper[i]) or bool(tau[i] < self.arb(self.upper[i]))) and \
             (not np.isfinite(self.lower[i]) or bool(tau[i] > self.arb(self.lower[i])))
        return not ok

    def torque_reached(self, tau, i: int) -> bool:
        return (np.isfinite(self.upper[i]) and bool(tau[i] > self.arb(self.upper[i]))) or \
            (np.isfinite(self.lower[i]) and bool(tau[i] < self.arb(self.lower[i])))

    def torque_text(self, i: int) -> str:
        what, units = ("force", "N") if self.slides[i] else ("torque", "N m")
        return (f"the commanded {what} of {self.names[i]} (at rest) reaches its limits "
                f"[{self.lower[i]:g}, {self.upper[i]:g}] {units}")

    def scale(self) -> np.ndarray:
        k = np.diag(self.k_r)
        return np.sqrt(np.maximum(k, 1e-9 * max(float(k.max()), 1.0)))

    def _outer(self) -> np.ndarray:
        """The largest box searched: half a turn either side of each hinge's reference,
        :data:`SLIDE_SEARCH` either side of each slide's, within its range where that is an
        admissible region."""
        half = np.where(self.slides, SLIDE_SEARCH, math.pi)
        return np.column_stack([np.maximum(self.reference - half, self.ranges[:, 0]),
                                np.minimum(self.reference + half, self.ranges[:, 1])])

    def level_cap(self, config) -> float:
        """An upper bound of the least P on the largest box's faces (points on each)."""
        outer, points = self._outer(), []
        for a in range(self.dim):
            for side in (0, 1):
                q = self.reference.copy()
                q[a] = outer[a, side]
                points.append(self.point(q))
        return min(points)

    def domain(self, config, level_cap: float) -> np.ndarray:
        """The largest box within the hinges' ranges that are admissible regions, narrowed
        where a spring alone holds every P <= ``level_cap`` inside."""
        g = sum(float(np.linalg.norm([float(x.mid()) for x in w])) for w in self.G)
        reach = sum(float(np.linalg.norm([float(x.mid()) for x in r])) for r in self.R_c + self.R_p)
        outer = self._outer()  # with the slides' largest |q| in the box searched
        reach += sum(float(np.max(np.abs(outer[j]))) for j in range(self.dim) if self.slides[j])
        floor = -g * reach + float(self.h.mid())  # |X_i| <= the sum of every |R| (|q|): -G'X >= -|G| that
        k = np.diag(self.k_r)
        with np.errstate(divide="ignore"):
            half = np.where(k > 0, np.sqrt(np.maximum(2.0 * (level_cap - floor) / np.where(k > 0, k, 1.0), 0.0)) * 1.05
                            + 1e-3, np.inf)
        return np.column_stack([np.maximum(self.reference - half, outer[:, 0]),
                                np.minimum(self.reference + half, outer[:, 1])])

    def boundary(self, config, a: int, edge: float) -> str:
        units, search = (("m", f"{SLIDE_SEARCH:g} m from the reference") if self.slides[a]
                         else ("rad", "half a turn from the reference"))
        if edge in self.ranges[a]:
            return (f"q of {self.names[a]} = {edge:.4g} {units} (joints.{self.joint_names[a]}.range, an admissible "
                    "region)")
        return f"q of {self.names[a]} = {edge:.4g} {units} (the search domain: {search})"

    def _square(self, lo: float, hi: float, centre: float):
        """(x - centre)^2 over [lo, hi], tight (0 where the interval holds the centre)."""
        a, b = lo - centre, hi - centre
        sq_hi = max(a * a, b * b)
        sq_lo = 0.0 if a <= 0.0 <= b else min(a * a, b * b)
        sq = self.arb(sq_lo).union(self.arb(sq_hi)) if sq_lo != sq_hi else self.arb(sq_lo)
        return sq + self.arb(0, 4e-16 * sq_hi + 1e-300)

    def _spring(self, j, x, lo, hi, hessian):
        """Hinge j's springs and stop as a jet: value tight, gradient and Hessian in arb."""
        arb, n = self.arb, self.dim
        k, r, kp, rp = self.springs[j]
        value = 0.5 * arb(k) * self._square(lo, hi, r) + 0.5 * arb(kp) * self._square(lo, hi, rp)
        slope = arb(k) * (x - arb(r)) + arb(kp) * (x - arb(rp))
        curvature = arb(k + kp)
        stop = self.stops[j]
        if stop is not None:  # beyond an end: 1/2 k_s (q - end)^2; a box across it: from 0
            lower, upper, k_s = stop
            for end, a, b in ((upper, max(lo, upper), hi), (lower, lo, min(hi, lower))):
                if a > b or (a == b and a == end):
                    continue  # the box lies inside the range on that side
                across = (lo < upper < hi) if end == upper else (lo < lower < hi)
                value = value + 0.5 * arb(k_s) * self._square(a, b, end)
                delta = _ball(arb, a - end, b - end)
                slope = slope + arb(k_s) * (delta.union(arb(0)) if across else delta)
                curvature = curvature + (arb(k_s).union(arb(0)) if across else arb(k_s))
        g = [self.zero] * n
        g[j] = slope
        h = None
        if hessian:
            h = [[self.zero] * n for _ in range(n)]
            h[j][j] = curvature
        return _Jet(value, g, h)

    def _turn(self, axis, x, c: int, hessian: bool):
        """exp(q [a]x) (Rodrigues) as a matrix of jets in coordinate c, q in the arb ball x."""
        zero, one, n = self.zero, self.one, self.dim
        cos_x, sin_x = x.cos(), x.sin()
        g_s, g_c = [zero] * n, [zero] * n
        g_s[c], g_c[c] = cos_x, -sin_x
        h_s = h_c = None
        if hessian:
            h_s, h_c = [[zero] * n for _ in range(n)], [[zero] * n for _ in range(n)]
            h_s[c][c], h_c[c][c] = -sin_x, -cos_x
        sin, cos = _Jet(sin_x, g_s, h_s), _Jet(cos_x, g_c, h_c)
        vers = one - cos
        x, y, z = axis
        return [[cos + vers * (x * x), vers * (x * y) - sin * z, vers * (x * z) + sin * y],
                [vers * (x * y) + sin * z, cos + vers * (y * y), vers * (y * z) - sin * x],
                [vers * (x * z) - sin * y, vers * (y * z) + sin * x, cos + vers * (z * z)]]

    def _size(self, lo, hi):
        """|phi|^2 over the box [lo, hi] of a rotation vector (3,), tight."""
        return self._square(lo[0], hi[0], 0.0) + self._square(lo[1], hi[1], 0.0) + self._square(lo[2], hi[2], 0.0)

    def _rodrigues(self, phi, lo, hi, c: int, hessian: bool):
        """exp([phi]x) (:func:`_rodrigues_values`) as a matrix of jets in coordinates c, c + 1,
        c + 2, phi the arb balls ``phi`` of the box [lo, hi]: each coefficient f(s) of
        s = |phi|^2 a jet by the chain rule, f'(s) grad s and f''(s) grad s grad s' + f'(s) H s."""
        arb, zero, n = self.arb, self.zero, self.dim
        g_s = [zero] * n
        for k in range(3):
            g_s[c + k] = 2 * phi[k]
        h_s = None
        if hessian:
            h_s = [[zero] * n for _ in range(n)]
            for k in range(3):
                h_s[c + k][c + k] = arb(2)
        s = _Jet(self._size(lo, hi), g_s, h_s)
        coefficients = []
        for offset in (0, 1, 2):
            f, df = _series(arb, (offset, 0), s.v), _series(arb, (offset, 1), s.v)
            h = None
            if hessian:
                ddf = _series(arb, (offset, 2), s.v)
                h = [[ddf * s.g[a] * s.g[b] + df * s.h[a][b] for b in range(n)] for a in range(n)]
            coefficients.append(_Jet(f, [df * g for g in s.g], h))
        c0, c1, c2 = coefficients
        x, y, z = (self._coordinate(phi[k], c + k, hessian) for k in range(3))
        return [[c0 + c2 * x * x, c2 * x * y - c1 * z, c2 * x * z + c1 * y],
                [c2 * x * y + c1 * z, c0 + c2 * y * y, c2 * y * z - c1 * x],
                [c2 * x * z - c1 * y, c2 * y * z + c1 * x, c0 + c2 * z * z]]

    def _coordinate(self, x, c: int, hessian: bool):
        """Coordinate c over the arb ball x as a jet."""
        g = [self.zero] * self.dim
        g[c] = self.one
        return _Jet(x, g, [[self.zero] * self.dim for _ in range(self.dim)] if hessian else None)

    def _ball_torque(self, phi, lo, hi, c: int):
        """A ball's commanded torque at rest -J_r(phi)^-T K phi [N m] (child frame; K its
        diagonal k_r, J_r^-1 = I + 1/2 [phi]x + c(s) [phi]x^2) over the arb balls ``phi``."""
        kphi = [self.arb(self.springs[c + k][0]) * phi[k] for k in range(3)]
        w = _cross(phi, kphi)
        u = _cross(phi, w)
        factor = _series(self.arb, "c", self._size(lo, hi))
        return [-(kphi[k] - 0.5 * w[k] + factor * u[k]) for k in range(3)]

    def evaluate(self, lo, hi, hessian: bool = False):
        """(P, grad P, tau) over the box [lo, hi] (arb balls); with ``hessian`` also the
        Hessian of P (dim x dim)."""
        arb, n, zero, one = self.arb, self.dim, self.zero, self.one
        q = [_ball(arb, lo[j], hi[j]) for j in range(n)]
        total = _Jet(self.h, [zero] * n, [[zero] * n for _ in range(n)] if hessian else None)
        rotations, positions = [], []  # each body's A_i and X_i
        for c in range(n):
            total = total + self._spring(c, q[c], lo[c], hi[c], hessian)
        for j, parent in enumerate(self.parents):
            c = self.first[j]
            if self.kinds[j] == "slide":  # turned as its parent; its point moved by q a (the parent's frame)
                g = [zero] * n
                g[c] = one
                slid = _Jet(q[c], g, [[zero] * n for _ in range(n)] if hessian else None)
                point = [self.R_p[j][r] + self.axes[j][r] * slid for r in range(3)]
                a = [[one if r == col else zero for col in range(3)] for r in range(3)] if parent < 0 \
                    else rotations[parent]
            else:  # A_rel = exp(q [a]x), a universal joint's exp(q_1 [a_1]x) exp(q_2 [a_2]x), a ball's A_ref exp(phi)
                if self.kinds[j] == "ball":
                    rel = _mm(self.frames[j], self._rodrigues(q[c: c + 3], lo[c: c + 3], hi[c: c + 3], c, hessian))
                else:
                    rel = self._turn(self.axes[j], q[c], c, hessian)
                if self.kinds[j] == "universal":
                    rel = _mm(rel, self._turn(self.axes_2[j], q[c + 1], c + 1, hessian))
                point, a = list(self.R_p[j]), rel if parent < 0 else _mm(rotations[parent], rel)
            if parent < 0:
                anchor = point
            else:
                offset = _mv(rotations[parent], point)
                anchor = [positions[parent][r] + offset[r] for r in range(3)]
            rotations.append(a)
            arm = _mv(a, self.R_c[j])
            x_j = [anchor[r] - arm[r] for r in range(3)]
            positions.append(x_j)
            for r in range(3):
                total = total - x_j[r] * self.G[j][r]
        tau = [-(arb(k) * (q[j] - arb(r))) for j, (k, r, _, _) in enumerate(self.springs)]
        for j, kind in enumerate(self.kinds):  # a ball's: -J_r(phi)^-T K phi (its commanded torque at rest)
            if kind == "ball":
                c = self.first[j]
                tau[c: c + 3] = self._ball_torque(q[c: c + 3], lo[c: c + 3], hi[c: c + 3], c)
        value = total.v if isinstance(total, _Jet) else total
        if not hessian:
            return value, total.g, tau
        return value, total.g, tau, total.h

    def point(self, q: np.ndarray) -> float:
        """P at a point (float, for the search's ordering only)."""
        return float(self.evaluate(q, q)[0].mid())

    def region(self, lo, hi):
        """(whether every body's Euler angles (eq 2) lie inside ``simulation.limits.theta``
        for certain over the box, whether some lie outside for certain, the first body
        and bound not certainly kept) from the bodies' rotations in arb: with A = Rx Ry Rz
        and cos theta_2 > 0, |theta_1| < L iff A_33 > 0 and |A_23| < tan(L) A_33, |theta_2| < L
        iff |A_13| < sin(L), |theta_3| < L iff A_11 > 0 and |A_12| < tan(L) A_11. A ball's turn
        |phi| stays inside its chart (:data:`BALL_CHART`) and the angle of its A_rel inside its
        range where that is an admissible region: angle < r iff trace A_rel > 1 + 2 cos r."""
        balls = "ball" in self.kinds
        if not np.any(np.isfinite(self.theta_limit)) and not balls:
            return True, False, ""
        arb = self.arb
        rotations, inside, outside, text = [], True, False, ""
        for j, kind in enumerate(self.kinds):
            if kind != "ball":
                continue
            c = self.first[j]
            size = self._size(lo[c: c + 3], hi[c: c + 3])
            if not size < arb(BALL_CHART ** 2) and inside:
                inside = False
                text = (f"the turn |phi| of {self.joint_names[c]} from its reference may reach {BALL_CHART:.4g} rad "
                        "(the chart of its rotation vector)")
            outside = outside or bool(size > arb(BALL_CHART ** 2))

        def turn(axis, lo_c, hi_c):
            x = _ball(arb, lo_c, hi_c)
            c, s = x.cos(), x.sin()
            v = 1 - c
            ax, ay, az = axis
            return [[c + v * ax * ax, v * ax * ay - s * az, v * ax * az + s * ay],
                    [v * ax * ay + s * az, c + v * ay * ay, v * ay * az - s * ax],
                    [v * ax * az - s * ay, v * ay * az + s * ax, c + v * az * az]]

        for j, parent in enumerate(self.parents):
            c = self.first[j]
            if self.kinds[j] == "slide":  # turned as its parent
                rotations.append([[arb(1) if r == col else arb(0) for col in range(3)] for r in range(3)]
                                 if parent < 0 else rotations[parent])
                continue
            if self.kinds[j] == "ball":
                phi = [_ball(arb, lo[c + k], hi[c + k]) for k in range(3)]
                rel = _mm(self.frames[j], _rodrigues_values(arb, phi, self._size(lo[c: c + 3], hi[c: c + 3])))
                if self.cones[j] is not None:
                    trace, least = rel[0][0] + rel[1][1] + rel[2][2], arb(1) + 2 * arb(self.cones[j]).cos()
                    if not trace > least and inside:
                        inside = False
                        text = (f"the turn of {self.joint_names[c]} may reach its range {self.cones[j]:g} rad "
                                f"(joints.{self.joint_names[c]}.range, an admissible region)")
                    outside = outside or bool(trace < least)
            else:
                rel = turn(self.axes[j], lo[c], hi[c])
            if self.kinds[j] == "universal":
                rel = _mm(rel, turn(self.axes_2[j], lo[c + 1], hi[c + 1]))
            a = rel if parent < 0 else _mm(rotations[parent], rel)
            rotations.append(a)
            for i, (num, den) in enumerate(((a[1][2], a[2][2]), (a[0][2], None), (a[0][1], a[0][0]))):
                bound = self.theta_limit[i]
                if not np.isfinite(bound):
                    continue
                if den is None:
                    keeps, leaves = abs(num) < arb(math.sin(bound)), abs(num) > arb(math.sin(bound))
                else:
                    keeps = den > 0 and abs(num) < arb(math.tan(bound)) * den
                    leaves = den < 0 or abs(num) > arb(math.tan(bound)) * den
                if not keeps and inside:
                    inside = False
                    text = f"|theta_{i + 1}| of {self.bodies[j]} may reach simulation.limits.theta = {bound:g} rad"
                outside = outside or bool(leaves)
        return inside, outside, text


def _positive_definite(hess) -> bool:
    """Every symmetric matrix in the interval matrix (1 x 1 to 3 x 3) is positive definite
    (leading minors bounded away from zero, Sylvester)."""
    minors = [hess[0][0]]
    if len(hess) > 1:
        minors.append(hess[0][0] * hess[1][1] - hess[0][1] * hess[1][0])
    if len(hess) > 2:
        minors.append(hess[0][0] * (hess[1][1] * hess[2][2] - hess[1][2] * hess[2][1])
                      - hess[0][1] * (hess[1][0] * hess[2][2] - hess[1][2] * hess[2][0])
                      + hess[0][2] * (hess[1][0] * hess[2][1] - hess[1][1] * hess[2][0]))
    return all(bool(m > 0) for m in minors)


def _convex_box(model, centre: np.ndarray, radius: float) -> float:
    """The largest half-width <= ``radius`` (halving) of a box around ``centre`` on which
    the interval Hessian of P is positive definite (on each of its 2^dim corner sub-boxes); 0 if none."""
    dim = model.dim
    for _ in range(24):
        ok = True
        for corner in range(2 ** dim):
            sign = np.array([1.0 if corner >> i & 1 else -1.0 for i in range(dim)])
            a, b = centre, centre + sign * radius
            if not _positive_definite(model.evaluate(np.minimum(a, b), np.maximum(a, b), hessian=True)[3]):
                ok = False
                break
        if ok:
            return radius
        radius *= 0.5
    return 0.0


def _domain(config, model: _Model, level_cap: float):
    """The box D of Theta, (3, 2) [rad]: |theta_2| <= pi/2 - gimbal margin, the bounds of
    ``simulation.limits.theta``, and otherwise wide enough about the reference posture that
    the spring alone holds every P <= level_cap inside it."""
    gimbal = GIMBAL_LOCK_ANGLE - config.simulation.gimbal_margin
    limits = config.simulation.limits
    theta_limit = np.full(3, np.inf) if limits is None else np.asarray(limits.array, dtype=float)[0]
    k_min = float(np.linalg.eigvalsh(model.k_r).min())
    # P >= 0.5 k_min |dTheta|^2 - (|R_p| + |R_c|) |G| + h  (0.5 X'K_t X >= 0, |X| <= |R_p| + |R_c|)
    floor = -model.reach * model.weight + model.offset
    # and with a diagonal K_r, P >= 0.5 k_i (theta_i - theta_ref_i)^2 + that floor for each i
    k = np.diag(model.k_r) if model.diag_kr else np.full(3, k_min)
    half = np.sqrt(np.maximum(2.0 * (level_cap - floor) / k, 0.0)) * 1.05 + 1e-3
    bound = np.minimum(theta_limit, [np.inf, gimbal, np.inf])
    return np.column_stack([np.maximum(model.reference - half, -bound), np.minimum(model.reference + half, bound)])


@dataclass(order=True)
class _Item:
    key: float
    index: int
    lo: np.ndarray = field(compare=False)
    hi: np.ndarray = field(compare=False)
    p_lo: object = field(compare=False)


def _lower(x) -> float:
    """A float <= every value of the arb ball x."""
    return math.nextafter(float(x.lower()), -math.inf)


def verify_sublevel(config, level: float | None = None, *, rtol: float = DEFAULT_RTOL,
                    max_boxes: int = MAX_BOXES) -> Verification:
    """Prove {v <= c} positively invariant and inside the region of attraction (module
    docstring).

    Parameters
    ----------
    config : RunConfig or path-like
        A ``permanent`` configuration, or a chain that is one (:func:`verified_model`,
        :func:`check_verifiable`).
    level : float, optional
        c [J] to prove; None: the largest c the method proves, to ``rtol``.
    rtol : float
        Relative tolerance of the largest c.
    max_boxes : int
        The most boxes of the search.

    Returns
    -------
    Verification

    Raises
    ------
    NotVerifiable
        For a configuration the method does not cover, or a ``level`` it cannot prove
        (the message names the box and the condition that failed there).
    """
    if isinstance(config, (str, os.PathLike)):
        from ..config import load_config  # heavy: pydantic

        config = load_config(config)
    config = verified_model(config)
    check_verifiable(config)
    arb = _arb()
    t0 = _time.perf_counter()
    model, equilibrium = _model(config, arb)
    dim, name = model.dim, model.coordinates
    level_cap = model.level_cap(config) if level is None else max(float(level), 0.0)
    domain = model.domain(config, level_cap)
    limits = config.simulation.limits
    omega_limit = np.full(3, np.inf) if limits is None else np.asarray(limits.array, dtype=float)[1]
    radius = _convex_box(model, equilibrium, 0.025 * float(np.min(domain[:, 1] - domain[:, 0])))
    if radius == 0.0:
        raise NotVerifiable("the interval Hessian of P is not positive definite on any box around the equilibrium "
                            f"{name} = {np.round(equilibrium, 6).tolist()} rad")
    e_lo, e_hi = equilibrium - radius, equilibrium + radius
    scale = model.scale()  # sides in units of the springs' sqrt(J)
    min_width = _MIN_WIDTH * float(np.max((domain[:, 1] - domain[:, 0]) * scale))

    heap: list[_Item] = []
    counter = 0

    def push(lo, hi) -> None:
        nonlocal counter
        counter += 1
        p_val, grad, tau = model.evaluate(lo, hi)
        # mean-value form: P(mid) + grad P(box) (q - mid), intersected with the plain one
        mid = 0.5 * (lo + hi)
        p_mid = model.evaluate(mid, mid)[0]
        mvf = p_mid
        for a in range(dim):  # q_a - mid_a over the box, in arb (no float rounding)
            mvf = mvf + grad[a] * (_ball(arb, lo[a], hi[a]) - arb(float(mid[a])))
        try:
            p_val = p_val.intersection(mvf)
        except ValueError:  # disjoint enclosures cannot both hold: keep the first
            pass
        heapq.heappush(heap, _Item(_lower(p_val), counter, lo, hi, (p_val, grad, tau)))

    push(domain[:, 0].copy(), domain[:, 1].copy())
    best_bad = math.inf  # least P found at a point that fails (for the stopping rule only)
    point_failure = ""
    p_floor = None
    reason, bad_box = "", np.zeros((dim, 2))
    result_level = None
    while heap:
        item = heapq.heappop(heap)
        lo, hi = item.lo, item.hi
        p_val, grad, tau = item.p_lo
        if p_floor is None:
            p_floor = item.key  # best-first: the least lower bound of P on D
        if level is not None and item.key > level:
            result_level = float(level)
            break
        if level is None and item.key >= best_bad * (1.0 - rtol):
            result_level = item.key
            reason = reason or "the search's tolerance"
            break
        failures = []
        on_face = ([(a, 0) for a in range(dim) if lo[a] <= domain[a, 0]]
                   + [(a, 1) for a in range(dim) if hi[a] >= domain[a, 1]])
        if on_face:
            a, side = on_face[0]
            edge = domain[a, side]
            failures.append(f"the level set reaches the domain boundary {model.boundary(config, a, edge)}")
            pt = 0.5 * (lo + hi)
            pt[a] = edge
            if model.point(pt) < best_bad:
                best_bad, point_failure = model.point(pt), failures[-1]
        inside, _, text = model.region(lo, hi)
        if not inside:
            failures.append(f"the level set reaches the admissible region's boundary: {text}")
            mid = 0.5 * (lo + hi)
            if model.region(mid, mid)[1] and model.point(mid) < best_bad:
                best_bad, point_failure = model.point(mid), failures[-1]
        for i in range(dim):
            if model.torque_fails(tau, i):
                failures.append(model.torque_text(i))
                mid = 0.5 * (lo + hi)
                if model.torque_reached(model.evaluate(mid, mid)[2], i) and model.point(mid) < best_bad:
                    best_bad, point_failure = model.point(mid), failures[-1]
        inside_e = bool(np.all(lo >= e_lo) and np.all(hi <= e_hi))
        if not inside_e and not any(g > 0 or g < 0 for g in grad):
            failures.append("grad P may vanish there (a rest point other than the equilibrium cannot be excluded)")
        if not failures:
            continue
        if level is not None and best_bad <= level:  # a point of the box fails below the level
            raise NotVerifiable(f"v <= {level:g} J not proven: box {name} in "
                                f"{_fmt_box(np.column_stack([lo, hi]))}: {point_failure}")
        widths = (hi - lo) * scale
        if float(np.max(widths)) <= min_width or counter >= max_boxes:
            reason = failures[0] + (" (box limit reached)" if counter >= max_boxes else "")
            bad_box = np.column_stack([lo, hi])
            if level is not None:
                raise NotVerifiable(f"v <= {level:g} J not proven: box {name} in "
                                    f"{_fmt_box(bad_box)}: {reason}")
            result_level = item.key
            break
        if level is None:  # the last box that failed before the search stopped
            reason = failures[0]
            bad_box = np.column_stack([lo, hi])
        a = int(np.argmax(widths))
        m = 0.5 * (lo[a] + hi[a])
        lo2, hi1 = lo.copy(), hi.copy()
        hi1[a], lo2[a] = m, m
        push(lo.copy(), hi1)
        push(lo2, hi.copy())
    else:
        result_level = math.inf if level is None else float(level)
    if level is None:
        result_level = min(result_level, level_cap)
        # strictly below the lower bound: no failing point has P <= c
        result_level = result_level * (1.0 - 1e-9) if result_level > 0 else result_level
    # Omega's bounds of simulation.limits (one body): 0.5 Omega' J_p Omega <= c - min P
    for i in range(3):
        if np.isfinite(omega_limit[i]):
            jp_inv = np.linalg.inv(model.pivot_inertia)
            cap = (p_floor or 0.0) + 0.5 * omega_limit[i] ** 2 / jp_inv[i, i] * (1.0 - 1e-9)
            if cap < result_level:
                if level is not None:
                    raise NotVerifiable(f"v <= {level:g} J not proven: |Omega_{i + 1}| may reach "
                                        f"simulation.limits.omega = {omega_limit[i]:g} rad/s")
                result_level = cap
                reason = f"|Omega_{i + 1}| may reach simulation.limits.omega = {omega_limit[i]:g} rad/s"
    if level is None and not result_level > 0.0:
        raise NotVerifiable(f"no level c > 0 proven: box {name} in {_fmt_box(bad_box)}: {reason}")
    if level is not None:
        reason = f"v <= {level:g} J proven"
    else:
        reason = f"box {name} in {_fmt_box(bad_box)}: {reason}"
    return Verification(level=float(result_level), boxes=counter, seconds=_time.perf_counter() - t0,
                        reason=reason, box=bad_box, equilibrium_box=radius, coordinates=name,
                        names=tuple(getattr(model, "names", ())))


def _fmt_box(box: np.ndarray) -> str:
    return " x ".join(f"[{a:.4g}, {b:.4g}]" for a, b in box)


def verify_analysis(analysis, *, rtol: float = DEFAULT_RTOL) -> Verification:
    """:func:`verify_sublevel` of an :class:`~rbstab.analysis.analyze.Analysis`'s analysed
    configuration (the largest c proven)."""
    return verify_sublevel(analysis.analysed, rtol=rtol)


def potential(config, theta: np.ndarray) -> float:
    """P(Theta) [J] of the module docstring at one Theta (3,) [rad], by the interval
    kernel (its ball's midpoint): v at rest."""
    return _model(config, _arb())[0].point(np.asarray(theta, dtype=float))


def _model(config, arb):
    """(the interval kernel of ``config``'s tree, its equilibrium (the tree's rest state,
    :func:`rbstab.analysis.linearise.linearise_chain`, with the tree's h): one body's
    :class:`_Model` and Theta_e (3,) [rad], or a tree of hinges, slides, universal joints
    and balls' :class:`_TreeModel` and each coordinate q at rest (dim,) [rad; a slide's m; a
    ball's rotation vector of its turn from its reference])."""
    from ..variants import chain as C  # heavy: numba
    from .linearise import ball_entries, linearise_chain, undisturbed  # heavy: numba

    compiled = C.compile_chain(undisturbed(config).chain)
    lin, _ = linearise_chain(compiled)
    if compiled.hinged:
        from ..variants.tree import tree_layout  # heavy: numba

        from scipy.spatial.transform import Rotation  # heavy: scipy

        model = _TreeModel(compiled, arb)
        r_at, rest = tree_layout(compiled).r_at, np.asarray(lin.equilibrium, dtype=float)
        z_index, r_index, balls = ball_entries(compiled)
        at = dict(zip(r_index.tolist(), z_index.tolist())) | {r: z for z, r in balls}  # reduced entry -> z's
        equilibrium = rest[[at[int(r_at[j])] + k for j, k in model.joint_of]]
        for j, kind in enumerate(model.kinds):  # a ball's rotation vector of A_rel as its turn from its reference
            if kind == "ball":
                c = model.first[j]
                turn = (Rotation.from_rotvec(np.array(compiled.params[j]["theta_ref"], dtype=float)).inv()
                        * Rotation.from_rotvec(equilibrium[c: c + 3]))
                equilibrium[c: c + 3] = turn.as_rotvec()
        return model, equilibrium
    return _Model(compiled.params[0], compiled.ppoints[0], compiled.offset, arb), np.asarray(lin.equilibrium[:3])
