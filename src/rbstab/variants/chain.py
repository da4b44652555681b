"""The physics of a chain of rigid bodies in maximal coordinates (docs/physics.md, "Chains
of rigid bodies"): the applied wrenches, the joints' quantities (Lambda_j of permanent joints
by the stacked eq 15), its Lyapunov function v with its terms and analytic rate at any
state, a push's jump, and its rest state. Runs integrate the same tree in reduced
coordinates (:mod:`rbstab.variants.tree`), whose rate calls :func:`chain_wrenches`; the
maximal rate here (:func:`chain_rate`) gives the outputs at the samples and is the
independent formulation the reduced one is checked against.

A chain is compiled once (:func:`compile_chain`) into runtime records, so one compiled code
path serves any chain of 1-8 bodies: a :data:`rbstab.model.PARAMETERS` record per body and
its joint (body ``i`` and joint ``i``, whose child it is: the body's mass, inertia, weight,
K_t, L_t and the limits of H; the joint's child point as ``attachment_point``, its K_r, L_r,
point-law gains and the limits of N_j and Lambda_j; the body's disturbances), the variant
code, parent index and parent point of each joint. The point laws are the variants' own
compiled functions (:mod:`rbstab.variants.kernels`): a one-body chain is today's body.

State layout (``n_states = 12 n + 3 e``): body ``i`` at ``y[12 i: 12 i + 12]`` = Theta
[rad], Omega [rad/s] (body frame), X [m], V [m/s] (inertial frame); then the 3 states D [m]
of each ``embedded`` joint, in joint order. ``permanent`` joints are held in maximal
coordinates by the constraint forces that make d^2E_j/dt^2 = 0 (the stacked eq 15: one
linear solve of 3k unknowns for k permanent joints).
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Sequence
import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np

from ..chain import Chain
from ..jit import jit
from ..kinematics import (IDENTITY, ZERO, add, axis_angle, axis_rotation, cross, euler_angles_of, dot, matTvec, matvec,
                          quadratic_form,
                          right_jacobian_inverse, rotation_and_rate_of, rotation_matrix, rotation_vector, sub,
                          universal_angles, universal_rate, universal_rotation, vector, vector_rotation)
from ..layout import AXES, BEYOND_PAPER, JOINT_CODES, LEFT_OUT, LIMITED_COMPONENTS, LYAPUNOV_TERMS, N_OUTPUTS, OUTPUTS, \
    POINT_FIXED, SATURATION_FLAGS, VARIANT_CODES, display_units
from ..model import (
    PARAMETERS,
    force_h,
    force_h_command,
    gyroscopic,
    parameters,
    saturate_between,
    saturated_between,
    torque_n_command,
)
from .disturbances import IMPULSE, PULSE, disturbance_power, disturbance_wrench
from .kernels import BALL, EMBEDDED, HINGE, PERMANENT, SLIDE, UNIVERSAL, body_pressures, constraint_dissipation, \
    constraint_energy, constraint_force, constraint_force_command, run_outputs, saturation_effects
from .paper import body_model
from .registry import record_offsets

__all__ = ["CompiledChain", "ChainTrajectory", "compile_chain", "initial_state", "chain_rate", "evaluate",
           "lyapunov", "rest_state", "rest_offset", "reference_posture", "records_of", "is_one_body", "one_body_mask", "papers_feedback", "gimbal_lock_message", "locked_part", "gimbal_part_name", "independent_coordinates", "full_state",
           "region_margin", "slide_coordinates", "gimbal_angles", "state_vector", "with_records", "bound_reached", "place", "chain_push", "chain_push_with", "chain_evaluate", "ChainWork", "chain_work", "impulse_times", "disturbance_edges", "BODY_OUTPUTS", "JOINT_OUTPUTS", "SCALAR_OUTPUTS"]

#: Per-body outputs of :func:`evaluate`, each (n_samples, n_bodies, 3).
BODY_OUTPUTS = ("theta", "omega", "position", "velocity", "force_h", "force_h_saturated")
#: Per-joint outputs of :func:`evaluate`, each (n_samples, n_joints, 3).
JOINT_OUTPUTS = ("constraint_error", "constraint_rate", "constraint_force", "torque_n", "controller_state",
                 "joint_theta", "joint_omega", "torque_n_saturated", "constraint_force_saturated")
#: Scalar outputs of :func:`evaluate`, each (n_samples,).
SCALAR_OUTPUTS = ("lyapunov", "lyapunov_rate", "lyapunov_translational", "lyapunov_rotational",
                  "lyapunov_constraint", "lyapunov_gravity")

# Rows of the per-joint record the compiled core fills.
_E, _F, _LAMBDA, _N, _D, _THETA_J, _OMEGA_J = range(7)
# Entries of the scalar record: the terms of v (eq 25's grouping; h not included) and dv/dt.
_TRANSLATIONAL, _ROTATIONAL, _CONSTRAINT, _GRAVITY, _RATE = range(5)

#: Scratch arrays of one evaluation of a chain of n bodies (:func:`chain_work`): ``rot``,
#: ``rate`` (n, 3, 3) A_i and B(Theta_i); ``torque``, ``force`` (n, 3) the wrench on each body
#: (body-frame torque [N m], inertial force [N]); ``g`` (n, 3, 3) the inverse inertias in
#: the inertial frame [1/(kg m^2)]; ``matrix`` (3n, 3n) and ``rhs`` (3n,) the permanent joints'
#: linear system; ``which`` (n,) int64 the permanent joints; ``joints`` (n, 7, 3),
#: ``bodies`` (n, 3), ``scalars`` (5,) the per-joint, per-body and scalar records
#: :func:`chain_core` fills; ``angle`` (n, 2) each hinge's q (column 0), each universal
#: joint's q_1, q_2 [rad]: given by the caller
#: (:func:`chain_wrenches`' ``rotations``), else the last one read (0 in a new work: a
#: new run starts from it); each slide's q [m] and u [m/s], as :func:`chain_wrenches` read them. The compiled driver holds one per chain (in its system), so an
#: evaluation allocates nothing.
ChainWork = namedtuple("ChainWork", ["rot", "rate", "torque", "force", "g", "matrix", "rhs",
                                     "which", "joints", "bodies", "scalars", "angle"])


@jit
def chain_work(n):
    """Scratch arrays (:class:`ChainWork`) of a chain of ``n`` bodies."""
    return ChainWork(np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3)),
                     np.empty((3 * n, 3 * n)), np.empty(3 * n), np.empty(n, dtype=np.int64),
                     np.empty((n, 7, 3)), np.empty((n, 3)), np.empty(5), np.zeros((n, 2)))


# -- compiled core --------------------------------------------------------------------------
@jit(forceinline=True)
def _relative(a_p, a_c):
    """A_rel = A_p' A_c as a tuple of rows."""
    return (
        (a_p[0][0] * a_c[0][0] + a_p[1][0] * a_c[1][0] + a_p[2][0] * a_c[2][0],
         a_p[0][0] * a_c[0][1] + a_p[1][0] * a_c[1][1] + a_p[2][0] * a_c[2][1],
         a_p[0][0] * a_c[0][2] + a_p[1][0] * a_c[1][2] + a_p[2][0] * a_c[2][2]),
        (a_p[0][1] * a_c[0][0] + a_p[1][1] * a_c[1][0] + a_p[2][1] * a_c[2][0],
         a_p[0][1] * a_c[0][1] + a_p[1][1] * a_c[1][1] + a_p[2][1] * a_c[2][1],
         a_p[0][1] * a_c[0][2] + a_p[1][1] * a_c[1][2] + a_p[2][1] * a_c[2][2]),
        (a_p[0][2] * a_c[0][0] + a_p[1][2] * a_c[1][0] + a_p[2][2] * a_c[2][0],
         a_p[0][2] * a_c[0][1] + a_p[1][2] * a_c[1][1] + a_p[2][2] * a_c[2][1],
         a_p[0][2] * a_c[0][2] + a_p[1][2] * a_c[1][2] + a_p[2][2] * a_c[2][2]),
    )


@jit(forceinline=True)
def compose(a_p, rel):
    """A_p A_rel as a tuple of rows."""
    return (
        (a_p[0][0] * rel[0][0] + a_p[0][1] * rel[1][0] + a_p[0][2] * rel[2][0],
         a_p[0][0] * rel[0][1] + a_p[0][1] * rel[1][1] + a_p[0][2] * rel[2][1],
         a_p[0][0] * rel[0][2] + a_p[0][1] * rel[1][2] + a_p[0][2] * rel[2][2]),
        (a_p[1][0] * rel[0][0] + a_p[1][1] * rel[1][0] + a_p[1][2] * rel[2][0],
         a_p[1][0] * rel[0][1] + a_p[1][1] * rel[1][1] + a_p[1][2] * rel[2][1],
         a_p[1][0] * rel[0][2] + a_p[1][1] * rel[1][2] + a_p[1][2] * rel[2][2]),
        (a_p[2][0] * rel[0][0] + a_p[2][1] * rel[1][0] + a_p[2][2] * rel[2][0],
         a_p[2][0] * rel[0][1] + a_p[2][1] * rel[1][1] + a_p[2][2] * rel[2][1],
         a_p[2][0] * rel[0][2] + a_p[2][1] * rel[1][2] + a_p[2][2] * rel[2][2]),
    )


@jit(forceinline=True)
def _nearest_turn(angle, reference):
    """``angle`` [rad] plus the whole turns 2 pi k that bring it nearest ``reference``."""
    return angle + 2.0 * math.pi * math.floor((reference - angle) / (2.0 * math.pi) + 0.5)


@jit(forceinline=True)
def euler_angles(a):
    """Theta with A(Theta) = a = Rx Ry Rz (eq 2), |theta_2| <= pi/2, theta_1, theta_3 in
    (-pi, pi]: a[0][2] = s2, a[1][2] = -s1 c2, a[2][2] = c1 c2, a[0][1] = -c2 s3,
    a[0][0] = c2 c3."""
    s2 = min(1.0, max(-1.0, a[0][2]))
    return (math.atan2(-a[1][2], a[2][2]), math.asin(s2), math.atan2(-a[0][1], a[0][0]))


@jit(forceinline=True)
def _euler_rate_of(a):
    """B(Theta) (eq 1, as :func:`rbstab.kinematics.rotation_and_rate_of`'s) of the rotation
    a = A(Theta), read from its entries: c2 = hypot(a[0][0], a[0][1]), s2 = a[0][2],
    c2 c3 = a[0][0], -c2 s3 = a[0][1] (no trigonometric function)."""
    c2_sq = a[0][0] * a[0][0] + a[0][1] * a[0][1]
    c2 = math.sqrt(c2_sq)
    s2 = a[0][2]
    c3_c2, s3_c2 = a[0][0] / c2_sq, -a[0][1] / c2_sq
    return ((c3_c2, -s3_c2, 0.0), (s3_c2 * c2, c3_c2 * c2, 0.0), (-s2 * c3_c2, s2 * s3_c2, 1.0))


@jit(forceinline=True)
def _put(out, i, x):
    out[i] = x[0]
    out[i + 1] = x[1]
    out[i + 2] = x[2]


@jit(forceinline=True)
def _acc_add(torque, force, i, dt, df):
    for k in range(3):
        torque[i, k] += dt[k]
        force[i, k] += df[k]


@jit(forceinline=True)
def _point_acceleration(i, r, rot, y, torque, force, params, with_velocity):
    """d^2/dt^2 (X_i + A_i r) [m/s^2], inertial frame, of body i under its body-frame torque
    and inertial force (rows i of ``torque``, ``force``); ``with_velocity``: with the
    centripetal term A (Omega x (Omega x r)), else the part linear in the wrench only."""
    p = params[i]
    omega_dot = matvec(p.inertia_inv, vector(torque[i], 0))
    acc = (force[i, 0] / p.mass, force[i, 1] / p.mass, force[i, 2] / p.mass)
    local = cross(omega_dot, r)
    if with_velocity:
        omega = vector(y, 12 * i + 3)
        local = add(local, cross(omega, cross(omega, r)))
    return add(acc, matvec(rot[i], local))


