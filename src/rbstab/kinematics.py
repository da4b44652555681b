"""Rigid-body kinematics as pure functions (paper section 2, physics-notes "Frames").

Two array forms
---------------
*Stacked rows* (the public form of rbstab): a vector is an array of shape ``(3,)`` or a
stack of shape ``(..., 3)``, a matrix ``(3, 3)`` or ``(..., 3, 3)``. :func:`hat`,
:func:`rotation_matrix`, :func:`euler_rate_matrix`, :func:`rotation_and_rate`,
:func:`cross`, :func:`matvec`, :func:`matTvec` and :func:`quadratic_form` take and
return this form, so the same code serves a single state and the post-processing of a
whole trajectory.

*Columns* (the right-hand side's working form, the ``*_columns`` functions): a stack of
m vectors is the ``(3, m)`` array whose columns are the vectors, so a constant matrix
acts on the whole stack as one product ``K @ X`` and each component ``X[i]`` is one
contiguous row; a stack of m matrices is a ``(3, 3, m)`` array with ``M[i, j]`` the row
of (i, j) entries. One vector is still ``(3,)`` and one matrix ``(3, 3)``: for a single
state both forms are the same arrays. The variants integrate in this form (it makes
each numpy call act on whole rows instead of on strided triples, see
``benchmarks/rhs.py``) and convert to stacked rows at their public boundary
(:func:`to_columns`, :func:`from_columns`).

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
    "rotation_and_rate",
    "cross",
    "matvec",
    "matTvec",
    "quadratic_form",
    "to_columns",
    "from_columns",
    "as_column",
    "rotation_and_rate_columns",
    "cross_columns",
    "matvec_columns",
    "matTvec_columns",
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


# -- A(theta) and B(theta) from one evaluation of sin and cos -----------------------
def _fill_rotation(out: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Write the entries of ``A = Rx(t1) Ry(t2) Rz(t3)`` (eq 2) into ``out[i, j]``.

    ``c``, ``s``: cos and sin of the three angles in columns form, shape (3, ...);
    ``out``: shape (3, 3, ...).
    """
    c1, c2, c3 = c
    s1, s2, s3 = s
    s1s2, c1s2 = s1 * s2, c1 * s2
    out[0, 0] = c2 * c3
    out[0, 1] = -c2 * s3
    out[0, 2] = s2
    out[1, 0] = c1 * s3 + s1s2 * c3
    out[1, 1] = c1 * c3 - s1s2 * s3
    out[1, 2] = -s1 * c2
    out[2, 0] = s1 * s3 - c1s2 * c3
    out[2, 1] = s1 * c3 + c1s2 * s3
    out[2, 2] = c1 * c2
    return out


