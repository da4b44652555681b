"""The admissible region (``simulation.limits``): a run that leaves it stops there, failed,
its message naming the bound and the time, located on the interpolant by every engine.

The crossing times are computed independently: a body without gravity or feedback spinning
about a principal axis turns at a constant rate (theta_2 = Omega_2 t), one under gravity
alone falls (V_3 = -g t, X_3 = -g t^2 / 2), a step torque about a principal axis spins it up
(Omega_3 = T t / J_3), an impulse jumps Omega_3 by P / J_3.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

from rbstab.variants.paper import paper_form, paper_initial_state
from rbstab.config import ConfigError, config_from_mapping
from rbstab.engine import integrate_runs
from rbstab.engine.settings import settings_rows
from rbstab.engine.status import GIMBAL_LOCK, limit_of, limit_status, status_message
from rbstab.model import Limits, parameters
from rbstab.simulator import simulate

#: A constant force of -20 N along z at the centre of mass of the 2 kg body from t = 0: it falls
#: as under g = 10 m/s^2 (gravity itself with no feedback has no equilibrium and is refused).
FALL = {"kind": "step", "quantity": "force", "value": [0, 0, -20.0], "start": 0.0}
ZERO_GAINS = {"k_t": [0, 0, 0], "l_t": [0, 0, 0], "k_r": [0, 0, 0], "l_r": [0, 0, 0]}
INERTIA = [1.0, 2.0, 3.0]


def _config(limits, *, variant="free", omega=(0.0, 0.5, 0.0), v=(0.0, 0.0, 0.0), gravity=(0.0, 0.0, 0.0),
            attachment=(0.0, 0.0, 0.5), method="DOP853", t_end=2.0, disturbances=None, **controller):
    data = {"name": "limits", "body": {"mass": 2.0, "inertia": INERTIA, "attachment_point": list(attachment),
                                       "gravity": list(gravity)},
            "controller": {"variant": variant, **ZERO_GAINS, **controller},
            "initial_state": {"omega": list(omega), "v": list(v)},
            "simulation": {"t_end": t_end, "n_samples": 201, "method": method, "rtol": 1e-10, "atol": 1e-12,
                           "limits": limits}}
    if disturbances:
        data["disturbances"] = disturbances
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # zero gains: semi-definite
        return config_from_mapping(data)


def _t_stop(config):
    """(status code, t_stop [s]) of the compiled engine."""
    variant = paper_form(config)
    sol = integrate_runs([variant.code], variant.parameters, paper_initial_state(config, variant)[None],
                         settings_rows([config.simulation]), method=config.simulation.method,
                         n_samples=config.simulation.n_samples)
    return int(sol.status[0]), float(sol.t_stop[0])


# -- where a run leaves the region ----------------------------------------------------------------
@pytest.mark.parametrize("method", ["RK23", "RK45", "DOP853"])
def test_theta_bound_is_crossed_at_bound_over_rate(method):
    """A free body spinning at Omega_2 = 0.5 rad/s about its principal axis y: theta_2 =
    0.5 t reaches 0.6 rad at t = 1.2 s, located on the interpolant (the samples are 0.01 s
    apart), with the message naming |theta_2|, the key, the bound and the time."""
    config = _config({"theta": [1.0, 0.6, 3.2]}, method=method)
    status, t = _t_stop(config)
    assert limit_of(status) == ("theta", 1)
    assert abs(t - 1.2) < 1e-8
    result = simulate(config)
    assert result.status == "failed"
    assert result.message == "left the admissible region: |theta_2| reached simulation.limits.theta = 0.6 rad at t = 1.2 s"
    time = result.time
    theta = result.outputs["theta"]
    assert np.all(np.isfinite(theta[time < 1.2 - 1e-9])) and np.all(np.isnan(theta[time > 1.2 + 1e-9]))


@pytest.mark.parametrize("limits, kwargs, expected, t_cross", [
    ({"velocity": [1.0, 1.0, 2.5]}, {"omega": (0, 0, 0), "disturbances": [FALL]}, ("velocity", 2), 0.25),
    ({"position": 0.45}, {"omega": (0, 0, 0), "disturbances": [FALL]}, ("position", 2), 0.3),
    ({"constraint_error": [0.06, 1, 1]}, {"omega": (0, 0, 0), "v": (0.3, 0, 0)}, ("constraint_error", 0), 0.2),
    ({"omega": [5, 5, 4.0]}, {"omega": (0, 0, 0), "disturbances": [
        {"kind": "step", "quantity": "torque", "value": [0, 0, 6.0], "start": 0.1}]}, ("omega", 2), 0.1 + 4.0 * 3 / 6),
])
def test_each_bound_is_crossed_where_the_motion_says(limits, kwargs, expected, t_cross):
    """Falling (:data:`FALL`), V_3 = -10 t reaches 2.5 m/s at 0.25 s, X_3 = -5 t^2 0.45 m at 0.3 s; E_1 =
    X_1 = 0.3 t (no rotation) reaches 0.06 m at 0.2 s; a step torque of 6 N m about z from
    0.1 s spins Omega_3 = 2 (t - 0.1) up to 4 rad/s at 2.1 s: each engine stops there with
    the same message."""
    config = _config(limits, t_end=3.0, **kwargs)
    status, t = _t_stop(config)
    assert limit_of(status) == expected
    assert abs(t - t_cross) < 1e-7
    compiled, reference = simulate(config), simulate(config, engine="scipy")
    assert compiled.status == reference.status == "failed"
    assert compiled.message == reference.message
    assert compiled.message.startswith(f"left the admissible region: |{ {'velocity': 'V', 'position': 'X', 'constraint_error': 'E', 'omega': 'Omega'}[expected[0]]}_{expected[1] + 1}| reached simulation.limits.{expected[0]} = ")
    assert compiled.message.endswith(f" at t = {t_cross:.6g} s")


@pytest.mark.parametrize("method", ["RK45", "DOP853", "Radau"])
def test_scipy_reference_agrees_with_the_compiled_engine(method):
    """solve_ivp's terminal event (brentq on its dense output) and the compiled bisection
    find the same crossing, to the tolerances, with the same message; Radau (scipy only) too."""
    config = _config({"theta": [1.0, 0.6, 3.2], "velocity": 10}, method=method)
    reference = simulate(config, engine="scipy")
    assert reference.message == "left the admissible region: |theta_2| reached simulation.limits.theta = 0.6 rad at t = 1.2 s"
    if method != "Radau":
        assert simulate(config).message == reference.message


def test_sign_law_engine_stops_at_the_bound():
    """The pure sign law's event-driven engine (sliding, boundary_layer 0) with C at the
    centre of mass (E = X = 0: C slides, no force): theta_2 = 0.5 t reaches 0.6 rad at 1.2 s."""
    config = _config({"theta": [1.0, 0.6, 3.2]}, variant="sliding", attachment=(0, 0, 0), k_s=10.0,
                     boundary_layer=0.0)
    result = simulate(config)
    assert result.status == "failed"
    assert result.message.startswith(
        "left the admissible region: |theta_2| reached simulation.limits.theta = 0.6 rad at t = 1.2 s Pure sign law")
    assert result.solver["solver_status"] == limit_status(0, 1)


def test_permanent_position_and_velocity_are_the_pinned_bodys():
    """``permanent`` (C pinned at R = (0, 0, 0.5)) spinning at Omega_2 = 0.5 rad/s: X = R - A R,
    |X_1| = 0.5 sin(0.5 t) reaches 0.1 m at t = 2 asin(0.2); |V_1| = 0.25 cos(0.5 t) stays below 0.3."""
    config = _config({"position": [0.1, 1, 1], "velocity": 0.3}, variant="permanent")
    status, t = _t_stop(config)
    assert limit_of(status) == ("position", 0)
    assert abs(t - 2 * math.asin(0.2)) < 1e-8
    assert simulate(config).message == simulate(config, engine="scipy").message


def test_impulse_out_of_the_region_stops_at_its_time():
    """An impulse of 9 N m s about z at 0.5 s jumps Omega_3 to 3 rad/s, beyond the bound 2:
    the run stops at 0.5 s on every CPU engine."""
    config = _config({"omega": 2.0}, omega=(0, 0, 0), disturbances=[
        {"kind": "impulse", "quantity": "torque", "value": [0, 0, 9.0], "start": 0.5}])
    status, t = _t_stop(config)
    assert (limit_of(status), t) == (("omega", 2), 0.5)
    for engine in ("compiled", "scipy"):
        assert simulate(config, engine=engine).message == (
            "left the admissible region: |Omega_3| reached simulation.limits.omega = 2 rad/s at t = 0.5 s")


def test_a_state_outside_stops_at_zero_and_without_limits_gimbal_lock_is_as_before():
    """integrate_runs from a state outside the region (the API takes any state) stops at
    t = 0 with no step; without bounds the event is the gimbal lock's alone."""
    config = _config({"omega": 1.0})
    variant = paper_form(config)
    y0 = paper_initial_state(config, variant)
    y0[4] = 1.5
    sol = integrate_runs([variant.code], variant.parameters, y0[None], settings_rows([config.simulation]),
                         method="DOP853", n_samples=11)
    assert (limit_of(sol.status[0]), sol.t_stop[0], sol.n_steps[0], sol.nfev[0]) == (("omega", 1), 0.0, 0, 0)
    assert np.isnan(sol.samples).all()
    free = _config(None, omega=(0, 2.0, 0))  # theta_2 = 2 t reaches pi/2 - 1e-3 at (pi/2 - 1e-3) / 2
    status, t = _t_stop(free)
    assert status == GIMBAL_LOCK and abs(t - (math.pi / 2 - 1e-3) / 2) < 1e-8


