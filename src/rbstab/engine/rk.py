"""scipy's explicit Runge-Kutta pairs (RK23, RK45, DOP853) as compiled code, one run at a time.

Each function follows ``scipy/integrate/_ivp/rk.py`` and ``common.py`` (scipy 1.17), so a
run takes the steps ``solve_ivp`` takes on the same right-hand side, up to rounding:
:func:`initial_step` is ``select_initial_step``, :func:`rk_step` is ``rk_step``,
:func:`error_norm` is ``_estimate_error_norm`` (DOP853's with its 3rd- and 5th-order
estimates), :func:`dense_coefficients` and :func:`dense_value` are ``_dense_output_impl``
and the ``DenseOutput`` classes. The right-hand side is the variant's compiled
:func:`~rbstab.variants.kernels.state_rate`, called at scipy's stage times t + c h; time
enters through the disturbances only. A step that ends at a breakpoint of the
disturbances evaluates no stage later than ``t_lim``, the float below it
(:mod:`rbstab.variants.disturbances`).

A method travels as its number, its index in :data:`METHODS`; its tableau is the rows of
that number in the module's tables (:data:`RK_A`, ...), built from
:mod:`rbstab.engine.tableaus`. Numba compiles global arrays in as constants, so a step
passes and reference-counts none of them: handed down every call as a tuple of arrays,
the tableau made numba reference-count each of its arrays in every step and stage, and
the integration took ~10 % longer (A/B, Case 3).

The helpers of a step (:func:`error_norm`, :func:`dense_value` ...) are ``forceinline``
and :func:`rk_step`, called from one place, ``inline="always"`` (:func:`rbstab.jit.jit`):
they end up in the driver (:mod:`rbstab.engine.integrate`), which then passes and
reference-counts no work array per call; the integration takes ~7 % less CPU (A/B in one
process, Case 3), the same bits. The right-hand side stays a call (inlined as well, it
gave nothing more: 0.592 against 0.597 ms a run).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import jit
from .systems import system_rate
from .tableaus import DOP853_EXTENDED, METHODS, TABLEAUS

__all__ = ["METHODS", "DOP853", "method_number", "rms_norm", "initial_step", "rk_step", "error_norm",
           "dense_coefficients", "dense_value"]

#: DOP853's number (its error estimate and dense output differ from the other two's).
DOP853 = METHODS.index("DOP853")


def method_number(method: str) -> int:
    """The compiled engine's number of ``method`` (``"RK23"``, ``"RK45"`` or ``"DOP853"``):
    its index in :data:`METHODS` (:mod:`rbstab.engine.tableaus`), the rows of its tableau
    in :mod:`rbstab.engine.rk`'s tables.

    Raises
    ------
    ValueError
        For a method not in :data:`METHODS`.
    """
    if method not in METHODS:
        raise ValueError(f"method: found {method!r}; the compiled engine has {', '.join(METHODS)}")
    return METHODS.index(method)


def _stacked(arrays, shape: tuple) -> np.ndarray:
    """The arrays, each zero-padded to ``shape``, stacked along a first axis (a method's row)."""
    out = np.zeros((len(arrays), *shape))
    for i, a in enumerate(arrays):
        out[(i, *(slice(0, n) for n in np.shape(a)))] = a
    return out


_T = [TABLEAUS[m] for m in METHODS]
#: Stages of a step (scipy's ``n_stages``) and the order of the error estimate, by method.
N_STAGES = np.array([t.n_stages for t in _T])
ERROR_ORDER = np.array([t.error_estimator_order for t in _T])
#: Rows of stage rates a step holds: the step's stages, the new state's rate (FSAL) and
#: DOP853's 3 dense-output stages.
STAGE_ROWS = np.array([max(t.n_stages + 1, DOP853_EXTENDED.N_STAGES_EXTENDED if m == "DOP853" else 0)
                       for m, t in zip(METHODS, _T)])
#: Rows of a step's interpolant coefficients: RK23/RK45 their P's columns, DOP853 7.
INTERPOLANT_ROWS = np.array([DOP853_EXTENDED.INTERPOLATOR_POWER if m == "DOP853" else t.P.shape[1]
                             for m, t in zip(METHODS, _T)])
#: A (DOP853's extended to its 16 stages), B, and RK23/RK45's E and P, by method, zero-padded.
RK_A = _stacked([DOP853_EXTENDED.A if m == "DOP853" else t.A for m, t in zip(METHODS, _T)],
                (max(STAGE_ROWS),) * 2)
RK_B = _stacked([t.B for t in _T], (max(N_STAGES),))
RK_E = _stacked([getattr(t, "E", np.zeros(0)) for t in _T], (max(N_STAGES) + 1,))
RK_C = _stacked([DOP853_EXTENDED.C if m == "DOP853" else t.C for m, t in zip(METHODS, _T)], (max(STAGE_ROWS),))
RK_P = _stacked([getattr(t, "P", np.zeros((0, 0))) for t in _T], (max(N_STAGES) + 1, max(INTERPOLANT_ROWS)))
#: DOP853's 3rd- and 5th-order error estimates and its dense output's D.
DOP853_E3, DOP853_E5, DOP853_D = TABLEAUS["DOP853"].E3, TABLEAUS["DOP853"].E5, TABLEAUS["DOP853"].D


@jit(_nrt=False)
def rms_norm(x, scale):
    """RMS norm of x / scale (scipy's ``norm``) over the entries of ``scale`` (the state's:
    an integrated work W after them is not part of any norm)."""
    n = scale.shape[0]
    total = 0.0
    for i in range(n):
        total += (x[i] / scale[i]) ** 2
    return math.sqrt(total) / math.sqrt(n)


@jit(_nrt=False)
def initial_step(code, p, s, t0, t_bound, t_lim, y0, f0, w):
    """scipy's ``select_initial_step`` from t0 towards t_bound (Hairer, Norsett & Wanner,
    II.4); its one right-hand-side call at min(t0 + h0, t_lim).

    ``s``: the run's settings (:data:`rbstab.engine.settings.SETTINGS`: ``max_step``,
    ``rtol``, ``atol``, ``method``); ``w``: its work arrays
    (:class:`rbstab.engine.settings.Work`: ``y_new``, ``work`` and ``scale`` are
    overwritten). The norms take the state's entries (``scale``'s), not a work W after them.
    """
    max_step, error_order, rtol, atol = s.max_step, ERROR_ORDER[s.method], s.rtol, s.atol
    t_bound = t_bound - t0
    y1, f1, scale = w.y_new, w.work, w.scale
    n = y0.shape[0]
    for i in range(scale.shape[0]):
        scale[i] = atol + abs(y0[i]) * rtol
    d0 = rms_norm(y0, scale)
    d1 = rms_norm(f0, scale)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t_bound)
    for i in range(n):
        y1[i] = y0[i] + h0 * f0[i]
    system_rate(code, min(t0 + h0, t_lim), y1, p, f1)
    for i in range(n):
        f1[i] = f1[i] - f0[i]
    d2 = rms_norm(f1, scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (error_order + 1))
    return min(100 * h0, h1, t_bound, max_step)


