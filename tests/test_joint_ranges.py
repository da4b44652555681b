"""A ball joint's range (``variant: permanent``, ``range`` of its Euler angles Theta_j): a
stop on each angle (a one-sided spring and damper, N_s = B(Theta_j)' f, docs/physics.md
"Joint kinds") and an admissible region (a run that leaves it fell). Checked against the
hinge it equals in planar motion (its stop and region), against v's own bookkeeping in
motion off the plane, and on every engine."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from rbstab.config import ConfigError, config_from_mapping
from rbstab.engine.status import fell
from rbstab.simulator import simulate

from test_hinge import _planar_twins


def _with_ranges(hinges, balls, joint, lower, upper, **law):
    """The planar twins with joint ``joint``'s range [lower, upper] about x (the hinge's q,
    the ball's theta_1; the ball's theta_2, theta_3 within +-1 rad) and the range's ``law``
    (``k_r``, ``l_r``; or ``kind: region``)."""
    hinges, balls = copy.deepcopy(hinges), copy.deepcopy(balls)
    hinges["joints"][joint]["range"] = {"lower": lower, "upper": upper, **law}
    balls["joints"][joint]["range"] = {"lower": [lower, -1.0, -1.0], "upper": [upper, 1.0, 1.0], **law}
    return hinges, balls


def test_a_ball_meets_its_stop_in_planar_motion_as_the_hinge_does():
    """The middle rods' stop at [-0.35, 0.1] rad about x (stiff, damped), reached in the
    swing: the ball's motion, torques and v are the hinge's."""
    hinges, balls = _with_ranges(*_planar_twins(), 1, -0.35, 0.1, k_r=300.0, l_r=3.0)
    one, other = simulate(config_from_mapping(hinges)), simulate(config_from_mapping(balls))
    assert one.status == other.status == "success"
    q = one.outputs["joint_theta"][:, 1, 0]
    assert q.max() > 0.1 or q.min() < -0.35  # the stop acts
    for key in ("position", "joint_theta", "torque_n", "lyapunov", "lyapunov_rate"):
        scale = max(1.0, float(np.abs(other.outputs[key]).max()))
        np.testing.assert_allclose(one.outputs[key], other.outputs[key], rtol=0, atol=1e-8 * scale, err_msg=key)


def test_a_ball_leaves_its_region_in_planar_motion_where_the_hinge_does():
    """The middle rods' range [-0.5, 0.05] about x as an admissible region: both runs fall
    at the same time, each naming its joint's coordinate and end."""
    hinges, balls = _with_ranges(*_planar_twins(), 1, -0.5, 0.05, kind="region")
    one, other = simulate(config_from_mapping(hinges)), simulate(config_from_mapping(balls))
    assert fell(one.status, one.message) and fell(other.status, other.message)
    assert "the angle q of joint j1 reached its upper end 0.05 rad" in one.message
    assert "theta_1 of joint j1's Euler angles Theta_j reached its upper end 0.05 rad" in other.message
    t_one, t_other = (float(r.message.rsplit("t = ", 1)[1].split()[0]) for r in (one, other))
    assert t_one == pytest.approx(t_other, abs=1e-6)


