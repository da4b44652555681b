"""A tree of rigid bodies in reduced coordinates (docs/physics.md, "A tree in reduced
coordinates"): a ``permanent`` joint holds its child by construction, the child carried by
the joint's relative orientation Theta_j [rad] and relative angular velocity Omega_j [rad/s]
(child frame); a body on any other joint keeps its own Theta, Omega, X, V.

The description is the chain's (:class:`rbstab.variants.chain.CompiledChain`: a
:data:`rbstab.model.PARAMETERS` record per body and its joint, variant codes, parents,
parent points) and a layout of the reduced state (:class:`TreeLayout`). The applied wrenches
are the chain's own (:func:`rbstab.variants.chain.chain_wrenches`, evaluated at the maximal
image of the reduced state, :func:`tree_expand`); the equations of motion are the bodies'
Newton-Euler equations projected on the generalised velocities u (Jourdain's principle):

    M(q) du/dt = sum_i S_i' (w_i - M_i kappa_i),   M = sum_i S_i' M_i S_i

with S_i = d(Omega_i, V_i)/du body i's velocity Jacobian, M_i = diag(J_i, m_i I), w_i the
wrench on body i (body-frame torque with -Omega x J Omega, inertial force) and kappa_i its
acceleration at du/dt = 0 (an outward recursion). M and the right-hand side are assembled
by composite rigid bodies (each joint's column moves the bodies hanging from it as one;
its momentum is projected on the columns of the joints above it), and M is solved by
Cholesky within its envelope (group by group of the bodies permanent joints hold
together). No constraint force enters the rate and no constraint drifts.

Reduced state layout (``n_r``): body ``i`` at ``y[r_at[i]:]``, the states of its joint's
kind (:data:`rbstab.layout.JOINT_KINDS`, :data:`rbstab.layout.REDUCED_STATES` by variant
code): Theta_j, Omega_j (6) where joint i is ``permanent`` (a ball), a hinge's or a slide's
q, u (2), a universal joint's q_1, q_2, u_1, u_2 (4), a quaternion ball's quaternion and
Omega_j (7), else Theta, Omega, X, V (12, free); then the 3 states D [m] of each ``embedded``
joint, in joint order (``rd_at``). Generalised velocities u (``n_u``): Omega_j (3), a
joint's u (1 or 2) or (Omega, V) (6) per body (:data:`rbstab.layout.VELOCITIES`), at
``u_at[i]``.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from ..jit import jit
from ..kinematics import (IDENTITY, ZERO, add, axis_rotation, cross, dot, matTvec, matvec, quaternion_of_vector,
                          quaternion_rotation, rotation_and_rate_of, sub, universal_columns, universal_rate,
                          universal_rotation, vector)
from ..layout import AXES, POINT_FIXED, REDUCED_STATES, VELOCITIES
from .chain import (
    _LAMBDA,
    _OMEGA_J,
    compose,
    _cholesky_solve,
    _THETA_J,
    CompiledChain,
    _put,
    _relative,
    chain_evaluate,
    chain_wrenches,
    chain_work,
    euler_angles,
    slide_coordinates,
)
from .disturbances import IMPULSE, disturbance_wrench
from .kernels import BALL, HINGE, PERMANENT, SLIDE, UNIVERSAL

__all__ = ["TreeLayout", "TreeWork", "tree_layout", "tree_work", "tree_expand", "tree_rate",
           "tree_push", "tree_impulses", "range_margin", "tree_reactions", "reaction_samples",
           "expand_samples", "reduce_state", "reduce_states", "reduced_size", "expand_state"]


@dataclass(frozen=True)
class TreeLayout:
    """Where each body's states sit in the reduced state and its generalised velocities in u.

    Attributes
    ----------
    r_at, u_at : ndarray, shape (n,), int64
        Start of body i's reduced states (6 or 12) and of its generalised velocities (3 or 6).
    rd_at : ndarray, shape (n,), int64
        Start of embedded joint j's D in the reduced state (-1: none).
    n_r, n_u : int
        Sizes of the reduced state and of u.
    """

    r_at: np.ndarray
    u_at: np.ndarray
    rd_at: np.ndarray
    n_r: int
    n_u: int

    @property
    def args(self) -> tuple:
        return self.r_at, self.u_at, self.rd_at


def tree_layout(compiled: CompiledChain) -> TreeLayout:
    """The reduced layout (module docstring) of the chain ``compiled``."""
    n = compiled.size
    r_at, u_at, rd_at = (np.full(n, -1, dtype=np.int64) for _ in range(3))
    r = u = 0
    for i in range(n):
        r_at[i], u_at[i] = r, u
        r += REDUCED_STATES[compiled.codes[i]]
        u += VELOCITIES[compiled.codes[i]]
    for j in range(n):
        if compiled.d_at[j] >= 0:
            rd_at[j] = r
            r += 3
    return TreeLayout(r_at, u_at, rd_at, r, u)


#: Scratch arrays of one evaluation of a tree of n bodies (:func:`tree_work`): ``y``, ``dy``
#: (12 n + 3 e + 1) the maximal image of the state and its rate; ``kappa`` (n, 6) each body's
#: (dOmega_i/dt, dV_i/dt) at du/dt = 0; ``matrix`` (6 n, 6 n) and ``rhs`` (6 n,) M and Q - b
#: (du/dt after the solve); per body, with the bodies that permanent joints hang from it (its
#: composite, inertial frame): ``mass`` (n,), ``first`` (n, 3) sum m X, ``second`` (n, 3, 3)
#: sum (A J A' + m [X]x' [X]x), ``force`` (n, 3) and ``moment`` (n, 3, about the origin) the
#: sum of w_b - M_b kappa_b; ``start`` (n,) int64 the first column of body i's rows of M (its
#: envelope, :func:`_group_start`); ``chain`` the chain's scratch
#: (:class:`rbstab.variants.chain.ChainWork`, whose ``joints``, ``bodies`` and ``scalars``
#: receive the joints', bodies' and v's quantities).
TreeWork = namedtuple("TreeWork", ["y", "dy", "kappa", "matrix", "rhs", "mass", "first", "second", "force", "moment",
                                   "start", "chain"])


@jit
def tree_work(n, n_states):
    """Scratch arrays (:class:`TreeWork`) of a tree of ``n`` bodies whose maximal state has
    ``n_states`` entries."""
    return TreeWork(np.empty(n_states), np.empty(n_states + 1), np.empty((n, 6)), np.empty((6 * n, 6 * n)),
                    np.empty(6 * n), np.empty(n), np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3)),
                    np.empty((n, 3)), np.empty(n, dtype=np.int64), chain_work(n))


@jit(forceinline=True)
def _column(a_i, code, rate, i, col):
    """Column ``col`` of a point-fixed joint's motion subspace in the inertial frame: the
    unit angular velocity A_i e_col of a ball's child (Omega_j's axis col), A_i s_col of a
    hinge's or a universal joint's (its child-frame column s_col, row col of ``rate[i]``,
    where :func:`tree_expand` put it); a slide's unit velocity A_i a along its axis."""
    if AXES[code] > 0:
        return matvec(a_i, (rate[i, col, 0], rate[i, col, 1], rate[i, col, 2]))
    return (a_i[0][col], a_i[1][col], a_i[2][col])


