"""Rigid-body kinematics and 3-vector algebra (paper section 2; frames and conventions: docs/physics.md).

The physics of rbstab is compiled with numba (:func:`rbstab.jit.jit`). Inside compiled
code a 3-vector is a tuple ``(x0, x1, x2)`` of floats, so that no operation allocates
memory (a right-hand side then costs ~0.1 us); a constant matrix (a gain, an inertia) is a
(3, 3) array, and a matrix that depends on the state (A, B) a tuple of its rows. The small
functions below (:func:`add`, :func:`sub`, :func:`neg`, :func:`scale`, :func:`cross`,
:func:`dot`, :func:`matvec`, :func:`matTvec`, :func:`quadratic_form`) are the vector
algebra of the equations; `M[i][j]` indexing serves both matrix kinds.

For Python callers and tests, :func:`rotation_matrix`, :func:`euler_rate_matrix`,
:func:`rotation_and_rate` and :func:`hat` take arrays of shape (3,) or (..., 3) and return
(3, 3) or (..., 3, 3) arrays, computed by the same compiled entries.

Conventions
-----------
- ``theta = (t1, t2, t3)``: Euler angles [rad], ``A = A1(t1) A2(t2) A3(t3) = Rx Ry Rz``
  (intrinsic x-y'-z'') maps body-frame (bcs) vectors to the inertial frame (ics), eq 2.
- ``omega``: angular velocity [rad/s] in the body frame; ``dA/dt = A hat(omega)``.
- ``hat(r) w = r x w`` (the paper's "R check").
"""

from __future__ import annotations

import math

import numpy as np

from .jit import jit

__all__ = [
    "GIMBAL_LOCK_ANGLE",
    "IDENTITY",
    "axis_rotation",
    "axis_angle",
    "turn_angle",
    "quaternion_rotation",
    "quaternion_of_vector",
    "quaternion_vector",
    "vector_rotation",
    "rotation_vector",
    "right_jacobian_inverse",
    "universal_rotation",
    "universal_angles",
    "universal_columns",
    "universal_rate",
    "euler_angles_of",
    "vector",
    "add",
    "sub",
    "neg",
    "scale",
    "dot",
    "cross",
    "matvec",
    "matTvec",
    "quadratic_form",
    "rotation_and_rate_of",
    "hat",
    "rotation_matrix",
    "euler_rate_matrix",
    "rotation_and_rate",
]

#: |theta_2| at which B(theta) is singular (eq 5).
GIMBAL_LOCK_ANGLE = math.pi / 2

#: The zero 3-vector.
ZERO = (0.0, 0.0, 0.0)


# -- 3-vector algebra (compiled; vectors are tuples, matrices M[i][j]) ----------------
@jit(forceinline=True)
def vector(y, i):
    """The 3-vector (y[i], y[i+1], y[i+2]) of an array ``y``."""
    return (y[i], y[i + 1], y[i + 2])


@jit(forceinline=True)
def add(a, b):
    """a + b."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@jit(forceinline=True)
def sub(a, b):
    """a - b."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@jit(forceinline=True)
def neg(a):
    """-a."""
    return (-a[0], -a[1], -a[2])


@jit(forceinline=True)
def scale(s, a):
    """s a for a scalar s."""
    return (s * a[0], s * a[1], s * a[2])


@jit(forceinline=True)
def dot(a, b):
    """a' b."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit(forceinline=True)
def cross(a, b):
    """a x b = hat(a) b."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@jit(forceinline=True)
def matvec(m, x):
    """M x for a 3x3 matrix M (array or tuple of rows)."""
    return (
        m[0][0] * x[0] + m[0][1] * x[1] + m[0][2] * x[2],
        m[1][0] * x[0] + m[1][1] * x[1] + m[1][2] * x[2],
        m[2][0] * x[0] + m[2][1] * x[1] + m[2][2] * x[2],
    )


@jit(forceinline=True)
def matTvec(m, x):
    """M' x for a 3x3 matrix M (array or tuple of rows)."""
    return (
        m[0][0] * x[0] + m[1][0] * x[1] + m[2][0] * x[2],
        m[0][1] * x[0] + m[1][1] * x[1] + m[2][1] * x[2],
        m[0][2] * x[0] + m[1][2] * x[1] + m[2][2] * x[2],
    )


@jit(forceinline=True)
def quadratic_form(x, m):
    """x' M x."""
    return dot(x, matvec(m, x))


