"""The slide (``variant: slide``, docs/physics.md "Joint kinds"): a row of the joint-kind table
whose child keeps its parent's orientation while its point C moves by q along an axis fixed in
the parent's frame, with the feedback -k (q - q_ref) - l dq/dt along the axis delivered between
asymmetric limits, a passive force of that form and a range (a stop or an admissible region).
Checked against MuJoCo (its slide joints), against v's own bookkeeping, and against the closed
form of a block on a spring."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from rbstab.config import ConfigError, config_from_mapping
from rbstab.simulator import simulate


def _cart_pole(t_end=2.0, n_samples=201):
    """A cart on an oblique slide to the ground (a spring about a reference, a damper), a pole
    on a hinge on it (a spring, a damper) and a block on a slide along the pole (a stiff spring
    about a reference), each joint's points off the centres of mass, released moving."""
    return {
        "name": "cart_pole", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "cart", "mass": 2.0, "inertia": [0.1, 0.2, 0.15]},
                   {"name": "pole", "mass": 0.5, "inertia": [0.05, 0.04, 0.01]},
                   {"name": "tip", "mass": 0.3, "inertia": [0.01, 0.02, 0.01]}],
        "joints": [{"name": "rail", "parent": "ground", "child": "cart", "variant": "slide", "axis": [1.0, 0.2, 0.1],
                    "parent_point": [0.1, 0.0, 0.3], "child_point": [0.0, 0.05, 0.1], "k_r": 3.0, "l_r": 0.5,
                    "theta_ref": 0.2},
                   {"name": "pin", "parent": "cart", "child": "pole", "variant": "hinge", "axis": [0.1, 1.0, 0.2],
                    "parent_point": [0.05, 0.0, 0.1], "child_point": [0.0, 0.02, -0.4], "k_r": 1.0, "l_r": 0.05},
                   {"name": "ext", "parent": "pole", "child": "tip", "variant": "slide", "axis": [0.2, -0.1, 1.0],
                    "parent_point": [0.0, 0.0, 0.3], "child_point": [0.02, 0.0, -0.1], "k_r": 20.0, "l_r": 0.3,
                    "theta_ref": 0.05}],
        "initial_state": {"cart": {"q": 0.3, "u": -0.2}, "pole": {"q": 0.4, "u": 0.5}, "tip": {"q": 0.1, "u": 0.3}},
        "simulation": {"t_end": t_end, "n_samples": n_samples, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def test_a_cart_pole_on_slides_moves_as_mujocos():
    """Two slides and a hinge as MuJoCo's slide and hinge joints: every centre of mass follows
    MuJoCo's (RK4 at 1e-4 s) to 1e-6 m over 2 s and each joint's reaction Lambda_j (a slide's
    with its spring's force along the axis) the force MuJoCo's body receives from its parent to
    1e-6 of the largest; a slide's E_j is q a (the ground's frame), its Theta_j, Omega_j and
    N_j zero; v falls with its analytic rate."""
    from test_hinge import _follow

    config = config_from_mapping(_cart_pole())
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    out = result.outputs
    a = np.array([1.0, 0.2, 0.1]) / np.linalg.norm([1.0, 0.2, 0.1])
    np.testing.assert_allclose(out["constraint_error"][0, 0], 0.3 * a, atol=1e-12)
    np.testing.assert_allclose(out["constraint_rate"][0, 0], -0.2 * a, atol=1e-12)
    for name in ("joint_theta", "joint_omega", "torque_n"):
        assert np.all(out[name][:, [0, 2]] == 0.0)
    assert np.all(np.diff(out["lyapunov"]) <= 1e-10)
    distance, reactions = _follow(config, result)
    assert distance < 1e-6 and reactions < 1e-6


def test_slide_servos_that_saturate_move_as_mujocos():
    """Each slide a passive spring and damper (never limited) and a servo toward its own
    target clipped to its own [lower, upper] N, which it reaches: MuJoCo's slides with
    ``position`` servos and their forceranges, to 1e-6 m; the limited force is flagged in
    ``constraint_force_saturated``'s first entry, no torque is."""
    from test_hinge import _follow

    data = _cart_pole(n_samples=10001)  # the numerical dv/dt across the kinks of the limits
    for joint in (data["joints"][0], data["joints"][2]):
        joint["passive"] = {"k_r": joint.pop("k_r"), "l_r": joint.pop("l_r"), "theta_ref": joint.pop("theta_ref")}
    data["joints"][0].update(k_r=40.0, l_r=5.0, theta_ref=-0.1, saturation={"torque_n": 6.0, "torque_n_lower": -2.0})
    data["joints"][2].update(k_r=30.0, l_r=0.1, theta_ref=0.2, saturation={"torque_n": 1.5})
    config = config_from_mapping(data)
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    flags = result.outputs["constraint_force_saturated"]
    assert flags[:, 0, 0].any() and flags[:, 2, 0].any() and not flags[:, :, 1:].any()
    assert not result.outputs["torque_n_saturated"][:, [0, 2]].any()
    assert max(_follow(config, result)) < 1e-6


def test_slides_among_every_other_kind_keep_the_energy_without_damping():
    """A free body held by a visco-elastic point law, a slide on it, a ball in Euler angles
    (``permanent``) on that and a slide at the end, springs everywhere and no damper: v is
    constant to 1e-9 of its size over 3 s (the slide's column, its Coriolis term under a
    turning parent and its spring's term of v, with the kinds around it)."""
    data = {
        "name": "mix", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "a", "mass": 1.5, "inertia": [0.1, 0.12, 0.05]},
                   {"name": "b", "mass": 0.7, "inertia": [0.02, 0.03, 0.01]},
                   {"name": "c", "mass": 0.4, "inertia": [0.01, 0.012, 0.004]},
                   {"name": "d", "mass": 0.3, "inertia": [0.01, 0.01, 0.004]}],
        "joints": [{"name": "ja", "parent": "ground", "child": "a", "variant": "visco_elastic", "k_c": [50, 50, 80],
                    "l_c": [0, 0, 0], "k_r": [2, 2, 2], "l_r": [0, 0, 0], "child_point": [0, 0, 0.3]},
                   {"name": "jb", "parent": "a", "child": "b", "variant": "slide", "axis": [0.3, 1.0, 0.2], "k_r": 40.0,
                    "parent_point": [0.1, 0, -0.2], "child_point": [0, 0.05, 0.1], "theta_ref": 0.05},
                   {"name": "jc", "parent": "b", "child": "c", "variant": "permanent", "k_r": [1, 1, 1],
                    "parent_point": [0, 0, -0.1], "child_point": [0, 0, 0.2]},
                   {"name": "jd", "parent": "c", "child": "d", "variant": "slide", "axis": [0, 0.2, 1.0], "k_r": 30.0,
                    "parent_point": [0, 0, -0.2], "child_point": [0.02, 0, 0.05]}],
        "initial_state": {"a": {"theta": [0.1, -0.2, 0.3], "omega": [0.5, 0.2, -0.3], "v": [0.1, 0.2, 0.0]},
                          "b": {"q": 0.1, "u": 0.5}, "c": {"theta": [0.3, 0.2, 0.1], "omega": [1.0, -0.5, 0.3]},
                          "d": {"q": -0.05, "u": 0.2}},
        "simulation": {"t_end": 3.0, "n_samples": 301, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }
    with pytest.warns(UserWarning, match="W002"):  # no damper: v is conserved, not strict
        result = simulate(config_from_mapping(data))
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    v = result.outputs["lyapunov"]
    assert np.max(np.abs(v - v[0])) < 1e-9 * abs(v[0])


