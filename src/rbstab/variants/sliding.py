"""``sliding``: sliding-mode constraint force Lambda = -K_s sgn(E) (eq 39), optional boundary layer.

With a boundary layer phi > 0 the law is smooth (sgn -> tanh(E/phi)) and any integrator
takes it. The pure sign law (phi = 0) is integrated piece by piece by
:mod:`rbstab.engine.switching`, in *modes*: a mode is a vector sigma in {-1, 0, 1}^3 that
stands for sgn(E) on a smooth piece of the motion,

- sigma_i = +-1: E_i is on that side of its switching surface E_i = 0 and
  Lambda_i = -K_s sigma_i (the one-sided vector field, extended past the surface so that
  the integrator sees a smooth right-hand side up to the located switching);
- sigma_i = 0: the motion slides on E_i = 0 (with F_i = 0): Lambda_i is Filippov's
  equivalent force, the one that keeps dF_i/dt = 0 (Utkin's equivalent control), as long as
  |Lambda_i| <= K_s.

E reaches Lambda through the body's accelerations only (relative degree 2): dF/dt =
a_0 + W Lambda, with W = I/m + (hat(R) A')' J^-1 (hat(R) A') the inverse mass of the body
at C (:func:`inverse_mass_at_c`, symmetric positive definite). See docs/sliding.md.
"""

from __future__ import annotations

import math

from ..jit import jit
from ..kinematics import ZERO, add, cross, dot, matTvec, matvec, rotation_and_rate_of, scale, vector
from ..layout import VARIANT_CODES
from ..model import force_h, torque_n
from .body import body_rates, constraint_error, constraint_rate

__all__ = ["MODE_CODES", "MODE_COLUMNS", "mode_code", "mode_of", "mode_force", "mode_rate",
           "mode_quantities", "mode_rows", "stop_at_c", "inverse_mass_at_c"]

_LOG2 = math.log(2.0)


@jit(forceinline=True)
def sign(u):
    """sgn(u): -1, 0 or 1 (NaN for NaN)."""
    if u > 0.0:
        return 1.0
    if u < 0.0:
        return -1.0
    return u * 0.0


@jit(forceinline=True)
def log_cosh(u):
    """log(cosh(u)) without overflow."""
    a = abs(u)
    return a + math.log1p(math.exp(-2.0 * a)) - _LOG2


@jit(forceinline=True)
def switching(e, phi):
    """sgn(e) for phi = 0, tanh(e / phi) for a boundary layer phi > 0 [m]."""
    if phi > 0.0:
        return math.tanh(e / phi)
    return sign(e)


@jit(forceinline=True)
def constraint_force(e, f, d, p):
    """Lambda = -K_s sgn(E) [N], componentwise, inertial frame (eq 39); sgn -> tanh(E/phi)
    with a boundary layer phi > 0. No controller state."""
    phi = p.boundary_layer
    lam = (-p.k_s * switching(e[0], phi), -p.k_s * switching(e[1], phi), -p.k_s * switching(e[2], phi))
    return lam, ZERO


@jit(forceinline=True)
def constraint_energy(e, d, p):
    """The potential of Lambda [J]: K_s |E|_1, or K_s phi sum log cosh(E_i / phi)."""
    phi = p.boundary_layer
    if phi > 0.0:
        return p.k_s * phi * (log_cosh(e[0] / phi) + log_cosh(e[1] / phi) + log_cosh(e[2] / phi))
    return p.k_s * (abs(e[0]) + abs(e[1]) + abs(e[2]))


@jit(forceinline=True)
def constraint_dissipation(f, d_rate, p):
    return 0.0


# -- the pure sign law in modes (see the module docstring) -------------------------------------
@jit(forceinline=True)
def inverse_mass_at_c(a, lam, p):
    """W Lambda [m/s^2]: the acceleration of C that a force Lambda [N] at C adds (eq 1),
    Lambda/m + A((J^-1 (R x A'Lambda)) x R); inertial frame."""
    r = p.attachment_point
    omega_dot = matvec(p.inertia_inv, cross(r, matTvec(a, lam)))
    return add(scale(1.0 / p.mass, lam), matvec(a, cross(omega_dot, r)))


@jit(forceinline=True)
def constraint_acceleration(omega, omega_dot, v_dot, a, p):
    """dF/dt = dV/dt + A (dOmega/dt x R) + A (Omega x (Omega x R)) [m/s^2], inertial frame."""
    r = p.attachment_point
    return add(v_dot, matvec(a, add(cross(omega_dot, r), cross(omega, cross(omega, r)))))


@jit(forceinline=True)
def _masked_column(column, on, k):
    """Column k of W where axes k and i are both ``on``, of the identity elsewhere."""
    return (column[0] if on[0] and on[k] else (1.0 if k == 0 else 0.0),
            column[1] if on[1] and on[k] else (1.0 if k == 1 else 0.0),
            column[2] if on[2] and on[k] else (1.0 if k == 2 else 0.0))


@jit(forceinline=True)
def solve_on(on, a, b, p):
    """x with (W x)_i = b_i on the axes i where ``on[i]``, and x_i = 0 elsewhere: the force
    at C [N] that changes the acceleration (or, as an impulse, the rate) of C by b along
    those axes. Cramer's rule on W restricted to them (W is positive definite)."""
    c0 = _masked_column(inverse_mass_at_c(a, (1.0, 0.0, 0.0), p), on, 0)
    c1 = _masked_column(inverse_mass_at_c(a, (0.0, 1.0, 0.0), p), on, 1)
    c2 = _masked_column(inverse_mass_at_c(a, (0.0, 0.0, 1.0), p), on, 2)
    rhs = (b[0] if on[0] else 0.0, b[1] if on[1] else 0.0, b[2] if on[2] else 0.0)
    det = dot(c0, cross(c1, c2))
    return (dot(rhs, cross(c1, c2)) / det, dot(c0, cross(rhs, c2)) / det, dot(c0, cross(c1, rhs)) / det)


