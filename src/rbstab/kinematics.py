"""Rigid-body kinematics as pure functions (paper section 2, physics-notes "Frames").

Every function accepts a single vector of shape ``(3,)`` or a stack of shape
``(..., 3)`` and returns arrays with the same leading dimensions, so the same code
serves a right-hand-side evaluation and the post-processing of a whole trajectory.

Conventions
-----------
- ``theta = (t1, t2, t3)``: Euler angles [rad], ``A = A1(t1) A2(t2) A3(t3) = Rx Ry Rz``
  (intrinsic x-y'-z'') maps body-frame (bcs) vectors to the inertial frame (ics), eq 2.
- ``omega``: angular velocity [rad/s] in the body frame; ``dA/dt = A hat(omega)``.
- ``hat(r) w = r x w`` (the paper's "R check").
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "hat",
    "rotation_matrix",
    "euler_rate_matrix",
    "cross",
    "matvec",
    "matTvec",
    "quadratic_form",
    "GIMBAL_LOCK_ANGLE",
]

#: |theta_2| at which B(theta) is singular (eq 5).
GIMBAL_LOCK_ANGLE = np.pi / 2


def hat(r: np.ndarray) -> np.ndarray:
    """Skew matrix of a vector, ``hat(r) @ w == cross(r, w)``.

    Parameters
    ----------
    r : array_like, shape (3,) or (..., 3)
        Vector in any frame.

    Returns
    -------
    ndarray, shape (3, 3) or (..., 3, 3)
        The paper's "R check" matrix (section 2).
    """
    r = np.asarray(r, dtype=float)
    out = np.zeros(r.shape + (3,))
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    out[..., 0, 1] = -z
    out[..., 0, 2] = y
    out[..., 1, 0] = z
    out[..., 1, 2] = -x
    out[..., 2, 0] = -y
    out[..., 2, 1] = x
    return out


def rotation_matrix(theta: np.ndarray) -> np.ndarray:
    """Rotation matrix ``A(theta) = A1(t1) A2(t2) A3(t3)`` (eq 2), body -> inertial.

    Parameters
    ----------
    theta : array_like, shape (3,) or (..., 3)
        Euler angles [rad], rotation order x-y'-z''.

    Returns
    -------
    ndarray, shape (3, 3) or (..., 3, 3)
        Orthonormal with determinant 1; ``A.T`` maps inertial to body vectors.
    """
    theta = np.asarray(theta, dtype=float)
    c = np.cos(theta)
    s = np.sin(theta)
    c1, c2, c3 = c[..., 0], c[..., 1], c[..., 2]
    s1, s2, s3 = s[..., 0], s[..., 1], s[..., 2]
    out = np.empty(theta.shape + (3,))
    out[..., 0, 0] = c2 * c3
    out[..., 0, 1] = -c2 * s3
    out[..., 0, 2] = s2
    out[..., 1, 0] = c1 * s3 + s1 * s2 * c3
    out[..., 1, 1] = c1 * c3 - s1 * s2 * s3
    out[..., 1, 2] = -s1 * c2
    out[..., 2, 0] = s1 * s3 - c1 * s2 * c3
    out[..., 2, 1] = s1 * c3 + c1 * s2 * s3
    out[..., 2, 2] = c1 * c2
    return out


def euler_rate_matrix(theta: np.ndarray) -> np.ndarray:
    """Euler-rate matrix ``B(theta)`` with ``d(theta)/dt = B omega`` (eq 1).

    This is the matrix consistent with ``dA/dt = A hat(omega)`` for ``A = Rx Ry Rz``.
    The paper prints the middle row as ``[s3/c2, c3/c2, 0]``, which violates that
    identity (see docs/physics.md); the correct middle row is ``[s3, c3, 0]``.

    Parameters
    ----------
    theta : array_like, shape (3,) or (..., 3)
        Euler angles [rad]; ``|theta_2| < pi/2`` (eq 5).

    Returns
    -------
    ndarray, shape (3, 3) or (..., 3, 3)
        Singular (infinite entries) at ``|theta_2| = pi/2``, the gimbal lock.
    """
    theta = np.asarray(theta, dtype=float)
    c2 = np.cos(theta[..., 1])
    s2 = np.sin(theta[..., 1])
    c3 = np.cos(theta[..., 2])
    s3 = np.sin(theta[..., 2])
    out = np.zeros(theta.shape + (3,))
    out[..., 0, 0] = c3 / c2
    out[..., 0, 1] = -s3 / c2
    out[..., 1, 0] = s3
    out[..., 1, 1] = c3
    out[..., 2, 0] = -s2 * c3 / c2
    out[..., 2, 1] = s2 * s3 / c2
    out[..., 2, 2] = 1.0
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over stacks: shapes (3,) or (..., 3), broadcast; a faster np.cross."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def matvec(m: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``m @ x`` over stacks: m shape (3, 3) or (..., 3, 3), x shape (3,) or (..., 3)."""
    if m.ndim == 2:
        return x @ m.T
    return np.einsum("...ij,...j->...i", m, x)


def matTvec(m: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``m.T @ x`` over stacks: m shape (3, 3) or (..., 3, 3), x shape (3,) or (..., 3)."""
    if m.ndim == 2:
        return x @ m
    return np.einsum("...ji,...j->...i", m, x)


def quadratic_form(x: np.ndarray, m: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
    """``x' m y`` over stacks (``y`` defaults to ``x``); returns shape ``x.shape[:-1]``."""
    if y is None:
        y = x
    return np.sum(matvec(m, y) * x, axis=-1)
