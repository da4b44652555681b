"""Disturbances acting on the body (docs/disturbances.md): compiled physics shared by every
engine through :mod:`rbstab.variants.kernels`.

A run's disturbances are fields of its :data:`~rbstab.model.PARAMETERS` record (at most
:data:`~rbstab.model.MAX_DISTURBANCES`; ``disturbance_count`` 0: none, nothing here is
read). The continuous kinds (pulse, step, sine, noise) are a force F (inertial frame, at
the point R_p of the body) or a torque T (body frame) that :func:`disturbance_wrench`
sums at a time t; their power is P = F'V_p + Omega'T = F'V + Omega'(T + R_p x A'F),
V_p = V + A (Omega x R_p) the velocity of the point (:func:`disturbance_power`). An
impulse is a jump of the velocities at its start (:func:`apply_impulses`).

Every edge of a window (the start of every kind, the end of a pulse) is a breakpoint of
the integration (:func:`next_breakpoint`): no step crosses one, and a step that ends at
one evaluates the disturbance just before it (the drivers clamp the stage times to the
float below the breakpoint), so the window is [start, end) on both sides of an edge.

``noise`` is a random-phase multisine: on axis j, with N = NOISE_TONES,

    x_j(tau) = rms_j sqrt(2 / N) sum_{k=0}^{N-1} sin(2 pi f_k tau + phi_jk),   tau = t - start,

at the frequencies f_k = f_lo + (k + 1/2) df, df = (f_hi - f_lo) / N (each inside the band),
with the phases phi_jk = 2 pi n_jk / 256, n_jk a byte of a 32-bit hash of (seed, axis, k)
(:func:`noise_level`): one hash gives 4 sines' phases. Its mean square over a long window is
rms_j^2 (N sines of mean square 1/2 at distinct frequencies). An evaluation takes two sines
and two cosines, whatever t: with E_k = exp(i 2 pi f_k tau), E_0 and D = exp(i 2 pi df tau)
from the fractions of a turn f_0 tau and df tau, E_{k+1} = E_k D (shared by the axes), and
sin(2 pi f_k tau + phi) = Im E_k cos(phi) + Re E_k sin(phi) with cos(phi), sin(phi) from the
table :data:`NOISE_PHASORS`. The round-off of the N - 1 products grows as k, and stays that
of a direct sum of the sines in double precision: against the exact sum, at most 6e-15 rms_j
for tau <= 1 s (direct: 6e-15), 3.5e-14 for tau <= 10 s (direct: 5.6e-14), 4e-12 for
tau <= 1000 s (direct: 5e-12), the rounding of f_k tau growing with tau. It needs no state and
gives the same numbers on every engine.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import jit
from ..kinematics import ZERO, add, cross, dot, matTvec, matvec, neg, rotation_and_rate_of, scale, sub, vector
from ..model import DISTURBANCE_KINDS, NOISE_TONES

__all__ = ["disturbance_wrench", "disturbance_power", "apply_impulses", "next_breakpoint", "edges_up_to", "noise_level",
           "NOISE_PHASORS", "kinetic_energy", "before", "state_power"]

IMPULSE, PULSE, STEP, SINE, NOISE = (float(DISTURBANCE_KINDS[k]) for k in ("impulse", "pulse", "step", "sine", "noise"))
TWO_PI = 2.0 * math.pi
_TONES = NOISE_TONES
if _TONES % 4:
    raise ValueError(f"NOISE_TONES must be a multiple of 4 (a hash gives 4 phases), not {_TONES}")
_MASK = 0xFFFFFFFF
#: (cos, sin) of the phase 2 pi n / 256 of a noise's sine, n = 0 ... 255 (:func:`noise_level`),
#: shape (256, 2): one table compiled into every engine.
NOISE_PHASORS = np.stack([np.cos(TWO_PI * np.arange(256) / 256), np.sin(TWO_PI * np.arange(256) / 256)], axis=1)


@jit(forceinline=True)
def _hash32(x):
    """A 32-bit integer hash (lowbias32's shape with multipliers below 2^31, so that every
    product fits an int64 on every engine)."""
    x = x & _MASK
    x ^= x >> 16
    x = (x * 0x7FEB352D) & _MASK
    x ^= x >> 15
    x = (x * 0x5BD1E995) & _MASK
    x ^= x >> 16
    return x


@jit(forceinline=True)
def _noise_key(seed, axis):
    """The 32-bit hash of (seed, axis) from which the phases of an axis of a noise follow."""
    return _hash32(_hash32(int(seed)) + axis * 0x9E3779B1 + 1)


@jit(forceinline=True)
def noise_level(seed, axis, k):
    """n in 0 ... 255, the phase 2 pi n / 256 [rad] of the k-th sine of axis ``axis`` (0, 1, 2)
    of a noise of ``seed``: byte k mod 4 (the lowest: 0) of h(key + k // 4), key = h(h(seed) +
    axis 0x9E3779B1 + 1), h :func:`_hash32`."""
    return (_hash32(_noise_key(seed, axis) + k // 4) >> (8 * (k % 4))) & 255


@jit(forceinline=True)
def _turn(x):
    """(cos, sin) of 2 pi x, x [turns] reduced to [0, 1) first."""
    angle = TWO_PI * (x - math.floor(x))
    return math.cos(angle), math.sin(angle)


@jit(forceinline=True)
def _noise(t, i, p):
    """The noise of entry i of ``p`` at time t [s] (acting from its start) on each axis, as a
    3-tuple [N] or [N m]: the sines' phasors E_k by the recurrence E_{k+1} = E_k D of the
    module's docstring, their phases from :data:`NOISE_PHASORS`."""
    f_lo, f_hi = p.disturbance_band[i, 0], p.disturbance_band[i, 1]
    df = (f_hi - f_lo) / _TONES
    tau = t - p.disturbance_start[i]
    seed = p.disturbance_seed[i]
    ec, es = _turn((f_lo + 0.5 * df) * tau)
    dc, ds = _turn(df * tau)
    key0, key1, key2 = _noise_key(seed, 0), _noise_key(seed, 1), _noise_key(seed, 2)
    out0 = 0.0
    out1 = 0.0
    out2 = 0.0
    for m in range(_TONES // 4):  # sine k = 4 m + b: byte b of the hashes of key + m (noise_level)
        h0, h1, h2 = _hash32(key0 + m), _hash32(key1 + m), _hash32(key2 + m)
        for b in range(4):
            n0, n1, n2 = (h0 >> 8 * b) & 255, (h1 >> 8 * b) & 255, (h2 >> 8 * b) & 255
            out0 += es * NOISE_PHASORS[n0, 0] + ec * NOISE_PHASORS[n0, 1]
            out1 += es * NOISE_PHASORS[n1, 0] + ec * NOISE_PHASORS[n1, 1]
            out2 += es * NOISE_PHASORS[n2, 0] + ec * NOISE_PHASORS[n2, 1]
            ec, es = ec * dc - es * ds, ec * ds + es * dc
    amp = math.sqrt(2.0 / _TONES)
    return (p.disturbance_value[i, 0] * amp * out0, p.disturbance_value[i, 1] * amp * out1,
            p.disturbance_value[i, 2] * amp * out2)


@jit(forceinline=True)
def disturbance_wrench(t, a, p):
    """(F [N], inertial frame; T [N m], body frame, about the centre of mass) of the
    continuous disturbances of ``p`` at time t with the body at attitude A: F the sum of
    the forces, T the sum of the torques and of the forces' moments R_p x A'F."""
    force = ZERO
    torque = ZERO
    for i in range(int(p.disturbance_count)):
        kind = p.disturbance_kind[i]
        t0 = p.disturbance_start[i]
        if kind == IMPULSE or t < t0:
            continue
        if kind == PULSE:
            if t >= t0 + p.disturbance_duration[i]:
                continue
            value = vector(p.disturbance_value[i], 0)
        elif kind == STEP:
            value = vector(p.disturbance_value[i], 0)
        elif kind == SINE:
            s = math.sin(TWO_PI * p.disturbance_frequency[i] * (t - t0) + p.disturbance_phase[i])
            value = scale(s, vector(p.disturbance_value[i], 0))
        else:
            value = _noise(t, i, p)
        if p.disturbance_torque[i] == 0.0:
            force = add(force, value)
            torque = add(torque, cross(vector(p.disturbance_point[i], 0), matTvec(a, value)))
        else:
            torque = add(torque, value)
    return force, torque


@jit(forceinline=True)
def disturbance_power(force, torque, omega, v):
    """P = F'V + Omega'T [W]: the power of the disturbances' wrench (F, T) of
    :func:`disturbance_wrench` on the body moving with V, Omega."""
    return dot(force, v) + dot(omega, torque)


@jit(forceinline=True)
def next_breakpoint(p, t, t_end):
    """The first edge of a disturbance's window after t (a start; a pulse's end), or
    ``t_end`` where none comes before it."""
    out = t_end
    for i in range(int(p.disturbance_count)):
        t0 = p.disturbance_start[i]
        if t < t0 < out:
            out = t0
        if p.disturbance_kind[i] == PULSE:
            t1 = t0 + p.disturbance_duration[i]
            if t < t1 < out:
                out = t1
    return out


@jit(forceinline=True)
def edges_up_to(p, t):
    """The number of edges of the disturbances' windows at or before t (each start, an
    impulse's included, and each pulse's end): constant between two breakpoints
    (:func:`next_breakpoint`), one more after each; a sample at an edge shows the state
    after it."""
    count = 0
    for i in range(int(p.disturbance_count)):
        t0 = p.disturbance_start[i]
        if t0 <= t:
            count += 1
        if p.disturbance_kind[i] == PULSE and t0 + p.disturbance_duration[i] <= t:
            count += 1
    return float(count)


@jit(forceinline=True)
def before(t):
    """The float just below t > 0 (the time a step that ends at a breakpoint evaluates)."""
    if t <= 0.0:
        return t
    m, e = math.frexp(t)
    return t - math.ldexp(1.0, e - 53) if m != 0.5 else t - math.ldexp(1.0, e - 54)


@jit(forceinline=True)
def kinetic_energy(permanent, y, p):
    """T [J] of the state y: m V'V/2 + Omega'J Omega/2 (``permanent``: Omega'J_p Omega/2,
    the kinetic energy about the fixed point C)."""
    omega = vector(y, 3)
    if permanent:
        return 0.5 * dot(omega, matvec(p.pivot_inertia, omega))
    v = vector(y, 9)
    return 0.5 * p.mass * dot(v, v) + 0.5 * dot(omega, matvec(p.inertia, omega))


@jit(forceinline=True)
def apply_impulses(permanent, t, y, p):
    """Apply the impulses of ``p`` that start at t to the state y (in place); returns the
    jump of the kinetic energy [J], their work.

    Full state: dV = P/m, J dOmega = R_p x (A'P) (a torque impulse L: J dOmega = L).
    ``permanent``: the pin's impulsive reaction keeps C at rest,
    J_p dOmega = (R_p - R) x (A'P) (torque: J_p dOmega = L).
    """
    before_jump = kinetic_energy(permanent, y, p)
    jumped = False
    for i in range(int(p.disturbance_count)):
        if p.disturbance_kind[i] != IMPULSE or p.disturbance_start[i] != t:
            continue
        jumped = True
        a, _ = rotation_and_rate_of(vector(y, 0))
        value = vector(p.disturbance_value[i], 0)
        if p.disturbance_torque[i] == 0.0:
            arm = vector(p.disturbance_point[i], 0)
            if permanent:
                arm = sub(arm, p.attachment_point)
            moment = cross(arm, matTvec(a, value))
            if not permanent:
                for j in range(3):
                    y[9 + j] += value[j] / p.mass
        else:
            moment = value
        d_omega = matvec(p.pivot_inertia_inv if permanent else p.inertia_inv, moment)
        for j in range(3):
            y[3 + j] += d_omega[j]
    if not jumped:
        return 0.0
    return kinetic_energy(permanent, y, p) - before_jump


@jit(forceinline=True)
def state_power(permanent, t, y, p):
    """P [W] of the disturbances at the state y (``permanent``: the reduced state, V = -A
    (Omega x R)) at time t."""
    omega = vector(y, 3)
    a, _ = rotation_and_rate_of(vector(y, 0))
    if permanent:
        v = neg(matvec(a, cross(omega, p.attachment_point)))
    else:
        v = vector(y, 9)
    force, torque = disturbance_wrench(t, a, p)
    return disturbance_power(force, torque, omega, v)
