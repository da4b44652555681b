"""``embedded``: a spring-damper network with internal state D (eqs 22, 44-46)."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import matvec, neg, quadratic_form, sub
from .base import Variant

__all__ = ["Embedded"]


@jit(forceinline=True)
def constraint_force(e, f, d, p):
    """Lambda = -K_c (E - D) - L_c F [N] and dD/dt = L_d^-1 (K_c (E - D) - K_d D) [m/s] (eq 22)."""
    spring = matvec(p.k_c, sub(e, d))  # K_c (E - D)
    d_rate = matvec(p.l_d_inv, sub(spring, matvec(p.k_d, d)))
    return sub(neg(spring), matvec(p.l_c, f)), d_rate


@jit(forceinline=True)
def constraint_energy(e, d, p):
    """(E-D)'K_c(E-D)/2 + D'K_d D/2 [J] (eqs 44, 45)."""
    return 0.5 * quadratic_form(sub(e, d), p.k_c) + 0.5 * quadratic_form(d, p.k_d)


@jit(forceinline=True)
def constraint_dissipation(f, d_rate, p):
    """F'L_c F + dD/dt' L_d dD/dt [W] (eq 46)."""
    return quadratic_form(f, p.l_c) + quadratic_form(d_rate, p.l_d)


class Embedded(Variant):
    """dD/dt = L_d^-1 (K_c (E - D) - K_d D),  Lambda = -K_c (E - D) - L_c F (eq 22).

    15 states: the body's 12 and D [m] (inertial frame).
    v = v_t + v_r + (E-D)'K_c(E-D)/2 + D'K_d D/2 (eqs 44, 45);
    dv/dt = -V'L_t V - Omega'L_r Omega - F'L_c F - dD/dt'L_d dD/dt (eq 46).
    """

    name = "embedded"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d")
    equation = "eq 22"
