"""``free``: no constraint, Lambda = 0; with gravity the body settles at X_e = K_t^-1 G (section 5.1)."""

from __future__ import annotations

from ..jit import jit
from ..kinematics import ZERO

__all__ = ["constraint_force", "constraint_energy", "constraint_dissipation"]


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