@jit(forceinline=True)
def _joint_rate(rate, i, code, u, at):
    """S u [rad/s, child frame] of joint i about axes: its columns (rows of ``rate[i]``, as
    :func:`tree_expand` put them) times the entries ``u[at:]`` (its u, or du/dt)."""
    w = (0.0, 0.0, 0.0)
    if code == SLIDE:  # it turns nothing
        return w
    for k in range(AXES[code]):
        w = add(w, (rate[i, k, 0] * u[at + k], rate[i, k, 1] * u[at + k], rate[i, k, 2] * u[at + k]))
    return w


@jit(forceinline=True)
def _joint_angles(yr, codes, r_at, angle):
    """Each joint's coordinates about axes (a hinge's q, a universal joint's q_1, q_2 [rad])
    from the reduced state ``yr`` into ``angle`` (n, 2), as the state holds them (beyond
    (-pi, pi] too)."""
    for i in range(codes.shape[0]):
        for k in range(AXES[codes[i]]):
            angle[i, k] = yr[r_at[i] + k]


@jit(forceinline=True)
def _rows(m, i):
    """Row-tuple copy of the 3x3 block ``m[i]``."""
    return ((m[i, 0, 0], m[i, 0, 1], m[i, 0, 2]), (m[i, 1, 0], m[i, 1, 1], m[i, 1, 2]),
            (m[i, 2, 0], m[i, 2, 1], m[i, 2, 2]))


@jit(forceinline=True)
def _moment_row(second, i, r, cs, point, m, shift):
    """Row r of composite i's second moment about the point P [kg m^2] from its second moment
    about the origin S, first moment cs = sum m X and mass m: S + shift I + cs P' + P cs' - m P P'
    (shift = m |P|^2 - 2 cs.P)."""
    s_r, c_r, p_r = second[i, r], cs[r], point[r]
    return (s_r[0] + c_r * point[0] + p_r * cs[0] - m * p_r * point[0] + (shift if r == 0 else 0.0),
            s_r[1] + c_r * point[1] + p_r * cs[1] - m * p_r * point[1] + (shift if r == 1 else 0.0),
            s_r[2] + c_r * point[2] + p_r * cs[2] - m * p_r * point[2] + (shift if r == 2 else 0.0))


@jit(forceinline=True, _nrt=False)
def tree_expand(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, rot, rate, angles):
    """The maximal image ``y`` (12 n + 3 e,; the chain's layout) of the reduced state ``yr``,
    parents first; ``rot`` (n, 3, 3) receives each A_i and ``rate`` (n, 3, 3) the B of each
    body's reduced angles (B(Theta_j) for a permanent joint's child, I for a hinge's, else
    B(Theta_i)). A point-fixed joint's child (ground: A_p = I, Omega_p = V_p = 0, X_p + A_p
    R_p = R_p; a hinge's A(Theta_j) is exp(q [a]x) and its Omega_j is a dq/dt):

        A_c = A_p A(Theta_j),  Omega_c = A_rel' Omega_p + Omega_j,
        X_c = X_p + A_p R_p - A_c R_c,  V_c = V_p + A_p (Omega_p x R_p) - A_c (Omega_c x R_c)

    and Theta_c = Theta_j on a permanent joint to the ground, else read from A_c (|theta_2| <= pi/2) where
    ``angles`` (the rate reads A_c, not Theta_c). A hinge's and a universal joint's ``rate[i]``
    holds its motion subspace's columns in the child's frame instead, as rows (its axis a;
    s_1, s_2: :func:`rbstab.kinematics.universal_columns`), then zero rows; a slide's its axis
    a. A slide's child keeps its parent's orientation (A_rel = I, Omega_j = 0) and its point
    sits at the parent's point moved by q a (the parent's frame), moving at a dq/dt."""
    n = codes.shape[0]
    for i in range(n):
        s = r_at[i]
        if not POINT_FIXED[codes[i]]:
            for k in range(12):
                y[12 * i + k] = yr[s + k]
            a, b = rotation_and_rate_of(vector(yr, s))
        else:
            if codes[i] == HINGE:  # A_rel = exp(q [a]x), Omega_j = a dq/dt; its column a in rate's first row
                axis = vector(params[i].axis, 0)
                rel, b = axis_rotation(axis, yr[s]), (axis, ZERO, ZERO)
                omega_j = (axis[0] * yr[s + 1], axis[1] * yr[s + 1], axis[2] * yr[s + 1])
            elif codes[i] == UNIVERSAL:  # A_rel = exp(q_1 [a_1]x) exp(q_2 [a_2]x), Omega_j = S dq/dt
                a_1, a_2 = vector(params[i].axis, 0), vector(params[i].axis_2, 0)
                rel = universal_rotation(a_1, a_2, yr[s], yr[s + 1])
                s_1, _ = universal_columns(a_1, a_2, yr[s + 1])
                b = (s_1, a_2, ZERO)  # its columns s_1, s_2 in rate's rows
                omega_j = add((s_1[0] * yr[s + 2], s_1[1] * yr[s + 2], s_1[2] * yr[s + 2]),
                              (a_2[0] * yr[s + 3], a_2[1] * yr[s + 3], a_2[2] * yr[s + 3]))
            elif codes[i] == BALL:  # A_rel of its quaternion
                rel, b = quaternion_rotation(yr[s], yr[s + 1], yr[s + 2], yr[s + 3]), IDENTITY
                omega_j = vector(yr, s + 4)
            elif codes[i] == SLIDE:  # A_rel = I, Omega_j = 0; its axis in rate's first row
                rel, b, omega_j = IDENTITY, (vector(params[i].axis, 0), ZERO, ZERO), ZERO
            else:
                rel, b = rotation_and_rate_of(vector(yr, s))
                omega_j = vector(yr, s + 3)
            r_c, r_p = vector(params[i].attachment_point, 0), vector(ppoints[i], 0)
            slid = ZERO  # a slide's a dq/dt (the parent's frame)
            if codes[i] == SLIDE:  # the parent's point moved by q a
                r_p = add(r_p, (b[0][0] * yr[s], b[0][1] * yr[s], b[0][2] * yr[s]))
                slid = (b[0][0] * yr[s + 1], b[0][1] * yr[s + 1], b[0][2] * yr[s + 1])
            q = parents[i]
            if q < 0:
                a = rel
                omega = omega_j
                point, rate_p = r_p, slid
            else:
                a_p = _rows(rot, q)
                omega_p = vector(y, 12 * q + 3)
                a = compose(a_p, rel)
                omega = add(matTvec(rel, omega_p), omega_j)
                point = add(vector(y, 12 * q + 6), matvec(a_p, r_p))
                rate_p = add(vector(y, 12 * q + 9), matvec(a_p, add(cross(omega_p, r_p), slid)))
            if q < 0 and codes[i] == PERMANENT:
                _put(y, 12 * i, vector(yr, s))
            elif angles:
                _put(y, 12 * i, euler_angles(a))
            _put(y, 12 * i + 3, omega)
            _put(y, 12 * i + 6, sub(point, matvec(a, r_c)))
            _put(y, 12 * i + 9, sub(rate_p, matvec(a, cross(omega, r_c))))
        for r in range(3):
            for c in range(3):
                rot[i, r, c] = a[r][c]
                rate[i, r, c] = b[r][c]
    for j in range(n):
        if d_at[j] >= 0:
            for k in range(3):
                y[d_at[j] + k] = yr[rd_at[j] + k]


