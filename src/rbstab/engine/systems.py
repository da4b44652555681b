"""The system a compiled run integrates: one rigid body, or a chain of them.

The compiled driver (:mod:`rbstab.engine.rk`, :mod:`rbstab.engine.integrate`) takes a
run's system as the pair (``code``, ``p``):

- one body: its variant code and its :data:`rbstab.model.PARAMETERS` record (the only
  system of the CUDA kernel and of the sign law's integrator);
- a tree of bodies (a chain): ``code`` :data:`CHAIN` and ``p`` a :class:`TreeSystem`, the
  arrays of the chain's compiled description (:class:`rbstab.variants.chain.CompiledChain`),
  its admissible region in every record, and its reduced layout (:func:`tree_system`).

The driver asks the system for the few things it needs through the functions below: its
rate, its admissible margin, whether it has bounds or disturbances, their next breakpoint
and the impulses there. Each is chosen by the type of ``p`` when numba compiles the
driver (``numba.extending.overload``, for every target: the CPU and CUDA), so a one-body
run compiles to the code it compiled to with the body's functions called directly, and a
chain takes the same steps, step-size control, dense output, sampling, event location
and wall-time limit.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import types
from numba.extending import overload

from ..jit import jit
from ..kinematics import rotation_and_rate_of, vector
from ..layout import BEYOND_PAPER, POINT_FIXED
from ..model import set_limits
from ..variants.chain import _relative
from ..variants.disturbances import apply_impulses, next_breakpoint
from ..variants.kernels import PERMANENT, limited_quantities, state_rate
from ..variants.tree import (expand_samples, range_margin, reduce_states, reduced_size, tree_expand, tree_layout,
                             tree_rate)
from ..variants.tree import tree_impulses as reduced_impulses
from .status import GIMBAL_LOCK, LEFT_REGION, PART_CODES, RANGE_LEFT, TREE_GIMBAL

__all__ = ["CHAIN", "TreeSystem", "tree_system", "with_offsets", "tree_rows", "reduce_tree_states", "expand_tree_samples", "tree_margin",
           "tree_impulses", "system_rate", "system_margin", "system_limited",
           "system_disturbed", "system_breakpoint", "system_impulses", "gimbal_event", "admissible_event",
           "admissible", "chain_bounds", "disturbed_of",
           "limited_of"]

#: The ``code`` of a chain's runs (no variant's code: a chain's joints carry theirs).
CHAIN = -1

#: A tree as the compiled driver reads it (:mod:`rbstab.variants.tree`): ``params`` (n,)
#: PARAMETERS records (body i with joint i's gains; the admissible region in every record),
#: ``codes`` (n,) the joints' variant codes, ``parents`` (n,) parent indices (-1: ground),
#: ``ppoints`` (n, 3) parent points [m], ``d_at`` (n,) the index of each embedded joint's D in
#: the maximal state (-1: none), the reduced layout (``r_at``, ``u_at``, ``rd_at``: each body's
#: states and generalised velocities, each embedded joint's D) and ``work`` the scratch arrays
#: of an evaluation (:class:`rbstab.variants.tree.TreeWork`): None in the description Python
#: passes (:func:`tree_system`); the driver attaches its own (each call of
#: :func:`rbstab.engine.integrate.integrate_tree_chunk`, each thread of the CUDA kernel), so
#: no two threads share them.
TreeSystem = namedtuple("TreeSystem", ["params", "codes", "parents", "ppoints", "d_at", "r_at", "u_at", "rd_at",
                                       "work"])


def tree_system(compiled, limits=None) -> TreeSystem:
    """The :class:`TreeSystem` of a :class:`rbstab.variants.chain.CompiledChain` (its
    reduced layout, :func:`rbstab.variants.tree.tree_layout`), with the admissible region
    ``limits`` (a :class:`rbstab.model.Limits`, the bounds (5, 3), or None: unbounded)
    written into copies of its records; ``work`` None (the driver's own)."""
    params = compiled.params.copy()
    set_limits(params, limits)
    return TreeSystem(params, compiled.codes, compiled.parents, compiled.ppoints, compiled.d_at,
                      *tree_layout(compiled).args, None)


def with_offsets(system: TreeSystem, offsets) -> TreeSystem:
    """``system`` (one tree, or t trees of one structure) with each tree's h [J] (``offsets``:
    a number, or (t,)) in its first record's ``lyapunov_offset``, in a copy of the records:
    the v the CUDA tree kernel streams (:func:`rbstab.engine.cuda.integrate_chain_runs_cuda`);
    the trees' rates and outputs read no h from the records."""
    params = np.array(system.params, copy=True)
    params[..., 0]["lyapunov_offset"] = offsets
    return system._replace(params=params)


def tree_rows(system: TreeSystem, k: int, tree_of=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trees of k runs of one structure (the same codes, parents and layout):
    ``(params (t, n), ppoints (t, n, 3), tree_of (k,) int64)``, the records and parent
    points of t trees and the tree each run integrates. ``system`` holds one tree
    (``params`` (n,), ``ppoints`` (n, 3); ``tree_of`` None: every run's, t = 1) or t of them
    (``params`` (t, n), ``ppoints`` (t, n, 3); ``tree_of`` (k,) indices into them).

    Raises
    ------
    ValueError
        For a ``tree_of`` of another length or with an index outside [0, t).
    """
    params, ppoints = np.asarray(system.params), np.asarray(system.ppoints, dtype=float)
    if params.ndim == 1:
        params, ppoints = params[None], ppoints[None]
    t = params.shape[0]
    tree_of = np.zeros(k, dtype=np.int64) if tree_of is None else np.ascontiguousarray(tree_of, dtype=np.int64)
    if tree_of.shape != (k,) or (k and not 0 <= tree_of.min() <= tree_of.max() < t):
        raise ValueError(f"tree_of: found shape {tree_of.shape} with indices in "
                         f"[{tree_of.min() if tree_of.size else 0}, {tree_of.max() if tree_of.size else 0}]; "
                         f"expected ({k},) indices into the {t} trees")
    return np.ascontiguousarray(params), np.ascontiguousarray(ppoints), tree_of


def reduce_tree_states(system: TreeSystem, params: np.ndarray, ppoints: np.ndarray, tree_of: np.ndarray,
                       y: np.ndarray) -> np.ndarray:
    """:func:`rbstab.variants.tree.reduce_states` of the maximal states ``y`` (k, 12 n + 3
    e) of k runs, run i's of tree ``tree_of[i]`` (:func:`tree_rows`): (k, n_r)."""
    out = np.empty((len(y), reduced_size(system.codes, system.d_at)))
    reduce_states(params, system.codes, system.parents, ppoints, *system[4:8], np.ascontiguousarray(y, dtype=float),
                  tree_of, out)
    return out


def expand_tree_samples(system: TreeSystem, params: np.ndarray, ppoints: np.ndarray, tree_of: np.ndarray,
                        samples: np.ndarray, out: np.ndarray) -> None:
    """:func:`rbstab.variants.tree.expand_samples` of k runs' reduced samples ``samples``
    (k, m, n_r) into ``out`` (k, m, 12 n + 3 e), run i's by tree ``tree_of[i]``
    (:func:`tree_rows`)."""
    expand_samples(samples, params, system.codes, system.parents, ppoints, *system[4:8], out, tree_of)


# -- one body's admissible region -------------------------------------------------------------
@jit(forceinline=True)
def gimbal_event(y, limit):
    """The event function: zero when |theta_2| reaches ``limit`` (decreasing through 0)."""
    return limit - abs(y[1])


@jit(forceinline=True)
def _bound_margin(q, bounds, j, margin, status):
    """(margin, status) after the bounds ``bounds`` (3,) of quantity j (``q``, a 3-tuple):
    the smaller of ``margin`` and bound_i - |q_i|, with the status code of its axis."""
    for i in range(3):
        m = bounds[i] - abs(q[i])
        if m < margin:
            margin, status = m, LEFT_REGION + 3 * j + i
    return margin, status


@jit(forceinline=True)
def admissible_event(code, y, p, limit):
    """The event function of the admissible region at the state ``y`` of variant ``code``
    with the record ``p``: (margin, status), margin the smallest of the gimbal-lock margin
    ``limit`` - |theta_2| [rad] (``limit`` = pi/2 - gimbal_margin) and every bound
    ``p.limits[j, i]`` - |q_j,i| of ``simulation.limits`` (in the bound's units;
    :func:`rbstab.variants.kernels.limited_quantities`), status the code of the smallest
    (GIMBAL_LOCK, or :func:`rbstab.engine.status.limit_status`). The run leaves the region
    where the margin falls through 0; without bounds (``p.limited`` 0) it is
    :func:`gimbal_event`, bit for bit."""
    margin, status = gimbal_event(y, limit), GIMBAL_LOCK
    if p.limited == 0.0:
        return margin, status
    theta, omega, x, v, e = limited_quantities(code, y, p)
    margin, status = _bound_margin(theta, p.limits[0], 0, margin, status)
    margin, status = _bound_margin(omega, p.limits[1], 1, margin, status)
    margin, status = _bound_margin(x, p.limits[2], 2, margin, status)
    margin, status = _bound_margin(v, p.limits[3], 3, margin, status)
    return _bound_margin(e, p.limits[4], 4, margin, status)


@jit
def admissible(code, y, p, limit):
    """:func:`admissible_event` as a function Python calls (the scipy reference's event,
    the checks of an initial state): (margin, status)."""
    return admissible_event(code, y, p, limit)


# -- a chain's admissible region ------------------------------------------------------------------
@jit(_nrt=False)
def chain_bounds(y, params, codes, parents, ppoints, margin, status):
    """(margin, status) after the bounds ``params[0].limits`` of ``simulation.limits`` on a
    chain's maximal state ``y`` (:class:`TreeSystem`'s arrays): every body's Theta, Omega,
    X, V and every joint's E_j but a point-fixed one's, as :func:`admissible_event`'s (status: the
    quantity, the axis and the body or joint, :func:`rbstab.engine.status.limit_status`)."""
    n = codes.shape[0]
    p0 = params[0]
    for i in range(n):
        part = PART_CODES // 3 * i  # _bound_margin's quantity index j, offset to body i's codes
        margin, status = _bound_margin(vector(y, 12 * i), p0.limits[0], part, margin, status)
        margin, status = _bound_margin(vector(y, 12 * i + 3), p0.limits[1], part + 1, margin, status)
        margin, status = _bound_margin(vector(y, 12 * i + 6), p0.limits[2], part + 2, margin, status)
        margin, status = _bound_margin(vector(y, 12 * i + 9), p0.limits[3], part + 3, margin, status)
    for j in range(n):
        if POINT_FIXED[codes[j]]:
            continue
        a = rotation_and_rate_of(vector(y, 12 * j))[0]
        r = params[j].attachment_point
        point = (y[12 * j + 6] + a[0][0] * r[0] + a[0][1] * r[1] + a[0][2] * r[2],
                 y[12 * j + 7] + a[1][0] * r[0] + a[1][1] * r[1] + a[1][2] * r[2],
                 y[12 * j + 8] + a[2][0] * r[0] + a[2][1] * r[1] + a[2][2] * r[2])
        q = parents[j]
        if q < 0:
            e = (point[0] - ppoints[j, 0], point[1] - ppoints[j, 1], point[2] - ppoints[j, 2])
        else:
            b = rotation_and_rate_of(vector(y, 12 * q))[0]
            s = ppoints[j]
            e = (point[0] - y[12 * q + 6] - (b[0][0] * s[0] + b[0][1] * s[1] + b[0][2] * s[2]),
                 point[1] - y[12 * q + 7] - (b[1][0] * s[0] + b[1][1] * s[1] + b[1][2] * s[2]),
                 point[2] - y[12 * q + 8] - (b[2][0] * s[0] + b[2][1] * s[1] + b[2][2] * s[2]))
        margin, status = _bound_margin(e, p0.limits[4], PART_CODES // 3 * j + 4, margin, status)
    return margin, status


@jit(_nrt=False)
def _chain_breakpoint(params, t, t_end):
    out = t_end
    for i in range(params.shape[0]):
        out = min(out, next_breakpoint(params[i], t, t_end))
    return out


@jit(_nrt=False)
def _chain_disturbed(params):
    for i in range(params.shape[0]):
        if params[i].disturbance_count > 0.0:
            return True
    return False


# -- a tree in reduced coordinates: its region and impulses on its maximal image -------------------------
@jit(_nrt=False, forceinline=True)
def tree_margin(y, p, limit):
    """(margin, status) of the admissible region at the reduced state ``y`` (a
    :class:`TreeSystem` ``p``; as :func:`admissible_event`'s): the gimbal lock, ``limit`` -
    |theta_2| (``limit`` = pi/2 - gimbal_margin [rad]), of the Euler angles the state holds
    (each body's Theta, or the Theta_j of the permanent joint that holds it: eq 1's B is
    singular at |theta_2| = pi/2) and of every other joint's relative Theta_j off the ground
    (the B(Theta_j) of its feedback, eq 23); each hinge's or ball's range that is an
    admissible region (:func:`rbstab.variants.tree.range_margin`); with ``simulation.limits`` also
    :func:`chain_bounds` on the maximal image. The Euler angles of a permanent joint's
    child are not the state's: they pass pi/2 without harm. The maximal image is made only
    where a bound or such a joint asks for it. The status of a gimbal lock names the body
    or joint nearest it (:func:`rbstab.engine.status.gimbal_status`)."""
    n = p.codes.shape[0]
    margin, status = math.inf, TREE_GIMBAL
    limited = p.params[0].limited != 0.0
    relative = False
    for i in range(n):
        if BEYOND_PAPER[p.codes[i]]:  # no Euler angles: a hinge's, a universal joint's, a quaternion ball's
            continue
        m = limit - abs(y[p.r_at[i] + 1])
        if m < margin:
            margin, status = m, TREE_GIMBAL + 2 * i + (1 if p.codes[i] == PERMANENT else 0)
        relative = relative or (not POINT_FIXED[p.codes[i]] and p.parents[i] >= 0)
    margin, status = range_margin(y, p.params, p.codes, p.r_at, margin, status, RANGE_LEFT)
    if not (limited or relative):
        return margin, status
    w = p.work
    tree_expand(y, p.params, p.codes, p.parents, p.ppoints, p.d_at, p.r_at, p.u_at, p.rd_at, w.y, w.chain.rot,
                w.chain.rate, True)
    for j in range(n):
        q = p.parents[j]
        if not POINT_FIXED[p.codes[j]] and q >= 0:
            rel = _relative(rotation_and_rate_of(vector(w.y, 12 * q))[0], rotation_and_rate_of(vector(w.y, 12 * j))[0])
            m = limit - abs(math.asin(min(1.0, max(-1.0, rel[0][2]))))
            if m < margin:
                margin, status = m, TREE_GIMBAL + 2 * j + 1
    if not limited:
        return margin, status
    return chain_bounds(w.y, p.params, p.codes, p.parents, p.ppoints, margin, status)


@jit(_nrt=False, forceinline=False)
def tree_impulses(t, y, p):
    """:func:`rbstab.variants.tree.tree_impulses` of the reduced state ``y`` (its generalised
    velocities jump by M^-1 S' P: the joints' impulsive reactions keep them joints); returns
    their energy [J]."""
    return reduced_impulses(t, y, p.params, p.codes, p.parents, p.ppoints, p.d_at, p.r_at, p.u_at, p.rd_at, p.work)


# -- what the driver asks of a system ----------------------------------------------------------
def system_rate(code, t, y, p, f):
    """dy/dt of the system (``code``, ``p``) at time ``t`` [s] into ``f`` (the disturbances'
    power after the state where ``f`` has one more entry)."""
    raise NotImplementedError("compiled code only")


def system_margin(code, y, p, limit):
    """(margin, status) of the admissible region at ``y``: :func:`admissible_event` or
    :func:`tree_margin`."""
    raise NotImplementedError("compiled code only")


def system_limited(p):
    """Whether the system has bounds of ``simulation.limits``."""
    raise NotImplementedError("compiled code only")


def system_disturbed(p):
    """Whether the system has disturbances (their work W is then integrated after the state)."""
    raise NotImplementedError("compiled code only")


def system_breakpoint(p, t, t_end):
    """The first edge of a disturbance's window after t, or ``t_end``."""
    raise NotImplementedError("compiled code only")


def system_impulses(code, t, y, p):
    """Apply the impulses that start at t to ``y`` (in place); returns their work [J]
    (:func:`rbstab.variants.disturbances.apply_impulses`, :func:`tree_impulses`)."""
    raise NotImplementedError("compiled code only")


_INLINE = {"forceinline": True, "error_model": "numpy", "_nrt": False}


def _is_body(p) -> bool:
    return isinstance(p, types.Record)


@overload(system_rate, target="generic", jit_options=_INLINE)
def _system_rate(code, t, y, p, f):
    if _is_body(p):
        return lambda code, t, y, p, f: state_rate(code, t, y, p, f)
    return lambda code, t, y, p, f: tree_rate(t, y, p.params, p.codes, p.parents, p.ppoints, p.d_at, p.r_at,
                                              p.u_at, p.rd_at, f, p.work)


@overload(system_margin, target="generic", jit_options=_INLINE)
def _system_margin(code, y, p, limit):
    if _is_body(p):
        return lambda code, y, p, limit: admissible_event(code, y, p, limit)
    return lambda code, y, p, limit: tree_margin(y, p, limit)


@overload(system_limited, target="generic", jit_options=_INLINE)
def _system_limited(p):
    if _is_body(p):
        return lambda p: p.limited != 0.0
    return lambda p: p.params[0].limited != 0.0


@overload(system_disturbed, target="generic", jit_options=_INLINE)
def _system_disturbed(p):
    if _is_body(p):
        return lambda p: p.disturbance_count > 0.0
    return lambda p: _chain_disturbed(p.params)


@overload(system_breakpoint, target="generic", jit_options=_INLINE)
def _system_breakpoint(p, t, t_end):
    if _is_body(p):
        return lambda p, t, t_end: next_breakpoint(p, t, t_end)
    return lambda p, t, t_end: _chain_breakpoint(p.params, t, t_end)


@overload(system_impulses, target="generic", jit_options=_INLINE)
def _system_impulses(code, t, y, p):
    if _is_body(p):
        return lambda code, t, y, p: apply_impulses(code == PERMANENT, t, y, p)
    return lambda code, t, y, p: tree_impulses(t, y, p)


# -- the same as compiled functions: what Python (the CUDA simulator's kernels) calls -----------------
@jit(forceinline=True)
def disturbed_of(p):
    """:func:`system_disturbed` as a compiled function (the CUDA kernels call it; under numba's
    CUDA simulator the kernel, Python, calls it compiled)."""
    return system_disturbed(p)


@jit(forceinline=True)
def limited_of(p):
    """:func:`system_limited` as a compiled function."""
    return system_limited(p)
