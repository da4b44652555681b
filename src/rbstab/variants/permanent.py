"""``permanent``: C pinned; the reduced 6-state system about the fixed point (eqs 18-21, 31-37).

The point C sits at its reference position (E = F = 0). The integrated state is
(Theta, Omega); X, V and the constraint force are reconstructed from it (eq 32 with
X_e = 0, eq 20). The independent check is the 12-state body of eq 1 with Lambda solved
from the acceleration constraint (eqs 15-17), in ``tests/reference.py``: both must give the
same trajectory.
"""

from __future__ import annotations

from ..jit import jit
from ..kinematics import add, cross, matTvec, matvec, neg, rotation_and_rate_of, scale, sub, vector
from ..model import force_h, gyroscopic, torque_n

__all__ = ["quantities"]


@jit(forceinline=True)
def quantities(y, p):
    """Eqs 20, 21 (corrected) and eq 32 at the reduced state y = (Theta, Omega).

    J_p dOmega/dt = -Omega x (J_p Omega) + N - hat(R) A'(G + H),  J_p = J - m hat(R)^2
    X = R - A R,  V = A hat(R) Omega = -A (Omega x R)
    Lambda = m dV/dt - G - H,  dV/dt = A (R x dOmega/dt) - A (Omega x (Omega x R))

    Returns (theta, omega, x, v, a, b, torque_n, force_h, constraint_force, dOmega/dt).
    """
    theta, omega = vector(y, 0), vector(y, 3)
    r = p.attachment_point
    a, b = rotation_and_rate_of(theta)
    omega_x_r = cross(omega, r)
    x = sub(r, matvec(a, r))
    v = neg(matvec(a, omega_x_r))
    n = torque_n(b, theta, omega, p)
    h = force_h(x, v, p)
    applied = add(p.weight, h)  # G + H [N], inertial frame
    torque = sub(add(gyroscopic(p.pivot_inertia, omega), n), cross(r, matTvec(a, applied)))
    omega_dot = matvec(p.pivot_inertia_inv, torque)
    acceleration = matvec(a, sub(cross(r, omega_dot), cross(omega, omega_x_r)))
    constraint_force = sub(scale(p.mass, acceleration), applied)
    return theta, omega, x, v, a, b, n, h, constraint_force, omega_dot