@jit
def chain_core(t, y, params, codes, parents, ppoints, d_at, dy, joints, bodies, scalars):
    """:func:`chain_evaluate` with scratch arrays of its own (for callers in Python)."""
    chain_evaluate(t, y, params, codes, parents, ppoints, d_at, dy, joints, bodies, scalars,
                   chain_work(codes.shape[0]))


@jit(forceinline=True)
def _stop(n_j, energy, dissipation, angle, rate, direction, p, i):
    """(N_j, v's term, the dissipation [W]) with the stop of coordinate i of a joint (its record
    ``p``: ends ``range_lower[i]``, ``range_upper[i]``, gains ``stop_k[i]``, ``stop_l[i]``) at
    ``angle`` [rad] and its ``rate`` [rad/s] added: beyond an end, by delta = angle - end,
    the torque n_s = -k delta - l rate along ``direction`` (the coordinate's row of B, whose
    power on Omega_j is n_s rate), the energy 1/2 k delta^2 and the dissipation l rate^2."""
    beyond = max(angle - p.range_upper[i], 0.0) + min(angle - p.range_lower[i], 0.0)
    if beyond == 0.0:
        return n_j, energy, dissipation
    n_s = -p.stop_k[i] * beyond - p.stop_l[i] * rate
    return (add(n_j, (n_s * direction[0], n_s * direction[1], n_s * direction[2])),
            energy + 0.5 * p.stop_k[i] * beyond * beyond, dissipation + p.stop_l[i] * rate * rate)


@jit(forceinline=True)
def _ball_strain(rel, reference):
    """(phi, J_r(phi)^-1) of a quaternion ball: phi = log(A(Theta_ref)' A_rel) [rad], the
    rotation vector of the turn from its reference ``reference`` (a rotation vector) to its
    relative rotation ``rel``, and the map of Omega_j to dphi/dt."""
    r = vector_rotation(vector(reference, 0))
    phi = rotation_vector(_relative(r, rel))
    return phi, right_jacobian_inverse(phi)


@jit(forceinline=True)
def _feedback(b_j, strain, b_p, passive, omega_j, p, rotational, dissipation, power):
    """A joint's torque N_j [N m] (child frame): eq 23 about the reference posture (``strain``
    = Theta_j - Theta_ref, ``b_j`` = B(Theta_j); a hinge's written as a ball's, B = I; a
    quaternion ball's phi and J_r(phi)^-1) through its actuators' limits [torque_floor,
    torque_limit] per axis, plus the passive torque of eq 23's form with its own gains and
    reference (``passive``, ``b_p`` its strain and B), never limited; returns it with v's
    rotational term, the dissipation [W] and the saturation deficit power [W] accumulated."""
    n_j = torque_n_command(b_j, strain, omega_j, p)
    if p.saturation > 0.0:
        commanded = n_j
        n_j = saturate_between(commanded, p.torque_floor, p.torque_limit, p.saturation)
        power += dot(omega_j, sub(n_j, commanded))
    rotational += 0.5 * quadratic_form(strain, p.k_r)
    dissipation += quadratic_form(omega_j, p.l_r)
    if p.passive > 0.0:
        n_j = sub(sub(n_j, matTvec(b_p, matvec(p.passive_k_r, passive))), matvec(p.passive_l_r, omega_j))
        rotational += 0.5 * quadratic_form(passive, p.passive_k_r)
        dissipation += quadratic_form(omega_j, p.passive_l_r)
    return n_j, rotational, dissipation, power


@jit(forceinline=True)
def _coordinate_feedback(b_j, strain, theta_j, omega_j, p, rotational, dissipation, power):
    """A universal joint's torque N_j = B' f [N m] (child frame; B its
    :func:`rbstab.kinematics.universal_rate`, whose rows give its coordinates' rates dq/dt =
    B Omega_j) of the force on its coordinates f = -K_r (q - q_ref) - L_r dq/dt [N m]
    (``strain`` = q - q_ref, entries 0-1 of 3-vectors): :func:`_feedback` on the coordinates
    (B = I there, dq/dt for Omega), its limits and passive torque per coordinate; returns
    it with v's rotational term, the dissipation [W] and the saturation deficit power [W]
    accumulated (S'N_j = f: the power on the child is dq/dt' f)."""
    f, rotational, dissipation, power = _feedback(IDENTITY, strain, IDENTITY, sub(theta_j, p.passive_theta_ref),
                                                  matvec(b_j, omega_j), p, rotational, dissipation, power)
    return matTvec(b_j, f), rotational, dissipation, power


@jit(forceinline=True)
def _joint_torque(code, p, rel, theta_j, b_j, strain, omega_j, rotational, dissipation, power):
    """A turning joint's torque N_j [N m] (child frame) on its coordinates, with its stop: a
    universal joint's on q_1, q_2 (:func:`_coordinate_feedback`), a quaternion ball's on the
    rotation vectors of its turns from its references (B = J_r^-1) and its cone, a hinge's,
    an Euler ball's and a free body's on Theta_j (``strain`` = Theta_j - Theta_ref, ``b_j``
    its B; a hinge's the rotation vector q a, B = I); returns it with v's rotational term,
    the dissipation [W] and the saturation deficit power [W] accumulated."""
    if code == UNIVERSAL:
        n_j, rotational, dissipation, power = _coordinate_feedback(b_j, strain, theta_j, omega_j, p, rotational,
                                                                   dissipation, power)
    elif code == BALL:
        passive, b_p = strain, b_j
        for r in range(2):  # its spring's, then its passive spring's (one copy of the code)
            phi, b = _ball_strain(rel, p.theta_ref if r == 0 else p.passive_theta_ref)
            if r == 0:
                strain, b_j = phi, b
            else:
                passive, b_p = phi, b
        n_j, rotational, dissipation, power = _feedback(b_j, strain, b_p, passive, omega_j, p, rotational,
                                                        dissipation, power)
    else:
        n_j, rotational, dissipation, power = _feedback(b_j, strain, b_j, sub(theta_j, p.passive_theta_ref),
                                                        omega_j, p, rotational, dissipation, power)
    if p.stop == 0.0:  # its range: beyond either end of a coordinate a one-sided spring and damper, never limited
        return n_j, rotational, dissipation, power
    if code == HINGE:  # q = a'Theta_j, its rate a'Omega_j, its torque along a
        axis = vector(p.axis, 0)
        n_j, rotational, dissipation = _stop(n_j, rotational, dissipation, dot(theta_j, axis), dot(omega_j, axis),
                                             axis, p, 0)
    elif code == BALL:  # its cone: the turn's angle |Theta_j|, its rate e'Omega_j, its torque along e
        angle = math.sqrt(dot(theta_j, theta_j))
        e = (0.0, 0.0, 1.0) if angle == 0.0 else (theta_j[0] / angle, theta_j[1] / angle, theta_j[2] / angle)
        n_j, rotational, dissipation = _stop(n_j, rotational, dissipation, angle, dot(e, omega_j), e, p, 0)
    else:  # a ball's Euler angle theta_i (a universal joint's q_i), its rate (B Omega_j)_i, its torque B' e_i
        for i in range(2 if code == UNIVERSAL else 3):
            n_j, rotational, dissipation = _stop(n_j, rotational, dissipation, theta_j[i], dot(b_j[i], omega_j),
                                                 b_j[i], p, i)
    return n_j, rotational, dissipation, power


@jit(forceinline=True)
def _pair_at(torque, force, rot, j, q, r_c, r_p, lam):
    """Add the force ``lam`` [N, inertial] on body j at its point ``r_c`` (its frame) and
    -``lam`` on its parent q at ``r_p`` (the parent's frame; none where q < 0, the ground), the
    same point: the wrench of a point law's or a slide's force."""
    _acc_add(torque, force, j, cross(r_c, matTvec(rot[j], lam)), lam)
    if q >= 0:
        back = cross(r_p, matTvec(rot[q], lam))
        _acc_add(torque, force, q, (-back[0], -back[1], -back[2]), (-lam[0], -lam[1], -lam[2]))


