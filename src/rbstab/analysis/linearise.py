"""The equilibrium, the rest check, the Jacobian there and its eigenvalues (modes, verdict).

The equilibrium is the compiled tree's rest state (:func:`linearise_chain`:
:func:`rbstab.variants.chain.rest_state`, the least stored energy near the reference
configuration, polished to a rest point; the origin without gravity). The Jacobian is that
of the tree's right-hand side (:func:`reduced_rates`) in its independent coordinates (one
body's: its own state, the reduced 6-state (Theta, Omega) system for ``permanent``, eq 21),
by central differences extrapolated to step zero (:mod:`rbstab.analysis.derivatives`).

Per eigenvalue s (python-control's ``damp`` conventions):

- natural frequency ``omega_n = |s|`` [rad/s];
- damping ratio ``zeta = -Re(s) / |s|`` (1 for a real stable mode, < 0 when unstable);
- time constant ``tau = -1 / Re(s)`` [s] of a decaying mode (Re(s) < -tol): the time it
  takes to shrink by the factor e; NaN for any other mode;
- e-folding time ``1 / Re(s)`` [s] of a growing mode (Re(s) > tol): the time it takes to
  grow by the factor e; NaN for any other mode.

A mode with |Re(s)| <= tol (a zero or purely imaginary eigenvalue) has neither.

Verdict (Lyapunov's indirect method): ``asymptotically stable`` when every Re(s) < -tol,
``unstable`` when some Re(s) > tol, else ``marginal`` (the linearisation cannot decide:
a centre-manifold question, e.g. a zero stiffness), with tol = :data:`EIGENVALUE_RTOL`
times the spectral radius (at least 1 s^-1 times it).

The time scale of the equilibrium is that of the eigenvalue with the largest real part:
the slowest time constant when asymptotically stable, the shortest e-folding time when
unstable, none when marginal (:func:`rbstab.analysis.text.time_scale` says which in words).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import math

import numpy as np

from ..layout import BLOCK_UNITS, JOINT_KIND_OF, JOINT_KINDS, REDUCED_STATES
from .derivatives import jacobian

__all__ = [
    "Linearisation",
    "linearise_chain",
    "coordinates_of",
    "ball_entries",
    "coordinates_state",
    "linearise_config",
    "undisturbed",
    "rest_verdict",
    "NO_LINEARISATION",
    "MAX_REST_CHECKS",
    "modes",
    "mode_shapes",
    "verdict",
    "rest_tolerance",
    "EIGENVALUE_RTOL",
    "REST_RTOL",
    "VERDICTS",
]

#: Eigenvalues with |Re(s)| at most this times max(1, spectral radius) [1/s] are marginal.
EIGENVALUE_RTOL = 1e-7
#: A rest point: every |dy/dt| at most this times the acceleration scale (:func:`rest_tolerance`).
REST_RTOL = 1e-9
#: The verdicts of :func:`verdict`.
VERDICTS = ("asymptotically stable", "marginal", "unstable")


@dataclass(frozen=True)
class Linearisation:
    """The linearised dynamics at the equilibrium, dy/dt ~ A (y - y_e).

    Attributes
    ----------
    equilibrium : ndarray, shape (n,)
        y_e in the variant's state layout (units per block, :data:`rbstab.layout.BLOCK_UNITS`).
    rest_residual : ndarray, shape (n,)
        dy/dt at y_e (zero at a rest point).
    rest_tolerance : float
        The bound the residual is held to (:func:`rest_tolerance`).
    jacobian : ndarray, shape (n, n)
        A = d(dy/dt)/dy at y_e [mixed SI units, row units / column units].
    jacobian_error : ndarray, shape (n, n)
        Error estimate of each entry of A (Richardson table).
    eigenvalues : ndarray of complex, shape (n,)
        Of A [1/s], sorted by real part, descending (then by imaginary part).
    tolerance : float
        |Re(s)| at most which a mode is marginal [1/s].
    """

    equilibrium: np.ndarray
    rest_residual: np.ndarray
    rest_tolerance: float
    jacobian: np.ndarray
    jacobian_error: np.ndarray
    eigenvalues: np.ndarray
    tolerance: float

    @property
    def is_rest_point(self) -> bool:
        """Whether every |dy/dt| at y_e is within :attr:`rest_tolerance`."""
        return bool(np.all(np.abs(self.rest_residual) <= self.rest_tolerance))

    @property
    def verdict(self) -> str:
        """One of :data:`VERDICTS` (see the module docstring)."""
        return verdict(self.eigenvalues, self.tolerance)

    @property
    def natural_frequency(self) -> np.ndarray:
        """|s| [rad/s] per eigenvalue."""
        return modes(self.eigenvalues)[0]

    @property
    def damping_ratio(self) -> np.ndarray:
        """-Re(s)/|s| per eigenvalue (NaN for s = 0)."""
        return modes(self.eigenvalues)[1]

    @property
    def time_constant(self) -> np.ndarray:
        """-1/Re(s) [s] per eigenvalue where Re(s) < -:attr:`tolerance` (a decaying mode), NaN elsewhere."""
        return modes(self.eigenvalues, self.tolerance)[2]

    @property
    def e_folding_time(self) -> np.ndarray:
        """1/Re(s) [s] per eigenvalue where Re(s) > :attr:`tolerance` (a growing mode), NaN elsewhere."""
        return modes(self.eigenvalues, self.tolerance)[3]

    @property
    def slowest_time_constant(self) -> float:
        """The time constant of the eigenvalue with the largest real part [s] when
        asymptotically stable; NaN otherwise."""
        return float(self.time_constant[0]) if self.verdict == "asymptotically stable" else float("nan")

    def settling_time(self, ratio: float) -> float:
        """Time [s] the slowest mode alone takes to bring v down by ``ratio``: v ~ exp(-2 t /
        tau), so tau ln(1/ratio) / 2 (NaN unless asymptotically stable)."""
        return 0.5 * self.slowest_time_constant * math.log(1.0 / ratio)

    @property
    def shortest_e_folding_time(self) -> float:
        """The e-folding time of the eigenvalue with the largest real part [s] when
        unstable (the fastest-growing mode); NaN otherwise."""
        return float(self.e_folding_time[0]) if self.verdict == "unstable" else float("nan")


def modes(eigenvalues: np.ndarray, tolerance: float = 0.0
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(natural frequency [rad/s], damping ratio, time constant [s], e-folding time [s])
    per eigenvalue (module docstring).

    Parameters
    ----------
    eigenvalues : ndarray of complex, shape (n,)
        [1/s]
    tolerance : float
        [1/s], >= 0: a mode with |Re(s)| at most this has neither a time constant nor an
        e-folding time (NaN).
    """
    s = np.asarray(eigenvalues, dtype=complex)
    omega_n = np.abs(s)
    with np.errstate(divide="ignore", invalid="ignore"):
        zeta = np.where(omega_n > 0, -s.real / np.where(omega_n > 0, omega_n, 1.0), np.nan)
        decaying, growing = s.real < -tolerance, s.real > tolerance
        tau = np.where(decaying, -1.0 / np.where(decaying, s.real, 1.0), np.nan)
        e_fold = np.where(growing, 1.0 / np.where(growing, s.real, 1.0), np.nan)
    return omega_n, zeta, tau, e_fold


