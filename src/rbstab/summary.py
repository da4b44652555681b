"""Summary figures of one run, computed from its sampled outputs (one place for all paths).

The same code serves the scipy path (:mod:`rbstab.simulate`), the batched path (a block of
runs at once, :func:`summarize_many`) and the writers, so a summary means the same thing
everywhere.
"""

from __future__ import annotations

import numpy as np

from .layout import BLOCK_UNITS

__all__ = ["numerical_rate", "summarize", "summarize_many", "LYAPUNOV_RATE_TOLERANCE", "MIN_CHECK_SAMPLES"]

#: Relative tolerance of the check "analytic dv/dt agrees with the numerical derivative
#: of v": max |analytic - numerical| <= tol * max |analytic|.
LYAPUNOV_RATE_TOLERANCE = 1e-3

#: Fewest finite samples for which the rate check means something (a quintic spline).
MIN_CHECK_SAMPLES = 6


def numerical_rate(time: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Derivative of sampled ``values`` along ``time`` by a quintic interpolating spline.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Strictly increasing sample times [s], n >= 6 for the quintic (fewer: lower degree).
    values : ndarray, shape (n,)
        Samples taken from the solver's dense output (e.g. v [J]).

    Returns
    -------
    ndarray, shape (n,)
        d(values)/dt [units of values per s]; NaN where ``values`` is NaN (a failed run's
        tail).
    """
    from scipy.interpolate import make_interp_spline

    out = np.full_like(values, np.nan, dtype=float)
    ok = np.isfinite(values)
    n_ok = int(np.argmin(ok)) if not ok.all() else len(values)  # finite prefix
    if n_ok < 2:
        return out
    k = min(5, n_ok - 1)
    spline = make_interp_spline(time[:n_ok], values[:n_ok], k=k)
    out[:n_ok] = spline.derivative()(time[:n_ok])
    return out


def summarize(time: np.ndarray, outputs: dict[str, np.ndarray]) -> dict:
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
        ``lyapunov_rate_mismatch`` [W] (max |analytic - numerical dv/dt|),
        ``lyapunov_rate_mismatch_relative`` (divided by max |analytic dv/dt|),
        ``lyapunov_rate_check`` (``"pass"`` when the relative mismatch is at most
        :data:`LYAPUNOV_RATE_TOLERANCE`, ``"fail"`` when it is larger, ``"n/a"`` when
        fewer than :data:`MIN_CHECK_SAMPLES` finite samples exist, e.g. a run that failed
        at once).
    """
    return summarize_many(time, {k: v[None] for k, v in outputs.items()})[0]


def summarize_many(time: np.ndarray, outputs: dict[str, np.ndarray]) -> list[dict]:
    """:func:`summarize` of k runs sampled at the same times, at once.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    outputs : dict
        The runs' variables with a leading run axis: shape (k, n, 3) or (k, n).

    Returns
    -------
    list of k dicts
        The same figures (the same numbers) as :func:`summarize` of each run alone.
    """
    lyapunov = outputs["lyapunov"]
    k, n = lyapunov.shape
    finite = np.isfinite(lyapunov)
    # index of the last finite sample of each run (0 when there is none)
    last = np.where(finite.any(axis=1), n - 1 - np.argmax(finite[:, ::-1], axis=1), 0)
    whole = np.flatnonzero(last == n - 1)
    out: list = [None] * k
    if whole.size:
        part = outputs if whole.size == k else {key: value[whole] for key, value in outputs.items()}
        for j, summary in zip(whole, _summaries(time, part)):
            out[j] = summary
    for j in np.flatnonzero(last != n - 1):  # failed runs: their finite samples only
        i = int(last[j])
        out[j] = _summaries(time[: i + 1], {key: value[j : j + 1, : i + 1] for key, value in outputs.items()})[0]
    return out


def _summaries(time: np.ndarray, outputs: dict[str, np.ndarray]) -> list[dict]:
    """The figures of :func:`summarize` over all samples of k runs ((k, n, ...) arrays)."""
    v = outputs["lyapunov"]
    rate = outputs["lyapunov_rate"]
    n = v.shape[1]
    t_final = float(time[n - 1])
    finals = {b: outputs[b][:, n - 1].tolist() for b in BLOCK_UNITS if b in outputs}
    error = np.abs(outputs["constraint_error"])
    # per axis: a reduction over the samples of one strided column is many times faster
    # than numpy's reduction of (k, n, 3) over its middle axis
    max_error = np.stack([np.max(error[:, :, i], axis=1) for i in range(3)], axis=1).tolist()
    initial, final = v[:, 0].tolist(), v[:, n - 1].tolist()
    max_rate = np.max(rate, axis=1).tolist()
    increase = np.max(v - np.minimum.accumulate(v, axis=1), axis=1).tolist()
    if n >= MIN_CHECK_SAMPLES:
        mismatch = np.max(np.abs(rate - outputs["lyapunov_rate_numerical"]), axis=1).tolist()
        scales = np.max(np.abs(rate), axis=1).tolist()
    summaries = []
    for j in range(v.shape[0]):
        summary: dict = {"t_final": t_final}
        for b, values in finals.items():
            summary[f"final_{b}"] = values[j]
        summary["max_abs_constraint_error"] = max_error[j]
        summary["lyapunov_initial"] = initial[j]
        summary["lyapunov_final"] = final[j]
        summary["max_lyapunov_rate"] = max_rate[j]
        summary["max_lyapunov_increase"] = increase[j]
        if n < MIN_CHECK_SAMPLES:
            summary["lyapunov_rate_mismatch"] = float("nan")
            summary["lyapunov_rate_mismatch_relative"] = float("nan")
            summary["lyapunov_rate_check"] = "n/a"
        else:
            scale = scales[j] or 1.0
            summary["lyapunov_rate_mismatch"] = mismatch[j]
            summary["lyapunov_rate_mismatch_relative"] = mismatch[j] / scale
            summary["lyapunov_rate_check"] = "pass" if mismatch[j] <= LYAPUNOV_RATE_TOLERANCE * scale else "fail"
        summaries.append(summary)
    return summaries