@jit(forceinline=True, _nrt=False)
def chain_wrenches(t, y, params, codes, parents, ppoints, d_at, dy, joints, bodies, scalars, work, rotations=False):
    """What :func:`chain_evaluate` computes before the permanent joints' Lambda_j: the
    rotations A_i and B(Theta_i) into ``work.rot``, ``work.rate`` (``rotations``: the caller
    has put A_i there already, B(Theta_j) of each joint to the ground and each hinge's q
    into ``work.angle``; else a hinge's q is read from A_rel, the angle nearest the last one
    read into ``work.angle``, which it replaces: q continued from sample to sample of a run
    that turns a hinge by less than pi between them; a slide's q, u read from its points into
    ``work.angle`` either way); the wrench on each body of
    everything but those Lambda_j into ``work.torque`` (body frame, the gyroscopic term
    -Omega x J Omega included) and ``work.force`` (inertial); per joint E_j, F_j, Lambda_j
    (point laws; zero for permanent joints), N_j, D_j, Theta_j, Omega_j into ``joints``; H
    into ``bodies``; the translational, rotational, constraint and gravity terms of v (eq
    25's grouping, summed over the bodies and joints) into ``scalars[:4]``; dD/dt of
    embedded joints into ``dy``. Returns (the number of permanent
    joints, the saturation deficit power, the disturbances' power, the dissipation [W], the
    state's size 12 n + 3 e)."""
    n = codes.shape[0]
    rot, rate, torque, force = work.rot, work.rate, work.torque, work.force
    torque[:] = 0.0
    force[:] = 0.0
    translational = 0.0
    rotational = 0.0
    constraint = 0.0
    gravity = 0.0
    dissipation = 0.0
    power = 0.0
    work_power = 0.0
    size = 12 * n
    for i in range(n):
        if d_at[i] >= 0:
            size += 3
        if rotations:
            continue
        a, b = rotation_and_rate_of(vector(y, 12 * i))
        for r in range(3):
            for c in range(3):
                rot[i, r, c] = a[r][c]
                rate[i, r, c] = b[r][c]
    for i in range(n):
        p = params[i]
        omega, x, v = vector(y, 12 * i + 3), vector(y, 12 * i + 6), vector(y, 12 * i + 9)
        h = force_h(x, v, p)
        if p.saturation > 0.0:
            power += dot(v, sub(h, force_h_command(x, v, p)))
        _put(bodies[i], 0, h)
        tq = gyroscopic(p.inertia, omega)
        fc = add(p.weight, h)
        if p.disturbance_count > 0.0:
            force_d, torque_d = disturbance_wrench(t, rot[i], p)
            tq, fc = add(tq, torque_d), add(fc, force_d)
            work_power += disturbance_power(force_d, torque_d, omega, v)
        _acc_add(torque, force, i, tq, fc)
        translational += 0.5 * p.mass * dot(v, v) + 0.5 * quadratic_form(x, p.k_t)
        rotational += 0.5 * quadratic_form(omega, p.inertia)
        gravity -= dot(x, p.weight)
        dissipation += quadratic_form(v, p.l_t)
    n_permanent = 0
    for j in range(n):
        p = params[j]
        q = parents[j]
        omega_c, x_c, v_c = vector(y, 12 * j + 3), vector(y, 12 * j + 6), vector(y, 12 * j + 9)
        r_c, r_p = p.attachment_point, vector(ppoints[j], 0)
        if q < 0:
            point_p, rate_p = r_p, ZERO
            theta_j, omega_j = vector(y, 12 * j), omega_c
            rel = ((rot[j, 0, 0], rot[j, 0, 1], rot[j, 0, 2]), (rot[j, 1, 0], rot[j, 1, 1], rot[j, 1, 2]),
                   (rot[j, 2, 0], rot[j, 2, 1], rot[j, 2, 2]))  # A(Theta_j) = A_j: the ground's A_p is I
            b_j = ((rate[j, 0, 0], rate[j, 0, 1], rate[j, 0, 2]), (rate[j, 1, 0], rate[j, 1, 1], rate[j, 1, 2]),
                   (rate[j, 2, 0], rate[j, 2, 1], rate[j, 2, 2]))
        else:
            omega_p, x_p, v_p = vector(y, 12 * q + 3), vector(y, 12 * q + 6), vector(y, 12 * q + 9)
            point_p = add(x_p, matvec(rot[q], r_p))
            rate_p = add(v_p, matvec(rot[q], cross(omega_p, r_p)))
            rel = _relative(rot[q], rot[j])
            theta_j = euler_angles(rel)
            b_j = _euler_rate_of(rel)
            omega_j = sub(omega_c, matTvec(rel, omega_p))
        if codes[j] == HINGE:  # its coordinate as the rotation vector q a, whose rate is Omega_j
            axis = vector(p.axis, 0)
            angle = work.angle[j, 0]
            if not rotations:
                angle = _nearest_turn(axis_angle(rel, axis), angle)
                work.angle[j, 0] = angle
            theta_j, b_j = (angle * axis[0], angle * axis[1], angle * axis[2]), IDENTITY
        elif codes[j] == UNIVERSAL:  # its coordinates (q_1, q_2, 0), B maps Omega_j to their rates
            a_1, a_2 = vector(p.axis, 0), vector(p.axis_2, 0)
            q_1, q_2 = work.angle[j, 0], work.angle[j, 1]
            if not rotations:
                read_1, read_2 = universal_angles(rel, a_1, a_2)
                q_1, q_2 = _nearest_turn(read_1, q_1), _nearest_turn(read_2, q_2)
                work.angle[j, 0], work.angle[j, 1] = q_1, q_2
            theta_j, b_j = (q_1, q_2, 0.0), universal_rate(a_1, a_2, q_2)
        elif codes[j] == BALL:  # the rotation vector of A_rel; its feedback on the turn from its reference
            theta_j = rotation_vector(rel)
        e = sub(add(x_c, matvec(rot[j], r_c)), point_p)
        f = sub(add(v_c, matvec(rot[j], cross(omega_c, r_c))), rate_p)
        strain = sub(theta_j, p.theta_ref)  # the spring's: Theta_j - Theta_ref (eq 23 about the reference posture)
        pull = ZERO
        if codes[j] == SLIDE:  # on its coordinate q = a'E_j, u = a'F_j (a the axis, inertial): the force f a at C
            axis = vector(p.axis, 0)
            if q >= 0:
                axis = matvec(rot[q], axis)
            s, u = dot(axis, e), dot(axis, f)
            work.angle[j, 0], work.angle[j, 1] = s, u
            theta_j, omega_j, n_j = ZERO, ZERO, ZERO
            coordinate, constraint, dissipation, power = _feedback(
                IDENTITY, (s - p.theta_ref[0], 0.0, 0.0), IDENTITY, (s - p.passive_theta_ref[0], 0.0, 0.0),
                (u, 0.0, 0.0), p, constraint, dissipation, power)
            if p.stop > 0.0:
                coordinate, constraint, dissipation = _stop(coordinate, constraint, dissipation, s, u, (1.0, 0.0, 0.0),
                                                            p, 0)
            pull = (axis[0] * coordinate[0], axis[1] * coordinate[0], axis[2] * coordinate[0])
            _pair_at(torque, force, rot, j, q, r_c, add(r_p, (p.axis[0] * s, p.axis[1] * s, p.axis[2] * s)), pull)
        else:
            n_j, rotational, dissipation, power = _joint_torque(codes[j], p, rel, theta_j, b_j, strain, omega_j,
                                                                rotational, dissipation, power)
        _acc_add(torque, force, j, n_j, ZERO)
        if q >= 0:
            reaction = matvec(rel, n_j)
            _acc_add(torque, force, q, (-reaction[0], -reaction[1], -reaction[2]), ZERO)
        d = ZERO
        lam = pull  # a slide's force at C (its reaction, from the motion: rbstab.variants.tree.tree_reactions)
        if d_at[j] >= 0:
            d = vector(y, d_at[j])
        if codes[j] == PERMANENT:
            n_permanent += 1
        elif not POINT_FIXED[codes[j]]:
            lam, d_rate = constraint_force(codes[j], e, f, d, p)
            if p.saturation > 0.0:
                lam_c, _ = constraint_force_command(codes[j], e, f, d, p)
                power += dot(f, sub(lam, lam_c))
            constraint += constraint_energy(codes[j], e, d, p)
            dissipation += constraint_dissipation(codes[j], f, d_rate, p)
            _pair_at(torque, force, rot, j, q, r_c, r_p, lam)
            if d_at[j] >= 0:
                _put(dy, d_at[j], d_rate)
        _put(joints[j, _E], 0, e)
        _put(joints[j, _F], 0, f)
        _put(joints[j, _LAMBDA], 0, lam)
        _put(joints[j, _N], 0, n_j)
        _put(joints[j, _D], 0, d)
        _put(joints[j, _THETA_J], 0, theta_j)
        _put(joints[j, _OMEGA_J], 0, omega_j)
    scalars[_TRANSLATIONAL] = translational
    scalars[_ROTATIONAL] = rotational
    scalars[_CONSTRAINT] = constraint
    scalars[_GRAVITY] = gravity
    return n_permanent, power, work_power, dissipation, size


@jit(forceinline=True, _nrt=False)
def chain_evaluate(t, y, params, codes, parents, ppoints, d_at, dy, joints, bodies, scalars, work):
    """The state rate of a chain and everything it is made of, at time ``t`` [s].

    ``y`` (n_states,) (module docstring); ``params`` (n,) :data:`PARAMETERS` records;
    ``codes`` (n,) variant codes; ``parents`` (n,) parent index or -1 (ground); ``ppoints``
    (n, 3) parent points R_p [m] (inertial frame for the ground, else the parent's body
    frame); ``d_at`` (n,) the index of each embedded joint's D in ``y`` (-1: none).
    Writes dy/dt into ``dy`` (n_states,; with one more entry, the disturbances' power after
    the state, the rate of their work W); per joint (n, 7, 3) into ``joints``: E_j, F_j,
    Lambda_j (inertial), N_j (child frame, delivered), D_j, Theta_j, Omega_j; per body
    (n, 3) into ``bodies``: H (delivered); into ``scalars`` (5,): the translational,
    rotational, constraint and gravity terms of v (eq 25's grouping, without h) and dv/dt (analytic: minus the
    dissipations, plus the saturation deficit, disturbance and permanent-constraint
    powers; the last is F_j' Lambda_j, zero on the constraint). ``work``: scratch arrays
    (:class:`ChainWork`). A tree with a hinge is integrated in reduced coordinates only
    (:mod:`rbstab.variants.tree`): here its point-fixed joints' reactions are left out
    (Lambda_j zero here, NaN in :func:`evaluate`'s outputs; from the reduced motion:
    :func:`rbstab.variants.tree.reaction_samples`) and dy/dt is not its motion; every other
    output is.
    """
    n = codes.shape[0]
    rot, rate, torque, force = work.rot, work.rate, work.torque, work.force
    n_permanent, power, work_power, dissipation, size = chain_wrenches(t, y, params, codes, parents, ppoints, d_at, dy,
                                                                       joints, bodies, scalars, work)
    hinged = False
    for j in range(n):
        hinged = hinged or BEYOND_PAPER[codes[j]]
    if n_permanent > 0 and not hinged:
        _permanent_forces(y, params, codes, parents, ppoints, rot, torque, force, joints, n_permanent, work, True)
        for j in range(n):
            if codes[j] == PERMANENT:
                power += dot(vector(joints[j, _F], 0), vector(joints[j, _LAMBDA], 0))
    for i in range(n):
        p = params[i]
        omega, v = vector(y, 12 * i + 3), vector(y, 12 * i + 9)
        _put(dy, 12 * i, matvec(rate[i], omega))
        _put(dy, 12 * i + 3, matvec(p.inertia_inv, vector(torque[i], 0)))
        _put(dy, 12 * i + 6, v)
        _put(dy, 12 * i + 9, (force[i, 0] / p.mass, force[i, 1] / p.mass, force[i, 2] / p.mass))
    scalars[_RATE] = power + work_power - dissipation
    if dy.shape[0] > size:  # the work W of the disturbances, integrated after the state
        dy[size] = work_power


@jit(forceinline=True)
def _joint_acceleration(j, y, params, parents, ppoints, rot, torque, force, with_velocity):
    """d^2E_j/dt^2 [m/s^2] under the wrenches ``torque``, ``force`` (linear part only unless
    ``with_velocity``)."""
    q = parents[j]
    acc = _point_acceleration(j, params[j].attachment_point, rot, y, torque, force, params, with_velocity)
    if q >= 0:
        acc = sub(acc, _point_acceleration(q, vector(ppoints[j], 0), rot, y, torque, force, params, with_velocity))
    return acc


@jit(forceinline=True)
def _cholesky_solve(matrix, rhs, m):
    """Solve ``matrix[:m, :m] x = rhs[:m]`` for a symmetric positive definite matrix, in
    place: its lower triangle becomes the Cholesky factor L (L L' = matrix), ``rhs`` x."""
    for c in range(m):
        total = matrix[c, c]
        for k in range(c):
            total -= matrix[c, k] * matrix[c, k]
        diagonal = math.sqrt(total)
        matrix[c, c] = diagonal
        for r in range(c + 1, m):
            total = matrix[r, c]
            for k in range(c):
                total -= matrix[r, k] * matrix[c, k]
            matrix[r, c] = total / diagonal
    for r in range(m):
        total = rhs[r]
        for k in range(r):
            total -= matrix[r, k] * rhs[k]
        rhs[r] = total / matrix[r, r]
    for r in range(m - 1, -1, -1):
        total = rhs[r]
        for k in range(r + 1, m):
            total -= matrix[k, r] * rhs[k]
        rhs[r] = total / matrix[r, r]


@jit(forceinline=True)
def _add_mobility(matrix, row, col, sign, mass, g, i, u, w):
    """Add ``sign`` W to the 3x3 block of ``matrix`` at (``row``, ``col``): W = I/m -
    [u]x G [w]x [s^2/kg], the acceleration of the point u [m] of body i (inertial frame,
    from its centre of mass) under a unit force at its point w (G = A J^-1 A', the body's
    inverse inertia in the inertial frame, ``g[i]``)."""
    for k in range(3):
        c = cross(w, (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0))  # w x e_k
        alpha = (g[i, 0, 0] * c[0] + g[i, 0, 1] * c[1] + g[i, 0, 2] * c[2],
                 g[i, 1, 0] * c[0] + g[i, 1, 1] * c[1] + g[i, 1, 2] * c[2],
                 g[i, 2, 0] * c[0] + g[i, 2, 1] * c[1] + g[i, 2, 2] * c[2])
        column = cross(alpha, u)
        for r in range(3):
            matrix[row + r, col + k] += sign * ((1.0 / mass if r == k else 0.0) + column[r])


