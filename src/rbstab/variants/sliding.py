"""``sliding``: sliding-mode constraint force Lambda = -K_s sgn(E) (eq 39), optional boundary layer."""

from __future__ import annotations

import math

from ..jit import jit
from ..kinematics import ZERO
from .base import Variant

__all__ = ["Sliding"]

_LOG2 = math.log(2.0)


@jit(inline="always")
def sign(u):
    """sgn(u): -1, 0 or 1 (NaN for NaN)."""
    if u > 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    return u * 0.0


@jit(inline="always")
def log_cosh(u):
    """log(cosh(u)) without overflow."""
    a = abs(u)
    return a + math.log1p(math.exp(-2.0 * a)) - _LOG2


@jit(inline="always")
def switching(e, phi):
    """sgn(e) for phi = 0, tanh(e / phi) for a boundary layer phi > 0 [m]."""
    if phi > 0.0:
        return math.tanh(e / phi)
    return sign(e)


@jit(inline="always")
def constraint_force(e, f, d, p):
    """Lambda = -K_s sgn(E) [N], componentwise, inertial frame (eq 39); sgn -> tanh(E/phi)
    with a boundary layer phi > 0. No controller state."""
    phi = p.boundary_layer
    lam = (-p.k_s * switching(e[0], phi), -p.k_s * switching(e[1], phi), -p.k_s * switching(e[2], phi))
    return lam, ZERO


@jit(inline="always")
def constraint_energy(e, d, p):
    """The potential of Lambda [J]: K_s |E|_1, or K_s phi sum log cosh(E_i / phi)."""
    phi = p.boundary_layer
    if phi > 0.0:
        return p.k_s * phi * (log_cosh(e[0] / phi) + log_cosh(e[1] / phi) + log_cosh(e[2] / phi))
    return p.k_s * (abs(e[0]) + abs(e[1]) + abs(e[2]))


@jit(inline="always")
def constraint_dissipation(f, d_rate, p):
    return 0.0


class Sliding(Variant):
    """Lambda = -K_s sgn(E) (eq 39); with a boundary layer phi > 0, sgn(E) -> tanh(E/phi).

    The force derives from the potential K_s sum|E_i| (phi = 0) or
    K_s phi sum log cosh(E_i/phi) (phi > 0), so v = v_t + v_r + that potential and
    dv/dt = -V'L_t V - Omega'L_r Omega (almost everywhere when phi = 0: v has kinks where
    a component of E changes sign, and the pure sign law chatters).
    """

    name = "sliding"
    code = 2
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_s")
    equation = "eq 39"

    @property
    def smooth(self) -> bool:
        """False for the pure sign law (boundary_layer 0)."""
        return self.gains.boundary_layer > 0
