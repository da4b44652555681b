"""``permanent``: C pinned; the reduced 6-state system about the fixed point (eqs 18-21, 31-37).

The point C sits at its reference position (E = F = 0). The integrated state is
(Theta, Omega); X, V and the constraint force are reconstructed from it (eq 32 with
X_e = 0, eq 20). :meth:`Permanent.full_state_variant` gives the independent 12-state
formulation with Lambda solved from the acceleration constraint (eqs 15-17); both must
give the same trajectory.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..kinematics import (
    as_column,
    cross_columns,
    matTvec_columns,
    matvec_columns,
    rotation_and_rate_columns,
)
from ..layout import FULL_BODY, REDUCED, StateLayout
from ..model import force_h, gyroscopic, torque_n
from .base import FullBodyVariant, Variant

__all__ = ["Permanent", "PermanentFullState"]


class Permanent(Variant):
    """Rigid body rotating about the fixed point C (Euler's equation about C).

    J_p dOmega/dt = -Omega x (J_p Omega) + N - hat(R) A'(G + H),  J_p = J - m hat(R)^2
    (eq 21, corrected: the paper's extra term hat(R) hat(Omega) Omega is identically zero
    and its sign of the hat(Omega)^2 R term is inconsistent; see docs/physics.md).
    Reconstruction: X = R - A R, V = A hat(R) Omega;
    Lambda = m (A hat(R) dOmega/dt - A hat(Omega)^2 R) - G - H.
    v = v_t + v_r - X'G + h (eqs 31, 34); dv/dt = -Omega'L_r Omega - V'L_t V (eq 37).
    """

    name = "permanent"
    layout: ClassVar[StateLayout] = REDUCED
    equation = "eqs 20, 21"

    def quantities_columns(self, y: np.ndarray, outputs: bool = True) -> dict[str, np.ndarray]:
        """Eqs 20, 21 (corrected) and eq 32 in columns form (see
        :meth:`Variant.quantities_columns`). Without ``outputs`` E, F (zero by
        construction) and Lambda are skipped: the state rate does not need them."""
        body, gains = self.body, self.gains
        q = self.layout.split_columns(y)
        theta, omega = q["theta"], q["omega"]
        r, r_hat = body.attachment_point, body.r_hat
        a, b = rotation_and_rate_columns(theta)
        q["rotation_matrix"], q["euler_rate_matrix"] = a, b
        a_r = matvec_columns(a, r)
        omega_x_r = r_hat.T @ omega  # Omega x R = hat(R)' Omega
        x = as_column(r, a_r) - a_r  # X = R - A R
        v = -matvec_columns(a, omega_x_r)  # V = A hat(R) Omega
        q["position"], q["velocity"] = x, v
        q["torque_n"] = torque_n(b, theta, omega, gains)
        q["force_h"] = h = force_h(x, v, gains)
        applied = as_column(body.weight, h) + h  # G + H [N], inertial frame
        torque = (
            -cross_columns(omega, body.pivot_inertia @ omega)
            + q["torque_n"]
            - r_hat @ matTvec_columns(a, applied)
        )
        omega_dot = body.pivot_inertia_inv @ torque
        if outputs:
            q["constraint_error"] = x + a_r - as_column(r, x)
            q["constraint_rate"] = v + matvec_columns(a, omega_x_r)
            # dV/dt = A (R x dOmega/dt) - A (Omega x (Omega x R))
            accel = matvec_columns(a, r_hat @ omega_dot - cross_columns(omega, omega_x_r))
            q["constraint_force"] = body.mass * accel - applied
        q["state_rate"] = self.layout.join_columns(theta=matvec_columns(b, omega), omega=omega_dot)
        return q

    def constraint_energy(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])

    def constraint_dissipation(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])

    def full_state(self, y: np.ndarray) -> np.ndarray:
        """The 12-state vector (Theta, Omega, X, V) of reduced states y, shape (..., 12)."""
        q = self.quantities(y)
        return FULL_BODY.join(**{b: q[b] for b in FULL_BODY.blocks})

    def full_state_variant(self) -> "PermanentFullState":
        """The independent 12-state formulation of the same constraint (eqs 15-17)."""
        return PermanentFullState(self.body, self.gains)


class PermanentFullState(FullBodyVariant):
    """The 12-state body of eq 1 with Lambda solved from the acceleration constraint (eq 15).

    dF/dt = dV/dt - A hat(R) dOmega/dt + A hat(Omega)^2 R = 0 with eq 1 substituted gives
    [I/m + (A hat(R)) J^-1 (A hat(R))'] Lambda = A hat(R) J^-1 (f + N) - (G + H)/m - A hat(Omega)^2 R.
    Used to check :class:`Permanent`; not in the variant registry.
    """

    name = "permanent_full_state"
    equation = "eq 15"
    constraint_inputs = ()

    def constraint_law(self, q: dict[str, np.ndarray]) -> np.ndarray:
        """Lambda [N] of eq 15 (columns form), solved state by state."""
        body = self.body
        omega, a = q["omega"], q["rotation_matrix"]
        r_hat, j_inv = body.r_hat, body.inertia_inv
        rhs = (
            matvec_columns(a, r_hat @ (j_inv @ (gyroscopic(body.inertia, omega) + q["torque_n"])))
            - (as_column(body.weight, omega) + q["force_h"]) / body.mass
            - matvec_columns(a, cross_columns(omega, cross_columns(omega, body.attachment_point)))
        )
        a_r = np.moveaxis(a, (0, 1), (-2, -1)) @ r_hat  # A hat(R), stacked rows (..., 3, 3)
        m_c = np.eye(3) / body.mass + a_r @ j_inv @ np.swapaxes(a_r, -1, -2)
        lam = np.linalg.solve(m_c, np.moveaxis(rhs, 0, -1)[..., None])[..., 0]
        return np.moveaxis(lam, -1, 0)

    def constraint_energy(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])

    def constraint_dissipation(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])