def mode_shapes(lin: Linearisation, rows) -> np.ndarray:
    """The right eigenvectors of ``lin.jacobian`` in the order of ``lin.eigenvalues`` (each
    eigenvalue's nearest eigenvalue of the matrix, none taken twice), on the state entries
    ``rows`` (m indices) only: shape (n, m) complex, each row divided by its entry of largest
    modulus (so that entry is 1; the others give their size and phase relative to it; a row
    that is zero on ``rows`` stays zero). A real eigenvalue's are real: for one of
    multiplicity k with k independent eigenvectors, the k right singular vectors of A - s I
    of the smallest singular values (a basis of its eigenspace, where rounding made a
    complex pair of it)."""
    w, v = np.linalg.eig(lin.jacobian)
    free = list(range(w.size))
    order = []
    for s in lin.eigenvalues:
        k = min(free, key=lambda i: abs(w[i] - s))
        free.remove(k)
        order.append(k)
    v = v[:, order].astype(complex)
    scale = max(1.0, float(np.linalg.norm(lin.jacobian, 2))) if w.size else 1.0
    for s in np.unique(lin.eigenvalues.real[lin.eigenvalues.imag == 0]):
        same = np.flatnonzero(lin.eigenvalues == s)
        _, sigma, vt = np.linalg.svd(lin.jacobian - s * np.eye(len(w)))
        if sigma[-len(same)] <= 1e-6 * scale:  # k independent eigenvectors (not a Jordan block)
            v[:, same] = vt[-len(same):].T
    shapes = v[list(rows)].T
    pivot = shapes[np.arange(shapes.shape[0]), np.argmax(np.abs(shapes), axis=1)]
    return shapes / np.where(pivot == 0, 1.0, pivot)[:, None]


