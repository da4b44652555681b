"""The description of a chain of rigid bodies: bodies, the joints that connect them, gravity.

A chain is a tree of 1-8 bodies (:data:`MAX_BODIES`). Every body has exactly one joint; the
joint's parent is the ground (index :data:`GROUND`) or an earlier body, so the bodies are in
topological order and the joints are numbered like their children (joint ``j`` holds body
``j``). Each joint holds a point C of its child (``child_point``, child body frame) to a point
of its parent (``parent_point``: inertial frame for the ground, else the parent's body frame)
by one of the paper's five laws (``variant``), and carries the rotational feedback of eq 23 on
the relative orientation, applied as an internal torque pair. A body may also carry the
ground-anchored feedback H of eq 24 (``k_t``, ``l_t``, zero: none). What the actuators can
deliver is a :class:`rbstab.model.Saturation` per joint (its ``torque_n``, the limits of N_j,
and ``constraint_force``, of the point force Lambda_j) and per body (its ``force_h``, the
limits of H); the disturbances act on the body that lists them.

This module is the compiled description's plain data, shared by the config layer (which builds
it, validated) and the physics (which trusts it); the per-run state lives elsewhere. A one-body
config is the one-body chain :func:`single` builds: its joint to the ground is today's
``controller`` law holding C to the ground point R (eq 4), its body's ``k_t``, ``l_t`` today's H.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .model import Disturbance, Saturation

__all__ = ["GROUND", "MAX_BODIES", "Body", "Passive", "Stop", "Region", "Joint", "Chain", "single", "hinge",
           "universal", "slide", "hinge_vectors"]

#: The parent index of a joint to the ground.
GROUND = -1
#: Most bodies of one chain.
MAX_BODIES = 8

_ZERO3 = np.zeros((3, 3))


@dataclass(frozen=True, eq=False)
class Body:
    """One body of a chain (Table 1) with its optional ground-anchored feedback (eq 24).

    Attributes
    ----------
    name : str
        The name used in configs, files, reports and errors.
    mass : float
        m [kg], > 0.
    inertia : ndarray, shape (3, 3)
        J [kg m^2] about the centre of mass, body frame, symmetric positive definite.
    k_t, l_t : ndarray, shape (3, 3)
        H = -K_t X - L_t V [N] on the centre of mass, inertial frame (eq 24); zero: none.
    saturation : Saturation or None
        The limits of H (its ``force_h``; its other limits are inf); None: unlimited.
    disturbances : tuple of Disturbance
        The disturbances acting on this body (``point`` in its body frame).
    """

    name: str
    mass: float
    inertia: np.ndarray
    k_t: np.ndarray = field(default_factory=lambda: _ZERO3.copy())
    l_t: np.ndarray = field(default_factory=lambda: _ZERO3.copy())
    saturation: Saturation | None = None
    disturbances: tuple[Disturbance, ...] = ()


@dataclass(frozen=True, eq=False)
class Passive:
    """A joint's passive visco-elastic torque (ligaments, cartilage, a joint capsule; MJCF's
    joint ``stiffness``, ``damping`` and ``springref``), never limited by an actuator:
    N_p = -B(Theta_j)' K_r (Theta_j - Theta_ref) - L_r Omega_j [N m], child frame.

    Attributes
    ----------
    k_r, l_r : ndarray, shape (3, 3)
        Its stiffness [N m/rad] and damping [N m s/rad], symmetric positive semi-definite.
    theta_ref : ndarray, shape (3,)
        Theta_ref [rad]: the relative Euler angles at which its spring is relaxed.
    """

    k_r: np.ndarray
    l_r: np.ndarray
    theta_ref: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True, eq=False)
class Stop:
    """A joint's range of motion as a stop (a knee's hyperextension, MJCF's joint ``range``):
    beyond either end of [``lower``, ``upper``] a one-sided spring and damper on each
    coordinate, never limited: a hinge's n_s = -k_r (q - end) - l_r dq/dt [N m] about its
    axis; a ball's on each Euler angle theta_i of Theta_j, N_s = B(Theta_j)' f with f_i =
    -k_r,i (theta_i - end_i) - l_r,i dtheta_i/dt. Its energy 1/2 k_r (q - end)^2 is v's and
    its dissipation l_r (dq/dt)^2 is in dv/dt there; zero inside.

    Attributes
    ----------
    lower, upper : float, or ndarray of shape (3,) for a ball
        The range's ends [rad], lower < upper (-inf, inf: none on that side).
    k_r : float, or ndarray of shape (3,) for a ball
        The stop's stiffness [N m/rad], > 0.
    l_r : float, or ndarray of shape (3,) for a ball
        Its damping [N m s/rad], >= 0.
    """

    lower: float | np.ndarray
    upper: float | np.ndarray
    k_r: float | np.ndarray
    l_r: float | np.ndarray = 0.0


@dataclass(frozen=True, eq=False)
class Region:
    """A joint's range of motion as an admissible region: a run whose hinge angle q, or one of
    whose ball's Euler angles Theta_j, leaves [``lower``, ``upper``] [rad] (lower < upper;
    -inf, inf: no end on that side; a ball's (3,) each) stops where it reaches an end, and
    fell (as one that leaves ``simulation.limits``); no torque acts inside it."""

    lower: float | np.ndarray
    upper: float | np.ndarray


@dataclass(frozen=True, eq=False)
class Joint:
    """One joint: the law holding the child's point C to a point of its parent, and the
    rotational feedback across it.

    Attributes
    ----------
    name : str
        The name used in configs, files, reports and errors.
    parent : int
        Index of the parent body, or :data:`GROUND`; always < ``child``.
    child : int
        Index of the child body.
    parent_point : ndarray, shape (3,)
        R_p [m]: inertial frame if the parent is the ground, else the parent's body frame
        from its centre of mass.
    child_point : ndarray, shape (3,)
        R_c [m]: the point C, child body frame, from its centre of mass.
    variant : str
        ``free``, ``permanent``, ``sliding``, ``visco_elastic`` or ``embedded``: the law of
        the point (the paper's variants, E_j = X_c + A_c R_c - X_p - A_p R_p); or ``hinge``:
        the point held and the child turned about ``axis`` only (:func:`hinge`); or
        ``universal``: the point held and the child turned about ``axis`` then ``axis_2``
        (:func:`universal`); ``slide``: the child's orientation held and its point moved
        along ``axis`` (:func:`slide`).
    k_r, l_r : ndarray, shape (3, 3)
        N_j = -B(Theta_j)' K_r (Theta_j - Theta_ref) - L_r Omega_j [N m] (eq 23 on the relative
        orientation Theta_j and the relative angular velocity Omega_j, child frame).
    k_c, l_c : ndarray, shape (3, 3), or None
        Point-law stiffness [N/m] and damping [N s/m] (eqs 22, 40).
    k_d, l_d : ndarray, shape (3, 3), or None
        Embedded-controller stiffness [N/m] and damping [N s/m] (eq 22).
    k_s : float or None
        Sliding-law force magnitude [N] (eq 39).
    boundary_layer : float
        Sliding boundary-layer width phi [m]; 0: the sign law.
    saturation : Saturation or None
        The limits of N_j (``torque_n`` [N m], child frame) and of Lambda_j
        (``constraint_force`` [N], inertial frame; inf for ``permanent``, whose Lambda_j is
        the pin's reaction); its ``force_h`` is inf. None: unlimited.
    theta_ref : ndarray, shape (3,)
        Theta_ref [rad]: the joint's reference posture, the relative Euler angles at which its
        spring is relaxed (N_j's stiffness term and v's term 1/2 (Theta_j - Theta_ref)' K_r
        (Theta_j - Theta_ref) are zero there); zero: the paper's eq 23.
    passive : Passive or None
        The joint's passive torque, added to the feedback N_j (which ``saturation`` limits)
        and never limited; None: none, the paper's joint.
    axis : ndarray, shape (3,)
        A hinge's or a slide's unit axis a (the parent's and the child's frames), a universal
        joint's first a_1 (the parent's frame); zero for any other joint.
    axis_2 : ndarray, shape (3,)
        A universal joint's second unit axis a_2 (the child's frame); zero for any other joint.
    stop : Stop or None
        A hinge's, a universal joint's or a ball's (``permanent``) range of motion as a stop;
        None: none.
    region : Region or None
        Such a joint's range of motion as an admissible region (not with ``stop``); None: none.
    """

    name: str
    parent: int
    child: int
    parent_point: np.ndarray
    child_point: np.ndarray
    variant: str
    k_r: np.ndarray
    l_r: np.ndarray
    k_c: np.ndarray | None = None
    l_c: np.ndarray | None = None
    k_d: np.ndarray | None = None
    l_d: np.ndarray | None = None
    k_s: float | None = None
    boundary_layer: float = 0.0
    saturation: Saturation | None = None
    theta_ref: np.ndarray = field(default_factory=lambda: np.zeros(3))
    passive: Passive | None = None
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    stop: Stop | None = None
    region: Region | None = None


def hinge_vectors(axis, k=0.0, l=0.0, q_ref=0.0, lower=-math.inf, upper=math.inf):
    """A hinge's feedback written as a ball's (docs/physics.md, "Joint kinds"): its child
    turned by the angle q [rad] about the unit axis a = ``axis`` / |axis| (the parent's and
    the child's frames), its feedback n = -k (q - ``q_ref``) - l dq/dt [N m] about a (``k``
    [N m/rad], ``l`` [N m s/rad]) delivered between ``lower`` < 0 < ``upper`` [N m] (inf:
    none). As the joint's 3-vectors in its child's frame, Theta_j = q a (the rotation
    vector), Omega_j = a dq/dt and N_j = n a, its gains are K_r = k a a', L_r = l a a',
    Theta_ref = q_ref a and its per-axis limits a_i [lower, upper] (ordered by a_i's sign,
    none where a_i = 0): eq 23 with B = I then gives n, its term 1/2 k (q - q_ref)^2 of v and
    its saturation, axis by axis. Each argument may have leading dimensions (a column of
    runs: axis (..., 3), the others (...)).

    Returns (a (..., 3), K_r (..., 3, 3), L_r (..., 3, 3), Theta_ref (..., 3), the lower
    and upper per-axis limits (..., 3)). ValueError for an axis of zero length."""
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if not np.all(norm > 0.0):
        raise ValueError("a hinge's axis of zero length")
    a = axis / norm
    k, l, q_ref, lower, upper = (np.asarray(x, dtype=float)[..., None] for x in (k, l, q_ref, lower, upper))
    outer = a[..., :, None] * a[..., None, :]
    with np.errstate(invalid="ignore"):  # 0 x inf: an axis a has no part of has no limit
        low = np.where(a > 0, a * lower, np.where(a < 0, a * upper, -math.inf))
        high = np.where(a > 0, a * upper, np.where(a < 0, a * lower, math.inf))
    return a, k[..., None] * outer, l[..., None] * outer, q_ref * a, low, high


def hinge(name: str, parent: int, child: int, parent_point, child_point, axis, k: float = 0.0, l: float = 0.0,
          q_ref: float = 0.0, limits: tuple[float, float] | None = None, shape: str = "clip",
          passive: tuple[float, float, float] | None = None, stop: Stop | None = None,
          region: Region | None = None) -> Joint:
    """A hinge joint (docs/physics.md, "Joint kinds"): the child's point C held to the
    parent's point, the child turned about ``axis`` with the feedback of gains ``k``, ``l``
    and reference angle ``q_ref`` delivered between ``limits`` (lower < 0 < upper [N m];
    None: unlimited, ``shape`` their :data:`rbstab.model.SATURATION_SHAPES` key) and a
    passive torque of that form, ``passive`` (k, l, q_ref), never limited, and its range as a
    ``stop`` or as an admissible ``region``; written as a ball's by :func:`hinge_vectors`.
    ValueError for an axis of zero length."""
    lower, upper = (-math.inf, math.inf) if limits is None else limits
    a, k_r, l_r, theta_ref, low, high = hinge_vectors(axis, k, l, q_ref, lower, upper)
    infinite = np.full(3, math.inf)
    saturation = None if limits is None else Saturation(high, infinite, infinite, shape, low)
    if passive is not None:
        _, p_k, p_l, p_ref, _, _ = hinge_vectors(axis, *passive)
        passive = Passive(p_k, p_l, p_ref)
    return Joint(name=name, parent=parent, child=child, parent_point=np.asarray(parent_point, dtype=float),
                 child_point=np.asarray(child_point, dtype=float), variant="hinge", k_r=k_r, l_r=l_r,
                 saturation=saturation, theta_ref=theta_ref, passive=passive, axis=a, stop=stop,
                 region=region)


def universal(name: str, parent: int, child: int, parent_point, child_point, axes, k=(0.0, 0.0), l=(0.0, 0.0),
              q_ref=(0.0, 0.0), limits: tuple | None = None, shape: str = "clip", passive: tuple | None = None,
              stop: Stop | None = None, region: Region | None = None) -> Joint:
    """A universal joint (docs/physics.md, "Joint kinds"): the child's point C held to the
    parent's point, the child turned by q_1 about the unit axis a_1 (the parent's frame),
    then by q_2 about a_2 (the child's frame), ``axes`` = (a_1, a_2) (each normalised, not
    parallel). Its feedback Q_k = -k_k (q_k - q_ref_k) - l_k dq_k/dt [N m] on each
    coordinate (``k`` [N m/rad], ``l`` [N m s/rad], ``q_ref`` [rad]: 2 numbers each) is
    delivered between ``limits`` ((lower_1, lower_2), (upper_1, upper_2)) [N m], lower < 0 <
    upper; None: unlimited), ``passive`` (k, l, q_ref) of that form never limited, its range
    a ``stop`` or an admissible ``region`` (2 numbers per end). The records hold the
    coordinates' entries 0 and 1 of 3-vectors: K_r = diag(k_1, k_2, 0), L_r, Theta_ref,
    the limits. ValueError for an axis of zero length or two parallel axes."""
    a = np.asarray(axes, dtype=float).reshape(2, 3)
    norm = np.linalg.norm(a, axis=-1, keepdims=True)
    if not np.all(norm > 0.0):
        raise ValueError("a universal joint's axis of zero length")
    a = a / norm
    if np.linalg.norm(np.cross(a[0], a[1])) < PARALLEL_AXES:
        raise ValueError("a universal joint's two axes are parallel")

    def entries(values, fill=0.0):
        return np.array([*np.broadcast_to(np.asarray(values, dtype=float), (2,)), fill])

    saturation = None
    if limits is not None:
        low, high = limits
        infinite = np.full(3, math.inf)
        saturation = Saturation(entries(high, math.inf), infinite, infinite, shape, entries(low, -math.inf))
    if passive is not None:
        passive = Passive(np.diag(entries(passive[0])), np.diag(entries(passive[1])), entries(passive[2]))
    return Joint(name=name, parent=parent, child=child, parent_point=np.asarray(parent_point, dtype=float),
                 child_point=np.asarray(child_point, dtype=float), variant="universal", k_r=np.diag(entries(k)),
                 l_r=np.diag(entries(l)), saturation=saturation, theta_ref=entries(q_ref), passive=passive, axis=a[0],
                 axis_2=a[1], stop=stop, region=region)


def slide(name: str, parent: int, child: int, parent_point, child_point, axis, k: float = 0.0, l: float = 0.0,
          q_ref: float = 0.0, limits: tuple[float, float] | None = None, shape: str = "clip",
          passive: tuple[float, float, float] | None = None, stop: Stop | None = None,
          region: Region | None = None) -> Joint:
    """A slide (prismatic) joint (docs/physics.md, "Joint kinds"): the child keeps its
    parent's orientation and its point C moves by q [m] along the unit axis a = ``axis`` /
    |axis| (the parent's frame, the child's too) from the parent's point. Its feedback f = -k
    (q - ``q_ref``) - l dq/dt [N] along a (``k`` [N/m], ``l`` [N s/m]) is delivered between
    ``limits`` (lower < 0 < upper [N]; None: unlimited), ``passive`` (k, l, q_ref) of that
    form never limited, its range [m] a ``stop`` (gains [N/m], [N s/m]) or an admissible
    ``region``. The records hold the coordinate's numbers as entry 0 of the 3-vectors (K_r =
    diag(k, 0, 0), Theta_ref = (q_ref, 0, 0), the limits). ValueError for an axis of zero
    length."""
    a = np.asarray(axis, dtype=float).reshape(3)
    norm = float(np.linalg.norm(a))
    if not norm > 0.0:
        raise ValueError("a slide's axis of zero length")

    def entries(value, fill=0.0):
        return np.array([float(value), fill, fill])

    saturation = None
    if limits is not None:
        infinite = np.full(3, math.inf)
        saturation = Saturation(entries(limits[1], math.inf), infinite, infinite, shape, entries(limits[0], -math.inf))
    if passive is not None:
        passive = Passive(np.diag(entries(passive[0])), np.diag(entries(passive[1])), entries(passive[2]))
    return Joint(name=name, parent=parent, child=child, parent_point=np.asarray(parent_point, dtype=float),
                 child_point=np.asarray(child_point, dtype=float), variant="slide", k_r=np.diag(entries(k)),
                 l_r=np.diag(entries(l)), saturation=saturation, theta_ref=entries(q_ref), passive=passive,
                 axis=a / norm, stop=stop, region=region)


#: |a_1 x a_2| below which a universal joint's axes are parallel (its coordinates degenerate).
PARALLEL_AXES = 1e-6


@dataclass(frozen=True, eq=False)
class Chain:
    """A tree of rigid bodies (module docstring for the conventions).

    Attributes
    ----------
    bodies : tuple of Body
        1-:data:`MAX_BODIES` bodies, in topological order.
    joints : tuple of Joint
        ``joints[j].child == j`` for every j.
    gravity : ndarray, shape (3,)
        g [m/s^2], inertial frame.
    """

    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    gravity: np.ndarray

    @property
    def sign_law(self) -> bool:
        """Whether a joint is ``sliding`` with the pure sign law (``boundary_layer`` 0): its
        runs go to the event-driven integrator (:mod:`rbstab.engine.switching`)."""
        return any(j.variant == "sliding" and not j.boundary_layer for j in self.joints)

    @property
    def size(self) -> int:
        """The number of bodies (= joints)."""
        return len(self.bodies)

    @property
    def parents(self) -> np.ndarray:
        """Each joint's parent index (:data:`GROUND` for the ground), shape (n,), int."""
        return np.array([j.parent for j in self.joints], dtype=np.int64)

    @property
    def body_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.bodies)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)


def single(body: Body, joint: Joint, gravity) -> Chain:
    """The one-body chain: ``body`` held to the ground by ``joint`` (parent :data:`GROUND`,
    child 0)."""
    return Chain(bodies=(body,), joints=(joint,), gravity=np.asarray(gravity, dtype=float))