#: The first mode code: the compiled right-hand side (``kernels.state_rate``) takes the
#: mode sigma as ``code = MODE_CODES + sum_i (sigma_i + 1) 3^i`` (27 codes after the variants').
MODE_CODES = len(VARIANT_CODES)


@jit(forceinline=True)
def mode_code(mode):
    """The ``state_rate`` code of ``mode`` (sigma, 3 numbers in {-1, 0, 1})."""
    return MODE_CODES + int(mode[0] + 1) + 3 * int(mode[1] + 1) + 9 * int(mode[2] + 1)


@jit(forceinline=True)
def mode_of(code):
    """sigma (a 3-tuple of -1.0, 0.0, 1.0) of a mode code (:func:`mode_code`)."""
    k = code - MODE_CODES
    return (float(k % 3 - 1), float(k // 3 % 3 - 1), float(k // 9 - 1))


@jit(forceinline=True)
def mode_force(omega, v, a, b, n, h, mode, p):
    """Lambda [N] in ``mode``: -K_s sigma_i where sigma_i = +-1, the equivalent force that
    keeps dF_i/dt = 0 where sigma_i = 0 (eq 39 with sgn(E) -> sigma; not clipped: the
    integrator ends the sliding where |Lambda_i| reaches K_s)."""
    lam = (-p.k_s * mode[0], -p.k_s * mode[1], -p.k_s * mode[2])
    on = (mode[0] == 0.0, mode[1] == 0.0, mode[2] == 0.0)
    if not (on[0] or on[1] or on[2]):
        return lam
    _, omega_dot, _, v_dot = body_rates(omega, v, a, b, n, h, lam, p)
    free = constraint_acceleration(omega, omega_dot, v_dot, a, p)
    return add(lam, solve_on(on, a, scale(-1.0, free), p))


@jit
def _mode_body(y, p, mode):
    """(Omega, X, V, A, the rates of eq 1, Lambda) of ``y`` in ``mode``: the one compiled
    copy of the mode's physics that :func:`mode_rate` and :func:`mode_quantities` share."""
    theta, omega, x, v = vector(y, 0), vector(y, 3), vector(y, 6), vector(y, 9)
    a, b = rotation_and_rate_of(theta)
    n = torque_n(b, theta, omega, p)
    h = force_h(x, v, p)
    lam = mode_force(omega, v, a, b, n, h, mode, p)
    return omega, x, v, a, body_rates(omega, v, a, b, n, h, lam, p), lam


@jit
def mode_rate(y, p, mode, dy):
    """dy/dt of the 12-state ``y`` in ``mode`` into ``dy``: eq 1 with the Lambda of
    :func:`mode_force`; ``p`` a :data:`~rbstab.model.PARAMETERS` record. Not inlined: the
    shared ``kernels.state_rate`` calls it and stays as small as the other variants need."""
    rates = _mode_body(y, p, mode)[4]
    for k in range(4):
        for i in range(3):
            dy[3 * k + i] = rates[k][i]


@jit
def mode_quantities(y, p, mode):
    """E [m], F [m/s], Lambda [N] and dF/dt [m/s^2] of state ``y`` in ``mode``, inertial frame.

    Not inlined: the event functions of :mod:`rbstab.engine.switching` call it from many
    places, and one compiled copy keeps their compilation short."""
    omega, x, v, a, rates, lam = _mode_body(y, p, mode)
    e = constraint_error(x, a, p)
    f = constraint_rate(omega, v, a, p)
    return e, f, lam, constraint_acceleration(omega, rates[1], rates[3], a, p)


@jit
def stop_at_c(y, p, on, out):
    """``y`` after the impulse P at C along the axes where ``on`` (P_j = 0 on the others)
    that stops C along them (F_i = 0 there), into ``out`` (12,): P = -W^-1 F on those
    axes, V += P/m, Omega += J^-1 (R x A'P). A perfectly inelastic impact: the kinetic
    energy falls by -F'P/2 = F'W^-1 F/2 (on those axes) >= 0."""
    theta, omega, x, v = vector(y, 0), vector(y, 3), vector(y, 6), vector(y, 9)
    a = rotation_and_rate_of(theta)[0]
    impulse = solve_on(on, a, scale(-1.0, constraint_rate(omega, v, a, p)), p)
    omega_new = add(omega, matvec(p.inertia_inv, cross(p.attachment_point, matTvec(a, impulse))))
    v_new = add(v, scale(1.0 / p.mass, impulse))
    for i in range(3):
        out[i] = theta[i]
        out[3 + i] = omega_new[i]
        out[6 + i] = x[i]
        out[9 + i] = v_new[i]


#: Columns of a row of :func:`mode_rows`: E [m], F [m/s], Lambda [N], dF/dt [m/s^2], each
#: a 3-vector in the inertial frame.
MODE_COLUMNS = ("constraint_error", "constraint_rate", "constraint_force", "constraint_acceleration")


@jit
def mode_rows(y, params, modes, out):
    """:func:`mode_quantities` (:data:`MODE_COLUMNS`) of every state row of ``y`` (k, 12),
    each in its mode ``modes`` (k, 3), into ``out`` (k, 12); ``params``: a
    :data:`~rbstab.model.PARAMETERS` array of shape (1,)."""
    p = params[0]
    for k in range(y.shape[0]):
        columns = mode_quantities(y[k], p, (modes[k, 0], modes[k, 1], modes[k, 2]))
        for c in range(4):
            for i in range(3):
                out[k, 3 * c + i] = columns[c][i]
