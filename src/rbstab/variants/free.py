"""``free``: no constraint, Lambda = 0; with gravity the body settles at X_e = K_t^-1 G (section 5.1)."""

from __future__ import annotations

from .base import FullBodyVariant

__all__ = ["Free"]


class Free(FullBodyVariant):
    """Free rigid body under the feedback N, H (eqs 1, 23, 24, 29, 30).

    v = v_t + v_r - X'G + G'K_t^-1 G / 2 and dv/dt = -V'L_t V - Omega'L_r Omega.
    """

    name = "free"
    equation = "eqs 1, 23, 24, 29, 30"
    constraint_inputs = ()

    def constraint_law(self, q: dict) -> None:
        """No constraint force (Lambda = 0)."""
        return None

    def constraint_energy(self, q: dict) -> float:
        return 0.0

    def constraint_dissipation(self, q: dict) -> float:
        return 0.0