def verdict(eigenvalues: np.ndarray, tolerance: float) -> str:
    """``asymptotically stable``, ``unstable`` or ``marginal`` (module docstring).

    Parameters
    ----------
    eigenvalues : ndarray of complex, shape (n,)
        [1/s]
    tolerance : float
        [1/s], >= 0.
    """
    real = np.asarray(eigenvalues).real
    if np.any(real > tolerance):
        return "unstable"
    if np.all(real < -tolerance):
        return "asymptotically stable"
    return "marginal"


def sort_eigenvalues(eigenvalues: np.ndarray) -> np.ndarray:
    """By real part descending, then imaginary part descending (the ``--json`` order)."""
    s = np.asarray(eigenvalues, dtype=complex)
    return s[np.lexsort((-s.imag, -s.real))]


def rest_tolerance(jac: np.ndarray, equilibrium: np.ndarray, gravity: np.ndarray) -> float:
    """REST_RTOL times the acceleration scale max(1, |A|_inf |y_e|_inf, |g|) [SI rates].

    |A| |y_e| is the size of the rates that moving the state from the origin to y_e
    changes; |g| that of the weight an equilibrium with gravity balances.
    """
    scale = max(1.0, float(np.abs(jac).sum(axis=1).max() * np.abs(equilibrium).max()),
                float(np.linalg.norm(gravity)))
    return REST_RTOL * scale


def linearisation(rates, y_e: np.ndarray, gravity: np.ndarray) -> Linearisation:
    """The :class:`Linearisation` of the vectorised right-hand side ``rates`` ((k, n) -> (k,
    n)) at the equilibrium ``y_e`` (n,) of a model under ``gravity`` (3,) [m/s^2]: its rest
    residual and tolerance, its Jacobian (:func:`rbstab.analysis.derivatives.jacobian`) and
    eigenvalues."""
    residual = rates(y_e[None])[0]
    jac, error = jacobian(rates, y_e)
    eigenvalues = np.linalg.eigvals(jac)
    radius = float(np.abs(eigenvalues).max()) if eigenvalues.size else 0.0
    tolerance = EIGENVALUE_RTOL * max(1.0, radius)
    # a real eigenvalue of multiplicity 2 (two symmetric modes) comes out of the Jacobian's
    # rounding as a pair Re s +- i tiny: real within the tolerance that decides Re s
    eigenvalues = np.where(np.abs(eigenvalues.imag) <= tolerance, eigenvalues.real + 0j, eigenvalues)
    return Linearisation(
        equilibrium=y_e,
        rest_residual=residual,
        rest_tolerance=rest_tolerance(jac, y_e, gravity),
        jacobian=jac,
        jacobian_error=error,
        eigenvalues=sort_eigenvalues(eigenvalues),
        tolerance=tolerance,
    )