@jit(forceinline=True)
def _weighted_sum(w, K, s, out):
    """out = sum_{j<s} w[j] K[j], the weighted sum of the first s stage rates (rows of K).

    Taken a stage at a time over the whole state (the rows of K are contiguous): the
    elements' sums are then independent chains that the processor overlaps and LLVM
    vectorises, each in the order j = 0, 1, ... (the same bits as one element's sum at a
    time, which made the integration ~10 % slower).
    """
    n = out.shape[0]
    for i in range(n):
        out[i] = 0.0
    for j in range(s):
        c = w[j]
        for i in range(n):
            out[i] += K[j, i] * c


@jit(forceinline=True)
def _stage_state(y, h, a, K, s, out):
    """out = y + (sum_{j<s} a[j] K[j]) h."""
    _weighted_sum(a, K, s, out)
    for i in range(y.shape[0]):
        out[i] = y[i] + out[i] * h


@jit(inline="always")
def rk_step(code, p, t, t_lim, y, f, h, method, w):
    """One step from (t, y) (rate f) of size h: y_new and its rate in K[n_stages] (scipy's
    rk_step); no stage later than ``t_lim``.

    ``w``: the run's :class:`rbstab.engine.settings.Work` (``K`` (:data:`STAGE_ROWS`, n)
    stage rates, ``y_new``, ``work`` a state-sized array).
    """
    K, y_new, work = w.K, w.y_new, w.work
    n_stages = N_STAGES[method]
    for i in range(f.shape[0]):  # element by element: a slice store needs numba's runtime, absent on CUDA
        K[0, i] = f[i]
    for s in range(1, n_stages):
        _stage_state(y, h, RK_A[method, s], K, s, work)
        system_rate(code, min(t + RK_C[method, s] * h, t_lim), work, p, K[s])
    _stage_state(y, h, RK_B[method], K, n_stages, y_new)
    system_rate(code, min(t + h, t_lim), y_new, p, K[n_stages])


