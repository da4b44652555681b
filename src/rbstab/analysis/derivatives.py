"""Derivatives of the compiled model by central differences with Richardson extrapolation.

The model's kernels (:mod:`rbstab.variants.kernels`) are compiled for float64, so neither
the complex step nor automatic differentiation reaches them. Central differences do, and
their error is a series in even powers of the step h: a Richardson table over the steps
h0, h0/c, h0/c^2 ... removes the h^2, h^4 ... terms one column at a time. Ridders' choice
of the best entry (the one whose neighbours in the table agree best) also gives an error
estimate, returned beside each derivative.

Every function here takes a vectorised function ``f`` of a stack of states (shape
(k, n) -> (k, m) or (k,)) and calls it once, on every perturbed state at once.

References
----------
C. J. F. Ridders, "Accurate computation of F'(x) and F'(x)F''(x)", Adv. Eng. Software 4
(1982) 75-76; W. H. Press et al., Numerical Recipes, 3rd ed., section 5.7 (``dfridr``).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

__all__ = ["richardson", "jacobian", "hessian", "directional_derivative", "LEVELS", "RATIO"]

#: Steps in the Richardson table (h0, h0/RATIO, ... h0/RATIO^(LEVELS-1)): from the
#: default h0 = 0.5 down to 1e-6, so that some steps lie inside the smallest length scale
#: of the model (a sliding boundary layer of 0.1 mm) and some above the round-off.
LEVELS = 20
#: Ratio of successive steps.
RATIO = 2.0
#: Round-off floor of an entry of the table: this times the spacing of floats at the
#: magnitude of the function near the point (:func:`_magnitude`), divided by the step
#: (squared, for a second difference). It keeps noise-dominated fine steps from winning
#: by chance.
NOISE = 10.0
_EPS = np.finfo(float).eps


def richardson(estimates: np.ndarray, ratio: float = RATIO, noise: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Ridders' extrapolation of central-difference estimates to step zero.

    Every entry of the table competes (no early stop, unlike ``dfridr``): steps far
    above the model's length scale (a saturated tanh) and far below (round-off) give
    entries whose neighbours disagree, so they lose to those in between.

    Parameters
    ----------
    estimates : ndarray, shape (levels, ...)
        The estimate with step h0 / ratio**l in row l; its error is a series in h^2.
    ratio : float
        Ratio of successive steps (> 1).
    noise : ndarray, shape (levels, ...), optional
        Round-off bound of the estimates of each row: an entry that uses row l has at
        least this error.

    Returns
    -------
    value, error : ndarray, shape (...)
        The best extrapolated value of each element and its error estimate (the larger
        difference to its neighbours in the table).
    """
    factor = ratio * ratio
    previous = [estimates[0]]
    best = np.array(estimates[0], dtype=float, copy=True)
    error = np.full(best.shape, np.inf)
    for i in range(1, len(estimates)):
        row = [estimates[i]]
        f = factor
        for j in range(1, i + 1):
            t = (row[j - 1] * f - previous[j - 1]) / (f - 1.0)
            f *= factor
            e = np.maximum(np.abs(t - row[j - 1]), np.abs(t - previous[j - 1]))
            if noise is not None:
                e = np.maximum(e, noise[i])
            better = e <= error
            best = np.where(better, t, best)
            error = np.where(better, e, error)
            row.append(t)
        previous = row
    return best, error


