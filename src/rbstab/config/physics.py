"""Physical checks of a configuration whose values are each valid on their own.

- :func:`inertia_warnings`: an inertia no real body has (a warning, the equations hold).
- :func:`angle_warnings`: initial Euler angles beyond one turn (degrees typed as radians?).
- :func:`semidefinite_notes`: gains that are positive semi-definite but singular (a zero
  gain included): valid physics, but v is then not a strict Lyapunov function (a note).
- :func:`unheld_weight`: with gravity, stiffnesses that leave a direction in which nothing
  holds the weight: the body falls without end, there is no equilibrium (an error).
- :func:`unheld_bodies`: the same for a chain's bodies that no joint ties to the ground (a
  warning, W007).

Matrices here are the validated 3x3 arrays of :class:`rbstab.model.Gains`, symmetric
positive semi-definite (:mod:`rbstab.config.schema`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..layout import point_fixed
from ..warning_codes import coded

__all__ = ["inertia_warnings", "angle_warnings", "semidefinite_notes", "unheld_weight", "unheld_bodies",
           "SINGULAR_RTOL"]

#: An eigenvalue at most this times the largest eigenvalue magnitude counts as zero (also
#: down to minus this: rounding of a singular matrix written with decimals).
SINGULAR_RTOL = 1e-12

#: The weight G may have a component of this times |G| along a direction no spring
#: resists (rounding of the eigenvectors), no more.
_WEIGHT_RTOL = 1e-9


def _fmt(vector) -> str:
    """'(0, 0, -410)': a vector for messages (4 significant digits, no negative zero)."""
    v = np.asarray(vector, float)
    v = np.where(np.abs(v) <= 1e-12 * np.abs(v).max(), 0.0, v) + 0.0
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def inertia_warnings(inertia: np.ndarray) -> list[str]:
    """Warning lines (code ``W001``, :mod:`rbstab.warning_codes`) for an inertia that violates
    the triangle inequality j_i <= j_k + j_l.

    Parameters
    ----------
    inertia : ndarray, shape (3, 3)
        J [kg m^2], symmetric positive definite.
    """
    rows = np.asarray(inertia, dtype=float).tolist()  # plain floats: this runs for every run of a sweep
    if all(rows[i][k] == 0.0 for i in range(3) for k in range(3) if i != k):
        j = [rows[0][0], rows[1][1], rows[2][2]]  # diagonal: keep the user's j1, j2, j3 labels
    else:
        j = [float(x) for x in np.linalg.eigvalsh(inertia)]
    for i in range(3):
        others = [j[k] for k in range(3) if k != i]
        if j[i] > sum(others) * (1 + 1e-12):
            return [coded(
                "W001",
                f"body.inertia: principal moments ({', '.join(f'{x:g}' for x in j)}) kg m^2 violate the "
                f"triangle inequality (j{i + 1} = {j[i]:g} > {others[0]:g} + {others[1]:g}); no real body has them",
            )]
    return []


def angle_warnings(theta) -> list[str]:
    """Warning lines (code ``W005``) for initial Euler angles beyond one turn (2 pi rad),
    most often degrees typed as radians (``theta: [45, 0, 0]``)."""
    big = [(i, float(a)) for i, a in enumerate(np.asarray(theta, dtype=float).ravel()) if abs(a) > 2 * math.pi]
    if not big:
        return []
    which = ", ".join(f"theta[{i}] = {a:g} rad ({a / (2 * math.pi):.3g} turns)" for i, a in big)
    return [coded("W005", f"initial_state.theta: {which}; the angles are in radians (degrees typed as radians?)")]


def _null_space(matrix: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the null space of a symmetric PSD matrix, shape (n, k)."""
    eigenvalues, vectors = np.linalg.eigh(matrix)
    scale = np.abs(eigenvalues).max()
    return vectors[:, eigenvalues <= SINGULAR_RTOL * scale]


def _eigenvalues(gain) -> list[float]:
    """Ascending eigenvalues of a gain: 3 numbers (a diagonal) or a symmetric 3x3 matrix."""
    if isinstance(gain, (list, tuple)) and not isinstance(gain[0], (list, tuple)):
        return sorted(float(x) for x in gain)  # the common case, without numpy's overhead
    return np.linalg.eigvalsh(np.asarray(gain, dtype=float)).tolist()


