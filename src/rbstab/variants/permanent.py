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
    add_columns,
    add_constant_columns,
    cross_columns,
    div_columns,
    from_columns,
    matTvec_columns,
    matvec_columns,
    neg_columns,
    rate_matvec_columns,
    rotation_and_rate_columns,
    scale_columns,
    sub_columns,
    sub_constant_columns,
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

    def quantities_columns(self, y, outputs: bool = True, state_rate: bool = True) -> dict:
        """Eqs 20, 21 (corrected) and eq 32 in columns form (see
        :meth:`Variant.quantities_columns`). Without ``outputs`` E, F (zero by
        construction) and Lambda are skipped: the state rate does not need them."""
        body = self.body.columns
        q = self.layout.split_columns(y)
        theta, omega = q["theta"], q["omega"]
        r = body.attachment_point
        a, b = rotation_and_rate_columns(theta)
        q["rotation_matrix"], q["euler_rate_matrix"] = a, b
        a_r = matvec_columns(a, r)
        omega_x_r = cross_columns(omega, r)  # Omega x R = hat(R)' Omega
        x = neg_columns(sub_constant_columns(a_r, r))  # X = R - A R
        a_w = matvec_columns(a, omega_x_r)
        v = neg_columns(a_w)  # V = A hat(R) Omega = -A (Omega x R)
        q["position"], q["velocity"] = x, v
        q["torque_n"] = torque_n(b, theta, omega, self.gains)
        q["force_h"] = force_h(x, v, self.gains)
        applied = add_constant_columns(q["force_h"], body.weight)  # G + H [N], inertial frame
        torque = sub_columns(
            add_columns(gyroscopic(body.pivot_inertia, omega), q["torque_n"]),
            cross_columns(r, matTvec_columns(a, applied)),  # R x A'(G + H)
        )
        omega_dot = body.pivot_inertia_inv.apply(torque)
        if outputs:
            q["constraint_error"] = sub_constant_columns(add_columns(x, a_r), r)
            q["constraint_rate"] = add_columns(v, a_w)
            # dV/dt = A (R x dOmega/dt) - A (Omega x (Omega x R))
            accel = matvec_columns(a, sub_columns(cross_columns(r, omega_dot), cross_columns(omega, omega_x_r)))
            q["constraint_force"] = sub_columns(scale_columns(body.mass, accel), applied)  # m dV/dt - G - H
        if state_rate:
            q["state_rate"] = self.layout.join_columns(theta=rate_matvec_columns(b, omega), omega=omega_dot)
        return q

    def constraint_energy(self, q: dict) -> float:
        return 0.0

    def constraint_dissipation(self, q: dict) -> float:
        return 0.0

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

    def constraint_law(self, q: dict) -> tuple:
        """Lambda [N] of eq 15 (columns form), solved state by state."""
        body, cols = self.body, self.body.columns
        omega, a = q["omega"], q["rotation_matrix"]
        r = cols.attachment_point
        j_inv_moment = cols.inertia_inv.apply(add_columns(gyroscopic(cols.inertia, omega), q["torque_n"]))
        applied = add_constant_columns(q["force_h"], cols.weight)  # G + H
        rhs = sub_columns(
            sub_columns(matvec_columns(a, cross_columns(r, j_inv_moment)), div_columns(applied, cols.mass)),
            matvec_columns(a, cross_columns(omega, cross_columns(omega, r))),  # A hat(Omega)^2 R
        )
        shape = np.shape(omega[0])  # () for one state, (m,) for a stack
        a_r = from_columns(a, shape) @ body.r_hat  # A hat(R), stacked rows (..., 3, 3)
        m_c = np.eye(3) / body.mass + a_r @ body.inertia_inv @ np.swapaxes(a_r, -1, -2)
        lam = np.linalg.solve(m_c, from_columns(rhs, shape)[..., None])[..., 0]
        if not shape:
            return tuple(float(c) for c in lam)
        return (lam[:, 0], lam[:, 1], lam[:, 2])

    def constraint_energy(self, q: dict) -> float:
        return 0.0

    def constraint_dissipation(self, q: dict) -> float:
        return 0.0