def linearise_chain(compiled) -> tuple[Linearisation, list[tuple[str, str, int]]]:
    """Rest state, rest check, Jacobian and eigenvalues of a chain
    (:class:`rbstab.variants.chain.CompiledChain`), in its independent coordinates.

    The rest state is :func:`rbstab.variants.chain.rest_state` (the least potential near
    the reference configuration); the Jacobian is that of
    :func:`reduced_rates` (Theta_i, Omega_i of every body; X_i, V_i of
    bodies whose joint is not ``permanent``; D of embedded joints) by central differences
    extrapolated to step zero, so a ``permanent`` joint's constraint is not a mode.

    Returns
    -------
    (Linearisation, coordinates)
        ``Linearisation.equilibrium`` holds the independent coordinates at rest (shape
        (3 k,)); ``coordinates`` names them: (body, block, index into the full state), 3
        entries each (:func:`rbstab.variants.chain.independent_coordinates`).

    Raises
    ------
    ValueError
        Where the potential has no minimum near the reference configuration (no rest
        state to linearise at), or a sliding joint without a boundary layer.
    """
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    if any(j.variant == "sliding" and j.boundary_layer <= 0 for j in compiled.chain.joints):
        raise ValueError("a sliding joint with boundary_layer 0 has no linearisation; give it a boundary layer")
    y_rest, _ = C.rest_state(compiled)
    if y_rest is None:
        raise ValueError("the chain's potential has no minimum near its reference configuration "
                         "(a body falls without bound): there is no rest state to linearise at")
    coordinates = coordinates_of(compiled)
    if compiled.hinged:  # the reduced state at rest
        from ..variants.tree import reduce_state, tree_layout  # heavy: numba

        z = _polished(compiled, _coordinates_of_reduced(compiled, reduce_state(compiled, tree_layout(compiled),
                                                                               y_rest)[None])[0], coordinates)
    else:
        z = np.concatenate([y_rest[at: at + 3] for _, _, at, _ in coordinates])
    return linearisation(lambda rows: reduced_rates(compiled, rows), z, compiled.chain.gravity), coordinates


def _polished(compiled, z: np.ndarray, coordinates) -> np.ndarray:
    """The rest point ``z`` of a tree in its reduced coordinates (the minimiser's, to its
    gradient's tolerance) polished to rounding: its configuration's entries (a joint's angles,
    a free body's Theta and X, D) moved so that the rates of its velocities (at zero
    velocities) vanish (scipy's ``root``); ``z`` itself where the polish does not lower them."""
    from scipy.optimize import root  # heavy: scipy

    rates_of = {"omega", "velocity", "joint_omega", "u"}
    moved = np.array([k for _, block, at, size in _offsets(coordinates) if block not in rates_of
                      for k in range(at, at + size)], dtype=np.int64)
    still = np.array([k for _, block, at, size in _offsets(coordinates) if block in rates_of
                      for k in range(at, at + size)], dtype=np.int64)
    if len(moved) != len(still) + sum(size for _, block, _, size in coordinates if block == "controller_state"):
        return z
    rated = np.concatenate([still, [k for _, block, at, size in _offsets(coordinates) if block == "controller_state"
                                    for k in range(at, at + size)]]).astype(np.int64)

    def residual(x):
        row = z.copy()
        row[moved] = x
        return reduced_rates(compiled, row[None])[0, rated]

    start = residual(z[moved])
    if not np.all(np.isfinite(start)) or not np.any(start):
        return z
    with np.errstate(all="ignore"):
        found = root(residual, z[moved], method="hybr", options={"xtol": 1e-14})
    if not (np.all(np.isfinite(found.fun)) and np.linalg.norm(found.fun) < np.linalg.norm(start)):
        return z
    out = z.copy()
    out[moved] = found.x
    return out


def _offsets(coordinates) -> list[tuple[str, str, int, int]]:
    """(body, block, start in z, entries) of each block of the coordinates ``coordinates``."""
    out, at = [], 0
    for body, block, _, size in coordinates:
        out.append((body, block, at, size))
        at += size
    return out


def coordinates_of(compiled) -> list[tuple[str, str, int, int]]:
    """The coordinates of a chain's linearisation: (body name, block, index into the state,
    its entries) of each block. Without a hinge its
    independent coordinates in the full state (:func:`rbstab.variants.chain.independent_coordinates`:
    Theta_i, Omega_i of every body, X_i, V_i of bodies whose joint is not ``permanent``, D);
    with one its reduced state (:func:`rbstab.variants.tree.tree_layout`): each body's blocks
    of its joint kind (:attr:`rbstab.layout.JointKind.blocks`: a hinge's child's ``q``
    [rad] and ``u`` [rad/s], 1 entry each, a universal joint's 2 each; a ball's child's ``joint_theta``,
    ``joint_omega`` (Theta_j, Omega_j); a free body's ``theta``, ``omega``, ``position``,
    ``velocity``), then D of embedded joints."""
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    if not compiled.hinged:
        return C.independent_coordinates(compiled)
    from ..variants.tree import tree_layout  # heavy: numba

    layout, names, out = tree_layout(compiled), compiled.chain.body_names, []
    for i, joint in enumerate(compiled.chain.joints):
        at = int(layout.r_at[i])
        if joint.variant == "ball":  # the rotation vector of A_rel, a chart of its quaternion's tangent directions
            out += [(names[i], "joint_theta", at, 3), (names[i], "joint_omega", at + 4, 3)]
            continue
        for block, size in JOINT_KINDS[JOINT_KIND_OF[joint.variant]].blocks:
            out.append((names[i], block, at, size))
            at += size
    return out + [(names[j], "controller_state", int(layout.rd_at[j]), 3) for j in range(compiled.size)
                  if layout.rd_at[j] >= 0]


