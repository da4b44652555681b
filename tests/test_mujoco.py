"""rbstab against MuJoCo, an independent rigid-body engine.

MuJoCo integrates the body in its own coordinates (a unit quaternion, the angular
velocity of the joint, a mass matrix from composite rigid bodies, bias forces by
recursive Newton-Euler), with its own RK4. Nothing of rbstab's model is used on the
MuJoCo side: the tests convert MuJoCo's state to rbstab's (Euler angles of A = Rx Ry Rz,
Omega in the body frame, the centre of mass X) and compare trajectories.

(a) ``permanent``: a ball joint at C. The body frame of the MuJoCo body has its origin at C
    and its axes along the principal axes, the centre of mass at -R from it (C is at R in
    the body frame from the COM); the body sits at R in the world, so its COM is
    X = R - A R as in rbstab (eq 32). Gravity is MuJoCo's; the feedback N = -B'K_r Theta
    - L_r Omega (body frame, eq 23) and H = -K_t X - L_t V (at the COM, eq 24) are
    recomputed from MuJoCo's state at every RK4 stage (``mjcb_control`` runs inside each
    stage's forward pass) and applied as ``xfrc_applied``: the torque of G + H about C is
    MuJoCo's business, and it must come out as rbstab's -hat(R) A'(G + H) (eq 21).
(b) ``free`` with every gain zero and no gravity: a torque-free body on a free joint.

MuJoCo's RK4 converges at 4th order on both; at the steps used the two engines agree to
about 1e-9 (docs/physics.md), and the tests ask for 1e-7. A MuJoCo run that goes unstable
(a broken model) writes MUJOCO_LOG.TXT in the working directory.
"""

from __future__ import annotations

import math
import warnings

import mujoco
import numpy as np
import pytest

from rbstab.config import config_from_mapping, load_config
from rbstab.simulator import simulate

from conftest import ROOT

#: Agreement asked of the two engines, relative to each quantity's scale.
RTOL = 1e-7
TIGHT = ["simulation.rtol=1e-12", "simulation.atol=1e-12"]


# -- conventions, written here from the paper and docs/physics.md (not taken from rbstab) -------


def euler_angles(a: np.ndarray) -> np.ndarray:
    """Theta with A = Rx(t1) Ry(t2) Rz(t3), |t2| < pi/2, t1 and t3 in (-pi, pi]."""
    return np.array(
        [
            math.atan2(-a[1, 2], a[2, 2]),
            math.asin(min(1.0, max(-1.0, a[0, 2]))),
            math.atan2(-a[0, 1], a[0, 0]),
        ]
    )


def quaternion(theta) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of A = Rx(t1) Ry(t2) Rz(t3)."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    for axis, angle in zip(np.eye(3), theta):
        factor = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])
        mujoco.mju_mulQuat(q, q.copy(), factor)
    return q


def euler_rate_matrix(theta) -> np.ndarray:
    """B of dTheta/dt = B Omega (eq 1, consistent middle row)."""
    c2, s2 = math.cos(theta[1]), math.sin(theta[1])
    c3, s3 = math.cos(theta[2]), math.sin(theta[2])
    return np.array([[c3 / c2, -s3 / c2, 0.0], [s3, c3, 0.0], [-s2 * c3 / c2, s2 * s3 / c2, 1.0]])


