"""``visco_elastic``: the constraint imposed by a spring-damper at C (eqs 40-43)."""

from __future__ import annotations

from ..kinematics import neg_columns, quadratic_form_columns, sub_columns
from .base import FullBodyVariant

__all__ = ["ViscoElastic"]


class ViscoElastic(FullBodyVariant):
    """Lambda = -K_c E - L_c F (eq 40).

    v = v_t + v_r + E'K_c E/2 (eqs 41, 42); dv/dt = -V'L_t V - Omega'L_r Omega - F'L_c F (eq 43).
    """

    name = "visco_elastic"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c")
    equation = "eq 40"

    def constraint_law(self, q: dict):
        """Lambda [N], inertial frame, columns form (eq 40)."""
        g = self.gains.columns
        return sub_columns(neg_columns(g.k_c.apply(q["constraint_error"])), g.l_c.apply(q["constraint_rate"]))

    def constraint_energy(self, q: dict):
        return 0.5 * quadratic_form_columns(q["constraint_error"], self.gains.columns.k_c)

    def constraint_dissipation(self, q: dict):
        return quadratic_form_columns(q["constraint_rate"], self.gains.columns.l_c)
