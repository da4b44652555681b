"""The hinge joint (``variant: hinge``, docs/physics.md "Joint kinds"): a row of the joint-kind
table whose child is carried by one angle q about an axis a and its rate u (S = a), its
feedback -k (q - q_ref) - l u about a delivered between asymmetric limits, and a passive
torque of that form. Checked against MuJoCo's hinges (springs, dampers, springref, position
servos with a forcerange) on trees with oblique axes, against the ball joint it equals in
planar motion, against a closed-form balance, and against v's own bookkeeping."""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from rbstab.config import ConfigError, config_from_mapping, load_config
from rbstab.simulator import simulate
from rbstab.variants import chain as C

INERTIA = [0.08, 0.07, 0.02]  # kg m^2, about each body's centre of mass
CHILD_POINT = [0.0, 0.02, 0.5]  # m: each joint's point C, above the body's centre of mass
PARENT_POINT = [0.05, 0.0, -0.5]  # m: where the next body hangs, below the parent's centre of mass
AXES = [[1.0, 0.3, -0.2], [0.2, 1.0, 0.5], [-0.4, 0.1, 1.0]]  # not unit: normalised by the loader


def _hinges(k, l, q_ref, q0, u0, t_end=2.0, n_samples=11):
    """Three bodies hanging from the ground on hinges about the oblique ``AXES``, joint i
    with spring ``k[i]``, damper ``l[i]`` and reference ``q_ref[i]``, released at q0, u0."""
    names = [f"b{i}" for i in range(3)]
    return {
        "name": "hinges", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": b, "mass": 1.0 + 0.2 * i, "inertia": INERTIA} for i, b in enumerate(names)],
        "joints": [{"name": f"j{i}", "parent": "ground" if i == 0 else names[i - 1],
                    "parent_point": [0.0, 0.0, 0.0] if i == 0 else PARENT_POINT, "child": b,
                    "child_point": CHILD_POINT, "variant": "hinge", "axis": AXES[i], "k_r": k[i], "l_r": l[i],
                    "theta_ref": q_ref[i]} for i, b in enumerate(names)],
        "initial_state": {b: {"q": q0[i], "u": u0[i]} for i, b in enumerate(names)},
        "simulation": {"t_end": t_end, "n_samples": n_samples, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def _follow(config, result, dt=1e-4):
    """The largest distance [m] between rbstab's centres of mass at the samples of
    ``result`` and MuJoCo's (:func:`reference_mujoco.hinge_tree` of ``config``, RK4 at ``dt``),
    and the largest difference of rbstab's joint reactions Lambda_j from the force each
    MuJoCo body receives from its parent (``cfrc_int``'s linear part) over the largest of those."""
    mujoco = pytest.importorskip("mujoco")
    from reference_mujoco import hinge_tree

    model, state, qpos0, qvel0 = hinge_tree(config, dt)
    state.qpos[:], state.qvel[:] = qpos0, qvel0
    worst, forces = 0.0, []
    for s, t in enumerate(result.time):
        if s:
            mujoco.mj_step(model, state, nstep=int(round((t - result.time[s - 1]) / dt)))
        mujoco.mj_forward(model, state)
        mujoco.mj_rnePostConstraint(model, state)
        worst = max(worst, float(np.abs(result.outputs["position"][s] - state.xipos[1:]).max()))
        forces.append(state.cfrc_int[1:, 3:].copy())
    forces = np.array(forces)
    return worst, float(np.abs(result.outputs["constraint_force"] - forces).max() / np.abs(forces).max())


def test_a_tree_of_oblique_hinges_moves_as_mujocos():
    """Springs, dampers and reference angles about three oblique axes, under gravity: every
    centre of mass follows MuJoCo's (RK4 at 1e-4 s) to 1e-6 m over 2 s and each joint's
    reaction Lambda_j the force MuJoCo's body receives from its parent to 1e-6 of the
    largest, each joint's Theta_j is q a and Omega_j is a dq/dt, and v falls with its
    analytic rate."""
    k, l, q_ref, q0, u0 = [3.0, 2.0, 1.0], [0.1, 0.2, 0.05], [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, 0.0, -0.5]
    config = config_from_mapping(_hinges(k, l, q_ref, q0, u0, n_samples=2001))
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    out = result.outputs
    axes = np.array(AXES) / np.linalg.norm(AXES, axis=1, keepdims=True)
    np.testing.assert_allclose(out["joint_theta"][0], np.array(q0)[:, None] * axes, atol=1e-12)
    np.testing.assert_allclose(out["joint_omega"][0], np.array(u0)[:, None] * axes, atol=1e-12)
    assert np.all(np.diff(out["lyapunov"]) <= 1e-10)
    distance, reactions = _follow(config, result)
    assert distance < 1e-6 and reactions < 1e-6


@pytest.mark.parametrize("lower, upper", [(-0.6, 0.6), (-0.3, 1.2)])
def test_hinge_servos_that_saturate_move_as_mujocos(lower, upper):
    """Each joint a ligament (passive spring and damper, never limited) and a muscle (a
    feedback toward its own target, clipped to [lower, upper] N m about the oblique axis,
    which it reaches): MuJoCo's hinges with a ``position`` servo's kv and forcerange, to
    1e-6 m; the saturation flags mark the axis components of a limited hinge together."""
    k, l, q_ref, q0, u0 = [1.0, 0.5, 0.3], [0.05, 0.05, 0.02], [0.1, 0.0, -0.2], [0.6, -0.5, 0.7], [0.0, 1.0, 0.0]
    servos = [(0, 6.0, 0.4, -0.3, lower, upper), (1, 4.0, 0.3, 0.4, lower, upper)]
    data = _hinges([0.0] * 3, [0.0] * 3, [0.0] * 3, q0, u0, n_samples=2001)
    for joint, kk, ll, ref in zip(data["joints"], k, l, q_ref):
        joint["passive"] = {"k_r": kk, "l_r": ll, "theta_ref": ref}
    for j, kp, kv, target, lo, hi in servos:
        data["joints"][j].update(k_r=kp, l_r=kv, theta_ref=target, saturation={"torque_n": hi, "torque_n_lower": lo})
    config = config_from_mapping(data)
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    flags = result.outputs["torque_n_saturated"]
    assert flags[:, :2].any() and not flags[:, 2].any()
    assert np.all(flags[:, :2] == flags[:, :2, :1])  # every component of a hinge's torque at once
    assert max(_follow(config, result)) < 1e-6


def _planar_twins():
    """Three rods on hinges about x (springs, dampers, references, gravity) released in the
    y-z plane, and the same rods on ball joints with isotropic gains released there too
    (whose motion stays there): two config mappings."""
    hinges = _hinges([4.0, 2.0, 1.0], [0.3, 0.2, 0.1], [0.2, -0.1, 0.0], [0.4, -0.3, 0.2], [0.5, 0.0, -0.2],
                     n_samples=51)
    balls = copy.deepcopy(hinges)
    for joint in (*hinges["joints"], *balls["joints"]):
        joint["axis"], joint["child_point"] = [2.0, 0.0, 0.0], [0.0, 0.0, 0.5]
        joint["parent_point"] = joint["parent_point"] if joint["parent"] == "ground" else [0.0, 0.0, -0.5]
    angles = np.cumsum([s["q"] for s in hinges["initial_state"].values()])
    rates = np.cumsum([s["u"] for s in hinges["initial_state"].values()])
    for joint in balls["joints"]:
        joint.pop("axis")
        joint.update(variant="permanent", k_r=[joint["k_r"]] * 3, l_r=[joint["l_r"]] * 3,
                     theta_ref=[joint["theta_ref"], 0.0, 0.0])
    balls["initial_state"] = {b: {"theta": [float(a), 0.0, 0.0], "omega": [float(w), 0.0, 0.0]}
                              for b, a, w in zip(hinges["initial_state"], angles, rates)}
    return hinges, balls


def test_a_hinge_is_the_ball_it_equals_in_planar_motion():
    """Rods on hinges about x move as the same rods on ball joints with isotropic gains
    released in the y-z plane: the same centres of mass, joint angles, torques and v."""
    hinges, balls = _planar_twins()
    one, other = simulate(config_from_mapping(hinges)), simulate(config_from_mapping(balls))
    for key in ("position", "velocity", "joint_theta", "joint_omega", "torque_n", "lyapunov", "lyapunov_rate"):
        scale = max(1.0, float(np.abs(other.outputs[key]).max()))
        np.testing.assert_allclose(one.outputs[key], other.outputs[key], rtol=0, atol=1e-8 * scale, err_msg=key)


def test_a_hanging_rod_on_a_hinge_rests_where_its_spring_balances_gravity():
    """One rod on a hinge about x, its spring relaxed at q_ref: the rest state is the root of
    k (q - q_ref) + m g d sin(q) = 0 (d = 0.5 m to its centre of mass), v is zero there, and
    a damped run settles on it; undamped, v stays constant."""
    k, q_ref, m, g, d = 4.0, 1.1, 1.0, 9.81, 0.5
    data = _hinges([k] * 3, [2.0] * 3, [q_ref] * 3, [0.0] * 3, [0.0] * 3, t_end=30.0, n_samples=301)
    data["bodies"], data["joints"] = data["bodies"][:1], data["joints"][:1]
    data["bodies"][0]["mass"] = m
    data["joints"][0].update(axis=[1.0, 0.0, 0.0], child_point=[0.0, 0.0, d])
    data["initial_state"] = {"b0": {"q": 0.0}}
    balance = brentq(lambda q: k * (q - q_ref) + m * g * d * math.sin(q), 0.0, q_ref)
    config = config_from_mapping(data)
    compiled = C.compile_chain(config.chain)
    y, _ = C.rest_state(compiled)
    assert C.rest_coordinates(compiled, y) == pytest.approx([balance], abs=1e-9)
    assert C.lyapunov(compiled, y)[0] == pytest.approx(0.0, abs=1e-12)
    result = simulate(config)
    np.testing.assert_allclose(result.outputs["joint_theta"][-1, 0], [balance, 0.0, 0.0], atol=1e-6)
    assert result.outputs["lyapunov"][-1] == pytest.approx(0.0, abs=1e-9)
    data["joints"][0]["l_r"] = 0.0
    undamped = simulate(config_from_mapping(data)).outputs
    assert np.ptp(undamped["lyapunov"]) < 1e-8 * np.abs(undamped["lyapunov_rotational"]).max()


def test_a_spring_wound_past_half_a_turn_keeps_its_energy_in_the_files():
    """A wheel on a hinge about the vertical with a soft spring, spun up to wind it about
    5.7 rad (no singular angle; q is continued from sample to sample): the outputs' q
    passes pi without a jump and v stays constant, as its undamped run must."""
    data = _hinges([0.0] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3, t_end=1.0, n_samples=201)
    data["bodies"], data["joints"] = data["bodies"][:1], data["joints"][:1]
    data["joints"][0].update(axis=[0.0, 0.0, 1.0], k_r=1.0, child_point=[0.0, 0.0, 0.0])
    data["initial_state"] = {"b0": {"q": 0.0, "u": 40.0}}
    result = simulate(config_from_mapping(data))
    out = result.outputs
    q = out["joint_theta"][:, 0, 2]
    amplitude = 40.0 * math.sqrt(INERTIA[2] / 1.0)  # u0 / omega_n
    assert amplitude * (1 - 1e-3) < q.max() <= amplitude * (1 + 1e-9) and q.max() > math.pi + 2.0
    assert np.abs(np.diff(q)).max() < 0.3
    assert np.ptp(out["lyapunov"]) < 1e-9 * out["lyapunov"].max()
    assert result.summary["lyapunov_rate_check"] == "pass"


def _rod_on_a_stop(stop, q0=0.0, u0=0.0, t_end=2.0, n_samples=2001):
    """One rod (1 kg, its centre of mass 0.5 m below its hinge about x) with no feedback and
    the range ``stop`` ({lower, upper, k_r, l_r})."""
    data = _hinges([0.0] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3, t_end=t_end, n_samples=n_samples)
    data["bodies"], data["joints"] = data["bodies"][:1], data["joints"][:1]
    data["bodies"][0]["mass"] = 1.0
    data["joints"][0].update(axis=[1.0, 0.0, 0.0], child_point=[0.0, 0.0, 0.5], range=stop)
    data["initial_state"] = {"b0": {"q": q0, "u": u0}}
    return data


def test_a_swinging_rod_bounces_off_an_undamped_stop_keeping_its_energy():
    """Released from -1.2 rad, the rod swings through the bottom into its range's upper end
    at 0.6 rad, where the stop's spring (5,000 N m/rad) turns it back: q passes the end by
    about sqrt(2 E / k) and no more, and v (gravity's and the stop's energy) stays constant."""
    result = simulate(config_from_mapping(_rod_on_a_stop({"lower": -2.0, "upper": 0.6, "k_r": 5000.0}, q0=-1.2)))
    out = result.outputs
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    q = out["joint_theta"][:, 0, 0]
    energy = 9.81 * 0.5 * (math.cos(0.6) - math.cos(1.2))  # kinetic energy [J] at the stop's end
    assert 0.6 < q.max() < 0.6 + 1.05 * math.sqrt(2.0 * energy / 5000.0)
    assert q.max() > 0.6 + 0.9 * math.sqrt(2.0 * energy / 5000.0)
    assert q[-1] < 0.6 and np.ptp(out["lyapunov"]) < 1e-7 * np.abs(out["lyapunov"]).max()


def test_a_rod_rests_on_its_stop_where_the_stop_balances_gravity():
    """The range [0.5, 1] keeps the rod from hanging straight: its rest state is the root of
    k (q - 0.5) + m g d sin(q) = 0 just below the lower end, v is zero there, and a run
    released inside the range with a damped stop settles on it, v never rising."""
    stop = {"lower": 0.5, "upper": 1.0, "k_r": 200.0, "l_r": 5.0}
    balance = brentq(lambda q: 200.0 * (q - 0.5) + 9.81 * 0.5 * math.sin(q), 0.0, 0.5)
    config = config_from_mapping(_rod_on_a_stop(stop, q0=0.8, t_end=10.0, n_samples=1001))
    compiled = C.compile_chain(config.chain)
    y, _ = C.rest_state(compiled)
    assert C.rest_coordinates(compiled, y) == pytest.approx([balance], abs=1e-9)
    assert C.lyapunov(compiled, y)[0] == pytest.approx(0.0, abs=1e-12)
    out = simulate(config).outputs
    assert out["joint_theta"][-1, 0, 0] == pytest.approx(balance, abs=1e-6)
    assert np.all(np.diff(out["lyapunov"]) <= 1e-9)


def test_a_run_that_leaves_a_range_that_is_an_admissible_region_stops_there_on_every_engine():
    """The middle hinge's range [-0.6, 0.1] as an admissible region (``kind: region``): no
    torque acts inside it (the samples before the stop are the unbounded run's, bit for
    bit), and the run stops, fell, where q reaches 0.1 (the unbounded run's crossing, by its
    dense output), on the compiled driver and on scipy's methods alike, naming the joint and
    the end."""
    from rbstab.engine.integrate import integrate_chain_runs
    from rbstab.engine.settings import settings_rows
    from rbstab.engine.status import fell, range_status
    from rbstab.engine.systems import tree_system
    from rbstab.variants.tree import reduce_state, tree_layout

    data = _hinges([3.0, 2.0, 1.0], [0.1, 0.2, 0.05], [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, 0.0, -0.5], t_end=3.0,
                   n_samples=301)
    free = simulate(config_from_mapping(data))
    data["joints"][1]["range"] = {"lower": -0.6, "upper": 0.1, "kind": "region"}
    config = config_from_mapping(data)
    compiled = C.compile_chain(config.chain)
    system, layout = tree_system(compiled), tree_layout(compiled)
    y0 = reduce_state(compiled, layout, C.initial_state(config))[None]
    ends = integrate_chain_runs(system, y0, settings_rows([config.simulation]), method="DOP853", n_samples=2)
    assert ends.status.tolist() == [range_status(1, 0, True)]
    t_stop = float(ends.t_stop[0])
    axis = np.array(AXES[1]) / np.linalg.norm(AXES[1])
    data["simulation"].update(t_end=t_stop, n_samples=2)
    del data["joints"][1]["range"]
    assert simulate(config_from_mapping(data)).outputs["joint_theta"][-1, 1] @ axis == pytest.approx(0.1, abs=1e-9)
    for method in ("DOP853", "RK45", "Radau"):
        result = simulate(dataclasses.replace(config, simulation=dataclasses.replace(config.simulation,
                                                                                        method=method)))
        assert fell(result.status, result.message), result.message
        assert result.message.startswith("left the admissible region (joints.j1.range): the angle q of joint j1 "
                                         "reached its upper end 0.1 rad at t = "), result.message
        assert float(result.message.rsplit("t = ", 1)[1].split()[0]) == pytest.approx(t_stop, abs=1e-5)
        kept = ~np.isnan(result.outputs["lyapunov"])
        assert kept.sum() == 1 + int(t_stop / 0.01)
        if method == "DOP853":
            np.testing.assert_array_equal(result.outputs["position"][kept], free.outputs["position"][kept])


def test_a_run_that_falls_before_its_second_sample_counts_its_rising_time_on_the_grid():
    """A pulse that pushes v up from t = 0 and a range left at 5 ms, before the second sample
    (0.01 s): the one sample kept, rising, counts one sample spacing, as the GPU's streamed
    summary counts it."""
    data = _hinges([3.0, 2.0, 1.0], [0.0] * 3, [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, -1.0, -0.5], t_end=1.0,
                   n_samples=101)
    data["joints"][1]["range"] = {"lower": -0.405, "upper": 0.5, "kind": "region"}
    data["disturbances"] = [{"kind": "pulse", "quantity": "torque", "value": [-5.0, 0.0, 0.0], "start": 0.0,
                             "duration": 1.0, "body": "b2"}]
    result = simulate(config_from_mapping(data))
    assert result.message.startswith("left the admissible region (joints.j1.range)")
    assert result.outputs["lyapunov_rate"][0] > 0.0 and np.isnan(result.outputs["lyapunov_rate"][1])
    assert result.summary["time_lyapunov_rising"] == pytest.approx(0.01, rel=1e-12)


@pytest.mark.parametrize("quantity, value", [("force", [0.0, 2.0, 1.0]), ("torque", [0.3, -0.2, 0.1])])
def test_a_push_on_a_tree_of_hinges_is_the_limit_of_short_pulses(quantity, value):
    """An impulse on the lowest body of the oblique hinges (undamped, under gravity) makes
    the generalised velocities jump by M^-1 S' P: v jumps by its energy and v - W stays
    constant, and the motion after it is that after a pulse of the same impulse over 1e-5 s
    (to its O(duration) difference)."""
    base = _hinges([3.0, 2.0, 1.0], [0.0] * 3, [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, 0.0, -0.5], t_end=0.6,
                   n_samples=61)
    push = {"body": "b2", "kind": "impulse", "quantity": quantity, "value": value, "start": 0.2,
            **({"point": [0.0, 0.05, -0.1]} if quantity == "force" else {})}
    result = simulate(config_from_mapping({**base, "disturbances": [push]}))
    out = result.outputs
    assert result.status == "success"
    balance = out["lyapunov"] - out["disturbance_work"]
    assert np.ptp(balance) < 1e-8 * np.abs(out["lyapunov"]).max()
    assert out["disturbance_work"][-1] != 0.0
    duration = 1e-5
    pulse = {**push, "kind": "pulse", "duration": duration, "value": [x / duration for x in value]}
    pulsed = simulate(config_from_mapping({**base, "disturbances": [pulse]})).outputs
    np.testing.assert_allclose(out["position"][-1], pulsed["position"][-1], atol=1e-4)
    np.testing.assert_allclose(out["joint_omega"][-1], pulsed["joint_omega"][-1], atol=1e-3)
    assert np.abs(out["position"][-1] - simulate(config_from_mapping(base)).outputs["position"][-1]).max() > 1e-2


def test_a_hinge_sweep_gives_each_runs_own_result(tmp_path):
    """A sweep over a hinge's gain and its child's initial angle (the bodies it carries turn
    with it) gives each run the figures its own config gives."""
    import pandas as pd

    from rbstab.sweep import run_sweep, spec_from_mapping

    data = _hinges([3.0, 2.0, 1.0], [0.1, 0.2, 0.05], [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, 0.0, -0.5],
                   n_samples=21)
    grid = {"joints.j1.k_r": [1.0, 4.0], "initial_state.b0.q": [0.1, -0.6]}
    run_sweep(spec_from_mapping({"name": "hinges", "base": data, "grid": grid}), tmp_path, jobs=1, progress=False)
    index = pd.read_csv(tmp_path / "hinges" / "index.csv")
    assert len(index) == 4 and set(index["status"]) == {"success"}
    for _, row in index.iterrows():
        changed = copy.deepcopy(data)
        changed["joints"][1]["k_r"] = float(row["j1_k_r"])
        changed["initial_state"]["b0"]["q"] = float(row["b0_q"])
        alone = simulate(config_from_mapping(changed)).summary
        assert row["lyapunov_final"] == pytest.approx(alone["lyapunov_final"], rel=1e-12)
        final = [row[f"final_position_b2_{axis}"] for axis in "xyz"]
        np.testing.assert_allclose(final, np.asarray(alone["final_position"])[2], rtol=0, atol=1e-12)


def test_a_sweep_over_a_regions_end_gives_each_run_its_own_fall(tmp_path):
    """A sweep over the upper end of a hinge's range that is an admissible region: each
    run falls where its own config falls, or reaches t_end, as that config run alone."""
    import pandas as pd

    from rbstab.sweep import run_sweep, spec_from_mapping

    data = _hinges([3.0, 2.0, 1.0], [0.1, 0.2, 0.05], [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, 0.0, -0.5],
                   n_samples=21)
    data["joints"][1]["range"] = {"lower": -0.6, "upper": 0.1, "kind": "region"}
    grid = {"joints.j1.range.upper": [0.05, 0.1, 2.0]}
    run_sweep(spec_from_mapping({"name": "ranged", "base": data, "grid": grid}), tmp_path, jobs=1, progress=False)
    index = pd.read_csv(tmp_path / "ranged" / "index.csv")
    assert sorted(index["status"]) == ["failed", "failed", "success"]
    for _, row in index.iterrows():
        changed = copy.deepcopy(data)
        changed["joints"][1]["range"]["upper"] = float(row["j1_upper"])
        alone = simulate(config_from_mapping(changed))
        assert (row["status"], row["message"]) == (alone.status, alone.message)


def test_the_hinged_stance_example_comes_back_upright_and_a_deep_lean_falls():
    """configs/examples/stance_hinges.yaml (ankle, knee and hip hinges, its ankle stronger
    toward the toes): from its lean it comes back upright as MuJoCo's model of it does (to
    1e-6 m), v never rising; pushed forward at the trunk from quiet stance (13 N s, its
    ankle at its limit) it comes back; leaning 0.3 rad
    forward, further than the ankle's 120 N m can hold (m g h sin 0.3 = 194 N m), it leaves
    the admissible region: a fall reads as a fall."""
    example = "configs/examples/stance_hinges.yaml"
    config = load_config(example, ["simulation.t_end=3", "simulation.n_samples=3001"])
    result = simulate(config)
    out = result.outputs
    assert max(_follow(config, result)) < 1e-6  # MuJoCo's hinges and clamped servos
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    assert np.all(np.diff(out["lyapunov"]) <= 1e-9) and out["lyapunov"][-1] < 1e-3 * out["lyapunov"][0]
    assert np.abs(out["joint_theta"][-1]).max() < 2e-3
    pushed = simulate(load_config(example, [
        "simulation.t_end=6", "initial_state.shanks.q=0", "initial_state.trunk.q=0",
        "disturbances=[{kind: impulse, body: trunk, value: [0, -13, 0], point: [0, 0, 0.2], start: 0.5}]"]))
    assert pushed.status == "success" and np.abs(pushed.outputs["joint_theta"][-1]).max() < 1e-2  # a push from quiet
    assert pushed.outputs["disturbance_work"][-1] > 0.0 and pushed.outputs["torque_n_saturated"][:, 0, 0].any()
    deep = simulate(load_config(example, ["simulation.t_end=3", "initial_state.shanks.q=0.3"]))
    assert deep.status == "failed" and "left the admissible region" in deep.message
    assert deep.outputs["torque_n_saturated"][:, 0, 0].any()  # the ankle at its limit toward the toes


@pytest.mark.parametrize("change, key, expected", [
    (lambda d: d["joints"][1].update(axis=[0, 0, 0]), "joints.1.axis", "zero length"),
    (lambda d: d["joints"][1].pop("axis"), "joints.1.axis", "missing"),
    (lambda d: d["joints"][1].update(k_r=[1.0, 2.0, 3.0]), "joints.1.k_r", "a number"),
    (lambda d: d["joints"][1].update(k_r=-1.0), "joints.1.k_r", ">= 0"),
    (lambda d: d["joints"][1].update(theta_ref=[0.1, 0.0, 0.0]), "joints.1.theta_ref", "a number"),
    (lambda d: d["joints"][1].update(saturation={"torque_n": [1.0, 1.0, 1.0]}), "joints.1.saturation.torque_n",
     "a number"),
    (lambda d: d["joints"][1].update(variant="permanent", k_r=2.0), "joints.1.axis", "no axis"),
    (lambda d: d["joints"][1].update(variant="permanent", k_r=2.0) or d["joints"][1].pop("axis"),
     "joints.1.k_r", "a single number is a hinge's"),
    (lambda d: d["initial_state"]["b1"].update(theta=[0.1, 0.0, 0.0]), "initial_state.b1.theta", "a hinge's child"),
    (lambda d: d["initial_state"]["b1"].update(q=4.0), "initial_state.b1.q", "(-pi, pi)"),
    (lambda d: d["joints"][1].update(range={"lower": 0.5, "upper": 0.2, "k_r": 100.0}), "joints.1.range.upper",
     "> lower"),
    (lambda d: d["joints"][1].update(range={"lower": 0.0, "upper": 0.2, "k_r": 0.0}), "joints.1.range.k_r", "> 0"),
    (lambda d: d["joints"][1].update(range={"lower": 0.0, "upper": 0.2, "k_r": 100.0}), "joints.1.theta_ref",
     "in the range [0, 0.2]"),
    (lambda d: d["joints"][1].update(variant="visco_elastic", k_r=[2.0] * 3, l_r=[0.1] * 3, theta_ref=[0.0] * 3,
                                     k_c=[10.0] * 3, l_c=[1.0] * 3, range={"lower": 0.0, "upper": 0.2, "k_r": 100.0})
     or d["joints"][1].pop("axis"), "joints.1.range", "a range is a hinge's (of its angle q), a universal"),
    (lambda d: d["joints"][1].update(range={"lower": [0.0] * 3, "upper": 0.2, "k_r": 100.0}), "joints.1.range.lower",
     "a number: a hinge's range is of its angle q"),
    (lambda d: d["joints"][1].update(variant="permanent", k_r=[2.0] * 3, l_r=[0.1] * 3, theta_ref=[0.0, 0.3, 0.0],
                                     range={"lower": [-1, -0.2, -1], "upper": [1, 0.2, 1], "kind": "region"})
     or d["joints"][1].pop("axis"), "joints.1.theta_ref", "in the range theta_1 in [-1, 1], theta_2 in [-0.2, 0.2]"),
    (lambda d: d["joints"][1].update(range={"lower": -0.6, "upper": 0.2}), "joints.1.range.k_r", "required by a stop"),
    (lambda d: d["joints"][1].update(range={"lower": -0.6, "upper": 0.2, "kind": "region", "l_r": 1.0}),
     "joints.1.range.l_r", "no l_r"),
    (lambda d: d["joints"][1].update(range={"lower": -0.6, "upper": 0.2, "kind": "wall"}), "joints.1.range.kind",
     "region"),
    (lambda d: d["joints"][1].update(range={"lower": -0.35, "upper": 0.2, "kind": "region"}), "initial_state.b1.q",
     "joints.j1.range [-0.35, 0.2]"),
])
def test_a_hinges_bad_input_is_refused_in_one_line_naming_its_key(change, key, expected):
    data = _hinges([3.0, 2.0, 1.0], [0.1, 0.2, 0.05], [0.2, -0.3, 0.4], [0.5, -0.4, 0.8], [0.3, 0.0, -0.5])
    change(data)
    with pytest.raises(ConfigError) as raised:
        config_from_mapping(data)
    message = str(raised.value)
    assert key in message.replace("joints.j1.", "joints.1.") and expected in message, message


def test_a_ball_jointed_body_has_no_hinge_angle():
    data = _hinges([3.0] * 3, [0.1] * 3, [0.0] * 3, [0.0] * 3, [0.0] * 3)
    data["joints"][2].update(variant="permanent", k_r=[1.0] * 3, l_r=[0.1] * 3, theta_ref=[0.0] * 3)
    data["joints"][2].pop("axis")
    with pytest.raises(ConfigError, match="initial_state.b2.q.*not a hinge's child"):
        config_from_mapping(data)
    data["initial_state"]["b2"] = {"theta": [0.1, 0.2, 0.0]}
    assert simulate(config_from_mapping(data)).status == "success"  # hinges and a ball in one tree


def test_a_hinge_trees_linearisation_is_its_ball_twins_in_plane():
    """rbstab analyze of a hinge tree, linearised in its q and u: the rest state's joint
    angles are the ball twin's (whose linearisation is in the bodies' Euler angles, another
    formulation), and each of its 6 eigenvalues is one of the twin's 18 (the in-plane modes,
    which decouple at a planar rest state) to 1e-7 relative; the modes are shown on q."""
    from rbstab.analysis import analyze

    hinges, balls = (config_from_mapping(data) for data in _planar_twins())
    one = analyze(hinges, certificate=False, simulate=False)
    other = analyze(balls, certificate=False, simulate=False)
    assert one.layout.state_names() == ["b0.q", "b0.u", "b1.q", "b1.u", "b2.q", "b2.u"]
    rest = one.linearisation.equilibrium[::2]
    absolute = other.layout.split(other.linearisation.equilibrium)["theta"][:, 0]
    np.testing.assert_allclose(np.cumsum(rest), absolute, rtol=0, atol=1e-9)
    assert abs(rest[0] - 0.2) > 1e-3  # gravity bends it off its references
    assert len(one.linearisation.eigenvalues) == 6 and len(other.linearisation.eigenvalues) == 18
    for s in one.linearisation.eigenvalues:
        assert np.min(np.abs(other.linearisation.eigenvalues - s)) <= 1e-7 * abs(s)
    assert one.verdict == other.verdict == "asymptotically stable"
    assert [m["shape"].keys() for m in one.as_dict()["modes"]][0] == {"b0.q", "b1.q", "b2.q"}


def test_a_hinge_trees_certificate_holds_where_its_runs_converge():
    """The Lyapunov certificate of three rods on hinges, in q and u: v positive definite,
    its analytic dv/dt the derivative of v along the reduced rate at the samples (to 1e-6 of
    the power scale), its estimate bounded by the domain (a hinge's |q| at pi/2 -
    gimbal_margin), and runs from states on the level set {v = c} (written as each hinge's
    initial q and u, through the config) stay inside {v <= c} and come back."""
    from rbstab.analysis import analyze
    from rbstab.analysis.certificate import ChainModel, level_states
    from rbstab.variants import chain as C

    data = _planar_twins()[0]
    data["simulation"].update(t_end=30.0, n_samples=301)
    config = config_from_mapping(data)
    analysis = analyze(config, samples=500, falsification_runs=0, simulate=False)
    c = analysis.certificate
    assert c.positive_definite and 0 < c.sublevel < np.inf and c.sublevel_bound == "domain boundary"
    assert c.rate_mismatch < 1e-6
    model = ChainModel(C.compile_chain(config.chain))
    names = analysis.layout.state_names()
    for z in level_states(model, analysis.linearisation, c, 4, seed=3):
        start = {name.split(".")[0]: {} for name in names}
        for name, value in zip(names, z):
            body, block = name.split(".")
            start[body][block] = float(value)
        result = simulate(config_from_mapping({**data, "initial_state": start}))
        v = result.outputs["lyapunov"]
        assert result.status == "success" and v[0] == pytest.approx(c.sublevel, rel=1e-6)
        assert v.max() <= v[0] * (1 + 1e-9) and v[-1] < 0.5 * v[0]  # its slowest mode: tau 110 s


def test_a_hinged_stances_smallest_fatal_push_is_where_its_plain_runs_start_to_fall():
    """The push analysis of the hinged stance (a push backward on the trunk, from the rest
    state written as each hinge's q, u): a plain run with that impulse 2 % weaker comes back,
    2 % stronger leaves the admissible region (a fall), and the push estimate of the
    certificate lies below it."""
    from rbstab.analysis import analyze
    from rbstab.analysis.basin import time_to_converge

    config = load_config("configs/examples/stance_hinges.yaml", ["simulation.n_samples=501"])
    push = {"kind": "force", "body": "trunk", "point": (0.0, 0.0, 0.2), "directions": [(0.0, 1.0, 0.0)]}
    analysis = analyze(config, push=push, samples=500, falsification_runs=0, simulate=False)
    threshold = float(analysis.push.thresholds.threshold[0])
    assert 1.0 < threshold < 30.0
    for scale, falls in ((0.98, False), (1.02, True)):
        entry = {"kind": "impulse", "quantity": "force", "body": "trunk", "value": [0.0, scale * threshold, 0.0],
                 "point": [0.0, 0.0, 0.2], "start": 0.0}
        data = {**config.resolved, "initial_state": {}, "disturbances": [entry],
                "simulation": {**config.resolved["simulation"], "t_end": 15.0, "n_samples": 301}}
        result = simulate(config_from_mapping(data))
        assert (result.status == "failed" and "left the admissible region" in result.message) is falls
        if not falls:
            v = result.outputs["lyapunov"]
            assert v[-1] < 1e-3 * v[1]
    assert analysis.push.estimate(analysis.certificate.sublevel) < threshold


def test_a_pushs_energy_on_a_hinge_tree_is_the_jump_its_run_takes():
    """The push analysis's energy of a push on the hinged stance's trunk at rest is the work
    W the run with that impulse receives at t = 0 (its generalised velocities' jump, the
    hinges' impulsive reactions keeping them hinges), not a free body's."""
    from rbstab.analysis.push import Pushes

    config = load_config("configs/examples/stance_hinges.yaml", ["simulation.t_end=0.1", "simulation.n_samples=3"])
    pushes = Pushes(config, "force", body="trunk", point=(0.0, 0.0, 0.2))
    energy = pushes.energy(np.array([[0.0, 10.0, 0.0]]))[0]
    entry = {"kind": "impulse", "quantity": "force", "body": "trunk", "value": [0.0, 10.0, 0.0],
             "point": [0.0, 0.0, 0.2], "start": 0.0}
    result = simulate(config_from_mapping({**pushes.config.resolved, "disturbances": [entry]}))
    assert energy == pytest.approx(result.outputs["disturbance_work"][0], rel=1e-12)
    assert energy < 10.0 ** 2 / (2 * 47.46) + 0.2 ** 2 * 10.0 ** 2 / (2 * 2.97)  # the trunk alone, free: more


def test_a_hinge_trees_analysis_says_what_it_leaves_out():
    """A basin axis or a basin-stability range that is not a hinge's q or u is refused in one
    line naming the keys allowed."""
    from rbstab.analysis import analyze

    hinges = config_from_mapping(_planar_twins()[0])
    with pytest.raises(ValueError, match=r"initial_state.<b0\|b1\|b2>.<q\|u>"):
        analyze(hinges, certificate=False, simulate=False,
                basin_stability={"ranges": ["initial_state.b0.omega.0=-1:1"], "draws": 4})
    with pytest.raises(ValueError, match="maps its basin over its hinges', slides' and universal joints' q and u"):
        analyze(hinges, certificate=False, simulate=False,
                basin=["initial_state.b0.theta.0=-0.1:0.1:3", "initial_state.b1.q=-0.1:0.1:3"])


def test_a_hinge_trees_basin_map_is_its_plain_runs():
    """The basin map of the hinged stance over the shanks' lean q and the trunk's rate u: at
    every point v(0) and the outcome (converged, not converged, failed: left the admissible
    region) are those of the plain run from that initial state written as q and u."""
    from rbstab.analysis import analyze
    from rbstab.analysis.basin import time_to_converge

    config = load_config("configs/examples/stance_hinges.yaml", ["simulation.n_samples=501"])
    axes = ["initial_state.shanks.q=-0.1:0.1:3", "initial_state.trunk.u=-1:1:3"]
    basin = analyze(config, certificate=False, simulate=False, basin=axes).basin
    assert [a.label for a in basin.axes] == ["shanks q [rad]", "trunk u [rad s-1]"]
    assert set(basin.outcome.ravel()) == {0, 1, 2}
    for i, q in enumerate(basin.axes[0].values):
        for j, u in enumerate(basin.axes[1].values):
            start = copy.deepcopy(config.resolved["initial_state"])
            start["shanks"]["q"], start["trunk"]["u"] = float(q), float(u)
            result = simulate(config_from_mapping({**config.resolved, "initial_state": start}))
            v = result.outputs["lyapunov"]
            assert v[0] == pytest.approx(basin.lyapunov_initial[i, j], rel=1e-12)
            if result.status == "failed":
                assert basin.outcome[i, j] == 2 and "left the admissible region" in result.message
            else:
                converged = np.isfinite(time_to_converge(result.time, v, basin.ratio))
                assert basin.outcome[i, j] == (0 if converged else 1)


def test_a_hinge_trees_basin_stability_counts_its_plain_runs():
    """Basin stability of the hinged stance over the shanks' lean q and the trunk's rate u:
    each draw recovers exactly where the plain run from that initial state (written as q and
    u), long enough for its slowest mode (30 s; a draw still settling at t_end is judged at
    a longer one), converges by the sweeps' rule."""
    from rbstab.analysis import analyze
    from rbstab.convergence import converged

    config = load_config("configs/examples/stance_hinges.yaml", ["simulation.n_samples=501"])
    ranges = ["initial_state.shanks.q=-0.1:0.1", "initial_state.trunk.u=-1:1"]
    stability = analyze(config, certificate=False, simulate=False,
                        basin_stability={"ranges": ranges, "draws": 12, "seed": 2}).basin_stability
    assert 0 < stability.recovered.sum() < 12
    for (q, u), recovered in zip(stability.values, stability.recovered):
        start = copy.deepcopy(config.resolved["initial_state"])
        start["shanks"]["q"], start["trunk"]["u"] = float(q), float(u)
        simulation = {**config.resolved["simulation"], "t_end": 30.0, "n_samples": 3001}
        result = simulate(config_from_mapping({**config.resolved, "initial_state": start, "simulation": simulation}))
        v = result.outputs["lyapunov"]
        plain = converged(result.status == "success", v[0], v[-1],
                          max_increase=result.summary["max_lyapunov_increase"])
        assert bool(recovered) == bool(plain)


def test_an_animation_draws_each_hinges_axis_through_its_point(tmp_path):
    """The animation of three rods on oblique hinges: each hinge's axis is drawn through its
    point as A_c a (a fixed in the child's frame), which is also A_p a (the rotation about a
    leaves it); a tree of balls draws none."""
    from click.testing import CliRunner

    from rbstab.report.animate import _figure, pick_run, scene
    from rbstab_cli.main import cli

    out = tmp_path / "results"
    data = _hinges([4.0, 2.0, 1.0], [0.3, 0.2, 0.1], [0.2, -0.1, 0.0], [0.4, -0.3, 0.2], [0.5, 0.0, -0.2],
                   n_samples=21)
    path = tmp_path / "hinges.yaml"
    import yaml

    path.write_text(yaml.safe_dump(data))
    assert CliRunner().invoke(cli, ["run", str(path), "-o", str(out)]).exit_code == 0
    sc = scene(pick_run(out / "hinges.h5"), n_frames=5)
    axes = np.array(AXES) / np.linalg.norm(AXES, axis=1, keepdims=True)
    np.testing.assert_allclose(sc.hinge_axis, np.einsum("kiab,ib->kia", sc.rotation, axes), atol=1e-12)
    for j, parent in enumerate([-1, 0, 1]):  # the axis the parent's frame holds: A_p a
        held = np.broadcast_to(axes[j], (5, 3)) if parent < 0 else np.einsum("kab,b->ka", sc.rotation[:, parent],
                                                                              axes[j])
        np.testing.assert_allclose(sc.hinge_axis[:, j], held, atol=1e-3)  # frames interpolated from samples
    fig = _figure(sc, (-60.0, 20.0), (6.0, 5.0), 60)[0]
    assert "hinge axes" in [line.get_label() for line in fig.axes[0].get_lines()]
    result = CliRunner().invoke(cli, ["animate", str(out / "hinges.h5"), "-o", str(tmp_path / "a.png")])
    assert result.exit_code == 0, result.output


def test_the_whole_bodys_centre_of_mass_moves_under_gravity_and_the_ground_reaction():
    """The hinged stance swaying back to upright: the whole-body centre of mass X_com is
    sum m_i X_i / sum m_i, its velocity V_com is dX_com/dt (central differences), and
    Newton's law for the whole body holds with the ankle's reaction as the only force
    besides gravity: M dV_com/dt = M g + Lambda_ankle; the summary's COM excursion and peak
    sway are X_com's largest distances from its start."""
    config = load_config("configs/examples/stance_hinges.yaml", ["simulation.t_end=2", "simulation.n_samples=8001"])
    result = simulate(config)
    out, dt = result.outputs, float(result.time[1] - result.time[0])
    mass = np.array([b["mass"] for b in config.resolved["bodies"]])
    com = out["com_position"]
    np.testing.assert_allclose(com, np.einsum("n,mnc->mc", mass, out["position"]) / mass.sum(), atol=1e-14)
    np.testing.assert_allclose(out["com_velocity"][1:-1], (com[2:] - com[:-2]) / (2 * dt), atol=1e-5)
    acceleration = (out["com_velocity"][2:] - out["com_velocity"][:-2]) / (2 * dt)
    gravity = np.array([0.0, 0.0, -9.81])
    newton = mass.sum() * (acceleration - gravity)
    ankle = out["constraint_force"][1:-1, 0]
    kinks = np.abs(np.diff(out["torque_n_saturated"][:, 0, 0]))  # the clipped ankle: the rate jumps there
    smooth = np.convolve(kinks, np.ones(4), mode="same")[:-1] == 0
    np.testing.assert_allclose(newton[smooth], ankle[smooth], atol=1e-3 * np.abs(ankle).max())
    assert np.ptp(ankle[:, 1]) > 10.0  # the ground's horizontal push moves
    drift = np.linalg.norm(com - com[0], axis=1)
    assert result.summary["com_excursion"] == pytest.approx(drift.max(), rel=1e-12)
    assert result.summary["peak_sway"] == pytest.approx(np.linalg.norm((com - com[0])[:, :2], axis=1).max(), rel=1e-12)