@jit(forceinline=True)
def range_margin(yr, params, codes, r_at, margin, status, first):
    """(margin, status) after the ranges that are admissible regions (a record's ``region``)
    of the reduced state ``yr``'s joint coordinates, a hinge's q, a universal joint's q_1,
    q_2 and a ball's Euler angles Theta_j (entries 0, 0-1 and 0-2 of its ``range_lower``,
    ``range_upper``): coordinate - lower
    and upper - coordinate [rad] of each, smaller than ``margin``, replace it and ``status``
    with ``first`` + 6 j + 2 i (the lower end of coordinate i of joint j) or ``first`` + 6 j
    + 2 i + 1 (its upper end) (``first``: :data:`rbstab.engine.status.RANGE_LEFT`)."""
    for j in range(codes.shape[0]):
        if params[j].region != 0.0 and codes[j] == BALL:  # its cone: the angle of its quaternion's turn
            at = r_at[j]
            size = math.sqrt(yr[at + 1] * yr[at + 1] + yr[at + 2] * yr[at + 2] + yr[at + 3] * yr[at + 3])
            m = params[j].range_upper[0] - 2.0 * math.atan2(size, abs(yr[at]))
            if m < margin:
                margin, status = m, first + 6 * j + 1
            continue
        if params[j].region == 0.0 or not (AXES[codes[j]] > 0 or codes[j] == PERMANENT):
            continue
        for i in range(AXES[codes[j]] if AXES[codes[j]] > 0 else 3):
            q = yr[r_at[j] + i]
            m = q - params[j].range_lower[i]
            if m < margin:
                margin, status = m, first + 6 * j + 2 * i
            m = params[j].range_upper[i] - q
            if m < margin:
                margin, status = m, first + 6 * j + 2 * i + 1
    return margin, status


@jit(forceinline=True)
def _group_start(i, codes, parents, u_at):
    """The first generalised velocity of body i's group: the bodies its permanent joints
    chain it to up to a body whose joint is not permanent (or the ground's child). Body i's
    rows of M are zero before it (parents come first in the body order)."""
    k = i
    while POINT_FIXED[codes[k]] and parents[k] >= 0:
        k = parents[k]
    return u_at[k]


@jit(forceinline=True)
def _envelope_cholesky_solve(matrix, rhs, codes, u_at, start):
    """Solve M x = ``rhs`` in place for the tree's mass matrix M (lower triangle of
    ``matrix``, within its envelope: body i's rows from its group's first column
    ``start[i]``, :func:`_group_start`), its factor L (L L' = M) written over it. The groups of bodies
    that permanent joints hold together are blocks of M, and L keeps M's envelope, so a
    tree factorises group by group (a tree without permanent joints, body by body)."""
    n = codes.shape[0]
    for i in range(n):
        s_i = start[i]
        end_i = u_at[i] + VELOCITIES[codes[i]]
        for c in range(u_at[i], end_i):
            total = matrix[c, c]
            for k in range(s_i, c):
                total -= matrix[c, k] * matrix[c, k]
            diagonal = math.sqrt(total)
            matrix[c, c] = diagonal
            for j in range(i, n):
                s_j = start[j]
                if s_j > c:
                    continue
                first = max(s_i, s_j)
                for r in range(max(c + 1, u_at[j]), u_at[j] + VELOCITIES[codes[j]]):
                    total = matrix[r, c]
                    for k in range(first, c):
                        total -= matrix[r, k] * matrix[c, k]
                    matrix[r, c] = total / diagonal
    for i in range(n):
        s_i = start[i]
        for r in range(u_at[i], u_at[i] + VELOCITIES[codes[i]]):
            total = rhs[r]
            for k in range(s_i, r):
                total -= matrix[r, k] * rhs[k]
            rhs[r] = total / matrix[r, r]
    for j in range(n - 1, -1, -1):
        end_j = u_at[j] + VELOCITIES[codes[j]]
        for r in range(end_j - 1, u_at[j] - 1, -1):
            total = rhs[r]
            for i in range(j, n):
                if start[i] > r:
                    continue
                for k in range(max(r + 1, u_at[i]), u_at[i] + VELOCITIES[codes[i]]):
                    total -= matrix[k, r] * rhs[k]
            rhs[r] = total / matrix[r, r]