# -- A(theta) and B(theta): the one place that defines their entries -------------------
@jit(forceinline=True)
def rotation_and_rate_of(theta):
    """A(theta) = Rx Ry Rz (eq 2) and the Euler-rate matrix B(theta), dtheta/dt = B omega
    (eq 1 as corrected in docs/physics.md: middle row [s3, c3, 0]); tuples of rows."""
    c1, c2, c3 = math.cos(theta[0]), math.cos(theta[1]), math.cos(theta[2])
    s1, s2, s3 = math.sin(theta[0]), math.sin(theta[1]), math.sin(theta[2])
    a = (
        (c2 * c3, -c2 * s3, s2),
        (c1 * s3 + s1 * s2 * c3, c1 * c3 - s1 * s2 * s3, -s1 * c2),
        (s1 * s3 - c1 * s2 * c3, s1 * c3 + c1 * s2 * s3, c1 * c2),
    )
    b = (
        (c3 / c2, -s3 / c2, 0.0),
        (s3, c3, 0.0),
        (-s2 * c3 / c2, s2 * s3 / c2, 1.0),
    )
    return a, b


#: The identity's rows: B of a hinge's rotation vector q a (its rate is Omega_j = a dq/dt).
IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@jit(forceinline=True)
def axis_rotation(axis, q):
    """The rotation by ``q`` [rad] about the unit ``axis`` a (3-tuple), exp(q hat(a)) =
    cos q I + sin q hat(a) + (1 - cos q) a a' (Rodrigues); a tuple of rows. It leaves a
    fixed: a is the same in the frames it relates."""
    c, s = math.cos(q), math.sin(q)
    v = 1.0 - c
    x, y, z = axis[0], axis[1], axis[2]
    return ((c + v * x * x, v * x * y - s * z, v * x * z + s * y),
            (v * x * y + s * z, c + v * y * y, v * y * z - s * x),
            (v * x * z - s * y, v * y * z + s * x, c + v * z * z))


@jit(forceinline=True)
def axis_angle(rot, axis):
    """The angle q [rad] in (-pi, pi] of the rotation ``rot`` (rows) about the unit ``axis``
    a, the inverse of :func:`axis_rotation` there: sin q = a . vee(rot - rot') / 2, cos q =
    (tr rot - 1) / 2."""
    s = 0.5 * (axis[0] * (rot[2][1] - rot[1][2]) + axis[1] * (rot[0][2] - rot[2][0])
               + axis[2] * (rot[1][0] - rot[0][1]))
    return math.atan2(s, 0.5 * (rot[0][0] + rot[1][1] + rot[2][2] - 1.0))


@jit(forceinline=True)
def turn_angle(axis, x, y):
    """The angle [rad] in (-pi, pi] of the turn about the unit ``axis`` a that takes the
    vector ``x``'s part across a into the direction of ``y``'s (both not along a)."""
    xa, ya = dot(axis, x), dot(axis, y)
    xp = (x[0] - xa * axis[0], x[1] - xa * axis[1], x[2] - xa * axis[2])
    yp = (y[0] - ya * axis[0], y[1] - ya * axis[1], y[2] - ya * axis[2])
    return math.atan2(dot(axis, cross(xp, yp)), dot(xp, yp))


@jit(forceinline=True)
def universal_rotation(a_1, a_2, q_1, q_2):
    """A universal joint's A_rel = exp(q_1 [a_1]x) exp(q_2 [a_2]x) (rows) of its unit axes
    ``a_1`` (the parent's frame), ``a_2`` (the child's frame) and angles [rad]."""
    m, n = axis_rotation(a_1, q_1), axis_rotation(a_2, q_2)
    return ((m[0][0] * n[0][0] + m[0][1] * n[1][0] + m[0][2] * n[2][0],
             m[0][0] * n[0][1] + m[0][1] * n[1][1] + m[0][2] * n[2][1],
             m[0][0] * n[0][2] + m[0][1] * n[1][2] + m[0][2] * n[2][2]),
            (m[1][0] * n[0][0] + m[1][1] * n[1][0] + m[1][2] * n[2][0],
             m[1][0] * n[0][1] + m[1][1] * n[1][1] + m[1][2] * n[2][1],
             m[1][0] * n[0][2] + m[1][1] * n[1][2] + m[1][2] * n[2][2]),
            (m[2][0] * n[0][0] + m[2][1] * n[1][0] + m[2][2] * n[2][0],
             m[2][0] * n[0][1] + m[2][1] * n[1][1] + m[2][2] * n[2][1],
             m[2][0] * n[0][2] + m[2][1] * n[1][2] + m[2][2] * n[2][2]))