def _magnitude(values: np.ndarray) -> np.ndarray:
    """Magnitude of a function near the point, from ``values`` (signs/points, levels, ...):
    the median over the levels of the largest finite |value| of each level (a median, so
    that a few far steps, e.g. into gimbal lock, do not set it)."""
    finite = np.where(np.isfinite(values), np.abs(values), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices
        return np.nan_to_num(np.nanmedian(np.nanmax(finite, axis=0), axis=0), nan=0.0)


def _steps(h0: np.ndarray, levels: int, ratio: float) -> np.ndarray:
    """(levels, n): row l is h0 / ratio**l."""
    return np.asarray(h0, dtype=float)[None, :] / ratio ** np.arange(levels)[:, None]


def jacobian(
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    h0: np.ndarray | float = 0.5,
    levels: int = LEVELS,
    ratio: float = RATIO,
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian df/dx at ``x``.

    Parameters
    ----------
    f : callable
        Vectorised: states of shape (k, n) -> values of shape (k, m).
    x : ndarray, shape (n,)
    h0 : float or ndarray, shape (n,)
        Largest step of each coordinate (units of x).
    levels, ratio : see :data:`LEVELS`, :data:`RATIO`.

    Returns
    -------
    jac, error : ndarray, shape (m, n)
        ``jac[i, j] = d f_i / d x_j`` and its error estimate.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    h = _steps(np.broadcast_to(h0, (n,)), levels, ratio)  # (L, n)
    offsets = h[:, :, None] * np.eye(n)[None]  # (L, n, n): level, column j, state
    points = np.concatenate([x + offsets, x - offsets]).reshape(-1, n)
    values = np.asarray(f(points), dtype=float).reshape(2, levels, n, -1)
    estimates = (values[0] - values[1]) / (2.0 * h[:, :, None])  # (L, n, m)
    magnitude = _magnitude(values)  # (n, m)
    jac, error = richardson(estimates, ratio, NOISE * _EPS * magnitude / h[:, :, None])
    return jac.T, error.T


def hessian(
    v: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    h0: np.ndarray | float = 0.5,
    levels: int = LEVELS,
    ratio: float = RATIO,
) -> tuple[np.ndarray, np.ndarray]:
    """Hessian of a scalar function at ``x`` by the four-point second difference

    d2v/dx_i dx_j ~ [v(x+h_i+h_j) - v(x+h_i-h_j) - v(x-h_i+h_j) + v(x-h_i-h_j)] / (4 h_i h_j)

    (for i = j the three-point difference with step 2 h_i), extrapolated in h.

    Parameters
    ----------
    v : callable
        Vectorised: states (k, n) -> values (k,).
    x : ndarray, shape (n,)
    h0 : float or ndarray, shape (n,)
        Largest step of each coordinate.

    Returns
    -------
    hess, error : ndarray, shape (n, n)
        Symmetric.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    h = _steps(np.broadcast_to(h0, (n,)), levels, ratio)  # (L, n)
    i, j = np.triu_indices(n)
    eye = np.eye(n)
    di = h[:, i, None] * eye[i][None]  # (L, P, n)
    dj = h[:, j, None] * eye[j][None]
    points = np.stack([x + di + dj, x + di - dj, x - di + dj, x - di - dj]).reshape(-1, n)
    values = np.asarray(v(points), dtype=float).reshape(4, levels, len(i))
    estimates = (values[0] - values[1] - values[2] + values[3]) / (4.0 * h[:, i] * h[:, j])
    magnitude = _magnitude(values)  # (P,)
    upper, upper_error = richardson(estimates, ratio, NOISE * _EPS * magnitude / (h[:, i] * h[:, j]))
    hess = np.zeros((n, n))
    error = np.zeros((n, n))
    hess[i, j] = upper
    hess[j, i] = upper
    error[i, j] = upper_error
    error[j, i] = upper_error
    return hess, error


def directional_derivative(
    v: Callable[[np.ndarray], np.ndarray],
    y: np.ndarray,
    direction: np.ndarray,
    s0: float,
    levels: int = 8,
    ratio: float = RATIO,
) -> tuple[np.ndarray, np.ndarray]:
    """d/ds v(y + s direction) at s = 0, for each row of ``y``.

    With ``direction`` the right-hand side dy/dt and ``s`` a time [s], this is the rate of
    v along the flow, dv/dt = grad v . f, computed from v alone.

    Parameters
    ----------
    v : callable
        Vectorised: states (k, n) -> values (k,).
    y, direction : ndarray, shape (N, n)
    s0 : float
        Largest step (units of 1 / units of ``direction``).

    Returns
    -------
    rate, error : ndarray, shape (N,)
    """
    y = np.asarray(y, dtype=float)
    direction = np.asarray(direction, dtype=float)
    s = s0 / ratio ** np.arange(levels)  # (L,)
    step = s[:, None, None] * direction[None]  # (L, N, n)
    points = np.stack([y[None] + step, y[None] - step]).reshape(-1, y.shape[-1])
    values = np.asarray(v(points), dtype=float).reshape(2, levels, len(y))
    estimates = (values[0] - values[1]) / (2.0 * s[:, None])
    magnitude = _magnitude(values)  # (N,)
    return richardson(estimates, ratio, NOISE * _EPS * magnitude / s[:, None])
