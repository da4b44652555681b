"""When a run counts as converged: one rule for run, show, sweeps, basin maps and robustness.

A run *converged* when it succeeded (reached t_end), v(0) and v(t_end) are finite and

    |v(t_end)| <= ratio v_ref + ROUND_OFF,   v_ref = max(|v(0)|, v(0) + max rise of v)

(:data:`RULE`, the text that files and reports quote) with v the variant's Lyapunov function [J], zero at the
equilibrium, and v_ref the energy the run had to lose (:func:`lyapunov_reference`): v(0) where v never
rose (the paper's theorem: dv/dt <= 0), else v(0) plus the largest rise of v above its running minimum
(``max_lyapunov_increase``: a push, a disturbance's work, a saturated actuator), so that a body pushed
from rest (v(0) = 0) converges once it has lost all but ``ratio`` of what the push gave it. The ratio
defaults to :data:`DEFAULT_LYAPUNOV_RATIO`, 0.1 %. The magnitudes, because v is negative away from the
equilibrium when the equilibrium is not its minimum (an inverted pendulum held up by too weak a K_r): a
run that falls to a lower potential ends with v < 0 and has not converged. :data:`ROUND_OFF` is the
round-off of v at the equilibrium, so that a run started there (v(0) zero up to round-off) converges. A
run with a non-finite v has not converged.

Used by ``rbstab run`` and ``show`` (:mod:`rbstab.diagnostics`), a sweep's index (``converged``
column, :mod:`rbstab.sweep.folder`), the basin map (:mod:`rbstab.analysis.basin`, from every sample:
the time to converge, :data:`SAMPLE_RULE`), the robustness of a sweep
(:mod:`rbstab.analysis.robustness`) and the compiled summary of a run on the GPU
(:mod:`rbstab.summary`), all through :func:`within_bound`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["DEFAULT_LYAPUNOV_RATIO", "ROUND_OFF", "RULE", "SAMPLE_RULE", "converged", "lyapunov_reference",
           "floats",
           "within_bound"]

#: Default ratio (a sweep's ``convergence.lyapunov_ratio``, ``rbstab analyze --ratio``).
DEFAULT_LYAPUNOV_RATIO = 1e-3
#: Added to the bound ratio |v(0)| [J]: the round-off of v at the equilibrium.
ROUND_OFF = 1e-12
#: The bound at one time, as text (v [J]).
SAMPLE_RULE = f"|v| <= ratio v_ref + {ROUND_OFF:g} J, v_ref = max(|v(0)|, v(0) + the largest rise of v so far)"
#: The rule of :func:`converged` as text, in the names of a sweep's index columns (a sweep's
#: ``sweep_summary.json`` states it).
RULE = (f"converged = status == 'success' and lyapunov_initial, lyapunov_final finite and "
        f"|lyapunov_final| <= lyapunov_ratio * max(|lyapunov_initial|, lyapunov_initial + max_lyapunov_increase) "
        f"+ {ROUND_OFF:g} J")


def within_bound(v0, v, ratio):
    """Whether ``v0`` and v [J] are finite and |v| <= ``ratio`` |v0| + :data:`ROUND_OFF`:
    the rule's bound, with ``v0`` the reference v_ref (:func:`lyapunov_reference`; v(0) for a
    run whose v never rose), on numbers or arrays element by element (:mod:`rbstab.summary`
    compiles it, for the CPU and the GPU)."""
    # x - x == 0: whether x is finite, for numbers and arrays, in Python and compiled
    return (v0 - v0 == 0) & (v - v == 0) & (abs(v) <= ratio * abs(v0) + ROUND_OFF)


def lyapunov_reference(lyapunov_initial, max_increase):
    """v_ref [J], the energy a run had to lose: max(|v(0)|, v(0) + ``max_increase``), with
    ``max_increase`` the largest rise of v above its running minimum [J]
    (``max_lyapunov_increase``, >= 0); |v(0)| where it is not finite (a file or index
    without it). On numbers or arrays element by element (:mod:`rbstab.summary` compiles it)."""
    rise = lyapunov_initial + max_increase
    # rise - rise == 0: finite (NaN or inf: no rise known)
    return max(abs(lyapunov_initial), rise) if rise - rise == 0 else abs(lyapunov_initial)


def _reference_array(v0: np.ndarray, increase: np.ndarray) -> np.ndarray:
    """:func:`lyapunov_reference` of arrays."""
    with np.errstate(invalid="ignore", over="ignore"):
        rise = v0 + increase
        return np.where(np.isfinite(rise), np.maximum(np.abs(v0), rise), np.abs(v0))


#: Types of one value (the fast path of :func:`converged`: a sweep's index asks once a run).
_SCALARS = frozenset({float, int, bool, str, type(None), np.float64, np.float32, np.int64})


def converged(success: Any, lyapunov_initial: Any, lyapunov_final: Any,
              ratio: float = DEFAULT_LYAPUNOV_RATIO, max_increase: Any = None) -> Any:
    """Whether runs converged (module docstring), element by element.

    Parameters
    ----------
    success : bool or array_like of bool
        The run reached t_end (status ``success``).
    lyapunov_initial, lyapunov_final : float or array_like
        v(0) and v(t_end) [J] (broadcast together with ``success``); numbers, or text of
        numbers (an index read from CSV); None or text that is not a number: not converged.
    ratio : float
        In (0, 1).
    max_increase : float or array_like, optional
        The largest rise of v above its running minimum [J] (``max_lyapunov_increase``):
        the reference is then :func:`lyapunov_reference`; None, NaN or text that is not a
        number: |v(0)| (a file or index without the figure).

    Returns
    -------
    bool or ndarray of bool
        A Python bool for scalars (as a sweep's index and JSON records take it), else an
        array of the broadcast shape.
    """
    if type(lyapunov_initial) in _SCALARS and type(lyapunov_final) in _SCALARS:
        try:
            v0, v1 = float(lyapunov_initial), float(lyapunov_final)
        except (TypeError, ValueError):
            return False
        try:
            rise = float(max_increase) if max_increase is not None else math.nan
        except (TypeError, ValueError):
            rise = math.nan
        return bool(success) and bool(within_bound(lyapunov_reference(v0, rise), v1, ratio))
    v0 = floats(lyapunov_initial)
    v1 = floats(lyapunov_final)
    if max_increase is None:
        reference = np.abs(v0)
    else:
        reference = _reference_array(v0, floats(max_increase))
    with np.errstate(invalid="ignore", over="ignore"):
        return np.asarray(success, dtype=bool) & within_bound(reference, v1, ratio)


def floats(values: Any) -> np.ndarray:
    """``values`` as floats, NaN where an entry is not a number (None, text)."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        out = []
        for x in np.ravel(np.asarray(values, dtype=object)):
            try:
                out.append(float(x))
            except (TypeError, ValueError):
                out.append(math.nan)
        return np.asarray(out, dtype=float).reshape(np.shape(values))
