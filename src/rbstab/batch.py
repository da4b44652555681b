"""Vectorised explicit Runge-Kutta integration of many runs at once (the sweep fast path).

A parameter sweep integrates the same variant (same body, gains and simulation
settings) from many initial states. The variants' right-hand side ``variant.rhs(t, y)``
works on stacks ``y`` of shape ``(n_runs, n_state)``, so one numpy evaluation serves a
whole batch. :func:`integrate_batch` steps every run of a batch together, with a
**per-run** step size, error control and dense output, so that each run takes exactly
the steps it would take alone under :func:`scipy.integrate.solve_ivp`.

What is mirrored from scipy (``scipy.integrate._ivp.rk``, per run)
--------------------------------------------------------------------
- the tableaus themselves (``RK23``, ``RK45``, ``DOP853`` class attributes and
  ``dop853_coefficients``), copied in :mod:`rbstab.rk_tableaus` so that sweep workers
  never import ``scipy.integrate`` (a test checks them against scipy's, bit for bit);
- the initial step (``common.select_initial_step``), the tolerance validation
  (``rtol`` raised to ``100 eps`` with a warning), the RMS error norm of
  ``error / (atol + rtol * max(|y|, |y_new|))``, DOP853's combined 5th/3rd-order error
  estimate, ``SAFETY``, ``MIN_FACTOR``, ``MAX_FACTOR``, the error exponent
  ``-1 / (error_estimator_order + 1)``, the step-size clamps to ``max_step`` and to
  ``min_step = 10 * spacing(t)``, the no-growth-after-rejection rule, the clip of the
  last step to ``t_end``, and FSAL;
- the dense output: the RK23/RK45 polynomials ``K.T @ P`` and DOP853's 7-coefficient
  interpolant with its 3 extra stages, evaluated with scipy's operation order; a sample
  ``s`` is taken from the step ``(t_old, t_new]`` that contains it (``s = 0`` is ``y0``),
  as ``solve_ivp(..., dense_output=True).sol`` does.

A run of the batch therefore takes the same steps as
``solve_ivp(variant.rhs, (0, t_end), y0[i], method=..., rtol=..., atol=...,
dense_output=True)`` and its samples agree with that solution's ``.sol(t)`` to round-off
(about 1e-14 relative in the tests), not merely to the tolerance. The results are not
bit-identical to the solo solve: the stage sums are one ``einsum`` over the whole batch
(:func:`_lincomb`) instead of scipy's per-run products, which may sum in another order.
They are bit-identical to the same run integrated alone or in any other batch (every
operation acts on each run's rows alone). Caveat: DOP853's error estimate is a strongly cancelling
sum, so at loose tolerances a few ulps in the stages can move a step size by ~1e-7
relative or flip an accept/reject decision that sits on the threshold; the run then
follows a slightly different, equally valid step sequence and agrees with the solo
solve only to about the tolerance. Solo scipy has the same sensitivity: on paper Case 3
with rtol = 1e-6, perturbing y0 by one ulp moves its DOP853 result by 1e-10 to 2.5e-6
(RK45: 1e-14).

Differences from ``solve_ivp`` (all additions, none changes a successful trajectory)
-----------------------------------------------------------------------------------
- **gimbal lock**: after each accepted step, a run with ``|theta_2| >= pi/2 -
  gimbal_margin`` (``theta = y[..., 0:3]`` in every layout) is stopped; the crossing
  time is located by bisection on that step's dense interpolant (like a terminal
  ``solve_ivp`` event) and the run fails there (eq 5: ``B(theta)`` is singular);
- **non-finite states**: a non-finite ``y0`` or ``f(y0)`` fails the run at ``t = 0``; a
  trial step with NaN/inf is rejected exactly as scipy does (its error norm is NaN, the
  step shrinks by ``MIN_FACTOR``), and if that ends with the step-size failure the
  message says that the right-hand side was non-finite; an accepted state or derivative
  that is non-finite fails the run at once;
- DOP853's 3 extra dense-output stages are evaluated only for the steps that contain
  an output sample (or a gimbal-lock crossing), so ``nfev`` can be below scipy's
  ``dense_output=True`` count; the trajectory is unaffected. To save right-hand-side
  calls, their rows are appended to the next attempt's first three stage evaluations
  (so one call of ``fun`` can hold rows of two different steps, each with its own
  time).

Memory
------
One batch holds the samples, ``n_runs * n_samples * n_state`` float64 (plus about
``(n_k + 10) * n_runs * n_state`` working floats, ``n_k`` = 16 stages for DOP853). For large sweeps use
:func:`integrate_many`, which integrates chunks of ``chunk_size`` runs and yields one
:class:`BatchSolution` per chunk (see :func:`iter_chunks`), so the caller can write
each chunk out before the next is computed. Chunks of about a thousand runs amortise
numpy's per-call overhead (paper Case 3, DOP853, rtol 1e-6, 201 samples: chunks of 128,
256, 512, 1024, 2048 runs cost about 4.7, 3.0, 2.3, 1.9, 1.8 ms CPU per run, against
~300 ms for one solo ``solve_ivp``); beyond that the cost per run is flat.
"""