@jit(_nrt=False)
def _permanent_forces(y, params, codes, parents, ppoints, rot, torque, force, joints, k, work, with_velocity):
    """The constraint forces Lambda_j of the ``k`` permanent joints with d^2E_j/dt^2 = 0
    (the stacked eq 15), added to ``torque``, ``force`` and written to ``joints``.

    The system's matrix K = J M^-1 J' (symmetric positive definite) has a 3x3 block for each
    pair of permanent joints a, b that share a body i: the sum over such bodies of s_a s_b
    W_i(u_a, u_b) (:func:`_add_mobility`; s = +1 where i is the joint's child, -1 its
    parent; u the joint's point on i, inertial frame); its upper triangle is assembled,
    mirrored and solved by Cholesky. Without ``with_velocity``: the impulsive reactions that
    keep dE_j/dt of the permanent joints unchanged under the impulses ``torque`` (body
    frames) and ``force`` (the same linear map, no centripetal term). ``work``: scratch
    arrays (:class:`ChainWork`)."""
    n = codes.shape[0]
    which, rhs, matrix, g = work.which, work.rhs, work.matrix, work.g
    m = 0
    for j in range(n):
        if codes[j] == PERMANENT:
            which[m] = j
            m += 1
    for a in range(k):
        acc = _joint_acceleration(which[a], y, params, parents, ppoints, rot, torque, force, with_velocity)
        for r in range(3):
            rhs[3 * a + r] = -acc[r]
    for i in range(n):  # G_i = (A_i J_i^-1) A_i'
        inv = params[i].inertia_inv
        for r in range(3):
            row = (rot[i, r, 0] * inv[0, 0] + rot[i, r, 1] * inv[1, 0] + rot[i, r, 2] * inv[2, 0],
                   rot[i, r, 0] * inv[0, 1] + rot[i, r, 1] * inv[1, 1] + rot[i, r, 2] * inv[2, 1],
                   rot[i, r, 0] * inv[0, 2] + rot[i, r, 1] * inv[1, 2] + rot[i, r, 2] * inv[2, 2])
            for c in range(3):
                g[i, r, c] = row[0] * rot[i, c, 0] + row[1] * rot[i, c, 1] + row[2] * rot[i, c, 2]
    size = 3 * k
    for r in range(size):
        for c in range(size):
            matrix[r, c] = 0.0
    for b in range(k):
        jb = which[b]
        qb = parents[jb]
        ub_c = matvec(rot[jb], params[jb].attachment_point)
        for a in range(b + 1):
            ja = which[a]
            qa = parents[ja]
            ua_c = matvec(rot[ja], params[ja].attachment_point)
            if ja == jb:  # the joint's child body
                _add_mobility(matrix, 3 * a, 3 * b, 1.0, params[ja].mass, g, ja, ua_c, ub_c)
            if qb >= 0 and ja == qb:  # a's child is b's parent
                _add_mobility(matrix, 3 * a, 3 * b, -1.0, params[ja].mass, g, ja, ua_c,
                              matvec(rot[qb], vector(ppoints[jb], 0)))
            if qa >= 0:
                ua_p = matvec(rot[qa], vector(ppoints[ja], 0))
                if qa == jb:  # a's parent is b's child
                    _add_mobility(matrix, 3 * a, 3 * b, -1.0, params[qa].mass, g, qa, ua_p, ub_c)
                if qa == qb:  # a and b share their parent
                    _add_mobility(matrix, 3 * a, 3 * b, 1.0, params[qa].mass, g, qa, ua_p,
                                  matvec(rot[qb], vector(ppoints[jb], 0)))
    for c in range(size):
        for r in range(c + 1, size):
            matrix[r, c] = matrix[c, r]
    _cholesky_solve(matrix, rhs, size)
    for b in range(k):
        j = which[b]
        q = parents[j]
        lam = (rhs[3 * b], rhs[3 * b + 1], rhs[3 * b + 2])
        r_c, r_p = params[j].attachment_point, vector(ppoints[j], 0)
        _acc_add(torque, force, j, cross(r_c, matTvec(rot[j], lam)), lam)
        if q >= 0:
            back = cross(r_p, matTvec(rot[q], lam))
            _acc_add(torque, force, q, (-back[0], -back[1], -back[2]), (-lam[0], -lam[1], -lam[2]))
        _put(joints[j, _LAMBDA], 0, lam)


@jit
def chain_push(y, params, codes, parents, ppoints, body, point, value, torque_push):
    """:func:`chain_push_with` with scratch arrays of its own (for callers in Python)."""
    return chain_push_with(y, params, codes, parents, ppoints, body, point, value, torque_push,
                           chain_work(codes.shape[0]))


@jit(_nrt=False)
def chain_push_with(y, params, codes, parents, ppoints, body, point, value, torque_push, work):
    """Apply a push to the chain's state ``y`` (n_states,) in place and return its energy dT
    [J] (the jump of the kinetic energy): a force impulse ``value`` P [N s] (inertial frame)
    at ``point`` R [m] of body ``body`` (its body frame, from its centre of mass), or with
    ``torque_push`` a torque impulse L [N m s] (the body's frame). The permanent joints'
    impulsive reactions keep their dE_j/dt (docs/physics.md, "A push on a chain").
    ``work``: scratch arrays (:class:`ChainWork`)."""
    n = codes.shape[0]
    rot, torque, force = work.rot, work.torque, work.force
    for i in range(n):
        a = rotation_and_rate_of(vector(y, 12 * i))[0]
        for r in range(3):
            for c in range(3):
                rot[i, r, c] = a[r][c]
    torque[:] = 0.0
    force[:] = 0.0
    v = (value[0], value[1], value[2])
    if torque_push:
        _acc_add(torque, force, body, v, ZERO)
    else:
        _acc_add(torque, force, body, cross((point[0], point[1], point[2]), matTvec(rot[body], v)), v)
    k = 0
    for j in range(n):
        if codes[j] == PERMANENT:
            k += 1
    if k > 0:
        _permanent_forces(y, params, codes, parents, ppoints, rot, torque, force, work.joints, k, work, False)
    before = 0.0
    after = 0.0
    for i in range(n):
        p = params[i]
        omega, v_i = vector(y, 12 * i + 3), vector(y, 12 * i + 9)
        before += 0.5 * p.mass * dot(v_i, v_i) + 0.5 * quadratic_form(omega, p.inertia)
        omega = add(omega, matvec(p.inertia_inv, vector(torque[i], 0)))
        v_i = (v_i[0] + force[i, 0] / p.mass, v_i[1] + force[i, 1] / p.mass, v_i[2] + force[i, 2] / p.mass)
        _put(y, 12 * i + 3, omega)
        _put(y, 12 * i + 9, v_i)
        after += 0.5 * p.mass * dot(v_i, v_i) + 0.5 * quadratic_form(omega, p.inertia)
    return after - before


@jit
def chain_rate(t, y, params, codes, parents, ppoints, d_at, dy):
    """dy/dt of the chain's maximal state ``y`` at ``t`` into ``dy`` (:func:`chain_core`, the
    stacked eq 15; for callers in Python)."""
    chain_core(t, y, params, codes, parents, ppoints, d_at, dy, np.empty((codes.shape[0], 7, 3)),
               np.empty((codes.shape[0], 3)), np.empty(5))


@jit
def chain_rates(times, states, params, codes, parents, ppoints, d_at, out):
    """:func:`chain_rate` of each row of ``states`` (k, n_states) at ``times`` (k,) [s] into
    the rows of ``out`` (k, n_states) (for callers in Python: one call for a stack)."""
    n = codes.shape[0]
    joints, bodies, scalars = np.empty((n, 7, 3)), np.empty((n, 3)), np.empty(5)
    for k in range(states.shape[0]):
        chain_core(times[k], states[k], params, codes, parents, ppoints, d_at, out[k], joints, bodies, scalars)


@jit(forceinline=True, _nrt=False)
def _saturation_flags(y, params, codes, joints, angle, flags):
    """The actuators' saturation flags of one evaluated state into ``flags`` (n, 3, 3): per
    joint j, the axes of N_j, of H of body j (its child) and of Lambda_j commanded at or
    beyond their limits, 1.0 or 0.0 (:func:`rbstab.variants.kernels.saturation_effects`
    of joint j's E_j, F_j, D_j and body j's X, V, as one body's; N_j's from its command on
    Theta_j - Theta_ref, Omega_j, B(Theta_j) between its lower and upper limits; ``joints`` (n,
    7, 3) as :func:`chain_evaluate` filled it; a slide's force f a, commanded on its q, u
    (``angle``, :class:`ChainWork`'s, as :func:`chain_wrenches` read them), as Lambda_j's, in
    entry 0)."""
    for j in range(codes.shape[0]):
        theta_j = vector(joints[j, _THETA_J], 0)
        _, b_j = rotation_and_rate_of(theta_j)
        if codes[j] == HINGE:  # theta_j = q a: its rate is Omega_j
            b_j = IDENTITY
        elif codes[j] == UNIVERSAL:  # theta_j = (q_1, q_2, 0): B maps Omega_j to their rates
            b_j = universal_rate(vector(params[j].axis, 0), vector(params[j].axis_2, 0), theta_j[1])
        strain, omega_j = sub(theta_j, params[j].theta_ref), vector(joints[j, _OMEGA_J], 0)
        if codes[j] == BALL:  # theta_j the rotation vector of A_rel
            strain, b_j = _ball_strain(vector_rotation(theta_j), params[j].theta_ref)
        _, _, h_flags, lam_flags = saturation_effects(
            codes[j], strain, omega_j, vector(y, 12 * j + 6), vector(y, 12 * j + 9), b_j,
            vector(joints[j, _E], 0), vector(joints[j, _F], 0), vector(joints[j, _D], 0), params[j])
        n_flags = ZERO
        if codes[j] == SLIDE:
            lam_flags = ZERO
            if params[j].saturation > 0.0:
                commanded = torque_n_command(IDENTITY, (angle[j, 0] - params[j].theta_ref[0], 0.0, 0.0),
                                             (angle[j, 1], 0.0, 0.0), params[j])
                lam_flags = saturated_between(commanded, params[j].torque_floor, params[j].torque_limit)
        elif params[j].saturation > 0.0:  # N_j commanded on Theta_j - Theta_ref, between its two limits
            commanded = torque_n_command(b_j, strain, omega_j, params[j])
            if codes[j] == UNIVERSAL:  # on its coordinates: -K_r (q - q_ref) - L_r dq/dt
                commanded = torque_n_command(IDENTITY, strain, matvec(b_j, omega_j), params[j])
            n_flags = saturated_between(commanded, params[j].torque_floor, params[j].torque_limit)
        _put(flags[j, 0], 0, n_flags)
        _put(flags[j, 1], 0, h_flags)
        _put(flags[j, 2], 0, lam_flags)


@jit
def chain_samples(times, states, params, codes, parents, ppoints, d_at, tree_of, joints, bodies, scalars, power, flags,
                  blocks, per_run):
    """:func:`chain_evaluate` at every sample: ``states`` (m, n_states) at ``times`` (m,),
    sample s of the tree ``tree_of[s]`` (``params`` (t, n), ``ppoints`` (t, n, 3): t trees
    of one structure), each output component's samples side by side (numpy then reduces and
    copies a column of 3-vectors as one stride, not 3 numbers at a time): into ``joints``
    (n, 7, 3, m) (:func:`chain_evaluate`'s), ``bodies`` (n, 3, m), ``scalars`` (5, m),
    ``power`` (m,) the disturbances' power [W], ``flags`` (n, 3, 3, m) the saturation flags
    of N_j, H_j and Lambda_j (:func:`_saturation_flags`) and ``blocks`` (n, 4, 3, m) each
    body's Theta, Omega, X, V; NaN where the state is NaN. The samples are runs of
    ``per_run`` samples each: a hinge's angle is continued from sample to sample of a run
    (:func:`chain_wrenches`), from (-pi, pi] at its first."""
    n = codes.shape[0]
    dy = np.empty(states.shape[1] + 1)
    work = chain_work(n)
    joint, body, scalar, flag = np.empty((n, 7, 3)), np.empty((n, 3)), np.empty(5), np.empty((n, 3, 3))
    for s in range(states.shape[0]):
        if s % per_run == 0:
            work.angle[:] = 0.0
        if states[s, 0] != states[s, 0]:
            joint[:] = np.nan
            body[:] = np.nan
            scalar[:] = np.nan
            flag[:] = np.nan
            power[s] = np.nan
        else:
            t = tree_of[s]
            chain_evaluate(times[s], states[s], params[t], codes, parents, ppoints[t], d_at, dy, joint, body, scalar,
                           work)
            power[s] = dy[states.shape[1]]
            _saturation_flags(states[s], params[t], codes, joint, work.angle, flag)
        _put_sample(s, states[s], joint, body, scalar, flag, joints, bodies, scalars, flags, blocks)


@jit(forceinline=True)
def _put_sample(s, y, joint, body, scalar, flag, joints, bodies, scalars, flags, blocks):
    """Sample s's outputs (one state's: ``joint`` (n, 7, 3), ``body`` (n, 3), ``scalar`` (5,),
    ``flag`` (n, 3, 3), the state ``y``) into column s of :func:`chain_samples`' outputs."""
    for i in range(joint.shape[0]):
        for c in range(3):
            for k in range(7):
                joints[i, k, c, s] = joint[i, k, c]
            for k in range(3):
                flags[i, k, c, s] = flag[i, k, c]
            for k in range(4):
                blocks[i, k, c, s] = y[12 * i + 3 * k + c]
            bodies[i, c, s] = body[i, c]
    for k in range(5):
        scalars[k, s] = scalar[k]


