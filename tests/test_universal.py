"""The universal joint (``variant: universal``, docs/physics.md "Joint kinds"): a row of the
joint-kind table whose child turns by q_1 about the axis a_1 (the parent's frame), then by q_2
about a_2 (the child's frame), A_rel = exp(q_1 [a_1]x) exp(q_2 [a_2]x), with the motion subspace
S = (exp(-q_2 [a_2]x) a_1, a_2), its feedback -k_i (q_i - q_ref_i) - l_i dq_i/dt on each
coordinate delivered between asymmetric limits, and a passive torque of that form. Checked
against MuJoCo (a body with two hinges), against v's own bookkeeping, and through q_2 = pi/2,
where Euler angles would lock."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from rbstab.config import ConfigError, config_from_mapping
from rbstab.simulator import simulate

INERTIA = [0.08, 0.07, 0.02]  # kg m^2, about each body's centre of mass
CHILD_POINT = [0.0, 0.02, 0.5]  # m: each joint's point C, above the body's centre of mass
PARENT_POINT = [0.05, 0.0, -0.5]  # m: where the next body hangs, below the parent's centre of mass
AXES = [[[1.0, 0.3, -0.2], [0.2, 1.0, 0.5]], [-0.4, 0.1, 1.0], [[0.0, 1.0, 0.0], [1.0, 0.0, 0.4]]]


def _tree(q0, u0, t_end=2.0, n_samples=2001):
    """A universal joint to the ground (oblique axes, not orthogonal), a hinge, then a
    universal joint, each with a spring, a damper and a reference posture, released at q0, u0."""
    names = ["b0", "b1", "b2"]
    gains = [([3.0, 2.0], [0.1, 0.2], [0.2, -0.3]), (1.0, 0.05, 0.4), ([2.0, 1.5], [0.05, 0.1], [-0.1, 0.3])]
    return {
        "name": "universal", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": b, "mass": 1.0 + 0.2 * i, "inertia": INERTIA} for i, b in enumerate(names)],
        "joints": [{"name": f"j{i}", "parent": "ground" if i == 0 else names[i - 1],
                    "parent_point": [0.0, 0.0, 0.0] if i == 0 else PARENT_POINT, "child": b,
                    "child_point": CHILD_POINT, "variant": "hinge" if i == 1 else "universal", "axis": AXES[i],
                    "k_r": gains[i][0], "l_r": gains[i][1], "theta_ref": gains[i][2]} for i, b in enumerate(names)],
        "initial_state": {b: {"q": q0[i], "u": u0[i]} for i, b in enumerate(names)},
        "simulation": {"t_end": t_end, "n_samples": n_samples, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def _columns(axes, q_2):
    """(s_1, s_2) of a universal joint: Omega_j = s_1 u_1 + s_2 u_2 (child frame)."""
    a_1, a_2 = (np.asarray(a, dtype=float) / np.linalg.norm(a) for a in axes)
    k = np.array([[0.0, -a_2[2], a_2[1]], [a_2[2], 0.0, -a_2[0]], [-a_2[1], a_2[0], 0.0]])
    turn = np.eye(3) + np.sin(q_2) * k + (1.0 - np.cos(q_2)) * k @ k
    return turn.T @ a_1, a_2


def test_a_tree_with_universal_joints_moves_as_mujocos():
    """Universal joints as MuJoCo's bodies with two hinges: every centre of mass follows
    MuJoCo's (RK4 at 1e-4 s) to 1e-6 m over 2 s, each joint's reaction the force MuJoCo's
    body receives from its parent to 1e-6 of the largest; a universal joint's Theta_j is
    (q_1, q_2, 0) and its Omega_j is s_1 u_1 + s_2 u_2; v falls with its analytic rate."""
    from test_hinge import _follow

    q0, u0 = [[0.5, -0.4], 0.8, [0.3, 0.9]], [[0.3, 0.0], -0.5, [-0.4, 0.6]]
    config = config_from_mapping(_tree(q0, u0))
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    out = result.outputs
    np.testing.assert_allclose(out["joint_theta"][0, 0], [0.5, -0.4, 0.0], atol=1e-12)
    s_1, s_2 = _columns(AXES[0], -0.4)
    np.testing.assert_allclose(out["joint_omega"][0, 0], 0.3 * s_1 + 0.0 * s_2, atol=1e-12)
    assert np.all(np.diff(out["lyapunov"]) <= 1e-10)
    distance, reactions = _follow(config, result)
    assert distance < 1e-6 and reactions < 1e-6


def test_universal_servos_that_saturate_move_as_mujocos():
    """Each universal joint a ligament per coordinate (a passive spring and damper, never
    limited) and a muscle per coordinate (a servo toward its target clipped to its own
    [lower, upper] N m, which it reaches): MuJoCo's hinges with ``position`` servos and their
    forceranges, to 1e-6 m; the saturation flags mark the coordinates that reach a limit."""
    from test_hinge import _follow

    data = _tree([[0.6, -0.5], 0.7, [0.4, -0.3]], [[0.0, 1.0], 0.0, [1.0, 0.0]])
    for joint in data["joints"]:
        universal = joint["variant"] == "universal"
        joint["passive"] = {"k_r": joint.pop("k_r"), "l_r": joint.pop("l_r"), "theta_ref": joint.pop("theta_ref")}
        joint.update(k_r=[6.0, 4.0] if universal else 5.0, l_r=[0.4, 0.3] if universal else 0.2,
                     theta_ref=[-0.3, 0.4] if universal else 0.1)
        joint["saturation"] = ({"torque_n": [0.6, 1.2], "torque_n_lower": [-0.3, -0.6]} if universal
                               else {"torque_n": 0.8})
    config = config_from_mapping(data)
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    flags = result.outputs["torque_n_saturated"]
    assert flags[:, 0, :2].any() and not flags[:, 0, 2].any()
    assert max(_follow(config, result)) < 1e-6


def test_a_universal_joint_turns_through_a_right_angle_keeping_its_energy():
    """Without dampers a swinging body on a universal joint passes q_2 = +-pi/2 (where a
    ball's Euler angles would lock) with v constant to 1e-8 of its size, and its coordinates
    are continued past pi."""
    data = _tree([[0.0, 1.4], 0.0, [0.0, 0.0]], [[2.0, 3.0], 0.0, [0.0, 0.0]], t_end=3.0)
    data["bodies"], data["joints"] = data["bodies"][:1], data["joints"][:1]
    data["initial_state"] = {"b0": data["initial_state"]["b0"]}
    data["joints"][0].update(axis=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], l_r=0.0, k_r=[1.0, 0.5], theta_ref=0.0)
    result = simulate(config_from_mapping(data))
    assert result.status == "success"
    q = result.outputs["joint_theta"][:, 0]
    assert np.max(np.abs(q[:, 1])) > np.pi / 2
    v = result.outputs["lyapunov"]
    assert np.max(np.abs(v - v[0])) < 1e-8 * abs(v[0])


def test_a_universal_joints_stop_keeps_the_energy_and_its_region_is_a_fall():
    """An undamped stop on q_2 pushes back with v constant (its spring's energy in v); the
    same range as an admissible region ends the run where q_2 reaches the end, named."""
    data = _tree([[0.0, 0.0], 0.0, [0.0, 0.0]], [[0.0, 2.0], 0.0, [0.0, 0.0]], t_end=2.0)
    data["bodies"], data["joints"] = data["bodies"][:1], data["joints"][:1]
    data["initial_state"] = {"b0": data["initial_state"]["b0"]}
    data["joints"][0].update(l_r=0.0, theta_ref=0.0, range={"lower": -1.0, "upper": [1.0, 0.2], "k_r": [0.0001, 200.0]})
    stopped = simulate(config_from_mapping(data))
    q = stopped.outputs["joint_theta"][:, 0]
    assert stopped.status == "success" and np.max(q[:, 1]) > 0.2 and np.max(q[:, 1]) < 0.5
    v = stopped.outputs["lyapunov"]
    assert np.max(np.abs(v - v[0])) < 1e-7 * abs(v[0])
    data["joints"][0]["range"] = {"lower": -1.0, "upper": [1.0, 0.2], "kind": "region"}
    fell = simulate(config_from_mapping(data))
    assert fell.status != "success"
    assert "the angle q_2 of joint j0 reached its upper end 0.2 rad" in fell.message


@pytest.mark.parametrize("change, key, expected", [
    (lambda d: d["joints"][0].update(axis=[[1, 0, 0], [2, 0, 0]]), "joints.0.axis", "parallel"),
    (lambda d: d["joints"][0].update(axis=[1, 0, 0]), "joints.0.axis", "2 lists of 3 numbers"),
    (lambda d: d["joints"][0].update(k_r=[1.0, 2.0, 3.0]), "joints.0.k_r", "2 numbers"),
    (lambda d: d["joints"][0].update(l_r=[-1.0, 2.0]), "joints.0.l_r", ">= 0"),
    (lambda d: d["joints"][1].update(k_r=[1.0, 2.0]), "joints.1.k_r", "a number"),
    (lambda d: d["initial_state"]["b0"].update(q=0.3), "initial_state.b0.q", "2 numbers"),
    (lambda d: d["initial_state"]["b0"].update(q=[0.3, 4.0]), "initial_state.b0.q", "(-pi, pi)"),
    (lambda d: d["joints"][0].update(range={"lower": [0.0, 0.5], "upper": 0.2, "k_r": 10.0}),
     "joints.0.range.upper", "> lower"),
    (lambda d: d["joints"][0].update(range={"lower": -0.1, "upper": 0.25, "k_r": 10.0}), "joints.0.theta_ref",
     "q_1 in [-0.1, 0.25], q_2 in [-0.1, 0.25]"),
    (lambda d: d["joints"][0].update(range={"lower": -1.0, "upper": [1.0, 0.2], "kind": "region"}),
     "initial_state.b0.q", "q_2 in [-1, 0.2]"),
])
def test_a_universal_joints_bad_input_is_refused_in_one_line_naming_its_key(change, key, expected):
    data = _tree([[0.5, 0.4], 0.8, [0.3, 0.9]], [[0.3, 0.0], -0.5, [-0.4, 0.6]])
    data["joints"][0]["theta_ref"] = [0.2, -0.3] if key != "joints.0.theta_ref" else [0.3, 0.0]
    change(data)
    with pytest.raises(ConfigError) as raised:
        config_from_mapping(data)
    message = str(raised.value)
    assert key in message.replace("joints.j0.", "joints.0.").replace("joints.j1.", "joints.1.") and expected in message, \
        message


def test_a_sweep_over_a_universal_joints_numbers_gives_each_runs_own_result(tmp_path):
    """A grid over one coordinate's gain, reference and limit and over the initial q_2 gives
    each run the figures its own config gives (q_2 turns the bodies the joint carries)."""
    import pandas as pd

    from rbstab.sweep import run_sweep, spec_from_mapping

    data = _tree([[0.5, -0.4], 0.8, [0.3, 0.9]], [[0.3, 0.0], -0.5, [-0.4, 0.6]], t_end=0.5, n_samples=11)
    data["joints"][0]["saturation"] = {"torque_n": [2.0, 3.0]}
    grid = {"joints.j0.k_r.1": [1.0, 4.0], "joints.j0.theta_ref.0": [0.0, 0.3],
            "joints.j0.saturation.torque_n.0": [0.05, 2.0], "initial_state.b0.q.1": [-0.4, 0.2]}
    run_sweep(spec_from_mapping({"name": "universal", "base": data, "grid": grid}), tmp_path, jobs=1, progress=False)
    index = pd.read_csv(tmp_path / "universal" / "index.csv")
    assert len(index) == 16 and set(index["status"]) == {"success"}
    columns = {key: next(c for c in index.columns if c.endswith(suffix)) for key, suffix in
               (("k", "k_r_1"), ("ref", "theta_ref_0"), ("limit", "torque_n_0"), ("q", "q_1"))}
    for _, row in index.iloc[::5].iterrows():
        changed = copy.deepcopy(data)
        joint = changed["joints"][0]
        joint["k_r"], joint["theta_ref"] = [3.0, float(row[columns["k"]])], [float(row[columns["ref"]]), -0.3]
        joint["saturation"]["torque_n"] = [float(row[columns["limit"]]), 3.0]
        changed["initial_state"]["b0"]["q"] = [0.5, float(row[columns["q"]])]
        alone = simulate(config_from_mapping(changed)).summary
        assert row["lyapunov_final"] == pytest.approx(alone["lyapunov_final"], rel=1e-12)
        final = [row[f"final_position_b2_{axis}"] for axis in "xyz"]
        np.testing.assert_allclose(final, np.asarray(alone["final_position"])[2], rtol=0, atol=1e-12)