from __future__ import annotations

import mmap
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .rk_tableaus import (
    DOP853_EXTENDED,
    MAX_FACTOR,
    MIN_FACTOR,
    SAFETY,
    SUCCESS_MESSAGE,
    TABLEAUS,
    TOO_SMALL_STEP_MESSAGE,
)

__all__ = [
    "BatchSolution",
    "integrate_batch",
    "integrate_many",
    "iter_chunks",
    "SUPPORTED_METHODS",
    "SUCCESS_MESSAGE",
    "TOO_SMALL_STEP_MESSAGE",
]

#: Methods accepted by :func:`integrate_batch` (scipy's explicit Runge-Kutta pairs).
SUPPORTED_METHODS = ("RK23", "RK45", "DOP853")

#: Machine epsilon of float64 (scipy's ``common.EPS``).
EPS = float(np.finfo(float).eps)

#: Index of theta_2 in every state layout (theta is y[..., 0:3]).
_THETA_2 = 1


# ---------------------------------------------------------------------------------
# result
# ---------------------------------------------------------------------------------
@dataclass
class BatchSolution:
    """Result of :func:`integrate_batch` for ``n_runs`` runs.

    Attributes
    ----------
    t : ndarray, shape (n_samples,)
        Sample times ``np.linspace(0, t_end, n_samples)`` [s].
    y : ndarray, shape (n_runs, n_samples, n_state)
        States at the sample times (layout of the variant); NaN after a run's failure
        time ``t_final``.
    status : ndarray of int, shape (n_runs,)
        0: reached ``t_end``; -1: failed (see ``message``).
    message : list of str, length n_runs
        Per-run termination reason (scipy's messages for success and for a too-small
        step; a gimbal-lock or non-finite-state message otherwise).
    nfev : ndarray of int, shape (n_runs,)
        Right-hand-side evaluations attributable to each run (rows of the batched
        evaluations that belonged to it).
    t_final : ndarray, shape (n_runs,)
        Time reached [s]: ``t_end``, the gimbal-lock crossing time, or the time of the
        last accepted state of a failed run.
    y_final : ndarray, shape (n_runs, n_state)
        State at ``t_final`` (for a gimbal lock, the interpolated state at the crossing).
    n_steps, n_rejected : ndarray of int, shape (n_runs,)
        Accepted and rejected steps of each run.
    method : str
        The Runge-Kutta method used.
    """

    t: np.ndarray
    y: np.ndarray
    status: np.ndarray
    message: list[str]
    nfev: np.ndarray
    t_final: np.ndarray
    y_final: np.ndarray
    n_steps: np.ndarray
    n_rejected: np.ndarray
    method: str

    @property
    def success(self) -> np.ndarray:
        """Boolean mask of the runs that reached ``t_end``, shape (n_runs,)."""
        return self.status == 0

    @property
    def n_runs(self) -> int:
        return self.y.shape[0]


# ---------------------------------------------------------------------------------
# tableaus (scipy's numbers, from rbstab.rk_tableaus)
# ---------------------------------------------------------------------------------
class _Tableau:
    """The coefficients of one of scipy's explicit RK solvers, in the form used here."""

    def __init__(self, method: str) -> None:
        solver = TABLEAUS[method]
        self.method = method
        self.n_stages = solver.n_stages
        self.A = np.asarray(solver.A, dtype=float)
        self.B = np.asarray(solver.B, dtype=float)
        self.C = np.asarray(solver.C, dtype=float)
        self.error_estimator_order = solver.error_estimator_order
        self.error_exponent = -1 / (solver.error_estimator_order + 1)
        self.is_dop853 = method == "DOP853"
        # rows of A restricted to the previous stages, as scipy's rk_step uses them
        self.stage_rows = [self.A[s, :s].copy() for s in range(1, self.n_stages)]
        if self.is_dop853:
            self.E5 = np.asarray(solver.E5, dtype=float)
            self.E3 = np.asarray(solver.E3, dtype=float)
            self.E53 = np.stack([self.E5, self.E3])
            self.D = np.asarray(solver.D, dtype=float)
            self.n_k = DOP853_EXTENDED.N_STAGES_EXTENDED
            a_full = DOP853_EXTENDED.A
            self.extra = [
                (s, a_full[s, :s].copy(), float(DOP853_EXTENDED.C[s]))
                for s in range(self.n_stages + 1, self.n_k)
            ]
        else:
            self.E = np.asarray(solver.E, dtype=float)
            self.P = np.asarray(solver.P, dtype=float)
            self.n_k = self.n_stages + 1
            self.extra = []


def _tableau(method: str) -> _Tableau:
    if not isinstance(method, str) or method not in TABLEAUS:
        raise ValueError(
            f"unsupported method {method!r} for batch integration; supported: "
            f"{', '.join(SUPPORTED_METHODS)}"
        )
    return _Tableau(method)