def coordinates_state(compiled, z: np.ndarray) -> np.ndarray:
    """The full state (n_states,) of the linearisation's coordinates ``z``
    (:func:`coordinates_of`): :func:`rbstab.variants.chain.full_state`, or with a hinge the
    maximal image of the reduced state (:func:`rbstab.variants.tree.expand_samples`). A stack
    ``z`` (k, m) gives (k, n_states)."""
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    if not compiled.hinged:
        return C.full_state(compiled, z)
    from ..variants.tree import expand_samples, tree_layout  # heavy: numba

    z = np.asarray(z, dtype=float)
    rows = np.ascontiguousarray(_reduced_of_coordinates(compiled, np.atleast_2d(z)))
    y = np.empty((1, len(rows), compiled.n_states))
    expand_samples(rows[None], compiled.params[None], compiled.codes, compiled.parents, compiled.ppoints[None],
                   compiled.d_at, *tree_layout(compiled).args, y, np.zeros(1, dtype=np.int64))
    return y[0] if z.ndim == 2 else y[0, 0]


def reduced_rates(compiled, z, t=0.0) -> np.ndarray:
    """dz/dt (k, m) of a tree's independent coordinates
    (:func:`rbstab.variants.chain.independent_coordinates`) at each row of ``z`` (k, m) at
    the times ``t`` [s] (a number or (k,)): the chain's rate
    (:func:`rbstab.variants.chain.chain_rates`) at the full state of each row, the children of
    permanent joints placed on their parents, the whole stack at once
    (:func:`rbstab.variants.chain.full_state`), read at those coordinates; a tree with a
    hinge: the rate of its reduced state (:func:`rbstab.variants.tree.tree_rate`)."""
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    z = np.atleast_2d(np.asarray(z, dtype=float))
    t = np.ascontiguousarray(np.broadcast_to(np.asarray(t, dtype=float), len(z)))
    if compiled.hinged:  # z is the reduced state: the tree's own rate
        from ..variants.tree import tree_layout, tree_rate, tree_work  # heavy: numba

        layout = tree_layout(compiled)
        work = tree_work(compiled.size, compiled.n_states)
        out = np.empty((len(z), layout.n_r + 1))
        for k, row in enumerate(np.ascontiguousarray(_reduced_of_coordinates(compiled, z))):
            tree_rate(t[k], row, *compiled.args, *layout.args, out[k], work)
        return _coordinate_rates(compiled, z, out[:, : layout.n_r])
    y = C.full_state(compiled, z)
    dy = np.empty_like(y)
    C.chain_rates(t, y, *compiled.args, dy)
    return dy[:, compiled.independent_columns]


def ball_entries(compiled) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """How a tree's linearisation coordinates z (:func:`coordinates_of`) sit in its reduced
    state: (the entries of z, the entries of the reduced state they are, one to one; each
    quaternion ball's (start in z of its rotation vector phi, start in the reduced state of
    its quaternion), its Omega_j 3 entries after each)."""
    from ..variants.tree import tree_layout  # heavy: numba

    layout, copied, balls = tree_layout(compiled), [], []
    z_at = 0
    for i, joint in enumerate(compiled.chain.joints):
        r_at = int(layout.r_at[i])
        size = int(REDUCED_STATES[compiled.codes[i]])
        if joint.variant == "ball":
            balls.append((z_at, r_at))
            copied += [(z_at + 3 + k, r_at + 4 + k) for k in range(3)]
            z_at += 6
            continue
        copied += [(z_at + k, r_at + k) for k in range(size)]
        z_at += size
    copied += [(z_at + k, r_at) for k, r_at in enumerate(range(int(layout.r_at[-1]) + int(
        REDUCED_STATES[compiled.codes[-1]]), layout.n_r))]  # D of embedded joints
    z_index, r_index = (np.array(v, dtype=np.int64) for v in zip(*copied)) if copied else (np.zeros(0, np.int64),) * 2
    return z_index, r_index, balls


