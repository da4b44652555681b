"""``sliding``: sliding-mode constraint force Lambda = -K_s sgn(E) (eq 39), optional boundary layer."""

from __future__ import annotations

import numpy as np

from .base import FullBodyVariant

__all__ = ["Sliding"]

_LOG2 = np.log(2.0)


def _log_cosh(u: np.ndarray) -> np.ndarray:
    """log(cosh(u)) without overflow."""
    a = np.abs(u)
    return a + np.log1p(np.exp(-2.0 * a)) - _LOG2


class Sliding(FullBodyVariant):
    """Lambda = -K_s sgn(E) (eq 39); with a boundary layer phi > 0, sgn(E) -> tanh(E/phi).

    The force derives from the potential K_s sum|E_i| (phi = 0) or
    K_s phi sum log cosh(E_i/phi) (phi > 0), so v = v_t + v_r + that potential and
    dv/dt = -V'L_t V - Omega'L_r Omega (almost everywhere when phi = 0: v has kinks where
    a component of E changes sign, and the pure sign law chatters).
    """

    name = "sliding"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_s")
    equation = "eq 39"
    constraint_inputs = ("constraint_error",)

    def __init__(self, body, gains) -> None:
        super().__init__(body, gains)
        self.smooth = gains.boundary_layer > 0

    def constraint_law(self, q: dict[str, np.ndarray]) -> np.ndarray:
        """Lambda [N], inertial frame, columns form (eq 39)."""
        e = q["constraint_error"]
        phi = self.gains.boundary_layer
        return -self.gains.k_s * (np.tanh(e / phi) if phi > 0 else np.sign(e))

    def constraint_energy(self, q: dict[str, np.ndarray]) -> np.ndarray:
        e = q["constraint_error"]
        phi = self.gains.boundary_layer
        if phi > 0:
            return self.gains.k_s * phi * np.sum(_log_cosh(e / phi), axis=-1)
        return self.gains.k_s * np.sum(np.abs(e), axis=-1)

    def constraint_dissipation(self, q: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(q["theta"].shape[:-1])
