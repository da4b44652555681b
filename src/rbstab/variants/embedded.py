"""``embedded``: a spring-damper network with internal state D (eqs 22, 44-46)."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import matvec, neg, quadratic_form, sub

__all__ = ["constraint_force", "constraint_energy", "constraint_dissipation"]


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