def _reduced_of_coordinates(compiled, z: np.ndarray) -> np.ndarray:
    """The reduced states (k, n_r) of the coordinates ``z`` (k, m): a quaternion ball's
    quaternion (cos(|phi|/2), sin(|phi|/2) phi / |phi|) of its rotation vector phi."""
    z_index, r_index, balls = ball_entries(compiled)
    if not balls:
        return z
    out = np.empty((len(z), z.shape[1] + len(balls)))
    out[:, r_index] = z[:, z_index]
    for z_at, r_at in balls:
        phi = z[:, z_at: z_at + 3]
        angle = np.linalg.norm(phi, axis=1)
        half = np.where(angle < 1e-4, 0.5 - angle**2 / 48.0, np.sin(0.5 * angle) / np.where(angle > 0, angle, 1.0))
        out[:, r_at] = np.cos(0.5 * angle)
        out[:, r_at + 1: r_at + 4] = half[:, None] * phi
    return out


def _coordinates_of_reduced(compiled, reduced: np.ndarray) -> np.ndarray:
    """The coordinates z (k, m) of the reduced states ``reduced`` (k, n_r): a quaternion
    ball's rotation vector phi (|phi| <= pi) of its quaternion."""
    z_index, r_index, balls = ball_entries(compiled)
    if not balls:
        return reduced
    out = np.empty((len(reduced), reduced.shape[1] - len(balls)))
    out[:, z_index] = reduced[:, r_index]
    for z_at, r_at in balls:
        q = reduced[:, r_at: r_at + 4] * np.where(reduced[:, r_at: r_at + 1] < 0, -1.0, 1.0)
        size = np.linalg.norm(q[:, 1:], axis=1)
        scale = np.where(size < 1e-12 * np.abs(q[:, 0]), 2.0 / q[:, 0],
                         2.0 * np.arctan2(size, q[:, 0]) / np.where(size > 0, size, 1.0))
        out[:, z_at: z_at + 3] = scale[:, None] * q[:, 1:]
    return out


