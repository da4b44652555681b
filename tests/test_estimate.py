"""The sublevel estimate {v <= c}: the local search finds what uniform sampling misses, c
and the push estimate never lie above a simulated threshold (the stance body and the
saturated pendulum), a contradicting run lowers c and is named, the words follow the
evidence."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import ROOT
from paper_model import VariantModel, linearise

from rbstab.variants.paper import paper_form
from rbstab.analysis import analyze, read_analysis
from rbstab.analysis.certificate import BOUNDS, certify, checked
from rbstab.config import config_from_mapping, load_config
from rbstab_cli.main import cli

PENDULUM = ROOT / "configs/examples/saturated_pendulum.yaml"

#: One body pinned at the ankle: 70 kg, centre of mass 0.95 m above the pin, ankle torque
#: clipped at 180 N m about the tilt axes.
STANCE = {
    "name": "stance",
    "body": {"mass": 70.0, "inertia": [12.0, 12.0, 1.0], "attachment_point": [0.0, 0.0, -0.95],
             "gravity": [0.0, 0.0, -9.81]},
    "controller": {"variant": "permanent", "k_t": [0, 0, 0], "l_t": [0, 0, 0], "k_r": [1300, 1300, 200],
                   "l_r": [350, 350, 50], "saturation": {"torque_n": [180.0, 180.0, float("inf")], "shape": "clip"}},
    "initial_state": {"theta": [0.05, 0.0, 0.0]},
    "simulation": {"t_end": 5.0, "n_samples": 201},
}


def _quiet(load, *args):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load(*args)


def _exact_level(config) -> float:
    """The least v where dv/dt > 0 is possible, from the physics: on the pinned body's
    reduced state dv/dt = Omega'(N + B'K_r Theta) (eqs 34, 37 with k_t = l_t = 0), which is
    -Omega'L_r Omega while N is not clipped; clipped about axis 1 (|K_r1 theta_1| > N_max)
    it is omega_1 (K_r1 theta_1 - N_max) > 0 for small omega_1 > 0. The infimum of v over
    those states is v at rest at theta_1 = N_max / K_r1 (the tilt axes alike)."""
    variant = paper_form(config)
    theta_s = paper_form(config).gains.saturation.torque_n[0] / paper_form(config).gains.k_r[0, 0]
    return float(variant.lyapunov(np.array([[theta_s, 0, 0, 0, 0, 0]]))[0])


@pytest.mark.parametrize("load", [lambda: _quiet(load_config, PENDULUM), lambda: _quiet(config_from_mapping, STANCE)],
                         ids=["saturated_pendulum", "stance"])
def test_local_search_finds_the_sliver_sampling_misses(load):
    """At low levels the states with dv/dt > 0 are a sliver (a tilt just beyond the clip,
    a small velocity towards it): 250 uniform samples miss it and put c several times too
    high; the local search from them lands on the exact infimum, and never below it (a
    state below it with dv/dt > 0 would be spurious)."""
    config = load()
    variant = paper_form(config)
    cert = certify(VariantModel(variant), linearise(variant), gimbal_margin=config.simulation.gimbal_margin, n_samples=250)
    exact = _exact_level(config)
    assert cert.sublevel_sampled > 1.5 * exact  # sampling alone misses
    assert cert.sublevel_bound == BOUNDS[5]
    assert exact * (1 - 1e-6) <= cert.sublevel <= exact * (1 + 2e-3)
    assert list(cert.history_samples) == [62, 125, 250] and cert.sublevel_history[-1] == cert.sublevel
    assert np.all(np.diff(cert.sublevel_history) <= 0)


def test_a_run_that_contradicts_c_lowers_it_and_is_named():
    config = _quiet(load_config, PENDULUM)
    variant = paper_form(config)
    cert = certify(VariantModel(variant), linearise(variant), gimbal_margin=config.simulation.gimbal_margin, n_samples=100)
    c = cert.sublevel
    same = checked(cert, [0.5 * c, 2.0 * c, np.nan], [True, False, False], lambda i: f"run {i}")
    assert same.sublevel == c and same.runs_checked == 2 and not same.notes  # outside, or recovered
    lowered = checked(cert, [0.5 * c, 0.25 * c], [False, False], lambda i: f"run {i}")
    assert lowered.sublevel < 0.25 * c and lowered.sublevel_bound == BOUNDS[6]
    assert "run 1" in lowered.notes[0] and "1 more" in lowered.notes[0]
    assert "checked against 2 runs" in lowered.evidence and "certified" not in lowered.evidence


def test_a_basin_point_still_settling_is_no_counterexample_and_one_that_fails_or_rises_is():
    """The basin map's points count against c where they start inside and fail or end with v
    above their start; a point not converged by t_end with v(t_end) <= v(0) does not count.
    And a note tells the two levels apart however close they are."""
    from types import SimpleNamespace

    from rbstab.analysis.basin import BasinAxis
    from rbstab.analysis.evidence import check_runs

    config = _quiet(load_config, PENDULUM)
    variant = paper_form(config)
    cert = certify(VariantModel(variant), linearise(variant), gimbal_margin=config.simulation.gimbal_margin, n_samples=100)
    c = cert.sublevel
    axes = [BasinAxis.parse("initial_state.omega.0=-1:1:2"), BasinAxis.parse("initial_state.omega.1=-1:1:2")]

    def basin(outcome, v0, v1):
        return SimpleNamespace(basin=SimpleNamespace(axes=axes, outcome=np.array(outcome, dtype=np.int8).reshape(2, 2),
                                                     lyapunov_initial=np.reshape(v0, (2, 2)),
                                                     lyapunov_final=np.reshape(v1, (2, 2))),
                               push=None, basin_stability=None)

    inside = [0.5 * c] * 4
    settling = check_runs(cert, basin([0, 1, 1, 0], inside, [0.0, 0.4 * c, 0.49 * c, 0.0]))
    assert settling.sublevel == c and not settling.notes and settling.runs_checked == cert.runs_checked + 4
    fell = check_runs(cert, basin([0, 1, 2, 0], [0.5 * c, 0.5 * c, 0.3 * c, 0.5 * c], [0, 0.1 * c, np.nan, 0]))
    assert fell.sublevel < 0.3 * c and "failed" in fell.notes[0] and "omega.0 = 1, initial_state.omega.1 = -1" in fell.notes[0]
    rose = check_runs(cert, basin([0, 1, 0, 0], inside, [0, 0.6 * c, 0, 0]))
    assert rose.sublevel < 0.5 * c and "ended at v(t_end) =" in rose.notes[0] and "above its start" in rose.notes[0]
    close = checked(cert, [c * (1 - 1e-9)], [False], lambda i: "run")
    low, high = close.notes[0].split(": ")[0].split(" from ")[1].split(" J to ")
    assert low != high.removesuffix(" J")  # not "lowered from 6.219 J to 6.219 J"


def test_stance_push_estimate_lies_below_every_simulated_threshold():
    """A single analysis with pushes: c from the samples and the local search, checked
    against every push run; the estimate sqrt(c / dT) lies below the threshold along each
    direction; the words say estimate; no W002 for k_t = l_t = 0; a body under gravity
    without simulation.limits is told so."""
    config = _quiet(config_from_mapping, STANCE)
    assert not config.warnings
    result = analyze(config, samples=500, push={"kind": "force", "directions": [[-1, 0, 0], [0, 1, 0]],
                                                "point": [0, 0, 0.3], "tol": 1e-2})
    cert, push = result.certificate, result.push
    fatal_v, _ = push.fatal_starts()
    assert np.all(cert.sublevel < fatal_v)
    estimate = np.sqrt(cert.sublevel / push.unit_energy)
    assert np.all(estimate < push.threshold) and push.estimate(cert.sublevel) == pytest.approx(estimate.min())
    assert cert.runs_checked >= 32 + 1 + 2 and cert.settled
    from rbstab.analysis.text import describe

    text = "\n".join(describe(result))
    assert "certified" not in text and "estimate (sampled, 500 states" in text
    assert "simulation.limits" in text
    limited = _quiet(config_from_mapping, {**STANCE, "simulation": {**STANCE["simulation"],
                                                                      "limits": {"theta": [0.6, 0.6, float("inf")]}}})
    assert not any("simulation.limits" in n for n in analyze(limited, samples=100, simulate=False,
                                                             falsification_runs=0).notes)


@pytest.mark.parametrize("base", ["stance", "pendulum"])
def test_spec_analysis_reports_no_estimate_above_a_simulated_threshold(tmp_path, base):
    """The issue's sweep over the torque limit: at every point the push estimate lies below
    the smallest fatal push, the output says estimate (never certified), and a
    configuration warning shows once, with the count of points, no Python source line."""
    if base == "stance":
        import yaml

        path = tmp_path / "stance.yaml"
        path.write_text(yaml.safe_dump({**STANCE, "body": {**STANCE["body"], "inertia": [12.0, 12.0, 30.0]}}))
        grid = "controller.saturation.torque_n.1: [100, 180, 260]"
        push = ["--push", "force", "--push-direction=-1,0,0", "--push-point", "0,0,0.3"]
    else:
        path, grid = PENDULUM, "controller.saturation.torque_n: [[2.0, 2.0, .inf], [4.0, 4.0, .inf]]"
        push = ["--push", "torque", "--push-direction", "1,0,0", "--push-direction", "0,1,1"]
    spec = tmp_path / "spec.yaml"
    spec.write_text(f"name: limits\nbase: {path}\ngrid:\n  {grid}\n")
    out = tmp_path / "analysis"
    result = CliRunner().invoke(cli, ["analyze", str(spec), "-o", str(out), "--push-tol", "1e-2", "-j", "1",
                                      "--samples", "500", *push], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    ds = read_analysis(out / "limits.recovery.analysis.nc")
    assert np.all(ds["push_estimate"].values < ds["push_minimum"].values)
    assert np.all(ds["sublevel_runs_checked"].values >= 33)
    assert "certified" not in result.output and "estimate" in result.output
    assert ".py:" not in result.output
    if base == "stance":  # inertia [12, 12, 30] breaks the triangle inequality: W001 at each point
        lines = [line for line in result.output.splitlines() if "W001" in line]
        assert len(lines) == 1 and lines[0].endswith("(3 of 3 points)"), result.output


def test_push_sphere_colour_scale_separates_the_thresholds_that_matter():
    from rbstab.report.push import _threshold_norm

    t = np.array([20.0, 25.0, 31.0, 40.0] * 10 + [1366.0])
    norm = _threshold_norm(t)
    assert norm.vmax < 100 and norm.vmin == 20.0  # one vertical push does not take the whole scale
    assert norm(25.0) < norm(31.0) < norm(40.0)  # log: equal ratios, equal steps
    assert norm(40.0) - norm(31.0) == pytest.approx((norm(31.0) - norm(24.025)), rel=1e-6)


def test_a_fatal_push_inside_the_estimate_lowers_c_in_an_analysis():
    """An admissible region of |Omega_1| <= 0.05 rad/s: a torque push of 0.03 N m s leaves
    it at once (fatal), with dT far inside the sublevel set the samples and the search leave
    (which do not see the bound on Omega); the analysis lowers c below the weakest fatal
    push's dT, names that push, and the push estimate lies below the threshold."""
    data = dict(_quiet(load_config, PENDULUM).resolved)
    data["simulation"] = {**data["simulation"], "n_samples": 201, "limits": {"omega": [0.05, 0.05, 100.0]}}
    config = _quiet(config_from_mapping, data)
    result = analyze(config, samples=200, simulate=False, falsification_runs=0,
                     push={"kind": "torque", "directions": [[1, 0, 0]], "tol": 0.1})
    cert, push = result.certificate, result.push
    assert cert.sublevel_bound == BOUNDS[6] and cert.sublevel < cert.sublevel_history[-1]
    assert cert.sublevel < push.unit_energy[0] * push.threshold[0] ** 2
    assert "torque push of" in cert.notes[0] and "did not recover" in cert.notes[0]
    assert push.estimate(cert.sublevel) < push.threshold[0]