# -- the compiled description ------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CompiledChain:
    """A chain as the compiled core reads it (module docstring).

    Attributes
    ----------
    chain : Chain
    params : ndarray, shape (n,), dtype PARAMETERS
        Body i with joint i's gains and limits (``attachment_point`` = joint i's R_c).
    codes, parents, d_at : ndarray, shape (n,), int64
        Variant codes, parent indices (-1: ground), index of D in the state (-1: none).
    ppoints : ndarray, shape (n, 3)
        R_p [m] of each joint.
    n_states : int
        12 n + 3 (number of embedded joints).
    offset : float
        h [J]: v is zero at the chain's rest state nearest the reference configuration
        (:func:`rest_offset`); 0 where the potential has no minimum there.
    """

    chain: Chain
    params: np.ndarray
    codes: np.ndarray
    parents: np.ndarray
    ppoints: np.ndarray
    d_at: np.ndarray
    n_states: int
    offset: float = 0.0
    args: tuple = field(default=(), repr=False)

    @property
    def size(self) -> int:
        return int(self.codes.shape[0])

    @functools.cached_property
    def one_body(self) -> bool:
        """Whether the chain is the paper's one-body model (:func:`is_one_body`)."""
        return is_one_body(self.params, self.codes, self.parents, self.ppoints)

    @functools.cached_property
    def independent_columns(self) -> np.ndarray:
        """The full state's entries (3 k,) of the independent coordinates z
        (:func:`independent_coordinates`, in order), int64."""
        return np.array([at + c for _, _, at, _ in independent_coordinates(self) for c in range(3)], dtype=np.int64)

    @functools.cached_property
    def hinged(self) -> bool:
        """Whether a joint turns about axes, a hinge or a universal joint (the tree's
        linearisation is then in its reduced state)."""
        return bool(np.any(BEYOND_PAPER[self.codes]))

    @functools.cached_property
    def permanent(self) -> np.ndarray:
        """(n,) bool: the bodies a point-fixed joint holds (placed on their parents)."""
        return POINT_FIXED[self.codes]


def papers_feedback(theta_ref: np.ndarray, passive: np.ndarray, floor: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Whether each joint has the paper's feedback alone, eq 23: its spring relaxed at Theta
    = 0, no passive torque and symmetric limits of N, from its records' ``theta_ref`` (...,
    3), ``passive`` (...), ``torque_floor`` and ``torque_limit`` (..., 3) fields; bool (...)."""
    return ~np.any(theta_ref, axis=-1) & (passive == 0.0) & np.all(floor == -limit, axis=-1)


def one_body_mask(codes: np.ndarray, parents: np.ndarray, points: np.ndarray, attachment: np.ndarray,
                  papers: np.ndarray) -> np.ndarray:
    """Which of t trees of one structure (joint codes ``codes`` (n,), ``parents`` (n,))
    are the paper's one-body model (one of its five laws) (:func:`is_one_body`): ``points`` (t, 3) their first
    joint's R_p [m], ``attachment`` (t, 3) its R_c [m] (body frame), ``papers`` (t,) whether
    its feedback is the paper's (:func:`papers_feedback`); shape (t,) of bool."""
    if codes.shape[0] != 1 or parents[0] >= 0 or BEYOND_PAPER[codes[0]]:
        return np.zeros(len(points), dtype=bool)
    return np.all(points == attachment, axis=-1) & papers


def is_one_body(params: np.ndarray, codes: np.ndarray, parents: np.ndarray, ppoints: np.ndarray) -> bool:
    """Whether a tree (its records (n,), codes, parents and parent points (n, 3) as in
    :class:`CompiledChain`), or every one of t trees of one structure (records (t, n),
    parent points (t, n, 3)), is the paper's one-body model: one body held by its joint to
    the ground at the point R_p = R_c, where its point C rests with its centre of mass at the
    origin (E = X + A R - R, eq 4; the one-body spelling's body and controller), its spring
    relaxed at Theta = 0 and no passive torque (the paper's feedback). One body's
    compiled rate (:func:`rbstab.variants.kernels.state_rate`) and its h then serve the
    tree: its reduced state is the body's state."""
    first = params[..., 0]
    return bool(np.all(one_body_mask(codes, parents, np.reshape(np.asarray(ppoints)[..., 0, :], (-1, 3)),
                                     np.reshape(first["attachment_point"], (-1, 3)),
                                     np.reshape(papers_feedback(first["theta_ref"], first["passive"],
                                                                first["torque_floor"], first["torque_limit"]), (-1,)))))


def records_of(trees: Sequence[CompiledChain]) -> np.ndarray:
    """The records (t, n) of t chains of one structure, stacked (numpy's ``stack`` of
    structured arrays costs ~0.1 ms a chain)."""
    out = np.empty((len(trees), trees[0].size), dtype=trees[0].params.dtype)
    for t, tree in enumerate(trees):
        out[t] = tree.params
    return out


def with_records(compiled: CompiledChain, params: np.ndarray, ppoints: np.ndarray, offset: float = 0.0,
                 gravity: np.ndarray | None = None) -> CompiledChain:
    """``compiled``'s structure (codes, parents, embedded joints, names) with another run's
    records ``params`` (n,), parent points ``ppoints`` (n, 3) [m] and h ``offset`` [J] (a
    run of a :class:`rbstab.engine.RunBatch`); ``gravity`` (3,) [m/s^2] the chain's
    where None."""
    chain = compiled.chain if gravity is None else dataclasses.replace(compiled.chain,
                                                                       gravity=np.asarray(gravity, dtype=float))
    params, ppoints = np.ascontiguousarray(params), np.ascontiguousarray(ppoints, dtype=float)
    return CompiledChain(chain, params, compiled.codes, compiled.parents, ppoints, compiled.d_at, compiled.n_states,
                         float(offset), (params, compiled.codes, compiled.parents, ppoints, compiled.d_at))


def _record(chain: Chain, i: int) -> np.ndarray:
    """The :data:`rbstab.model.PARAMETERS` record of body ``i`` and its joint (h 0)."""
    p = parameters(*body_model(chain, i))
    joint = chain.joints[i]
    p["theta_ref"] = joint.theta_ref
    p["axis"], p["axis_2"] = joint.axis, joint.axis_2
    if joint.passive is not None:
        p["passive"] = 1.0
        p["passive_k_r"], p["passive_l_r"] = joint.passive.k_r, joint.passive.l_r
        p["passive_theta_ref"] = joint.passive.theta_ref
    if joint.stop is not None:
        p["stop"] = 1.0
        p["range_lower"], p["range_upper"] = joint.stop.lower, joint.stop.upper
        p["stop_k"], p["stop_l"] = joint.stop.k_r, joint.stop.l_r
    if joint.region is not None:
        p["region"] = 1.0
        p["range_lower"], p["range_upper"] = joint.region.lower, joint.region.upper
    return p


def _controller_states(chain: Chain) -> tuple[np.ndarray, int]:
    """(the index of each embedded joint's D in the state (n,), -1 where none; n_states)."""
    d_at = np.full(chain.size, -1, dtype=np.int64)
    size = 12 * chain.size
    for j, joint in enumerate(chain.joints):
        if joint.variant == "embedded":
            d_at[j] = size
            size += 3
    return d_at, size


def compile_chain(chain: Chain, offset: float | None = None) -> CompiledChain:
    """The runtime records of ``chain`` (:class:`CompiledChain`); ``offset`` h [J], None:
    :func:`rest_offset`."""
    n = chain.size
    params = np.zeros(n, dtype=PARAMETERS)
    for i in range(n):
        params[i] = _record(chain, i)
    codes = np.array([JOINT_CODES[j.variant] for j in chain.joints], dtype=np.int64)
    parents = np.array([j.parent for j in chain.joints], dtype=np.int64)
    ppoints = np.array([np.asarray(j.parent_point, dtype=float) for j in chain.joints]).reshape(n, 3)
    d_at, size = _controller_states(chain)
    compiled = CompiledChain(chain, params, codes, parents, ppoints, d_at, size, 0.0,
                             (params, codes, parents, ppoints, d_at))
    h = rest_offset(compiled) if offset is None else float(offset)
    return CompiledChain(chain, params, codes, parents, ppoints, d_at, size, h, compiled.args)


# -- rest state and v ---------------------------------------------------------------------------
@jit(forceinline=True)
def slide_coordinates(y, i, params, parents, ppoints):
    """(q [m], u [m/s], the axis a [inertial frame]) of the slide that holds body i, read from
    the maximal state ``y`` (n_states,): q = a'E_i, u = a'F_i, E_i and F_i the offset of
    body i's point C from its parent's point and its rate (the part of F_i across the axis,
    A_p (Omega_p x q a), has no component along it)."""
    a_c = rotation_and_rate_of(vector(y, 12 * i))[0]
    r_c = vector(params[i].attachment_point, 0)
    axis, point, rate = vector(params[i].axis, 0), vector(ppoints[i], 0), ZERO
    p = parents[i]
    if p >= 0:
        a_p = rotation_and_rate_of(vector(y, 12 * p))[0]
        r_p = point
        axis = matvec(a_p, axis)
        point = add(vector(y, 12 * p + 6), matvec(a_p, r_p))
        rate = add(vector(y, 12 * p + 9), matvec(a_p, cross(vector(y, 12 * p + 3), r_p)))
    e = sub(add(vector(y, 12 * i + 6), matvec(a_c, r_c)), point)
    f = sub(add(vector(y, 12 * i + 9), matvec(a_c, cross(vector(y, 12 * i + 3), r_c))), rate)
    return dot(axis, e), dot(axis, f), axis


@jit(forceinline=True)
def _place_body(y, i, params, codes, parents, ppoints, x_placed, v_placed):
    """Place body i of the state ``y`` (n_states,) on its joint (:func:`place`): its X where
    ``x_placed`` so that the joint's points coincide (E_i = 0), its V where ``v_placed`` so
    that they move together (F_i = 0), from its parent's X, V, Theta, Omega (ground: X_p =
    V_p = 0, A_p = I); on a slide, C kept at its offset q a from the parent's point and its
    rate u along the axis (:func:`slide_coordinates`)."""
    a = rotation_and_rate_of(vector(y, 12 * i))[0]
    r_c = vector(params[i].attachment_point, 0)
    point, rate = vector(ppoints[i], 0), ZERO
    p = parents[i]
    slid, slid_rate = ZERO, ZERO  # a slide's q a, u a (inertial)
    if codes[i] == SLIDE:
        s, u, axis = slide_coordinates(y, i, params, parents, ppoints)
        slid, slid_rate = (axis[0] * s, axis[1] * s, axis[2] * s), (axis[0] * u, axis[1] * u, axis[2] * u)
    if p >= 0:
        a_p = rotation_and_rate_of(vector(y, 12 * p))[0]
        r_p = point
        omega_p = matvec(a_p, vector(y, 12 * p + 3))  # inertial
        point = add(vector(y, 12 * p + 6), matvec(a_p, r_p))
        rate = add(add(vector(y, 12 * p + 9), matvec(a_p, cross(vector(y, 12 * p + 3), r_p))), cross(omega_p, slid))
    point, rate = add(point, slid), add(rate, slid_rate)
    if x_placed:
        _put(y, 12 * i + 6, sub(point, matvec(a, r_c)))
    if v_placed:
        _put(y, 12 * i + 9, sub(rate, matvec(a, cross(vector(y, 12 * i + 3), r_c))))


@jit
def _place_rows(states, params, codes, parents, ppoints, x_placed, v_placed):
    """:func:`place` on each row of ``states`` (k, n_states), in place, parents first."""
    for k in range(states.shape[0]):
        for i in range(parents.shape[0]):
            if x_placed[i] or v_placed[i]:
                _place_body(states[k], i, params, codes, parents, ppoints, x_placed[i], v_placed[i])


