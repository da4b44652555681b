"""An independent plain-numpy formulation of the model, written from the paper (docs/physics.md).

What a researcher would write by hand (3x3 matrices, ``np.cross``): the reference that the
compiled kernels are checked against, and the naive baseline of ``benchmarks/``. It shares
no code with ``rbstab``'s physics. :func:`permanent_full_state_rhs` is the 12-state body of
eq 1 with Lambda solved from the acceleration constraint (eqs 15-17), the independent
check of the reduced 6-state ``permanent`` system.
"""

from __future__ import annotations

import numpy as np


def rotation(theta):
    """A = Rx(t1) Ry(t2) Rz(t3) (eq 2)."""
    c, s = np.cos(theta), np.sin(theta)
    rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    return rx @ ry @ rz


def euler_rate(theta):
    """B with dTheta/dt = B Omega (eq 1, corrected middle row)."""
    c2, s2, c3, s3 = np.cos(theta[1]), np.sin(theta[1]), np.cos(theta[2]), np.sin(theta[2])
    return np.array([[c3 / c2, -s3 / c2, 0], [s3, c3, 0], [-s2 * c3 / c2, s2 * s3 / c2, 1]])


def hat(r):
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


class Model:
    """The five variants' right-hand sides in plain numpy (``body``, ``gains``: rbstab's data)."""

    def __init__(self, variant: str, body, gains):
        self.variant, self.body, self.gains = variant, body, gains

    def delivered(self, u, which):
        """``u`` through the actuators' limits of ``which`` (gains.saturation), if any."""
        sat = getattr(self.gains, "saturation", None)
        if sat is None:
            return u
        limit = np.asarray(getattr(sat, which), dtype=float)
        if sat.shape == "smooth":
            with np.errstate(invalid="ignore"):  # inf * tanh(0) where unlimited: not taken
                return np.where(np.isinf(limit), u, limit * np.tanh(u / limit))
        return np.clip(u, -limit, limit)

    def commanded_controls(self, theta, omega, x, v):
        g = self.gains
        n = -euler_rate(theta).T @ g.k_r @ theta - g.l_r @ omega  # eq 23
        h = -g.k_t @ x - g.l_t @ v  # eq 24
        return n, h

    def controls(self, theta, omega, x, v):
        n, h = self.commanded_controls(theta, omega, x, v)
        return self.delivered(n, "torque_n"), self.delivered(h, "force_h")

    def commanded_constraint(self, e, f, d):
        g = self.gains
        if self.variant == "visco_elastic":
            return -g.k_c @ e - g.l_c @ f, np.zeros(3)
        if self.variant == "embedded":
            d_dot = np.linalg.solve(g.l_d, g.k_c @ (e - d) - g.k_d @ d)
            return -g.k_c @ (e - d) - g.l_c @ f, d_dot
        if self.variant == "sliding":
            phi = g.boundary_layer
            return -g.k_s * (np.tanh(e / phi) if phi > 0 else np.sign(e)), np.zeros(3)
        return np.zeros(3), np.zeros(3)

    def constraint(self, e, f, d):
        lam, d_dot = self.commanded_constraint(e, f, d)
        return self.delivered(lam, "constraint_force"), d_dot

    def rhs(self, t, y):
        if self.variant == "permanent":
            return self.reduced_rhs(y)
        b = self.body
        m, J, r, G = b.mass, b.inertia, b.attachment_point, b.mass * b.gravity
        theta, omega, x, v = y[0:3], y[3:6], y[6:9], y[9:12]
        d = y[12:15] if len(y) == 15 else np.zeros(3)
        a = rotation(theta)
        e = x + a @ r - r
        f = v + a @ np.cross(omega, r)
        n, h = self.controls(theta, omega, x, v)
        lam, d_dot = self.constraint(e, f, d)
        omega_dot = np.linalg.solve(J, -np.cross(omega, J @ omega) + n + hat(r) @ a.T @ lam)
        v_dot = (G + h + lam) / m
        out = np.concatenate([euler_rate(theta) @ omega, omega_dot, v, v_dot])
        return np.concatenate([out, d_dot]) if len(y) == 15 else out

    def reduced_rhs(self, y):
        """Euler's equation about the fixed point C (eq 21, corrected)."""
        b = self.body
        m, J, r, G = b.mass, b.inertia, b.attachment_point, b.mass * b.gravity
        theta, omega = y[0:3], y[3:6]
        a = rotation(theta)
        x, v = r - a @ r, a @ hat(r) @ omega
        n, h = self.controls(theta, omega, x, v)
        j_p = J - m * hat(r) @ hat(r)
        omega_dot = np.linalg.solve(j_p, -np.cross(omega, j_p @ omega) + n - hat(r) @ a.T @ (G + h))
        return np.concatenate([euler_rate(theta) @ omega, omega_dot])


