"""An independent plain-numpy model of a tree of rigid bodies in reduced coordinates
(docs/physics.md, "A tree in reduced coordinates").

What a physicist would write by hand from that section: a ``permanent`` joint (a ball) is
held by construction, its child carried by the joint's relative orientation Theta_j and
relative angular velocity Omega_j (child frame); a ``hinge`` likewise by its angle q about
its unit axis a (A_rel = exp(q [a]x) by Rodrigues' formula, Omega_j = a dq/dt); a ``slide`` by
its displacement q along its unit axis a (the parent's frame): the child turned as its parent,
its point C at the parent's point moved by q a, pushed along a by f = -k q - l dq/dt; a
``universal`` joint by q_1 about a_1 (the parent's frame) then q_2 about a_2 (the child's),
A_rel = exp(q_1 [a_1]x) exp(q_2 [a_2]x), Omega_j = S dq/dt with S = (exp(-q_2 [a_2]x) a_1, a_2),
its feedback f_k = -k_k q_k - l_k dq_k/dt on each coordinate delivered as the torque
N_j = S (S'S)^-1 f (the torque in the span of S whose generalised forces S'N_j are f); a
``ball`` (free of gimbal lock) by the unit quaternion of A_rel (scipy's Rotation reads it) and
Omega_j, its spring the potential 1/2 phi'K_r phi of the rotation vector phi of A_rel, its torque
minus the potential's gradient under a turn of the child (central differences) less L_r Omega_j,
clipped axis by axis; a body on any
other joint (here ``free`` or ``visco_elastic``) keeps its own Theta, Omega, X, V. A ball's
or a hinge's range may be a stop: beyond either end of each coordinate (a ball's Euler
angles, a hinge's q) a one-sided spring and damper on that coordinate and its rate, as a
torque whose power is the coordinate's generalised force times its rate (docs/physics.md,
"Joint kinds"). The equations of motion are the bodies'
Newton-Euler equations projected on the generalised velocities u (Jourdain's principle):

    M(q) du/dt = Q - b,   M = sum_i S_i' M_i S_i,   Q = sum_i S_i' w_i,
    b = sum_i S_i' (M_i kappa_i + (Omega_i x J_i Omega_i, 0))

with S_i = d(Omega_i, V_i)/du body i's velocity Jacobian, M_i = diag(J_i, m_i I), w_i the
applied wrench (torque about the centre of mass in the body frame, force in the inertial
frame) and kappa_i body i's acceleration at du/dt = 0. The mass matrix is assembled from the
Jacobians (not by the composite-rigid-body or articulated-body algorithms, so that this
model shares no method with an engine built on those); the constraint forces Lambda_j of
the permanent joints are recovered afterwards from the bodies' Newton equations, leaves
first.

It shares no code with rbstab's physics; the rotation, Euler-rate and skew matrices are
those of :mod:`reference` (the paper's eqs 1, 2, written there by hand).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from reference import euler_rate, hat, rotation

GROUND = -1
PERMANENT, FREE, VISCO_ELASTIC, HINGE, SLIDE, UNIVERSAL, BALL = ("permanent", "free", "visco_elastic", "hinge",
                                                                 "slide", "universal", "ball")
LAWS = (PERMANENT, FREE, VISCO_ELASTIC, HINGE, SLIDE, UNIVERSAL, BALL)
#: The joints on coordinates along axes, by law: their number of coordinates q (and rates).
COORDINATES = {HINGE: 1, SLIDE: 1, UNIVERSAL: 2}


def _zero():
    return np.zeros((3, 3))


@dataclass(frozen=True)
class Body:
    """m [kg], J [kg m^2] (3x3, about the centre of mass, body frame), and the ground-anchored
    feedback H = -K_t X - L_t V [N] (eq 24; zero: none)."""

    mass: float
    inertia: np.ndarray
    k_t: np.ndarray = field(default_factory=_zero)
    l_t: np.ndarray = field(default_factory=_zero)


@dataclass(frozen=True)
class Joint:
    """Joint j holds body j's point R_c (its body frame) to the point R_p of its parent
    (``parent`` < j, or GROUND: R_p in the inertial frame) by ``law``, with the rotational
    feedback N_j = -B(Theta_j)' K_r Theta_j - L_r Omega_j (eq 23 on the relative motion),
    clipped to +-``torque_limit`` [N m] axis by axis where given; K_c, L_c: the
    visco-elastic law Lambda_j = -K_c E_j - L_c F_j (eq 40). A ``hinge``: the unit ``axis``
    a, its feedback n = -k q - l dq/dt about a with k = ``k_r``[0, 0], l = ``l_r``[0, 0],
    clipped to +-``torque_limit``[0]; a ``slide``'s the force f = -k q - l dq/dt along a [N],
    clipped the same way. ``stop``: (lower, upper, k, l) of each coordinate (3 a ball's Euler
    angles, entry 0 a hinge's or a slide's q) or None."""

    parent: int
    parent_point: np.ndarray
    child_point: np.ndarray
    law: str = PERMANENT
    k_r: np.ndarray = field(default_factory=_zero)
    l_r: np.ndarray = field(default_factory=_zero)
    k_c: np.ndarray = field(default_factory=_zero)
    l_c: np.ndarray = field(default_factory=_zero)
    torque_limit: np.ndarray | None = None
    axis: np.ndarray | None = None
    stop: tuple | None = None
    axis_2: np.ndarray | None = None


@dataclass(frozen=True)
class Tree:
    """Bodies and joints (joint i holds body i; parents before children), gravity g [m/s^2]."""

    bodies: tuple
    joints: tuple
    gravity: np.ndarray

    @property
    def size(self):
        return len(self.bodies)

    def permanent(self, i):
        """Whether joint i places its child by construction (a ball, a hinge, a slide or a
        universal joint)."""
        return self.joints[i].law in (PERMANENT, BALL, *COORDINATES)

    def hinge(self, i):
        return self.joints[i].law == HINGE

    def slide(self, i):
        return self.joints[i].law == SLIDE

    def universal(self, i):
        return self.joints[i].law == UNIVERSAL

    def single(self, i):
        """Whether joint i has coordinates along axes (a hinge's angle, a slide's displacement,
        a universal joint's two angles)."""
        return self.joints[i].law in COORDINATES

    def m(self, i):
        """The number of joint i's coordinates along axes (0: none)."""
        return COORDINATES.get(self.joints[i].law, 0)

    def children(self, i):
        return [k for k, joint in enumerate(self.joints) if joint.parent == i]


# -- layout -----------------------------------------------------------------------------------
def state_blocks(tree):
    """Where each body's states start in y: 2 (q, dq/dt) for a hinge's child, 6 (Theta_j,
    Omega_j) for a ball's, 12 (Theta, Omega, X, V) for any other; and the state's size."""
    starts, at = [], 0
    for i in range(tree.size):
        starts.append(at)
        at += 2 * tree.m(i) if tree.single(i) else 7 if tree.joints[i].law == BALL else 6 if tree.permanent(i) else 12
    return starts, at


def velocity_blocks(tree):
    """Where each body's generalised velocities start in u: 1 (dq/dt), 3 (Omega_j) or 6
    (Omega, V)."""
    starts, at = [], 0
    for i in range(tree.size):
        starts.append(at)
        at += tree.m(i) if tree.single(i) else 3 if tree.permanent(i) else 6
    return starts, at


def generalised_velocities(tree, y):
    """u: dq/dt of each hinge's child, Omega_j of each ball's, (Omega, V) of every other body."""
    starts, _ = state_blocks(tree)
    parts = []
    for i, s in enumerate(starts):
        parts.append(y[s + tree.m(i): s + 2 * tree.m(i)] if tree.single(i) else y[s + 4: s + 7]
                     if tree.joints[i].law == BALL else y[s + 3: s + 6] if tree.permanent(i)
                     else np.concatenate([y[s + 3: s + 6], y[s + 9: s + 12]]))
    return np.concatenate(parts)


def axis_rotation(axis, q):
    """exp(q [a]x) = cos q I + sin q [a]x + (1 - cos q) a a' (Rodrigues)."""
    return math.cos(q) * np.eye(3) + math.sin(q) * hat(axis) + (1.0 - math.cos(q)) * np.outer(axis, axis)


def cross(a, b):
    """a x b of two 3-vectors (np.cross, without its generality: it dominates the run time)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def euler_angles(a):
    """Theta with rotation(Theta) = a (A = Rx Ry Rz: a[0,2] = s2, a[1,2] = -s1 c2,
    a[2,2] = c1 c2, a[0,1] = -c2 s3, a[0,0] = c2 c3)."""
    return np.array([math.atan2(-a[1, 2], a[2, 2]), math.asin(max(-1.0, min(1.0, a[0, 2]))),
                     math.atan2(-a[0, 1], a[0, 0])])


# -- kinematics: positions, velocities, accelerations, outward from the ground ------------------
@dataclass
class Configuration:
    """Of each body i: A_i, X_i [m]; of each joint j: Theta_j [rad], A_rel = A_p' A_c; of
    each slide j: its q [m]."""

    rot: list
    position: list
    theta_j: list
    rel: list
    slid: dict = field(default_factory=dict)


def parent_frame(tree, conf, j):
    """(A_p, X_p) of joint j's parent (ground: I, 0)."""
    p = tree.joints[j].parent
    return (np.eye(3), np.zeros(3)) if p == GROUND else (conf.rot[p], conf.position[p])


def configuration(tree, y):
    """Every body's A_i, X_i and every joint's Theta_j, A_rel from the state y, parents first:
    permanent A_c = A_p A(Theta_j), X_c = X_p + A_p R_p - A_c R_c; else A(Theta_c), X_c."""
    starts, _ = state_blocks(tree)
    conf = Configuration([], [], [], [])
    for c, joint in enumerate(tree.joints):
        s = starts[c]
        a_p, x_p = parent_frame(tree, conf, c)
        if tree.slide(c):  # turned as its parent, its point at R_p + q a (the parent's frame)
            conf.slid[c] = y[s]
            theta_j, a_rel, a_c = np.zeros(3), np.eye(3), a_p
            x_c = x_p + a_p @ (joint.parent_point + y[s] * joint.axis) - a_c @ joint.child_point
        elif joint.law == BALL:  # Theta_j: the rotation vector of A_rel, its quaternion's (w, x, y, z)
            turn = Rotation.from_quat([y[s + 1], y[s + 2], y[s + 3], y[s]])
            theta_j, a_rel = turn.as_rotvec(), turn.as_matrix()
            a_c = a_p @ a_rel
            x_c = x_p + a_p @ joint.parent_point - a_c @ joint.child_point
        elif tree.universal(c):  # Theta_j: (q_1, q_2, 0)
            theta_j = np.array([y[s], y[s + 1], 0.0])
            a_rel = axis_rotation(joint.axis, y[s]) @ axis_rotation(joint.axis_2, y[s + 1])
            a_c = a_p @ a_rel
            x_c = x_p + a_p @ joint.parent_point - a_c @ joint.child_point
        elif tree.hinge(c):  # Theta_j: the rotation vector q a
            theta_j = y[s] * joint.axis
            a_rel = axis_rotation(joint.axis, y[s])
            a_c = a_p @ a_rel
            x_c = x_p + a_p @ joint.parent_point - a_c @ joint.child_point
        elif tree.permanent(c):
            theta_j = y[s: s + 3]
            a_rel = rotation(theta_j)
            a_c = a_p @ a_rel
            x_c = x_p + a_p @ joint.parent_point - a_c @ joint.child_point
        else:
            a_c = rotation(y[s: s + 3])
            x_c = y[s + 6: s + 9]
            a_rel = a_p.T @ a_c
            theta_j = y[s: s + 3] if joint.parent == GROUND else euler_angles(a_rel)
        conf.rot.append(a_c)
        conf.position.append(x_c)
        conf.theta_j.append(np.asarray(theta_j, dtype=float))
        conf.rel.append(a_rel)
    return conf


def motion(tree, conf, u, du):
    """(Omega_i, V_i, dOmega_i/dt, dV_i/dt) of every body [(n, 3) each] and Omega_j of every
    joint from the generalised velocities u and their rates du, parents first. A permanent
    joint's child (ground: Omega_p = V_p = 0, A_p = I):

        Omega_c = A_rel' Omega_p + Omega_j
        V_c = V_p + A_p (Omega_p x R_p) - A_c (Omega_c x R_c)
        dOmega_c/dt = A_rel' dOmega_p/dt + dOmega_j/dt + Omega_c x Omega_j
        dV_c/dt = dV_p/dt + A_p (dOmega_p/dt x R_p + Omega_p x (Omega_p x R_p))
                  - A_c (dOmega_c/dt x R_c + Omega_c x (Omega_c x R_c))

    Velocities are linear in u; with du = 0 the accelerations are the bias kappa_i."""
    n = tree.size
    starts, _ = velocity_blocks(tree)
    omega, v, omega_dot, v_dot, omega_j = (np.zeros((n, 3)) for _ in range(5))
    for c, joint in enumerate(tree.joints):
        s, p = starts[c], joint.parent
        if p == GROUND:
            a_p, w_p, v_p, dw_p, dv_p = np.eye(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
        else:
            a_p, w_p, v_p, dw_p, dv_p = conf.rot[p], omega[p], v[p], omega_dot[p], v_dot[p]
        a_c, a_rel, r_p, r_c = conf.rot[c], conf.rel[c], joint.parent_point, joint.child_point
        if tree.slide(c):  # Omega_j = 0; C moves along a at dq/dt from the parent's point moved by q a
            r, along, along_dot = r_p + conf.slid[c] * joint.axis, joint.axis * u[s], joint.axis * du[s]
            omega[c], omega_dot[c] = w_p, dw_p
            v[c] = v_p + a_p @ (cross(w_p, r) + along) - a_c @ cross(omega[c], r_c)
            v_dot[c] = (dv_p + a_p @ (cross(dw_p, r) + cross(w_p, cross(w_p, r)) + 2.0 * cross(w_p, along) + along_dot)
                        - a_c @ (cross(omega_dot[c], r_c) + cross(omega[c], cross(omega[c], r_c))))
        elif tree.permanent(c):
            if tree.universal(c):  # S dq/dt; d(exp(-q_2 [a_2]x) a_1)/dt = (s_1 x a_2) dq_2/dt
                columns = motion_subspace(joint, conf.theta_j[c][1])
                omega_j[c] = columns @ u[s: s + 2]
                omega_j_dot = columns @ du[s: s + 2] + u[s] * u[s + 1] * cross(columns[:, 0], joint.axis_2)
            elif tree.hinge(c):  # Omega_j = a dq/dt, a fixed in the child's frame
                omega_j[c], omega_j_dot = joint.axis * u[s], joint.axis * du[s]
            else:
                omega_j[c], omega_j_dot = u[s: s + 3], du[s: s + 3]
            omega[c] = a_rel.T @ w_p + omega_j[c]
            v[c] = v_p + a_p @ cross(w_p, r_p) - a_c @ cross(omega[c], r_c)
            omega_dot[c] = a_rel.T @ dw_p + omega_j_dot + cross(omega[c], omega_j[c])
            v_dot[c] = (dv_p + a_p @ (cross(dw_p, r_p) + cross(w_p, cross(w_p, r_p)))
                        - a_c @ (cross(omega_dot[c], r_c) + cross(omega[c], cross(omega[c], r_c))))
        else:
            omega[c], v[c] = u[s: s + 3], u[s + 3: s + 6]
            omega_dot[c], v_dot[c] = du[s: s + 3], du[s + 3: s + 6]
            omega_j[c] = omega[c] - a_rel.T @ w_p
    return omega, v, omega_dot, v_dot, omega_j


def motion_subspace(joint, q_2):
    """A universal joint's S (3, 2) at q_2 [rad]: its columns exp(-q_2 [a_2]x) a_1 and a_2
    (child frame)."""
    return np.column_stack([axis_rotation(joint.axis_2, -q_2) @ joint.axis, joint.axis_2])


def jacobians(tree, conf):
    """S_i = d(Omega_i, V_i)/du, shape (n, 6, n_u): the velocities of unit generalised
    velocities (they are linear in u)."""
    _, n_u = velocity_blocks(tree)
    s = np.zeros((tree.size, 6, n_u))
    for k in range(n_u):
        unit = np.zeros(n_u)
        unit[k] = 1.0
        omega, v, _, _, _ = motion(tree, conf, unit, np.zeros(n_u))
        s[:, :3, k], s[:, 3:, k] = omega, v
    return s


def spatial_inertia(body):
    """M_i = diag(J_i, m_i I), the kinetic energy's matrix of (Omega_i, V_i)."""
    m = np.zeros((6, 6))
    m[:3, :3], m[3:, 3:] = body.inertia, body.mass * np.eye(3)
    return m


def mass_matrix(tree, conf):
    """M(q) = sum_i S_i' M_i S_i: T = u' M u / 2."""
    s = jacobians(tree, conf)
    return sum(s[i].T @ spatial_inertia(b) @ s[i] for i, b in enumerate(tree.bodies))


# -- forces ---------------------------------------------------------------------------------------
def point_motion(tree, conf, omega, v, j):
    """(E_j, F_j) of joint j: E_j = X_c + A_c R_c - X_p - A_p R_p,
    F_j = V_c + A_c (Omega_c x R_c) - V_p - A_p (Omega_p x R_p)."""
    joint, c, p = tree.joints[j], j, tree.joints[j].parent
    e = conf.position[c] + conf.rot[c] @ joint.child_point
    f = v[c] + conf.rot[c] @ cross(omega[c], joint.child_point)
    if p == GROUND:
        return e - joint.parent_point, f
    return (e - conf.position[p] - conf.rot[p] @ joint.parent_point,
            f - v[p] - conf.rot[p] @ cross(omega[p], joint.parent_point))


def ball_potential(joint, turn):
    """1/2 phi'K_r phi [J] of a ball turned by the rotation matrix ``turn`` (A_rel), phi its
    rotation vector."""
    phi = Rotation.from_matrix(turn).as_rotvec()
    return 0.5 * phi @ joint.k_r @ phi


def ball_torque(joint, theta_j, omega_j):
    """(N_j delivered, N_j commanded) [N m] of a ball at the rotation vector ``theta_j`` of
    A_rel: minus the gradient of :func:`ball_potential` under a turn exp([e]x) of the child
    (its frame: A_rel exp([e]x)), by central differences, less L_r Omega_j; clipped axis by
    axis."""
    turn, step = Rotation.from_rotvec(theta_j).as_matrix(), 1e-5
    gradient = np.array([(ball_potential(joint, turn @ Rotation.from_rotvec(step * e).as_matrix())
                          - ball_potential(joint, turn @ Rotation.from_rotvec(-step * e).as_matrix())) / (2 * step)
                         for e in np.eye(3)])
    command = -gradient - joint.l_r @ omega_j
    delivered = command if joint.torque_limit is None else np.clip(command, -joint.torque_limit, joint.torque_limit)
    return delivered, command


def joint_torque(joint, theta_j, omega_j):
    """(N_j delivered, N_j commanded) [N m], child frame: N = -B(Theta_j)' K_r Theta_j - L_r Omega_j
    (eq 23 on the relative motion), clipped to the joint's limits; a hinge's n a, n = -k q - l
    dq/dt clipped to +-its limit; plus its stop (never limited)."""
    if joint.law == BALL:
        return ball_torque(joint, theta_j, omega_j)
    if joint.law == UNIVERSAL:  # f on (q_1, q_2) clipped per coordinate, as the torque S (S'S)^-1 f
        columns = motion_subspace(joint, theta_j[1])
        q, rate = theta_j[:2], np.linalg.lstsq(columns, omega_j, rcond=None)[0]
        f = -np.diag(joint.k_r)[:2] * q - np.diag(joint.l_r)[:2] * rate
        delivered = f if joint.torque_limit is None else np.clip(f, -joint.torque_limit[:2], joint.torque_limit[:2])
        stop = stop_terms(joint, q, rate)[0]
        to_torque = columns @ np.linalg.inv(columns.T @ columns)
        return to_torque @ (delivered + stop), to_torque @ (f + stop)
    if joint.law == HINGE:
        q, rate = theta_j @ joint.axis, omega_j @ joint.axis
        n = -joint.k_r[0, 0] * q - joint.l_r[0, 0] * rate
        delivered = n if joint.torque_limit is None else min(max(n, -joint.torque_limit[0]), joint.torque_limit[0])
        stop = stop_terms(joint, np.array([q]), np.array([rate]))[0][0] * joint.axis
        return delivered * joint.axis + stop, n * joint.axis + stop
    command = -euler_rate(theta_j).T @ joint.k_r @ theta_j - joint.l_r @ omega_j
    delivered = command if joint.torque_limit is None else np.clip(command, -joint.torque_limit, joint.torque_limit)
    if joint.stop is None:
        return delivered, command
    b = euler_rate(theta_j)
    stop = b.T @ stop_terms(joint, theta_j, b @ omega_j)[0]
    return delivered + stop, command + stop


def slide_force(joint, q, rate):
    """(f delivered, f commanded) [N] of a slide at its q [m] and dq/dt [m/s]: -k q - l dq/dt
    clipped to +-its limit, plus its stop (never limited)."""
    f = -joint.k_r[0, 0] * q - joint.l_r[0, 0] * rate
    delivered = f if joint.torque_limit is None else min(max(f, -joint.torque_limit[0]), joint.torque_limit[0])
    stop = stop_terms(joint, np.array([q]), np.array([rate]))[0][0]
    return delivered + stop, f + stop


def stop_terms(joint, coordinates, rates):
    """(f (k,) [N m] the stop's generalised force on each coordinate, its energy [J], its
    dissipation [W]) of the joint's ``stop`` at its ``coordinates`` and their ``rates``
    (k,): beyond an end, delta = coordinate - end, f = -k delta - l rate, the energy 1/2 k
    delta^2 and the dissipation l rate^2; zero inside (and without a stop)."""
    f = np.zeros(len(coordinates))
    if joint.stop is None:
        return f, 0.0, 0.0
    lower, upper, k, l = (np.asarray(x, dtype=float)[: len(coordinates)] for x in joint.stop)
    delta = np.maximum(coordinates - upper, 0.0) + np.minimum(coordinates - lower, 0.0)
    beyond = delta != 0.0
    f = np.where(beyond, -k * delta - l * rates, 0.0)
    return f, float(np.sum(0.5 * k * delta ** 2)), float(np.sum(np.where(beyond, l * rates ** 2, 0.0)))


@dataclass
class Forces:
    """The applied wrenches (everything but the permanent joints' Lambda_j): per body the
    torque about the centre of mass (body frame) and the force (inertial frame); per joint
    N_j (delivered and commanded), and Lambda_j, E_j, F_j of the point laws."""

    torque: np.ndarray
    force: np.ndarray
    n_j: np.ndarray
    n_command: np.ndarray
    h: np.ndarray
    lam: np.ndarray
    e: np.ndarray
    f: np.ndarray


def applied_forces(tree, conf, omega, v, omega_j):
    """Gravity G_i = m_i g and H_i on each centre of mass; N_j on the child and -A_rel N_j on
    the parent; a point law's Lambda_j on the child at R_c and -Lambda_j on the parent at R_p."""
    n = tree.size
    out = Forces(*(np.zeros((n, 3)) for _ in range(8)))
    for i, body in enumerate(tree.bodies):
        out.h[i] = -body.k_t @ conf.position[i] - body.l_t @ v[i]  # eq 24
        out.force[i] += body.mass * tree.gravity + out.h[i]
    for j, joint in enumerate(tree.joints):
        c, p = j, joint.parent
        if joint.law == SLIDE:  # f a at C on the child, -f a on the parent at the same point; no torque
            out.e[j], out.f[j] = point_motion(tree, conf, omega, v, j)
            a_p = np.eye(3) if p == GROUND else conf.rot[p]
            delivered, _ = slide_force(joint, conf.slid[j], (a_p @ joint.axis) @ out.f[j])
            out.lam[j] = delivered * (a_p @ joint.axis)
            out.torque[c] += cross(joint.child_point, conf.rot[c].T @ out.lam[j])
            out.force[c] += out.lam[j]
            if p != GROUND:
                moved = joint.parent_point + conf.slid[j] * joint.axis
                out.torque[p] -= cross(moved, conf.rot[p].T @ out.lam[j])
                out.force[p] -= out.lam[j]
            continue
        out.n_j[j], out.n_command[j] = joint_torque(joint, conf.theta_j[j], omega_j[j])
        out.torque[c] += out.n_j[j]
        if p != GROUND:
            out.torque[p] -= conf.rel[j] @ out.n_j[j]
        out.e[j], out.f[j] = point_motion(tree, conf, omega, v, j)
        if joint.law == PERMANENT:
            continue
        if joint.law == VISCO_ELASTIC:
            out.lam[j] = -joint.k_c @ out.e[j] - joint.l_c @ out.f[j]  # eq 40
        out.torque[c] += cross(joint.child_point, conf.rot[c].T @ out.lam[j])
        out.force[c] += out.lam[j]
        if p != GROUND:
            out.torque[p] -= cross(joint.parent_point, conf.rot[p].T @ out.lam[j])
            out.force[p] -= out.lam[j]
    return out


# -- equations of motion ---------------------------------------------------------------------------
@dataclass
class Evaluation:
    """Everything one evaluation computes: dy/dt, the generalised quantities, each body's
    velocities and accelerations, the applied forces and the permanent joints' Lambda_j."""

    dy: np.ndarray
    u: np.ndarray
    du: np.ndarray
    mass: np.ndarray
    conf: Configuration
    omega: np.ndarray
    v: np.ndarray
    omega_dot: np.ndarray
    v_dot: np.ndarray
    omega_j: np.ndarray
    forces: Forces
    lam: np.ndarray


def evaluate(tree, y):
    """The rate of the reduced state y and the quantities it is made of (module docstring):
    M du/dt = Q - b, then dTheta_j/dt = B(Theta_j) Omega_j for a permanent joint's child,
    dTheta/dt = B(Theta) Omega, dX/dt = V for every other body."""
    conf = configuration(tree, y)
    u = generalised_velocities(tree, y)
    n_u = u.size
    omega, v, kappa_w, kappa_v, omega_j = motion(tree, conf, u, np.zeros(n_u))
    forces = applied_forces(tree, conf, omega, v, omega_j)
    s = jacobians(tree, conf)
    mass = np.zeros((n_u, n_u))
    q = np.zeros(n_u)
    b = np.zeros(n_u)
    for i, body in enumerate(tree.bodies):
        m_i = spatial_inertia(body)
        mass += s[i].T @ m_i @ s[i]
        q += s[i].T @ np.concatenate([forces.torque[i], forces.force[i]])
        gyroscopic = cross(omega[i], body.inertia @ omega[i])
        b += s[i].T @ (m_i @ np.concatenate([kappa_w[i], kappa_v[i]]) + np.concatenate([gyroscopic, np.zeros(3)]))
    du = np.linalg.solve(mass, q - b)
    _, _, omega_dot, v_dot, _ = motion(tree, conf, u, du)
    lam = constraint_forces(tree, v_dot, forces)
    starts, size = state_blocks(tree)
    ustarts, _ = velocity_blocks(tree)
    dy = np.zeros(size)
    for i, s0 in enumerate(starts):
        k = ustarts[i]
        if tree.single(i):
            m = tree.m(i)
            dy[s0: s0 + m], dy[s0 + m: s0 + 2 * m] = u[k: k + m], du[k: k + m]
        elif tree.joints[i].law == BALL:  # dq/dt = 1/2 q (0, Omega_j), the quaternion product
            w, x = y[s0], y[s0 + 1: s0 + 4]
            dy[s0] = -0.5 * x @ omega_j[i]
            dy[s0 + 1: s0 + 4] = 0.5 * (w * omega_j[i] + cross(x, omega_j[i]))
            dy[s0 + 4: s0 + 7] = du[k: k + 3]
        elif tree.permanent(i):
            dy[s0: s0 + 3] = euler_rate(conf.theta_j[i]) @ omega_j[i]
            dy[s0 + 3: s0 + 6] = du[k: k + 3]
        else:
            dy[s0: s0 + 3] = euler_rate(y[s0: s0 + 3]) @ omega[i]
            dy[s0 + 3: s0 + 6] = du[k: k + 3]
            dy[s0 + 6: s0 + 9] = v[i]
            dy[s0 + 9: s0 + 12] = du[k + 3: k + 6]
    return Evaluation(dy, u, du, mass, conf, omega, v, omega_dot, v_dot, omega_j, forces, lam)


def rate(tree, y, t=0.0):
    """dy/dt (for solve_ivp)."""
    return evaluate(tree, y).dy


def constraint_forces(tree, v_dot, forces):
    """Lambda_j [N] (inertial frame, on the child at R_c) of each permanent joint, from the
    Newton equation of its child, leaves first (eqs 15, 20 for one body):

        Lambda_c = m_c dV_c/dt - (G_c + H_c + the point laws' forces on c) + sum_k Lambda_k

    the sum over the permanent joints k whose parent is c (each pulls on c with -Lambda_k).
    The point laws' Lambda_j are ``forces.lam``; the permanent ones are filled in here."""
    lam = forces.lam.copy()
    for c in reversed(range(tree.size)):
        if not tree.permanent(c):
            continue
        # a slide's own force along its axis is in ``forces.force`` (on the child, and its opposite on the
        # parent) and in its Lambda: the whole force its parent applies at C
        pulled = sum((lam[k] - (forces.lam[k] if tree.slide(k) else 0.0) for k in tree.children(c)
                      if tree.permanent(k)), np.zeros(3))
        lam[c] = (tree.bodies[c].mass * v_dot[c] - forces.force[c] + pulled
                  + (forces.lam[c] if tree.slide(c) else 0.0))
    return lam


def coordinates(tree, ev, j):
    """(joint j's coordinates, their rates) at the evaluation ``ev``: a hinge's or a slide's q
    and dq/dt (1,), a universal joint's (2,), an Euler ball's or a free body's relative Euler
    angles Theta_j and dTheta_j/dt (3,), a quaternion ball's rotation vector and Omega_j."""
    joint, theta_j, omega_j = tree.joints[j], ev.conf.theta_j[j], ev.omega_j[j]
    if joint.law == HINGE:
        return np.array([theta_j @ joint.axis]), np.array([omega_j @ joint.axis])
    if joint.law in (SLIDE, UNIVERSAL):
        at, m = velocity_blocks(tree)[0][j], tree.m(j)
        return (np.array([ev.conf.slid[j]]) if joint.law == SLIDE else theta_j[:2]), ev.u[at: at + m]
    if joint.law == BALL:  # its rotation vector and Omega_j
        return theta_j, omega_j
    return theta_j, euler_rate(theta_j) @ omega_j


# -- v and dv/dt -----------------------------------------------------------------------------------
def lyapunov(tree, y):
    """(the terms of v without the constant h, eq 25's grouping summed over the bodies and
    joints: translational, rotational, constraint, gravity [J]; dv/dt analytic [W]):

        v = sum_i (m_i V_i'V_i / 2 + X_i'K_t X_i / 2) + sum_i Omega_i'J_i Omega_i / 2
            + sum_j Theta_j'K_r Theta_j / 2 + sum_visco E_j'K_c E_j / 2 - sum_i X_i'G_i
        dv/dt = -sum_j Omega_j'L_r Omega_j - sum_i V_i'L_t V_i - sum_visco F_j'L_c F_j
                + sum_j Omega_j'(N_j - N_j,commanded)

    No term of the permanent joints' Lambda_j: in these coordinates F_j is 0 identically."""
    ev = evaluate(tree, y)
    conf, forces = ev.conf, ev.forces
    translational = sum(0.5 * b.mass * ev.v[i] @ ev.v[i] + 0.5 * conf.position[i] @ b.k_t @ conf.position[i]
                        for i, b in enumerate(tree.bodies))
    rotational = sum(0.5 * ev.omega[i] @ b.inertia @ ev.omega[i] for i, b in enumerate(tree.bodies))
    constraint = 0.0
    dv_dt = 0.0
    for j, jt in enumerate(tree.joints):
        if jt.law == SLIDE:  # 1/2 k q^2 (with the point laws' energy), l (dq/dt)^2 along its axis
            (q,), (rate,) = coordinates(tree, ev, j)
            delivered, commanded = slide_force(jt, q, rate)
            _, energy, dissipation = stop_terms(jt, np.array([q]), np.array([rate]))
            constraint += 0.5 * jt.k_r[0, 0] * q * q + energy
            dv_dt += -jt.l_r[0, 0] * rate * rate - dissipation + rate * (delivered - commanded)
            continue
        if jt.law == BALL:  # 1/2 phi'K_r phi, Omega_j'L_r Omega_j
            rotational += ball_potential(jt, conf.rel[j])
            dv_dt += -ev.omega_j[j] @ jt.l_r @ ev.omega_j[j] + ev.omega_j[j] @ (forces.n_j[j] - forces.n_command[j])
            continue
        if jt.law == UNIVERSAL:  # sum 1/2 k_k q_k^2, l_k (dq_k/dt)^2; the torque's power dq/dt'(f - f_command)
            q, rate = coordinates(tree, ev, j)
            _, energy, dissipation = stop_terms(jt, q, rate)
            rotational += 0.5 * np.sum(np.diag(jt.k_r)[:2] * q * q) + energy
            dv_dt += (-np.sum(np.diag(jt.l_r)[:2] * rate * rate) - dissipation
                      + ev.omega_j[j] @ (forces.n_j[j] - forces.n_command[j]))
            continue
        if jt.law == HINGE:  # 1/2 k q^2, l (dq/dt)^2 about its axis
            q, rate = conf.theta_j[j] @ jt.axis, ev.omega_j[j] @ jt.axis
            _, energy, dissipation = stop_terms(jt, np.array([q]), np.array([rate]))
            rotational += 0.5 * jt.k_r[0, 0] * q * q + energy
            dv_dt += -jt.l_r[0, 0] * rate * rate - dissipation + ev.omega_j[j] @ (forces.n_j[j] - forces.n_command[j])
            continue
        b = euler_rate(conf.theta_j[j])
        _, energy, dissipation = stop_terms(jt, conf.theta_j[j], b @ ev.omega_j[j])
        rotational += 0.5 * conf.theta_j[j] @ jt.k_r @ conf.theta_j[j] + energy
        dv_dt += -ev.omega_j[j] @ jt.l_r @ ev.omega_j[j] + ev.omega_j[j] @ (forces.n_j[j] - forces.n_command[j])
        dv_dt -= dissipation
        if jt.law == VISCO_ELASTIC:
            constraint += 0.5 * forces.e[j] @ jt.k_c @ forces.e[j]
            dv_dt -= forces.f[j] @ jt.l_c @ forces.f[j]
    gravity = -sum(b.mass * tree.gravity @ conf.position[i] for i, b in enumerate(tree.bodies))
    dv_dt -= sum(ev.v[i] @ b.l_t @ ev.v[i] for i, b in enumerate(tree.bodies))
    return (translational, rotational, constraint, gravity), dv_dt


# -- a push -----------------------------------------------------------------------------------------
def push(tree, y, body, point, impulse):
    """(the state just after a force impulse P [N s] (inertial frame) at ``point`` [m] of body
    ``body`` (its frame, from its centre of mass); the permanent joints' impulsive reactions
    (n, 3) [N s]): M du = J_P' P, J_P = dV_P/du the Jacobian of the point's velocity
    V_P = V_b - A_b hat(point) Omega_b; the configuration does not move."""
    conf = configuration(tree, y)
    s = jacobians(tree, conf)
    j_point = s[body, 3:] - conf.rot[body] @ hat(point) @ s[body, :3]
    du = np.linalg.solve(mass_matrix(tree, conf), j_point.T @ impulse)
    _, dv, _, _, _ = motion(tree, conf, du, np.zeros_like(du))  # the velocities are linear in u
    external = Forces(*(np.zeros((tree.size, 3)) for _ in range(8)))
    external.force[body] = impulse
    reactions = constraint_forces(tree, dv, external)
    after = np.array(y, dtype=float)
    starts, _ = state_blocks(tree)
    ustarts, _ = velocity_blocks(tree)
    for i, s0 in enumerate(starts):
        k = ustarts[i]
        if tree.single(i):
            m = tree.m(i)
            after[s0 + m: s0 + 2 * m] += du[k: k + m]
            continue
        if tree.joints[i].law == BALL:
            after[s0 + 4: s0 + 7] += du[k: k + 3]
            continue
        after[s0 + 3: s0 + 6] += du[k: k + 3]
        if not tree.permanent(i):
            after[s0 + 9: s0 + 12] += du[k + 3: k + 6]
    return after, reactions


# -- maximal coordinates (rbstab's chain state) --------------------------------------------------------
def maximal_state(tree, y):
    """The chain's maximal state (12 n,): (Theta_i, Omega_i, X_i, V_i) of every body, Theta_i
    the Euler angles of A_i."""
    conf = configuration(tree, y)
    u = generalised_velocities(tree, y)
    omega, v, _, _, _ = motion(tree, conf, u, np.zeros(u.size))
    starts, _ = state_blocks(tree)
    out = np.zeros(12 * tree.size)
    for i in range(tree.size):
        theta = y[starts[i]: starts[i] + 3] if not tree.permanent(i) else euler_angles(conf.rot[i])
        out[12 * i: 12 * i + 12] = np.concatenate([theta, omega[i], conf.position[i], v[i]])
    return out


def reduced_state(tree, y12):
    """The reduced state of a maximal one (inverse of :func:`maximal_state` on the
    constraints): a permanent joint's Theta_j = the Euler angles of A_p' A_c,
    Omega_j = Omega_c - A_rel' Omega_p."""
    starts, size = state_blocks(tree)
    out = np.zeros(size)
    rot = [rotation(y12[12 * i: 12 * i + 3]) for i in range(tree.size)]
    for c, joint in enumerate(tree.joints):
        s, p = starts[c], joint.parent
        if not tree.permanent(c):
            out[s: s + 12] = y12[12 * c: 12 * c + 12]
            continue
        a_p, w_p = (np.eye(3), np.zeros(3)) if p == GROUND else (rot[p], y12[12 * p + 3: 12 * p + 6])
        a_rel = a_p.T @ rot[c]
        omega_j = y12[12 * c + 3: 12 * c + 6] - a_rel.T @ w_p
        if tree.slide(c):  # q, dq/dt along the axis of its point's offset from its parent's, and their rates
            x_p, v_p = (np.zeros(3), np.zeros(3)) if p == GROUND else (y12[12 * p + 6: 12 * p + 9],
                                                                        y12[12 * p + 9: 12 * p + 12])
            axis = a_p @ joint.axis
            e = y12[12 * c + 6: 12 * c + 9] + rot[c] @ joint.child_point - x_p - a_p @ joint.parent_point
            f = (y12[12 * c + 9: 12 * c + 12] + rot[c] @ cross(y12[12 * c + 3: 12 * c + 6], joint.child_point)
                 - v_p - a_p @ cross(w_p, joint.parent_point))
            out[s], out[s + 1] = axis @ e, axis @ f
            continue
        if joint.law == BALL:  # its quaternion (w >= 0) and Omega_j
            x, y_, z, w = Rotation.from_matrix(a_rel).as_quat()
            out[s: s + 4] = np.array([w, x, y_, z]) * (1.0 if w >= 0.0 else -1.0)
            out[s + 4: s + 7] = omega_j
            continue
        if tree.universal(c):  # A_rel a_2 = exp(q_1 [a_1]x) a_2, A_rel' a_1 = exp(-q_2 [a_2]x) a_1
            a_1, a_2 = joint.axis, joint.axis_2
            z, w = a_rel @ a_2, a_rel.T @ a_1
            q_1 = math.atan2(cross(a_1, a_2) @ z, (a_2 - (a_1 @ a_2) * a_1) @ z)
            q_2 = math.atan2(-(cross(a_2, a_1) @ w), (a_1 - (a_2 @ a_1) * a_2) @ w)
            out[s], out[s + 1] = q_1, q_2
            out[s + 2: s + 4] = np.linalg.lstsq(motion_subspace(joint, q_2), omega_j, rcond=None)[0]
            continue
        if tree.hinge(c):  # sin q = a . vee(A_rel), cos q = (tr A_rel - 1) / 2
            vee = 0.5 * np.array([a_rel[2, 1] - a_rel[1, 2], a_rel[0, 2] - a_rel[2, 0], a_rel[1, 0] - a_rel[0, 1]])
            out[s] = math.atan2(joint.axis @ vee, 0.5 * (np.trace(a_rel) - 1.0))
            out[s + 1] = joint.axis @ omega_j
            continue
        out[s: s + 3] = euler_angles(a_rel)
        out[s + 3: s + 6] = omega_j
    return out