@jit
def rest_configuration(q, params, codes, parents, ppoints, d_at, y):
    """Fill ``y`` (n_states,) with the state at rest of the configuration ``q``
    (:func:`rest_coordinates`: each body's Theta_i [rad], a hinge's child's q [rad] instead,
    a universal joint's child's q_1, q_2 [rad], a slide's child's q [m] (its child turned as
    its parent, its point C at q a from the parent's point);
    then X_i [m, inertial] of the bodies whose joint is not point-fixed, then D [m] of the
    embedded joints); every Omega, V zero; a hinge's child turned by q about its axis from
    its parent (A_c = A_p exp(q [a]x)); X of a point-fixed joint's child placed on its
    parent's point (E_j = 0), parents first: X_c = X_p + A_p R_p - A_c R_c."""
    n = codes.shape[0]
    for k in range(y.shape[0]):
        y[k] = 0.0
    k = 0
    slide_at = np.zeros(n, dtype=np.int64)  # each slide's q in q
    for i in range(n):
        if codes[i] == SLIDE:  # its child turned as its parent
            slide_at[i] = k
            if parents[i] >= 0:
                for c in range(3):
                    y[12 * i + c] = y[12 * parents[i] + c]
            k += 1
        elif AXES[codes[i]] > 0:
            if codes[i] == HINGE:
                rel = axis_rotation(vector(params[i].axis, 0), q[k])
            else:
                rel = universal_rotation(vector(params[i].axis, 0), vector(params[i].axis_2, 0), q[k], q[k + 1])
            a = rel
            if parents[i] >= 0:
                a = compose(rotation_and_rate_of(vector(y, 12 * parents[i]))[0], rel)
            _put(y, 12 * i, euler_angles(a))
            k += AXES[codes[i]]
        elif codes[i] == BALL:  # its rotation vector
            a = vector_rotation((q[k], q[k + 1], q[k + 2]))
            if parents[i] >= 0:
                a = compose(rotation_and_rate_of(vector(y, 12 * parents[i]))[0], a)
            _put(y, 12 * i, euler_angles(a))
            k += 3
        else:
            for c in range(3):
                y[12 * i + c] = q[k + c]
            k += 3
    for i in range(n):
        if not POINT_FIXED[codes[i]]:
            for c in range(3):
                y[12 * i + 6 + c] = q[k + c]
            k += 3
    for j in range(n):
        if d_at[j] >= 0:
            for c in range(3):
                y[d_at[j] + c] = q[k + c]
            k += 3
    for i in range(n):
        if POINT_FIXED[codes[i]]:
            _place_body(y, i, params, codes, parents, ppoints, True, False)
            if codes[i] == SLIDE:  # then moved to its q along the axis
                s, _, axis = slide_coordinates(y, i, params, parents, ppoints)
                for c in range(3):
                    y[12 * i + 6 + c] += axis[c] * (q[slide_at[i]] - s)


@jit
def rest_potential(q, params, codes, parents, ppoints, d_at, y, dy, work):
    """The potential [J] (joint and body feedback, point laws, gravity; h not included) of
    the configuration ``q`` (:func:`rest_configuration`, written into ``y``): v's terms at
    rest, whose kinetic parts are zero."""
    rest_configuration(q, params, codes, parents, ppoints, d_at, y)
    chain_core(0.0, y, params, codes, parents, ppoints, d_at, dy, work.joints, work.bodies, work.scalars)
    s = work.scalars
    return s[_TRANSLATIONAL] + s[_ROTATIONAL] + s[_CONSTRAINT] + s[_GRAVITY]


@jit
def rest_gradient(q, params, codes, parents, ppoints, d_at, y, dy, work, gradient):
    """The gradient of :func:`rest_potential` at ``q`` into ``gradient``, by central
    differences (step (machine epsilon)^(1/3) max(1, |q_k|)). Returns the potential at q."""
    value = rest_potential(q, params, codes, parents, ppoints, d_at, y, dy, work)
    for k in range(q.shape[0]):
        held = q[k]
        step = 6.0554544523933395e-06 * max(1.0, abs(held))
        q[k] = held + step
        up = rest_potential(q, params, codes, parents, ppoints, d_at, y, dy, work)
        q[k] = held - step
        down = rest_potential(q, params, codes, parents, ppoints, d_at, y, dy, work)
        q[k] = held
        gradient[k] = (up - down) / (2.0 * step)
    return value


@jit
def rest_acceleration(q, params, codes, parents, ppoints, d_at, y, dy, work, out):
    """The accelerations at rest in the configuration ``q`` (:func:`rest_configuration`)
    into ``out``: dOmega_i/dt of every body, dV_i/dt of bodies whose joint is not
    permanent, dD/dt of embedded joints."""
    rest_configuration(q, params, codes, parents, ppoints, d_at, y)
    chain_core(0.0, y, params, codes, parents, ppoints, d_at, dy, work.joints, work.bodies, work.scalars)
    n = codes.shape[0]
    k = 0
    for i in range(n):
        for c in range(3):
            out[k + c] = dy[12 * i + 3 + c]
        k += 3
    for i in range(n):
        if codes[i] != PERMANENT:
            for c in range(3):
                out[k + c] = dy[12 * i + 9 + c]
            k += 3
    for j in range(n):
        if d_at[j] >= 0:
            for c in range(3):
                out[k + c] = dy[d_at[j] + c]
            k += 3


def _undisturbed(params: np.ndarray) -> np.ndarray:
    """The records ``params`` without their disturbances: a copy where they have some
    (``params`` itself, read only, where they have none)."""
    if not np.any(params["disturbance_count"]):
        return params
    params = params.copy()
    params["disturbance_count"] = 0.0
    return params


def rest_state(compiled: CompiledChain) -> tuple[np.ndarray | None, float]:
    """(the chain's rest state (n_states,), its potential [J] without h): the least potential
    (joint and body feedback, point laws, gravity) found by a local minimisation (scipy's
    BFGS) over the configuration (every Theta_i, X_i of bodies whose joint is not
    ``permanent``, D of embedded joints; a permanent joint's child placed on its parent)
    from the reference configuration (every joint at its reference posture Theta_j =
    Theta_ref, :func:`reference_posture`, every body placed on its joint, E_j = 0);
    (None, nan) where the potential has no minimum there (it falls without bound); then
    polished to a rest point to rounding (scipy's ``root``: the accelerations zero). A
    reference configuration already at rest (gradient within the tolerance, accelerations
    zero, as an upright stance's) is taken as it is, without the solvers' setup. The
    rest state is the undisturbed chain's: its disturbances do not move it (nor v's zero)."""
    from scipy.optimize import minimize, root  # heavy: scipy, only where a rest state is sought

    n = compiled.size
    q0 = rest_coordinates(compiled, reference_posture(compiled))
    hinged = compiled.hinged  # the maximal rates leave out the reactions of joints about axes
    y, dy, work = np.empty(compiled.n_states), np.empty(compiled.n_states), chain_work(n)
    args = (_undisturbed(compiled.params), *compiled.args[1:], y, dy, work)

    def potential_and_gradient(q):
        gradient = np.empty(q.shape[0])
        return rest_gradient(np.array(q, dtype=float), *args, gradient), gradient

    def acceleration(q):
        out = np.empty(q.shape[0])
        rest_acceleration(np.asarray(q, dtype=float), *args, out)
        return out

    q = q0
    value, gradient = potential_and_gradient(q0)
    if not (np.isfinite(value) and np.max(np.abs(gradient)) <= _REST_GTOL):  # else BFGS stops at once, at q0
        result = minimize(potential_and_gradient, q0, jac=True, method="BFGS",
                          options={"gtol": _REST_GTOL, "maxiter": 5000})
        value = float(result.fun)
        if not np.isfinite(value) or np.max(np.abs(result.x - q0)) > 1e3:
            return None, math.nan
        q = result.x
    # a rest point to rounding: the minimiser's gradient tolerance is not; a tree with a kind beyond the
    # paper's (whose maximal rates leave out its joints' reactions) polished on the potential's gradient
    residual_of = (lambda x: potential_and_gradient(x)[1]) if hinged else acceleration
    residual = residual_of(q)
    if np.any(residual != 0.0):
        try:
            with np.errstate(all="ignore"):
                polished = root(residual_of, q, method="hybr", options={"xtol": 1e-13})
        except (np.linalg.LinAlgError, ValueError):  # the polish left for a singular configuration
            polished = None  # (its rate not finite): the minimiser's rest point stands
        if (polished is not None and np.all(np.isfinite(polished.fun))
                and np.linalg.norm(polished.fun) < np.linalg.norm(residual)):
            q = polished.x
    value = rest_potential(q, *args)
    return y.copy(), float(value)


#: The gradient tolerance [J per unit of a coordinate] of :func:`rest_state`'s minimisation.
_REST_GTOL = 1e-11


def rest_coordinates(compiled: CompiledChain, y: np.ndarray) -> np.ndarray:
    """The configuration (:func:`rest_configuration`'s ``q``) of the state ``y``
    (n_states,): each body's Theta_i [rad] (a hinge's child: its q [rad], in (-pi, pi]; a
    universal joint's: q_1, q_2; a slide's: its q [m]),
    X_i [m] of the bodies whose joint is not point-fixed, D [m] of the embedded joints."""
    n, y = compiled.size, np.asarray(y, dtype=float)
    joints = np.empty((n, 7, 3))
    chain_core(0.0, np.ascontiguousarray(y), *compiled.args, np.empty(compiled.n_states), joints, np.empty((n, 3)),
               np.empty(5))
    angles = [[slide_coordinates(np.ascontiguousarray(y), i, compiled.params, compiled.parents, compiled.ppoints)[0]]
              if compiled.codes[i] == SLIDE
              else [float(compiled.params[i]["axis"] @ joints[i, _THETA_J])] if compiled.codes[i] == HINGE
              else list(joints[i, _THETA_J, :2]) if compiled.codes[i] == UNIVERSAL
              else list(joints[i, _THETA_J]) if compiled.codes[i] == BALL
              else list(y[12 * i: 12 * i + 3]) for i in range(n)]
    positions = [list(y[12 * i + 6: 12 * i + 9]) for i in range(n) if not POINT_FIXED[compiled.codes[i]]]
    states = [list(y[d: d + 3]) for d in compiled.d_at if d >= 0]
    return np.array([x for part in (*angles, *positions, *states) for x in part], dtype=float)


def reference_posture(compiled: CompiledChain) -> np.ndarray:
    """The state (n_states,) whose bodies hold every joint at its reference posture, Theta_j
    = Theta_ref [rad] (A_c = A_p A(Theta_ref), parents first; the ground's A_p = I; a hinge's
    A(Theta_ref) the rotation by a . Theta_ref about its axis a, a universal joint's by its
    q_ref; a slide's child turned as its parent, A_rel = I), at rest, every body placed on its
    joint (:func:`place`; a slide's child at its q_ref along the axis, the bodies it carries
    with it); D zero."""
    y = np.zeros(compiled.n_states)
    rotations = []
    for i in range(compiled.size):
        a = rotation_matrix(compiled.params[i]["theta_ref"])
        if compiled.codes[i] == SLIDE:
            a = np.eye(3)
        elif compiled.codes[i] == HINGE:
            axis = compiled.params[i]["axis"]
            a = np.array(axis_rotation(tuple(axis), float(axis @ compiled.params[i]["theta_ref"])))
        elif compiled.codes[i] == UNIVERSAL:
            p = compiled.params[i]
            a = np.array(universal_rotation(tuple(p["axis"]), tuple(p["axis_2"]), *p["theta_ref"][:2]))
        elif compiled.codes[i] == BALL:  # its reference a rotation vector
            a = np.array(vector_rotation(tuple(compiled.params[i]["theta_ref"])))
        q = int(compiled.parents[i])
        if q >= 0:
            a = rotations[q] @ a
        rotations.append(a)
        y[12 * i: 12 * i + 3] = euler_angles_of(a)
    y = _place(compiled, y)
    for i in np.flatnonzero(compiled.codes == SLIDE):  # parents first: each moved to its q_ref, with its subtree
        s, _, axis = slide_coordinates(y, int(i), compiled.params, compiled.parents, compiled.ppoints)
        shift = np.asarray(axis) * (compiled.params[i]["theta_ref"][0] - s)
        for b in range(i, compiled.size):
            k = b
            while k > i:
                k = int(compiled.parents[k])
            if k == i:
                y[12 * b + 6: 12 * b + 9] += shift
    return y