@jit(forceinline=True)
def error_norm(K, h, scale, method):
    """The scaled RMS norm of the local error estimate (scipy's ``_estimate_error_norm``),
    over the entries of ``scale`` (the state's; not a work W integrated after them)."""
    n_stages = N_STAGES[method]
    E, E3, E5 = RK_E[method], DOP853_E3, DOP853_E5
    n = scale.shape[0]
    if method != DOP853:
        total = 0.0
        for i in range(n):
            acc = 0.0
            for j in range(n_stages + 1):
                acc += K[j, i] * E[j]
            total += (acc * h / scale[i]) ** 2
        return math.sqrt(total) / math.sqrt(n)
    err5_2 = 0.0
    err3_2 = 0.0
    for i in range(n):
        e5 = 0.0
        e3 = 0.0
        for j in range(n_stages + 1):
            e5 += K[j, i] * E5[j]
            e3 += K[j, i] * E3[j]
        err5_2 += (e5 / scale[i]) ** 2
        err3_2 += (e3 / scale[i]) ** 2
    if err5_2 == 0.0 and err3_2 == 0.0:
        return 0.0
    denom = err5_2 + 0.01 * err3_2
    return abs(h) * err5_2 / math.sqrt(denom * n)


@jit(_nrt=False)
def dense_coefficients(code, p, t_old, t_lim, y_old, h, method, w):
    """The interpolant of the step from y_old to y_new into ``w.Q`` (rows of coefficients;
    ``w``: the run's :class:`rbstab.engine.settings.Work`, its stage rates ``w.K``).

    RK23/RK45: Q = (K' P)' (order rows); DOP853: its 3 extra stages (3 right-hand-side
    calls) and the 7 rows F of scipy's ``Dop853DenseOutput``.
    """
    K, Q, work, y_new = w.K, w.Q, w.work, w.y_new
    n_stages, D = N_STAGES[method], DOP853_D
    f_new = K[n_stages]
    n = y_old.shape[0]
    if method != DOP853:
        for r in range(INTERPOLANT_ROWS[method]):
            _weighted_sum(RK_P[method, :, r], K, n_stages + 1, Q[r])
        return 0
    for s in range(n_stages + 1, STAGE_ROWS[method]):
        _stage_state(y_old, h, RK_A[method, s], K, s, work)
        system_rate(code, min(t_old + RK_C[method, s] * h, t_lim), work, p, K[s])
    for i in range(n):
        delta = y_new[i] - y_old[i]
        Q[0, i] = delta
        Q[1, i] = h * K[0, i] - delta
        Q[2, i] = 2 * delta - h * (f_new[i] + K[0, i])
    for r in range(D.shape[0]):
        _weighted_sum(D[r], K, D.shape[1], Q[3 + r])
        for i in range(n):
            Q[3 + r, i] = h * Q[3 + r, i]
    return STAGE_ROWS[method] - n_stages - 1


@jit(forceinline=True)
def dense_value(x, h, y_old, Q, dop853, out):
    """The interpolant at x = (t - t_old) / h in [0, 1] into ``out``.

    RK23/RK45: y_old + h sum_r Q[r] x^(r+1); DOP853: scipy's nested product, from the
    last row, alternately times x and (1 - x).
    """
    n = y_old.shape[0]
    if dop853:
        x1 = 1.0 - x
        for i in range(n):
            acc = ((((((Q[6, i] * x + Q[5, i]) * x1 + Q[4, i]) * x + Q[3, i]) * x1 + Q[2, i]) * x + Q[1, i]) * x1
                   + Q[0, i]) * x
            out[i] = acc + y_old[i]
        return
    rows = Q.shape[0]
    for i in range(n):
        acc = 0.0
        power = 1.0
        for r in range(rows):
            power *= x
            acc += Q[r, i] * power
        out[i] = y_old[i] + h * acc