@jit(_nrt=False, forceinline=True)
def tree_rate(t, yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, dyr, work):
    """The rate of a tree in reduced coordinates (docs/physics.md, "A tree in reduced
    coordinates"; for one body on a permanent joint, eq 21).

    ``yr`` (n_r,) the reduced state (module docstring: Theta_j [rad], Omega_j [rad/s, child
    frame] of a permanent joint's child; Theta [rad], Omega [rad/s, body frame], X [m], V
    [m/s, inertial] of every other body; D [m]) at time ``t`` [s]; ``params``, ``codes``,
    ``parents``, ``ppoints``, ``d_at`` the chain's description
    (:class:`rbstab.variants.chain.CompiledChain`), ``r_at``, ``u_at``, ``rd_at`` its
    :class:`TreeLayout`. Writes dy/dt into ``dyr`` (n_r,; with one more entry, the
    disturbances' power [W], the rate of their work W), and the joints', bodies' and v's
    quantities of the maximal image into ``work.chain``'s ``joints``, ``bodies`` and
    ``scalars`` (as :func:`rbstab.variants.chain.chain_evaluate`'s, the permanent joints'
    Lambda_j not computed: zero there). ``work``: :class:`TreeWork`. Raises nothing: M is
    positive definite at every orientation, and a state at an Euler singularity (eq 5) of a
    12-state body or a permanent joint gives non-finite rates, which the driver reports."""
    n = codes.shape[0]
    y, dy, cw = work.y, work.dy, work.chain
    tree_expand(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, cw.rot, cw.rate, False)
    _joint_angles(yr, codes, r_at, cw.angle)
    _, _, work_power, _, _ = chain_wrenches(t, y, params, codes, parents, ppoints, d_at, dy, cw.joints, cw.bodies,
                                            cw.scalars, cw, True)
    torque, force = cw.torque, cw.force
    n_u = 0
    for i in range(n):
        n_u += VELOCITIES[codes[i]]
    if n_u == 6 * n:  # no permanent joint: M = diag(J_i, m_i I), each body's own Newton-Euler equations
        for i in range(n):
            at, p = r_at[i], params[i]
            _put(dyr, at, matvec(_rows(cw.rate, i), vector(y, 12 * i + 3)))
            _put(dyr, at + 3, matvec(p.inertia_inv, vector(torque[i], 0)))
            _put(dyr, at + 6, vector(y, 12 * i + 9))
            _put(dyr, at + 9, (force[i, 0] / p.mass, force[i, 1] / p.mass, force[i, 2] / p.mass))
    else:
        _coupled_rate(yr, params, codes, parents, ppoints, r_at, u_at, dyr, work)
    n_r = 0
    for i in range(n):
        n_r += REDUCED_STATES[codes[i]]
    for j in range(n):
        if d_at[j] >= 0:
            n_r += 3
            for k in range(3):
                dyr[rd_at[j] + k] = dy[d_at[j] + k]
    if dyr.shape[0] > n_r:  # the work W of the disturbances, integrated after the state
        dyr[n_r] = work_power


@jit(forceinline=True)
def _coupled_rate(yr, params, codes, parents, ppoints, r_at, u_at, dyr, work):
    """:func:`tree_rate`'s generalised accelerations of a tree with point-fixed joints, after
    its applied wrenches (``work.chain``'s ``torque``, ``force``, rotations at ``work.y``):
    kappa, then :func:`_generalised_solve`; writes every body's rates into ``dyr``."""
    n = codes.shape[0]
    y, kappa, rhs, cw = work.y, work.kappa, work.rhs, work.chain
    rot = cw.rot
    # kappa_i, outward: each body's (dOmega_i/dt, dV_i/dt) at du/dt = 0
    for i in range(n):
        if not POINT_FIXED[codes[i]]:
            for r in range(6):
                kappa[i, r] = 0.0
            continue
        _carried_accelerations(i, yr, y, params, codes, parents, ppoints, r_at, rot, cw.rate, (0.0, 0.0, 0.0), kappa)
    _generalised_solve(params, codes, parents, u_at, work)
    for i in range(n):
        at, u = r_at[i], u_at[i]
        if AXES[codes[i]] > 0:  # dq/dt = u
            m = AXES[codes[i]]
            for k in range(m):
                dyr[at + k] = yr[at + m + k]
                dyr[at + m + k] = rhs[u + k]
        elif codes[i] == PERMANENT:
            _put(dyr, at, matvec(_rows(cw.rate, i), vector(yr, at + 3)))
            for k in range(3):
                dyr[at + 3 + k] = rhs[u + k]
        elif codes[i] == BALL:  # dq/dt = 1/2 q (0, Omega_j), the quaternion product
            w, x, y_, z = yr[at], yr[at + 1], yr[at + 2], yr[at + 3]
            o1, o2, o3 = yr[at + 4], yr[at + 5], yr[at + 6]
            dyr[at] = -0.5 * (x * o1 + y_ * o2 + z * o3)
            dyr[at + 1] = 0.5 * (w * o1 + y_ * o3 - z * o2)
            dyr[at + 2] = 0.5 * (w * o2 + z * o1 - x * o3)
            dyr[at + 3] = 0.5 * (w * o3 + x * o2 - y_ * o1)
            for k in range(3):
                dyr[at + 4 + k] = rhs[u + k]
        else:
            _put(dyr, at, matvec(_rows(cw.rate, i), vector(y, 12 * i + 3)))
            _put(dyr, at + 6, vector(y, 12 * i + 9))
            for k in range(3):
                dyr[at + 3 + k] = rhs[u + k]
                dyr[at + 9 + k] = rhs[u + 3 + k]


