"""``embedded``: a spring-damper network with internal state D (eqs 22, 44-46)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..kinematics import quadratic_form
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

    def constraint_law(self, q: dict[str, np.ndarray]) -> np.ndarray:
        """Lambda [N] and, into ``q``, dD/dt [m/s] (eq 22); columns form, inertial frame."""
        g = self.gains
        d = q["controller_state"]
        spring = g.k_c @ (q["constraint_error"] - d)  # K_c (E - D)
        q["controller_rate"] = g.l_d_inv @ (spring - g.k_d @ d)
        return -spring - g.l_c @ q["constraint_rate"]

    def constraint_energy(self, q: dict[str, np.ndarray]) -> np.ndarray:
        g = self.gains
        d = q["controller_state"]
        return 0.5 * quadratic_form(q["constraint_error"] - d, g.k_c) + 0.5 * quadratic_form(d, g.k_d)

    def constraint_dissipation(self, q: dict[str, np.ndarray]) -> np.ndarray:
        g = self.gains
        return quadratic_form(q["constraint_rate"], g.l_c) + quadratic_form(q["controller_rate"], g.l_d)
