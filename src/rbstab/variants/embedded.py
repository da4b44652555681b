"""``embedded``: a spring-damper network with internal state D (eqs 22, 44-46)."""

from __future__ import annotations

from typing import ClassVar

from ..kinematics import neg_columns, quadratic_form_columns, sub_columns
from ..layout import EMBEDDED, StateLayout
from .base import FullBodyVariant

__all__ = ["Embedded"]


class Embedded(FullBodyVariant):
    """dD/dt = L_d^-1 (K_c (E - D) - K_d D),  Lambda = -K_c (E - D) - L_c F (eq 22).

    15 states: the body's 12 and D [m] (inertial frame).
    v = v_t + v_r + (E-D)'K_c(E-D)/2 + D'K_d D/2 (eqs 44, 45);
    dv/dt = -V'L_t V - Omega'L_r Omega - F'L_c F - dD/dt'L_d dD/dt (eq 46).
    """

    name = "embedded"
    layout: ClassVar[StateLayout] = EMBEDDED
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d")
    equation = "eq 22"

    def constraint_law(self, q: dict):
        """Lambda [N] and, into ``q``, dD/dt [m/s] (eq 22); columns form, inertial frame."""
        g = self.gains.columns
        d = q["controller_state"]
        spring = g.k_c.apply(sub_columns(q["constraint_error"], d))  # K_c (E - D)
        q["controller_rate"] = g.l_d_inv.apply(sub_columns(spring, g.k_d.apply(d)))
        return sub_columns(neg_columns(spring), g.l_c.apply(q["constraint_rate"]))

    def constraint_energy(self, q: dict):
        g = self.gains.columns
        d = q["controller_state"]
        return 0.5 * quadratic_form_columns(sub_columns(q["constraint_error"], d), g.k_c) + 0.5 * quadratic_form_columns(
            d, g.k_d
        )

    def constraint_dissipation(self, q: dict):
        g = self.gains.columns
        return quadratic_form_columns(q["constraint_rate"], g.l_c) + quadratic_form_columns(q["controller_rate"], g.l_d)
