"""``free``: no constraint, Lambda = 0; with gravity the body settles at X_e = K_t^-1 G (section 5.1)."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import ZERO
from .base import Variant

__all__ = ["Free"]


@jit(forceinline=True)
def constraint_force(e, f, d, p):
    """Lambda = 0 [N]; no controller state (dD/dt = 0)."""
    return ZERO, ZERO


@jit(forceinline=True)
def constraint_energy(e, d, p):
    return 0.0


@jit(forceinline=True)
def constraint_dissipation(f, d_rate, p):
    return 0.0


class Free(Variant):
    """Free rigid body under the feedback N, H (eqs 1, 23, 24, 29, 30).

    v = v_t + v_r - X'G + G'K_t^-1 G / 2 and dv/dt = -V'L_t V - Omega'L_r Omega.
    """

    name = "free"
    equation = "eqs 1, 23, 24, 29, 30"
