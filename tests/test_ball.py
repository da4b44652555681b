"""The ball joint free of gimbal lock (``variant: ball``, docs/physics.md "Joint kinds"): a row of
the joint-kind table whose child is carried by the unit quaternion of its relative rotation and
Omega_j, its spring 1/2 phi' K_r phi on the rotation vector phi = log(A(Theta_ref)' A_rel) with the
torque -J_r(phi)^-T K_r phi - L_r Omega_j. Checked against MuJoCo's ball joints (springs and
dampers) through the relative Euler angles' gimbal lock, against v's own bookkeeping, and its
linearisation against MuJoCo's in its tangent directions."""

from __future__ import annotations

import numpy as np
import pytest

from rbstab.analysis import analyze
from rbstab.config import ConfigError, config_from_mapping
from rbstab.kinematics import rotation_matrix
from rbstab.simulator import simulate

mujoco = pytest.importorskip("mujoco")

INERTIA = ([0.08, 0.07, 0.02], [0.06, 0.05, 0.03])  # kg m^2, about each body's centre of mass
CHILD_POINT = [0.0, 0.02, 0.5]  # m: each joint's point C, above the body's centre of mass
PARENT_POINT = [0.05, 0.0, -0.5]  # m: where the second body hangs, below the first's centre of mass


