"""``sliding``: sliding-mode constraint force Lambda = -K_s sgn(E) (eq 39), optional boundary layer."""

from __future__ import annotations

import math

import numpy as np

from .base import FullBodyVariant

__all__ = ["Sliding"]

_LOG2 = math.log(2.0)


def _tanh(u):
    return math.tanh(u) if isinstance(u, float) else np.tanh(u)


def _sign(u):
    """sgn(u) (0 at 0, NaN for NaN), for a float or an array."""
    if not isinstance(u, float):
        return np.sign(u)
    if u > 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    return u * 0.0  # 0.0, or NaN for NaN


def _log_cosh(u):
    """log(cosh(u)) without overflow, for a float or an array."""
    if isinstance(u, float):
        a = abs(u)
        return a + math.log1p(math.exp(-2.0 * a)) - _LOG2
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

    def constraint_law(self, q: dict) -> tuple:
        """Lambda [N], inertial frame, columns form (eq 39)."""
        g = self.gains.columns
        k_s, phi = g.k_s, g.boundary_layer
        if phi > 0:
            return tuple(-k_s * _tanh(e / phi) for e in q["constraint_error"])
        return tuple(-k_s * _sign(e) for e in q["constraint_error"])

    def constraint_energy(self, q: dict):
        g = self.gains.columns
        k_s, phi = g.k_s, g.boundary_layer
        e0, e1, e2 = q["constraint_error"]
        if phi > 0:
            return k_s * phi * (_log_cosh(e0 / phi) + _log_cosh(e1 / phi) + _log_cosh(e2 / phi))
        return k_s * (abs(e0) + abs(e1) + abs(e2))

    def constraint_dissipation(self, q: dict) -> float:
        return 0.0