def semidefinite_notes(gains: Mapping[str, Any]) -> list[str]:
    """A note (one line, or none) naming the gains that are singular.

    Parameters
    ----------
    gains : Mapping
        The gains a variant uses, by config key: ``k_t`` ... ``l_d`` as written in a
        config (3 numbers, a diagonal, or a symmetric 3x3 list of lists or array), ``k_s``
        a number [N]; None values are skipped.

    Returns
    -------
    list of str
        Empty, or one line ``"W002 controller.k_t, controller.l_r: ..."`` (its code,
        :mod:`rbstab.warning_codes`): with a singular
        stiffness v is not positive definite (it does not grow in that direction), with a
        singular damper dv/dt misses that direction; either way v is not a strict
        Lyapunov function and asymptotic stability is not implied.
    """
    singular: dict[str, str] = {}
    for key, gain in gains.items():
        if gain is None:
            continue
        if not isinstance(gain, (list, tuple)) and np.ndim(gain) == 0:
            if float(gain) == 0.0:
                singular[key] = f"{key} = 0"
            continue
        eigenvalues = _eigenvalues(gain)
        if eigenvalues[0] <= SINGULAR_RTOL * max(abs(eigenvalues[0]), abs(eigenvalues[-1])):
            matrix = np.diag(gain) if np.ndim(gain) == 1 else np.asarray(gain, dtype=float)
            null = _null_space(matrix)
            singular[key] = (
                f"{key} = 0" if null.shape[1] == 3 else f"{key} has no stiffness or damping along "
                + " and ".join(_fmt(null[:, i]) for i in range(null.shape[1]))
            )
    if not singular:
        return []
    keys = ", ".join(f"controller.{k}" for k in singular)
    return [coded(
        "W002",
        f"{keys}: positive semi-definite, not definite ({'; '.join(singular.values())}); "
        "v is then not a strict Lyapunov function (asymptotic stability is not implied)",
    )]


def _sliding_capacity(null: np.ndarray, weight: np.ndarray) -> float:
    """max of G.u over u in span(null) with |u|_1 <= 1: the sliding force K_s needed.

    Along u (K_t u = 0) the potential is K_s sum|E_i| - X'G + bounded terms, bounded
    below exactly when G.u <= K_s |u|_1 for every such u (a small linear programme).
    """
    from scipy.optimize import linprog  # heavy: scipy

    k = null.shape[1]
    eye = np.eye(3)
    # variables (c, t): u = null @ c, -t <= u <= t, sum(t) <= 1
    a_ub = np.block(
        [[null, -eye], [-null, -eye], [np.zeros((1, k)), np.ones((1, 3))]]
    )
    b_ub = np.concatenate([np.zeros(6), [1.0]])
    cost = np.concatenate([-(null.T @ weight), np.zeros(3)])
    bounds = [(None, None)] * k + [(0, None)] * 3
    result = linprog(cost, A_ub=a_ub, b_ub=b_ub, bounds=bounds, method="highs")
    return float(-result.fun)


def unheld_weight(
    variant: str,
    mass: float,
    gravity: np.ndarray,
    gains: Mapping[str, np.ndarray | float | None],
    boundary_layer: float = 0.0,
) -> tuple[str, str] | None:
    """With gravity: is there a direction in which nothing holds the weight G = m g?

    The stored energy at rest, -X'G plus the springs, must be bounded below for an
    equilibrium to exist (rbstab's v is measured from it, eq 30). For ``permanent`` the
    pivot holds the weight (X = R - A R is bounded). For the others, X (and the controller
    state D) may run off along the null space of the translational stiffness:

    - ``free``: K_t (the equilibrium is X_e = K_t^-1 G, eq 30);
    - ``visco_elastic``: K_t + K_c (E = X + A R - R differs from X by a bounded term);
    - ``embedded``: the (X, D) stiffness [[K_t + K_c, -K_c], [-K_c, K_c + K_d]] (eq 44);
    - ``sliding``: K_t, and along its null space the force K_s sgn(E) (at most K_s per
      axis) must carry G: G.u <= K_s |u|_1 for every u with K_t u = 0 (strictly, with a
      boundary layer: tanh never reaches 1).

    Parameters
    ----------
    variant : str
    mass : float
        m [kg].
    gravity : ndarray, shape (3,)
        g [m/s^2], inertial frame.
    gains : Mapping
        The variant's gains by config key (3x3 arrays, ``k_s`` a float [N]).
    boundary_layer : float
        phi [m] of ``sliding``.

    Returns
    -------
    (key, detail) or None
        The config key to blame (``controller.k_t``, or ``controller.k_s`` for sliding)
        and why, or None when the weight is held (or there is no gravity).
    """
    weight = mass * np.asarray(gravity, float)
    size = np.linalg.norm(weight)
    if not size or point_fixed(variant):
        return None
    k_t = gains["k_t"]
    diagonal = k_t.diagonal()
    if diagonal.min() > 0 and np.count_nonzero(k_t) == 3:
        return None  # K_t alone holds any weight (the common case, checked cheaply)
    if variant == "sliding":
        return _sliding_unheld(k_t, float(gains["k_s"]), weight, boundary_layer)
    return _springs_unheld(variant, gains, weight, size)