def _balls(k, l, theta, omega, t_end=2.0, n_samples=201, **joint):
    """Two bodies hanging from the ground on balls, joint i with the isotropic spring ``k[i]``
    and damper ``l[i]`` [per axis], released at the bodies' Euler angles ``theta`` and angular
    velocities ``omega`` (body frames)."""
    names = ["b0", "b1"]
    return {
        "name": "balls", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": b, "mass": 1.0 + 0.2 * i, "inertia": INERTIA[i]} for i, b in enumerate(names)],
        "joints": [{"name": f"j{i}", "parent": "ground" if i == 0 else names[i - 1],
                    "parent_point": [0.0, 0.0, 0.0] if i == 0 else PARENT_POINT, "child": b,
                    "child_point": CHILD_POINT, "variant": "ball", "k_r": [k[i]] * 3, "l_r": [l[i]] * 3, **joint}
                   for i, b in enumerate(names)],
        "initial_state": {b: {"theta": theta[i], "omega": omega[i]} for i, b in enumerate(names)},
        "simulation": {"t_end": t_end, "n_samples": n_samples, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def _mujoco(config, timestep=1e-4):
    """(model, data) of MuJoCo's two bodies on ball joints with the config's springs
    (``stiffness``: MuJoCo's ball spring, -k times the rotation vector of the turn from the
    reference) and dampers, at its initial state, RK4 at ``timestep`` [s]."""
    data = config.resolved
    bodies, joints = data["bodies"], data["joints"]

    def vec(x):
        return " ".join(repr(float(v)) for v in np.ravel(x))

    k = [float(np.ravel(j["k_r"])[0]) for j in joints]
    l = [float(np.ravel(j["l_r"])[0]) for j in joints]
    offset = np.asarray(PARENT_POINT) - np.asarray(CHILD_POINT)  # the second joint from the first's point
    xml = (f'<mujoco><option gravity="0 0 -9.81" timestep="{timestep}" integrator="RK4"/><worldbody>'
           f'<body name="b0"><joint type="ball" stiffness="{k[0]}" damping="{l[0]}"/>'
           f'<inertial pos="{vec(np.negative(CHILD_POINT))}" mass="{bodies[0]["mass"]}" diaginertia="{vec(INERTIA[0])}"/>'
           f'<body name="b1" pos="{vec(offset)}"><joint type="ball" stiffness="{k[1]}" damping="{l[1]}"/>'
           f'<inertial pos="{vec(np.negative(CHILD_POINT))}" mass="{bodies[1]["mass"]}" diaginertia="{vec(INERTIA[1])}"/>'
           "</body></body></worldbody></mujoco>")
    model = mujoco.MjModel.from_xml_string(xml)
    state = mujoco.MjData(model)
    a = [rotation_matrix(np.asarray(data["initial_state"][b]["theta"], dtype=float)) for b in ("b0", "b1")]
    omega = [np.asarray(data["initial_state"][b]["omega"], dtype=float) for b in ("b0", "b1")]
    for i, rel in enumerate((a[0], a[0].T @ a[1])):
        mujoco.mju_mat2Quat(state.qpos[4 * i: 4 * i + 4], rel.flatten())
    state.qvel[:3], state.qvel[3:] = omega[0], omega[1] - (a[0].T @ a[1]).T @ omega[0]
    return model, state


@pytest.mark.parametrize("theta, omega, locks", [
    ([[0.5, -0.4, 0.3], [0.8, 1.2, -0.5]], [[0.3, 2.0, -1.0], [-0.5, 3.0, 0.4]], False),  # tumbling
    ([[0.0, 0.0, 0.0], [1e-3, 1.3, 0.0]], [[0.0, 0.0, 0.0], [0.0, 8.0, 1e-3]], True),  # through theta_2 = pi/2
])
def test_a_tree_of_balls_moves_as_mujocos_through_the_euler_angles_gimbal_lock(theta, omega, locks):
    """Springs and dampers on two balls, tumbling, or the lower one turning through theta_2 =
    pi/2 of its relative Euler angles (where the same tree on Euler-angle balls, ``permanent``,
    stops at gimbal lock): every centre of mass follows MuJoCo's (RK4 at 1e-4 s) to 1e-6 m
    over 2 s and each reaction the force MuJoCo's body receives from its parent to 1e-6 of
    the largest; v falls with its analytic rate."""
    data = _balls([3.0, 2.0], [0.1, 0.05], theta, omega)
    config = config_from_mapping(data)
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    assert np.all(np.diff(result.outputs["lyapunov"]) <= 1e-10)
    for joint in data["joints"]:
        joint["variant"] = "permanent"
    euler = simulate(config_from_mapping(data))
    assert (euler.status == "failed" and "gimbal lock" in euler.message) == locks
    model, state = _mujoco(config)
    worst, forces = 0.0, []
    for s, t in enumerate(result.time):
        if s:
            mujoco.mj_step(model, state, nstep=int(round((t - result.time[s - 1]) / 1e-4)))
        mujoco.mj_forward(model, state)
        mujoco.mj_rnePostConstraint(model, state)
        worst = max(worst, float(np.abs(result.outputs["position"][s] - state.xipos[1:]).max()))
        forces.append(state.cfrc_int[1:, 3:].copy())
    forces = np.array(forces)
    assert worst < 1e-6
    assert np.abs(result.outputs["constraint_force"] - forces).max() < 1e-6 * np.abs(forces).max()


def test_an_anisotropic_ball_spring_about_a_reference_keeps_the_energy():
    """Without dampers, springs of three stiffnesses about a reference turn (and a passive
    spring about another) keep v constant to 1e-8 of its size as the bodies tumble, and
    Theta_j is the rotation vector of A_rel."""
    data = _balls([0.0, 0.0], [0.0, 0.0], [[0.5, -0.4, 0.3], [0.8, 1.2, -0.5]], [[0.3, 2.0, -1.0], [-0.5, 3.0, 0.4]],
                  n_samples=401)
    for joint, k, reference in zip(data["joints"], ([3.0, 5.0, 1.0], [2.0, 0.5, 4.0]), ([0.2, -0.1, 0.3], [0, 0.5, 0])):
        joint.update(k_r=k, theta_ref=reference, passive={"k_r": [1.0, 2.0, 0.5], "theta_ref": [-0.3, 0.0, 0.2]})
    result = simulate(config_from_mapping(data))
    assert result.status == "success"
    v = result.outputs["lyapunov"]
    assert np.max(np.abs(v - v[0])) < 1e-8 * abs(v[0])
    theta = result.outputs["theta"]
    rel = rotation_matrix(theta[-1, 0]).T @ rotation_matrix(theta[-1, 1])
    from scipy.spatial.transform import Rotation

    np.testing.assert_allclose(result.outputs["joint_theta"][-1, 1], Rotation.from_matrix(rel).as_rotvec(), atol=1e-9)


def test_a_ball_trees_eigenvalues_are_mujocos_in_the_tangent_directions():
    """``rbstab analyze`` of the tree at rest (isotropic springs balancing gravity about an
    offset joint point): 12 coordinates, each ball's rotation vector and Omega_j (not its 4
    quaternion entries), and the eigenvalues of MuJoCo's dynamics linearised by central
    differences in its tangent directions (``mj_integratePos``) there, to 1e-6 relative."""
    data = _balls([3.0, 2.0], [0.1, 0.05], [[0.0] * 3] * 2, [[0.0] * 3] * 2)
    config = config_from_mapping(data)
    analysis = analyze(config, certificate=False, simulate=False)
    assert analysis.layout.state_names()[:6] == [f"b0.joint_{b}_{i}" for b in ("theta", "omega") for i in (1, 2, 3)]
    lin = analysis.linearisation
    assert lin.is_rest_point and len(lin.eigenvalues) == 12
    model, state = _mujoco(config)
    rest = [lin.equilibrium[0:3], lin.equilibrium[6:9]]  # each ball's rotation vector at rest
    qpos = np.empty(8)
    for i, phi in enumerate(rest):
        mujoco.mju_axisAngle2Quat(qpos[4 * i: 4 * i + 4], phi / np.linalg.norm(phi), np.linalg.norm(phi))

    def acceleration(dq, qvel):
        state.qpos[:] = qpos
        mujoco.mj_integratePos(model, state.qpos, dq, 1.0)
        state.qvel[:] = qvel
        mujoco.mj_forward(model, state)
        return state.qacc.copy()

    n, step = model.nv, 1e-6
    jac = np.zeros((2 * n, 2 * n))
    jac[:n, n:] = np.eye(n)
    assert np.abs(acceleration(np.zeros(n), np.zeros(n))).max() < 1e-7
    for k in range(n):
        d = np.zeros(n)
        d[k] = step
        jac[n:, k] = (acceleration(d, 0 * d) - acceleration(-d, 0 * d)) / (2 * step)
        jac[n:, n + k] = (acceleration(0 * d, d) - acceleration(0 * d, -d)) / (2 * step)
    for s in np.linalg.eigvals(jac):
        assert np.min(np.abs(lin.eigenvalues - s)) <= 1e-6 * abs(s), (s, lin.eigenvalues)


def test_a_balls_cone_as_a_stop_keeps_the_energy_and_as_a_region_is_a_fall():
    """MJCF's ball range, a cone [0, upper] of the turn's angle: as an undamped stop the body
    swinging into it is pushed back with v constant to 1e-6 of its size (the stop's spring
    in v), its turn past the cone by a little; as an admissible region the run ends where the
    turn reaches the cone, named."""
    data = _balls([0.0, 0.0], [0.0, 0.0], [[0.0] * 3] * 2, [[2.0, 1.0, 0.5], [0.0] * 3], n_samples=2001)
    data["bodies"], data["joints"] = data["bodies"][:1], data["joints"][:1]
    data["initial_state"] = {"b0": data["initial_state"]["b0"]}
    data["joints"][0]["range"] = {"lower": 0.0, "upper": 0.3, "k_r": 400.0}
    stopped = simulate(config_from_mapping(data))
    turn = np.linalg.norm(stopped.outputs["joint_theta"][:, 0], axis=1)
    assert stopped.status == "success" and 0.3 < turn.max() < 0.45
    v = stopped.outputs["lyapunov"]
    assert np.max(np.abs(v - v[0])) < 1e-6 * abs(v[0])  # the steps across the stop's kink: 2e-7
    data["joints"][0]["range"] = {"lower": 0.0, "upper": 0.3, "kind": "region"}
    fell = simulate(config_from_mapping(data))
    assert fell.status == "failed" and "the turn of joint j0" in fell.message and "0.3 rad" in fell.message
    data["joints"][0]["theta_ref"] = [0.2, -0.2, 0.0]  # a reference inside the cone (its turn 0.28 rad), an entry < 0
    assert config_from_mapping(data).chain.joints[0].theta_ref[1] == -0.2


@pytest.mark.parametrize("change, key, expected", [
    (lambda d: d["joints"][0].update(range={"lower": -1.0, "upper": 1.0, "k_r": 10.0}), "joints.j0.range.lower",
     "a ball's range is a cone"),
    (lambda d: d["joints"][0].update(range={"lower": 0.0, "upper": [1.0, 1.0, 1.0], "k_r": 10.0}),
     "joints.j0.range.upper", "a ball's range is a cone"),
    (lambda d: d["joints"][0].update(k_r=3.0), "joints.j0.k_r", "3 numbers"),
    (lambda d: d["joints"][0].update(axis=[1, 0, 0]), "joints.j0.axis", "no axis"),
    (lambda d: d["joints"][0].update(theta_ref=[0.1, 0.2]), "joints.j0.theta_ref", "3 numbers"),
    (lambda d: d["joints"][0].update(theta_ref=[0.3, -0.3, 0.0], range={"lower": 0.0, "upper": 0.4, "k_r": 10.0}),
     "joints.j0.theta_ref", "the spring would be relaxed where the stop pushes back"),  # its turn 0.42 rad > 0.4
])
def test_a_balls_bad_input_is_refused_in_one_line_naming_its_key(change, key, expected):
    data = _balls([3.0, 2.0], [0.1, 0.05], [[0.0] * 3] * 2, [[0.0] * 3] * 2)
    change(data)
    with pytest.raises(ConfigError) as raised:
        config_from_mapping(data)
    message = str(raised.value).replace("joints.0.", "joints.j0.")
    assert key in message and expected in message, message


def test_a_balls_basin_stability_draws_its_relative_angular_velocity():
    """A ball's child takes ``initial_state.<body>.omega.<i>`` as a basin axis or a basin
    stability range: Omega_j (relative to its parent, child frame) set in the reduced state;
    each drawn run's initial Omega_j is the draw (joint_omega at t = 0); its Euler angles
    are refused in one line naming the keys allowed."""
    from rbstab.analysis.runs import Runs

    data = _balls([3.0, 2.0], [0.3, 0.2], [[0.0] * 3] * 2, [[0.0] * 3] * 2)
    config = config_from_mapping(data)
    analysis = analyze(config, certificate=False, simulate=False,
                       basin_stability={"ranges": ["initial_state.b1.omega.0=-2:2", "initial_state.b0.omega.2=-1:1"],
                                        "draws": 8})
    assert analysis.basin_stability is not None and len(analysis.basin_stability.values) == 8
    from rbstab.analysis.basin import BasinAxis

    axes = [BasinAxis.parse("initial_state.b1.omega.0=-2:2:3"), BasinAxis.parse("initial_state.b0.omega.2=-1:1:3")]
    states = Runs(config).states(axes, np.array([[1.5, -0.5]]))
    start = dict(data, initial_state={"b0": {"theta": states[0, :3].tolist(), "omega": states[0, 3:6].tolist()},
                                      "b1": {"theta": states[0, 12:15].tolist(), "omega": states[0, 15:18].tolist()}})
    result = simulate(config_from_mapping(start))
    np.testing.assert_allclose(result.outputs["joint_omega"][0, :, :], [[0.0, 0.0, -0.5], [1.5, 0.0, 0.0]], atol=1e-12)
    with pytest.raises(ValueError, match=r"initial_state.<b0\|b1>.omega.<0\|1\|2>"):
        analyze(config, certificate=False, simulate=False,
                basin_stability={"ranges": ["initial_state.b1.theta.0=-1:1"], "draws": 4})