def _block(**joint):
    """A block on a slide to the ground along an oblique axis, under gravity."""
    return {
        "name": "block", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "block", "mass": 2.0, "inertia": [0.1, 0.2, 0.15]}],
        "joints": [{"name": "rail", "parent": "ground", "child": "block", "variant": "slide", "axis": [0.3, 0.0, 1.0],
                    "child_point": [0.1, 0.0, 0.0], **joint}],
        "initial_state": {"block": {"q": 0.2, "u": 0.0}},
        "simulation": {"t_end": 3.0, "n_samples": 301, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def test_a_block_on_a_spring_rests_where_gravity_balances_it_and_rings_at_its_natural_frequency():
    """rbstab analyze of a block on a sprung slide: its rest q is q_ref + m (g . a) / k, its
    eigenvalues the roots of m s^2 + l s + k, and the certificate holds (its samples reach a
    slide's |q| = 1 m: no angle bounds the domain)."""
    from rbstab.analysis import analyze

    m, k, l, q_ref = 2.0, 400.0, 6.0, 0.1
    analysis = analyze(config_from_mapping(_block(k_r=k, l_r=l, theta_ref=q_ref)), samples=2000, simulate=False)
    a = np.array([0.3, 0.0, 1.0]) / math.hypot(0.3, 1.0)
    rest = q_ref + m * (-9.81 * a[2]) / k
    assert analysis.linearisation.equilibrium[0] == pytest.approx(rest, abs=1e-12)
    expected = np.roots([m, l, k])
    found = np.sort_complex(analysis.linearisation.eigenvalues)
    np.testing.assert_allclose(found, np.sort_complex(expected), rtol=1e-6)
    assert analysis.certificate.holds


def test_an_undamped_slides_stop_keeps_the_energy_and_its_region_is_a_fall():
    """An undamped stop at the slide's upper end pushes the block back with v constant (the
    stop's energy in v); the same range as an admissible region ends the run where q reaches
    its end, named in metres."""
    data = _block(k_r=50.0, range={"lower": -1.0, "upper": 0.25, "k_r": 5000.0})
    data["initial_state"]["block"]["u"] = 2.0
    stopped = simulate(config_from_mapping(data))
    assert stopped.status == "success"
    error = stopped.outputs["constraint_error"][:, 0] @ (np.array([0.3, 0.0, 1.0]) / math.hypot(0.3, 1.0))
    assert 0.25 < error.max() < 0.3
    v = stopped.outputs["lyapunov"]
    assert np.max(np.abs(v - v[0])) < 1e-7 * abs(v[0])
    data["joints"][0]["range"] = {"lower": -1.0, "upper": 0.25, "kind": "region"}
    fell = simulate(config_from_mapping(data))
    assert fell.status != "success"
    assert "the displacement q of joint rail reached its upper end 0.25 m" in fell.message


@pytest.mark.parametrize("change, key, expected", [
    (lambda d: d["joints"][0].pop("axis"), "joints.0.axis", "the slide's axis"),
    (lambda d: d["joints"][0].update(axis=[0, 0, 0]), "joints.0.axis", "zero length"),
    (lambda d: d["joints"][0].update(k_r=[1.0, 2.0, 3.0]), "joints.0.k_r", "a number"),
    (lambda d: d["joints"][0].update(l_r=-1.0), "joints.0.l_r", ">= 0"),
    (lambda d: d["joints"][0].update(saturation={"constraint_force": 3.0}), "joints.0.saturation.constraint_force",
     "saturation.torque_n"),
    (lambda d: d["initial_state"]["block"].update(q=[0.3, 0.1]), "initial_state.block.q", "slide's displacement"),
    (lambda d: d["initial_state"]["block"].update(x=[0.3, 0.1, 0.0]), "initial_state.block.x", "q (m) and u (m/s)"),
    (lambda d: d["joints"][0].update(range={"lower": 0.5, "upper": 0.2, "k_r": 10.0}), "joints.0.range.upper",
     "> lower"),
    (lambda d: d["joints"][0].update(range={"lower": -0.1, "upper": 0.25, "kind": "region"}),
     "initial_state.block.q", "[-0.1, 0.25]"),
])
def test_a_slides_bad_input_is_refused_in_one_line_naming_its_key(change, key, expected):
    data = _block(k_r=10.0, l_r=1.0, theta_ref=0.1)
    data["initial_state"]["block"]["q"] = 0.4
    change(data)
    with pytest.raises(ConfigError) as raised:
        config_from_mapping(data)
    message = str(raised.value)
    assert key in message.replace("joints.rail.", "joints.0.") and expected in message, message


def test_a_sweep_over_a_slides_numbers_gives_each_runs_own_result(tmp_path):
    """A grid over a slide's gain, reference and force limit and over its initial q gives each
    run the figures its own config gives; the sweep's dataset gives those parameters a
    slide's units."""
    import pandas as pd

    import rbstab

    from rbstab.sweep import run_sweep, spec_from_mapping

    data = _cart_pole(t_end=0.5, n_samples=11)
    data["joints"][0]["saturation"] = {"torque_n": 2.0}
    grid = {"joints.rail.k_r": [1.0, 4.0], "joints.rail.theta_ref": [0.0, 0.3],
            "joints.rail.saturation.torque_n": [0.05, 2.0], "initial_state.cart.q": [-0.4, 0.2]}
    run_sweep(spec_from_mapping({"name": "slides", "base": data, "grid": grid}), tmp_path, jobs=1, progress=False)
    index = pd.read_csv(tmp_path / "slides" / "index.csv")
    assert len(index) == 16 and set(index["status"]) == {"success"}
    dataset = rbstab.open_sweep(tmp_path / "slides")
    units = {dataset[name].attrs["config_key"]: dataset[name].attrs["units"] for name in dataset.coords
             if "config_key" in dataset[name].attrs}
    assert units == {"joints.rail.k_r": "N m-1", "joints.rail.theta_ref": "m", "joints.rail.saturation.torque_n": "N",
                     "initial_state.cart.q": "m"}
    columns = {key: next(c for c in index.columns if c.endswith(suffix)) for key, suffix in
               (("k", "k_r"), ("ref", "theta_ref"), ("limit", "torque_n"), ("q", "cart_q"))}
    for _, row in index.iloc[::5].iterrows():
        changed = copy.deepcopy(data)
        joint = changed["joints"][0]
        joint["k_r"], joint["theta_ref"] = float(row[columns["k"]]), float(row[columns["ref"]])
        joint["saturation"]["torque_n"] = float(row[columns["limit"]])
        changed["initial_state"]["cart"]["q"] = float(row[columns["q"]])
        alone = simulate(config_from_mapping(changed)).summary
        assert row["lyapunov_final"] == pytest.approx(alone["lyapunov_final"], rel=1e-12)
        final = [row[f"final_position_tip_{axis}"] for axis in "xyz"]
        np.testing.assert_allclose(final, np.asarray(alone["final_position"])[2], rtol=0, atol=1e-12)


def test_a_table_of_slide_runs_has_each_runs_own_records():
    """A table of runs over a slide's gain and reference (its limits, passive force and stop
    as written) gives each run the records compiling its own config gives, field by field."""
    from rbstab.engine.batch import batch_from_table
    from rbstab.variants import chain as C

    data = _cart_pole()
    data["joints"][0].update(saturation={"torque_n": 2.0, "torque_n_lower": -1.0},
                             passive={"k_r": 3.0, "l_r": 0.2, "theta_ref": 0.05},
                             range={"lower": -1.0, "upper": 1.0, "k_r": 100.0})
    columns = {"joints.rail.k_r": np.array([5.0, 7.0]), "joints.rail.theta_ref": np.array([0.1, 0.3])}
    batch = batch_from_table([config_from_mapping(data).resolved], list(columns), columns, np.zeros(2, dtype=np.int64))
    for run in range(2):
        changed = copy.deepcopy(data)
        changed["joints"][0].update(k_r=float(columns["joints.rail.k_r"][run]),
                                    theta_ref=float(columns["joints.rail.theta_ref"][run]))
        own = C.compile_chain(config_from_mapping(changed).chain).params
        for name in own.dtype.names:
            if name != "limits":
                np.testing.assert_array_equal(batch.params[run][name], own[name], err_msg=name)


def test_a_push_along_a_slide_gives_the_energy_of_its_joint_space_inertia():
    """A push P along the rail at the cart's centre of mass, a pole upright on a hinge across
    it: the push analysis's energy is 1/2 P^2 (M^-1)_11 of the cart-pole's joint-space mass
    matrix M = [[M_c + m, m l], [m l, J + m l^2]] (the pole's mass m, inertia J about its
    centre of mass, l its height over the hinge), and the work W its run receives."""
    from rbstab.analysis.push import Pushes

    cart, pole, inertia, height, push = 1.0, 0.2, 0.01, 0.4, 2.0
    data = {
        "name": "push_cart", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "cart", "mass": cart, "inertia": [0.01, 0.02, 0.02]},
                   {"name": "pole", "mass": pole, "inertia": [0.01, inertia, 0.001]}],
        "joints": [{"name": "rail", "parent": "ground", "child": "cart", "variant": "slide", "axis": [1, 0, 0],
                    "k_r": 20.0, "l_r": 4.0},
                   {"name": "pivot", "parent": "cart", "child": "pole", "variant": "hinge", "axis": [0, 1, 0],
                    "child_point": [0, 0, -height], "k_r": 8.0, "l_r": 1.0}],
        "initial_state": {"cart": {"q": 0.0, "u": 0.0}},
        "simulation": {"t_end": 0.1, "n_samples": 3},
    }
    config = config_from_mapping(data)
    pushes = Pushes(config, "force", body="cart", point=(0.0, 0.0, 0.0))
    energy = pushes.energy(np.array([[push, 0.0, 0.0]]))[0]
    mass = np.array([[cart + pole, pole * height], [pole * height, inertia + pole * height ** 2]])
    assert energy == pytest.approx(0.5 * push ** 2 * np.linalg.inv(mass)[0, 0], rel=1e-12)
    entry = {"kind": "impulse", "quantity": "force", "body": "cart", "value": [push, 0.0, 0.0], "start": 0.0}
    result = simulate(config_from_mapping({**pushes.config.resolved, "disturbances": [entry]}))
    assert energy == pytest.approx(result.outputs["disturbance_work"][0], rel=1e-12)


def test_a_cart_poles_energy_balance_under_pulses_and_an_impulse():
    """A pulse at the cart's side, an impulse on the tip and a torque pulse on the pole: v - W
    (W the disturbances' work) never rises (its rate is minus the dampers' dissipation; the
    impulse's jump of v is its W's), and the numerical dv/dt is the analytic one between the
    disturbances' edges."""
    data = _cart_pole(n_samples=2001)
    data["disturbances"] = [
        {"kind": "pulse", "body": "cart", "value": [3.0, 1.0, 0.5], "start": 0.3, "duration": 0.2,
         "point": [0.05, 0, 0]},
        {"kind": "impulse", "body": "tip", "value": [0.2, -0.3, 0.4], "start": 0.9},
        {"kind": "pulse", "body": "pole", "quantity": "torque", "value": [0.2, 0.1, -0.1], "start": 1.2,
         "duration": 0.3}]
    result = simulate(config_from_mapping(data))
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    v, work = result.outputs["lyapunov"], result.outputs["disturbance_work"]
    assert np.abs(work).max() > 0.5
    assert np.all(np.diff(v - work) <= 1e-9 * np.abs(v).max())
