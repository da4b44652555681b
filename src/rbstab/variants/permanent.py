"""``permanent``: C pinned; the reduced 6-state system about the fixed point (eqs 18-21, 31-37).

The point C sits at its reference position (E = F = 0). The integrated state is
(Theta, Omega); X, V and the constraint force are reconstructed from it (eq 32 with
X_e = 0, eq 20). The independent check is the 12-state body of eq 1 with Lambda solved
from the acceleration constraint (eqs 15-17), in ``tests/reference.py``: both must give the
same trajectory.
"""

from __future__ import annotations

from ..jit import jit
from ..kinematics import ZERO, add, cross, matTvec, matvec, neg, rotation_and_rate_of, scale, sub, vector
from ..model import force_h, gyroscopic, torque_n
from .disturbances import disturbance_wrench

__all__ = ["quantities", "pin_motion"]


@jit(forceinline=True)
def pin_motion(omega, a, p):
    """X = R - A R [m] and V = -A (Omega x R) [m/s] (eq 32 with X_e = 0), inertial frame:
    the centre of mass of the body pinned at C, from Omega [rad/s] (body frame) and A."""
    r = p.attachment_point
    return sub(r, matvec(a, r)), neg(matvec(a, cross(omega, r)))


@jit(forceinline=True)
def quantities(t, y, p):
    """Eqs 20, 21 (corrected) and eq 32 at the reduced state y = (Theta, Omega), time t.

    J_p dOmega/dt = -Omega x (J_p Omega) + N + T - hat(R) A'(G + H + F),  J_p = J - m hat(R)^2
    X = R - A R,  V = A hat(R) Omega = -A (Omega x R)
    Lambda = m dV/dt - G - H - F,  dV/dt = A (R x dOmega/dt) - A (Omega x (Omega x R))

    with the disturbances' force F (inertial frame) and torque T about the centre of mass
    (body frame; :func:`rbstab.variants.disturbances.disturbance_wrench`), zero without.

    Returns (theta, omega, x, v, a, b, torque_n, force_h, constraint_force, dOmega/dt,
    F, T).
    """
    theta, omega = vector(y, 0), vector(y, 3)
    r = p.attachment_point
    a, b = rotation_and_rate_of(theta)
    omega_x_r = cross(omega, r)
    x, v = pin_motion(omega, a, p)
    n = torque_n(b, theta, omega, p)
    h = force_h(x, v, p)
    applied = add(p.weight, h)  # G + H [N], inertial frame
    moment = n
    if p.disturbance_count > 0.0:
        force_d, torque_d = disturbance_wrench(t, a, p)
        applied = add(applied, force_d)
        moment = add(n, torque_d)
    else:
        force_d, torque_d = ZERO, ZERO
    torque = sub(add(gyroscopic(p.pivot_inertia, omega), moment), cross(r, matTvec(a, applied)))
    omega_dot = matvec(p.pivot_inertia_inv, torque)
    acceleration = matvec(a, sub(cross(r, omega_dot), cross(omega, omega_x_r)))
    constraint_force = sub(scale(p.mass, acceleration), applied)
    return theta, omega, x, v, a, b, n, h, constraint_force, omega_dot, force_d, torque_d