@jit(forceinline=True)
def universal_angles(rot, a_1, a_2):
    """(q_1, q_2) [rad], each in (-pi, pi], of the rotation ``rot`` = :func:`universal_rotation`
    (a_1 and a_2 not parallel): rot a_2 = exp(q_1 [a_1]x) a_2 and rot' a_1 = exp(-q_2 [a_2]x) a_1."""
    return turn_angle(a_1, a_2, matvec(rot, a_2)), -turn_angle(a_2, a_1, matTvec(rot, a_1))


@jit(forceinline=True)
def universal_columns(a_1, a_2, q_2):
    """A universal joint's motion subspace in the child's frame, (s_1, s_2): Omega_j = s_1
    dq_1/dt + s_2 dq_2/dt [rad/s] with s_1 = exp(-q_2 [a_2]x) a_1, s_2 = a_2."""
    return matTvec(axis_rotation(a_2, q_2), a_1), a_2


@jit(forceinline=True)
def universal_rate(a_1, a_2, q_2):
    """A universal joint's B (rows), the map of Omega_j [rad/s, child frame] to (dq_1/dt,
    dq_2/dt, 0) on its motion subspace (:func:`universal_columns`): rows 1-2 G^-1 S' (G = S'S
    = [[1, c], [c, 1]], c = a_1 . a_2, constant: the turn about a_2 keeps s_1's angle to
    it), row 3 the unit normal n = s_1 x s_2 / |s_1 x s_2|; so B S = [I; 0], and N = B' f
    has the generalised forces S' N = (f_1, f_2)."""
    s_1, s_2 = universal_columns(a_1, a_2, q_2)
    c = dot(a_1, a_2)
    d = 1.0 / (1.0 - c * c)
    n = cross(s_1, s_2)
    size = 1.0 / math.sqrt(dot(n, n))
    return ((d * (s_1[0] - c * s_2[0]), d * (s_1[1] - c * s_2[1]), d * (s_1[2] - c * s_2[2])),
            (d * (s_2[0] - c * s_1[0]), d * (s_2[1] - c * s_1[1]), d * (s_2[2] - c * s_1[2])),
            (size * n[0], size * n[1], size * n[2]))


@jit(forceinline=True)
def quaternion_rotation(w, x, y, z):
    """The rotation (rows) of the quaternion (w, x, y, z), normalised first (a run's
    quaternion drifts off unit length by its integration error only)."""
    n = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * n, x * n, y * n, z * n
    return ((1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
            (2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
            (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)))


@jit(forceinline=True)
def quaternion_of_vector(phi):
    """The unit quaternion (w, x, y, z) of the rotation vector ``phi`` [rad] (the turn by
    |phi| about phi / |phi|): (cos(|phi|/2), sin(|phi|/2) phi / |phi|)."""
    angle = math.sqrt(dot(phi, phi))
    half = 0.5 - angle * angle / 48.0 if angle < 1e-4 else math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), half * phi[0], half * phi[1], half * phi[2]


@jit(forceinline=True)
def vector_rotation(phi):
    """exp([phi]x) (rows): the rotation by the rotation vector ``phi`` [rad]."""
    w, x, y, z = quaternion_of_vector(phi)
    return quaternion_rotation(w, x, y, z)


@jit(forceinline=True)
def rotation_vector(rot):
    """log of the rotation ``rot`` (rows): its rotation vector phi [rad], |phi| <= pi (the
    shorter of the two turns), from its quaternion (Shepperd's method, w >= 0)."""
    trace = rot[0][0] + rot[1][1] + rot[2][2]
    if trace >= rot[0][0] and trace >= rot[1][1] and trace >= rot[2][2]:
        s = 2.0 * math.sqrt(max(1.0 + trace, 0.0))
        w, x, y, z = 0.25 * s, (rot[2][1] - rot[1][2]) / s, (rot[0][2] - rot[2][0]) / s, (rot[1][0] - rot[0][1]) / s
    elif rot[0][0] >= rot[1][1] and rot[0][0] >= rot[2][2]:
        s = 2.0 * math.sqrt(max(1.0 + rot[0][0] - rot[1][1] - rot[2][2], 0.0))
        w, x, y, z = (rot[2][1] - rot[1][2]) / s, 0.25 * s, (rot[0][1] + rot[1][0]) / s, (rot[0][2] + rot[2][0]) / s
    elif rot[1][1] >= rot[2][2]:
        s = 2.0 * math.sqrt(max(1.0 - rot[0][0] + rot[1][1] - rot[2][2], 0.0))
        w, x, y, z = (rot[0][2] - rot[2][0]) / s, (rot[0][1] + rot[1][0]) / s, 0.25 * s, (rot[1][2] + rot[2][1]) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 - rot[0][0] - rot[1][1] + rot[2][2], 0.0))
        w, x, y, z = (rot[1][0] - rot[0][1]) / s, (rot[0][2] + rot[2][0]) / s, (rot[1][2] + rot[2][1]) / s, 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return quaternion_vector(w, x, y, z)


