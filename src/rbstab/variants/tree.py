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

with S_i = d(Omega_i, V_i)/du body i's velocity Jacobian (an outward recursion), M_i =
diag(J_i, m_i I), w_i the wrench on body i (body-frame torque with -Omega x J Omega,
inertial force) and kappa_i its acceleration at du/dt = 0; M is solved by Cholesky. No
constraint force enters the rate and no constraint drifts.

Reduced state layout (``n_r``): body ``i`` at ``y[r_at[i]:]``: Theta_j, Omega_j (6) where
joint i is ``permanent``, else Theta, Omega, X, V (12); then the 3 states D [m] of each
``embedded`` joint, in joint order (``rd_at``). Generalised velocities u (``n_u``): Omega_j
(3) or (Omega, V) (6) per body, at ``u_at[i]``.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from ..jit import jit
from ..kinematics import add, cross, matTvec, matvec, rotation_and_rate_of, sub, vector
from .chain import (
    _OMEGA_J,
    _THETA_J,
    CompiledChain,
    _cholesky_solve,
    _put,
    _relative,
    chain_core,
    chain_wrenches,
    chain_work,
    euler_angles,
)
from .kernels import PERMANENT

__all__ = ["TreeLayout", "TreeWork", "tree_layout", "tree_work", "tree_expand", "tree_rate", "reduce_state",
           "expand_state"]


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
        permanent = compiled.codes[i] == PERMANENT
        r += 6 if permanent else 12
        u += 3 if permanent else 6
    for j in range(n):
        if compiled.d_at[j] >= 0:
            rd_at[j] = r
            r += 3
    return TreeLayout(r_at, u_at, rd_at, r, u)


#: Scratch arrays of one evaluation of a tree of n bodies (:func:`tree_work`): ``y``, ``dy``
#: (12 n + 3 e + 1) the maximal image of the state and its rate; ``s`` (n, 6 n, 6) the
#: velocity Jacobians S_i (``s[i, k]``: column k of S_i, (Omega_i, V_i) of a unit u_k); ``kappa`` (n, 6) the accelerations at du/dt = 0; ``matrix`` (6 n,
#: 6 n) and ``rhs`` (6 n,) M and the right-hand side (du/dt after the solve); ``chain`` the
#: ``support`` (n, 6 n) int64 and ``n_support`` (n,) the columns of u that move body i (its
#: own and those of the bodies it hangs from by permanent joints: S_i is zero elsewhere);
#: ``chain`` the chain's scratch (:class:`rbstab.variants.chain.ChainWork`, whose ``joints``,
#: ``bodies`` and ``scalars`` receive the joints', bodies' and v's quantities).
TreeWork = namedtuple("TreeWork", ["y", "dy", "s", "kappa", "matrix", "rhs", "support", "n_support", "chain"])


@jit
def tree_work(n, n_states):
    """Scratch arrays (:class:`TreeWork`) of a tree of ``n`` bodies whose maximal state has
    ``n_states`` entries."""
    return TreeWork(np.empty(n_states), np.empty(n_states + 1), np.empty((n, 6 * n, 6)), np.empty((n, 6)),
                    np.empty((6 * n, 6 * n)), np.empty(6 * n), np.empty((n, 6 * n), dtype=np.int64),
                    np.empty(n, dtype=np.int64), chain_work(n))


@jit(forceinline=True)
def _compose(a_p, rel):
    """A_p A_rel as a tuple of rows."""
    return (
        (a_p[0][0] * rel[0][0] + a_p[0][1] * rel[1][0] + a_p[0][2] * rel[2][0],
         a_p[0][0] * rel[0][1] + a_p[0][1] * rel[1][1] + a_p[0][2] * rel[2][1],
         a_p[0][0] * rel[0][2] + a_p[0][1] * rel[1][2] + a_p[0][2] * rel[2][2]),
        (a_p[1][0] * rel[0][0] + a_p[1][1] * rel[1][0] + a_p[1][2] * rel[2][0],
         a_p[1][0] * rel[0][1] + a_p[1][1] * rel[1][1] + a_p[1][2] * rel[2][1],
         a_p[1][0] * rel[0][2] + a_p[1][1] * rel[1][2] + a_p[1][2] * rel[2][2]),
        (a_p[2][0] * rel[0][0] + a_p[2][1] * rel[1][0] + a_p[2][2] * rel[2][0],
         a_p[2][0] * rel[0][1] + a_p[2][1] * rel[1][1] + a_p[2][2] * rel[2][1],
         a_p[2][0] * rel[0][2] + a_p[2][1] * rel[1][2] + a_p[2][2] * rel[2][2]),
    )


@jit(forceinline=True)
def _rows(m, i):
    """Row-tuple copy of the 3x3 block ``m[i]``."""
    return ((m[i, 0, 0], m[i, 0, 1], m[i, 0, 2]), (m[i, 1, 0], m[i, 1, 1], m[i, 1, 2]),
            (m[i, 2, 0], m[i, 2, 1], m[i, 2, 2]))


