"""Rigid-body kinematics as pure functions (paper section 2, physics-notes "Frames").

Two array forms
---------------
*Stacked rows* (the public form of rbstab): a vector is an array of shape ``(3,)`` or a
stack of shape ``(..., 3)``, a matrix ``(3, 3)`` or ``(..., 3, 3)``. :func:`hat`,
:func:`rotation_matrix`, :func:`euler_rate_matrix`, :func:`rotation_and_rate`,
:func:`cross`, :func:`matvec`, :func:`matTvec` and :func:`quadratic_form` take and
return this form.

*Columns* (the variants' working form, the ``*_columns`` functions and
:class:`ConstantMatrix`): a vector is the sequence of its three components
``(x0, x1, x2)``; for **one state** each component is a Python float, for a **stack** of
m states each is an array of shape (m,) (row i of the (3, m) array whose columns are the
vectors; such a (3, m) array is accepted as input too). A matrix is the nested sequence
of its entries, ``M[i][j]`` a component (a (3, 3, m) array is accepted as input). The
functions return tuples of components, and apply every operation elementwise (``+``,
``-``, ``*``, ``/`` on components, and cos, sin), never a matrix product, so:

- one model serves both integrators: for a single state (scipy's ``solve_ivp``) the
  arithmetic is plain Python floats, which costs far less than numpy's per-call overhead
  on (3,) arrays; for a stack each operation is one numpy call on whole rows;
- a state gets the same bits whatever else is in its stack (a matrix product hands
  different shapes to different BLAS kernels, which round differently), and the same
  bits as alone wherever ``math.cos``/``math.sin`` and numpy's cos/sin agree (both are
  the C library's on common builds);
- a constant matrix (a gain, an inertia) is applied through :class:`ConstantMatrix`,
  which skips its zero entries (a diagonal gain costs three products).

:func:`to_columns` and :func:`from_columns` convert between the two forms.

Conventions
-----------
- ``theta = (t1, t2, t3)``: Euler angles [rad], ``A = A1(t1) A2(t2) A3(t3) = Rx Ry Rz``
  (intrinsic x-y'-z'') maps body-frame (bcs) vectors to the inertial frame (ics), eq 2.
- ``omega``: angular velocity [rad/s] in the body frame; ``dA/dt = A hat(omega)``.
- ``hat(r) w = r x w`` (the paper's "R check").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

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
    "ConstantVector",
    "ConstantMatrix",
    "rotation_and_rate_columns",
    "rate_matvec_columns",
    "rate_matTvec_columns",
    "cross_columns",
    "matvec_columns",
    "matTvec_columns",
    "add_columns",
    "sub_columns",
    "neg_columns",
    "scale_columns",
    "div_columns",
    "dot_columns",
    "add_constant_columns",
    "sub_constant_columns",
    "dot_constant_columns",
    "quadratic_form_columns",
    "zeros_columns",
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


# -- A(theta) and B(theta): the one place that defines their entries -----------------
def _rotation_entries(c, s) -> tuple:
    """Entries of ``A = Rx(t1) Ry(t2) Rz(t3)`` (eq 2), ``A[i][j]``.

    ``c``, ``s``: cos and sin of the three angles, each a sequence of 3 components
    (floats, or arrays of one shape).
    """
    c1, c2, c3 = c
    s1, s2, s3 = s
    s1s2, c1s2 = s1 * s2, c1 * s2
    return (
        (c2 * c3, -(c2 * s3), s2),
        (c1 * s3 + s1s2 * c3, c1 * c3 - s1s2 * s3, -(s1 * c2)),
        (s1 * s3 - c1s2 * c3, s1 * c3 + c1s2 * s3, c1 * c2),
    )


def _rate_entries(c, s) -> tuple:
    """Entries of ``B(theta)`` (eq 1, middle row corrected), ``B[i][j]``; the structural
    zeros and the one of B are the Python floats 0.0 and 1.0. Only t2, t3 enter."""
    c2, c3 = c[1], c[2]
    s2, s3 = s[1], s[2]
    c3_c2, s3_c2 = c3 / c2, s3 / c2
    return (
        (c3_c2, -s3_c2, 0.0),
        (s3, c3, 0.0),
        (-(s2 * c3_c2), s2 * s3_c2, 1.0),
    )


def _cos_sin(theta) -> tuple:
    """cos and sin of three angles in columns form: ``math`` for floats (one state),
    one numpy call each for a stack."""
    t1, t2, t3 = _parts(theta)
    if isinstance(t1, float):
        return (math.cos(t1), math.cos(t2), math.cos(t3)), (math.sin(t1), math.sin(t2), math.sin(t3))
    theta = np.asarray(theta, dtype=float)
    return _parts(np.cos(theta)), _parts(np.sin(theta))


def _stacked_matrix(entries, shape: tuple[int, ...]) -> np.ndarray:
    """Nested entries (each broadcastable to ``shape``) -> array ``shape + (3, 3)``."""
    out = np.empty(shape + (3, 3))
    for i, row in enumerate(entries):
        for j, value in enumerate(row):
            out[..., i, j] = value
    return out


def _stacked_entries(theta: np.ndarray, entries) -> np.ndarray:
    theta = np.asarray(theta, dtype=float)
    t = np.moveaxis(theta, -1, 0)
    return _stacked_matrix(entries(np.cos(t), np.sin(t)), theta.shape[:-1])


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
    return _stacked_entries(theta, _rotation_entries)


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
    return _stacked_entries(theta, _rate_entries)


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
    t = np.moveaxis(theta, -1, 0)
    c, s = np.cos(t), np.sin(t)
    shape = theta.shape[:-1]
    return _stacked_matrix(_rotation_entries(c, s), shape), _stacked_matrix(_rate_entries(c, s), shape)


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
def _is_stack(x) -> bool:
    """Whether the vector ``x`` is a stack in array form, a (3, m) ndarray (fast path)."""
    return isinstance(x, np.ndarray) and x.ndim == 2


def _parts(x) -> Sequence:
    """The 3 components of a vector in columns form (indexing an array is much cheaper
    than iterating it)."""
    if isinstance(x, np.ndarray):
        return x[0], x[1], x[2]
    return x


def _pack(c0, c1, c2):
    """A vector from its components: a tuple for one state (floats), a (3, m) array for a
    stack (so that the vector-level operations that follow are one numpy call each)."""
    if type(c0) is np.ndarray:
        return np.array((c0, c1, c2))
    return (c0, c1, c2)


def to_columns(y: np.ndarray):
    """Stacked rows -> columns form.

    Parameters
    ----------
    y : array_like, shape (n,) or (..., n)
        One vector (e.g. a state) or a stack.

    Returns
    -------
    list of n floats, or ndarray of shape (n, m)
        For one vector its components as Python floats; for a stack the C-contiguous
        (n, m) array whose rows are the components (the leading dimensions flattened,
        m their product; :func:`from_columns` restores them).
    """
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        return y.tolist()
    return np.ascontiguousarray(y.reshape(-1, y.shape[-1]).T)


def from_columns(x, batch_shape: tuple[int, ...]) -> np.ndarray:
    """Columns form -> stacked rows, the inverse of :func:`to_columns`.

    Parameters
    ----------
    x : sequence of components, or nested sequence (a matrix)
        A vector of any length n (components floats, arrays of shape (m,), or scalars
        standing for a constant component; or an (n, m) array) or a 3x3 matrix of such
        entries (or a (3, 3, m) array).
    batch_shape : tuple of int
        The leading dimensions of the stacked rows (``()`` for one vector), product m.

    Returns
    -------
    ndarray, shape batch_shape + (n,) or batch_shape + (3, 3), C-contiguous.
    """
    first = x[0]
    if isinstance(first, Sequence) or np.ndim(first) == 2:  # a matrix of entries
        out = _stacked_matrix(x, (math.prod(batch_shape),) if batch_shape else ())
        return out.reshape(batch_shape + (3, 3))
    if not batch_shape:
        return np.array(x, dtype=float)
    m, n = math.prod(batch_shape), len(x)
    if isinstance(x, np.ndarray) and (n > 3 or m <= 1024):
        out = np.ascontiguousarray(x.T)  # one transposed copy: cheapest for a state
    else:  # a long (3, m) stack: three strided writes are several times cheaper
        out = np.empty((m, n))
        for i, component in enumerate(x):
            out[:, i] = component
    return out.reshape(batch_shape + (n,))


class ConstantVector(tuple):
    """A constant 3-vector (R, G) for the columns form: the tuple of its 3 floats, which
    also carries its (3, 1) array ``column`` for stacks in array form.

    Parameters
    ----------
    values : iterable of 3 numbers
    """

    def __new__(cls, values) -> "ConstantVector":
        obj = super().__new__(cls, (float(v) for v in values))
        if len(obj) != 3:
            raise ValueError(f"a constant vector has 3 components, got {len(obj)}")
        obj.column = np.array(obj).reshape(3, 1)
        obj.column.setflags(write=False)
        obj.is_zero = not any(obj)
        return obj


class ConstantMatrix:
    """A constant 3x3 matrix (a gain, an inertia) that acts on vectors in columns form.

    Products skip the zero entries: component i of ``M x`` is the sum of ``M[i, j] x_j``
    over the nonzero entries of row i, in column order, for one state (floats) and for a
    stack alike, so each state's result depends only on that state. A diagonal matrix
    costs three multiplications (for a stack in array form, one with its diagonal
    repeated to the stack's (3, m) shape: numpy broadcasts a (3, 1) column slowly).

    Parameters
    ----------
    matrix : array_like, shape (3, 3)
    """

    __slots__ = ("matrix", "diagonal", "_rows", "_diagonal_column", "_repeated")

    #: Stack sizes up to which the repeated diagonal is kept (at most 8 sizes at once).
    _CACHE_MAX_M = 8192

    def __init__(self, matrix) -> None:
        m = np.array(matrix, dtype=float)
        if m.shape != (3, 3):
            raise ValueError(f"a constant matrix has shape (3, 3), got {m.shape}")
        m.setflags(write=False)
        self.matrix = m
        #: The diagonal as floats when every off-diagonal entry is zero, else None.
        self.diagonal = (
            tuple(float(d) for d in np.diag(m)) if not np.any(m - np.diag(np.diag(m))) else None
        )
        self._rows = tuple(tuple((j, float(m[i, j])) for j in range(3) if m[i, j] != 0.0) for i in range(3))
        self._diagonal_column = np.diag(m).reshape(3, 1).copy()
        self._repeated: dict[int, np.ndarray] = {}

    def __repr__(self) -> str:
        return f"ConstantMatrix({self.matrix.tolist()})"

    def _diagonal_repeated(self, m: int) -> np.ndarray:
        """The diagonal as a (3, m) array (kept for small m)."""
        out = self._repeated.get(m)
        if out is None:
            out = np.repeat(self._diagonal_column, m, axis=1)
            if m <= self._CACHE_MAX_M:
                if len(self._repeated) >= 8:
                    self._repeated.clear()
                self._repeated[m] = out
        return out

    def apply(self, x):
        """``M x`` for a vector ``x`` in columns form."""
        d = self.diagonal
        if d is not None:
            if type(x) is tuple:
                x0, x1, x2 = x
                return (d[0] * x0, d[1] * x1, d[2] * x2)
            if _is_stack(x):
                return self._diagonal_repeated(x.shape[1]) * x
            x0, x1, x2 = _parts(x)
            return (d[0] * x0, d[1] * x1, d[2] * x2)
        x = _parts(x)
        out = []
        for row in self._rows:
            acc = None
            for j, k in row:
                acc = k * x[j] if acc is None else acc + k * x[j]
            out.append(0.0 * x[0] if acc is None else acc)
        return _pack(*out)


def rotation_and_rate_columns(theta) -> tuple[tuple, tuple]:
    """``(A(theta), B(theta))`` in columns form, from one cos and one sin per angle (eqs 1, 2).

    Parameters
    ----------
    theta : vector in columns form
        Euler angles [rad] (3 floats for one state, a (3, m) array or 3 arrays (m,) for
        a stack); ``|theta_2| < pi/2`` (eq 5).

    Returns
    -------
    a, b : nested tuples of components
        ``A`` (body -> inertial, eq 2) and ``B`` (``d(theta)/dt = B omega``, eq 1,
        middle row corrected): ``a[i][j]`` is the (i, j) entry (of every matrix of the
        stack). ``b``'s structural zeros and one are the floats 0.0 and 1.0. Apply
        ``a`` with :func:`matvec_columns`, :func:`matTvec_columns`, ``b`` with
        :func:`rate_matvec_columns`, :func:`rate_matTvec_columns`.
    """
    c, s = _cos_sin(theta)
    return _rotation_entries(c, s), _rate_entries(c, s)


# In the helpers below a vector is a tuple for one state (the fast test ``type(x) is
# tuple`` comes first, so that float arithmetic pays for no other check), a (3, m) array
# for a stack in array form, or any other sequence of 3 components (e.g. a constant
# vector, or 3 arrays (m,)). Results are tuples for one state and (3, m) arrays for
# stacks (``_pack``).
def rate_matvec_columns(b, x):
    """``B x`` for ``b`` from :func:`rotation_and_rate_columns`, skipping B's structural
    zeros and one (``dTheta/dt = B Omega``, eq 1)."""
    (b00, b01, _), (b10, b11, _), (b20, b21, _) = b
    x0, x1, x2 = x if type(x) is tuple else _parts(x)
    return _pack(b00 * x0 + b01 * x1, b10 * x0 + b11 * x1, b20 * x0 + b21 * x1 + x2)


def rate_matTvec_columns(b, x):
    """``B' x`` for ``b`` from :func:`rotation_and_rate_columns`, skipping B's structural
    zeros and one."""
    (b00, b01, _), (b10, b11, _), (b20, b21, _) = b
    x0, x1, x2 = x if type(x) is tuple else _parts(x)
    return _pack(b00 * x0 + b10 * x1 + b20 * x2, b01 * x0 + b11 * x1 + b21 * x2, x2)


def cross_columns(a, b):
    """``a x b`` in columns form (either operand may be a constant vector)."""
    a0, a1, a2 = a if type(a) is tuple else _parts(a)
    b0, b1, b2 = b if type(b) is tuple else _parts(b)
    return _pack(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def matvec_columns(mat, x):
    """``mat x`` in columns form.

    Parameters
    ----------
    mat : nested sequence, ``mat[i][j]`` a component
        One matrix or a stack (e.g. ``a`` of :func:`rotation_and_rate_columns`), or a
        (3, 3) / (3, 3, m) array.
    x : vector in columns form
        One vector or a stack; a constant vector may be paired with a stack of matrices
        and one matrix with a stack of vectors.

    Returns
    -------
    vector in columns form (a tuple for one state, a (3, m) array for a stack)
    """
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = mat
    x0, x1, x2 = x if type(x) is tuple else _parts(x)
    return _pack(
        m00 * x0 + m01 * x1 + m02 * x2,
        m10 * x0 + m11 * x1 + m12 * x2,
        m20 * x0 + m21 * x1 + m22 * x2,
    )


def matTvec_columns(mat, x):
    """``mat' x`` in columns form; arguments as :func:`matvec_columns`."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = mat
    x0, x1, x2 = x if type(x) is tuple else _parts(x)
    return _pack(
        m00 * x0 + m10 * x1 + m20 * x2,
        m01 * x0 + m11 * x1 + m21 * x2,
        m02 * x0 + m12 * x1 + m22 * x2,
    )


def add_columns(a, b):
    """``a + b`` in columns form (one numpy call for two stacks in array form)."""
    if type(a) is not tuple or type(b) is not tuple:
        if _is_stack(a) and _is_stack(b):
            return a + b
        a, b = _parts(a), _parts(b)
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a0 + b0, a1 + b1, a2 + b2)