def permanent_full_state_rhs(body, gains):
    """The 12-state right-hand side of the pinned body (eq 1 with Lambda from eq 15) and
    a function giving Lambda at a 12-state."""
    model = Model("free", body, gains)
    m, J, r, G = body.mass, body.inertia, body.attachment_point, body.mass * body.gravity

    def constraint_force(y):
        theta, omega, x, v = y[0:3], y[3:6], y[6:9], y[9:12]
        a = rotation(theta)
        n, h = model.controls(theta, omega, x, v)
        a_r = a @ hat(r)
        # dF/dt = dV/dt - A hat(R) dOmega/dt + A hat(Omega)^2 R = 0 with eq 1 substituted
        lhs = np.eye(3) / m + a_r @ np.linalg.solve(J, a_r.T)
        rhs = a_r @ np.linalg.solve(J, -np.cross(omega, J @ omega) + n) - (G + h) / m - a @ np.cross(omega, np.cross(omega, r))
        return np.linalg.solve(lhs, rhs)

    def rhs(t, y):
        theta, omega, x, v = y[0:3], y[3:6], y[6:9], y[9:12]
        a = rotation(theta)
        n, h = model.controls(theta, omega, x, v)
        lam = constraint_force(y)
        omega_dot = np.linalg.solve(J, -np.cross(omega, J @ omega) + n + hat(r) @ a.T @ lam)
        return np.concatenate([euler_rate(theta) @ omega, omega_dot, v, (G + h + lam) / m])

    return rhs, constraint_force


# -- disturbances (docs/disturbances.md), written again from the definitions ------------------------
def disturbance_value(d, t):
    """The value of one continuous disturbance ``d`` (rbstab.model.Disturbance) at t, or None
    where it does not act (an impulse, or outside its window)."""
    if d.kind == "impulse" or t < d.start:
        return None
    if d.kind == "pulse":
        return None if t >= d.start + d.duration else np.asarray(d.value, float)
    if d.kind == "step":
        return np.asarray(d.value, float)
    if d.kind == "sine":
        return np.asarray(d.value, float) * np.sin(2 * np.pi * d.frequency * (t - d.start) + d.phase)
    return noise_value(d, t)


#: The sines of a noise per axis (docs/disturbances.md).
NOISE_TONES = 16


def _hash32(x):
    """lowbias32's shape with the multipliers 0x7FEB352D, 0x5BD1E995 (Python integers)."""
    x &= 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x5BD1E995) & 0xFFFFFFFF
    return x ^ (x >> 16)


def noise_phases(seed, axis):
    """The phases phi_k = 2 pi n_k / 256 [rad], k = 0 ... 15, of the sines of axis ``axis`` of a
    noise of ``seed``: n_k byte k mod 4 (the lowest first) of h(key + k // 4), key =
    h(h(seed) + axis 0x9E3779B1 + 1) (h: :func:`_hash32`)."""
    key = _hash32(_hash32(seed) + axis * 0x9E3779B1 + 1)
    levels = [(_hash32(key + k // 4) >> (8 * (k % 4))) & 0xFF for k in range(NOISE_TONES)]
    return 2 * np.pi * np.array(levels) / 256


def noise_value(d, t):
    """A noise's value [N] or [N m] at t >= start: on axis j, rms_j sqrt(2/N) times the sum of
    sin(2 pi f_k (t - start) + phi_jk), f_k = f_lo + (k + 1/2) (f_hi - f_lo) / N, each sine
    evaluated on its own."""
    f_lo, f_hi = d.band
    n = NOISE_TONES
    f = f_lo + (np.arange(n) + 0.5) * (f_hi - f_lo) / n
    tau = t - d.start
    rms = np.asarray(d.value, float)
    return np.array([rms[j] * np.sqrt(2.0 / n) * np.sum(np.sin(2 * np.pi * f * tau + noise_phases(int(d.seed), j)))
                     for j in range(3)])


def disturbance_wrench(disturbances, theta, t):
    """(F inertial [N], T body [N m] about the centre of mass) of the continuous disturbances."""
    a = rotation(theta)
    force, torque = np.zeros(3), np.zeros(3)
    for d in disturbances:
        value = disturbance_value(d, t)
        if value is None:
            continue
        if d.quantity == "force":
            force += value
            torque += np.cross(d.point, a.T @ value)
        else:
            torque += value
    return force, torque


def disturbed_rates(body, disturbances, theta, t):
    """What the disturbances add to (dOmega/dt, dV/dt) of a full-state body: J^-1 T, F / m."""
    force, torque = disturbance_wrench(disturbances, theta, t)
    return np.linalg.solve(body.inertia, torque), force / body.mass


def impulse_jump(body, d, theta, permanent=False):
    """(dOmega, dV) of an impulse: J dOmega = R_p x A'P, dV = P / m (permanent: J_p dOmega =
    (R_p - R) x A'P, V follows C at rest); torque impulses J dOmega = L."""
    a = rotation(theta)
    value = np.asarray(d.value, float)
    r = np.asarray(body.attachment_point, float)
    j_p = body.inertia - body.mass * hat(r) @ hat(r)
    inertia = j_p if permanent else body.inertia
    if d.quantity == "torque":
        return np.linalg.solve(inertia, value), np.zeros(3)
    arm = np.asarray(d.point, float) - (r if permanent else 0.0)
    return np.linalg.solve(inertia, np.cross(arm, a.T @ value)), (np.zeros(3) if permanent else value / body.mass)
