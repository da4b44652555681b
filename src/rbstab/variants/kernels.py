"""The compiled right-hand side and outputs of every variant, selected by ``Variant.code``.

One compiled kernel serves every run of every sweep: the variant is a runtime number and
the body and gains a runtime :data:`~rbstab.model.PARAMETERS` record, so runs of
different variants and parameters share a chunk. The physics lives in the variants'
modules; this module only puts it together:

- :func:`state_rate`: dy/dt of one state (what the integrators call);
- :func:`output_row`: every output of one state (E, F, Lambda, H, N, v, its terms, dv/dt);
- :func:`state_rates`, :func:`run_outputs`: the same over many states, from Python.
"""

from __future__ import annotations

from ..jit import jit
from ..kinematics import ZERO, matvec, rotation_and_rate_of, vector
from ..model import force_h, torque_n
from . import embedded, free, permanent, sliding, visco_elastic
from .base import body_dissipation, body_energy, body_rates, constraint_error, constraint_rate

__all__ = ["FREE", "PERMANENT", "SLIDING", "VISCO_ELASTIC", "EMBEDDED", "state_rate", "output_row",
           "state_rates", "run_outputs", "STATE_SIZE"]

FREE, PERMANENT, SLIDING, VISCO_ELASTIC, EMBEDDED = 0, 1, 2, 3, 4
#: Scalar states of each variant, by code.
STATE_SIZE = (12, 6, 12, 12, 15)


@jit(inline="always")
def constrained_body(constraint_force, y, p):
    """Eq 1 with the constraint law ``constraint_force`` (a variant's) at the 12- or
    15-state y (D = y[12:15] when there).

    Returns (theta, omega, x, v, d, a, b, n, h, e, f, lam, d_rate).
    """
    theta, omega, x, v = vector(y, 0), vector(y, 3), vector(y, 6), vector(y, 9)
    d = vector(y, 12) if y.shape[0] == 15 else ZERO
    a, b = rotation_and_rate_of(theta)
    e = constraint_error(x, a, p)
    f = constraint_rate(omega, v, a, p)
    n = torque_n(b, theta, omega, p)
    h = force_h(x, v, p)
    lam, d_rate = constraint_force(e, f, d, p)
    return theta, omega, x, v, d, a, b, n, h, e, f, lam, d_rate


@jit(inline="always")
def _put(out, i, x):
    out[i] = x[0]
    out[i + 1] = x[1]
    out[i + 2] = x[2]


@jit(inline="always")
def _constrained_rate(constraint_force, y, p, dy):
    theta, omega, x, v, d, a, b, n, h, e, f, lam, d_rate = constrained_body(constraint_force, y, p)
    theta_dot, omega_dot, x_dot, v_dot = body_rates(omega, v, a, b, n, h, lam, p)
    _put(dy, 0, theta_dot)
    _put(dy, 3, omega_dot)
    _put(dy, 6, x_dot)
    _put(dy, 9, v_dot)
    if y.shape[0] == 15:
        _put(dy, 12, d_rate)


@jit
def state_rate(code, y, p, dy):
    """dy/dt of one state ``y`` of the variant ``code`` into ``dy`` (same shape)."""
    if code == PERMANENT:
        theta, omega, x, v, a, b, n, h, lam, omega_dot = permanent.quantities(y, p)
        _put(dy, 0, matvec(b, omega))
        _put(dy, 3, omega_dot)
    elif code == EMBEDDED:
        _constrained_rate(embedded.constraint_force, y, p, dy)
    elif code == VISCO_ELASTIC:
        _constrained_rate(visco_elastic.constraint_force, y, p, dy)
    elif code == SLIDING:
        _constrained_rate(sliding.constraint_force, y, p, dy)
    else:
        _constrained_rate(free.constraint_force, y, p, dy)


@jit(inline="always")
def _lyapunov(out, theta, omega, x, v, p, constraint, constraint_dissipation):
    """v, its terms and dv/dt into out[30:36]: the body's (eq 25, gravity) plus the constraint's."""
    translational, rotational, gravity = body_energy(theta, omega, x, v, p)
    out[30] = translational
    out[31] = rotational
    out[32] = constraint
    out[33] = gravity
    out[34] = translational + rotational + constraint + gravity
    out[35] = -(body_dissipation(omega, v, p) + constraint_dissipation)


@jit(inline="always")
def _constrained_outputs(constraint_force, constraint_energy, constraint_dissipation, y, p, out):
    """Outputs of a full-body variant, given its module's constraint law, energy and dissipation."""
    theta, omega, x, v, d, a, b, n, h, e, f, lam, d_rate = constrained_body(constraint_force, y, p)
    for i, block in enumerate((theta, omega, x, v, d, e, f, lam, h, n)):
        _put(out, 3 * i, block)
    _lyapunov(out, theta, omega, x, v, p, constraint_energy(e, d, p), constraint_dissipation(f, d_rate, p))


@jit
def output_row(code, y, p, out):
    """Every output of one state into ``out`` (length N_OUTPUTS, order of
    :data:`~rbstab.variants.base.OUTPUT_VECTORS` then ``OUTPUT_SCALARS``)."""
    if code == PERMANENT:
        theta, omega, x, v, a, b, n, h, lam, omega_dot = permanent.quantities(y, p)
        e = constraint_error(x, a, p)
        f = constraint_rate(omega, v, a, p)
        for i, block in enumerate((theta, omega, x, v, ZERO, e, f, lam, h, n)):
            _put(out, 3 * i, block)
        _lyapunov(out, theta, omega, x, v, p, 0.0, 0.0)
    elif code == EMBEDDED:
        m = embedded
        _constrained_outputs(m.constraint_force, m.constraint_energy, m.constraint_dissipation, y, p, out)
    elif code == VISCO_ELASTIC:
        m = visco_elastic
        _constrained_outputs(m.constraint_force, m.constraint_energy, m.constraint_dissipation, y, p, out)
    elif code == SLIDING:
        m = sliding
        _constrained_outputs(m.constraint_force, m.constraint_energy, m.constraint_dissipation, y, p, out)
    else:
        m = free
        _constrained_outputs(m.constraint_force, m.constraint_energy, m.constraint_dissipation, y, p, out)


@jit
def state_rates(code, y, params, out):
    """dy/dt of every row of ``y`` (m, n_state) into ``out``; ``params`` has 1 or m records."""
    for k in range(y.shape[0]):
        state_rate(code, y[k], params[min(k, params.shape[0] - 1)], out[k])


@jit
def run_outputs(codes, params, samples, out):
    """Outputs of k runs: ``samples`` (k, n_samples, n_state) of runs with variant
    ``codes`` (k,) and ``params`` (k,) into ``out`` (k, n_samples, N_OUTPUTS)."""
    for k in range(samples.shape[0]):
        for j in range(samples.shape[1]):
            output_row(codes[k], samples[k, j], params[k], out[k, j])