STANCE_ANKLE = ROOT / "configs/examples/stance_ankle.yaml"
SATURATED_PUSH = ROOT / "configs/examples/saturated_push.yaml"


def test_a_slow_run_from_inside_is_run_longer_and_does_not_lower_c():
    """The stance example with t_end = 0.5 s: its run from the configured start (inside
    {v <= c}) has not converged by then, v never above c; run longer it converges, so c is
    the one without the run, with a note saying so."""
    config = _quiet(load_config, STANCE_ANKLE, ["simulation.t_end=0.5", "simulation.n_samples=2001"])
    result = analyze(config, samples=200, falsification_runs=0)
    s, cert = result.settling, result.certificate
    assert s["status"] == "success" and not np.isfinite(s["time_to_converge"])  # slow at t_end
    assert 0 < s["lyapunov_initial"] < cert.sublevel
    unchecked = analyze(config, samples=200, falsification_runs=0, simulate=False).certificate
    assert cert.sublevel == unchecked.sublevel and cert.sublevel_bound == unchecked.sublevel_bound != BOUNDS[6]
    assert cert.runs_checked == 1 and len(cert.notes) == 1
    assert "had not converged by t_end = 0.5 s" in cert.notes[0] and "it converged" in cert.notes[0]


def test_a_run_that_fails_from_inside_lowers_c_and_says_why():
    """The stance example with |Omega_i| <= 0.02 rad/s as its admissible region: the run
    from the configured start, inside {v <= c}, leaves it in its first swing; c is lowered
    below its start and the note names the failure."""
    config = _quiet(load_config, STANCE_ANKLE, ["simulation.limits.omega=[0.02,0.02,0.02]"])
    result = analyze(config, samples=200, falsification_runs=0)
    s, cert = result.settling, result.certificate
    assert s["status"] == "failed" and "simulation.limits.omega" in s["message"]
    assert cert.sublevel < s["lyapunov_initial"] < cert.sublevel_history[-1]
    assert cert.sublevel_bound == BOUNDS[6]
    assert f"failed: {s['message']}" in cert.notes[0] and "from the configured initial state" in cert.notes[0]