@jit(forceinline=True)
def _carried_accelerations(i, yr, y, params, codes, parents, ppoints, r_at, rot, rate, dw_j, acc):
    """Point-fixed joint i's child's (dOmega_c/dt [rad/s^2, child frame], dV_c/dt [m/s^2,
    inertial]) into ``acc[i]`` (n, 6), its parent's already in ``acc[parents[i]]`` (the
    ground's zero), its joint's dOmega_j/dt ``dw_j`` at fixed columns (S du/dt): the time
    derivative of :func:`tree_expand`'s Omega_c = A_rel' Omega_p + Omega_j and V_c (kappa_i
    with dw_j = 0); a universal joint's turning column adds u_1 u_2 (s_1 x a_2). A slide's
    child turns with its parent, its point at R_p + q a (the parent's frame) moving along a:
    dV_c/dt = dV_p/dt + A_p (dOmega_p/dt x r + Omega_p x (Omega_p x r) + 2 Omega_p x a u + a
    du/dt), r = R_p + q a - R_c (``dw_j`` = (du/dt, 0, 0) for a slide)."""
    q = parents[i]
    r_c = vector(params[i].attachment_point, 0)
    if codes[i] == SLIDE:
        axis, at = vector(params[i].axis, 0), r_at[i]
        arm = sub(add(vector(ppoints[i], 0), (axis[0] * yr[at], axis[1] * yr[at], axis[2] * yr[at])), r_c)
        u, du = yr[at + 1], dw_j[0]
        lin = (axis[0] * du, axis[1] * du, axis[2] * du)
        dw_c = ZERO
        if q >= 0:
            omega_p, dw_c, dv_p = vector(y, 12 * q + 3), vector(acc[q], 0), vector(acc[q], 3)
            lin = add(lin, add(add(cross(dw_c, arm), cross(omega_p, cross(omega_p, arm))),
                               cross(omega_p, (2.0 * u * axis[0], 2.0 * u * axis[1], 2.0 * u * axis[2]))))
            lin = add(dv_p, matvec(_rows(rot, q), lin))
        _put(acc[i], 0, dw_c)
        _put(acc[i], 3, lin)
        return
    a_c = _rows(rot, i)
    omega_c = vector(y, 12 * i + 3)
    omega_j = vector(yr, r_at[i] + (4 if codes[i] == BALL else 3))
    if AXES[codes[i]] > 0:  # S dq/dt
        omega_j = _joint_rate(rate, i, codes[i], yr, r_at[i] + AXES[codes[i]])
    if codes[i] == UNIVERSAL:  # ds_1/dt = s_1 x a_2 dq_2/dt: s_1 = exp(-q_2 [a_2]x) a_1
        at = r_at[i]
        bias = cross((rate[i, 0, 0], rate[i, 0, 1], rate[i, 0, 2]), (rate[i, 1, 0], rate[i, 1, 1], rate[i, 1, 2]))
        rates = yr[at + 2] * yr[at + 3]
        dw_j = add(dw_j, (rates * bias[0], rates * bias[1], rates * bias[2]))
    dw_c = add(dw_j, cross(omega_c, omega_j))
    dv_c = (0.0, 0.0, 0.0)
    if q >= 0:
        r_p = vector(ppoints[i], 0)
        a_p = _rows(rot, q)
        omega_p = vector(y, 12 * q + 3)
        dw_p, dv_p = vector(acc[q], 0), vector(acc[q], 3)
        dw_c = add(matTvec(_relative(a_p, a_c), dw_p), dw_c)
        dv_c = add(dv_p, matvec(a_p, add(cross(dw_p, r_p), cross(omega_p, cross(omega_p, r_p)))))
    dv_c = sub(dv_c, matvec(a_c, add(cross(dw_c, r_c), cross(omega_c, cross(omega_c, r_c)))))
    _put(acc[i], 0, dw_c)
    _put(acc[i], 3, dv_c)


@jit(forceinline=True)
def _generalised_solve(params, codes, parents, u_at, work):
    """M x = sum_i S_i' (w_i - M_i kappa_i) into ``work.rhs`` (n_u,): the tree's mass matrix
    M (at the rotations ``work.chain.rot`` and positions ``work.y``) and the wrenches
    ``work.chain``'s ``torque`` (body frame), ``force`` (inertial) less each body's
    ``work.kappa`` (its accelerations at du/dt = 0), by composite rigid bodies and the
    Cholesky solve within M's envelope: x the generalised accelerations, or the jump of u
    of impulsive wrenches with kappa zero."""
    n = codes.shape[0]
    y, kappa, matrix, rhs, cw = work.y, work.kappa, work.matrix, work.rhs, work.chain
    rot, torque, force = cw.rot, cw.torque, cw.force
    mass, first, second, f_net, n_net = work.mass, work.first, work.second, work.force, work.moment
    n_u = 0
    for i in range(n):
        n_u += VELOCITIES[codes[i]]
    # composite rigid bodies, leaves first: each body with the bodies that permanent joints hang
    # from it: mass, first moment sum m X, second moment about the origin sum (A J A' + m [X]x' [X]x)
    # (inertial frame), and the residual wrench sum (w_b - M_b kappa_b): force, moment about the origin
    for i in range(n):
        p = params[i]
        m = p.mass
        a = _rows(rot, i)
        x = vector(y, 12 * i + 6)
        mass[i] = m
        _put(first[i], 0, (m * x[0], m * x[1], m * x[2]))
        xx = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
        for r in range(3):
            ja = matvec(p.inertia, (a[r][0], a[r][1], a[r][2]))  # J A' e_r
            for c in range(3):
                second[i, r, c] = (a[c][0] * ja[0] + a[c][1] * ja[1] + a[c][2] * ja[2]
                                   + m * ((xx if r == c else 0.0) - x[r] * x[c]))
        jk = matvec(p.inertia, vector(kappa[i], 0))
        tau = matvec(a, (torque[i, 0] - jk[0], torque[i, 1] - jk[1], torque[i, 2] - jk[2]))
        rf = (force[i, 0] - m * kappa[i, 3], force[i, 1] - m * kappa[i, 4], force[i, 2] - m * kappa[i, 5])
        _put(f_net[i], 0, rf)
        _put(n_net[i], 0, add(tau, cross(x, rf)))
    for i in range(n - 1, -1, -1):
        q = parents[i]
        if POINT_FIXED[codes[i]] and q >= 0:
            mass[q] += mass[i]
            for r in range(3):
                first[q, r] += first[i, r]
                f_net[q, r] += f_net[i, r]
                n_net[q, r] += n_net[i, r]
                for c in range(3):
                    second[q, r, c] += second[i, r, c]
    # M and Q - b: a column of body i's joint moves its composite (a unit angular velocity
    # about the joint's point P along A_i e_c; for a 12-state body about its centre of mass,
    # and a unit velocity e_l); its momentum (f, moment about P) projected on the columns of
    # the joint and of every joint above it in the group
    start = work.start
    for i in range(n):  # M's envelope: a row's columns from its group's first (parents come first)
        start[i] = _group_start(i, codes, parents, u_at)
        for a in range(u_at[i], u_at[i] + VELOCITIES[codes[i]]):
            rhs[a] = 0.0
            for b in range(start[i], a + 1):
                matrix[a, b] = 0.0
    for i in range(n):
        at = u_at[i]
        a_i = _rows(rot, i)
        fixed = POINT_FIXED[codes[i]]
        point = vector(y, 12 * i + 6)
        if fixed:
            point = add(point, matvec(a_i, vector(params[i].attachment_point, 0)))
        m = mass[i]
        c = sub(vector(first[i], 0), (m * point[0], m * point[1], m * point[2]))  # first moment about P
        cs = vector(first[i], 0)
        shift = m * (point[0] * point[0] + point[1] * point[1] + point[2] * point[2]) - 2.0 * (
            cs[0] * point[0] + cs[1] * point[1] + cs[2] * point[2])
        moment_p = sub(vector(n_net[i], 0), cross(point, vector(f_net[i], 0)))  # residual moment about P
        inertia_p = (_moment_row(second, i, 0, cs, point, m, shift), _moment_row(second, i, 1, cs, point, m, shift),
                     _moment_row(second, i, 2, cs, point, m, shift))
        for col in range(VELOCITIES[codes[i]] if fixed else 3):  # the rotational columns (a slide's translation)
            e = _column(a_i, codes[i], cw.rate, i, col)
            row = at + col
            if codes[i] == SLIDE:  # a unit velocity e: momentum m e, its moment about P c x e
                f, inertia_e = (m * e[0], m * e[1], m * e[2]), cross(c, e)
                rhs[row] = dot(e, vector(f_net[i], 0))
                matrix[row, at] = m
            else:
                f = cross(e, c)
                inertia_e = matvec(inertia_p, e)
                rhs[row] = dot(e, moment_p)
                for col2 in range(col + 1):
                    matrix[row, at + col2] = dot(_column(a_i, codes[i], cw.rate, i, col2), inertia_e)
            if not fixed:
                for l in range(3):
                    matrix[at + 3 + l, row] = f[l]
            k = i
            while POINT_FIXED[codes[k]] and parents[k] >= 0:
                k = parents[k]
                a_k = _rows(rot, k)
                if codes[k] == SLIDE:  # its column a unit velocity: the momentum's projection
                    matrix[row, u_at[k]] = dot(_column(a_k, codes[k], cw.rate, k, 0), f)
                    continue
                fixed_k = POINT_FIXED[codes[k]]
                point_k = vector(y, 12 * k + 6)
                if fixed_k:
                    point_k = add(point_k, matvec(a_k, vector(params[k].attachment_point, 0)))
                moment_k = add(inertia_e, cross(sub(point, point_k), f))
                for col2 in range(VELOCITIES[codes[k]] if fixed_k else 3):
                    matrix[row, u_at[k] + col2] = dot(_column(a_k, codes[k], cw.rate, k, col2), moment_k)
                if not fixed_k:
                    for l in range(3):
                        matrix[row, u_at[k] + 3 + l] = f[l]
        if not fixed:
            for l in range(3):
                rhs[at + 3 + l] = f_net[i, l]
                for l2 in range(l + 1):
                    matrix[at + 3 + l, at + 3 + l2] = m if l == l2 else 0.0
    groups = 0
    for i in range(n):
        groups += 1 if start[i] == u_at[i] else 0
    if groups == 1:  # one group: M is dense
        _cholesky_solve(matrix, rhs, n_u)
    else:
        _envelope_cholesky_solve(matrix, rhs, codes, u_at, start)