@jit
def tree_expand(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, rot, rate, angles):
    """The maximal image ``y`` (12 n + 3 e,; the chain's layout) of the reduced state ``yr``,
    parents first; ``rot`` (n, 3, 3) receives each A_i and ``rate`` (n, 3, 3) the B of each
    body's reduced angles (B(Theta_j) for a permanent joint's child, else B(Theta_i)). A
    permanent joint's child (ground: A_p = I, Omega_p = V_p = 0, X_p + A_p R_p = R_p):

        A_c = A_p A(Theta_j),  Omega_c = A_rel' Omega_p + Omega_j,
        X_c = X_p + A_p R_p - A_c R_c,  V_c = V_p + A_p (Omega_p x R_p) - A_c (Omega_c x R_c)

    and Theta_c = Theta_j on the ground, else read from A_c (|theta_2| <= pi/2) where
    ``angles`` (the rate reads A_c, not Theta_c)."""
    n = codes.shape[0]
    for i in range(n):
        s = r_at[i]
        if codes[i] != PERMANENT:
            for k in range(12):
                y[12 * i + k] = yr[s + k]
            a, b = rotation_and_rate_of(vector(yr, s))
        else:
            rel, b = rotation_and_rate_of(vector(yr, s))
            omega_j = vector(yr, s + 3)
            r_c, r_p = vector(params[i].attachment_point, 0), vector(ppoints[i], 0)
            q = parents[i]
            if q < 0:
                a = rel
                omega = omega_j
                point, rate_p = r_p, (0.0, 0.0, 0.0)
            else:
                a_p = _rows(rot, q)
                omega_p = vector(y, 12 * q + 3)
                a = _compose(a_p, rel)
                omega = add(matTvec(rel, omega_p), omega_j)
                point = add(vector(y, 12 * q + 6), matvec(a_p, r_p))
                rate_p = add(vector(y, 12 * q + 9), matvec(a_p, cross(omega_p, r_p)))
            if q < 0:
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


