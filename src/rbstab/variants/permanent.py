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

from ..kinematics import cross, euler_rate_matrix, matTvec, matvec, rotation_matrix
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

    def quantities(self, y: np.ndarray) -> dict[str, np.ndarray]:
        body, gains = self.body, self.gains
        q = self.layout.split(np.asarray(y, dtype=float))
        theta, omega = q["theta"], q["omega"]
        r = body.attachment_point
        a = rotation_matrix(theta)
        b = euler_rate_matrix(theta)
        a_r = matvec(a, r)
        omega_x_r = cross(omega, r)
        x = r - a_r
        v = -matvec(a, omega_x_r)  # A hat(R) Omega
        q["position"], q["velocity"] = x, v
        q["constraint_error"] = x + a_r - r
        q["constraint_rate"] = v + matvec(a, omega_x_r)
        q["torque_n"] = torque_n(b, theta, omega, gains)
        q["force_h"] = h = force_h(x, v, gains)
        j_p = body.pivot_inertia
        applied = body.weight + h
        torque = -cross(omega, matvec(j_p, omega)) + q["torque_n"] - cross(r, matTvec(a, applied))
        omega_dot = matvec(body.pivot_inertia_inv, torque)
        accel = matvec(a, cross(r, omega_dot) - cross(omega, omega_x_r))
        q["constraint_force"] = body.mass * accel - applied
        q["state_rate"] = self.layout.join(theta=matvec(b, omega), omega=omega_dot)
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

    def constraint_law(self, q: dict[str, np.ndarray]) -> np.ndarray:
        body = self.body
        theta, omega = q["theta"], q["omega"]
        a = rotation_matrix(theta)
        a_r = a @ body.r_hat
        j_inv = body.inertia_inv
        m_c = np.eye(3) / body.mass + a_r @ j_inv @ np.swapaxes(a_r, -1, -2)
        rhs = (
            matvec(a_r, matvec(j_inv, gyroscopic(body.inertia, omega) + q["torque_n"]))
            - (body.weight + q["force_h"]) / body.mass
            - matvec(a, cross(omega, cross(omega, body.attachment_point)))
        )
        return np.linalg.solve(m_c, rhs[..., None])[..., 0]

    def constraint_energy(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])

    def constraint_dissipation(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])
