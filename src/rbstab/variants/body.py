"""Eq 1 under a constraint force Lambda at C, and the terms of v that every variant has
(eq 25): compiled physics shared by the variants' modules and :mod:`rbstab.variants.kernels`."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import add, cross, dot, matTvec, matvec, quadratic_form, scale
from ..model import gyroscopic

__all__ = ["body_rates", "constraint_error", "constraint_rate", "body_energy", "body_dissipation"]


@jit(forceinline=True)
def body_rates(omega, v, a, b, torque_n, force_h, constraint_force, p):
    """Eq 1 under the force Lambda at C; returns (dTheta/dt, dOmega/dt, dX/dt, dV/dt).

    dTheta/dt = B Omega
    J dOmega/dt = f(Omega) + N + hat(R) A' Lambda
    dX/dt = V
    m dV/dt = G + H + Lambda
    """
    r = p.attachment_point
    torque = add(add(gyroscopic(p.inertia, omega), torque_n), cross(r, matTvec(a, constraint_force)))
    force = add(add(p.weight, force_h), constraint_force)
    return matvec(b, omega), matvec(p.inertia_inv, torque), v, scale(1.0 / p.mass, force)


@jit(forceinline=True)
def constraint_error(x, a, p):
    """E = X + A R - R [m], inertial frame (eq 4)."""
    r = p.attachment_point
    ar = matvec(a, r)
    return (x[0] + ar[0] - r[0], x[1] + ar[1] - r[1], x[2] + ar[2] - r[2])


@jit(forceinline=True)
def constraint_rate(omega, v, a, p):
    """F = dE/dt = V + A (Omega x R) = V - A hat(R) Omega [m/s], inertial frame (eq 4)."""
    return add(v, matvec(a, cross(omega, p.attachment_point)))


@jit(forceinline=True)
def body_energy(theta, omega, x, v, p):
    """v_t, v_r (eq 25) and the gravity term -X'G + h [J]."""
    translational = 0.5 * p.mass * dot(v, v) + 0.5 * quadratic_form(x, p.k_t)
    rotational = 0.5 * quadratic_form(omega, p.inertia) + 0.5 * quadratic_form(theta, p.k_r)
    gravity = -dot(x, p.weight) + p.lyapunov_offset
    return translational, rotational, gravity


@jit(forceinline=True)
def body_dissipation(omega, v, p):
    """Power dissipated by the feedback, V'L_t V + Omega'L_r Omega [W] (eq 29)."""
    return quadratic_form(v, p.l_t) + quadratic_form(omega, p.l_r)