def test_record_fields_and_status_codes():
    """PARAMETERS' ``limits`` rows follow rbstab.layout.LIMITED, inf where unbounded, and
    ``limited`` says whether any is finite; a status code names each (quantity, axis)."""
    config = _config({"theta": [1.0, 0.6, 3.2], "constraint_error": 0.05})
    p = paper_form(config).parameters[0]
    assert p["limited"] == 1.0
    np.testing.assert_array_equal(p["limits"], [[1.0, 0.6, 3.2], [np.inf] * 3, [np.inf] * 3, [np.inf] * 3,
                                                [0.05] * 3])
    none = parameters(paper_form(config).body, paper_form(config).gains)
    assert none["limited"] == 0.0 and np.isinf(none["limits"]).all()
    assert Limits.of().bounded is False and Limits.of(omega=3).bounded
    codes = {limit_status(j, i) for j in range(5) for i in range(3)}
    assert codes == set(range(2, 17)) and all(limit_of(c) for c in codes) and limit_of(GIMBAL_LOCK) is None
    assert status_message(limit_status(4, 2), 0.5, 1e-3, limits=p["limits"]) == (
        "left the admissible region: |E_3| reached simulation.limits.constraint_error = 0.05 m at t = 0.5 s")


# -- what is refused ------------------------------------------------------------------------------
@pytest.mark.parametrize("limits, line", [
    ({"theta": 0}, "config key 'simulation.limits.theta': found 0; expected |theta_i| <= bound (rad): a number > 0"),
    ({"omega": -2}, "config key 'simulation.limits.omega': found -2;"),
    ({"velocity": float("nan")}, "config key 'simulation.limits.velocity': found nan;"),
    ({"position": [1, 2]}, "config key 'simulation.limits.position': found [1, 2]; expected"),
    ({"theta": [1, 0.6, "x"]}, "config key 'simulation.limits.theta': found [1, 0.6, 'x']"),
    ({"tilt": 1}, "config key 'simulation.limits.tilt': unknown key"),
    ({"omega": 0.4}, "config key 'simulation.limits.omega': found 0.4; expected bounds that contain the initial "
                     "state (the initial state lies outside simulation.limits: |Omega_2| = 0.5 rad/s > 0.4 rad/s)"),
])
def test_bad_limits_are_refused_in_one_line(limits, line):
    with pytest.raises(ConfigError) as caught:
        _config(limits)
    assert len(caught.value.errors) == 1 and caught.value.errors[0].startswith(line), caught.value.errors