def _coordinate_rates(compiled, z: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """dz/dt (k, m) at the coordinates ``z`` of the reduced states' rates ``rates`` (k,
    n_r): a quaternion ball's dphi/dt = J_r(phi)^-1 Omega_j."""
    z_index, r_index, balls = ball_entries(compiled)
    if not balls:
        return rates
    out = np.empty_like(z)
    out[:, z_index] = rates[:, r_index]
    for z_at, _ in balls:
        phi, omega = z[:, z_at: z_at + 3], z[:, z_at + 3: z_at + 6]
        angle2 = np.einsum("ki,ki->k", phi, phi)
        angle = np.sqrt(angle2)
        with np.errstate(all="ignore"):
            c = np.where(angle < 1e-4, 1.0 / 12.0 + angle2 / 720.0,
                         1.0 / angle2 - (1.0 + np.cos(angle)) / (2.0 * angle * np.sin(angle)))
        cross = np.cross(phi, omega)
        out[:, z_at: z_at + 3] = omega + 0.5 * cross + c[:, None] * np.cross(phi, cross)
    return out


@dataclass(frozen=True)
class TreeCoordinates:
    """A chain's independent coordinates (:func:`rbstab.variants.chain.independent_coordinates`)
    as the layout of its linearisation's state z: each (body, state block) with its entries,
    the blocks of :data:`rbstab.layout.STATE_BLOCKS` a body has (Theta, Omega of every body;
    X, V of one whose joint is not ``permanent``; D of an ``embedded`` joint's child), as
    :class:`rbstab.layout.StateLayout` lays out one body's state; a tree with a kind beyond
    the paper's: its reduced state's blocks (a hinge's child's q and u, 1 entry each, a
    universal joint's 2; an Euler ball's child's Theta_j, Omega_j; a quaternion ball's
    rotation vector of A_rel and Omega_j; a free body's Theta, Omega, X, V).

    Attributes
    ----------
    coordinates : tuple of (str, str, int, int)
        (body name, block, index into the full or reduced state, entries) of each block of z.
    bodies : tuple of str
        The chain's bodies, in order.
    """

    coordinates: tuple
    bodies: tuple

    @property
    def blocks(self) -> tuple[str, ...]:
        """The state blocks some body has, in :data:`rbstab.layout.BLOCK_UNITS`' order
        (:data:`rbstab.layout.STATE_BLOCKS`, then the joints' blocks of a reduced state)."""
        present = {block for _, block, _, _ in self.coordinates}
        return tuple(b for b in BLOCK_UNITS if b in present)

    def offsets(self) -> list[int]:
        """Where each (body, block) starts in z."""
        return list(np.cumsum([0] + [size for _, _, _, size in self.coordinates])[:-1])

    def state_names(self) -> list[str]:
        """Scalar coordinate names ``<body>.<block>_<i>`` (``legs.theta_1``), a one-entry
        block's ``<body>.<block>`` (a hinge's ``shank.q``), in z's order."""
        return [f"{body}.{block}_{i}" if size > 1 else f"{body}.{block}"
                for body, block, _, size in self.coordinates for i in range(1, size + 1)]

    def state_units(self) -> list[str]:
        """The units of each scalar coordinate (:data:`rbstab.layout.BLOCK_UNITS`), in z's order."""
        return [BLOCK_UNITS[block] for _, block, _, size in self.coordinates for _ in range(size)]

    def split(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """Each block of ``z`` (n_z,) by body: {block: shape (n_bodies, 3)}, NaN for a body
        without that block (a one-entry block, a hinge's q or u: its first column)."""
        z = np.asarray(z, dtype=float)
        out = {b: np.full((len(self.bodies), 3), np.nan) for b in self.blocks}
        for (body, block, _, size), at in zip(self.coordinates, self.offsets()):
            out[block][self.bodies.index(body), :size] = z[at: at + size]
        return out


def linearise_config(config) -> Linearisation:
    """The linearisation at the rest state of a run configuration, as ``rbstab analyze``
    finds it, without its disturbances (they act in time, not at rest: :func:`undisturbed`):
    :func:`linearise_chain` of its compiled tree (one body's: its one-body tree, in its
    variant's own state).

    Raises
    ------
    ValueError
        Where there is none: the pure sign law of ``sliding``, a tree with no rest state
        near its reference configuration (:func:`linearise_chain`).
    """
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    return linearise_chain(C.compile_chain(undisturbed(config).chain))[0]


def undisturbed(config):
    """A run configuration (:class:`rbstab.config.RunConfig`) without its disturbances (they
    act in time, not at rest): what its equilibrium or rest state, linearisation and
    certificate see; ``config`` itself where it has none."""
    tree = config.chain
    if not any(b.disturbances for b in tree.bodies):
        return config
    return replace(config, chain=replace(tree, bodies=tuple(replace(b, disturbances=()) for b in tree.bodies)))


#: :func:`rest_verdict` where the configuration has no linearisation.
NO_LINEARISATION = "no linearisation"
#: Most distinct physical configurations a report's table or a robustness analysis passes
#: to :func:`rest_verdict`: a chain's takes ~0.1-0.2 s (the minimisation to its rest state,
#: then the Jacobian), one body's ~10 ms; 1000 chains ~2-3 min.
MAX_REST_CHECKS = 1000


def rest_verdict(config, name: str = "run") -> str:
    """The verdict of the linearisation at the rest state of a run's resolved configuration
    ``config`` (a mapping: one body's or a chain's; :func:`linearise_config`, as
    ``rbstab analyze`` finds it): one of :data:`VERDICTS`, or :data:`NO_LINEARISATION`
    where there is none (the pure sign law, no rest state, a rest point the search did not
    reach, a configuration that does not validate today). Its warnings are not shown (the
    run gave them)."""
    from ..config.loader import config_from_mapping  # heavy: pydantic

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lin = linearise_config(config_from_mapping(config, default_name=name))
    except ValueError:  # ConfigError included
        return NO_LINEARISATION
    return lin.verdict if lin.is_rest_point else NO_LINEARISATION