def _fill_rate(out: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Write the entries of ``B(theta)`` (eq 1, middle row corrected) into ``out[i, j]``.

    ``c``, ``s``: cos and sin of the three angles (only t2, t3 enter), shape (3, ...);
    ``out``: shape (3, 3, ...).
    """
    c2, c3 = c[1], c[2]
    s2, s3 = s[1], s[2]
    c3_c2, s3_c2 = c3 / c2, s3 / c2
    out[0, 0] = c3_c2
    out[0, 1] = -s3_c2
    out[0, 2] = 0.0
    out[1, 0] = s3
    out[1, 1] = c3
    out[1, 2] = 0.0
    out[2, 0] = -s2 * c3_c2
    out[2, 1] = s2 * s3_c2
    out[2, 2] = 1.0
    return out


def _rows_of_entries(m: np.ndarray) -> np.ndarray:
    """Matrices with entries first, shape (3, 3, ...) -> stacked rows, shape (..., 3, 3)."""
    return np.ascontiguousarray(np.moveaxis(m, (0, 1), (-2, -1)))


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
    theta = np.moveaxis(np.asarray(theta, dtype=float), -1, 0)
    a = _fill_rotation(np.empty((3,) + theta.shape), np.cos(theta), np.sin(theta))
    return _rows_of_entries(a)


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
    theta = np.moveaxis(np.asarray(theta, dtype=float), -1, 0)
    b = _fill_rate(np.empty((3,) + theta.shape), np.cos(theta), np.sin(theta))
    return _rows_of_entries(b)


def rotation_and_rate(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A(theta), B(theta))`` from one evaluation of sin and cos (eqs 1, 2).

    Equal to ``(rotation_matrix(theta), euler_rate_matrix(theta))``.

    Parameters
    ----------
    theta : array_like, shape (3,) or (..., 3)
        Euler angles [rad]; ``|theta_2| < pi/2`` (eq 5).

    Returns
    -------
    a, b : ndarray, shape (3, 3) or (..., 3, 3)
        Rotation body -> inertial and Euler-rate matrix, stacked rows.
    """
    theta = np.asarray(theta, dtype=float)
    a, b = rotation_and_rate_columns(np.moveaxis(theta, -1, 0))
    return _rows_of_entries(a), _rows_of_entries(b)


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


# -- columns form (see the module docstring) -----------------------------------------
def to_columns(y: np.ndarray) -> np.ndarray:
    """Stacked rows -> columns: shape (n,) stays (n,); (..., n) -> contiguous (n, m).

    The leading dimensions are flattened (m = their product); :func:`from_columns`
    restores them.
    """
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        return y
    return np.ascontiguousarray(y.reshape(-1, y.shape[-1]).T)


def from_columns(x: np.ndarray, batch_shape: tuple[int, ...]) -> np.ndarray:
    """Columns -> stacked rows, the inverse of :func:`to_columns`.

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, m), or matrices (3, 3) or (3, 3, m)
        Columns of vectors of any length n, or matrices with entries first.
    batch_shape : tuple of int
        The leading dimensions of the stacked rows (``()`` for one vector), product m.

    Returns
    -------
    ndarray, shape batch_shape + (n,) or batch_shape + (3, 3), C-contiguous.
    """
    if not batch_shape:
        return x
    if x.ndim == 2:
        return np.ascontiguousarray(x.T).reshape(batch_shape + x.shape[:1])
    return _rows_of_entries(x).reshape(batch_shape + x.shape[:2])


def as_column(r: np.ndarray, like: np.ndarray) -> np.ndarray:
    """Constant vector ``r`` (shape (3,)) shaped to broadcast against columns ``like``.

    ``like`` of shape (3,) gives ``r``; of shape (3, m) gives ``r[:, None]``. Adding a
    (3,) array to a (3, m) stack directly would broadcast along the wrong axis (silently
    so when m == 3).
    """
    return r.reshape(r.shape + (1,) * (like.ndim - 1))


def rotation_and_rate_columns(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A(theta), B(theta))`` of a columns stack, from one sin and one cos call (eqs 1, 2).

    Parameters
    ----------
    theta : ndarray, shape (3,) or (3, ...)
        Euler angles [rad] in columns form; ``|theta_2| < pi/2`` (eq 5).

    Returns
    -------
    a, b : ndarray, shape (3, 3) or (3, 3, ...)
        ``A`` (body -> inertial, eq 2) and ``B`` (``d(theta)/dt = B omega``, eq 1,
        middle row corrected), entries first: ``a[i, j]`` is the (i, j) entry of every
        matrix of the stack. Apply them with :func:`matvec_columns`,
        :func:`matTvec_columns`.
    """
    c, s = np.cos(theta), np.sin(theta)
    shape = (3, 3) + theta.shape[1:]
    return _fill_rotation(np.empty(shape), c, s), _fill_rate(np.empty(shape), c, s)


def cross_columns(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` in columns form: a, b shape (3,) or (3, ...) (broadcast); a constant
    (3,) operand may be paired with a stack."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def matvec_columns(mat: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``mat x`` in columns form.

    Parameters
    ----------
    mat : ndarray, shape (3, 3) or (3, 3, m)
        One matrix (a constant, or the matrix of one state) or a stack, entries first.
    x : ndarray, shape (3,) or (3, m)
        One vector or a stack; a single vector may be paired with a stack of matrices
        and a single matrix with a stack of vectors.

    Returns
    -------
    ndarray, shape (3,) or (3, m)
    """
    if mat.ndim == 2 and x.ndim <= 2:
        return mat @ x
    return np.einsum("ij...,j...->i...", mat, x)


def matTvec_columns(mat: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``mat' x`` in columns form; shapes as :func:`matvec_columns`."""
    if mat.ndim == 2 and x.ndim <= 2:
        return mat.T @ x
    return np.einsum("ji...,j...->i...", mat, x)