# ---------------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------------
def _rhs_of(variant) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    rhs = getattr(variant, "rhs", None)
    if rhs is not None:
        return rhs
    if callable(variant):
        return variant
    raise TypeError("variant must have a .rhs(t, y) method or be a callable fun(t, y)")


def _validate_tol(rtol, atol, n: int) -> tuple[float, np.ndarray]:
    """scipy's ``common.validate_tol``: rtol >= 100 eps (with a warning), atol >= 0."""
    rtol = float(rtol)
    if rtol < 100 * EPS:
        warnings.warn(
            "At least one element of `rtol` is too small. "
            f"Setting `rtol = np.maximum(rtol, {100 * EPS})`.",
            stacklevel=3,
        )
        rtol = max(rtol, 100 * EPS)
    atol = np.asarray(atol, dtype=float)
    if atol.ndim > 0 and atol.shape != (n,):
        raise ValueError(f"`atol` must be a scalar or have shape ({n},), got {atol.shape}")
    if np.any(atol < 0):
        raise ValueError("`atol` must be positive.")
    return rtol, atol


def _lincomb(c: np.ndarray, K2: np.ndarray) -> np.ndarray:
    """``c @ K2`` for stage coefficients c (shape (s,) or (k, s)) and stages K2 (s, N).

    Uses einsum's own loops rather than BLAS: these products are long and thin
    (N = n_runs * n_state), which OpenBLAS splits over threads; on a busy machine the
    threads wait for cores and make the batch several times slower, while the
    single-threaded loop costs only a little more than an uncontended gemv.
    """
    if c.ndim == 1:
        return np.einsum("s,sn->n", c, K2)
    return np.einsum("ks,sn->kn", c, K2)


def _rms(x: np.ndarray) -> np.ndarray:
    """scipy's ``common.norm`` (RMS) of every row of x, shape (m, n) -> (m,)."""
    return np.sqrt(np.einsum("ij,ij->i", x, x)) / x.shape[1] ** 0.5


