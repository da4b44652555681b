"""The controller-variant protocol shared by the integrators and the writers.

A variant is one way of holding the point C of the body (section 5). The integrators
and the HDF5 writer talk only to this protocol, never to a variant by name:

- ``layout``: the state blocks (:mod:`rbstab.layout`);
- ``initial_state``: the state vector from the configured initial blocks;
- ``rhs(t, y)``: the right-hand side, for one state (shape (n_state,)) or a stack
  (shape (..., n_state));
- ``evaluate(y)``: every output quantity along a stack of states (constraint error E and
  rate F, constraint force Lambda, controls H and N, the Lyapunov function v, its terms
  and its analytic rate dv/dt).

All physics follows ``docs/physics.md`` (the consistent restatement of eqs 1-46).

The dynamics live in one method per variant, :meth:`Variant.quantities_columns`, which
works in the columns form of :mod:`rbstab.kinematics`: a vector is the tuple of its 3
components, Python floats for one state and arrays of shape (m,) for a stack of m
states, and every operation is elementwise. ``rhs`` calls it with ``outputs=False``
(only what the state rate needs) and ``quantities``/``evaluate`` with ``outputs=True``;
both convert at the boundary to the stacked rows (..., n_state) that the integrators and
writers use. The Lyapunov function and its rate (``lyapunov_terms``, ``lyapunov_rate``,
``constraint_energy``, ``constraint_dissipation``) read the columns-form quantities too.
So the same code gives the single-state right-hand side of ``solve_ivp`` (float
arithmetic, no numpy per-call overhead), the batched right-hand side and the outputs of
a whole block of runs, and a state gets the same bits whatever else shares its stack.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property
from typing import ClassVar

import numpy as np

from ..kinematics import (
    add_columns,
    add_constant_columns,
    cross_columns,
    div_columns,
    dot_columns,
    dot_constant_columns,
    from_columns,
    matTvec_columns,
    matvec_columns,
    quadratic_form_columns,
    rate_matvec_columns,
    rotation_and_rate_columns,
    sub_constant_columns,
    to_columns,
    zeros_columns,
)
from ..layout import FULL_BODY, StateLayout
from ..model import Gains, RigidBody, force_h, gyroscopic, torque_n

__all__ = ["Variant", "FullBodyVariant", "OUTPUT_UNITS", "OUTPUT_DESCRIPTIONS", "LYAPUNOV_TERMS"]

#: Names of the terms of v, in the order they are summed.
LYAPUNOV_TERMS = (
    "lyapunov_translational",
    "lyapunov_rotational",
    "lyapunov_constraint",
    "lyapunov_gravity",
)

#: Units of every output quantity other than the state blocks.
OUTPUT_UNITS = {
    "constraint_error": "m",
    "constraint_rate": "m s-1",
    "constraint_force": "N",
    "force_h": "N",
    "torque_n": "N m",
    "lyapunov": "J",
    "lyapunov_rate": "W",
    "lyapunov_translational": "J",
    "lyapunov_rotational": "J",
    "lyapunov_constraint": "J",
    "lyapunov_gravity": "J",
}

#: Descriptions of every output quantity other than the state blocks.
OUTPUT_DESCRIPTIONS = {
    "constraint_error": "E = X + A R - R, displacement of the point C, inertial frame (eq 4)",
    "constraint_rate": "F = dE/dt = V - A hat(R) Omega, velocity of C, inertial frame (eq 4)",
    "constraint_force": "Lambda, force applied at C, inertial frame (eqs 20, 22, 39, 40)",
    "force_h": "H = -K_t X - L_t V, translational feedback, inertial frame (eq 24)",
    "torque_n": "N = -B' K_r Theta - L_r Omega, rotational feedback, body frame (eq 23)",
    "lyapunov": "Lyapunov function v, the sum of the lyapunov_* terms (eqs 28-46)",
    "lyapunov_rate": "analytic dv/dt (eqs 29, 37, 43, 46)",
    "lyapunov_translational": "v_t = V'MV/2 + X'K_t X/2 (eq 25)",
    "lyapunov_rotational": "v_r = Omega'J Omega/2 + Theta'K_r Theta/2 (eq 25)",
    "lyapunov_constraint": "energy stored in the constraint controller (eqs 41, 44; "
    "K_s |E|_1 or its boundary-layer smoothing for sliding; 0 for free and permanent)",
    "lyapunov_gravity": "-X'G plus the constant h that makes v zero at the equilibrium (eq 30)",
}


#: The vector outputs of :meth:`Variant.evaluate` after the state blocks, in order.
_OUTPUT_VECTORS = ("constraint_error", "constraint_rate", "constraint_force", "force_h", "torque_n")


def _component_array(c, shape: tuple[int, ...]) -> np.ndarray:
    """One component in columns form (a float, an array (m,), or a constant scalar for a
    stack) as an array of ``shape`` (stacked rows; a 0-d float for one state)."""
    if not shape:
        return np.float64(c)
    if np.ndim(c) == 0:
        return np.full(shape, float(c))
    return c.reshape(shape)


def _vector_rows(x, shape: tuple[int, ...]) -> np.ndarray:
    """A vector in columns form as stacked rows of ``shape + (3,)``: the transposed view
    of a (3, m) array (no copy), else :func:`~rbstab.kinematics.from_columns`."""
    if isinstance(x, np.ndarray) and x.ndim == 2 and shape:
        return x.T.reshape(shape + (3,))
    return from_columns(x, shape)


class Variant(ABC):
    """One controller variant for the point C (the protocol; see module docstring).

    Parameters
    ----------
    body : RigidBody
        The rigid body (Table 1).
    gains : Gains
        Gains; those in ``required_gains`` are not None.
    """

    #: Registry name (the config value of ``controller.variant``).
    name: ClassVar[str]
    #: Layout of the integrated state.
    layout: ClassVar[StateLayout]
    #: Gains that must be configured for this variant.
    required_gains: ClassVar[tuple[str, ...]] = ("k_t", "l_t", "k_r", "l_r")
    #: Whether the right-hand side is smooth (False for the pure sign function).
    smooth: ClassVar[bool] = True
    #: Paper equation of the constraint law, for documentation and reports.
    equation: ClassVar[str] = ""

    def __init__(self, body: RigidBody, gains: Gains) -> None:
        self.body = body
        self.gains = gains

    # -- state ---------------------------------------------------------------
    def initial_state(self, blocks: dict[str, np.ndarray]) -> np.ndarray:
        """State vector, shape (layout.size,), from initial blocks (each shape (3,)).

        Blocks the layout does not hold (e.g. ``position`` for ``permanent``) are ignored.
        """
        return self.layout.join(**{b: blocks[b] for b in self.layout.blocks})

    # -- dynamics ------------------------------------------------------------
    @abstractmethod
    def quantities_columns(self, y, outputs: bool = True, state_rate: bool = True) -> dict:
        """The dynamics: the state rate and, with ``outputs``, every output quantity.

        Columns form (:mod:`rbstab.kinematics`): ``y`` is the state's components, a list
        of ``layout.size`` floats (one state, :func:`~rbstab.kinematics.to_columns` of a
        (n_state,) array) or an (n_state, m) array (m states as columns); every vector in
        the result is a tuple of 3 components (floats, or arrays (m,)), every matrix a
        nested tuple of entries.

        Returns a dict holding the state blocks ``theta``, ``omega``, ``position``,
        ``velocity`` (reconstructed where not integrated), ``rotation_matrix`` A,
        ``euler_rate_matrix`` B, ``force_h``, ``torque_n`` and, with ``state_rate``, the
        time derivative ``state_rate`` of y (``layout.size`` components); with
        ``outputs`` also ``constraint_error``, ``constraint_rate`` and
        ``constraint_force``. Without ``outputs`` (the right-hand side) quantities that
        only the outputs need may be skipped; without ``state_rate`` (the outputs) the
        parts of the state rate that the outputs do not need may be skipped.
        """

    def quantities(self, y: np.ndarray, outputs: bool = True) -> dict[str, np.ndarray]:
        """Everything the right-hand side and the outputs need, for y shape (..., n_state).

        Returns a dict holding at least the state blocks ``theta``, ``omega``,
        ``position``, ``velocity`` (reconstructed where not integrated), and
        ``constraint_error``, ``constraint_rate``, ``constraint_force``, ``force_h``,
        ``torque_n`` (each shape (..., 3)), ``rotation_matrix`` and
        ``euler_rate_matrix`` (shape (..., 3, 3)) and the time derivative ``state_rate``
        of y (see :meth:`quantities_columns`; here in stacked rows, C-contiguous).
        """
        y = np.asarray(y, dtype=float)
        q = self.quantities_columns(to_columns(y), outputs)
        return {k: from_columns(value, y.shape[:-1]) for k, value in q.items()}

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """dy/dt, shape like ``y`` ((n_state,) or (..., n_state)); ``t`` [s] is unused.

        One state is computed in Python floats (solve_ivp's call), a stack with one numpy
        call per operation on whole rows (the batch engine's); both run
        :meth:`quantities_columns`.
        """
        y = np.asarray(y, dtype=float)
        if y.ndim == 1:
            return np.array(self.quantities_columns(y.tolist(), outputs=False)["state_rate"])
        rate = self.quantities_columns(to_columns(y), outputs=False)["state_rate"]
        return from_columns(rate, y.shape[:-1])

    # -- Lyapunov function ---------------------------------------------------
    # Each of these reads the columns-form quantities of :meth:`quantities_columns`
    # (with ``outputs``) and returns one component: a float for one state, an array (m,)
    # (or a constant scalar) for a stack.
    @abstractmethod
    def constraint_energy(self, q: dict):
        """Energy stored in the constraint law [J] (columns form, see above)."""

    @abstractmethod
    def constraint_dissipation(self, q: dict):
        """Power dissipated by the constraint law [W] (>= 0) (columns form, see above)."""

    def lyapunov_terms(self, q: dict) -> dict:
        """The terms of v [J] (see :data:`LYAPUNOV_TERMS`), columns form (see above)."""
        terms = self._raw_lyapunov_terms(q)
        terms["lyapunov_gravity"] = terms["lyapunov_gravity"] + self.lyapunov_offset
        return terms

    def _raw_lyapunov_terms(self, q: dict) -> dict:
        """The terms of v without the constant h (eq 25 and the constraint energy)."""
        body, gains = self.body.columns, self.gains.columns
        x, v = q["position"], q["velocity"]
        theta, omega = q["theta"], q["omega"]
        return {
            "lyapunov_translational": 0.5 * body.mass * dot_columns(v, v)
            + 0.5 * quadratic_form_columns(x, gains.k_t),
            "lyapunov_rotational": 0.5 * quadratic_form_columns(omega, body.inertia)
            + 0.5 * quadratic_form_columns(theta, gains.k_r),
            "lyapunov_constraint": self.constraint_energy(q),
            "lyapunov_gravity": -dot_constant_columns(x, body.weight),
        }

    def lyapunov_rate(self, q: dict):
        """Analytic dv/dt [W] (eqs 29, 37, 43, 46), columns form (see above): never positive."""
        gains = self.gains.columns
        return (
            -quadratic_form_columns(q["velocity"], gains.l_t)
            - quadratic_form_columns(q["omega"], gains.l_r)
            - self.constraint_dissipation(q)
        )

    def evaluate(self, y: np.ndarray) -> dict[str, np.ndarray]:
        """All outputs along states ``y`` of shape (n, n_state), or (..., n_state).

        Elementwise throughout (:mod:`rbstab.kinematics`), so the outputs of a state do
        not depend on the other states of ``y``: a block of runs stacked as (k, n,
        n_state) gives each run the bits it gets alone.

        Returns
        -------
        dict
            The state blocks, ``constraint_error``, ``constraint_rate``,
            ``constraint_force``, ``force_h``, ``torque_n`` (shape (n, 3)), and
            ``lyapunov``, ``lyapunov_rate`` and the terms of v (shape (n,)); leading
            dimensions those of ``y``. For a stack the vectors are transposed views of
            the columns-form arrays (strided, not C-contiguous: a copy costs more than
            the rest of the evaluation, and a writer copies anyway); the scalars are
            C-contiguous.
        """
        y = np.asarray(y, dtype=float)
        shape = y.shape[:-1]
        q = self.quantities_columns(to_columns(y), outputs=True, state_rate=False)
        terms = self.lyapunov_terms(q)
        vectors = ("theta", "omega", "position", "velocity", "controller_state", *_OUTPUT_VECTORS)
        out = {k: _vector_rows(q[k], shape) for k in vectors if k in q}
        out["lyapunov"] = _component_array(sum(terms[k] for k in LYAPUNOV_TERMS), shape)
        out["lyapunov_rate"] = _component_array(self.lyapunov_rate(q), shape)
        for k in LYAPUNOV_TERMS:
            out[k] = _component_array(terms[k], shape)
        return out

    def lyapunov(self, y: np.ndarray) -> np.ndarray:
        """v [J] along states ``y`` of shape (..., n_state); shape (...)."""
        y = np.asarray(y, dtype=float)
        q = self.quantities_columns(to_columns(y), outputs=True, state_rate=False)
        terms = self.lyapunov_terms(q)
        return _component_array(sum(terms[k] for k in LYAPUNOV_TERMS), y.shape[:-1])

    # -- equilibrium -----------------------------------------------------------
    @property
    def _configuration_blocks(self) -> tuple[str, ...]:
        return tuple(b for b in self.layout.blocks if b in ("theta", "position", "controller_state"))

    def _potential(self, p: np.ndarray) -> float:
        """Stored energy without the constant h, at rest, for configuration vector p."""
        q = self.quantities_columns(self._rest_state(p).tolist(), outputs=True, state_rate=False)
        terms = self._raw_lyapunov_terms(q)
        return float(sum(terms[k] for k in LYAPUNOV_TERMS))

    def _rest_state(self, p: np.ndarray) -> np.ndarray:
        """State at rest (zero velocities) with configuration blocks from vector ``p``."""
        blocks = {b: np.zeros(3) for b in self.layout.blocks}
        for i, b in enumerate(self._configuration_blocks):
            blocks[b] = p[3 * i : 3 * i + 3]
        return self.layout.join(**blocks)

    def _rest_acceleration(self, p: np.ndarray) -> np.ndarray:
        """Rates of omega, velocity (and D) at rest: zero exactly at an equilibrium."""
        rate = self.layout.split(self.rhs(0.0, self._rest_state(p)))
        return np.concatenate(
            [rate[b] for b in ("omega", "velocity", "controller_state") if b in self.layout.blocks]
        )

    @cached_property
    def _equilibrium(self) -> tuple[np.ndarray, float]:
        n = 3 * len(self._configuration_blocks)
        if not np.any(self.body.weight):
            return self._rest_state(np.zeros(n)), 0.0
        from scipy.optimize import minimize, root

        if self.smooth:
            # the minimum of the stored energy, polished to a rest point of the dynamics
            p = minimize(self._potential, np.zeros(n), method="BFGS").x
            polished = root(self._rest_acceleration, p, method="hybr", options={"xtol": 1e-13})
            if np.linalg.norm(polished.fun) < np.linalg.norm(self._rest_acceleration(p)):
                p = polished.x
        else:
            p = minimize(
                self._potential,
                np.zeros(n),
                method="Nelder-Mead",
                options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 20000 * n, "maxfev": 20000 * n},
            ).x
        return self._rest_state(p), -self._potential(p)

    @property
    def equilibrium(self) -> np.ndarray:
        """Equilibrium state, shape (n_state,): the local minimum of the stored energy nearest
        the origin (zero velocities). Without gravity it is the origin."""
        return self._equilibrium[0]

    @cached_property
    def lyapunov_offset(self) -> float:
        """The constant h [J] that makes v zero at :attr:`equilibrium` (eq 30)."""
        return self._equilibrium[1]


class FullBodyVariant(Variant):
    """Base of the variants that integrate the 12 body states (eq 1) under a force Lambda.

    Subclasses give the constraint force law :meth:`constraint_law` and list in
    :attr:`constraint_inputs` the constraint quantities it reads.
    """

    layout: ClassVar[StateLayout] = FULL_BODY
    #: Which of ``constraint_error`` (E) and ``constraint_rate`` (F) the constraint law
    #: reads; the right-hand side computes only these (the outputs compute both).
    constraint_inputs: ClassVar[tuple[str, ...]] = ("constraint_error", "constraint_rate")

    @abstractmethod
    def constraint_law(self, q: dict):
        """Lambda [N], inertial frame, or None when there is no constraint force.

        ``q`` is the columns-form dict being built by :meth:`quantities_columns` (state
        blocks, ``rotation_matrix``, ``euler_rate_matrix``, ``torque_n``, ``force_h`` and
        those of E, F listed in :attr:`constraint_inputs`); returns a vector (3
        components) and may add extra columns-form rates to ``q`` (``controller_rate``).
        """

    def quantities_columns(self, y, outputs: bool = True, state_rate: bool = True) -> dict:
        """Eq 1 under Lambda, in columns form (see :meth:`Variant.quantities_columns`).

        dTheta/dt = B Omega, J dOmega/dt = f(Omega) + N + hat(R) A' Lambda,
        dX/dt = V, m dV/dt = G + H + Lambda; E = X + A R - R, F = V + A (Omega x R) (eq 4).
        """
        body = self.body.columns
        q = self.layout.split_columns(y)
        theta, omega, x, v = q["theta"], q["omega"], q["position"], q["velocity"]
        a, b = rotation_and_rate_columns(theta)
        q["rotation_matrix"], q["euler_rate_matrix"] = a, b
        r = body.attachment_point
        needed = ("constraint_error", "constraint_rate") if outputs else self.constraint_inputs
        if "constraint_error" in needed:
            q["constraint_error"] = sub_constant_columns(add_columns(x, matvec_columns(a, r)), r)
        if "constraint_rate" in needed:
            q["constraint_rate"] = add_columns(v, matvec_columns(a, cross_columns(omega, r)))
        q["torque_n"] = torque_n(b, theta, omega, self.gains)
        q["force_h"] = force_h(x, v, self.gains)
        lam = self.constraint_law(q)
        if outputs:
            q["constraint_force"] = zeros_columns(x) if lam is None else lam
        if state_rate:
            torque = add_columns(gyroscopic(body.inertia, omega), q["torque_n"])
            force = add_constant_columns(q["force_h"], body.weight)  # G + H
            if lam is not None:
                torque = add_columns(torque, cross_columns(r, matTvec_columns(a, lam)))  # + R x A' Lambda
                force = add_columns(force, lam)
            rates = {
                "theta": rate_matvec_columns(b, omega),
                "omega": body.inertia_inv.apply(torque),
                "position": v,
                "velocity": div_columns(force, body.mass),
            }
            if "controller_state" in q:
                rates["controller_state"] = q["controller_rate"]
            q["state_rate"] = self.layout.join_columns(**rates)
        return q
