"""Rules of one or two thresholds that separate two outcomes of runs (stable or not,
recovered or not) along one key.

A rule says where along the key x the stable runs lie: below a threshold, above it, inside
an interval or outside it. Its *balanced accuracy* is the mean of the fractions of the
stable and of the unstable runs it puts on their side (0.5 chance, 1 complete; unlike the
plain accuracy it does not reward calling every run by the commoner outcome).
:func:`split_rule` picks the best, preferring one threshold to an interval unless the
interval is better by :data:`INTERVAL_MARGIN`; the rule *explains* the outcome when its
balanced accuracy is at least :data:`EXPLAINS_BAR`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["SplitRule", "split_rule", "split_rules", "EXPLAINS_BAR", "INTERVAL_MARGIN"]

#: A rule of one key explains the outcome from this balanced accuracy on: on average at
#: most one run in ten of each outcome on the wrong side (0.5 is chance).
EXPLAINS_BAR = 0.9
#: An interval rule (two thresholds) is chosen over the best single threshold only when its
#: balanced accuracy is higher by at least this much: a second threshold fitted to the same
#: runs always gains a little by chance.
INTERVAL_MARGIN = 0.05


@dataclass(frozen=True)
class SplitRule:
    """Where along one key x the stable (recovered) runs lie.

    Attributes
    ----------
    side : str
        ``"below"`` (x < high), ``"above"`` (x > low), ``"inside"`` (low < x < high) or
        ``"outside"`` (x < low or x > high).
    low, high : float
        The thresholds, each midway between two observed values (units of the key); NaN
        where the rule has none (``high`` of ``"above"``, ``low`` of ``"below"``).
    balanced_accuracy : float
        Mean of the fractions of the stable and of the unstable runs the rule puts on their
        side: 0.5 chance, 1 complete.
    explains : bool
        balanced_accuracy >= :data:`EXPLAINS_BAR`.
    """

    side: str
    low: float
    high: float
    balanced_accuracy: float
    explains: bool

    def holds(self, x) -> np.ndarray:
        """Whether the rule says stable at the values ``x`` (array of bool, the shape of x)."""
        x = np.asarray(x, dtype=float)
        if self.side == "below":
            return x < self.high
        if self.side == "above":
            return x > self.low
        inside = (x > self.low) & (x < self.high)
        return inside if self.side == "inside" else ~inside


def _rule(side: str, low: float, high: float, accuracy: float) -> SplitRule:
    return SplitRule(side, float(low), float(high), float(accuracy), bool(accuracy >= EXPLAINS_BAR))


def split_rules(values: np.ndarray, stable: np.ndarray) -> tuple[SplitRule, SplitRule | None]:
    """(best single threshold, best interval or None with fewer than two cuts) of runs with
    both outcomes: ``values`` (n,) float, ``stable`` (n,) bool.

    g(c) = (stable fraction below c) - (unstable fraction below c) at each cut c between
    distinct values: "stable below c" has balanced accuracy (1 + g(c)) / 2, "stable above"
    (1 - g(c)) / 2, "stable inside (a, b)" (1 + g(b) - g(a)) / 2 and "stable outside"
    (1 - g(b) + g(a)) / 2; the best interval is found in one pass (running minimum).
    """
    order = np.argsort(values, kind="stable")
    x, y = values[order], stable[order]
    cuts = np.flatnonzero(np.diff(x) > 0)
    if not cuts.size:
        return _rule("below", math.nan, x[0], 0.5), None
    at = 0.5 * (x[cuts] + x[cuts + 1])
    g = np.cumsum(y)[cuts] / y.sum() - np.cumsum(~y)[cuts] / (~y).sum()
    k = int(np.argmax(np.abs(g)))
    one = _rule("below", math.nan, at[k], 0.5 * (1.0 + g[k])) if g[k] >= 0 else \
        _rule("above", at[k], math.nan, 0.5 * (1.0 - g[k]))
    if cuts.size < 2:
        return one, None
    best = None
    for side, h in (("inside", g), ("outside", -g)):
        gain = h[1:] - np.minimum.accumulate(h[:-1])  # h(b) - min over a < b of h(a)
        j = int(np.argmax(gain)) + 1
        i = int(np.argmin(h[:j]))
        if best is None or gain[j - 1] > best[3]:
            best = (side, at[i], at[j], gain[j - 1])
    side, low, high, gain = best
    return one, _rule(side, low, high, 0.5 * (1.0 + gain))


def split_rule(values, stable, margin: float = INTERVAL_MARGIN) -> SplitRule | None:
    """The rule of one key that best separates stable from unstable runs.

    Parameters
    ----------
    values : array_like, shape (n,)
        The key's value of each run.
    stable : array_like of bool, shape (n,)
        Whether the run was stable (recovered).
    margin : float
        The interval (stable inside or outside two thresholds) is chosen only where its
        balanced accuracy exceeds the best single threshold's by at least ``margin``.

    Returns
    -------
    SplitRule or None
        None without both stable and unstable runs.
    """
    values = np.asarray(values, dtype=float)
    stable = np.asarray(stable, dtype=bool)
    if stable.all() or not stable.any():
        return None
    one, interval = split_rules(values, stable)
    if interval is not None and interval.balanced_accuracy >= one.balanced_accuracy + margin - 1e-12:
        return interval
    return one
