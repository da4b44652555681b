"""The compiled right-hand side and outputs of every variant, selected by ``Variant.code``.

One compiled kernel serves every run of every sweep: the variant is a runtime number and
the body and gains a runtime :data:`~rbstab.model.PARAMETERS` record, so runs of
different variants and parameters share a chunk. The physics lives in the variants'
modules; this module only puts it together:

- :func:`state_rate`: dy/dt of one state (what the integrators call); codes from
  ``sliding.MODE_CODES`` on are the pure sign law of ``sliding`` in a mode (sgn(E) -> sigma,
  :mod:`rbstab.engine.switching`);
- :func:`output_row`: every output of one state (E, F, Lambda, H, N, v, its terms, dv/dt),
  or only those the summaries and a thinned store read;
- :func:`state_rates`, :func:`run_outputs`: the same over many states, from Python.
"""

from __future__ import annotations

import math

from ..jit import jit
from ..kinematics import ZERO, add, cross, dot, matvec, rotation_and_rate_of, sub, vector
from ..layout import JOINT_CODES, OUTPUTS, STATE_SIZE, VARIANT_CODES
from ..model import force_h, force_h_command, pressure_point, saturate, saturated, torque_n, torque_n_command
from . import embedded, free, permanent, sliding, visco_elastic
from .body import body_dissipation, body_energy, body_rates, constraint_error, constraint_rate
from .disturbances import disturbance_power, disturbance_wrench, edges_up_to, state_power

__all__ = ["FREE", "PERMANENT", "HINGE", "UNIVERSAL", "BALL", "SLIDE", "SLIDING", "VISCO_ELASTIC", "EMBEDDED", "state_rate", "output_row", "limited_quantities",
           "state_rates", "run_outputs", "state_powers", "STATE_SIZE", "body_pressure", "body_pressures"]

#: The variants' codes (:data:`rbstab.layout.VARIANT_CODES`); :data:`STATE_SIZE`: their
#: scalar states, by code.
FREE, PERMANENT, SLIDING, VISCO_ELASTIC, EMBEDDED = (
    VARIANT_CODES[name] for name in ("free", "permanent", "sliding", "visco_elastic", "embedded"))
#: The hinge's, the universal joint's and the quaternion ball's codes
#: (:data:`rbstab.layout.JOINT_CODES`): a tree's joints, no one-body variant.
HINGE, UNIVERSAL, BALL, SLIDE = (JOINT_CODES[kind] for kind in ("hinge", "universal", "ball", "slide"))
#: The states' sizes: ``permanent``'s reduced state, the full state (free, sliding,
#: visco_elastic) and ``embedded``'s (with its controller state D).
PERMANENT_SIZE, FULL_SIZE, EMBEDDED_SIZE = STATE_SIZE[PERMANENT], STATE_SIZE[FREE], STATE_SIZE[EMBEDDED]

# First column of each output in a row of outputs (rbstab.layout.OUTPUTS): module-level
# ints, which numba compiles as constants.
THETA_AT = OUTPUTS["theta"].offset
OMEGA_AT = OUTPUTS["omega"].offset
POSITION_AT = OUTPUTS["position"].offset
VELOCITY_AT = OUTPUTS["velocity"].offset
CONTROLLER_STATE_AT = OUTPUTS["controller_state"].offset
CONSTRAINT_ERROR_AT = OUTPUTS["constraint_error"].offset
CONSTRAINT_RATE_AT = OUTPUTS["constraint_rate"].offset
CONSTRAINT_FORCE_AT = OUTPUTS["constraint_force"].offset
FORCE_H_AT = OUTPUTS["force_h"].offset
TORQUE_N_AT = OUTPUTS["torque_n"].offset
TORQUE_N_SATURATED_AT = OUTPUTS["torque_n_saturated"].offset
FORCE_H_SATURATED_AT = OUTPUTS["force_h_saturated"].offset
CONSTRAINT_FORCE_SATURATED_AT = OUTPUTS["constraint_force_saturated"].offset
TRANSLATIONAL_AT = OUTPUTS["lyapunov_translational"].offset
ROTATIONAL_AT = OUTPUTS["lyapunov_rotational"].offset
CONSTRAINT_AT = OUTPUTS["lyapunov_constraint"].offset
GRAVITY_AT = OUTPUTS["lyapunov_gravity"].offset
LYAPUNOV_AT = OUTPUTS["lyapunov"].offset
LYAPUNOV_RATE_AT = OUTPUTS["lyapunov_rate"].offset
DISTURBANCE_POWER_AT = OUTPUTS["disturbance_power"].offset
DISTURBANCE_WORK_AT = OUTPUTS["disturbance_work"].offset
DISTURBANCE_EDGES_AT = OUTPUTS["disturbance_edges"].offset