def sub_columns(a, b):
    """``a - b`` in columns form (one numpy call for two stacks in array form)."""
    if type(a) is not tuple or type(b) is not tuple:
        if _is_stack(a) and _is_stack(b):
            return a - b
        a, b = _parts(a), _parts(b)
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a0 - b0, a1 - b1, a2 - b2)


def neg_columns(a):
    """``-a`` in columns form."""
    if type(a) is not tuple:
        if _is_stack(a):
            return -a
        a = _parts(a)
    a0, a1, a2 = a
    return (-a0, -a1, -a2)


def scale_columns(s: float, a):
    """``s a`` for a float ``s``, in columns form."""
    if type(a) is not tuple:
        if _is_stack(a):
            return s * a
        a = _parts(a)
    a0, a1, a2 = a
    return (s * a0, s * a1, s * a2)


def div_columns(a, s: float):
    """``a / s`` for a float ``s``, in columns form."""
    if type(a) is not tuple:
        if _is_stack(a):
            return a / s
        a = _parts(a)
    a0, a1, a2 = a
    return (a0 / s, a1 / s, a2 / s)


def add_constant_columns(x, c: ConstantVector):
    """``x + c`` for a constant vector ``c`` in columns form (a zero ``c`` costs nothing)."""
    if c.is_zero:
        return x
    if _is_stack(x):
        return x + c.column
    x0, x1, x2 = _parts(x)
    return (x0 + c[0], x1 + c[1], x2 + c[2])


