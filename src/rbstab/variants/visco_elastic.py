"""``visco_elastic``: the constraint imposed by a spring-damper at C (eqs 40-43)."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import ZERO, matvec, neg, quadratic_form, sub
from .base import Variant

__all__ = ["ViscoElastic"]


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


class ViscoElastic(Variant):
    """Lambda = -K_c E - L_c F (eq 40).

    v = v_t + v_r + E'K_c E/2 (eqs 41, 42); dv/dt = -V'L_t V - Omega'L_r Omega - F'L_c F (eq 43).
    """

    name = "visco_elastic"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c")
    equation = "eq 40"