def rest_offset(compiled: CompiledChain) -> float:
    """h [J] with v = 0 at the chain's rest state (:func:`rest_state`); 0 without gravity
    and reference postures, the passive springs' included (the potential's least value is
    then 0 at the reference configuration) or where the potential has no minimum."""
    if (not np.any(compiled.chain.gravity) and not np.any(compiled.params["theta_ref"])
            and not np.any(compiled.params["passive_theta_ref"])):
        return 0.0
    if compiled.one_body:  # the paper's one body: h as a batch of its records computes it
        name = _VARIANT_NAMES[int(compiled.codes[0])]
        return float(record_offsets(compiled.params[:1], compiled.chain.gravity[None], name)[0])
    key = b"".join(np.ascontiguousarray(a).tobytes() for a in (_undisturbed(compiled.params), *compiled.args[1:],
                                                                 compiled.chain.gravity))
    if key not in _OFFSETS:  # the runs of a sweep over initial states share their chain's
        if len(_OFFSETS) >= _MAX_OFFSETS:
            _OFFSETS.clear()
        y, value = rest_state(compiled)
        _OFFSETS[key] = 0.0 if y is None else -value
    return _OFFSETS[key]


#: Variant names by their code (:data:`rbstab.layout.VARIANT_CODES`).
_VARIANT_NAMES = {code: name for name, code in VARIANT_CODES.items()}

#: h of the chains met so far in this process, by their records' bytes (:func:`rest_offset`).
_OFFSETS: dict[bytes, float] = {}
_MAX_OFFSETS = 1024


def independent_coordinates(compiled: CompiledChain) -> list[tuple[str, str, int, int]]:
    """The chain's independent coordinates, in the order of :func:`full_state`'s ``z``:
    (body name, block, index into the full state, entries) for Theta_i, Omega_i of every body, X_i,
    V_i of bodies whose joint is not ``permanent`` (a permanent joint's child is placed on
    its parent), and D of embedded joints (block ``controller_state``), 3 entries each (a
    tree with a hinge is linearised in its reduced state instead)."""
    out = []
    names = compiled.chain.body_names
    for i in range(compiled.size):
        blocks = [("theta", 0), ("omega", 3)]
        if compiled.codes[i] != PERMANENT:
            blocks += [("position", 6), ("velocity", 9)]
        out += [(names[i], block, 12 * i + at, 3) for block, at in blocks]
    for j in range(compiled.size):
        if compiled.d_at[j] >= 0:
            out.append((names[j], "controller_state", int(compiled.d_at[j]), 3))
    return out


def full_state(compiled: CompiledChain, z: np.ndarray) -> np.ndarray:
    """The full state (n_states,) of the independent coordinates ``z``
    (:func:`independent_coordinates`, 3 entries each): the children of permanent joints
    placed on their parents (E_j = F_j = 0). A stack ``z`` (k, m) gives (k, n_states)."""
    z = np.asarray(z, dtype=float)
    stack = z.reshape(1, -1) if z.ndim == 1 else z
    y = np.zeros((len(stack), compiled.n_states))
    y[:, compiled.independent_columns] = stack
    _place_rows(y, compiled.params, compiled.codes, compiled.parents, compiled.ppoints, compiled.permanent,
                compiled.permanent)
    return y if z.ndim == 2 else y[0]


def _place(compiled: CompiledChain, y: np.ndarray, only_permanent: bool = False) -> np.ndarray:
    """``y`` with every body's (``only_permanent``: every permanent joint's child's) X, V
    placed on its parent's point (E_j = F_j = 0), parents first."""
    chosen = compiled.permanent if only_permanent else np.ones(compiled.size, dtype=bool)
    return place(compiled, y, chosen, chosen)


def place(compiled: CompiledChain, y: np.ndarray, x_placed, v_placed) -> np.ndarray:
    """A copy of the state ``y`` (n_states,), or of each row of a stack (k, n_states), with
    X_i of the bodies i where ``x_placed[i]`` (V_i where ``v_placed[i]``), (n,) booleans,
    placed so that joint i's points coincide (E_i = 0) and move together (F_i = 0), parents
    first: X_c = X_p + A_p R_p - A_c R_c, V_c = V_p + A_p (Omega_p x R_p) - A_c (Omega_c x
    R_c) (ground: X_p = V_p = 0, A_p = I); a slide's child's C kept at its offset along the
    axis and its rate along it (:func:`slide_coordinates`)."""
    y = np.array(y, dtype=float)
    _place_rows(y.reshape(-1, y.shape[-1]), compiled.params, compiled.codes, compiled.parents, compiled.ppoints,
                np.asarray(x_placed, dtype=np.bool_), np.asarray(v_placed, dtype=np.bool_))
    return y


def _terms(compiled: CompiledChain, t: float, y: np.ndarray):
    n = compiled.size
    dy = np.empty(compiled.n_states)
    joints, bodies, scalars = np.empty((n, 7, 3)), np.empty((n, 3)), np.empty(5)
    chain_core(float(t), np.ascontiguousarray(y, dtype=float), *compiled.args, dy, joints, bodies, scalars)
    return dy, joints, scalars


def lyapunov(compiled: CompiledChain, y: np.ndarray, t: float = 0.0) -> tuple[float, float]:
    """(v [J], dv/dt [W] analytic) at the state ``y`` (n_states,) and time ``t`` [s]."""
    _, _, scalars = _terms(compiled, t, y)
    return float(scalars[:_RATE].sum() + compiled.offset), float(scalars[_RATE])


def initial_state(config) -> np.ndarray:
    """The initial state (n_states,) of a :class:`rbstab.config.RunConfig` (module
    docstring for the layout)."""
    return state_vector(config.chain, config.initial_state)


def state_vector(chain: Chain, states) -> np.ndarray:
    """The state (n_states,) of ``chain`` whose bodies have the blocks ``states`` (by body
    name, then block: :attr:`rbstab.config.RunConfig.initial_state`'s form)."""
    d_at, size = _controller_states(chain)
    y = np.zeros(size)
    for i, body in enumerate(chain.bodies):
        state = states[body.name]
        for k, block in enumerate(("theta", "omega", "position", "velocity")):
            y[12 * i + 3 * k: 12 * i + 3 * k + 3] = state[block]
        if d_at[i] >= 0:
            y[d_at[i]: d_at[i] + 3] = state["controller_state"]
    return y


# -- integration and outputs ------------------------------------------------------------------
@dataclass
class ChainTrajectory:
    """A chain run's samples.

    Attributes
    ----------
    time : ndarray, shape (n_samples,)
        [s], evenly spaced on [0, t_end].
    states : ndarray, shape (n_samples, n_states)
        Rows after a failure are NaN.
    status : str
        ``"success"`` or ``"failed"``.
    message : str
    solver : dict
        ``nfev``, ``solver_status``, ``wall_time`` [s].
    compiled : CompiledChain
    work : ndarray, shape (n_samples,)
        The disturbances' work W [J] at the samples (0 without; NaN after a failure).
    """

    time: np.ndarray
    states: np.ndarray
    status: str
    message: str
    solver: dict
    compiled: CompiledChain
    work: np.ndarray


def gimbal_angles(compiled: CompiledChain, y: np.ndarray) -> tuple[np.ndarray, list[tuple[int, bool]]]:
    """(theta_2 [rad] of every Euler angle a run integrates (each body's Theta, or the Theta_j
    of the permanent joint that holds it) and of every other joint's relative Theta_j off
    the ground, at the maximal state ``y``; the part each is: (body or joint index, whether
    it is the joint's Theta_j), as :func:`rbstab.engine.status.gimbal_status` numbers them)."""
    n = compiled.size
    joints = np.empty((n, 7, 3))
    chain_core(0.0, np.ascontiguousarray(y, dtype=float), *compiled.args, np.empty(compiled.n_states), joints,
               np.empty((n, 3)), np.empty(5))
    angles, parts = [], []
    for i in range(n):
        if BEYOND_PAPER[compiled.codes[i]]:  # no Euler angles
            continue
        if compiled.codes[i] == PERMANENT:
            angles.append(joints[i, _THETA_J, 1])
            parts.append((i, True))
            continue
        angles.append(float(np.asarray(y)[12 * i + 1]))
        parts.append((i, False))
        if compiled.parents[i] >= 0:
            angles.append(joints[i, _THETA_J, 1])
            parts.append((i, True))
    return np.array(angles, dtype=float), parts


def gimbal_part_name(compiled: CompiledChain, part: int, joint: bool) -> str:
    """In words, the Euler angles of :func:`gimbal_angles`' ``(part, joint)``: ``"body
    trunk's Theta"`` or ``"joint hip's Theta_j"``."""
    if joint:
        return f"joint {compiled.chain.joint_names[part]}'s Theta_j"
    return f"body {compiled.chain.body_names[part]}'s Theta"


def _gimbal_margin(compiled: CompiledChain, y: np.ndarray, margin: float) -> float:
    """min of (pi/2 - margin - |theta_2|) [rad] over the angles of :func:`gimbal_angles` at
    the maximal state ``y``: the run stops where it reaches 0 (eq 1's B(Theta) is singular
    at |theta_2| = pi/2; the compiled driver's :func:`rbstab.engine.systems.tree_margin`);
    inf for a tree of hinges (no Euler angles)."""
    return float(np.min(math.pi / 2 - margin - np.abs(gimbal_angles(compiled, y)[0]), initial=math.inf))


def locked_part(compiled: CompiledChain, y: np.ndarray) -> tuple[int, bool]:
    """The part of :func:`gimbal_angles` whose |theta_2| is largest at the maximal state ``y``
    (at a gimbal-lock event: the one that reached the lock)."""
    angles, parts = gimbal_angles(compiled, y)
    return parts[int(np.argmax(np.abs(angles)))]


def gimbal_lock_message(compiled: CompiledChain, part: int, joint: bool, margin: float, t: float) -> str:
    """The message of a run stopped by gimbal lock at ``t`` [s] where |theta_2| of body
    ``part``'s Theta (or, with ``joint``, joint ``part``'s Theta_j) reached pi/2 - ``margin``
    (the run's ``simulation.gimbal_margin`` [rad])."""
    return (f"gimbal lock: |theta_2| of {gimbal_part_name(compiled, part, joint)} reached pi/2 - {margin:g} rad "
            f"at t = {t:.6g} s; B(theta) is singular there (eq 5), so the Euler-angle model stops")


def bound_reached(compiled: CompiledChain, quantity: str, axis: int, part: int, bound: float) -> str:
    """In words, the bound ``bound`` (the quantity's units) of ``simulation.limits`` that
    body ``part`` of the tree reached on ``axis`` (0-2) of ``quantity`` (one of
    :data:`rbstab.layout.LIMITED`; for ``constraint_error``, E_j of joint ``part``), in the
    words of one body's message; e.g. ``"|theta_1| of trunk reached simulation.limits.theta =
    0.2 rad"``."""
    owner = (f"joint {compiled.chain.joint_names[part]}" if quantity == "constraint_error"
             else compiled.chain.body_names[part])
    return (f"|{LIMITED_COMPONENTS[quantity]}_{axis + 1}| of {owner} reached simulation.limits.{quantity} = "
            f"{bound:g} {display_units(OUTPUTS[quantity].units)}")