def test_constraint_error_bound_on_permanent_is_refused():
    with pytest.raises(ConfigError) as caught:
        _config({"constraint_error": 0.01}, variant="permanent")
    assert caught.value.errors == ["config key 'simulation.limits.constraint_error': found 0.01; expected no bound "
                                   "with variant 'permanent' (C is pinned: E = 0 at every instant; bound theta, "
                                   "omega, position or velocity)"]


def test_run_refuses_an_initial_state_outside_and_writes_nothing(tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text("name: c\nbody: {mass: 2, inertia: [1, 2, 3], attachment_point: [0, 0, 0.5]}\n"
                      "controller: {variant: free, k_t: [1, 1, 1], l_t: [1, 1, 1], k_r: [1, 1, 1], l_r: [1, 1, 1]}\n"
                      "initial_state: {v: [0, 0, 3]}\nsimulation: {t_end: 0.1, limits: {velocity: [1, 1, 2]}}\n")
    done = subprocess.run([sys.executable, "-m", "rbstab", "run", str(config), "-o", str(tmp_path / "out")],
                          capture_output=True, text=True)
    assert done.returncode != 0
    assert "the initial state lies outside simulation.limits: |V_3| = 3 m/s > 2 m/s" in done.stderr
    assert not (tmp_path / "out").exists()


def test_resolved_without_limits_is_unchanged_and_with_them_rebuilds():
    """A run without limits keeps its resolved form (and so its config_hash); one with them
    rebuilds from its resolved mapping with the same record."""
    from rbstab.config import RunConfig

    plain = _config(None)
    assert "limits" not in plain.resolved["simulation"]
    bounded = _config({"theta": [1.0, 0.6, 3.2]})
    assert bounded.resolved["simulation"]["limits"] == {"theta": [1.0, 0.6, 3.2]}
    rebuilt = RunConfig.from_resolved(bounded.resolved)
    np.testing.assert_array_equal(paper_form(rebuilt).parameters["limits"], paper_form(bounded).parameters["limits"])


# -- sweeps and analyses ----------------------------------------------------------------------------
def test_sweep_batches_carry_each_runs_limits_and_show_failures_as_not_ok():
    """A table varying a bound (``simulation.limits.theta.1``, written as one number in the
    base) and the initial spin: each run's record is its configuration's, and the runs that
    leave the region are failed, not ok (rbstab.studies.batch.run_generation)."""
    import pandas as pd

    from rbstab.studies.batch import run_generation
    from rbstab.sweep import plan_table, spec_from_mapping

    base = _config({"theta": 1.0, "velocity": 5}).resolved
    design = pd.DataFrame({"simulation.limits.theta.1": [0.6, 0.6, 2.0], "initial_state.omega.1": [0.5, 0.2, 0.5]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = plan_table(spec_from_mapping({"name": "t", "base": dict(base), "table": design}))
        batch = table.slice(np.arange(3)).batch()
        for i in range(3):
            config = config_from_mapping(table.slice(np.arange(3)).resolved(i))
            np.testing.assert_array_equal(batch.params[i, 0], paper_form(config).parameters[0])
        runs = run_generation(base, design)
    np.testing.assert_array_equal(batch.params["limits"][:, 0, 0], [[1.0, 0.6, 1.0], [1.0, 0.6, 1.0], [1.0, 2.0, 1.0]])
    assert runs.ok.tolist() == [False, True, True]  # 0.5 t reaches 0.6 at 1.2 s < t_end; 0.2 t does not


def test_sweep_refuses_runs_whose_initial_state_lies_outside():
    from rbstab.sweep import SweepSpecError, plan_table, spec_from_mapping

    base = _config({"omega": 1.0}).resolved
    with warnings.catch_warnings(), pytest.raises(SweepSpecError) as caught:
        warnings.simplefilter("ignore")
        plan_table(spec_from_mapping({"name": "s", "base": dict(base),
                                      "grid": {"initial_state.omega.1": [0.5, 1.5, 0.9]}}))
    text = str(caught.value)
    assert "1 of 3 runs have an invalid configuration" in text
    assert "the initial state lies outside simulation.limits: |Omega_2| = 1.5 rad/s > 1 rad/s" in text


def test_sweep_parameter_names_of_limits_are_their_own():
    from rbstab.sweep.folder import parameter_name

    assert parameter_name("simulation.limits.theta.1") == "limits_theta_1" != parameter_name("initial_state.theta.1")


def test_analyze_refuses_an_equilibrium_outside_the_limits():
    """Under gravity the visco-elastic body sags to X_3 = -mg / (k_t + k_c) at rest: a bound
    of |X_3| below that excludes the equilibrium (its linearisation point)."""
    from rbstab.analysis import OutsideLimits, analyze

    sag = 2.0 * 10.0 / (100.0 + 300.0)
    gains = {k: [g] * 3 for k, g in {"k_t": 100, "l_t": 10, "k_r": 10, "l_r": 1, "k_c": 300, "l_c": 10}.items()}
    config = _config({"position": [1, 1, 0.9 * sag]}, variant="visco_elastic", omega=(0, 0, 0), gravity=(0, 0, -10),
                     attachment=(0, 0, 0), **{**ZERO_GAINS, **gains})
    with pytest.raises(OutsideLimits, match=r"^the equilibrium lies outside simulation.limits: \|X_3\| = 0.05 m > "
                                            r"0.045 m \(simulation.limits.position\)$"):
        analyze(config, certificate=False, simulate=False)


@pytest.mark.parametrize("bound", ["theta", "constraint_error"])
def test_a_bound_grazed_inside_one_step_is_caught(bound):
    """A damped oscillation about x that overshoots its bound by 0.1 % for a few
    milliseconds, inside one step of a loose tolerance (no sign change at the step's
    ends): the run stops at the first crossing, computed independently (theta_1 of J
    theta'' + L theta' + K theta = 0 from Omega_1(0) = w0; E = X + A R - R with X = 0, so
    E_2 = -R_3 sin(theta_1) for R = (0, 0, r) on a free body, as the constraint point
    turns)."""
    j, k, damping, w0 = 1.0, 50.0, 5.0, 1.0
    w_n, zeta = math.sqrt(k / j), damping / (2 * math.sqrt(k * j))
    w_d = w_n * math.sqrt(1 - zeta**2)
    tilt = lambda t: w0 / w_d * math.exp(-zeta * w_n * t) * math.sin(w_d * t)  # noqa: E731
    t_peak = math.atan2(w_d, zeta * w_n) / w_d
    peak = tilt(t_peak)
    from scipy.optimize import brentq

    if bound == "theta":
        limits, b = {"theta": [peak / 1.001, 3, 3]}, peak / 1.001
        t_cross = brentq(lambda t: tilt(t) - b, 0.0, t_peak, xtol=1e-14)
    else:
        r = 0.5
        b = r * math.sin(peak) / 1.001
        limits = {"constraint_error": [1, b, 1]}
        t_cross = brentq(lambda t: r * math.sin(tilt(t)) - b, 0.0, t_peak, xtol=1e-14)
    data = {"name": "graze", "body": {"mass": 1.0, "inertia": [j, j, j], "attachment_point": [0.0, 0.0, 0.5],
                                      "gravity": [0.0, 0.0, 0.0]},
            "controller": {"variant": "free", "k_t": [0, 0, 0], "l_t": [0, 0, 0], "k_r": [k] * 3, "l_r": [damping] * 3},
            "initial_state": {"omega": [w0, 0.0, 0.0]},
            "simulation": {"t_end": 2.0, "n_samples": 11, "method": "DOP853", "rtol": 1e-5, "atol": 1e-8,
                           "limits": limits}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = config_from_mapping(data)
    status, t = _t_stop(config)
    assert limit_of(status) == (bound, 0 if bound == "theta" else 1)
    # near a grazed bound the crossing time moves by the state's error over its slow rate
    # there (~1e-6 rad / 0.03 rad/s at rtol 1e-5)
    assert abs(t - t_cross) < 2e-4, (t, t_cross)
