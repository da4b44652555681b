"""When a run counts as converged: one rule for sweeps, basin maps and robustness.

A run *converged* when it succeeded (reached t_end), v(0) and v(t_end) are finite and

    |v(t_end)| <= ratio |v(0)| + ROUND_OFF

(:data:`RULE`, the text that files and reports quote) with v the variant's Lyapunov function [J], zero at the equilibrium: the run lost all but
``ratio`` of its initial "energy" by t_end (default :data:`DEFAULT_LYAPUNOV_RATIO`, 0.1 %).
The magnitudes, because v is negative away from the equilibrium when the equilibrium is
not its minimum (an inverted pendulum held up by too weak a K_r): a run that falls to a
lower potential ends with v < 0 and has not converged. :data:`ROUND_OFF` is the round-off
of v at the equilibrium, so that a run started there (v(0) zero up to round-off)
converges. A run with a non-finite v has not converged.

Used by a sweep's index (``converged`` column, :mod:`rbstab.sweep.folder`), the basin map
(:mod:`rbstab.analysis.basin`, from every sample: the time to converge, :data:`SAMPLE_RULE`),
the robustness of a sweep (:mod:`rbstab.analysis.robustness`) and the compiled summary of
a run on the GPU (:mod:`rbstab.summary`), all through :func:`within_bound`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["DEFAULT_LYAPUNOV_RATIO", "ROUND_OFF", "RULE", "SAMPLE_RULE", "converged", "within_bound"]

#: Default ratio (a sweep's ``convergence.lyapunov_ratio``, ``rbstab analyze --ratio``).
DEFAULT_LYAPUNOV_RATIO = 1e-3
#: Added to the bound ratio |v(0)| [J]: the round-off of v at the equilibrium.
ROUND_OFF = 1e-12
#: The bound at one time, as text (v [J]).
SAMPLE_RULE = f"|v| <= ratio |v(0)| + {ROUND_OFF:g} J"
#: The rule of :func:`converged` as text, in the names of a sweep's index columns (a sweep's
#: ``sweep_summary.json`` states it).
RULE = (f"converged = status == 'success' and lyapunov_initial, lyapunov_final finite and "
        f"|lyapunov_final| <= lyapunov_ratio * |lyapunov_initial| + {ROUND_OFF:g} J")


def within_bound(v0, v, ratio):
    """Whether v(0) and v [J] are finite and |v| <= ``ratio`` |v(0)| + :data:`ROUND_OFF`:
    the rule's bound, on numbers or arrays element by element (:mod:`rbstab.summary`
    compiles it, for the CPU and the GPU)."""
    # x - x == 0: whether x is finite, for numbers and arrays, in Python and compiled
    return (v0 - v0 == 0) & (v - v == 0) & (abs(v) <= ratio * abs(v0) + ROUND_OFF)


#: Types of one value (the fast path of :func:`converged`: a sweep's index asks once a run).
_SCALARS = frozenset({float, int, bool, str, type(None), np.float64, np.float32, np.int64})


def converged(success: Any, lyapunov_initial: Any, lyapunov_final: Any,
              ratio: float = DEFAULT_LYAPUNOV_RATIO) -> Any:
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
        return bool(success) and bool(within_bound(v0, v1, ratio))
    v0 = np.asarray(lyapunov_initial, dtype=float)
    v1 = np.asarray(lyapunov_final, dtype=float)
    with np.errstate(invalid="ignore", over="ignore"):
        return np.asarray(success, dtype=bool) & within_bound(v0, v1, ratio)