@jit(forceinline=True)
def body_state(y, p):
    """The body's state at the 12- or 15-state y (D = y[12:15] when there; an entry after
    them, the work W of an integrator's augmented state, is not read).

    Returns (theta, omega, x, v, d, a, b, e, f): A, B (eqs 2, 5), the constraint error E
    and rate F (eqs 7, 8).
    """
    theta, omega, x, v = vector(y, 0), vector(y, 3), vector(y, 6), vector(y, 9)
    d = vector(y, 12) if y.shape[0] >= 15 else ZERO
    a, b = rotation_and_rate_of(theta)
    e = constraint_error(x, a, p)
    f = constraint_rate(omega, v, a, p)
    return theta, omega, x, v, d, a, b, e, f


@jit(forceinline=True)
def limited_quantities(code, y, p):
    """The quantities ``simulation.limits`` bounds at the state ``y`` of variant ``code``, in
    the order of :data:`rbstab.layout.LIMITED`: (Theta [rad], Omega [rad/s] body frame,
    X [m], V [m/s], E [m] inertial frame), each a 3-tuple. ``permanent``'s X and V are
    those of the pinned body (:func:`rbstab.variants.permanent.pin_motion`), its E that of
    eq 4 (0 to rounding)."""
    if code == PERMANENT:
        theta, omega = vector(y, 0), vector(y, 3)
        a = rotation_and_rate_of(theta)[0]
        x, v = permanent.pin_motion(omega, a, p)
        return theta, omega, x, v, constraint_error(x, a, p)
    theta, omega, x, v, _, _, _, e, _ = body_state(y, p)
    return theta, omega, x, v, e


@jit(forceinline=True)
def constraint_force(code, e, f, d, p):
    """(Lambda [N], inertial frame, as delivered through ``p``'s limits of Lambda
    (:func:`rbstab.model.saturate`); dD/dt [m/s], zero without D) of the constraint law of
    variant ``code`` (not ``permanent``) at E [m], F [m/s], D [m]."""
    lam, d_rate = constraint_force_command(code, e, f, d, p)
    if p.saturation > 0.0:
        return saturate(lam, p.constraint_force_limit, p.saturation), d_rate
    return lam, d_rate


@jit(forceinline=True)
def constraint_force_command(code, e, f, d, p):
    """(Lambda [N] as the constraint law of variant ``code`` (not ``permanent``) commands
    it, inertial frame; dD/dt [m/s]) at E [m], F [m/s], D [m]: the variant module's
    ``constraint_force`` (eqs 22, 39, 40)."""
    if code == EMBEDDED:
        return embedded.constraint_force(e, f, d, p)
    if code == VISCO_ELASTIC:
        return visco_elastic.constraint_force(e, f, d, p)
    if code == SLIDING:
        return sliding.constraint_force(e, f, d, p)
    return free.constraint_force(e, f, d, p)


@jit(forceinline=True)
def constraint_energy(code, e, d, p):
    """The energy [J] stored by the constraint of variant ``code`` (not ``permanent``)."""
    if code == EMBEDDED:
        return embedded.constraint_energy(e, d, p)
    if code == VISCO_ELASTIC:
        return visco_elastic.constraint_energy(e, d, p)
    if code == SLIDING:
        return sliding.constraint_energy(e, d, p)
    return free.constraint_energy(e, d, p)