@jit(forceinline=True)
def _kinetic_energy(y, params):
    """The kinetic energy [J] of the maximal state ``y``: sum 1/2 (m V'V + Omega' J Omega)."""
    total = 0.0
    for i in range(params.shape[0]):
        v, omega = vector(y, 12 * i + 9), vector(y, 12 * i + 3)
        total += 0.5 * params[i].mass * dot(v, v) + 0.5 * dot(omega, matvec(params[i].inertia, omega))
    return total


@jit(_nrt=False)
def tree_reactions(t, yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, dyr, work, total, out, moment):
    """Lambda_j [N] (inertial frame) of every point-fixed joint j (a ball's, a hinge's, a
    slide's: with its force along the axis): the force its parent (or the ground) applies to
    body j at C_j, into ``out[j]`` (n, 3; other rows untouched). From the motion (:func:`tree_rate` at ``t`` [s] and the reduced state
    ``yr``: every body's accelerations, an outward recursion from du/dt) and Newton's law on
    the bodies that joint j carries, leaves first:

        Lambda_j = m_j dV_j/dt - F_j + sum over point-fixed children c of Lambda_c

    with F_j the applied force on body j (gravity, feedback H, the point laws' forces of the
    joints at it, disturbances; inertial). Into ``moment[r]`` (n, 3; other rows untouched) of
    each joint r to the ground whose bodies all hang on point-fixed joints: the ground's whole
    moment on them about its point C_r [N m, inertial] (the joint's torque and its reaction's),
    from their angular momentum about C_r,

        M_r = sum_b [A_b (J_b dOmega_b/dt + Omega_b x J_b Omega_b - T_b) + (X_b - C_r) x (m_b dV_b/dt - F_b)]

    (T_b the disturbances' torque on body b about its centre of mass; the joints' torques
    between the bodies cancel); NaN where a body it carries hangs on a point law. ``dyr``
    (n_r + 1,), ``work`` (:class:`TreeWork`) and ``total`` (n, 6) scratch: ``total[i]``
    receives body i's (dOmega_i/dt [rad/s^2, body frame], dV_i/dt [m/s^2])."""
    n = codes.shape[0]
    tree_rate(t, yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, dyr, work)
    fixed = False
    for i in range(n):
        fixed = fixed or POINT_FIXED[codes[i]]
    if not fixed:
        return
    y, rhs, cw = work.y, work.rhs, work.chain
    rot, force = cw.rot, cw.force
    for i in range(n):  # outward: each body's accelerations with du/dt (kappa's recursion, du/dt added)
        u = u_at[i]
        if not POINT_FIXED[codes[i]]:
            for r in range(6):
                total[i, r] = rhs[u + r]
        elif codes[i] == SLIDE:  # its du/dt along its axis
            _carried_accelerations(i, yr, y, params, codes, parents, ppoints, r_at, rot, cw.rate, (rhs[u], 0.0, 0.0),
                                   total)
        elif AXES[codes[i]] > 0:  # dOmega_j/dt = S du/dt (+ a universal joint's turning column's term)
            _carried_accelerations(i, yr, y, params, codes, parents, ppoints, r_at, rot, cw.rate,
                                   _joint_rate(cw.rate, i, codes[i], rhs, u), total)
        else:
            _carried_accelerations(i, yr, y, params, codes, parents, ppoints, r_at, rot, cw.rate, vector(rhs, u),
                                   total)
    for r in range(n):  # the ground's moment on the bodies of each joint to the ground
        if parents[r] < 0 and POINT_FIXED[codes[r]]:
            for k in range(3):
                moment[r, k] = 0.0
    for b in range(n):
        root, held = b, POINT_FIXED[codes[b]]
        while parents[root] >= 0:
            root = parents[root]
            held = held and POINT_FIXED[codes[root]]
        if not POINT_FIXED[codes[root]]:
            continue
        if not held:
            for k in range(3):
                moment[root, k] = np.nan
            continue
        p = params[b]
        a_b = _rows(rot, b)
        omega = vector(y, 12 * b + 3)
        _, t_b = disturbance_wrench(t, a_b, p)
        jw = matvec(p.inertia, omega)
        spin = add(matvec(p.inertia, vector(total[b], 0)), cross(omega, jw))
        arm = sub(vector(y, 12 * b + 6), vector(ppoints[root], 0))
        lin = (p.mass * total[b, 3] - force[b, 0], p.mass * total[b, 4] - force[b, 1],
               p.mass * total[b, 5] - force[b, 2])
        if b == root and codes[b] == SLIDE:  # its force from the ground (in force[b]) is the ground's
            lin = add(lin, vector(cw.joints[b, _LAMBDA], 0))
        m_b = add(matvec(a_b, sub(spin, t_b)), cross(arm, lin))
        for k in range(3):
            moment[root, k] += m_b[k]
    for i in range(n):  # then each body's m dV/dt - F, and leaves first the reactions they pass up
        m = params[i].mass
        for k in range(3):
            total[i, k] = m * total[i, 3 + k] - force[i, k]
    for i in range(n - 1, -1, -1):  # a slide's reaction with its force along the axis (in force[i], and its
        if POINT_FIXED[codes[i]]:   # opposite in its parent's: the sum passed up is the whole)
            for k in range(3):
                out[i, k] = total[i, k] + (cw.joints[i, _LAMBDA, k] if codes[i] == SLIDE else 0.0)
                if parents[i] >= 0:
                    total[parents[i], k] += total[i, k]