@jit(forceinline=True)
def quaternion_vector(w, x, y, z):
    """The rotation vector phi [rad] of the quaternion (w, x, y, z) (any length, w >= 0:
    |phi| <= pi): 2 atan2(|v|, w) v / |v|."""
    size = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 / w if size < 1e-12 * abs(w) else 2.0 * math.atan2(size, w) / size
    return scale * x, scale * y, scale * z


@jit(forceinline=True)
def right_jacobian_inverse(phi):
    """J_r(phi)^-1 (rows): the map of a rotation's angular velocity in its own (rotated)
    frame to the rate of its rotation vector phi [rad] (|phi| < 2 pi): I + 1/2 [phi]x + (1 /
    |phi|^2 - (1 + cos|phi|) / (2 |phi| sin|phi|)) [phi]x^2."""
    angle2 = dot(phi, phi)
    angle = math.sqrt(angle2)
    if angle < 1e-4:
        c = 1.0 / 12.0 + angle2 / 720.0
    else:
        c = 1.0 / angle2 - (1.0 + math.cos(angle)) / (2.0 * angle * math.sin(angle))
    x, y, z = phi[0], phi[1], phi[2]
    return ((1.0 + c * (-y * y - z * z), -0.5 * z + c * x * y, 0.5 * y + c * x * z),
            (0.5 * z + c * x * y, 1.0 + c * (-x * x - z * z), -0.5 * x + c * y * z),
            (-0.5 * y + c * x * z, 0.5 * x + c * y * z, 1.0 + c * (-x * x - y * y)))


@jit
def _rotation_and_rate_rows(theta, a_out, b_out):
    for n in range(theta.shape[0]):
        a, b = rotation_and_rate_of(vector(theta[n], 0))
        for i in range(3):
            for j in range(3):
                a_out[n, i, j] = a[i][j]
                b_out[n, i, j] = b[i][j]


# -- array wrappers for Python callers ----------------------------------------------------
def rotation_and_rate(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A(theta) and B(theta) together.

    Parameters
    ----------
    theta : array_like, shape (3,) or (..., 3)
        Euler angles [rad].

    Returns
    -------
    a, b : ndarray, shape (3, 3) or (..., 3, 3)
        The rotation matrix (body to inertial frame, eq 2) and the Euler-rate matrix (eq 1).
    """
    theta = np.asarray(theta, dtype=float)
    flat = np.ascontiguousarray(theta.reshape(-1, 3))
    a = np.empty((len(flat), 3, 3))
    b = np.empty((len(flat), 3, 3))
    _rotation_and_rate_rows(flat, a, b)
    shape = theta.shape[:-1] + (3, 3)
    return a.reshape(shape), b.reshape(shape)


def rotation_matrix(theta: np.ndarray) -> np.ndarray:
    """A(theta) = Rx(t1) Ry(t2) Rz(t3), body frame to inertial frame (eq 2).

    ``theta``: shape (3,) or (..., 3) [rad]; returns shape (3, 3) or (..., 3, 3).
    """
    return rotation_and_rate(theta)[0]


def euler_angles_of(a: np.ndarray) -> np.ndarray:
    """Theta [rad] (3,) with A(Theta) = ``a`` (3, 3) (eq 2): |theta_2| <= pi/2, theta_1,
    theta_3 in (-pi, pi] (a[0, 2] = s2, a[1, 2] = -s1 c2, a[2, 2] = c1 c2, a[0, 1] = -c2 s3,
    a[0, 0] = c2 c3)."""
    a = np.asarray(a, dtype=float)
    return np.array([math.atan2(-a[1, 2], a[2, 2]), math.asin(min(1.0, max(-1.0, a[0, 2]))),
                     math.atan2(-a[0, 1], a[0, 0])])


def euler_rate_matrix(theta: np.ndarray) -> np.ndarray:
    """B(theta) with dtheta/dt = B omega, omega in the body frame (eq 1, corrected).

    ``theta``: shape (3,) or (..., 3) [rad]; returns shape (3, 3) or (..., 3, 3).
    Singular at |t2| = pi/2 (gimbal lock, eq 5).
    """
    return rotation_and_rate(theta)[1]


def hat(r: np.ndarray) -> np.ndarray:
    """Skew matrix of a vector, ``hat(r) @ w == np.cross(r, w)`` (the paper's "R check").

    ``r``: shape (3,) or (..., 3), any frame; returns shape (3, 3) or (..., 3, 3).
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