@jit(forceinline=True)
def constraint_dissipation(code, f, d_rate, p):
    """The power [W] dissipated by the constraint of variant ``code`` (not ``permanent``)."""
    if code == EMBEDDED:
        return embedded.constraint_dissipation(f, d_rate, p)
    if code == VISCO_ELASTIC:
        return visco_elastic.constraint_dissipation(f, d_rate, p)
    if code == SLIDING:
        return sliding.constraint_dissipation(f, d_rate, p)
    return free.constraint_dissipation(f, d_rate, p)


@jit(forceinline=True)
def _put(out, i, x):
    out[i] = x[0]
    out[i + 1] = x[1]
    out[i + 2] = x[2]


@jit
def state_rate(code, t, y, p, dy):
    """dy/dt of one state ``y`` at time ``t`` [s] of the variant ``code`` into ``dy``
    (same shape).

    The body's equations (eq 1) are written once; only the constraint law depends on the
    variant (:func:`constraint_force`). ``permanent`` is the reduced system (eq 15). The
    time enters through the disturbances only (:mod:`rbstab.variants.disturbances`: their
    force F joins H, their torque T about the centre of mass joins N).

    ``y`` may carry one entry after the variant's state (size :data:`STATE_SIZE`): the
    work W [J] of the disturbances, which the compiled drivers integrate with the state
    (eq 26's work term); its rate is their power P = F'V + Omega'(T + R_p x A'F) [W]
    (:func:`rbstab.variants.disturbances.disturbance_power`; 0 without disturbances).
    """
    if code == PERMANENT:
        theta, omega, x, v, a, b, n, h, lam, omega_dot, force_d, torque_d = permanent.quantities(t, y, p)
        _put(dy, 0, matvec(b, omega))
        _put(dy, 3, omega_dot)
        if dy.shape[0] > PERMANENT_SIZE:  # force_d, torque_d are zero without disturbances
            dy[PERMANENT_SIZE] = disturbance_power(force_d, torque_d, omega, v)
        return
    if code >= sliding.MODE_CODES:  # the pure sign law in a mode (rbstab.engine.switching)
        sliding.mode_rate(y, p, sliding.mode_of(code), dy)
        return
    theta, omega, x, v, d, a, b, e, f = body_state(y, p)
    lam, d_rate = constraint_force(code, e, f, d, p)
    n, h = torque_n(b, theta, omega, p), force_h(x, v, p)
    force_d, torque_d = ZERO, ZERO
    if p.disturbance_count > 0.0:
        force_d, torque_d = disturbance_wrench(t, a, p)
        n, h = add(n, torque_d), add(h, force_d)
    theta_dot, omega_dot, x_dot, v_dot = body_rates(omega, v, a, b, n, h, lam, p)
    _put(dy, 0, theta_dot)
    _put(dy, 3, omega_dot)
    _put(dy, 6, x_dot)
    _put(dy, 9, v_dot)
    size = EMBEDDED_SIZE if code == EMBEDDED else FULL_SIZE
    if size == EMBEDDED_SIZE:
        _put(dy, 12, d_rate)
    if dy.shape[0] > size:
        dy[size] = disturbance_power(force_d, torque_d, omega, v)


@jit(forceinline=True)
def _lyapunov(out, theta, omega, x, v, p, constraint, constraint_dissipation, added):
    """v, its terms and dv/dt into ``out``: the body's (eq 25, gravity) plus the
    constraint's, and ``added`` [W], the power that the saturation of the controls
    (:func:`saturation_effects`) and the disturbances add to dv/dt."""
    translational, rotational, gravity = body_energy(theta, omega, x, v, p)
    out[TRANSLATIONAL_AT] = translational
    out[ROTATIONAL_AT] = rotational
    out[CONSTRAINT_AT] = constraint
    out[GRAVITY_AT] = gravity
    out[LYAPUNOV_AT] = translational + rotational + constraint + gravity
    out[LYAPUNOV_RATE_AT] = -(body_dissipation(omega, v, p) + constraint_dissipation) + added