@jit
def reaction_samples(times, states, joint_theta, joint_omega, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at,
                     tree_of, out, moments):
    """:func:`tree_reactions` at every sample: ``states`` (m, 12 n + 3 e) the maximal states
    at ``times`` (m,) [s] with their joints' Theta_j [rad], Omega_j [rad/s, child frame]
    ``joint_theta``, ``joint_omega`` (m, n, 3; as :func:`rbstab.variants.chain.evaluate`
    gives them: a hinge's q continued from sample to sample of a run), sample s of the tree
    ``tree_of[s]`` (``params`` (t, n), ``ppoints`` (t, n, 3)); Lambda_j [N, inertial] into
    ``out`` (n, 3, m), NaN where the state is NaN, rows of joints that are not point-fixed
    untouched; the ground's moments [N m, inertial] into ``moments`` (n, 3, m) at the
    point-fixed joints to the ground (the others untouched)."""
    n = codes.shape[0]
    n_r = reduced_size_of(codes, d_at)
    yr, dyr = np.empty(n_r), np.empty(n_r + 1)
    work = tree_work(n, states.shape[1])
    total, sample, moment = np.empty((n, 6)), np.empty((n, 3)), np.empty((n, 3))
    for s in range(states.shape[0]):
        if states[s, 0] != states[s, 0]:
            sample[:] = np.nan
            moment[:] = np.nan
        else:
            t = tree_of[s]
            _reduced_from(states[s], params[t], codes, parents, ppoints[t], d_at, r_at, rd_at, joint_theta[s],
                          joint_omega[s], yr)
            tree_reactions(times[s], yr, params[t], codes, parents, ppoints[t], d_at, r_at, u_at, rd_at, dyr, work,
                           total, sample, moment)
        for i in range(n):
            if POINT_FIXED[codes[i]]:
                for k in range(3):
                    out[i, k, s] = sample[i, k]
                    if parents[i] < 0:
                        moments[i, k, s] = moment[i, k]


@jit(forceinline=True)
def reduced_size_of(codes, d_at):
    """n_r of a tree of joint codes ``codes`` whose embedded joints' D sit at ``d_at`` (-1: none)."""
    n_r = 0
    for i in range(codes.shape[0]):
        n_r += REDUCED_STATES[codes[i]] + (3 if d_at[i] >= 0 else 0)
    return n_r


@jit(forceinline=True)
def _reduced_from(y, params, codes, parents, ppoints, d_at, r_at, rd_at, theta_j, omega_j, out):
    """The reduced state ``out`` (n_r,) of the maximal state ``y`` whose joints' Theta_j,
    Omega_j (n, 3) are ``theta_j``, ``omega_j`` (:func:`rbstab.variants.chain.chain_evaluate`'s;
    a hinge's q the angle it continued): q = a . Theta_j, u = a . Omega_j of a hinge; q_1,
    q_2 (entries 0-1 of Theta_j) and u = B Omega_j (rows 0-1) of a universal joint; Theta_j,
    Omega_j of a ball; a slide's q, u from its points (:func:`rbstab.variants.chain.slide_coordinates`);
    every other body's Theta, Omega, X, V; D."""
    for i in range(codes.shape[0]):
        at = r_at[i]
        if codes[i] == SLIDE:
            out[at], out[at + 1], _ = slide_coordinates(y, i, params, parents, ppoints)
        elif codes[i] == HINGE:
            axis = vector(params[i].axis, 0)
            out[at] = dot(axis, vector(theta_j[i], 0))
            out[at + 1] = dot(axis, vector(omega_j[i], 0))
        elif codes[i] == UNIVERSAL:
            b = universal_rate(vector(params[i].axis, 0), vector(params[i].axis_2, 0), theta_j[i, 1])
            out[at], out[at + 1] = theta_j[i, 0], theta_j[i, 1]
            out[at + 2], out[at + 3] = dot(b[0], vector(omega_j[i], 0)), dot(b[1], vector(omega_j[i], 0))
        elif codes[i] == PERMANENT:
            for c in range(3):
                out[at + c] = theta_j[i, c]
                out[at + 3 + c] = omega_j[i, c]
        elif codes[i] == BALL:  # its quaternion of the rotation vector Theta_j
            out[at], out[at + 1], out[at + 2], out[at + 3] = quaternion_of_vector(vector(theta_j[i], 0))
            for c in range(3):
                out[at + 4 + c] = omega_j[i, c]
        else:
            for c in range(12):
                out[at + c] = y[12 * i + c]
    for j in range(codes.shape[0]):
        if d_at[j] >= 0:
            for c in range(3):
                out[rd_at[j] + c] = y[d_at[j] + c]