def hat(r) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def angle_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| with t1 and t3 compared modulo 2 pi (a free body turns over and over)."""
    d = a - b
    d[..., [0, 2]] = (d[..., [0, 2]] + np.pi) % (2 * np.pi) - np.pi
    return np.abs(d)


def relative_error(mine: np.ndarray, theirs: np.ndarray) -> float:
    return float(np.max(np.abs(mine - theirs)) / np.max(np.abs(theirs)))


# -- MuJoCo side ---------------------------------------------------------------------------------


def mujoco_body(joint: str, mass: float, inertia, body_pos, com, gravity, timestep: float):
    """Model and data of one body on a ``joint`` ("ball" or "free") to the world, RK4.

    ``com``: the centre of mass in the body frame, whose axes are the principal axes.
    The principal moments are set after compiling: MuJoCo's compiler refuses moments that
    violate the triangle inequality, such as Table 1's (10, 8, 0.4); its dynamics do not
    care (and neither do rbstab's equations). mj_setConst refreshes what the compiler
    derived from them.
    """
    joint_xml = "<freejoint/>" if joint == "free" else '<joint type="ball"/>'

    def xyz(vector) -> str:
        return " ".join(repr(float(x)) for x in vector)

    xml = f"""
    <mujoco>
      <option timestep="{float(timestep)!r}" integrator="RK4" gravity="{xyz(gravity)}">
        <flag energy="enable"/>
      </option>
      <worldbody>
        <body name="body" pos="{xyz(body_pos)}">
          {joint_xml}
          <inertial pos="{xyz(com)}" mass="{float(mass)!r}" diaginertia="1 1 1"/>
        </body>
      </worldbody>
    </mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    model.body_inertia[1] = inertia
    data = mujoco.MjData(model)
    mujoco.mj_setConst(model, data)
    return model, data


def run_mujoco(model, data, t_end: float, n_samples: int, record) -> list:
    """mj_step to t_end; ``record(data)`` at n_samples evenly spaced times (0 and t_end too)."""
    steps = round(t_end / model.opt.timestep)
    every = steps // (n_samples - 1)
    assert every * (n_samples - 1) == steps and abs(steps * model.opt.timestep - t_end) < 1e-12
    mujoco.mj_forward(model, data)
    samples = [record(data)]
    for i in range(1, steps + 1):
        mujoco.mj_step(model, data)
        if i % every == 0:
            mujoco.mj_forward(model, data)  # positions, velocities of the new state
            samples.append(record(data))
    return samples


# -- (a) permanent: a ball joint at C with gravity and feedback --------------------------------


def test_permanent_case_1_agrees_with_a_ball_joint_in_mujoco():
    n_samples = 21
    config = load_config(ROOT / "configs/paper/case1_permanent.yaml", [*TIGHT, f"simulation.n_samples={n_samples}"])
    ours = simulate(config)
    assert ours.status == "success"
    body, ctrl = config.resolved["body"], config.resolved["controller"]
    mass, inertia = body["mass"], np.array(body["inertia"], float)
    r, gravity = np.array(body["attachment_point"], float), np.array(body["gravity"], float)
    k_t, l_t, k_r, l_r = (np.diag(ctrl[k]) for k in ("k_t", "l_t", "k_r", "l_r"))
    theta0 = np.array(config.resolved["initial_state"]["theta"], float)
    omega0 = np.array(config.resolved["initial_state"]["omega"], float)

    model, data = mujoco_body("ball", mass, inertia, r, -r, gravity, timestep=5e-4)
    data.qpos[:] = quaternion(theta0)
    data.qvel[:] = omega0  # a ball joint's velocity: Omega in the body frame
    mujoco.mj_forward(model, data)
    # MuJoCo's kinetic energy about the pivot: 1/2 Omega' (J - m hat(R)^2) Omega
    j_p = np.diag(inertia) - mass * hat(r) @ hat(r)
    assert data.energy[1] == pytest.approx(0.5 * omega0 @ j_p @ omega0, rel=1e-12)

    reference = {"theta": theta0.copy()}
    velocity = np.zeros(6)
    calls = []

    def state(d):
        """Theta (continuous along the run), Omega, X, V from MuJoCo's state."""
        a = d.xmat[1].reshape(3, 3)
        theta = euler_angles(a)
        theta = reference["theta"] + (theta - reference["theta"] + np.pi) % (2 * np.pi) - np.pi
        reference["theta"] = theta
        mujoco.mj_objectVelocity(model, d, mujoco.mjtObj.mjOBJ_BODY, 1, velocity, 0)  # at the COM
        return a, theta, d.qvel[:3].copy(), d.xipos[1].copy(), velocity[3:].copy()

    def feedback(m, d):
        a, theta, omega, x, v = state(d)
        torque_n = -euler_rate_matrix(theta).T @ k_r @ theta - l_r @ omega  # eq 23, body frame
        force_h = -k_t @ x - l_t @ v  # eq 24, at the COM
        d.xfrc_applied[1, :3] = force_h
        d.xfrc_applied[1, 3:] = a @ torque_n
        calls.append(d.time)

    def record(d):
        mujoco.mj_rnePostConstraint(model, d)  # cfrc_int: the force through the joint
        _, theta, omega, x, _ = state(d)
        return theta, omega, x, d.cfrc_int[1, 3:].copy()

    mujoco.set_mjcb_control(feedback)
    try:
        samples = run_mujoco(model, data, config.simulation.t_end, n_samples, record)
    finally:
        mujoco.set_mjcb_control(None)
    steps = round(config.simulation.t_end / model.opt.timestep)
    # the feedback ran at each of RK4's 4 stages, at t, t + h/2 (twice) and t + h (plus
    # once per recorded sample)
    assert len(calls) == 4 * steps + n_samples
    h = model.opt.timestep
    assert np.count_nonzero(np.isclose(calls, 0.5 * h, rtol=0, atol=1e-15)) == 2

    theirs = {k: np.array([s[i] for s in samples]) for i, k in enumerate(("theta", "omega", "position", "force"))}
    out = ours.outputs
    np.testing.assert_allclose(ours.time, np.linspace(0, config.simulation.t_end, n_samples), rtol=0, atol=1e-15)
    assert relative_error(out["theta"], theirs["theta"]) < RTOL
    assert relative_error(out["omega"], theirs["omega"]) < RTOL
    assert relative_error(out["position"], theirs["position"]) < RTOL  # X = R - A R (eq 32)
    assert relative_error(out["constraint_force"], theirs["force"]) < RTOL  # Lambda (eq 20)
    # the final state (decayed to about 1e-3 of the initial one), each to its own size
    for ours_key, theirs_key in (("theta", "theta"), ("omega", "omega"), ("constraint_force", "force")):
        assert relative_error(out[ours_key][-1], theirs[theirs_key][-1]) < RTOL, ours_key


# -- (b) free, zero gains, no gravity: torque-free tumbling --------------------------------------


def test_torque_free_body_agrees_with_a_free_joint_in_mujoco():
    n_samples, t_end = 21, 2.0
    zero = [0.0, 0.0, 0.0]
    data_in = {
        "name": "tumbling",
        "body": {"mass": 41.0, "inertia": [10.0, 8.0, 0.4], "attachment_point": [0.15, 0.10, -0.42]},
        "controller": {"variant": "free", "k_t": zero, "l_t": zero, "k_r": zero, "l_r": zero},
        "initial_state": {
            "theta": [0.3, -0.2, 0.1],
            "omega": [16.0, 32.0, -16.0],
            "x": [0.1, 0.2, -0.3],
            "v": [0.5, -0.2, 0.1],
        },
        "simulation": {"t_end": t_end, "n_samples": n_samples, "rtol": 1e-12, "atol": 1e-12},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Table 1's inertia; the zero gains' note
        config = config_from_mapping(data_in)
    ours = simulate(config)
    assert ours.status == "success"
    state0 = {k: np.array(v, float) for k, v in data_in["initial_state"].items()}
    mass, inertia = data_in["body"]["mass"], np.array(data_in["body"]["inertia"])

    model, data = mujoco_body("free", mass, inertia, zero, zero, zero, timestep=1e-4)
    # a free joint: qpos = (COM position, quaternion), qvel = (V in the world, Omega in the body)
    data.qpos[:] = np.concatenate([state0["x"], quaternion(state0["theta"])])
    data.qvel[:] = np.concatenate([state0["v"], state0["omega"]])
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(euler_angles(data.xmat[1].reshape(3, 3)), state0["theta"], atol=1e-15)
    kinetic = 0.5 * mass * state0["v"] @ state0["v"] + 0.5 * state0["omega"] @ (inertia * state0["omega"])
    assert data.energy[1] == pytest.approx(kinetic, rel=1e-12)

    def record(d):
        return euler_angles(d.xmat[1].reshape(3, 3)), d.qvel[3:].copy(), d.xipos[1].copy(), d.qvel[:3].copy()

    samples = run_mujoco(model, data, t_end, n_samples, record)
    theirs = {k: np.array([s[i] for s in samples]) for i, k in enumerate(("theta", "omega", "position", "velocity"))}
    out = ours.outputs
    assert np.max(np.abs(out["theta"][:, 0])) > 2 * np.pi  # it turns over: angles modulo 2 pi
    assert np.max(angle_error(out["theta"], theirs["theta"])) < RTOL  # [rad]
    assert relative_error(out["omega"], theirs["omega"]) < RTOL
    assert relative_error(out["omega"][-1], theirs["omega"][-1]) < RTOL
    assert relative_error(out["position"], theirs["position"]) < RTOL
    assert relative_error(out["velocity"], theirs["velocity"]) < RTOL