@jit(forceinline=True)
def saturation_effects(code, theta, omega, x, v, b, e, f, d, p):
    """(power [W], N flags, H flags, Lambda flags) of the actuators' limits at one state.

    The power Omega'(N - N_c) + V'(H - H_c) + F'(Lambda - Lambda_c) is what dv/dt gains
    when the delivered controls N, H, Lambda differ from the commanded N_c, H_c, Lambda_c
    (eqs 23, 24, 22, 39, 40). dv/dt = Omega'(N + B'K_r Theta) + V'(H + K_t X) + F'Lambda +
    dv_c/dt (eq 1 with eqs 25, 42, 45), whose commanded form is the paper's -V'L_t V -
    Omega'L_r Omega - ... (eqs 29, 43, 46): the delivered dv/dt is that plus this term
    (docs/physics.md). ``permanent``'s Lambda is the pin's reaction (F = 0, no work, never
    flagged). The flags (3 each, 1.0 or 0.0) mark the axes commanded at or beyond their
    limits (:func:`rbstab.model.saturated`). 0 and no flags without limits."""
    if p.saturation == 0.0:
        return 0.0, ZERO, ZERO, ZERO
    n_c, h_c = torque_n_command(b, theta, omega, p), force_h_command(x, v, p)
    n, h = saturate(n_c, p.torque_limit, p.saturation), saturate(h_c, p.force_limit, p.saturation)
    power = dot(omega, sub(n, n_c)) + dot(v, sub(h, h_c))
    lam_flags = ZERO
    if code != PERMANENT:
        lam_c, _ = constraint_force_command(code, e, f, d, p)
        power += dot(f, sub(saturate(lam_c, p.constraint_force_limit, p.saturation), lam_c))
        lam_flags = saturated(lam_c, p.constraint_force_limit)
    return power, saturated(n_c, p.torque_limit), saturated(h_c, p.force_limit), lam_flags


@jit(forceinline=True)
def output_row(code, t, y, p, out, full):
    """The outputs of one state at time ``t`` [s] into ``out`` (length N_OUTPUTS, each at
    its offset in :data:`rbstab.layout.OUTPUTS`; the saturation flags from
    :func:`saturation_effects`): all of them if
    ``full``, else all but :data:`~rbstab.layout.LEFT_OUT` (their entries are not written;
    N and H are then not computed: 20-30 % less time a sample). ``disturbance_work`` is
    written 0: it is the run's history, not the state's (the drivers write it).

    Inlined into :func:`run_outputs`: ~20 % less time than a call a sample (the same bits).
    """
    if code == PERMANENT:
        theta, omega, x, v, a, b, n, h, lam, omega_dot, force_d, torque_d = permanent.quantities(t, y, p)
        e = constraint_error(x, a, p)
        f = constraint_rate(omega, v, a, p)
        d, energy, dissipation = ZERO, 0.0, 0.0
    else:
        theta, omega, x, v, d, a, b, e, f = body_state(y, p)
        lam, d_rate = constraint_force(code, e, f, d, p)
        energy = constraint_energy(code, e, d, p)
        dissipation = constraint_dissipation(code, f, d_rate, p)
        if full:
            n, h = torque_n(b, theta, omega, p), force_h(x, v, p)
        else:  # not written below; given a value so that n and h are defined on every path
            n, h = ZERO, ZERO
        if p.disturbance_count > 0.0:
            force_d, torque_d = disturbance_wrench(t, a, p)
        else:
            force_d, torque_d = ZERO, ZERO
    _put(out, THETA_AT, theta)
    _put(out, OMEGA_AT, omega)
    _put(out, POSITION_AT, x)
    _put(out, VELOCITY_AT, v)
    _put(out, CONTROLLER_STATE_AT, d)
    _put(out, CONSTRAINT_ERROR_AT, e)
    if full or code == PERMANENT:  # rbstab.layout.LEFT_OUT, but a pinned body's Lambda and N (computed: its
        _put(out, CONSTRAINT_FORCE_AT, lam)  # centre of pressure reads them, body_pressure)
        _put(out, TORQUE_N_AT, n)
    if full:
        _put(out, CONSTRAINT_RATE_AT, f)
        _put(out, FORCE_H_AT, h)
    power = 0.0
    if p.disturbance_count > 0.0:
        power = disturbance_power(force_d, torque_d, omega, v)
    out[DISTURBANCE_POWER_AT] = power
    out[DISTURBANCE_WORK_AT] = 0.0 if y[0] == y[0] else math.nan  # NaN after a stop, as the drivers'
    edges = 0.0
    if p.disturbance_count > 0.0:
        edges = edges_up_to(p, t)
    out[DISTURBANCE_EDGES_AT] = edges if y[0] == y[0] else math.nan
    added, n_flags, h_flags, lam_flags = saturation_effects(code, theta, omega, x, v, b, e, f, d, p)
    if y[0] != y[0]:  # a stopped run's NaN rows: no flag either
        n_flags = h_flags = lam_flags = (math.nan, math.nan, math.nan)
    _put(out, TORQUE_N_SATURATED_AT, n_flags)
    _put(out, FORCE_H_SATURATED_AT, h_flags)
    _put(out, CONSTRAINT_FORCE_SATURATED_AT, lam_flags)
    if p.disturbance_count > 0.0:
        added += power
    _lyapunov(out, theta, omega, x, v, p, energy, dissipation, added)