@jit
def tree_rate(t, yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, dyr, work):
    """dy/dt (``dyr``, n_r; with one more entry, the disturbances' power: the rate of their
    work W) of the reduced state ``yr`` at time ``t`` [s] (module docstring); the joints',
    bodies' and v's quantities of the maximal image into ``work.chain``'s ``joints``,
    ``bodies`` and ``scalars`` (the permanent joints' Lambda_j not computed: zero there).
    ``work``: :class:`TreeWork`."""
    n = codes.shape[0]
    y, dy, s, kappa, matrix, rhs, cw = work.y, work.dy, work.s, work.kappa, work.matrix, work.rhs, work.chain
    tree_expand(yr, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, y, cw.rot, cw.rate, False)
    _, _, work_power, _, _ = chain_wrenches(t, y, params, codes, parents, ppoints, d_at, dy, cw.joints, cw.bodies,
                                            cw.scalars, cw, True)
    rot, torque, force = cw.rot, cw.torque, cw.force
    n_u = 0
    for i in range(n):
        n_u += 3 if codes[i] == PERMANENT else 6
    # S_i and kappa_i, outward, on the columns that move body i: S_c(Omega) = A_rel' S_p(Omega) + I_j,
    # S_c(V) = S_p(V) + A_p (S_p(Omega) x R_p) - A_c (S_c(Omega) x R_c)
    support, n_support = work.support, work.n_support
    for i in range(n):
        at = u_at[i]
        kappa_zero = True
        if codes[i] != PERMANENT:
            for k in range(6):
                support[i, k] = at + k
                for r in range(6):
                    s[i, at + k, r] = 1.0 if r == k else 0.0
                kappa[i, k] = 0.0
            n_support[i] = 6
            continue
        q = parents[i]
        m = 0
        if q >= 0:
            for k in range(n_support[q]):
                support[i, m] = support[q, k]
                m += 1
        for k in range(3):
            support[i, m] = at + k
            m += 1
        n_support[i] = m
        r_c, r_p = vector(params[i].attachment_point, 0), vector(ppoints[i], 0)
        a_c = _rows(rot, i)
        omega_c = vector(y, 12 * i + 3)
        omega_j = (yr[r_at[i] + 3], yr[r_at[i] + 4], yr[r_at[i] + 5])
        if q >= 0:
            a_p = _rows(rot, q)
            rel = _relative(a_p, a_c)
            for kk in range(n_support[q]):
                k = support[q, kk]
                w_p = (s[q, k, 0], s[q, k, 1], s[q, k, 2])
                w_c = matTvec(rel, w_p)
                v_c = sub(add((s[q, k, 3], s[q, k, 4], s[q, k, 5]), matvec(a_p, cross(w_p, r_p))),
                          matvec(a_c, cross(w_c, r_c)))
                _put(s[i, k], 0, w_c)
                _put(s[i, k], 3, v_c)
            omega_p = vector(y, 12 * q + 3)
            dw_p, dv_p = (kappa[q, 0], kappa[q, 1], kappa[q, 2]), (kappa[q, 3], kappa[q, 4], kappa[q, 5])
            dw_c = add(matTvec(rel, dw_p), cross(omega_c, omega_j))
            dv_c = add(dv_p, matvec(a_p, add(cross(dw_p, r_p), cross(omega_p, cross(omega_p, r_p)))))
        else:
            dw_c = cross(omega_c, omega_j)
            dv_c = (0.0, 0.0, 0.0)
        for k in range(3):  # the joint's own columns: Omega_c moves with Omega_j
            unit = (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
            _put(s[i, at + k], 0, unit)
            _put(s[i, at + k], 3, sub((0.0, 0.0, 0.0), matvec(a_c, cross(unit, r_c))))
        dv_c = sub(dv_c, matvec(a_c, add(cross(dw_c, r_c), cross(omega_c, cross(omega_c, r_c)))))
        _put(kappa[i], 0, dw_c)
        _put(kappa[i], 3, dv_c)
    # M = sum_i S_i' M_i S_i, rhs = sum_i S_i' (w_i - M_i kappa_i), over each body's columns
    for a in range(n_u):
        rhs[a] = 0.0
        for b in range(a + 1):
            matrix[a, b] = 0.0
    for i in range(n):
        p = params[i]
        inertia, mass = p.inertia, p.mass
        jk = matvec(inertia, (kappa[i, 0], kappa[i, 1], kappa[i, 2]))
        net_t = (torque[i, 0] - jk[0], torque[i, 1] - jk[1], torque[i, 2] - jk[2])
        net_f = (force[i, 0] - mass * kappa[i, 3], force[i, 1] - mass * kappa[i, 4], force[i, 2] - mass * kappa[i, 5])
        for bb in range(n_support[i]):
            b = support[i, bb]
            w_b = (s[i, b, 0], s[i, b, 1], s[i, b, 2])
            jw = matvec(inertia, w_b)
            mv = (mass * s[i, b, 3], mass * s[i, b, 4], mass * s[i, b, 5])
            rhs[b] += (w_b[0] * net_t[0] + w_b[1] * net_t[1] + w_b[2] * net_t[2] + s[i, b, 3] * net_f[0]
                       + s[i, b, 4] * net_f[1] + s[i, b, 5] * net_f[2])
            for aa in range(n_support[i]):
                a = support[i, aa]
                if a > b:
                    continue
                matrix[b, a] += (s[i, a, 0] * jw[0] + s[i, a, 1] * jw[1] + s[i, a, 2] * jw[2] + s[i, a, 3] * mv[0]
                                 + s[i, a, 4] * mv[1] + s[i, a, 5] * mv[2])
    _cholesky_solve(matrix, rhs, n_u)
    for i in range(n):
        at, u = r_at[i], u_at[i]
        if codes[i] == PERMANENT:
            _put(dyr, at, matvec(_rows(cw.rate, i), vector(yr, at + 3)))
            for k in range(3):
                dyr[at + 3 + k] = rhs[u + k]
        else:
            _put(dyr, at, matvec(_rows(cw.rate, i), vector(y, 12 * i + 3)))
            _put(dyr, at + 6, vector(y, 12 * i + 9))
            for k in range(3):
                dyr[at + 3 + k] = rhs[u + k]
                dyr[at + 9 + k] = rhs[u + 3 + k]
    n_r = 0
    for i in range(n):
        n_r += 6 if codes[i] == PERMANENT else 12
    for j in range(n):
        if d_at[j] >= 0:
            n_r += 3
            for k in range(3):
                dyr[rd_at[j] + k] = dy[d_at[j] + k]
    if dyr.shape[0] > n_r:  # the work W of the disturbances, integrated after the state
        dyr[n_r] = work_power


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
    n = compiled.size
    joints = np.empty((n, 7, 3))
    chain_core(0.0, np.ascontiguousarray(y, dtype=float), *compiled.args, np.empty(compiled.n_states), joints,
               np.empty((n, 3)), np.empty(5))
    yr = np.empty(layout.n_r)
    for i in range(n):
        at = layout.r_at[i]
        if compiled.codes[i] == PERMANENT:
            yr[at: at + 3], yr[at + 3: at + 6] = joints[i, _THETA_J], joints[i, _OMEGA_J]
        else:
            yr[at: at + 12] = y[12 * i: 12 * i + 12]
    for j in range(n):
        if compiled.d_at[j] >= 0:
            yr[layout.rd_at[j]: layout.rd_at[j] + 3] = y[compiled.d_at[j]: compiled.d_at[j] + 3]
    return yr
