"""Frozen physical inputs of a run: the rigid body and the gains (Table 1, eqs 22-24, 39, 40).

These are plain data; validation happens once, when a configuration is loaded
(:mod:`rbstab.config`). The core trusts what it finds here.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from types import SimpleNamespace

import numpy as np

from .kinematics import (
    ConstantMatrix,
    ConstantVector,
    cross_columns,
    hat,
    neg_columns,
    rate_matTvec_columns,
    sub_columns,
)

__all__ = ["RigidBody", "Gains", "gyroscopic", "torque_n", "force_h"]


@dataclass(frozen=True, eq=False)
class RigidBody:
    """One rigid body (Table 1).

    Attributes
    ----------
    mass : float
        m [kg], > 0.
    inertia : ndarray, shape (3, 3)
        J [kg m^2] about the centre of mass, body frame, symmetric positive definite.
    attachment_point : ndarray, shape (3,)
        R [m], the point C in the body frame.
    gravity : ndarray, shape (3,)
        g [m/s^2] in the inertial frame; the weight is ``G = mass * g`` [N].
    """

    mass: float
    inertia: np.ndarray
    attachment_point: np.ndarray
    gravity: np.ndarray

    @cached_property
    def weight(self) -> np.ndarray:
        """G = m g [N], inertial frame, shape (3,)."""
        return self.mass * np.asarray(self.gravity, dtype=float)

    @cached_property
    def inertia_inv(self) -> np.ndarray:
        """J^-1 [1/(kg m^2)], shape (3, 3)."""
        return np.linalg.inv(self.inertia)

    @cached_property
    def r_hat(self) -> np.ndarray:
        """hat(R) [m], shape (3, 3)."""
        return hat(self.attachment_point)

    @cached_property
    def pivot_inertia(self) -> np.ndarray:
        """J_p = J - m hat(R)^2 [kg m^2], inertia about C (eq 21 corrected), shape (3, 3)."""
        return self.inertia - self.mass * self.r_hat @ self.r_hat

    @cached_property
    def pivot_inertia_inv(self) -> np.ndarray:
        """J_p^-1, shape (3, 3)."""
        return np.linalg.inv(self.pivot_inertia)

    @cached_property
    def columns(self) -> SimpleNamespace:
        """The body's constants prepared for the columns form (:mod:`rbstab.kinematics`),
        computed once: ``mass`` (float), ``attachment_point`` R and ``weight`` G
        (:class:`~rbstab.kinematics.ConstantVector`), and ``inertia``, ``inertia_inv``,
        ``pivot_inertia``, ``pivot_inertia_inv``
        (:class:`~rbstab.kinematics.ConstantMatrix`)."""
        return SimpleNamespace(
            mass=float(self.mass),
            attachment_point=ConstantVector(self.attachment_point),
            weight=ConstantVector(self.weight),
            inertia=ConstantMatrix(self.inertia),
            inertia_inv=ConstantMatrix(self.inertia_inv),
            pivot_inertia=ConstantMatrix(self.pivot_inertia),
            pivot_inertia_inv=ConstantMatrix(self.pivot_inertia_inv),
        )


@dataclass(frozen=True, eq=False)
class Gains:
    """Feedback and constraint gains, each symmetric positive definite, shape (3, 3).

    Attributes
    ----------
    k_t, l_t : ndarray
        Translational stiffness [N/m] and damping [N s/m] of H (eq 24).
    k_r, l_r : ndarray
        Rotational stiffness [N m/rad] and damping [N m s/rad] of N (eq 23).
    k_c, l_c : ndarray or None
        Constraint stiffness [N/m] and damping [N s/m] (eqs 22, 40).
    k_d, l_d : ndarray or None
        Embedded-controller stiffness [N/m] and damping [N s/m] (eq 22).
    k_s : float or None
        Sliding-mode force magnitude K_s [N] (eq 39).
    boundary_layer : float
        Sliding boundary-layer width phi [m]; 0 means a pure sign function.
    """

    k_t: np.ndarray
    l_t: np.ndarray
    k_r: np.ndarray
    l_r: np.ndarray
    k_c: np.ndarray | None = None
    l_c: np.ndarray | None = None
    k_d: np.ndarray | None = None
    l_d: np.ndarray | None = None
    k_s: float | None = None
    boundary_layer: float = 0.0

    @cached_property
    def l_d_inv(self) -> np.ndarray:
        """L_d^-1 [m/(N s)], shape (3, 3)."""
        return np.linalg.inv(self.l_d)

    @cached_property
    def columns(self) -> SimpleNamespace:
        """The configured gains as :class:`~rbstab.kinematics.ConstantMatrix` (columns
        form, computed once): ``k_t``, ``l_t``, ``k_r``, ``l_r``, and those of ``k_c``,
        ``l_c``, ``k_d``, ``l_d``, ``l_d_inv`` that are set (None otherwise); ``k_s``
        and ``boundary_layer`` as floats (``k_s`` None when unset)."""
        def op(m):
            return None if m is None else ConstantMatrix(m)

        return SimpleNamespace(
            k_t=op(self.k_t),
            l_t=op(self.l_t),
            k_r=op(self.k_r),
            l_r=op(self.l_r),
            k_c=op(self.k_c),
            l_c=op(self.l_c),
            k_d=op(self.k_d),
            l_d=op(self.l_d),
            l_d_inv=None if self.l_d is None else ConstantMatrix(self.l_d_inv),
            k_s=None if self.k_s is None else float(self.k_s),
            boundary_layer=float(self.boundary_layer),
        )


def gyroscopic(inertia: ConstantMatrix, omega):
    """f(Omega) = -Omega x (J Omega) [N m], body frame (eq 1).

    ``inertia``: J (``RigidBody.columns.inertia``); ``omega`` [rad/s] and the result in
    columns form (:mod:`rbstab.kinematics`).
    """
    return neg_columns(cross_columns(omega, inertia.apply(omega)))


def torque_n(b, theta, omega, gains: Gains):
    """Rotational feedback N = -B' K_r Theta - L_r Omega [N m], body frame (eq 23).

    Columns form (:mod:`rbstab.kinematics`).

    Parameters
    ----------
    b : nested tuple
        Euler-rate matrix B(theta) from :func:`~rbstab.kinematics.rotation_and_rate_columns`.
    theta, omega : vectors in columns form
        Euler angles [rad] and body angular velocity [rad/s].
    gains : Gains

    Returns
    -------
    vector in columns form
    """
    g = gains.columns
    return sub_columns(neg_columns(rate_matTvec_columns(b, g.k_r.apply(theta))), g.l_r.apply(omega))


def force_h(x, v, gains: Gains):
    """Translational feedback H = -K_t X - L_t V [N], inertial frame (eq 24).

    ``x`` [m], ``v`` [m/s] and the result in columns form (:mod:`rbstab.kinematics`).
    """
    g = gains.columns
    return sub_columns(neg_columns(g.k_t.apply(x)), g.l_t.apply(v))
