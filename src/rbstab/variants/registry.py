"""The controller variants as classes of the :class:`~rbstab.variants.base.Variant` protocol,
and their registry.

Each class names a variant (``controller.variant``; its number in the compiled kernels
and its state layout come from :mod:`rbstab.layout` by that name) and the gains it
needs; its physics (constraint law, stored energy, dissipated power) is compiled code in
the variant's own module (:mod:`.free`, :mod:`.permanent`, :mod:`.sliding`,
:mod:`.visco_elastic`, :mod:`.embedded`), put together by :mod:`rbstab.variants.kernels`.
"""

from __future__ import annotations

import numpy as np

from ..layout import FULL_BODY
from ..model import Gains, RigidBody
from .base import Variant, rest_equilibria

__all__ = ["VARIANTS", "Free", "Permanent", "Sliding", "ViscoElastic", "Embedded", "record_offset", "record_offsets"]


class Free(Variant):
    """Free rigid body under the feedback N, H (eqs 1, 23, 24, 29, 30).

    v = v_t + v_r - X'G + G'K_t^-1 G / 2 and dv/dt = -V'L_t V - Omega'L_r Omega.
    """

    name = "free"
    equation = "eqs 1, 23, 24, 29, 30"


class Permanent(Variant):
    """Rigid body rotating about the fixed point C (Euler's equation about C).

    J_p dOmega/dt = -Omega x (J_p Omega) + N - hat(R) A'(G + H),  J_p = J - m hat(R)^2
    (eq 21, corrected: the paper's extra term hat(R) hat(Omega) Omega is identically zero
    and its sign of the hat(Omega)^2 R term is inconsistent; see docs/physics.md).
    Reconstruction: X = R - A R, V = A hat(R) Omega;
    Lambda = m (A hat(R) dOmega/dt - A hat(Omega)^2 R) - G - H.
    v = v_t + v_r - X'G + h (eqs 31, 34); dv/dt = -Omega'L_r Omega - V'L_t V (eq 37).
    """

    name = "permanent"
    equation = "eqs 20, 21"
    #: On the reduced state (Theta, Omega), v is positive definite with K_r alone and
    #: dv/dt <= -Omega'L_r Omega (eqs 34, 37): K_t and L_t only add terms >= 0 to v and <= 0
    #: to dv/dt, so they may be singular (zero) without loss.
    definite_gains = ("k_r", "l_r")

    def full_state(self, y: np.ndarray) -> np.ndarray:
        """The 12-state vector (Theta, Omega, X, V) of reduced states y, shape (..., 12)."""
        q = self.evaluate(y)
        return FULL_BODY.join(**{b: q[b] for b in FULL_BODY.blocks})


class Sliding(Variant):
    """Lambda = -K_s sgn(E) (eq 39); with a boundary layer phi > 0, sgn(E) -> tanh(E/phi).

    The force derives from the potential K_s sum|E_i| (phi = 0) or
    K_s phi sum log cosh(E_i/phi) (phi > 0), so v = v_t + v_r + that potential and
    dv/dt = -V'L_t V - Omega'L_r Omega (for phi = 0 on every smooth piece of the Filippov
    motion: off the surfaces F'Lambda and d(K_s |E|_1)/dt cancel, on a sliding axis both
    vanish). The pure sign law chatters; :func:`rbstab.simulator.simulate` integrates it
    with :mod:`rbstab.engine.switching`, in the modes above (docs/sliding.md).
    """

    name = "sliding"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_s")
    equation = "eq 39"

    @property
    def smooth(self) -> bool:
        """False for the pure sign law (boundary_layer 0)."""
        return self.gains.boundary_layer > 0


class ViscoElastic(Variant):
    """Lambda = -K_c E - L_c F (eq 40).

    v = v_t + v_r + E'K_c E/2 (eqs 41, 42); dv/dt = -V'L_t V - Omega'L_r Omega - F'L_c F (eq 43).
    """

    name = "visco_elastic"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c")
    equation = "eq 40"


class Embedded(Variant):
    """dD/dt = L_d^-1 (K_c (E - D) - K_d D),  Lambda = -K_c (E - D) - L_c F (eq 22).

    15 states: the body's 12 and D [m] (inertial frame).
    v = v_t + v_r + (E-D)'K_c(E-D)/2 + D'K_d D/2 (eqs 44, 45);
    dv/dt = -V'L_t V - Omega'L_r Omega - F'L_c F - dD/dt'L_d dD/dt (eq 46).
    """

    name = "embedded"
    required_gains = ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d")
    equation = "eq 22"


#: name -> variant class (the values allowed for ``controller.variant``).
VARIANTS: dict[str, type[Variant]] = {
    cls.name: cls for cls in (Free, Permanent, Sliding, ViscoElastic, Embedded)
}


def record_offset(record: np.void, gravity: np.ndarray, name: str) -> float:
    """h [J] (``Variant.lyapunov_offset``, eq 30) of the body and gains of one
    :data:`rbstab.model.PARAMETERS` record under ``gravity`` [m/s^2] (3,) with the variant
    ``name``'s law, without disturbances (the undisturbed equilibrium's)."""
    cls = VARIANTS[name]
    body = RigidBody(float(record["mass"]), record["inertia"].copy(), record["attachment_point"].copy(),
                     np.array(gravity, dtype=float))
    used = cls.required_gains
    gains = Gains(**{g: record[g].copy() for g in used if g != "k_s"},
                  k_s=float(record["k_s"]) if "k_s" in used else None,
                  boundary_layer=float(record["boundary_layer"]) if "k_s" in used else 0.0)
    return cls(body, gains).lyapunov_offset


def record_offsets(records: np.ndarray, gravity: np.ndarray, name: str) -> np.ndarray:
    """h [J], shape (k,): :func:`record_offset` of each of the :data:`rbstab.model.PARAMETERS`
    ``records`` (k,) under ``gravity`` (k, 3) [m/s^2, inertial frame] with the variant
    ``name``'s law (a key of :data:`VARIANTS`; KeyError otherwise): all at once where the law is smooth
    (:func:`rbstab.variants.base.rest_equilibria`; each record's h as it alone gives it),
    record by record where that finds no minimum (or for the pure sign law)."""
    out = np.full(len(records), np.nan)
    smooth = np.flatnonzero(records["boundary_layer"] > 0.0) if name == "sliding" else np.arange(len(records))
    if len(smooth):
        out[smooth] = rest_equilibria(VARIANTS[name], records[smooth])[1]
    for i in np.flatnonzero(np.isnan(out)):
        out[i] = record_offset(records[i], gravity[i], name)
    return out