@jit(_nrt=False)
def tree_push(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, body, point, value, torque_push, work):
    """Apply a push to the reduced state ``yr`` in place and return its energy dT [J] (the
    jump of the kinetic energy): a force impulse ``value`` P [N s] (inertial frame) at
    ``point`` R [m] of body ``body`` (its frame, from its centre of mass), or with
    ``torque_push`` a torque impulse L [N m s] (its frame). The generalised velocities jump
    by du = M^-1 S' P (the joints' impulsive reactions keep them joints: Jourdain's
    principle at an instant, docs/physics.md "A push on a chain"), the configuration stays.
    ``work``: :class:`TreeWork`."""
    n = codes.shape[0]
    y, cw, kappa = work.y, work.chain, work.kappa
    tree_expand(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, cw.rot, cw.rate, False)
    before = _kinetic_energy(y, params)
    cw.torque[:] = 0.0
    cw.force[:] = 0.0
    kappa[:] = 0.0
    v = (value[0], value[1], value[2])
    if torque_push:
        _put(cw.torque[body], 0, v)
    else:
        _put(cw.torque[body], 0, cross((point[0], point[1], point[2]), matTvec(_rows(cw.rot, body), v)))
        _put(cw.force[body], 0, v)
    _generalised_solve(params, codes, parents, u_at, work)
    rhs = work.rhs
    for i in range(n):
        at, u = r_at[i], u_at[i]
        if AXES[codes[i]] > 0:
            for k in range(AXES[codes[i]]):
                yr[at + AXES[codes[i]] + k] += rhs[u + k]
        elif codes[i] == PERMANENT or codes[i] == BALL:
            for k in range(3):
                yr[at + REDUCED_STATES[codes[i]] - 3 + k] += rhs[u + k]
        else:
            for k in range(3):
                yr[at + 3 + k] += rhs[u + k]
                yr[at + 9 + k] += rhs[u + 3 + k]
    tree_expand(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, cw.rot, cw.rate, False)
    return _kinetic_energy(y, params) - before


@jit(_nrt=False)
def tree_impulses(t, yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, work):
    """Apply the impulses of every body's disturbances that start at ``t`` [s] to the reduced
    state ``yr`` in place (:func:`tree_push`, one after the other); returns their energy, the
    jump of the kinetic energy [J] (0 where none starts at t). ``work``: :class:`TreeWork`."""
    jump = 0.0
    for i in range(codes.shape[0]):
        p = params[i]
        for k in range(int(p.disturbance_count)):
            if p.disturbance_kind[k] == IMPULSE and p.disturbance_start[k] == t:
                jump += tree_push(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, i,
                                  p.disturbance_point[k], p.disturbance_value[k], p.disturbance_torque[k] != 0.0, work)
    return jump


@jit
def expand_samples(samples, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, out, tree_of):
    """The maximal image ``out`` (k, m, 12 n + 3 e) of k runs' reduced states ``samples``
    (k, m, n_r) row by row, run a's of the tree ``tree_of[a]`` (``params`` (t, n), ``ppoints``
    (t, n, 3): t trees of one structure; NaN rows stay NaN)."""
    rot, rate = np.empty((codes.shape[0], 3, 3)), np.empty((codes.shape[0], 3, 3))
    permanent = False
    for i in range(codes.shape[0]):
        permanent = permanent or POINT_FIXED[codes[i]]
    if not permanent:  # the two layouts are one
        out[:] = samples
        return
    for a in range(samples.shape[0]):
        t = tree_of[a]
        for b in range(samples.shape[1]):
            tree_expand(samples[a, b], params[t], codes, parents, ppoints[t], d_at, r_at, u_at, rd_at, out[a, b], rot,
                        rate, True)


def expand_state(compiled: CompiledChain, layout: TreeLayout, yr: np.ndarray) -> np.ndarray:
    """The maximal image (the chain's state, 12 n + 3 e) of the reduced state ``yr`` (n_r,)."""
    y = np.empty(compiled.n_states)
    n = compiled.size
    tree_expand(np.ascontiguousarray(yr, dtype=float), *compiled.args, *layout.args, y, np.empty((n, 3, 3)),
                np.empty((n, 3, 3)), True)
    return y


def reduce_state(compiled: CompiledChain, layout: TreeLayout, y: np.ndarray) -> np.ndarray:
    """The reduced state (n_r,) of the chain's state ``y`` (12 n + 3 e,): Theta_j, Omega_j
    of each permanent joint (the joint's quantities of the chain), every other body's
    Theta, Omega, X, V, and D."""
    params, codes, parents, ppoints, d_at = compiled.args
    out = np.empty((1, layout.n_r))
    reduce_states(params[None], codes, parents, ppoints[None], d_at, *layout.args,
                  np.ascontiguousarray(y, dtype=float)[None], np.zeros(1, np.int64), out)
    return out[0]


def reduced_size(codes, d_at) -> int:
    """n_r: the size of the reduced state of a tree of joint variant codes ``codes`` (n,)
    whose embedded joints' D sit at ``d_at`` (n,; -1: none)."""
    return int(reduced_size_of(np.asarray(codes, dtype=np.int64), np.asarray(d_at, dtype=np.int64)))


@jit
def reduce_states(params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, tree_of, out):
    """The reduced states ``out`` (k, n_r) of k runs' maximal states ``y`` (k, 12 n + 3 e),
    run a's of the tree ``tree_of[a]`` (``params`` (t, n), ``ppoints`` (t, n, 3): t trees
    of one structure, :class:`rbstab.engine.systems.TreeSystem`'s arrays): a body whose joint
    is not permanent keeps its maximal entries; a permanent joint's child is carried by its
    Theta_j, Omega_j (its position follows from its parent's, eq 32)."""
    n = codes.shape[0]
    permanent = False
    for i in range(n):
        permanent = permanent or POINT_FIXED[codes[i]]
    joints, bodies, scalars = np.empty((n, 7, 3)), np.empty((n, 3)), np.empty(5)
    dy, work = np.empty(y.shape[1]), chain_work(n)
    for a in range(y.shape[0]):
        t = tree_of[a]
        if permanent:
            work.angle[:] = 0.0  # a hinge's angle read in (-pi, pi]
            chain_evaluate(0.0, y[a], params[t], codes, parents, ppoints[t], d_at, dy, joints, bodies, scalars, work)
        _reduced_from(y[a], params[t], codes, parents, ppoints[t], d_at, r_at, rd_at, joints[:, _THETA_J],
                      joints[:, _OMEGA_J], out[a])