def _sliding_unheld(k_t: np.ndarray, k_s: float, weight: np.ndarray, boundary_layer: float) -> tuple[str, str] | None:
    """:func:`unheld_weight` of ``sliding``: along the null space of K_t the force
    K_s sgn(E) must carry G (strictly with a boundary layer)."""
    null = _null_space(k_t)
    if null.shape[1] == 0:
        return None
    need = _sliding_capacity(null, weight)
    strict = boundary_layer > 0
    if (need < k_s) if strict else (need <= k_s * (1 + 1e-12)):
        return None
    relation = ">" if strict else ">="
    return "controller.k_s", (
        f"with gravity and K_t singular along {' and '.join(_fmt(u) for u in null.T)}, the "
        f"sliding force must carry the weight G = {_fmt(weight)} N there: K_s {relation} "
        f"{need:.6g} N is needed; otherwise the body falls without end and there is no "
        "equilibrium"
    )


def _springs_unheld(variant: str, gains: Mapping[str, np.ndarray | float | None], weight: np.ndarray,
                    size: float) -> tuple[str, str] | None:
    """:func:`unheld_weight` of ``free``, ``visco_elastic`` and ``embedded``: the part of
    (G, 0) in the null space of the translational stiffness."""
    k_t = gains["k_t"]
    if variant == "free":
        stiffness, what = k_t, "K_t"
    elif variant == "visco_elastic":
        stiffness, what = k_t + gains["k_c"], "K_t + K_c"
    elif variant == "embedded":
        k_c, k_d = gains["k_c"], gains["k_d"]
        stiffness = np.block([[k_t + k_c, -k_c], [-k_c, k_c + k_d]])
        what = "K_t and K_c in series with K_d"
    else:
        raise ValueError(f"unknown variant {variant!r}")
    null = _null_space(stiffness)
    load = np.concatenate([weight, np.zeros(len(stiffness) - 3)])
    along = null @ (null.T @ load)  # the part of (G, 0) no spring resists
    if np.linalg.norm(along) <= _WEIGHT_RTOL * size:
        return None
    direction = along[:3] / np.linalg.norm(along[:3])
    equilibrium = " (X_e = K_t^-1 G, eq 30)" if variant == "free" else ""
    return "controller.k_t", (
        f"with gravity, {what} must resist every direction in which the weight pulls: "
        f"G = {_fmt(weight)} N has {weight @ direction:.6g} N along {_fmt(direction)}, "
        "where no spring acts; the body falls without end and there is no "
        f"equilibrium{equilibrium}"
    )


def unheld_bodies(names, masses, k_t, joints, gravity) -> list[str]:
    """W007 warnings: with gravity, the groups of a chain's bodies that nothing holds.

    Joints other than ``free`` hold their child to their parent (``permanent``, ``sliding``,
    ``visco_elastic``, ``embedded``: a constraint or a spring at the point C); a ``free``
    joint exerts torques only. The bodies tied together by such joints form groups; a group
    tied to the ground holds its weight. Another group is held only by its bodies' ground-
    anchored feedback H_b = -K_t,b X_b - L_t,b V_b (eq 24): at rest the net force on it is
    sum_b (m_b g - K_t,b X_b), so along a direction u with K_t,b u = 0 for every body of the
    group (the null space of sum_b K_t,b, each PSD) the weight (sum_b m_b) g.u pulls without
    end: the group falls without bound and v has no minimum.

    Parameters
    ----------
    names : sequence of str
        The bodies' names.
    masses : sequence of float
        m_b [kg].
    k_t : sequence of ndarray, shape (3, 3)
        K_t,b [N/m], each symmetric positive semi-definite.
    joints : sequence of (int or None, int, str)
        (parent body's index, None for the ground; child body's index; variant) per joint.
    gravity : ndarray, shape (3,)
        g [m/s^2], inertial frame.

    Returns
    -------
    list of str
        One W007 line per group that falls, naming its bodies.
    """
    g = np.asarray(gravity, float)
    if not np.linalg.norm(g):
        return []
    group = list(range(len(names)))  # union-find over the holding joints

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i

    grounded = set()
    for parent, child, variant in joints:
        if variant == "free":
            continue
        if parent is None:
            grounded.add(child)
        else:
            group[root(child)] = root(parent)
    grounded = {root(i) for i in grounded}
    lines = []
    for r in sorted({root(i) for i in range(len(names))} - grounded):
        members = [i for i in range(len(names)) if root(i) == r]
        weight = sum(masses[i] for i in members) * g
        null = _null_space(sum(np.asarray(k_t[i], float) for i in members))
        along = null @ (null.T @ weight)
        if np.linalg.norm(along) <= _WEIGHT_RTOL * np.linalg.norm(weight):
            continue
        who = ", ".join(f"'{names[i]}'" for i in members)
        lines.append(coded("W007", (
            f"joints: bod{'y' if len(members) == 1 else 'ies'} {who} held by no joint to the ground and no k_t along "
            f"{_fmt(along / np.linalg.norm(along))}: with gravity the weight {_fmt(weight)} N pulls there without end, "
            "so it falls without bound and v has no minimum")))
    return lines
