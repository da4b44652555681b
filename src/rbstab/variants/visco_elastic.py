"""``visco_elastic``: the constraint imposed by a spring-damper at C (eqs 40-43)."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import ZERO, matvec, neg, quadratic_form, sub

__all__ = ["constraint_force", "constraint_energy", "constraint_dissipation"]


@jit(forceinline=True)
def constraint_force(e, f, d, p):
    """Lambda = -K_c E - L_c F [N], inertial frame (eq 40); no controller state."""
    return sub(neg(matvec(p.k_c, e)), matvec(p.l_c, f)), ZERO


@jit(forceinline=True)
def constraint_energy(e, d, p):
    """E'K_c E / 2 [J] (eqs 41, 42)."""
    return 0.5 * quadratic_form(e, p.k_c)


@jit(forceinline=True)
def constraint_dissipation(f, d_rate, p):
    """F'L_c F [W] (eq 43)."""
    return quadratic_form(f, p.l_c)