def region_margin(compiled: CompiledChain, y: np.ndarray, limits) -> tuple[float, tuple[int, int, int]]:
    """(min over bodies, joints and axes of bound - |q| [the quantity's units], the bound
    reached first: (its quantity's index in :data:`rbstab.layout.LIMITED`, the axis, the body
    or joint)) of ``simulation.limits``: Theta, Omega, X, V of every body, E_j of every joint
    (not point-fixed); a run stops where it reaches 0."""
    n = compiled.size
    worst, code = math.inf, (0, 0, 0)
    for k, block in enumerate(("theta", "omega", "position", "velocity")):
        bound = np.asarray(getattr(limits, block), dtype=float)
        values = np.abs(y[: 12 * n].reshape(n, 4, 3)[:, k])
        margin = bound[None, :] - values
        i, axis = np.unravel_index(int(np.argmin(margin)), margin.shape)
        if margin[i, axis] < worst:
            worst, code = float(margin[i, axis]), (k, int(axis), int(i))
    bound = np.asarray(limits.constraint_error, dtype=float)
    if np.isfinite(bound).any():
        joints = np.empty((n, 7, 3))
        chain_core(0.0, y, *compiled.args, np.empty(compiled.n_states), joints, np.empty((n, 3)), np.empty(5))
        for j in range(n):
            if POINT_FIXED[compiled.codes[j]]:
                continue
            margin = bound - np.abs(joints[j, _E])
            axis = int(np.argmin(margin))
            if margin[axis] < worst:
                worst, code = float(margin[axis]), (4, axis, j)
    return worst, code


def disturbance_edges(compiled: CompiledChain, time: np.ndarray) -> np.ndarray:
    """The number of edges of the bodies' disturbances' windows (each start, an impulse's
    included, and each pulse's end) at or before each of the times ``time`` (n,) [s]: the
    samples between two edges are one piece (v and dv/dt continuous there)."""
    time = np.asarray(time, dtype=float)
    count = np.zeros(time.shape)
    for p in compiled.params:
        for k in range(int(p["disturbance_count"])):
            start = p["disturbance_start"][k]
            count += time >= start
            if p["disturbance_kind"][k] == PULSE:
                count += time >= start + p["disturbance_duration"][k]
    return count


def impulse_times(compiled: CompiledChain, t_end: float) -> list[float]:
    """The times [s] in [0, t_end] at which an impulse of a body's disturbances starts, sorted."""
    times = set()
    for p in compiled.params:
        for k in range(int(p["disturbance_count"])):
            if p["disturbance_kind"][k] == IMPULSE and 0.0 <= p["disturbance_start"][k] <= t_end:
                times.add(float(p["disturbance_start"][k]))
    return sorted(times)


def _tree_outputs(time, states, params, first: CompiledChain, ppoints, rows, per_run) -> dict[str, np.ndarray]:
    """:func:`evaluate`'s outputs of m samples of trees of ``first``'s structure
    (:func:`chain_samples`; ``params`` (t, n), ``ppoints`` (t, n, 3), ``rows`` (m,) each
    sample's tree, runs of ``per_run`` samples), each (m, ...) a view of a component-major
    buffer; v and its terms without h."""
    m, n = states.shape[0], first.size
    joints, bodies, scalars, power = np.empty((n, 7, 3, m)), np.empty((n, 3, m)), np.empty((5, m)), np.empty(m)
    flags, blocks = np.empty((n, 3, 3, m)), np.empty((n, 4, 3, m))
    chain_samples(time, states, params, first.codes, first.parents, ppoints, first.d_at, rows, joints, bodies, scalars,
                  power, flags, blocks, per_run)
    joints, bodies, flags = joints.transpose(3, 0, 1, 2), bodies.transpose(2, 0, 1), flags.transpose(3, 0, 1, 2)
    blocks, scalars = blocks.transpose(3, 0, 1, 2), scalars.T
    out = {name: blocks[:, :, k] for k, name in enumerate(BODY_OUTPUTS[:4])}
    out["force_h"] = bodies
    for k in range(_OMEGA_J + 1):
        out[JOINT_OUTPUTS[k]] = joints[:, :, k]
    out["controller_state"][:, first.d_at < 0] = np.nan
    if np.any(BEYOND_PAPER[first.codes]):  # not computed here: rbstab.variants.tree.reaction_samples
        out["constraint_force"][:, first.permanent] = np.nan
    for k, (name, _) in enumerate(SATURATION_FLAGS.values()):  # N_j, H_j, Lambda_j: _saturation_flags' order
        out[name] = flags[:, :, k]
    for k, name in enumerate(LYAPUNOV_TERMS):
        out[name] = scalars[:, k]
    out["lyapunov"] = scalars[:, :_RATE].sum(axis=1)
    out["lyapunov_rate"], out["disturbance_power"] = scalars[:, _RATE], power
    return out


def _one_body_outputs(code, time, states, params, lead, tree_of, full) -> dict[str, np.ndarray]:
    """:func:`evaluate`'s outputs of m samples (runs of ``lead[-1]`` samples each, run i's of the tree
    ``tree_of[i]``) of trees that are the paper's one-body model (:func:`is_one_body`; ``code``
    their joint's law): :func:`rbstab.variants.kernels.run_outputs` (eqs 20-25, an output a
    row; v's terms without h where the records' h is 0), each (m, 1, 3) or (m,) a view of its
    rows; a permanent joint's state is Theta, Omega; with gravity, a permanent joint's
    ``net_centre_of_pressure`` (m, 3) (:func:`rbstab.variants.kernels.body_pressure`)."""
    m, per_run = states.shape[0], lead[-1]
    runs = m // per_run
    records = (np.repeat(params[:1, 0], runs) if tree_of is None else
               np.ascontiguousarray(params[np.asarray(tree_of, dtype=np.int64), 0]))
    size = 6 if code == PERMANENT else states.shape[1]
    columns = np.empty((N_OUTPUTS, runs, per_run))
    run_outputs(np.full(runs, code, dtype=np.int64), records, time.reshape(runs, -1),
                np.ascontiguousarray(states[:, :size]).reshape(runs, per_run, size), columns, full)
    columns = columns.reshape(N_OUTPUTS, m)
    out = {name: columns[at].T[:, None] if vector else columns[at] for name, at, vector in _ONE_BODY_ROWS[full]}
    out["joint_theta"], out["joint_omega"] = out["theta"], out["omega"]  # the ground joint's: A_p = I, Omega_p = 0
    if code == PERMANENT and np.any(records["weight"]):  # its net centre of pressure, as the GPU's stream takes it
        pressure = np.empty((runs, per_run, 3))
        body_pressures(code, records, columns.reshape(N_OUTPUTS, runs, per_run), pressure)
        out["net_centre_of_pressure"] = pressure.reshape(m, 3)
    if code != EMBEDDED:
        out["controller_state"] = np.full((m, 1, 3), np.nan)
    return out


#: One body's outputs :func:`evaluate` makes itself (v with the tree's h; W and the windows' edges: the run's
#: history, not its samples').
_NOT_EVALUATED = ("disturbance_work", "disturbance_edges", "lyapunov")
#: The rows of :func:`_one_body_outputs`' outputs (with ``full`` and without): (name, its
#: rows of the kernel's columns, whether a 3-vector).
_ONE_BODY_ROWS = {full: tuple((name, q.columns if q.size == 3 else q.offset, q.size == 3) for name, q in OUTPUTS.items()
                              if (full or name not in LEFT_OUT) and name not in _NOT_EVALUATED)
                  for full in (False, True)}
#: :func:`evaluate`'s outputs, in order.
_EVALUATED = (*BODY_OUTPUTS[:5], *JOINT_OUTPUTS[:7], *(name for name, _ in SATURATION_FLAGS.values()), *LYAPUNOV_TERMS,
              "lyapunov", "lyapunov_rate", "disturbance_power", "disturbance_work", "disturbance_edges")
#: :func:`evaluate`'s outputs of the paper's one body with ``full`` False.
_EVALUATED_BRIEF = tuple(key for key in _EVALUATED if key not in LEFT_OUT)


def evaluate(compiled: CompiledChain | Sequence[CompiledChain], time: np.ndarray, states: np.ndarray,
             work: np.ndarray | None = None, tree_of: np.ndarray | None = None,
             full: bool = True) -> dict[str, np.ndarray]:
    """Every output of a chain run's samples ``states`` (m, n_states) at ``time`` (m,), or
    of k runs' samples (k, m, n_states) at the same times (m,) (each output then has a
    leading run axis, and run i's are those of its samples alone):
    per body (m, n, 3): theta, omega, position, velocity, force_h (H delivered, inertial);
    per joint (m, n, 3): constraint_error E_j, constraint_rate F_j, constraint_force
    Lambda_j (inertial, on the child at C), torque_n N_j (child frame, delivered),
    controller_state D_j (NaN where not embedded), joint_theta Theta_j [rad], joint_omega
    Omega_j [rad/s] (child frame); the saturation flags (m, n, 3), 1.0 on an axis commanded
    at or beyond its limit, else 0.0 (:func:`rbstab.model.saturated`): torque_n_saturated
    and constraint_force_saturated per joint (Lambda_j never for a permanent joint),
    force_h_saturated per body; scalars (m,): lyapunov v [J], lyapunov_rate dv/dt [W] (analytic) and the
    terms lyapunov_translational, lyapunov_rotational, lyapunov_constraint, lyapunov_gravity [J] (eq 25's
    grouping; h in the
    gravity term), disturbance_power [W], disturbance_work W [J] (``work`` (m,) or (k, m),
    the run's integrated work at the samples; 0 where not given: it is a run's history,
    not a state's) and disturbance_edges (the windows' edges at or before each sample,
    :func:`disturbance_edges`). ``compiled``: the chain, or the chains (a sequence, one
    structure) of k runs' samples (k, m, n_states), run i's ``compiled[tree_of[i]]``.
    ``full`` False: the paper's one body's without :data:`rbstab.layout.LEFT_OUT`, which it
    then does not compute (neither a summary nor its thinned store reads them)."""
    trees = [compiled] if isinstance(compiled, CompiledChain) else list(compiled)
    first = trees[0]
    states = np.asarray(states, dtype=float)
    lead = states.shape[:-1] if states.ndim > 1 else (1,)
    time = np.ascontiguousarray(np.broadcast_to(np.asarray(time, dtype=float), lead)).reshape(-1)
    states = np.ascontiguousarray(states).reshape(-1, states.shape[-1])
    m = states.shape[0]
    rows = (np.zeros(m, dtype=np.int64) if tree_of is None else
            np.repeat(np.asarray(tree_of, dtype=np.int64), lead[-1]))  # each sample's tree
    params = first.params[None] if len(trees) == 1 else records_of(trees)
    offset = first.offset if len(trees) == 1 else np.array([c.offset for c in trees])[rows]  # h of each sample's tree
    one_body = all(c.one_body for c in trees)
    if one_body:  # the paper's one body: its own compiled outputs (eq 20's Lambda; 1.4x faster)
        out = _one_body_outputs(int(first.codes[0]), time, states, params, lead, tree_of, full)
        out["lyapunov_gravity"] = out["lyapunov_gravity"] + offset
        # summed as one body's file sums it: the two spellings' v bit for bit
        out["lyapunov"] = (out["lyapunov_translational"] + out["lyapunov_rotational"] + out["lyapunov_constraint"]
                           + out["lyapunov_gravity"])
    else:
        out = _tree_outputs(time, states, params, first, np.stack([c.ppoints for c in trees]), rows, lead[-1])
        out["lyapunov_gravity"] = out["lyapunov_gravity"] + offset
        out["lyapunov"] = out["lyapunov"] + offset
    out["disturbance_work"] = np.zeros(m) if work is None else np.array(work, dtype=float).reshape(-1)
    out["disturbance_edges"] = np.zeros(m)
    for t, tree in enumerate(trees):
        if np.any(tree.params["disturbance_count"] > 0):  # a tree with disturbances
            at = rows == t
            out["disturbance_edges"][at] = disturbance_edges(tree, time[at])
    keys = (*(_EVALUATED if full or not one_body else _EVALUATED_BRIEF),
            *(("net_centre_of_pressure",) if "net_centre_of_pressure" in out else ()))
    if len(lead) == 1:
        return {key: out[key] for key in keys}
    return {key: out[key].reshape(*lead, *out[key].shape[1:]) for key in keys}