def _select_initial_step(fun, t0, y0, f0, t_bound, max_step, order, rtol, atol):
    """``scipy.integrate._ivp.common.select_initial_step``, vectorised over rows of y0.

    Returns the initial |h| of every run, shape (m,), and evaluates ``fun`` once.
    """
    interval_length = abs(t_bound - t0)
    scale = atol + np.abs(y0) * rtol
    d0 = _rms(y0 / scale)
    d1 = _rms(f0 / scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        h0 = np.where((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / d1)
    h0 = np.minimum(h0, interval_length)
    y1 = y0 + h0[:, None] * f0
    f1 = fun(t0 + h0[:, None], y1)
    d2 = _rms((f1 - f0) / scale) / h0
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = np.where(
            (d1 <= 1e-15) & (d2 <= 1e-15),
            np.maximum(1e-6, h0 * 1e-3),
            (0.01 / np.maximum(d1, d2)) ** (1 / (order + 1)),
        )
    return np.minimum(np.minimum(np.minimum(100 * h0, h1), interval_length), max_step)


def iter_chunks(n: int, chunk_size: int) -> Iterator[np.ndarray]:
    """Index arrays ``arange(start, stop)`` covering ``range(n)`` in chunks of ``chunk_size``.

    A chunk of ``c`` runs needs about ``8 * c * (n_samples + 20) * n_state`` bytes in
    :func:`integrate_batch`.
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
    for start in range(0, n, chunk_size):
        yield np.arange(start, min(start + chunk_size, n))


#: Samples per row evaluated together when a step's dense output is written: the
#: temporaries (SAMPLE_BLOCK x n_state x rows floats) stay in the CPU caches. 2 to 8 take
#: the same time on paper Case 3 (a 500-run batch at rtol 1e-6).
SAMPLE_BLOCK = 4


#: Sample buffers of at least this many bytes are mapped by :func:`_nan_buffer`.
_MAPPED_BUFFER_BYTES = 1 << 22


def _nan_buffer(shape: tuple[int, ...]) -> np.ndarray:
    """``np.full(shape, np.nan)``, for a batch's samples (120 MB for 500 runs of Case 3).

    Where the platform has ``MAP_POPULATE`` (Linux), a large buffer is an anonymous
    mapping whose pages the kernel supplies in one system call, instead of one page
    fault per 4 KiB on first touch or, with numpy's transparent-huge-page advice, a
    synchronous memory compaction: on the 2-core benchmark machine ``np.full`` of 120 MB
    took 0.02 to 0.45 s (0.12 s without the advice), this a steady 0.07 s. The mapping is
    released with the array.
    """
    n_bytes = int(np.prod(shape)) * 8
    populate = getattr(mmap, "MAP_POPULATE", 0)
    if n_bytes < _MAPPED_BUFFER_BYTES or not populate:
        return np.full(shape, np.nan)
    memory = mmap.mmap(-1, n_bytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | populate)
    out = np.frombuffer(memory, dtype=float).reshape(shape)
    out.fill(np.nan)
    return out


class _Dense:
    """Dense-output interpolants of one step for a subset of the runs.

    Mirrors ``RkDenseOutput`` (``Q = K.T @ P``) and ``Dop853DenseOutput`` (7 coefficients,
    3 extra stages) of scipy, vectorised over the rows of the subset. ``K`` (shape
    (n_k, md, n)) holds the step's stages; for DOP853 its rows 13-15 must hold the extra
    stages (see :class:`_DenseStep`).
    """

    def __init__(self, tab: _Tableau, K, t_old, h, y_old, y_new, f_old, f_new):
        self.t_old = t_old
        self.h = h
        self.y_old = y_old
        self.is_dop853 = tab.is_dop853
        n_k, md, n = K.shape
        K2 = K.reshape(n_k, md * n)
        if tab.is_dop853:
            hc = h[:, None]
            delta_y = y_new - y_old
            F = np.empty((DOP853_EXTENDED.INTERPOLATOR_POWER, md, n))
            F[0] = delta_y
            F[1] = hc * f_old - delta_y
            F[2] = 2 * delta_y - hc * (f_new + f_old)
            F[3:] = hc * _lincomb(tab.D, K2).reshape(-1, md, n)
            # scipy evaluates the coefficients in reverse order
            self.coef = F[::-1]
        else:
            self.coef = _lincomb(tab.P.T, K2).reshape(-1, md, n)  # (order+1, md, n)

    def __call__(self, rows: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        """States at normalised times ``x = (t - t_old) / h`` (shape (p,)) of subset
        ``rows`` (shape (p,); None: every row once, in order); returns shape (p, n)."""
        if rows is None:
            return self.evaluate(self.coef, self.y_old, self.h[:, None], x[:, None])
        # one gather, (J, p, n)
        return self.evaluate(np.take(self.coef, rows, axis=1), self.y_old[rows], self.h[rows, None], x[:, None])

    def evaluate(self, coef: np.ndarray, y_old: np.ndarray, h: np.ndarray, xc: np.ndarray) -> np.ndarray:
        """The interpolant with coefficients ``coef`` (J, ...) at ``xc``; ``y_old``, ``h``
        (the step of each row; unused by DOP853) and ``xc`` broadcast against
        ``coef[0]``: for p rows (J, p, n), (p, n), (p, 1), (p, 1) or (k, p, 1) (k times
        per row), or transposed (J, n, p), (n, p), (p,), (k, 1, p). Returns the shape of
        the broadcast. scipy's operations in scipy's order, elementwise."""
        if self.is_dop853:
            # scipy: y = 0; for each coefficient (reversed): y += F; y *= x or (1 - x)
            one_minus = 1 - xc
            y = coef[0] * xc
            for i in range(1, coef.shape[0]):
                y += coef[i]
                y *= xc if i % 2 == 0 else one_minus
            y += y_old
            return y
        # scipy: y = h * Q @ (x, x^2, ...) + y_old
        p = xc
        acc = coef[0] * p
        for j in range(1, coef.shape[0]):
            p = p * xc
            acc += coef[j] * p
        y = h * acc
        y += y_old
        return y


class _DenseStep:
    """The data of accepted steps (a subset of runs) whose samples are still to be written.

    For DOP853 the 3 extra stages of the interpolant are evaluated one at a time
    (:meth:`extra_input`, :meth:`extra_output`): the main loop appends their rows to the
    next attempt's first right-hand-side calls, which saves three separate calls per
    step; :meth:`complete` evaluates any that are left on their own.
    """

    def __init__(self, tab: _Tableau, K, gidx, t_old, h, y_old, y_new, f_old, f_new, lo, hi):
        self.tab = tab
        self.K = K  # (n_k, md, n), C-contiguous copy
        self.K2 = K.reshape(K.shape[0], -1)
        self.gidx, self.t_old, self.h = gidx, t_old, h
        self.y_old, self.y_new, self.f_old, self.f_new = y_old, y_new, f_old, f_new
        self.lo, self.hi = lo, hi
        self.n_done = 0

    @property
    def ready(self) -> bool:
        return self.n_done == len(self.tab.extra)

    def extra_input(self):
        """(t, y) at which the next extra stage is evaluated, shapes (md, 1), (md, n)."""
        s, a, c = self.tab.extra[self.n_done]
        dy = _lincomb(a, self.K2[:s]).reshape(self.y_old.shape)
        dy *= self.h[:, None]
        dy += self.y_old
        return (self.t_old + c * self.h)[:, None], dy

    def extra_output(self, f) -> None:
        self.K[self.tab.extra[self.n_done][0]] = f
        self.n_done += 1

    def complete(self, fun) -> None:
        while not self.ready:
            self.extra_output(fun(*self.extra_input()))

    def dense(self) -> _Dense:
        return _Dense(self.tab, self.K, self.t_old, self.h, self.y_old, self.y_new, self.f_old, self.f_new)

    def write_samples(self, dense: _Dense, samples: "_Samples") -> None:
        """Evaluate and store samples lo .. hi-1 of every row.

        The rows are sorted by their number of samples in this step (most first), so the
        rows that have a j-th sample are a prefix. The coefficients are gathered in that
        order and transposed once, to (J, n, rows): the interpolant is then evaluated
        :data:`SAMPLE_BLOCK` samples per row at a time on the prefix with the rows as the
        contiguous axis (:meth:`_Dense.evaluate`, the same operations as one at a time,
        ~2x faster than with the 15-long state axis innermost), and each block is stored
        with one scatter of whole sample rows; the few values beyond a row's last sample
        go to the buffer's spare row.
        """
        lo = self.lo
        counts = self.hi - lo
        n_max = int(counts.max())
        if n_max <= 0:
            return
        order = np.argsort(-counts, kind="stable")
        counts, lo = counts[order], lo[order]
        coef = np.ascontiguousarray(np.take(dense.coef, order, axis=1).transpose(0, 2, 1))  # (J, n, rows)
        y_old = np.ascontiguousarray(dense.y_old[order].T)  # (n, rows)
        h, t_old = dense.h[order], dense.t_old[order]
        first = self.gidx[order] * samples.n_samples + lo  # flat row of each row's sample lo
        ts = samples.ts
        last = len(ts) - 1
        for k0 in range(0, n_max, SAMPLE_BLOCK):
            p = int(np.count_nonzero(counts > k0))  # rows with a sample k0: a prefix
            k_end = min(k0 + SAMPLE_BLOCK, n_max)
            k = np.arange(k0, k_end)[:, None]
            x = (ts[np.minimum(lo[:p] + k, last)] - t_old[:p]) / h[:p]  # (block, p)
            y = dense.evaluate(coef[:, :, :p], y_old[:, :p], h[:p], x[:, None, :])  # (block, n, p)
            flat_rows = first[:p] + k
            if k_end > counts[p - 1]:  # some rows have fewer samples than the block
                flat_rows = np.where(k < counts[:p], flat_rows, samples.spare)
            samples.flat[flat_rows] = y.transpose(0, 2, 1)


class _Samples:
    """The sample buffer of a batch: ``y`` (n_runs, n_samples, n), NaN until written, a
    view of ``flat`` (n_runs * n_samples + 1, n) whose last row (``spare``) takes the
    values a block evaluates beyond a row's last sample in a step."""

    def __init__(self, ts: np.ndarray, n_runs: int, n: int) -> None:
        self.ts = ts
        self.n_samples = len(ts)
        self.spare = n_runs * self.n_samples
        self.flat = _nan_buffer((self.spare + 1, n))
        self.y = self.flat[: self.spare].reshape(n_runs, self.n_samples, n)


def _locate_crossing(dense: _Dense, rows: np.ndarray, sign: np.ndarray, limit: float) -> np.ndarray:
    """Normalised time x in (0, 1] where ``sign * theta_2`` first reaches ``limit`` on the
    dense interpolant of ``rows`` (bisection; ``g(0) < 0 <= g(1)``)."""
    lo = np.zeros(len(rows))
    hi = np.ones(len(rows))
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        g = sign * dense(rows, mid)[:, _THETA_2] - limit
        up = g >= 0
        hi = np.where(up, mid, hi)
        lo = np.where(up, lo, mid)
        # stop at the time resolution of solve_ivp's event location (4 eps)
        t_hi = dense.t_old[rows] + hi * dense.h[rows]
        if np.all((hi - lo) * np.abs(dense.h[rows]) <= 4 * EPS * np.maximum(np.abs(t_hi), 1.0)):
            break
    return hi


# ---------------------------------------------------------------------------------
# the integrator
# ---------------------------------------------------------------------------------
def integrate_batch(
    variant,
    y0,
    t_end: float,
    n_samples: int,
    *,
    method: str = "DOP853",
    rtol: float = 1e-8,
    atol=1e-10,
    max_step: float = np.inf,
    gimbal_margin: float | None = 1e-3,
) -> BatchSolution:
    """Integrate many runs of one variant at once, each with its own adaptive step.

    Every run gets scipy's algorithm for ``method`` (see the module docstring for what
    is mirrored); all runs share the numpy evaluations of the right-hand side, and a
    run that finishes or fails leaves the batch, so it costs nothing afterwards.

    Parameters
    ----------
    variant : Variant or callable
        Anything with ``rhs(t, y)`` (a :class:`~rbstab.variants.base.Variant`), or such a
        function itself. It is called with ``y`` of shape ``(m, n_state)`` (the active
        runs) and ``t`` an array of shape ``(m, 1)`` of per-run times [s] (the variants
        ignore ``t``), and must return shape ``(m, n_state)``.
    y0 : array_like, shape (n_runs, n_state) or (n_state,)
        Initial states, layout of the variant (``theta`` is ``y[..., 0:3]`` [rad]).
    t_end : float
        Final time [s], > 0; every run starts at ``t = 0``.
    n_samples : int
        Number of output samples ``np.linspace(0, t_end, n_samples)``, >= 1.
    method : {"DOP853", "RK45", "RK23"}
        scipy's explicit Runge-Kutta pair to mirror.
    rtol, atol : float (atol also array of shape (n_state,))
        Tolerances, as in ``solve_ivp``.
    max_step : float
        Largest step [s], as in ``solve_ivp``.
    gimbal_margin : float or None
        A run fails once ``|theta_2| >= pi/2 - gimbal_margin`` [rad] (eq 5); None
        disables the check.

    Returns
    -------
    BatchSolution
        Samples ``y`` of shape ``(n_runs, n_samples, n_state)`` (NaN after a failure)
        and per-run ``status``, ``message``, ``nfev``, ``t_final``, ``y_final``,
        ``n_steps``, ``n_rejected``. Failures are reported per run, never raised.

    Raises
    ------
    ValueError
        For an unsupported ``method`` (the message names the supported ones), a ``y0``
        of the wrong shape for the variant's layout, ``t_end <= 0``, ``n_samples < 1``,
        ``max_step <= 0``, a negative or misshaped ``atol``, or a ``gimbal_margin``
        outside ``[0, pi/2)``.
    TypeError
        If ``variant`` has no ``rhs`` and is not callable.

    Notes
    -----
    Memory: ``8 * n_runs * n_samples * n_state`` bytes for the samples plus about
    ``8 * (n_k + 10) * n_runs * n_state`` of working storage (``n_k`` stages: 4 for
    RK23, 7 for RK45, 16 for DOP853); chunk large sweeps with :func:`integrate_many`.
    """
    tab = _tableau(method)
    fun = _rhs_of(variant)

    y0 = np.array(y0, dtype=float)
    if y0.ndim == 1:
        y0 = y0[None, :]
    if y0.ndim != 2:
        raise ValueError(f"y0 must have shape (n_runs, n_state), got {y0.shape}")
    n_runs, n = y0.shape
    layout = getattr(variant, "layout", None)
    if layout is not None and n != layout.size:
        raise ValueError(
            f"y0 has {n} states per run but the {getattr(variant, 'name', 'variant')} layout "
            f"{layout.blocks} has {layout.size}"
        )
    t_end = float(t_end)
    if not (np.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be a finite time > 0 [s], got {t_end}")
    n_samples = int(n_samples)
    if n_samples < 1:
        raise ValueError(f"n_samples must be >= 1, got {n_samples}")
    if not max_step > 0:
        raise ValueError("`max_step` must be positive.")
    rtol, atol = _validate_tol(rtol, atol, n)
    if gimbal_margin is None:
        limit = np.inf
    else:
        if n <= _THETA_2:
            raise ValueError(f"the gimbal-lock check needs theta = y[..., 0:3]; y0 has {n} states "
                             "(pass gimbal_margin=None)")
        gimbal_margin = float(gimbal_margin)
        if not 0 <= gimbal_margin < np.pi / 2:
            raise ValueError(f"gimbal_margin must be in [0, pi/2) rad, got {gimbal_margin}")
        limit = np.pi / 2 - gimbal_margin

    ts = np.linspace(0.0, t_end, n_samples)
    samples = _Samples(ts, n_runs, n)
    out_y = samples.y
    out_y[:, 0] = y0
    status = np.zeros(n_runs, dtype=int)
    message = [""] * n_runs
    nfev = np.zeros(n_runs, dtype=int)
    n_steps = np.zeros(n_runs, dtype=int)
    n_rejected = np.zeros(n_runs, dtype=int)
    t_final = np.zeros(n_runs)
    y_final = y0.copy()
    sol = BatchSolution(ts, out_y, status, message, nfev, t_final, y_final, n_steps, n_rejected, method)
    if n_runs == 0:
        return sol

    def lock_message(t):
        return (
            f"gimbal lock: |theta_2| reached pi/2 - {gimbal_margin:g} rad at t = {t:.6g} s; "
            "B(theta) is singular (eq 5)"
        )

    # -- start: f(y0), checks at t = 0, initial step (scipy's __init__) -------------------
    with np.errstate(all="ignore"):
        f0 = np.asarray(fun(np.zeros((n_runs, 1)), y0), dtype=float)
    nfev += 1
    finite0 = np.isfinite(y0).all(axis=1) & np.isfinite(f0).all(axis=1)
    check_lock = limit < np.inf
    locked0 = finite0 & (np.abs(y0[:, _THETA_2]) >= limit) if check_lock else np.zeros(n_runs, bool)
    for i in np.flatnonzero(~finite0):
        status[i] = -1
        message[i] = "non-finite state: y0 or the right-hand side at y0 is NaN/inf at t = 0 s"
    for i in np.flatnonzero(locked0):
        status[i] = -1
        message[i] = lock_message(0.0)
    idx = np.flatnonzero(finite0 & ~locked0)  # global indices of the active runs
    if idx.size == 0:
        return sol
    y = y0[idx]
    f = f0[idx]
    with np.errstate(all="ignore"):
        h_abs = _select_initial_step(fun, 0.0, y, f, t_end, max_step, tab.error_estimator_order, rtol, atol)
    nfev[idx] += 1
    m = idx.size
    t = np.zeros(m)
    rejected = np.zeros(m, dtype=bool)  # inside a rejection sequence (scipy's step_rejected)
    nonfinite = np.zeros(m, dtype=bool)  # that sequence met NaN/inf trial values
    next_sample = np.ones(m, dtype=np.intp)  # first sample index not yet written
    K = np.empty((tab.n_k, m, n))
    pending: _DenseStep | None = None  # DOP853 step whose extra dense stages are pending

    n_stages = tab.n_stages
    expo = tab.error_exponent
    sqrt_n = n**0.5

    while m:
        # -- step-size clamps at the start of scipy's _step_impl --------------------------
        min_step = 10 * np.abs(np.nextafter(t, np.inf) - t)
        fresh = ~rejected
        h_abs = np.where(
            fresh & (h_abs > max_step),
            max_step,
            np.where(fresh & (h_abs < min_step), min_step, h_abs),
        )
        too_small = h_abs < min_step
        if too_small.any():
            for k in np.flatnonzero(too_small):
                i = idx[k]
                status[i] = -1
                t_final[i] = t[k]
                y_final[i] = y[k]
                if nonfinite[k]:
                    message[i] = (
                        f"non-finite state: the right-hand side gave NaN/inf near t = {t[k]:.6g} s "
                        f"and the step could not be reduced further ({TOO_SMALL_STEP_MESSAGE})"
                    )
                else:
                    message[i] = f"{TOO_SMALL_STEP_MESSAGE} (t = {t[k]:.6g} s)"
            keep = ~too_small
            idx, t, y, f, h_abs = idx[keep], t[keep], y[keep], f[keep], h_abs[keep]
            rejected, nonfinite, next_sample = rejected[keep], nonfinite[keep], next_sample[keep]
            m = idx.size
            K = np.empty((tab.n_k, m, n))
            if not m:
                break

        t_new = t + h_abs
        t_new = np.where(t_new > t_end, t_end, t_new)
        h = t_new - t
        h_abs = np.abs(h)
        hc = h[:, None]

        # -- one Runge-Kutta attempt for every active run (scipy's rk_step) ---------------
        with np.errstate(all="ignore"):
            K2 = K.reshape(tab.n_k, m * n)  # stage s of run k: K2[s, k*n:(k+1)*n]
            K[0] = f
            for s, a in enumerate(tab.stage_rows, start=1):
                dy = _lincomb(a, K2[:s]).reshape(m, n)  # one pass for all runs
                dy *= hc
                dy += y
                t_s = (t + tab.C[s] * h)[:, None]
                if pending is not None and not pending.ready:
                    # the previous step's DOP853 dense stages ride along in this call
                    t_p, y_p = pending.extra_input()
                    out = fun(np.concatenate((t_s, t_p)), np.concatenate((dy, y_p)))
                    K[s] = out[:m]
                    pending.extra_output(out[m:])
                else:
                    K[s] = fun(t_s, dy)
            if pending is not None:
                pending.complete(fun)
                pending.write_samples(pending.dense(), samples)
                pending = None
            y_new = _lincomb(tab.B, K2[:n_stages]).reshape(m, n)
            y_new *= hc
            y_new += y
            f_new = np.asarray(fun(t_new[:, None], y_new), dtype=float)
            K[n_stages] = f_new
            nfev[idx] += n_stages

            # -- error norm and step-size factor ------------------------------------------
            scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
            if tab.is_dop853:
                err53 = _lincomb(tab.E53, K2[: n_stages + 1]).reshape(2, m, n)
                err53 /= scale
                e5 = np.sqrt(np.einsum("ij,ij->i", err53[0], err53[0])) ** 2
                e3 = np.sqrt(np.einsum("ij,ij->i", err53[1], err53[1])) ** 2
                denom = e5 + 0.01 * e3
                error_norm = np.where(
                    (e5 == 0) & (e3 == 0), 0.0, h_abs * e5 / np.sqrt(denom * n)
                )
            else:
                err = _lincomb(tab.E, K2[: n_stages + 1]).reshape(m, n)
                err *= hc
                err /= scale
                error_norm = np.sqrt(np.einsum("ij,ij->i", err, err)) / sqrt_n
            growth = SAFETY * error_norm**expo
            accepted = error_norm < 1
            factor_ok = np.where(error_norm == 0, MAX_FACTOR, np.minimum(MAX_FACTOR, growth))
            factor_ok = np.where(rejected, np.minimum(1, factor_ok), factor_ok)
            # fmax = Python's max(MIN_FACTOR, nan) == MIN_FACTOR, as in scipy
            factor_bad = np.fmax(MIN_FACTOR, growth)
        h_abs = h_abs * np.where(accepted, factor_ok, factor_bad)

        # -- per-run outcome of the attempt -------------------------------------------------
        bad_trial = ~np.isfinite(error_norm)
        nonfinite = np.where(accepted, False, nonfinite | bad_trial)
        n_rejected[idx[~accepted]] += 1
        # NaN/inf anywhere in a row makes its sum non-finite (cheaper than isfinite().all())
        finite_new = np.isfinite(y_new.sum(axis=1) + f_new.sum(axis=1))
        accepted_bad = accepted & ~finite_new
        good = accepted & finite_new
        n_steps[idx[good]] += 1
        locked = good & (np.abs(y_new[:, _THETA_2]) >= limit) if check_lock else np.zeros(m, bool)

        # samples passed by this step: indices next_sample .. last_sample-1
        last_sample = np.where(good, np.searchsorted(ts, t_new, side="right"), next_sample)
        need_dense = (last_sample > next_sample) | locked
        t_stop = t_new
        y_stop = y_new
        if need_dense.any():
            d = np.flatnonzero(need_dense)
            nfev[idx[d]] += len(tab.extra)
            step = _DenseStep(tab, np.take(K, d, axis=1), idx[d], t[d], h[d], y[d], y_new[d],
                              f[d], f_new[d], next_sample[d], last_sample[d])
            lock_rows = np.flatnonzero(locked[d])
            if lock_rows.size:
                # rare: complete this step's interpolant now, locate the crossing, write all
                with np.errstate(all="ignore"):
                    step.complete(fun)
                dense = step.dense()
                k_lock = d[lock_rows]
                x_lock = _locate_crossing(dense, lock_rows, np.sign(y_new[k_lock, _THETA_2]), limit)
                t_lock = t[k_lock] + x_lock * h[k_lock]
                t_stop = t_new.copy()
                t_stop[k_lock] = t_lock
                y_stop = y_new.copy()
                y_stop[k_lock] = dense(lock_rows, x_lock)
                last_sample[k_lock] = np.searchsorted(ts, t_lock, side="right")
                step.hi = last_sample[d]
                step.write_samples(dense, samples)
            elif tab.extra:
                pending = step  # finished by the next attempt (or after the loop)
            else:
                step.write_samples(step.dense(), samples)
        next_sample = last_sample

        # -- advance accepted runs --------------------------------------------------------
        if good.all():
            t, y, f = t_new, y_new, f_new
        else:
            acc_c = good[:, None]
            t = np.where(good, t_new, t)
            y = np.where(acc_c, y_new, y)
            f = np.where(acc_c, f_new, f)
        rejected = ~accepted

        finished = good & ~locked & (t_new >= t_end)
        done = finished | locked | accepted_bad
        if done.any():
            for k in np.flatnonzero(done):
                i = idx[k]
                if finished[k]:
                    status[i] = 0
                    message[i] = SUCCESS_MESSAGE
                    t_final[i] = t_new[k]
                    y_final[i] = y_new[k]
                elif locked[k]:
                    status[i] = -1
                    message[i] = lock_message(t_stop[k])
                    t_final[i] = t_stop[k]
                    y_final[i] = y_stop[k]
                else:
                    status[i] = -1
                    message[i] = (
                        f"non-finite state: the accepted step to t = {t_new[k]:.6g} s gave NaN/inf"
                    )
                    t_final[i] = t[k]
                    y_final[i] = y[k]
            keep = ~done
            idx, t, y, f, h_abs = idx[keep], t[keep], y[keep], f[keep], h_abs[keep]
            rejected, nonfinite, next_sample = rejected[keep], nonfinite[keep], next_sample[keep]
            m = idx.size
            K = np.empty((tab.n_k, m, n))

    if pending is not None:
        with np.errstate(all="ignore"):
            pending.complete(fun)
        pending.write_samples(pending.dense(), samples)
    return sol


def integrate_many(
    variant,
    y0,
    t_end: float,
    n_samples: int,
    *,
    chunk_size: int = 1024,
    **kwargs,
) -> Iterator[tuple[np.ndarray, BatchSolution]]:
    """Integrate ``y0`` (shape (n_runs, n_state)) chunk by chunk with :func:`integrate_batch`.

    Yields ``(indices, solution)`` per chunk, ``indices`` the rows of ``y0`` (shape
    (c,)) and ``solution`` their :class:`BatchSolution`; only one chunk's samples
    (``8 * chunk_size * n_samples * n_state`` bytes) are alive at a time if the caller
    drops each solution after use. ``kwargs`` go to :func:`integrate_batch` (method,
    rtol, atol, max_step, gimbal_margin). The result of each run does not depend on
    the chunking (up to round-off).

    Raises
    ------
    ValueError
        At once (not at the first chunk) for a ``y0`` that is not 2-D, an unsupported
        method or ``chunk_size < 1``; the other checks of :func:`integrate_batch` run
        per chunk.
    """
    y0 = np.asarray(y0, dtype=float)
    if y0.ndim != 2:
        raise ValueError(f"y0 must have shape (n_runs, n_state), got {y0.shape}")
    _tableau(kwargs.get("method", "DOP853"))
    chunks = iter_chunks(y0.shape[0], chunk_size)
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")

    def generate():
        for indices in chunks:
            yield indices, integrate_batch(variant, y0[indices], t_end, n_samples, **kwargs)

    return generate()