@jit
def state_rates(code, t, y, params, out):
    """dy/dt of every row of ``y`` (m, n_state) at the times ``t`` (1 or m) into ``out``;
    ``params`` has 1 or m records."""
    for k in range(y.shape[0]):
        state_rate(code, t[min(k, t.shape[0] - 1)], y[k], params[min(k, params.shape[0] - 1)], out[k])


@jit(forceinline=True)
def body_pressure(code, row, p):
    """The centre of pressure [m] (inertial frame; :func:`rbstab.model.pressure_point`) of
    one body of law ``code`` at one row of outputs ``row`` (:func:`output_row`; read: Theta,
    Lambda, N): for ``permanent`` the ground's force Lambda at C = R and its moment A N about
    C (eq 20), about the origin A N + R x Lambda; NaN for the other laws (no point the ground
    holds). ``p`` the body's record (R, its weight's direction)."""
    if code != PERMANENT:
        return math.nan, math.nan, math.nan
    lam = vector(row, CONSTRAINT_FORCE_AT)
    a, _ = rotation_and_rate_of(vector(row, THETA_AT))
    moment = add(matvec(a, vector(row, TORQUE_N_AT)), cross(p.attachment_point, lam))
    return pressure_point(lam, moment, p.weight)


@jit(nogil=True)
def body_pressures(code, params, columns, out):
    """:func:`body_pressure` of every sample of k runs of law ``code``: ``columns``
    (N_OUTPUTS, k, m) their outputs (:func:`run_outputs`), ``params`` (k,) their records;
    into ``out`` (k, m, 3) [m]."""
    for k in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[k, j, 0], out[k, j, 1], out[k, j, 2] = body_pressure(code, columns[:, k, j], params[k])


@jit(nogil=True)  # no Python object inside: threads run it in parallel
def run_outputs(codes, params, times, samples, out, full):
    """Outputs of k runs: ``samples`` (k, n_samples, n_state) at ``times`` (k or 1,
    n_samples) of runs with variant ``codes`` (k,) and ``params`` (k,) into ``out``
    (N_OUTPUTS, k, n_samples), an output by row: each output of a run is contiguous in
    time, as the summaries read it. ``full`` (bool): every output, or all but
    :data:`~rbstab.layout.LEFT_OUT` (their rows not written)."""
    for k in range(samples.shape[0]):
        row = min(k, times.shape[0] - 1)
        for j in range(samples.shape[1]):
            output_row(codes[k], times[row, j], samples[k, j], params[k], out[:, k, j], full)


@jit
def state_powers(code, t, y, params, out):
    """The disturbances' power P [W] at every row of ``y`` (m, n_state) at the times ``t``
    (m,) into ``out`` (m,); ``params`` has 1 record."""
    for k in range(y.shape[0]):
        out[k] = state_power(code == PERMANENT, t[k], y[k], params[0])
