"""Frozen physical inputs of a run (Table 1, eqs 22-24, 39, 40) and the feedback (eqs 23, 24).

:class:`RigidBody` and :class:`Gains` are plain data; validation happens once, when a
configuration is loaded (:mod:`rbstab.config`), and the core trusts what it finds here.
:func:`parameters` packs both into one record of :data:`PARAMETERS`, the runtime argument of
every compiled function: one compiled kernel per variant serves every body and every gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .jit import jit
from .layout import LIMITED
from .kinematics import cross, hat, matTvec, matvec, neg, sub

__all__ = ["RigidBody", "Gains", "Saturation", "SATURATION_SHAPES", "Disturbance", "DISTURBANCE_KINDS",
           "DISTURBANCE_QUANTITIES", "MAX_DISTURBANCES", "NOISE_TONES", "Limits", "PARAMETERS", "parameters",
           "set_disturbances", "set_limits", "gyroscopic", "pressure_point",
           "saturate", "saturated", "saturate_between", "saturated_between", "torque_n_command", "force_h_command", "torque_n", "force_h"]


@dataclass(frozen=True, eq=False)
class RigidBody:
    """One rigid body (Table 1).

    Attributes
    ----------
    mass : float
        m [kg], > 0.
    inertia : ndarray, shape (3, 3)
        J [kg m^2] about the centre of mass, body frame, symmetric positive definite.
    attachment_point : ndarray, shape (3,)
        R [m], the point C in the body frame.
    gravity : ndarray, shape (3,)
        g [m/s^2] in the inertial frame; the weight is ``G = mass * g`` [N].
    """

    mass: float
    inertia: np.ndarray
    attachment_point: np.ndarray
    gravity: np.ndarray

    @cached_property
    def weight(self) -> np.ndarray:
        """G = m g [N], inertial frame, shape (3,)."""
        return self.mass * np.asarray(self.gravity, dtype=float)

    @cached_property
    def inertia_inv(self) -> np.ndarray:
        """J^-1 [1/(kg m^2)], shape (3, 3)."""
        return np.linalg.inv(self.inertia)

    @cached_property
    def r_hat(self) -> np.ndarray:
        """hat(R) [m], shape (3, 3)."""
        return hat(self.attachment_point)

    @cached_property
    def pivot_inertia(self) -> np.ndarray:
        """J_p = J - m hat(R)^2 [kg m^2], inertia about C (eq 21 corrected), shape (3, 3)."""
        return self.inertia - self.mass * self.r_hat @ self.r_hat

    @cached_property
    def pivot_inertia_inv(self) -> np.ndarray:
        """J_p^-1, shape (3, 3)."""
        return np.linalg.inv(self.pivot_inertia)


#: The shapes of a saturating actuator by name, and their codes in :data:`PARAMETERS`'s
#: ``saturation`` (0: no limits): ``clip`` min(max(u, -u_max), u_max); ``smooth`` u_max
#: tanh(u / u_max).
SATURATION_SHAPES = {"clip": 1, "smooth": 2}


@dataclass(frozen=True, eq=False)
class Saturation:
    """What the actuators can deliver: |u_i| <= limit_i for each axis i (inf: unlimited).

    Attributes
    ----------
    torque_n : ndarray, shape (3,)
        Limits of N [N m], body frame (eq 23).
    force_h : ndarray, shape (3,)
        Limits of H [N], inertial frame (eq 24).
    constraint_force : ndarray, shape (3,)
        Limits of Lambda [N], inertial frame (eqs 22, 39, 40; not ``permanent``'s pin).
    shape : str
        A key of :data:`SATURATION_SHAPES`.
    torque_n_lower : ndarray, shape (3,), or None
        Lower limits of a tree joint's N [N m], each < 0 (-inf: none), ``torque_n`` then its
        upper limits: lower_i <= N_i <= torque_n_i (an actuator stronger one way, MJCF's
        ``forcerange``). None: -``torque_n``, the paper's symmetric limits.
    """

    torque_n: np.ndarray
    force_h: np.ndarray
    constraint_force: np.ndarray
    shape: str = "clip"
    torque_n_lower: np.ndarray | None = None


#: The kinds of a disturbance by name, and their codes in :data:`PARAMETERS`'s
#: ``disturbance_kind`` (0: no entry): ``impulse`` a jump of the velocities at ``start``;
#: ``pulse`` a constant value on [start, start + duration); ``step`` a constant value from
#: ``start`` on; ``sine`` value sin(2 pi frequency (t - start) + phase) from ``start`` on;
#: ``noise`` a seeded random-phase multisine in ``band`` with RMS ``rms`` from ``start`` on.
DISTURBANCE_KINDS = {"impulse": 1, "pulse": 2, "step": 3, "sine": 4, "noise": 5}
#: What a disturbance applies, and its code in ``disturbance_torque``: a force at a point of
#: the body (value in the inertial frame) or a torque (body frame).
DISTURBANCE_QUANTITIES = {"force": 0, "torque": 1}
#: Most disturbances of one run (the entries of :data:`PARAMETERS`'s disturbance fields).
MAX_DISTURBANCES = 4
#: Sines of a noise disturbance per axis (a random-phase multisine, equal amplitudes).
NOISE_TONES = 16


@dataclass(frozen=True, eq=False)
class Disturbance:
    """One disturbance acting on the body (docs/disturbances.md).

    Attributes
    ----------
    kind : str
        A key of :data:`DISTURBANCE_KINDS`.
    quantity : str
        ``force`` (at ``point``, inertial frame) or ``torque`` (body frame).
    value : ndarray, shape (3,)
        impulse [N s] or [N m s]; pulse, step, sine amplitude [N] or [N m]; noise: the RMS
        per axis [N] or [N m].
    point : ndarray, shape (3,)
        R_p [m], body frame, from the centre of mass (force only).
    start : float
        t0 [s].
    duration : float
        pulse only [s].
    frequency, phase : float
        sine only [Hz], [rad].
    band : tuple of float
        noise only: (f_lo, f_hi) [Hz].
    seed : int
        noise only.
    """

    kind: str
    quantity: str
    value: np.ndarray
    point: np.ndarray
    start: float
    duration: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0
    band: tuple[float, float] = (0.0, 0.0)
    seed: int = 0


@dataclass(frozen=True, eq=False)
class Limits:
    """The admissible region of a run (``simulation.limits``): |q_i| <= bound_i for each
    bounded quantity q and axis i; inf where unbounded. A run that leaves it stops, failed.

    Attributes
    ----------
    theta : ndarray, shape (3,)
        Bounds of |theta_i| [rad] (Euler angles).
    omega : ndarray, shape (3,)
        Bounds of |Omega_i| [rad/s], body frame.
    position : ndarray, shape (3,)
        Bounds of |X_i| [m], the centre of mass in the inertial frame (from the origin,
        where the translational feedback H = -K_t X - L_t V pulls it; not from the
        equilibrium, which gravity moves).
    velocity : ndarray, shape (3,)
        Bounds of |V_i| [m/s], inertial frame.
    constraint_error : ndarray, shape (3,)
        Bounds of |E_i| [m], inertial frame (eq 4; not ``permanent``, whose E is 0).
    """

    theta: np.ndarray
    omega: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    constraint_error: np.ndarray

    @classmethod
    def of(cls, **bounds) -> "Limits":
        """Limits from keyword bounds (names of :data:`rbstab.layout.LIMITED`), each a number
        (every axis) or 3, None or absent: inf."""
        unknown = set(bounds) - set(LIMITED)
        if unknown:
            raise TypeError(f"Limits.of: unknown quantities {sorted(unknown)}; allowed: {', '.join(LIMITED)}")
        return cls(**{name: np.broadcast_to(np.array(np.inf if bounds.get(name) is None else bounds[name],
                                                     dtype=float), (3,)).copy() for name in LIMITED})

    @property
    def array(self) -> np.ndarray:
        """The bounds as rows in the order of :data:`rbstab.layout.LIMITED`, shape (5, 3)."""
        return np.array([getattr(self, name) for name in LIMITED], dtype=float)

    @property
    def bounded(self) -> bool:
        """Whether any bound is finite."""
        return bool(np.isfinite(self.array).any())


@dataclass(frozen=True, eq=False)
class Gains:
    """Feedback and constraint gains, each symmetric, shape (3, 3).

    Attributes
    ----------
    k_t, l_t : ndarray
        Translational stiffness [N/m] and damping [N s/m] of H (eq 24).
    k_r, l_r : ndarray
        Rotational stiffness [N m/rad] and damping [N m s/rad] of N (eq 23).
    k_c, l_c : ndarray or None
        Constraint stiffness [N/m] and damping [N s/m] (eqs 22, 40).
    k_d, l_d : ndarray or None
        Embedded-controller stiffness [N/m] and damping [N s/m] (eq 22).
    k_s : float or None
        Sliding-mode force magnitude K_s [N] (eq 39).
    boundary_layer : float
        Sliding boundary-layer width phi [m]; 0 means a pure sign function.
    saturation : Saturation or None
        The actuators' limits (None: unlimited, the paper's linear feedback).
    disturbances : tuple of Disturbance
        What acts on the body besides the controls (at most :data:`MAX_DISTURBANCES`).
    """

    k_t: np.ndarray
    l_t: np.ndarray
    k_r: np.ndarray
    l_r: np.ndarray
    k_c: np.ndarray | None = None
    l_c: np.ndarray | None = None
    k_d: np.ndarray | None = None
    l_d: np.ndarray | None = None
    k_s: float | None = None
    boundary_layer: float = 0.0
    saturation: Saturation | None = None
    disturbances: tuple[Disturbance, ...] = ()

    @cached_property
    def l_d_inv(self) -> np.ndarray:
        """L_d^-1 [m/(N s)], shape (3, 3)."""
        return np.linalg.inv(self.l_d)


_MATRIX = (np.float64, (3, 3))
_VECTOR = (np.float64, (3,))

#: One run's physical parameters as a numpy record (the argument ``p`` of every compiled
#: function; fields read as ``p.mass``, ``p.k_t``): the body (SI units, frames as in
#: :class:`RigidBody`), the quantities derived from it once (J^-1, J_p = J - m hat(R)^2 and
#: its inverse, G = m g), every gain (zero where the variant has none), L_d^-1, K_s,
#: the boundary layer phi, the constant h [J] that makes v zero at the equilibrium, and the
#: actuators' limits of N [N m], H [N] and Lambda [N] with the code of their shape
#: (:data:`SATURATION_SHAPES`; 0, as in a record of zeros: no limits, which are then not read);
#: then the disturbances: their number (0: none, the other fields not read) and, entry by
#: entry (:data:`MAX_DISTURBANCES`), the code of their kind (:data:`DISTURBANCE_KINDS`),
#: whether a torque (:data:`DISTURBANCE_QUANTITIES`), value (noise: its RMS), point, start,
#: duration, frequency, phase, band and seed (:class:`Disturbance`); last the admissible
#: region (:class:`Limits`): ``limited`` (1 when any bound is finite; 0, as in a record of
#: zeros: none, ``limits`` not read) and ``limits`` (5, 3), the bounds of |theta_i| [rad],
#: |Omega_i| [rad/s], |X_i| [m], |V_i| [m/s], |E_i| [m] in the rows of
#: :data:`rbstab.layout.LIMITED` (inf: none); last what a tree's joint adds to the paper's
#: feedback (:class:`rbstab.chain.Joint`; the paper's one body: zero, not read): its
#: reference posture ``theta_ref`` Theta_ref [rad], the lower limits of N ``torque_floor``
#: [N m] (-``torque_limit`` unless :class:`Saturation` gives its own) and its passive torque
#: (:class:`rbstab.chain.Passive`): ``passive`` (1 where the joint has one; 0, as in a
#: record of zeros: none, the next fields not read), ``passive_k_r`` [N m/rad],
#: ``passive_l_r`` [N m s/rad] and ``passive_theta_ref`` [rad]; a hinge's unit ``axis``
#: a (the parent's and the child's frames; zero for any other joint), a universal joint's
#: unit ``axis`` a_1 (the parent's frame) and ``axis_2`` a_2 (the child's frame; zero for
#: any other joint), and the range of a joint's coordinates (entry 0 a hinge's q, entries
#: 0-1 a universal joint's q_1, q_2, entries 0-2 a ball's Euler angles Theta_j) as a stop (:class:`rbstab.chain.Stop`): ``stop`` (1 where it has one; 0: none,
#: the next fields not read), ``range_lower``, ``range_upper`` [rad], ``stop_k`` [N m/rad]
#: and ``stop_l`` [N m s/rad], or as an admissible region (:class:`rbstab.chain.Region`):
#: ``region`` 1 (a run whose coordinate leaves [``range_lower``, ``range_upper``] stops
#: there, fell; 0: none).
PARAMETERS = np.dtype(
    [
        ("mass", np.float64),
        ("inertia", *_MATRIX),
        ("inertia_inv", *_MATRIX),
        ("pivot_inertia", *_MATRIX),
        ("pivot_inertia_inv", *_MATRIX),
        ("attachment_point", *_VECTOR),
        ("weight", *_VECTOR),
        ("k_t", *_MATRIX),
        ("l_t", *_MATRIX),
        ("k_r", *_MATRIX),
        ("l_r", *_MATRIX),
        ("k_c", *_MATRIX),
        ("l_c", *_MATRIX),
        ("k_d", *_MATRIX),
        ("l_d", *_MATRIX),
        ("l_d_inv", *_MATRIX),
        ("k_s", np.float64),
        ("boundary_layer", np.float64),
        ("lyapunov_offset", np.float64),
        ("torque_limit", *_VECTOR),
        ("force_limit", *_VECTOR),
        ("constraint_force_limit", *_VECTOR),
        ("saturation", np.float64),
        ("disturbance_count", np.float64),
        ("disturbance_kind", np.float64, (MAX_DISTURBANCES,)),
        ("disturbance_torque", np.float64, (MAX_DISTURBANCES,)),
        ("disturbance_value", np.float64, (MAX_DISTURBANCES, 3)),
        ("disturbance_point", np.float64, (MAX_DISTURBANCES, 3)),
        ("disturbance_start", np.float64, (MAX_DISTURBANCES,)),
        ("disturbance_duration", np.float64, (MAX_DISTURBANCES,)),
        ("disturbance_frequency", np.float64, (MAX_DISTURBANCES,)),
        ("disturbance_phase", np.float64, (MAX_DISTURBANCES,)),
        ("disturbance_band", np.float64, (MAX_DISTURBANCES, 2)),
        ("disturbance_seed", np.float64, (MAX_DISTURBANCES,)),
        ("limited", np.float64),
        ("limits", np.float64, (len(LIMITED), 3)),
        ("theta_ref", *_VECTOR),
        ("torque_floor", *_VECTOR),
        ("passive", np.float64),
        ("passive_k_r", *_MATRIX),
        ("passive_l_r", *_MATRIX),
        ("passive_theta_ref", *_VECTOR),
        ("axis", *_VECTOR),
        ("axis_2", *_VECTOR),
        ("stop", np.float64),
        ("range_lower", *_VECTOR),
        ("range_upper", *_VECTOR),
        ("stop_k", *_VECTOR),
        ("stop_l", *_VECTOR),
        ("region", np.float64),
    ],
    align=True,
)


def parameters(body: RigidBody, gains: Gains, lyapunov_offset: float = 0.0,
               limits: Limits | None = None) -> np.ndarray:
    """The record of :data:`PARAMETERS` for ``body``, ``gains`` and the admissible region
    ``limits`` (None: unbounded): a 0-d structured array.

    Gains that are None (not used by the variant) are zero; ``lyapunov_offset`` is h [J].
    """
    p = np.zeros((), dtype=PARAMETERS)
    p["mass"] = body.mass
    p["inertia"] = body.inertia
    p["inertia_inv"] = body.inertia_inv
    p["pivot_inertia"] = body.pivot_inertia
    p["pivot_inertia_inv"] = body.pivot_inertia_inv
    p["attachment_point"] = body.attachment_point
    p["weight"] = body.weight
    for name in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d"):
        value = getattr(gains, name)
        if value is not None:
            p[name] = value
    if gains.l_d is not None:
        p["l_d_inv"] = gains.l_d_inv
    p["k_s"] = 0.0 if gains.k_s is None else gains.k_s
    p["boundary_layer"] = gains.boundary_layer
    p["lyapunov_offset"] = lyapunov_offset
    sat = gains.saturation
    if sat is not None:
        p["torque_limit"] = sat.torque_n
        p["torque_floor"] = -np.asarray(sat.torque_n) if sat.torque_n_lower is None else sat.torque_n_lower
        p["force_limit"] = sat.force_h
        p["constraint_force_limit"] = sat.constraint_force
        p["saturation"] = SATURATION_SHAPES[sat.shape]
    set_disturbances(p, gains.disturbances)
    set_limits(p, limits)
    return p


def set_limits(p: np.ndarray, limits) -> None:
    """Write the admissible region ``limits`` into the record(s) ``p`` (shape () or (n,)):
    ``limits`` (5, 3) with inf where unbounded, ``limited`` 1 when any bound is finite.
    ``limits``: a :class:`Limits`, None (unbounded), or the bounds as an array (5, 3) or one
    a record (n, 5, 3)."""
    if limits is None:
        bounds = np.full((len(LIMITED), 3), np.inf)
    else:
        bounds = limits.array if isinstance(limits, Limits) else np.asarray(limits, dtype=float)
    p["limits"] = bounds
    p["limited"] = np.isfinite(bounds).any(axis=(-2, -1))


def set_disturbances(p: np.ndarray, disturbances) -> None:
    """Write ``disturbances`` (a sequence of :class:`Disturbance`) into the record ``p``.

    Raises
    ------
    ValueError
        For more than :data:`MAX_DISTURBANCES` of them.
    """
    if len(disturbances) > MAX_DISTURBANCES:
        raise ValueError(f"disturbances: found {len(disturbances)} entries; at most {MAX_DISTURBANCES}")
    p["disturbance_count"] = len(disturbances)
    for i, d in enumerate(disturbances):
        p["disturbance_kind"][i] = DISTURBANCE_KINDS[d.kind]
        p["disturbance_torque"][i] = DISTURBANCE_QUANTITIES[d.quantity]
        p["disturbance_value"][i] = d.value
        p["disturbance_point"][i] = d.point
        p["disturbance_start"][i] = d.start
        p["disturbance_duration"][i] = d.duration
        p["disturbance_frequency"][i] = d.frequency
        p["disturbance_phase"][i] = d.phase
        p["disturbance_band"][i] = d.band
        p["disturbance_seed"][i] = d.seed


# -- the feedback, compiled (3-vectors are tuples, see rbstab.kinematics) ---------------------
@jit(forceinline=True)
def pressure_point(force, moment, gravity):
    """The centre of pressure [m] (inertial frame) of a wrench from the ground: its force F
    [N] and its moment M [N m] about the origin (inertial), on the ground plane through the
    origin perpendicular to ``gravity`` (its direction): the point P of that plane with
    M = P x F + tau n (F applied at P plus a free moment about the upward normal n),
    P = n x M / (n . F); NaN where n . F <= 0 (the ground would have to pull) or g is zero."""
    g = math.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2])
    if not g > 0.0:
        return math.nan, math.nan, math.nan
    n = (-gravity[0] / g, -gravity[1] / g, -gravity[2] / g)
    normal = n[0] * force[0] + n[1] * force[1] + n[2] * force[2]
    if not normal > 0.0:
        return math.nan, math.nan, math.nan
    p = cross(n, moment)
    return p[0] / normal, p[1] / normal, p[2] / normal


@jit(forceinline=True)
def gyroscopic(inertia, omega):
    """f(Omega) = -Omega x (J Omega) [N m], body frame (eq 1); ``inertia`` J (3, 3)."""
    return neg(cross(omega, matvec(inertia, omega)))


@jit(forceinline=True)
def _saturate(u, limit, shape):
    """One axis: ``u`` delivered through an actuator of limit ``limit`` (> 0, inf: none)."""
    if shape == 2.0 and limit < math.inf:
        return limit * math.tanh(u / limit)
    return min(max(u, -limit), limit)


@jit(forceinline=True)
def saturate(u, limit, shape):
    """The 3-vector ``u`` as actuators deliver it, axis by axis: clipped to [-limit_i,
    limit_i] (``shape`` 1) or limit_i tanh(u_i / limit_i) (``shape`` 2); ``limit`` (3,),
    inf where unlimited (:data:`SATURATION_SHAPES`)."""
    return (_saturate(u[0], limit[0], shape), _saturate(u[1], limit[1], shape), _saturate(u[2], limit[2], shape))


@jit(forceinline=True)
def _saturate_between(u, lower, upper, shape):
    """One axis through an actuator whose output lies in [``lower``, ``upper``] (lower < 0 <
    upper, infinite: none): ``shape`` 1 clips, 2 is ``upper`` tanh(u / upper) for u > 0 and
    -``lower`` tanh(u / lower) below (each side the symmetric shape of its own limit)."""
    if u >= 0.0:
        return _saturate(u, upper, shape)
    return -_saturate(-u, -lower, shape)


@jit(forceinline=True)
def saturate_between(u, lower, upper, shape):
    """The 3-vector ``u`` through actuators with the limits ``lower`` (3,) and ``upper``
    (3,) per axis (:func:`_saturate_between`); with lower = -upper, :func:`saturate`."""
    return (_saturate_between(u[0], lower[0], upper[0], shape), _saturate_between(u[1], lower[1], upper[1], shape),
            _saturate_between(u[2], lower[2], upper[2], shape))


@jit(forceinline=True)
def saturated_between(u, lower, upper):
    """1.0 on each axis where ``u`` is at or beyond its limit, u_i >= upper_i or u_i <=
    lower_i, else 0.0 (:func:`saturated` for limits of each sign)."""
    return (1.0 if u[0] >= upper[0] or u[0] <= lower[0] else 0.0, 1.0 if u[1] >= upper[1] or u[1] <= lower[1] else 0.0,
            1.0 if u[2] >= upper[2] or u[2] <= lower[2] else 0.0)


@jit(forceinline=True)
def _at_limit(u, limit):
    return 1.0 if abs(u) >= limit else 0.0


@jit(forceinline=True)
def saturated(u, limit):
    """1.0 on each axis i where the commanded 3-vector ``u`` is at or beyond its limit,
    |u_i| >= limit_i, else 0.0 (``limit`` (3,), inf where unlimited: never). There a
    ``clip`` actuator delivers its limit and a ``smooth`` one at least tanh(1) = 0.76 of it
    (:func:`saturate`); the summaries count these samples (docs/saturation.md)."""
    return (_at_limit(u[0], limit[0]), _at_limit(u[1], limit[1]), _at_limit(u[2], limit[2]))


@jit(forceinline=True)
def torque_n_command(b, theta, omega, p):
    """Rotational feedback N = -B' K_r Theta - L_r Omega [N m], body frame (eq 23), as
    commanded (before the actuators' limits).

    ``b``: B(theta); ``theta`` [rad], ``omega`` [rad/s]; ``p``: a :data:`PARAMETERS` record.
    """
    return sub(neg(matTvec(b, matvec(p.k_r, theta))), matvec(p.l_r, omega))


@jit(forceinline=True)
def force_h_command(x, v, p):
    """Translational feedback H = -K_t X - L_t V [N], inertial frame (eq 24), as commanded.

    ``x`` [m], ``v`` [m/s]; ``p``: a :data:`PARAMETERS` record.
    """
    return sub(neg(matvec(p.k_t, x)), matvec(p.l_t, v))


@jit(forceinline=True)
def torque_n(b, theta, omega, p):
    """N [N m], body frame, as the actuators deliver it: eq 23 through ``p``'s torque limits
    (:func:`saturate`; eq 23 itself without limits)."""
    n = torque_n_command(b, theta, omega, p)
    if p.saturation > 0.0:
        return saturate(n, p.torque_limit, p.saturation)
    return n


@jit(forceinline=True)
def force_h(x, v, p):
    """H [N], inertial frame, as the actuators deliver it: eq 24 through ``p``'s force
    limits (:func:`saturate`; eq 24 itself without limits)."""
    h = force_h_command(x, v, p)
    if p.saturation > 0.0:
        return saturate(h, p.force_limit, p.saturation)
    return h