def _spinning_rod(stop, t_end=3.0):
    """One rod on a ball joint to the ground (no feedback, under gravity), released turning
    about all three axes, with the range ``stop`` of its Euler angles."""
    return {
        "name": "rod", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "rod", "mass": 1.0, "inertia": [0.08, 0.07, 0.02]}],
        "joints": [{"name": "ball", "parent": "ground", "parent_point": [0.0, 0.0, 0.0], "child": "rod",
                    "child_point": [0.0, 0.02, 0.5], "variant": "permanent", "k_r": [0.0] * 3, "l_r": [0.0] * 3,
                    "range": stop}],
        "initial_state": {"rod": {"theta": [0.1, -0.05, 0.2], "omega": [1.5, -1.0, 2.0]}},
        "simulation": {"t_end": t_end, "n_samples": 3001, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def test_an_undamped_stop_of_each_euler_angle_keeps_v_constant_off_the_plane():
    """A spinning rod hanging on a ball joint that reaches the stops of its first two Euler
    angles (their torques B' e_i f_i along B's rows): v (kinetic, gravity's and the stops'
    energy) stays constant; with damping it never rises, and falls by the integral of its
    analytic rate -sum l_i (dtheta_i/dt)^2 (to the trapezoid's error across the stops' ends,
    where the damping force jumps: 0.2 % at 0.1 ms samples, 1st order)."""
    stop = {"lower": [-0.3, -0.2, -np.inf], "upper": [0.3, 0.2, np.inf], "k_r": [400.0, 300.0, 100.0]}
    result = simulate(config_from_mapping(_spinning_rod(stop)))
    theta = result.outputs["joint_theta"][:, 0]
    assert result.status == "success"
    assert theta[:, 0].max() > 0.3 and theta[:, 1].min() < -0.2  # both stops act
    v = result.outputs["lyapunov"]
    assert np.ptp(v) < 1e-7 * np.abs(v).max()
    data = _spinning_rod({**stop, "l_r": [4.0, 4.0, 0.0]})
    data["simulation"]["n_samples"] = 30001
    damped = simulate(config_from_mapping(data))
    v, rate = damped.outputs["lyapunov"], damped.outputs["lyapunov_rate"]
    assert np.all(np.diff(v) <= 1e-9) and v[-1] < v[0] - 0.1
    dissipated = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(damped.time)))
    assert dissipated == pytest.approx(v[-1] - v[0], rel=5e-3)


def test_a_ball_region_on_every_engine_and_a_start_outside_it_refused():
    """A spinning rod whose theta_2 reaches -0.16 rad, its range's lower end -0.15 as a region:
    the compiled driver and scipy's methods stop there, naming theta_2; a rod that would
    start outside the region is refused, naming its initial_state key."""
    data = _spinning_rod({"lower": [-1.0, -0.15, -np.inf], "upper": [1.0, 0.2, np.inf], "kind": "region"})
    config = config_from_mapping(data)
    times = []
    for method in ("DOP853", "RK45", "Radau"):
        result = simulate(dataclasses.replace(config, simulation=dataclasses.replace(config.simulation,
                                                                                        method=method)))
        assert fell(result.status, result.message), result.message
        assert "theta_2 of joint ball's Euler angles Theta_j reached its lower end -0.15 rad" in result.message
        times.append(float(result.message.rsplit("t = ", 1)[1].split()[0]))
    assert max(times) - min(times) < 1e-5
    data["initial_state"]["rod"]["theta"] = [0.1, -0.25, 0.2]
    with pytest.raises(ConfigError, match=r"initial_state.rod.theta.*joints.ball.range"):
        config_from_mapping(data)


def test_a_sweep_over_a_ball_ranges_entries_gives_each_run_its_own_result(tmp_path):
    """A sweep over one end of a ball's region (``range.upper.0``) and its stop's stiffness
    elsewhere: each run's status, message and final v are its config's run alone."""
    import pandas as pd

    from rbstab.sweep import run_sweep, spec_from_mapping

    hinges, balls = _with_ranges(*_planar_twins(), 1, -0.5, 0.05, kind="region")
    balls["joints"][2]["range"] = {"lower": [-0.1, -1.0, -1.0], "upper": [0.1, 1.0, 1.0], "k_r": 300.0, "l_r": 3.0}
    grid = {"joints.j1.range.upper.0": [0.05, 1.0], "joints.j2.range.k_r": [100.0, 300.0]}
    run_sweep(spec_from_mapping({"name": "balls", "base": balls, "grid": grid}), tmp_path, jobs=1, progress=False)
    index = pd.read_csv(tmp_path / "balls" / "index.csv")
    assert len(index) == 4 and sorted(set(index["status"])) == ["failed", "success"]
    upper = next(c for c in index.columns if c.startswith("j1_") and "upper" in c)
    stiffness = next(c for c in index.columns if c.startswith("j2_"))
    for _, row in index.iterrows():
        changed = copy.deepcopy(balls)
        changed["joints"][1]["range"]["upper"][0] = float(row[upper])
        changed["joints"][2]["range"]["k_r"] = float(row[stiffness])
        alone = simulate(config_from_mapping(changed))
        assert (row["status"], row["message"]) == (alone.status, alone.message)
        assert row["lyapunov_final"] == pytest.approx(alone.summary["lyapunov_final"], rel=1e-12)
