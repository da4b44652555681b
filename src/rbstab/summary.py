"""Summary figures of one run, computed from its sampled outputs (one place for all paths).

The same code serves the scipy path (:mod:`rbstab.simulator`), the batched path (a block of
runs at once, :func:`summarize_many`) and the writers, so a summary means the same thing
everywhere. The figures' units and long names: :data:`rbstab.layout.SUMMARY_FIGURES`.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .convergence import lyapunov_reference, within_bound
from .results import row
from .jit import jit
from .layout import (LYAPUNOV_TERMS, OUTPUTS, POINT_FIXED, SATURATION_FLAGS, SETTLE_E, SETTLE_OMEGA, STATE_BLOCKS,
                     summary_stride)
from .model import pressure_point

__all__ = [
    "numerical_rate",
    "piecewise_numerical_rate",
    "stencil_weights",
    "summarize",
    "summarize_many",
    "summary_table",
    "tree_summary_table",
    "LYAPUNOV_RATE_TOLERANCE",
    "MIN_CHECK_SAMPLES",
    "RATE_STENCIL",
    "ACCUMULATOR_SIZE",
    "LAST_ABOVE",
    "V_INITIAL",
    "stream_start",
    "stream_sample",
    "stream_finish",
    "tree_stream_table",
    "streamed_final_lyapunov",
    "stream_member_start",
    "stream_member",
    "MEMBER_SLOTS",
    "short_stencils",
    "settling_times",
    "warm_up_balance",
    "balance_columns",
    "stream_settle",
    "stream_centre",
    "stream_tree_balance",
    "stream_body_balance",
    "largest_norm",
    "centre_of_mass",
    "total_weight",
    "ground_pressure",
    "grounded",
    "stream_pressure",
    "pressure_samples",
    "pressure_stride",
]

#: Relative tolerance of the check "analytic dv/dt agrees with the numerical derivative
#: of v": max |analytic - numerical| <= tol * P, where the reference power P is the larger
#: of max |analytic| and the run's energy scale over its duration (:func:`summarize`).
LYAPUNOV_RATE_TOLERANCE = 1e-3

#: Fewest finite samples for which the rate check means something.
MIN_CHECK_SAMPLES = 6

#: Samples per finite-difference stencil of :func:`numerical_rate` (6th order).
RATE_STENCIL = 7


def stencil_weights(time: np.ndarray, width: int = RATE_STENCIL) -> tuple[np.ndarray, np.ndarray]:
    """Finite-difference weights of d/dt at every sample (Fornberg's algorithm).

    Sample i uses the ``w = min(width, n)`` consecutive samples ``first[i] .. first[i] +
    w - 1`` nearest to it (centred inside, one-sided at the ends); the weights
    differentiate every polynomial of degree < w exactly, so the derivative is of order
    w - 1 in the sample spacing (6 for the default 7 points), on any strictly increasing
    grid.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Strictly increasing sample times [s], n >= 2.
    width : int
        Stencil points, >= 2.

    Returns
    -------
    first : ndarray of int, shape (n,)
    weights : ndarray, shape (n, w)
        d/dt at sample i is ``sum_j weights[i, j] * values[first[i] + j]`` [1/s].

    References
    ----------
    B. Fornberg, "Generation of finite difference formulas on arbitrarily spaced grids",
    Math. Comp. 51 (1988) 699-706.
    """
    time = np.asarray(time, dtype=float)
    n = len(time)
    w = min(int(width), n)
    if w < 2:
        raise ValueError(f"a derivative needs at least 2 samples, got {n}")
    first = np.clip(np.arange(n) - w // 2, 0, n - w)
    # node offsets from each sample, in units of the mean spacing (numbers of order 1)
    h = (time[-1] - time[0]) / (n - 1)
    x = (time[first[:, None] + np.arange(w)] - time[:, None]) / h
    # Fornberg's recursion for derivative orders 0 and 1, vectorised over the n samples
    c0 = np.zeros((w, n))
    c1 = np.zeros((w, n))
    c0[0] = 1.0
    p1 = np.ones(n)
    x_prev = x[:, 0]
    for i in range(1, w):
        p2 = np.ones(n)
        x_i = x[:, i]
        for j in range(i):
            d = x_i - x[:, j]
            p2 = p2 * d
            if j == i - 1:
                c1[i] = p1 * (c0[i - 1] - x_prev * c1[i - 1]) / p2
                c0[i] = -p1 * x_prev * c0[i - 1] / p2
            c1[j] = (x_i * c1[j] - c0[j]) / d
            c0[j] = x_i * c0[j] / d
        p1 = p2
        x_prev = x_i
    return first, c1.T / h


def _stencil_weights_of(time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`stencil_weights` of ``time``, computed once per grid (a sweep's runs share one)."""
    return _cached_weights(time.tobytes())


@functools.lru_cache(maxsize=16)
def _cached_weights(grid: bytes) -> tuple[np.ndarray, np.ndarray]:
    first, weights = stencil_weights(np.frombuffer(grid, dtype=float))
    first.setflags(write=False)
    weights.setflags(write=False)
    return first, weights


def numerical_rate(time: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Derivative of sampled ``values`` along ``time`` by finite differences.

    Each sample's derivative comes from the :data:`RATE_STENCIL` (7) samples nearest to
    it (:func:`stencil_weights`: exact for polynomials of degree <= 6, so of 6th order in
    the spacing; one-sided at the ends). It is independent of the model: it sees only the
    samples, so it checks the analytic ``lyapunov_rate`` (eq 25).

    Parameters
    ----------
    time : ndarray, shape (n,)
        Strictly increasing sample times [s].
    values : ndarray, shape (n,) or (m, n)
        Samples taken from the solver's dense output (e.g. v [J]), one run per row.

    Returns
    -------
    ndarray, the shape of ``values``
        d(values)/dt [units of values per s]; NaN where ``values`` is NaN (a failed run's
        tail: each row uses its finite prefix) and for a row of fewer than 2 finite
        samples. Every row gets the same bits as it would alone.
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    rows = values.reshape(-1, values.shape[-1]) if values.ndim else values.reshape(1, 1)
    out = np.full(rows.shape, np.nan)
    n = rows.shape[1]
    finite = np.isfinite(rows)
    n_ok = np.where(finite.all(axis=1), n, np.argmin(finite, axis=1))  # finite prefix
    # sorted(set()), not np.unique: that imports numpy.ma (~50 ms) into a sweep worker
    for length in sorted(set(n_ok.tolist())):
        if length < 2:
            continue
        which = np.flatnonzero(n_ok == length)
        part = np.ascontiguousarray(rows[which, :length])  # one C-contiguous layout for the kernel
        first, weights = _stencil_weights_of(time[:length])
        acc = np.empty_like(part)
        _apply_stencil(part, first, weights, acc)
        out[which, :length] = acc
    return out.reshape(values.shape)


@jit(nogil=True)  # no Python object inside: threads run it in parallel
def _apply_stencil(part, first, weights, out):
    """out[r, i] = sum_j weights[i, j] part[r, first[i] + j] for the rows r of ``part``
    (m, n), the terms added in the order j = 0, 1, ... (compiled: ~1.4x as fast as
    numpy's term-at-a-time sum, the same bits)."""
    for r in range(part.shape[0]):
        for i in range(part.shape[1]):
            acc = weights[i, 0] * part[r, first[i]]
            for j in range(1, weights.shape[1]):
                acc += weights[i, j] * part[r, first[i] + j]
            out[r, i] = acc


def piecewise_numerical_rate(time: np.ndarray, values: np.ndarray, breaks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`numerical_rate` of ``values`` on each smooth piece between ``breaks`` alone.

    Where a run's right-hand side switches (the pure sign law of ``sliding``), v is smooth
    only between switchings; a stencil across one compares unlike things. Each sample's
    stencil here takes only samples of its own piece (one-sided at the piece's ends).

    Parameters
    ----------
    time : ndarray, shape (n,)
        Strictly increasing sample times [s].
    values : ndarray, shape (n,)
        Samples (e.g. v [J]); NaN after a failure.
    breaks : ndarray, shape (k,)
        Times where the right-hand side switches [s]; a sample at a break belongs to the
        piece before it.

    Returns
    -------
    rate : ndarray, shape (n,)
        d(values)/dt per piece; on a piece of one sample, the plain :func:`numerical_rate`.
    checked : ndarray of bool, shape (n,)
        Samples whose stencil has all :data:`RATE_STENCIL` points on their piece (and finite):
        the ones whose rate has the stencil's full order, those a rate check should compare.
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    rate = numerical_rate(time, values)
    checked = np.zeros(len(time), dtype=bool)
    piece = np.searchsorted(np.sort(np.asarray(breaks, dtype=float)), time, side="left")
    edges = np.flatnonzero(np.diff(piece)) + 1
    for lo, hi in zip(np.r_[0, edges], np.r_[edges, len(time)]):
        if hi - lo >= 2:
            rate[lo:hi] = numerical_rate(time[lo:hi], values[lo:hi])
        checked[lo:hi] = hi - lo >= RATE_STENCIL
    return rate, checked & np.isfinite(rate)


def summarize(time: np.ndarray, outputs: dict[str, np.ndarray], checked: np.ndarray | None = None,
              params: np.ndarray | None = None) -> dict:
    """Summary figures of a run.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    outputs : dict
        The run's variables (see :meth:`rbstab.variants.Variant.evaluate`) plus
        ``lyapunov_rate_numerical``; NaN rows after a failure.

    Returns
    -------
    dict
        Plain floats and lists: ``t_final`` [s] (time of the last finite sample), ``final_<block>`` (3 floats each, for every state block
        in ``outputs``, reconstructed ones included),
        ``max_abs_constraint_error`` [m] (3 floats, per axis), ``lyapunov_initial``,
        ``lyapunov_final`` [J], ``max_lyapunov_rate`` [W], ``max_lyapunov_increase`` [J]
        (largest rise of v above its running minimum: 0 for a non-increasing v),
        ``time_lyapunov_rising`` [s] (the samples with analytic dv/dt > 0 times the
        spacing: 0 where the paper's theorem holds; saturating actuators can make v rise),
        ``settling_time`` [s] (:func:`settling_times` with :data:`rbstab.layout.SETTLE_E`,
        :data:`rbstab.layout.SETTLE_OMEGA`: the first sample time after which every |E_j| and |Omega_i|
        stays within them; NaN when the last sample is not, or the run stopped early),
        ``com_excursion`` [m] (the largest distance of the whole-body centre of mass
        sum m_i X_i / sum m_i from its initial position) and ``peak_sway`` [m] (the largest
        horizontal distance of it from its initial position: the part perpendicular to
        gravity; NaN without gravity), both NaN without ``params``, ``cop_excursion`` [m]
        (the largest distance of the net centre of pressure of the point-fixed joints to the
        ground, ``outputs["net_centre_of_pressure"]``, from its initial position, at every
        :func:`rbstab.layout.summary_stride`-th sample: a thinned store's; NaN without it,
        and once the ground would have to pull at such a sample),
        ``fraction_saturated_torque_n``, ``_force_h``, ``_constraint_force`` (3 floats each,
        per axis: the fraction of the samples whose ``<control>_saturated`` flag is set, the
        control commanded at or beyond its limit; 0 without limits),
        ``lyapunov_rate_mismatch`` [W] (max |analytic - numerical dv/dt|),
        ``lyapunov_rate_mismatch_relative`` (divided by the reference power
        P = max(max |analytic dv/dt|, E / T): E [J] the energy scale, the largest sum over
        a sample of the magnitudes of v's terms, T [s] the duration of the samples),
        ``lyapunov_rate_check`` (over the samples whose stencil lies between two of the
        disturbances' edges, when ``outputs`` holds ``disturbance_edges``: across an impulse
        or a pulse's edge v or dv/dt jumps; ``"pass"`` when the relative mismatch is at most
        :data:`LYAPUNOV_RATE_TOLERANCE`, ``"fail"`` when it is larger, ``"n/a"`` when
        fewer than :data:`MIN_CHECK_SAMPLES` finite samples exist, e.g. a run that failed
        at once).
    checked : ndarray of bool, shape (n,), optional
        The samples the rate check compares (default: all), e.g. those whose numerical rate
        lies on one smooth piece (:func:`piecewise_numerical_rate`); given, the summary also
        holds ``lyapunov_rate_checked``, the fraction of the samples compared.
    params : ndarray, optional
        The run's :data:`rbstab.model.PARAMETERS` records, one a body (a record, or shape
        (bodies,)): the masses and weights of the centre of mass's figures.

    Notes
    -----
    The floor E / T of the reference power keeps a conservative run (zero gains: the
    analytic dv/dt is 0 up to rounding) from failing on the noise of the numerical
    derivative; a mismatch below tol E / T changes v by less than tol E over the whole
    run. See docs/physics.md for the measured noise.
    """
    return summarize_many(time, {k: v[None] for k, v in outputs.items()},
                          None if checked is None else np.asarray(checked, dtype=bool)[None],
                          None if params is None else np.asarray(params).reshape(1, -1))[0]


def summarize_many(time: np.ndarray, outputs: dict[str, np.ndarray], checked: np.ndarray | None = None,
                   params: np.ndarray | None = None) -> list[dict]:
    """:func:`summarize` of k runs sampled at the same times, at once.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    outputs : dict
        The runs' variables with a leading run axis: shape (k, n, 3) or (k, n).
    checked : ndarray of bool, shape (k, n), optional
        See :func:`summarize`.
    params : ndarray, shape (k,) or (k, bodies), optional
        Each run's records (:func:`summarize`).

    Returns
    -------
    list of k dicts
        The same figures (the same numbers) as :func:`summarize` of each run alone.
    """
    table = summary_table(time, outputs, checked, params)
    return [row(table, j) for j in range(outputs["lyapunov"].shape[0])]


def summary_table(time: np.ndarray, outputs: dict[str, np.ndarray], checked: np.ndarray | None = None,
                  params: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """:func:`summarize_many` as columns: figure -> its k values, shape (k,) or (k, 3) for
    a 3-vector figure (floats; ``lyapunov_rate_check`` an object array of str), the
    figures in :func:`summarize`'s order; the same numbers (:func:`rbstab.results.row` gives run j's, as :func:`summarize` does)."""
    lyapunov = outputs["lyapunov"]
    k, n = lyapunov.shape
    finite = np.isfinite(lyapunov)
    # index of the last finite sample of each run (0 when there is none)
    last = np.where(finite.any(axis=1), n - 1 - np.argmax(finite[:, ::-1], axis=1), 0)
    whole = np.flatnonzero(last == n - 1)
    if whole.size == k:
        return _table(time, outputs, checked, params)
    parts = []  # (runs, their table)
    if whole.size:
        parts.append((whole, _table(time, {key: value[whole] for key, value in outputs.items()},
                                    None if checked is None else checked[whole], None if params is None else params[whole])))
    for i in np.unique(last[last != n - 1]).tolist():  # failed runs: their finite samples only, by their number
        runs = np.flatnonzero(last == i)
        parts.append((runs, _table(time[: i + 1], {key: value[runs, : i + 1] for key, value in outputs.items()},
                                   None if checked is None else checked[runs, : i + 1],
                                   None if params is None else params[runs], complete=False, spacing=_spacing(time),
                                   grid=n)))
    table = {key: np.empty((k, *value.shape[1:]), dtype=value.dtype) for key, value in parts[0][1].items()}
    for runs, part in parts:
        for key, values in part.items():
            table[key][runs] = values
    return table


def _table(time: np.ndarray, outputs: dict[str, np.ndarray], checked: np.ndarray | None = None,
           params: np.ndarray | None = None, complete: bool = True,
           spacing: float | None = None, grid: int | None = None) -> dict[str, np.ndarray]:
    """The figures of :func:`summarize` over all samples of k runs ((k, n, ...) arrays), as
    columns; the rate check over the ``checked`` samples (k, n) only, when given; the
    centre of mass's figures with the bodies' records ``params`` (k, bodies) only, else
    NaN; ``complete`` False: the runs stopped before the end of their grid (no settling
    time), whose ``spacing`` [s] and ``grid`` (its sample count) are given (a run stopped
    before its second sample has one)."""
    v = outputs["lyapunov"]
    rate = outputs["lyapunov_rate"]
    k, n = v.shape
    table: dict[str, np.ndarray] = {"t_final": np.full(k, float(time[n - 1]))}
    for b in STATE_BLOCKS:
        if b in outputs:
            table[f"final_{b}"] = outputs[b][:, n - 1].copy()
    table["max_abs_constraint_error"] = _over_samples(np.max, np.abs(outputs["constraint_error"]))
    table["lyapunov_initial"] = v[:, 0].copy()
    table["lyapunov_final"] = v[:, n - 1].copy()
    table["max_lyapunov_rate"] = np.max(rate, axis=1)
    table["max_lyapunov_increase"] = np.max(v - np.minimum.accumulate(v, axis=1), axis=1)
    table["time_lyapunov_rising"] = np.sum(rate > 0.0, axis=1) * (_spacing(time) if spacing is None else spacing)
    acc = np.full((k, ACCUMULATOR_SIZE), np.nan)
    acc[:, TAKEN], acc[:, LAST_UNSETTLED] = n, n - 1
    if "omega" in outputs:
        _settle_rows(_per_sample(outputs["constraint_error"]), _per_sample(outputs["omega"]), SETTLE_E, SETTLE_OMEGA,
                     acc)
    if params is not None:
        _centre_rows(_per_sample(outputs["position"]), np.ascontiguousarray(params).reshape(k, -1), acc)
    if "net_centre_of_pressure" in outputs:
        _pressure_rows(np.ascontiguousarray(outputs["net_centre_of_pressure"], dtype=float),
                       summary_stride(n if grid is None else grid), acc)
    table.update(balance_columns(time, acc, complete))
    for flags, figure in SATURATION_FLAGS.values():
        if flags in outputs:
            table[figure] = _over_samples(np.sum, outputs[flags]) / n
    n_checked = np.full(k, n) if checked is None else np.sum(checked, axis=1)
    if checked is not None:
        table["lyapunov_rate_checked"] = n_checked / n
    largest = scales = np.full(k, np.nan)
    if n >= MIN_CHECK_SAMPLES:
        difference = np.abs(rate - outputs["lyapunov_rate_numerical"])
        if checked is not None:
            difference = np.where(checked, difference, 0.0)
        if "disturbance_edges" in outputs:
            difference = np.where(_within_one_piece(time, outputs["disturbance_edges"]), difference, 0.0)
        largest = np.max(difference, axis=1)
        scales = np.maximum(np.max(np.abs(rate), axis=1), _energy_scale(outputs) / (time[n - 1] - time[0]))
    table.update(_rate_check(largest, scales, n_checked >= MIN_CHECK_SAMPLES))
    return table


def _over_samples(reduce, values: np.ndarray) -> np.ndarray:
    """``reduce`` (np.max, np.sum) of k runs' ``values`` (k, n, ...) over their n samples:
    (k, ...), e.g. (k, 3) per axis, (k, n_joints, 3) per joint and axis. Reduced a strided
    column at a time, many times faster than numpy's reduction over the middle axis."""
    k, n = values.shape[:2]
    columns = values.reshape(k, n, -1)
    out = np.stack([reduce(columns[:, :, i], axis=1) for i in range(columns.shape[2])], axis=1)
    return out.reshape(k, *values.shape[2:])


def _within_one_piece(time: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Whether each sample's stencil (:func:`stencil_weights` of ``time``, as
    :func:`numerical_rate` takes it) lies between two of the disturbances' edges: the
    ``disturbance_edges`` (k, n) of its first and last samples are equal. Elsewhere v or
    dv/dt may jump inside the stencil (an impulse, a pulse's edge), and the numerical dv/dt
    there is not a derivative: the rate check does not compare it."""
    first, weights = _stencil_weights_of(np.ascontiguousarray(time, dtype=float))
    return edges[:, first] == edges[:, first + weights.shape[1] - 1]


def _spacing(time: np.ndarray) -> float:
    """The spacing of an even sample grid [s] (0 for one sample)."""
    return float(time[1] - time[0]) if len(time) > 1 else 0.0


def _rate_check(largest: np.ndarray, scales: np.ndarray, enough: np.ndarray) -> dict[str, np.ndarray]:
    """``lyapunov_rate_mismatch``, ``_relative`` and ``lyapunov_rate_check`` of k runs: the
    largest |analytic - numerical dv/dt| [W], the reference power [W] (0 is taken as 1) and
    whether the run has enough samples compared (else NaN, NaN and ``"n/a"``)."""
    scale = np.where(scales == 0.0, 1.0, scales)
    with np.errstate(invalid="ignore"):
        verdict = np.where(largest <= LYAPUNOV_RATE_TOLERANCE * scale, "pass", "fail").astype(object)
    verdict[~enough] = "n/a"
    return {"lyapunov_rate_mismatch": np.where(enough, largest, np.nan),
            "lyapunov_rate_mismatch_relative": np.where(enough, largest / scale, np.nan),
            "lyapunov_rate_check": verdict}


def _energy_scale(outputs: dict[str, np.ndarray]) -> np.ndarray:
    """E [J] of k runs, shape (k,): the largest over the samples of the summed magnitudes
    of v's terms (|v| when the outputs lack them), the size of what v's rounding and the
    solver's error act on."""
    terms = [np.abs(outputs[key]) for key in LYAPUNOV_TERMS if key in outputs]
    magnitude = sum(terms[1:], terms[0]) if terms else np.abs(outputs["lyapunov"])
    return np.max(magnitude, axis=1)


# -- the summary figures as a run goes (the CUDA engine: no run keeps its samples) -----------------
#: Slots of a streaming summary's accumulator (:func:`stream_sample`, :func:`stream_finish`,
#: :func:`tree_stream_table`): v(0), max dv/dt, running min of v, largest rise of v above
#: it, max |analytic - numerical dv/dt|, max |dv/dt|, the energy scale E, the samples
#: taken, the last sample not converged (:func:`rbstab.convergence.converged` with v(0), the
#: largest rise of v so far and its v; -1 for none), the samples with dv/dt > 0, the last
#: :data:`RATE_STENCIL` values of v, of dv/dt and of the disturbances' edges (rings), then the
#: balance figures' (:func:`stream_balance`): the last sample not settled (-1 for none), the
#: largest distance and horizontal distance of the centre of mass from its start, and that start (3),
#: the largest distance of the net centre of pressure from its start, and that start (3).
V_INITIAL, MAX_RATE, V_MIN, MAX_INCREASE, MAX_MISMATCH, MAX_ABS_RATE, ENERGY, TAKEN, LAST_ABOVE, RISING = range(10)
_FLAG_SLOTS = 3 * len(SATURATION_FLAGS)
V_RING = RISING + 1
RATE_RING = V_RING + RATE_STENCIL
EDGE_RING = RATE_RING + RATE_STENCIL
LAST_UNSETTLED = EDGE_RING + RATE_STENCIL
MAX_EXCURSION, MAX_SWAY, COM_START = LAST_UNSETTLED + 1, LAST_UNSETTLED + 2, LAST_UNSETTLED + 3
MAX_COP, COP_START = COM_START + 3, COM_START + 4
ACCUMULATOR_SIZE = COP_START + 3
_V_AT = OUTPUTS["lyapunov"].offset
_RATE_AT = OUTPUTS["lyapunov_rate"].offset
_EDGES_AT = OUTPUTS["disturbance_edges"].offset
#: The convergence rule's bound (:func:`rbstab.convergence.within_bound`), compiled.
_within_bound = jit(forceinline=True)(within_bound)
_reference = jit(forceinline=True)(lyapunov_reference)
_T0, _T1, _T2, _T3 = (OUTPUTS[name].offset for name in LYAPUNOV_TERMS)


@jit(forceinline=True)
def _max(a, b):
    """max(a, b) that keeps a NaN of either, as numpy's max does."""
    return b if (b > a or b != b) else a


@jit(forceinline=True)
def _min(a, b):
    """min(a, b) that keeps a NaN of either, as numpy's minimum does."""
    return b if (b < a or b != b) else a


@jit(forceinline=True)
def stream_start(acc):
    """Reset the accumulator ``acc`` (:data:`ACCUMULATOR_SIZE`) for a new run."""
    for i in range(acc.shape[0]):
        acc[i] = -math.inf
    acc[TAKEN] = 0.0
    acc[LAST_ABOVE] = -1.0
    acc[RISING] = 0.0
    acc[LAST_UNSETTLED] = -1.0


@jit(forceinline=True)
def _numerical_rate(acc, start, w):
    """sum_j w[j] v[start + j], v from the ring, the terms in the order j = 0, 1, ..."""
    total = w[0] * acc[V_RING + start % RATE_STENCIL]
    for j in range(1, w.shape[0]):
        total += w[j] * acc[V_RING + (start + j) % RATE_STENCIL]
    return total


@jit(forceinline=True)
def _compare(acc, i, numerical, start, w, rates, stride):
    """Take sample i's numerical dv/dt, from the stencil of the w samples from ``start``: into
    the mismatch (0 for a stencil across a disturbance's edge, as :func:`summary_table`
    counts it), and into ``rates`` where they keep sample i."""
    if acc[EDGE_RING + start % RATE_STENCIL] == acc[EDGE_RING + (start + w - 1) % RATE_STENCIL]:
        acc[MAX_MISMATCH] = _max(acc[MAX_MISMATCH], abs(acc[RATE_RING + i % RATE_STENCIL] - numerical))
    else:
        acc[MAX_MISMATCH] = _max(acc[MAX_MISMATCH], 0.0)
    if i % stride == 0 and i // stride < rates.shape[0]:
        rates[i // stride] = numerical


@jit(forceinline=True)
def stream_sample(acc, i, row, first, weights, ratio, rates, stride):
    """Take sample i (0, 1, ... in order) of a run into ``acc`` (:data:`ACCUMULATOR_SIZE`):
    ``row`` its outputs, shape (N_OUTPUTS,), at the offsets of :data:`rbstab.layout.OUTPUTS`
    (read: v [J] and its terms, eq 25; analytic dv/dt [W]; the disturbances' edges).

    ``first``, ``weights``: :func:`stencil_weights` of the run's whole sample grid [s],
    shapes (n,) and (n, w) [1/s], w <= :data:`RATE_STENCIL`; a sample's numerical dv/dt is
    taken when the last sample of its stencil arrives; ``rates`` (n_kept,) receive every
    ``stride``-th sample's (NaN until its stencil is complete; 0 entries: none kept). The
    figures are those of :func:`summary_table`, the same numbers for a run that fills its
    grid. ``ratio``: the convergence ratio of the last sample not converged (what a basin
    map's time to converge reads).
    """
    v = row[_V_AT]
    rate = row[_RATE_AT]
    if i == 0:
        acc[V_INITIAL] = v
        acc[V_MIN] = v
    acc[V_MIN] = _min(acc[V_MIN], v)
    acc[MAX_INCREASE] = _max(acc[MAX_INCREASE], v - acc[V_MIN])
    if rate > 0.0:
        acc[RISING] += 1.0
    if not _within_bound(_reference(acc[V_INITIAL], acc[MAX_INCREASE]), v, ratio):
        acc[LAST_ABOVE] = i
    acc[MAX_RATE] = _max(acc[MAX_RATE], rate)
    acc[MAX_ABS_RATE] = _max(acc[MAX_ABS_RATE], abs(rate))
    acc[ENERGY] = _max(acc[ENERGY], abs(row[_T0]) + abs(row[_T1]) + abs(row[_T2]) + abs(row[_T3]))
    acc[V_RING + i % RATE_STENCIL] = v
    acc[RATE_RING + i % RATE_STENCIL] = rate
    acc[EDGE_RING + i % RATE_STENCIL] = row[_EDGES_AT]
    acc[TAKEN] = i + 1
    if i % stride == 0 and i // stride < rates.shape[0]:
        rates[i // stride] = math.nan  # until its stencil is complete
    w = weights.shape[1]
    start = i - (w - 1)  # the samples whose stencil ends at i start there
    if start >= 0:
        for q in range(max(0, i - w + 1), i + 1):
            if first[q] == start:
                _compare(acc, q, _numerical_rate(acc, start, weights[q]), start, w, rates, stride)


#: Slots of a tree member's streamed figures (:func:`stream_member`, :func:`tree_stream_table`):
#: max |E_j| (3), then the samples with each axis of N_j, of H of its child body and of
#: Lambda_j flagged at its limit (3 each, in the order of SATURATION_FLAGS).
MEMBER_SLOTS = 3 + _FLAG_SLOTS


@jit(forceinline=True)
def stream_member_start(members):
    """Reset a run's member slots ``members`` (n, :data:`MEMBER_SLOTS`)."""
    for i in range(members.shape[0]):
        for a in range(3):
            members[i, a] = -math.inf
        for a in range(3, MEMBER_SLOTS):
            members[i, a] = 0.0


@jit(forceinline=True)
def stream_member(members, i, error, flags):
    """Take one sample of tree member i (joint i and its child body) into ``members`` (n,
    :data:`MEMBER_SLOTS`): ``error`` E_i (3,) [m], ``flags`` (3, 3) the saturation flags of
    N_i, H_i and Lambda_i (1.0 or 0.0 an axis)."""
    for a in range(3):
        members[i, a] = _max(members[i, a], abs(error[a]))
    for c in range(3):
        for a in range(3):
            members[i, 3 + 3 * c + a] += flags[c, a]


@jit(forceinline=True)
def stream_finish(acc, first, weights, short, rates, stride):
    """The numerical dv/dt of the last samples of a run that stopped before the end of its
    grid (n_taken < n), one-sided on its own samples as :func:`numerical_rate` takes a
    run's finite samples: with the whole grid's weights (the same up to rounding), or for a
    run of fewer samples than a stencil, from ``short`` (w, w, w): ``short[m, :m, :m]`` the
    weights of :func:`stencil_weights` of the grid's first m samples (the same numbers)."""
    n, w = weights.shape
    taken = int(acc[TAKEN])
    if taken >= n:
        return
    if taken < w:
        if taken < 2:
            acc[MAX_MISMATCH] = math.nan
            return
        for i in range(taken):
            _compare(acc, i, _numerical_rate(acc, 0, short[taken, i, :taken]), 0, taken, rates, stride)
        return
    start = taken - w
    for i in range(max(0, taken - w), taken):
        if first[i] + w - 1 > taken - 1:  # its stencil on the whole grid reaches past the run
            _compare(acc, i, _numerical_rate(acc, start, weights[i + n - taken]), start, w, rates, stride)


def short_stencils(time: np.ndarray) -> np.ndarray:
    """The weights :func:`stream_finish` takes for a run of m < w samples, shape (w, w, w):
    ``[m, :m, :m]`` those of :func:`stencil_weights` of ``time[:m]`` (m >= 2), w the
    stencil's width on the whole grid ``time``."""
    w = min(RATE_STENCIL, len(time))
    short = np.zeros((w, w, w))
    for m in range(2, w):
        short[m, :m, :m] = stencil_weights(time[:m])[1]
    return short


# -- the balance figures: settling time, centre-of-mass excursion and sway -------------------------------
# One definition for every engine: the CPU's tables (:func:`settling_times`, :func:`summary_table`)
# and the GPU's streams (:func:`stream_tree_balance`, :func:`stream_body_balance`) take each
# sample with the same compiled functions; :func:`balance_columns` makes the figures.
_ERROR_AT, _OMEGA_AT, _POSITION_AT = (OUTPUTS[name].offset for name in ("constraint_error", "omega", "position"))


@jit(forceinline=True)
def _norm3(x, y, z):
    """The Euclidean norm of (x, y, z), its terms summed in order."""
    return math.sqrt(x * x + y * y + z * z)


@jit(forceinline=True)
def largest_norm(values, start, stride, count):
    """The largest Euclidean norm of ``count`` 3-vectors of ``values`` (1-D), vector i at
    ``values[start + stride i:][:3]``: 0 for none, NaN where one is NaN."""
    largest = 0.0
    for i in range(count):
        at = start + stride * i
        largest = _max(largest, _norm3(values[at], values[at + 1], values[at + 2]))
    return largest


@jit(forceinline=True)
def centre_of_mass(values, start, stride, params):
    """The whole-body centre of mass (x, y, z) [m] of the bodies of ``params`` (n,
    :data:`rbstab.model.PARAMETERS` records: their masses [kg]), body i's X_i at
    ``values[start + stride i:][:3]``: sum m_i X_i / sum m_i; one body's X as it is."""
    n = params.shape[0]
    if n == 1:
        return values[start], values[start + 1], values[start + 2]
    x, y, z, total = 0.0, 0.0, 0.0, 0.0
    for i in range(n):
        m = params[i].mass
        at = start + stride * i
        x += m * values[at]
        y += m * values[at + 1]
        z += m * values[at + 2]
        total += m
    return x / total, y / total, z / total


@jit(forceinline=True)
def total_weight(params):
    """The summed weight m_i g (x, y, z) [N] of the bodies of ``params`` (n records): its
    direction is gravity's, the vertical of :func:`stream_centre`."""
    x, y, z = 0.0, 0.0, 0.0
    for i in range(params.shape[0]):
        w = params[i].weight
        x += w[0]
        y += w[1]
        z += w[2]
    return x, y, z


@jit(forceinline=True)
def grounded(codes, parents, params):
    """Whether a tree (joint codes, parents, records (n,)) has a point-fixed joint to the
    ground and gravity: a net centre of pressure (:func:`ground_pressure`)."""
    gx, gy, gz = total_weight(params)
    if gx == 0.0 and gy == 0.0 and gz == 0.0:
        return False
    for j in range(codes.shape[0]):
        if parents[j] < 0 and POINT_FIXED[codes[j]]:
            return True
    return False


@jit(forceinline=True)
def ground_pressure(forces, moments, ppoints, codes, parents, params):
    """The net centre of pressure (x, y, z) [m] of a tree's point-fixed joints to the ground
    (:func:`rbstab.model.pressure_point` of their wrenches summed, as one force plate under both feet
    reads them): ``forces`` (n, 3) each joint's Lambda_j [N] and ``moments`` (n, 3) the
    ground's moment M_j about its point C_j = ``ppoints[j]`` [N m] (inertial frame;
    :func:`rbstab.variants.tree.tree_reactions`), the whole wrench about the origin
    sum (M_j + C_j x Lambda_j); gravity's direction the bodies' weights' (``params``). NaN
    without such a joint, or where a term is NaN."""
    fx, fy, fz, mx, my, mz = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    grounded = False
    for j in range(codes.shape[0]):
        if parents[j] < 0 and POINT_FIXED[codes[j]]:
            grounded = True
            f, c = forces[j], ppoints[j]
            fx += f[0]
            fy += f[1]
            fz += f[2]
            mx += moments[j, 0] + c[1] * f[2] - c[2] * f[1]
            my += moments[j, 1] + c[2] * f[0] - c[0] * f[2]
            mz += moments[j, 2] + c[0] * f[1] - c[1] * f[0]
    if not grounded:
        return math.nan, math.nan, math.nan
    return pressure_point((fx, fy, fz), (mx, my, mz), total_weight(params))


#: :func:`rbstab.layout.summary_stride`, compiled: the samples the centre of pressure's figure reads.
pressure_stride = jit(forceinline=True)(summary_stride)


@jit(forceinline=True)
def stream_pressure(acc, i, px, py, pz):
    """Take sample i's net centre of pressure (px, py, pz) [m] (NaN: none) into ``acc``: the
    largest distance of it from its position at sample 0 (NaN once a sample's is NaN). The
    figure reads every :func:`pressure_stride`-th sample of the run's grid alone (a thinned
    store's samples): each is a solve of the tree's dynamics (its accelerations), and the
    dense samples of dv/dt's check would double a sweep's time."""
    if i == 0:
        acc[COP_START], acc[COP_START + 1], acc[COP_START + 2] = px, py, pz
    distance = _norm3(px - acc[COP_START], py - acc[COP_START + 1], pz - acc[COP_START + 2])
    acc[MAX_COP] = _max(acc[MAX_COP], distance)


@jit(forceinline=True)
def stream_settle(acc, i, largest_error, largest_omega, e_bound, omega_bound):
    """Take sample i into the settling time's slot of ``acc``: the last sample whose largest
    |E_j| [m] or largest |Omega_i| [rad/s] is above its bound (or NaN)."""
    if not (largest_error <= e_bound and largest_omega <= omega_bound):
        acc[LAST_UNSETTLED] = i


@jit(forceinline=True)
def stream_centre(acc, i, cx, cy, cz, gx, gy, gz):
    """Take sample i's whole-body centre of mass c (cx, cy, cz) [m] into ``acc``: the
    largest |c - c(0)| and the largest horizontal |c - c(0)|, its part perpendicular to
    (gx, gy, gz) (gravity's direction; NaN where it is zero: no horizontal)."""
    if i == 0:
        acc[COM_START], acc[COM_START + 1], acc[COM_START + 2] = cx, cy, cz
    dx, dy, dz = cx - acc[COM_START], cy - acc[COM_START + 1], cz - acc[COM_START + 2]
    acc[MAX_EXCURSION] = _max(acc[MAX_EXCURSION], _norm3(dx, dy, dz))
    g = _norm3(gx, gy, gz)
    sway = math.nan
    if g > 0.0:
        ux, uy, uz = gx / g, gy / g, gz / g
        along = dx * ux + dy * uy + dz * uz
        sway = _norm3(dx - along * ux, dy - along * uy, dz - along * uz)
    acc[MAX_SWAY] = _max(acc[MAX_SWAY], sway)


@jit(forceinline=True)
def stream_tree_balance(acc, i, y, errors, params):
    """Take sample i of a tree run into the balance slots of ``acc``: ``y`` its maximal
    state (12 a body: Theta, Omega, X, V), ``errors`` (n, 3) each joint's E_j [m],
    ``params`` (n,) its records; the settling time's bounds :data:`rbstab.layout.SETTLE_E`, :data:`rbstab.layout.SETTLE_OMEGA`."""
    n = params.shape[0]
    largest_error = 0.0
    for j in range(n):
        largest_error = _max(largest_error, _norm3(errors[j, 0], errors[j, 1], errors[j, 2]))
    stream_settle(acc, i, largest_error, largest_norm(y, 3, 12, n), SETTLE_E, SETTLE_OMEGA)
    cx, cy, cz = centre_of_mass(y, 6, 12, params)
    gx, gy, gz = total_weight(params)
    stream_centre(acc, i, cx, cy, cz, gx, gy, gz)


@jit(forceinline=True)
def stream_body_balance(acc, i, row, p):
    """:func:`stream_tree_balance` of sample i of one body's run: ``row`` its outputs
    (N_OUTPUTS,), ``p`` its record (its weight)."""
    stream_settle(acc, i, largest_norm(row, _ERROR_AT, 3, 1), largest_norm(row, _OMEGA_AT, 3, 1), SETTLE_E,
                  SETTLE_OMEGA)
    w = p.weight
    stream_centre(acc, i, row[_POSITION_AT], row[_POSITION_AT + 1], row[_POSITION_AT + 2], w[0], w[1], w[2])


@jit(nogil=True)
def _settle_rows(error, omega, e_bound, omega_bound, acc):
    """:func:`stream_settle` of every sample of k runs: ``error`` (k, n, 3 joints) [m],
    ``omega`` (k, n, 3 bodies) [rad/s] (C-contiguous), into ``acc`` (k, ACCUMULATOR_SIZE)."""
    n_error, n_omega = error.shape[2] // 3, omega.shape[2] // 3
    for r in range(error.shape[0]):
        acc[r, LAST_UNSETTLED] = -1.0
        for i in range(error.shape[1]):
            stream_settle(acc[r], i, largest_norm(error[r, i], 0, 3, n_error), largest_norm(omega[r, i], 0, 3, n_omega),
                          e_bound, omega_bound)


@jit(nogil=True)
def pressure_samples(forces, moments, ppoints, codes, parents, params, tree_of, out, joints):
    """:func:`ground_pressure` at every sample s: ``forces``, ``moments`` (n, 3, S) the
    joints' Lambda_j [N] and the ground's moments [N m] (inertial;
    :func:`rbstab.variants.tree.reaction_samples`), sample s of the tree ``tree_of[s]``
    (``ppoints`` (t, n, 3), ``params`` (t, n)); into ``out`` (S, 3) [m]; into ``joints``
    (S, n, 3) [m] each point-fixed joint to the ground's own centre of pressure
    (:func:`rbstab.model.pressure_point` of its wrench alone), NaN for the other joints."""
    for s in range(out.shape[0]):
        t = tree_of[s]
        out[s, 0], out[s, 1], out[s, 2] = ground_pressure(forces[:, :, s], moments[:, :, s], ppoints[t], codes,
                                                          parents, params[t])
        weight = total_weight(params[t])
        for j in range(codes.shape[0]):
            joints[s, j, 0], joints[s, j, 1], joints[s, j, 2] = math.nan, math.nan, math.nan
            if parents[j] < 0 and POINT_FIXED[codes[j]]:
                f, m, c = forces[j, :, s], moments[j, :, s], ppoints[t, j]
                joints[s, j, 0], joints[s, j, 1], joints[s, j, 2] = pressure_point(
                    (f[0], f[1], f[2]), (m[0] + c[1] * f[2] - c[2] * f[1], m[1] + c[2] * f[0] - c[0] * f[2],
                                         m[2] + c[0] * f[1] - c[1] * f[0]), weight)


@jit(nogil=True)
def _pressure_rows(pressure, stride, acc):
    """:func:`stream_pressure` of every ``stride``-th sample of k runs: ``pressure`` (k, m, 3)
    their net centres of pressure [m] (the others not read), into ``acc`` (k, ACCUMULATOR_SIZE)."""
    for r in range(pressure.shape[0]):
        acc[r, MAX_COP] = -math.inf
        for i in range(0, pressure.shape[1], stride):
            stream_pressure(acc[r], i, pressure[r, i, 0], pressure[r, i, 1], pressure[r, i, 2])


@jit(nogil=True)
def _centre_rows(position, params, acc):
    """:func:`stream_centre` of every sample of k runs: ``position`` (k, n, 3 bodies) [m]
    (C-contiguous), ``params`` (k, bodies) records, into ``acc`` (k, ACCUMULATOR_SIZE)."""
    for r in range(position.shape[0]):
        acc[r, MAX_EXCURSION] = -math.inf
        acc[r, MAX_SWAY] = -math.inf
        gx, gy, gz = total_weight(params[r])
        for i in range(position.shape[1]):
            cx, cy, cz = centre_of_mass(position[r, i], 0, 3, params[r])
            stream_centre(acc[r], i, cx, cy, cz, gx, gy, gz)


def warm_up_balance(params: np.ndarray) -> None:
    """Compile (or load from the cache) the balance figures' kernels of :func:`summary_table`
    on a tiny input (:func:`rbstab.engine.warm_up`), so that a run's wall time is its own:
    ``params`` (1,) :data:`rbstab.model.PARAMETERS` records."""
    acc = np.zeros((1, ACCUMULATOR_SIZE))
    _settle_rows(np.zeros((1, 2, 3)), np.zeros((1, 2, 3)), SETTLE_E, SETTLE_OMEGA, acc)
    _centre_rows(np.zeros((1, 2, 3)), np.ascontiguousarray(params).reshape(1, -1), acc)
    _pressure_rows(np.zeros((1, 2, 3)), 1, acc)


def _per_sample(values: np.ndarray) -> np.ndarray:
    """k runs' 3-vectors (k, n, 3) or (k, n, m, 3) as (k, n, 3 m), C-contiguous floats."""
    values = np.ascontiguousarray(values, dtype=float)
    return values.reshape(values.shape[0], values.shape[1], -1)


def _settled_at(time: np.ndarray, last: np.ndarray, complete: np.ndarray | bool) -> np.ndarray:
    """The settling time [s] of runs whose last sample not settled is ``last`` (-1: none):
    the next sample's time; NaN where that is the grid's last sample or the run is not
    ``complete`` (it stopped before the end of its grid ``time``)."""
    n = len(time)
    last = last.astype(np.int64)
    return np.where(np.asarray(complete) & (last < n - 1), time[np.clip(last + 1, 0, n - 1)], np.nan)


def settling_times(time: np.ndarray, error: np.ndarray, omega: np.ndarray, e_bound: float = SETTLE_E,
                   omega_bound: float = SETTLE_OMEGA) -> np.ndarray:
    """Settling time of k runs: the first sample time after which |E| and |Omega| stay
    within their bounds (the summary figure ``settling_time``).

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    error : ndarray, shape (k, n, 3), or (k, n, joints, 3) for chains
        Constraint error E [m] (every joint's must hold).
    omega : ndarray, shape (k, n, 3), or (k, n, bodies, 3) for chains
        Angular velocity Omega [rad/s] (every body's must hold).
    e_bound, omega_bound : float
        Bounds on the Euclidean norms |E| [m] and |Omega| [rad/s].

    Returns
    -------
    ndarray, shape (k,)
        The earliest ``time[i]`` such that every ``|E_j| <= e_bound`` and every
        ``|Omega_i| <= omega_bound`` at every sample from ``i`` to the end [s]; NaN when the
        last sample is outside the bounds or not finite (a failed run never settles).
        Resolution: the sample spacing.
    """
    k = error.shape[0]
    acc = np.empty((k, ACCUMULATOR_SIZE))
    _settle_rows(_per_sample(error), _per_sample(omega), float(e_bound), float(omega_bound), acc)
    return _settled_at(np.asarray(time, dtype=float), acc[:, LAST_UNSETTLED], True)


def balance_columns(time: np.ndarray, acc: np.ndarray, complete: np.ndarray | bool) -> dict[str, np.ndarray]:
    """The balance figures of k runs from their accumulators ``acc`` (k, ACCUMULATOR_SIZE)
    after every sample taken (:func:`stream_settle`, :func:`stream_centre`), ``time`` (n,)
    their grid [s], ``complete`` (k,) whether each reached its end: ``settling_time`` [s]
    (with :data:`rbstab.layout.SETTLE_E`, :data:`rbstab.layout.SETTLE_OMEGA`; NaN unless settled at the end of a
    complete run), ``com_excursion`` and ``peak_sway`` [m] (NaN for a run without a sample),
    ``cop_excursion`` [m] (NaN also where no sample's net centre of pressure was taken)."""
    taken = acc[:, TAKEN] > 0
    return {"settling_time": _settled_at(time, acc[:, LAST_UNSETTLED], np.asarray(complete) & taken),
            "com_excursion": np.where(taken, acc[:, MAX_EXCURSION], np.nan),
            "peak_sway": np.where(taken, acc[:, MAX_SWAY], np.nan),
            "cop_excursion": np.where(taken & (acc[:, MAX_COP] > -math.inf), acc[:, MAX_COP], np.nan)}


def tree_stream_table(time: np.ndarray, acc: np.ndarray, members: np.ndarray, last: np.ndarray, n_bodies: int,
                      d_at: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`tree_summary_table`'s columns from streamed accumulators (the CUDA tree kernel).

    Parameters
    ----------
    time : ndarray, shape (n,)
        The runs' sample grid [s].
    acc : ndarray, shape (k, ACCUMULATOR_SIZE)
        Each run's accumulator after :func:`stream_finish` (v, its terms, dv/dt and the
        disturbances' edges of the tree).
    members : ndarray, shape (k, n_bodies, MEMBER_SLOTS)
        Each run's member slots (:func:`stream_member`).
    last : ndarray, shape (k, 12 n_bodies + 3 e)
        Each run's maximal state at its last sample taken (NaN for a run with none).
    n_bodies : int
    d_at : ndarray of int, shape (n_bodies,)
        Where each embedded joint's D sits in the state (-1: none).
    """
    k = len(acc)
    taken = acc[:, TAKEN].astype(np.int64)
    last_index = np.maximum(taken - 1, 0)
    table: dict[str, np.ndarray] = {"t_final": time[last_index]}
    blocks = last[:, : 12 * n_bodies].reshape(k, n_bodies, 4, 3)
    for i, b in enumerate(STATE_BLOCKS[:4]):
        table[f"final_{b}"] = blocks[:, :, i].copy()
    if np.any(d_at >= 0):
        table["final_controller_state"] = np.full((k, n_bodies, 3), np.nan)
        for j in np.flatnonzero(d_at >= 0):
            table["final_controller_state"][:, j] = last[:, d_at[j]: d_at[j] + 3]
    none = taken == 0
    table["max_abs_constraint_error"] = np.where(none[:, None, None], np.nan, members[:, :, :3])
    table["lyapunov_initial"] = np.where(none, np.nan, acc[:, V_INITIAL])
    table["lyapunov_final"] = streamed_final_lyapunov(acc)
    table["max_lyapunov_rate"] = np.where(none, np.nan, acc[:, MAX_RATE])
    table["max_lyapunov_increase"] = np.where(none, np.nan, acc[:, MAX_INCREASE])
    table["time_lyapunov_rising"] = acc[:, RISING] * _spacing(time)
    table.update(balance_columns(time, acc, taken == len(time)))
    with np.errstate(all="ignore"):
        for c, (_, figure) in enumerate(SATURATION_FLAGS.values()):
            table[figure] = members[:, :, 3 + 3 * c: 6 + 3 * c] / taken[:, None, None]
    span = time[last_index] - time[0]
    with np.errstate(all="ignore"):
        scales = np.maximum(acc[:, MAX_ABS_RATE], acc[:, ENERGY] / span)
    largest = acc[:, MAX_MISMATCH]
    table.update(_rate_check(largest, scales, (taken >= MIN_CHECK_SAMPLES) & np.isfinite(largest)))
    return table


def streamed_final_lyapunov(acc: np.ndarray) -> np.ndarray:
    """v [J] at each run's last sample taken, from its accumulator's ring, shape (k,) of
    ``acc`` (k, ACCUMULATOR_SIZE) after :func:`stream_finish`; NaN for a run with none."""
    taken = acc[:, TAKEN].astype(np.int64)
    v = acc[np.arange(len(acc)), V_RING + np.maximum(taken - 1, 0) % RATE_STENCIL]
    return np.where(taken == 0, np.nan, v)


def tree_summary_table(time: np.ndarray, outputs: dict[str, np.ndarray], *, embedded: bool,
                       params: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """:func:`summary_table` of k runs of one tree sampled at the same times (the outputs of
    :func:`rbstab.variants.chain.evaluate` with a leading run axis, plus
    ``lyapunov_rate_numerical`` (k, m); NaN rows after a failure): its figures per body or
    joint and axis (:data:`rbstab.layout.SUMMARY_FIGURES`' ``member``; ``final_<block>`` (k,
    n_bodies, 3), ``final_controller_state`` (k, n_joints, 3) where the tree has an
    ``embedded`` joint, ``max_abs_constraint_error`` [m] (k, n_joints, 3): max |E_j,i| over
    the samples, for a permanent joint, which reduced coordinates hold by construction, the
    drift of its constraint (rounding); ``fraction_saturated_*`` (k, n_members, 3)). Run i's
    figures are those of its outputs alone; ``params`` (k, n_bodies) the runs' records (the
    centre of mass's figures, :func:`summarize`)."""
    table = summary_table(time, outputs, params=params)
    if not embedded:
        table.pop("final_controller_state", None)
    return table