def test_v_rising_above_c_lowers_it_and_an_impulse_does_not():
    """The saturated push example starts at rest at its equilibrium (v = 0): its impulse at
    0.5 s makes v jump above c, which is no run from inside, so c stays. With an impulse 80
    times weaker v stays inside {v <= c} after it, and the force pulse at 2.5 s (which
    few of 200 sampled times fall in) lifts v above c: c is lowered below v after the
    impulse, and the note says where v rose above c."""
    config = _quiet(load_config, SATURATED_PUSH)
    cert = analyze(config, samples=200, falsification_runs=0).certificate
    assert cert.sublevel == cert.sublevel_history[-1] and cert.sublevel_bound == BOUNDS[5] and not cert.notes
    weak = _quiet(load_config, SATURATED_PUSH, ["disturbances.0.value=[0.01,0,0]"])
    result = analyze(weak, samples=200, falsification_runs=0)
    lowered = result.certificate
    assert lowered.sublevel_bound == BOUNDS[6] and 0 < lowered.sublevel < 1e-2 * cert.sublevel
    assert "impulse at t = 0.5 s" in lowered.notes[0] and "v rose above c" in lowered.notes[0]
    t = float(lowered.notes[0].split("at t = ")[-1].split(" s")[0])
    assert 2.5 <= t <= 2.6  # during the pulse


def test_a_run_that_has_not_converged_when_run_longer_is_named_and_not_counted():
    """The stance example twisted 0.2 rad with a twist damper of 0.01 N m s/rad: v of the
    twist decays as exp(-2 t / tau), tau = 2 J_3 / L_r3 = 200 s, so the run has not
    converged by 16 t_end = 80 s either, without ever rising above c: c stays, and a note
    says the run was not counted."""
    config = _quiet(load_config, STANCE_ANKLE, ["controller.l_r=[350,350,0.01]", "initial_state.theta=[0,0,0.2]",
                                                "simulation.n_samples=2001"])
    result = analyze(config, samples=200, falsification_runs=0)
    cert = result.certificate
    assert result.linearisation.slowest_time_constant == pytest.approx(200.0)
    assert result.settling["lyapunov_initial"] < cert.sublevel
    unchecked = analyze(config, samples=200, falsification_runs=0, simulate=False).certificate
    assert cert.sublevel == unchecked.sublevel and cert.sublevel_bound != BOUNDS[6]
    assert "had not converged after 80 s" in cert.notes[0] and "not counted against c" in cert.notes[0]
