"""Summary figures of one run, computed from its sampled outputs (one place for all paths).

The same function serves the scipy path (:mod:`rbstab.simulate`), the batched path
(:mod:`rbstab.batch`) and the writers, so a summary means the same thing everywhere.
"""

from __future__ import annotations

import numpy as np

from .layout import BLOCK_UNITS

__all__ = ["numerical_rate", "summarize", "LYAPUNOV_RATE_TOLERANCE", "MIN_CHECK_SAMPLES"]

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


def _last_finite(a: np.ndarray) -> int:
    finite = np.all(np.isfinite(a.reshape(len(a), -1)), axis=1)
    idx = np.flatnonzero(finite)
    return int(idx[-1]) if idx.size else 0


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
    i = _last_finite(outputs["lyapunov"])
    v = outputs["lyapunov"][: i + 1]
    rate = outputs["lyapunov_rate"][: i + 1]
    num = outputs["lyapunov_rate_numerical"][: i + 1]
    summary: dict = {"t_final": float(time[i])}
    for b in (b for b in BLOCK_UNITS if b in outputs):
        summary[f"final_{b}"] = [float(c) for c in outputs[b][i]]
    summary["max_abs_constraint_error"] = [
        float(c) for c in np.max(np.abs(outputs["constraint_error"][: i + 1]), axis=0)
    ]
    summary["lyapunov_initial"] = float(v[0])
    summary["lyapunov_final"] = float(v[-1])
    summary["max_lyapunov_rate"] = float(np.max(rate))
    summary["max_lyapunov_increase"] = float(np.max(v - np.minimum.accumulate(v)))
    if len(v) < MIN_CHECK_SAMPLES:
        summary["lyapunov_rate_mismatch"] = float("nan")
        summary["lyapunov_rate_mismatch_relative"] = float("nan")
        summary["lyapunov_rate_check"] = "n/a"
        return summary
    mismatch = float(np.max(np.abs(rate - num)))
    scale = float(np.max(np.abs(rate))) or 1.0
    summary["lyapunov_rate_mismatch"] = mismatch
    summary["lyapunov_rate_mismatch_relative"] = mismatch / scale
    summary["lyapunov_rate_check"] = "pass" if mismatch <= LYAPUNOV_RATE_TOLERANCE * scale else "fail"
    return summary