def sub_constant_columns(x, c: ConstantVector):
    """``x - c`` for a constant vector ``c`` in columns form (see :func:`add_constant_columns`)."""
    if c.is_zero:
        return x
    if _is_stack(x):
        return x - c.column
    x0, x1, x2 = _parts(x)
    return (x0 - c[0], x1 - c[1], x2 - c[2])


def dot_columns(a, b):
    """``a . b`` in columns form, summed in component order: one component (a float for
    one state, an array (m,) for a stack)."""
    if type(a) is not tuple or type(b) is not tuple:
        if _is_stack(a) and _is_stack(b):
            p = a * b  # the same products, in one call
            return p[0] + p[1] + p[2]
        a, b = _parts(a), _parts(b)
    a0, a1, a2 = a
    b0, b1, b2 = b
    return a0 * b0 + a1 * b1 + a2 * b2


def dot_constant_columns(x, c):
    """``x . c`` for a constant vector ``c`` (3 floats), summed in component order over
    the nonzero components of ``c``; the float 0.0 when ``c`` is zero."""
    terms = [xi * ci for xi, ci in zip(_parts(x), c) if ci]
    if not terms:
        return 0.0
    acc = terms[0]
    for t in terms[1:]:
        acc = acc + t
    return acc


def quadratic_form_columns(x, m: ConstantMatrix, y=None):
    """``x' M y`` (``y`` defaults to ``x``) for a constant matrix, in columns form: one
    component, ``x . (M y)`` summed in component order."""
    return dot_columns(x, m.apply(x if y is None else y))


def zeros_columns(like):
    """A zero vector in columns form shaped like the vector ``like``."""
    if _is_stack(like):
        return np.zeros(like.shape)
    c = like[0]
    zero = 0.0 if isinstance(c, float) else np.zeros(np.shape(c))
    return (zero, zero, zero)
