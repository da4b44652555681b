"""Push recovery and basin stability (``rbstab analyze --push``, ``--basin-stability``):
thresholds against an independent planar model, non-monotone recovery flagged, a basin
known to be whole, files, JSON and bad input."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import ROOT
from scipy.integrate import solve_ivp

from rbstab.analysis import read_analysis
from rbstab.analysis.push import Pushes, basin_stability, push_analysis, push_directions
from rbstab.analysis.robustness import wilson_interval
from rbstab.analysis.text import rule_lines
from rbstab.analysis.thresholds import EXPLAINS_BAR, INTERVAL_MARGIN, split_rule
from rbstab.config import config_from_mapping, load_config
from rbstab_cli.main import cli

PENDULUM = str(ROOT / "configs/examples/saturated_pendulum.yaml")

# the pendulum of that file: m, L (pivot below the centre of mass), g, J_xx, K_r1, L_r1, |N_1| limit
M, LENGTH, G, J_XX, K, D, N_MAX = 2.0, 0.5, 9.81, 0.05, 200.0, 10.0, 4.0
J_P = J_XX + M * LENGTH**2  # about the pivot
T_END, RATIO = 4.0, 1e-3


@pytest.fixture(scope="module")
def pendulum():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(PENDULUM)
        data = dict(config.resolved)
        data["simulation"] = {**data["simulation"], "n_samples": 201}
        return config_from_mapping(data)


def _planar_recovers(impulse: float) -> bool:
    """The pendulum tilting about its x axis alone, written on its own: J_p theta'' =
    clip(-K theta - D theta', +-N_max) + m g L sin(theta), pushed at rest by a torque
    impulse (theta'(0) = impulse / J_p); it recovers when |v(t_end)| <= ratio dT + 1e-12 J,
    v = J_p theta'^2 / 2 + K theta^2 / 2 - m g L (1 - cos theta), dT = impulse^2 / (2 J_p).
    A run still settling at t_end (0 <= v <= dT) is judged at 2, 4, then 8 t_end (the
    slowest time constant, 2 J_p / D = 0.11 s, asks for less than 2 t_end)."""

    def rhs(t, y):
        torque = min(max(-K * y[0] - D * y[1], -N_MAX), N_MAX)
        return [y[1], (torque + M * G * LENGTH * math.sin(y[0])) / J_P]

    w0 = impulse / J_P
    dT = 0.5 * J_P * w0 * w0
    for t_end in (T_END, 2 * T_END, 4 * T_END, 8 * T_END):
        theta, w = solve_ivp(rhs, (0.0, t_end), [0.0, w0], method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
        v = 0.5 * J_P * w * w + 0.5 * K * theta * theta - M * G * LENGTH * (1.0 - math.cos(theta))
        if abs(v) <= RATIO * dT + 1e-12:
            return True
        if not -1e-12 <= v <= dT + 1e-12:
            return False
    return False


def test_the_kinetic_energy_of_a_push_is_that_of_the_jump(pendulum):
    """dT of a torque impulse L about x on the pinned body at rest: L^2 / (2 J_p)."""
    pushes = Pushes(pendulum, "torque")
    np.testing.assert_allclose(pushes.energy(np.array([[0.7, 0.0, 0.0]])), [0.49 / (2 * J_P)], rtol=1e-12)


def test_threshold_matches_an_independent_planar_model_and_flags_non_monotone_recovery(pendulum):
    """Along x, with the ladder's top at 2 N m s in 50 rungs: the threshold is the planar
    model's first fatal rung, bisected from the rung below within the tolerance (a push of
    0.96 N m s swings the pendulum out and v rises above dT before it comes back: fatal by
    the rule), and a recovering rung above it (the planar model recovers there too, one of
    them only after t_end) flags the direction as not monotone."""
    found = push_analysis(pendulum, "torque", directions=[[1.0, 0.0, 0.0]], push_max=2.0, tol=1e-3, rungs=50)
    threshold = float(found.threshold[0])
    # the planar model: the same ladder from below to the first fatal rung, then bisect
    grid = 2.0 * np.arange(1, 51) / 50
    fatal = next(p for p in grid if not _planar_recovers(p))
    lo, hi = fatal - 0.04, fatal
    while hi - lo > 1e-5 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _planar_recovers(mid) else (lo, mid)
    assert abs(threshold - hi) <= 1.5e-3 * hi, (threshold, hi)
    above = [p for p, ok in zip(found.thresholds.ladder[0], found.thresholds.ladder_recovered[0]) if ok and p > threshold]
    assert above and _planar_recovers(above[0])  # the island above is the physics', not the engine's
    assert not found.thresholds.monotone[0] and not found.monotone


def test_doubling_brackets_the_threshold_and_every_direction_advances_together(pendulum):
    """Without --push-max the doubling finds each direction's top; the thresholds of two
    directions symmetric under the body's symmetry (x, y: J_xx = J_yy, K_r, L_r alike)
    agree, and the local search is not run for given directions."""
    # bounded tilts: a fall ends at 0.6 rad about either axis (about y it would end at the
    # gimbal lock, about x swing through and come back)
    limited = config_from_mapping({**pendulum.resolved, "simulation": {**pendulum.resolved["simulation"],
                                                                     "limits": {"theta": [0.6, 0.6, 3.2]}}})
    found = push_analysis(limited, "torque", directions=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], tol=1e-3)
    t = found.threshold
    assert np.all(np.isfinite(t)) and abs(t[0] - t[1]) <= 1e-3 * t[0]
    assert np.all(found.thresholds.recovering < t) and np.all(t - found.thresholds.recovering <= 1e-3 * t)
    assert len(found.refined_thresholds) == 0
    assert found.batches < found.runs  # one batch a step, not a run


def test_directions_are_quasi_uniform_and_seeded():
    u = push_directions(200, seed=3)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, rtol=1e-12)
    assert np.allclose(u, push_directions(200, seed=3)) and not np.allclose(u, push_directions(200, seed=4))
    assert np.linalg.norm(u.mean(axis=0)) < 0.02  # balanced over the sphere
    # no direction far from the others: the largest nearest-neighbour angle is near the mean spacing
    cos = np.clip(u @ u.T - 2 * np.eye(len(u)), -1, 1)
    assert np.max(np.arccos(cos.max(axis=1))) < 2.0 * math.sqrt(4 * math.pi / len(u))


def test_basin_stability_of_a_box_inside_the_basin_is_one_with_the_wilson_bound(pendulum):
    """Every tilt in [-0.2, 0.2] rad recovers (the edge is arcsin(N_max / (m g L)) = 0.42 rad)."""
    found = basin_stability(pendulum, ranges=["initial_state.theta.0=-0.2:0.2"], draws=120, seed=1)
    assert found.fraction == 1.0 and found.recovered.all()
    assert found.interval == pytest.approx(wilson_interval(120, 120))
    assert found.interval[0] < 1.0 and not found.separations


def test_basin_stability_over_a_box_across_the_edge_separates_by_the_tilt(pendulum):
    """Tilts in [0, 0.8] rad: those below the edge recover, above fall; the tilt separates them."""
    found = basin_stability(pendulum, ranges=["initial_state.theta.0=0:0.8"], draws=80, seed=2)
    edge = math.asin(N_MAX / (M * G * LENGTH))
    theta = found.values[:, 0]
    assert np.all(found.recovered[theta < edge - 0.02]) and not np.any(found.recovered[theta > edge + 0.02])
    (s,) = found.separations
    assert s.stable_side == "below" and abs(s.threshold - edge) < 0.05 and s.auc < 0.05
    assert s.rule.side == "below" and abs(s.rule.high - edge) < 0.05 and np.isnan(s.rule.low) and s.rule.explains


def test_basin_stability_over_a_symmetric_box_recovers_inside_an_interval(pendulum):
    """Tilts in [-0.8, 0.8] rad: -theta falls like theta, the recovered draws lie inside
    (-edge, edge); one threshold would put half the failed draws on the wrong side."""
    found = basin_stability(pendulum, ranges=["initial_state.theta.0=-0.8:0.8"], draws=60, seed=3)
    edge = math.asin(N_MAX / (M * G * LENGTH))
    (s,) = found.separations
    rule = s.rule
    assert rule.side == "inside" and rule.explains and rule.balanced_accuracy == 1.0
    assert abs(rule.low + edge) < 0.05 and abs(rule.high - edge) < 0.05
    np.testing.assert_array_equal(rule.holds(found.values[:, 0]), found.recovered)


def _brute_force_accuracy(x, stable):
    """Best balanced accuracy of one threshold and of two, over every cut (and pair of cuts)
    between distinct values, each side."""
    u = np.unique(x)
    cuts = 0.5 * (u[1:] + u[:-1])

    def accuracy(says):
        return 0.5 * (says[stable].mean() + (~says[~stable]).mean())

    one = max(max(accuracy(x < c), accuracy(x > c)) for c in cuts)
    two = max(max(accuracy((x > a) & (x < b)), accuracy((x < a) | (x > b)))
              for i, a in enumerate(cuts) for b in cuts[i + 1:])
    return one, two


def test_split_rule_is_the_best_rule_of_one_or_two_thresholds():
    """Against every cut and pair of cuts, on noisy outcomes with tied values; the rule's own
    balanced accuracy is that of what it says on the samples."""
    rng = np.random.default_rng(5)
    for shape in ("one-sided", "inside", "outside"):
        x = np.round(rng.uniform(-1, 1, 80), 1)  # ties
        clean = {"one-sided": x < 0.2, "inside": np.abs(x - 0.1) < 0.4, "outside": np.abs(x) > 0.5}[shape]
        stable = clean ^ (rng.uniform(size=x.size) < 0.15)
        one, two = _brute_force_accuracy(x, stable)
        interval = split_rule(x, stable, margin=-1.0)  # the best interval, whatever it gains
        single = split_rule(x, stable, margin=2.0)  # the best single threshold
        assert single.side in ("below", "above") and single.balanced_accuracy == pytest.approx(one)
        assert interval.side in ("inside", "outside") and interval.balanced_accuracy == pytest.approx(two)
        for rule in (single, interval):
            says = rule.holds(x)
            assert rule.balanced_accuracy == pytest.approx(0.5 * (says[stable].mean() + (~says[~stable]).mean()))
            assert rule.explains == (rule.balanced_accuracy >= EXPLAINS_BAR)
        chosen, expected = split_rule(x, stable), interval if two >= one + INTERVAL_MARGIN else single
        assert chosen.side == expected.side and chosen.balanced_accuracy == expected.balanced_accuracy
        np.testing.assert_array_equal([chosen.low, chosen.high], [expected.low, expected.high])  # NaN == NaN here
    assert split_rule(x, np.ones(x.size, bool)) is None and split_rule(x, np.zeros(x.size, bool)) is None


def test_split_rule_of_a_two_sided_outcome_is_an_interval_and_of_a_one_sided_one_a_threshold():
    x = np.random.default_rng(6).uniform(-0.4, 0.4, 50)
    inside = split_rule(x, np.abs(x) < 0.24)
    assert inside.side == "inside" and inside.balanced_accuracy == 1.0 and inside.explains
    assert x[x < -0.24].max() < inside.low < x[np.abs(x) < 0.24].min()
    assert x[np.abs(x) < 0.24].max() < inside.high < x[x > 0.24].min()
    assert split_rule(x, np.abs(x) > 0.1).side == "outside"
    below = split_rule(x, x < 0.1)
    assert below.side == "below" and np.isnan(below.low) and x[x < 0.1].max() < below.high < x[x >= 0.1].min()
    assert split_rule(x, x > -0.2).side == "above"
    # one odd recovered draw at the top: an outside interval gains 1/(2 n_recovered) < the margin
    stable = x < 0.1
    stable[np.argmax(x)] = True
    assert split_rule(x, stable).side == "below"
    assert split_rule(x, stable, margin=0.0).side == "outside"


def test_no_single_key_explains_an_outcome_of_two_keys_together():
    """Recovered iff |theta + 0.5 omega| < 0.3: neither key alone reaches the bar."""
    rng = np.random.default_rng(7)
    theta, omega = rng.uniform(-0.8, 0.8, 400), rng.uniform(-3, 3, 400)
    recovered = np.abs(theta + 0.5 * omega) < 0.3
    rules = [("theta", split_rule(theta, recovered)), ("omega", split_rule(omega, recovered))]
    assert not any(r.explains for _, r in rules)
    best = max(r.balanced_accuracy for _, r in rules)
    (line,) = rule_lines(rules, EXPLAINS_BAR)
    assert f"no single key explains the outcome (best: balanced accuracy {best:.1%}" in line
    assert split_rule(theta + 0.5 * omega, recovered).explains  # the two together do


def test_cli_push_and_stability_files_and_json(tmp_path):
    out = tmp_path / "analysis"
    result = CliRunner().invoke(cli, ["analyze", PENDULUM, "-o", str(out), "--json", "--no-certificate",
                                      "--no-simulation", "--set", "simulation.n_samples=201", "--push", "torque",
                                      "--push-directions", "6", "--push-tol", "1e-2", "-j", "1"],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout.splitlines()[-1])
    push = record["push"]
    assert push["units"] == "N m s" and len(push["directions"]) == 6 and len(push["threshold"]) == 6
    assert push["minimum"]["threshold"] <= min(t for t in push["threshold"] if t is not None)
    assert "smallest fatal torque push" in result.stderr + result.stdout
    ds = read_analysis(out / "saturated_pendulum.analysis.nc")
    assert ds["push_threshold"].attrs["units"] == "N m s" and ds.attrs["push_kind"] == "torque"
    assert ds["push_ladder_recovered"].shape == (6, 16)
    np.testing.assert_allclose(ds["push_threshold"].values, [t if t is not None else np.inf for t in push["threshold"]])

    result = CliRunner().invoke(cli, ["analyze", PENDULUM, "-o", str(out), "--json", "--no-certificate",
                                      "--no-simulation", "--set", "simulation.n_samples=201", "--push", "torque",
                                      "--push-distribution", "0:0.5", "-n", "40", "-j", "1"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout.splitlines()[-1])
    assert "push" not in record and record["basin_stability"]["draws"] == 40
    assert record["basin_stability"]["fraction"] == 1.0  # far below every threshold


def test_cli_basin_stability_gives_a_rule_only_where_it_explains(tmp_path):
    """Text, --json and the file: tilt and rate drawn together, no single key explains the
    outcome; the tilt alone over a symmetric box, recovered inside an interval."""
    out = tmp_path / "analysis"
    base = ["analyze", PENDULUM, "-o", str(out), "--json", "--no-certificate", "--no-simulation", "--set",
            "simulation.n_samples=201", "-j", "1"]
    result = CliRunner().invoke(cli, [*base, "--basin-stability", "initial_state.theta.0=-0.8:0.8",
                                      "--basin-stability", "initial_state.omega.0=-4:4", "-n", "200", "--seed", "1"],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.output
    separations = json.loads(result.stdout.splitlines()[-1])["basin_stability"]["separations"]
    assert [s["explains"] for s in separations] == [False, False]
    best = max(s["balanced_accuracy"] for s in separations)
    assert f"no single key explains the outcome (best: balanced accuracy {best:.1%}" in result.stderr + result.stdout
    assert "recovered where" not in result.stderr + result.stdout
    ds = read_analysis(out / "saturated_pendulum.analysis.nc")
    assert ds["stability_explains"].values.tolist() == [0, 0]
    np.testing.assert_allclose(ds["stability_balanced_accuracy"].values, [s["balanced_accuracy"] for s in separations])

    result = CliRunner().invoke(cli, [*base, "--basin-stability", "initial_state.theta.0=-0.8:0.8", "-n", "40"],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.output
    (s,) = json.loads(result.stdout.splitlines()[-1])["basin_stability"]["separations"]
    assert s["recovered_side"] == "inside" and s["explains"] and s["threshold_low"] < 0 < s["threshold_high"]
    assert (f"initial_state.theta.0: recovered where {s['threshold_low']:.5g} < x < {s['threshold_high']:.5g}"
            in result.stderr + result.stdout)
    ds = read_analysis(out / "saturated_pendulum.analysis.nc")
    assert str(ds["stability_recovered_side"].values[0]) == "inside" and int(ds["stability_explains"].values[0]) == 1
    assert ds["stability_threshold_low"].values[0] == s["threshold_low"]
    assert ds["stability_threshold_high"].attrs["long_name"].startswith("upper threshold of the key's rule")


@pytest.mark.parametrize("args, expected", [
    (["--push", "torque", "--push-max", "0"], "--push-max: found 0.0; expected a magnitude > 0"),
    (["--push", "torque", "--push-direction", "0,0,0"], "--push-direction: found 0,0,0; expected a non-zero"),
    (["--push", "torque", "--push-point", "0,0,1"], "--push-point: a torque has no point of application"),
    (["--push", "force", "--push-point", "0,0,-0.5"], "the pin of this permanent body"),
    (["--push-directions", "8"], "--push-directions: give it with --push"),
    (["--push", "torque", "--push-directions", "0"], "--push-directions: found 0; expected an integer >= 1"),
    (["--basin-stability", "initial_state.theta.0=0:0.1", "-n", "0"], "-n: found 0; expected an integer >= 1"),
    (["--basin-stability", "initial_state.x.0=0:0.1"], "not a state of this variant"),
    (["--basin-stability", "initial_state.theta.1=-2:2"], "reaches |theta_2|"),
    (["--push", "torque", "--push-at", "9"], "--push-at: found 9; expected a time in [0, simulation.t_end)"),
])
def test_bad_push_options_are_refused_in_one_line(tmp_path, args, expected):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["analyze", PENDULUM, "-o", str(out), "--no-certificate", "--no-simulation",
                                      *args])
    assert result.exit_code != 0 and expected in result.output, result.output
    assert "Traceback" not in result.output and not out.exists()


def test_a_spec_gives_curves_over_its_configurations_resumes_and_refuses_other_options(tmp_path):
    """``rbstab analyze SPEC --push``: one record a configuration, the curves file with the
    varied key as a coordinate; the threshold grows with the torque limit (more torque holds
    a harder push), the estimate from {v <= c} is below the simulated one; run again, nothing is
    computed; with other options, refused without --overwrite."""
    spec = tmp_path / "spec.yaml"
    spec.write_text(f"name: limits\nbase: {PENDULUM}\ngrid:\n  controller.saturation.torque_n: [[2.0, 2.0, .inf], "
                    "[4.0, 4.0, .inf], [6.0, 6.0, .inf]]\n")
    out = tmp_path / "analysis"
    args = ["analyze", str(spec), "-o", str(out), "--set", "simulation.n_samples=201", "--push", "torque",
            "--push-direction", "1,0,0", "--push-tol", "1e-2", "-j", "1", "--samples", "500"]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    ds = read_analysis(out / "limits.recovery.analysis.nc")
    assert ds.attrs["kind"] == "recovery" and "run_id" in ds["push_minimum"].coords
    t, estimate = ds["push_minimum"].values, ds["push_estimate"].values
    assert np.all(np.diff(t) > 0) and np.all(estimate < t) and np.all(estimate > 0)
    assert "certified" not in result.output and "estimate" in result.output
    again = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert again.exit_code == 0 and "0 computed now, 3 read back" in again.output
    other = CliRunner().invoke(cli, [*args[:-2], "--samples", "400"])
    assert other.exit_code != 0 and "made with other options" in other.output and "--overwrite" in other.output


def test_report_draws_the_sphere_the_ladder_and_the_curves(tmp_path):
    out = tmp_path / "analysis"
    base = ["analyze", PENDULUM, "-o", str(out), "--no-certificate", "--no-simulation", "--set",
            "simulation.n_samples=201", "-j", "1"]
    assert CliRunner().invoke(cli, [*base, "--push", "torque", "--push-directions", "4", "--push-tol", "1e-2"]).exit_code == 0
    assert CliRunner().invoke(cli, [*base, "--set", "name=drawn", "--basin-stability", "initial_state.theta.0=0:0.8",
                                    "-n", "30"]).exit_code == 0
    report = tmp_path / "report"
    result = CliRunner().invoke(cli, ["report", str(out), "-o", str(report)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    figures = {p.name for p in (report / "figures").iterdir()}
    assert {"analysis_saturated_pendulum_push_sphere.png", "analysis_saturated_pendulum_push_ladder.png",
            "analysis_drawn_stability.png"} <= figures
    page = (report / "index.html").read_text()
    assert "smallest fatal torque push over 4 directions" in page and "basin stability: " in page
    assert "initial_state.theta.0: recovered where x &lt; " in page


def test_free_body_without_gravity_fails_only_where_the_push_reaches_the_theta_limit():
    """A free body without gravity and without limits on its actuators, its tilt bounded by
    |theta_i| <= b: a torque impulse P about a principal axis of an isotropic body makes
    J theta'' + L theta' + K theta = 0 with theta'(0) = P / J, whose largest tilt is P times
    e^(-zeta w_n t*) sin(w_d t*) / (J w_d), tan(w_d t*) = w_d / (zeta w_n): the threshold is
    the P at which that reaches b, along every axis, and recovery is monotone."""
    j, k, damping, b = 2.0, 50.0, 10.0, 0.3
    data = {"name": "free_limited",
            "body": {"mass": 3.0, "inertia": [j, j, j], "attachment_point": [0.0, 0.0, 0.0], "gravity": [0.0, 0.0, 0.0]},
            "controller": {"variant": "free", "k_t": [100.0] * 3, "l_t": [20.0] * 3, "k_r": [k] * 3,
                           "l_r": [damping] * 3},
            "initial_state": {},
            "simulation": {"t_end": 4.0, "n_samples": 201, "method": "DOP853", "rtol": 1e-10, "atol": 1e-12,
                           "limits": {"theta": b}}}
    config = config_from_mapping(data)
    found = push_analysis(config, "torque", directions=np.eye(3), tol=1e-4)
    w_n, zeta = math.sqrt(k / j), damping / (2 * math.sqrt(k * j))
    w_d = w_n * math.sqrt(1 - zeta**2)
    t_star = math.atan2(w_d, zeta * w_n) / w_d
    largest_tilt = math.exp(-zeta * w_n * t_star) * math.sin(w_d * t_star) / (j * w_d)
    np.testing.assert_allclose(found.threshold, b / largest_tilt, rtol=2e-4)
    assert found.monotone


def test_an_analysis_in_threads_takes_slices_in_order_and_an_interrupt_cancels_those_not_started():
    """The analyses' runs in threads (rbstab.analysis.runs._in_threads): slices of at most
    THREAD_SLICE runs, at least one a thread, their results in order; an exception in the
    calling thread (Ctrl-C's KeyboardInterrupt) cancels the slices not started, so it does
    not wait for the whole batch."""
    import threading

    from rbstab.analysis.runs import THREAD_SLICE, _in_threads

    parts = _in_threads(lambda rows: rows.sum(), 1000, 2)
    slices = [rows for rows, _ in parts]
    assert len(slices) >= 2 and max(len(r) for r in slices) <= THREAD_SLICE
    np.testing.assert_array_equal(np.concatenate(slices), np.arange(1000))
    assert [total for _, total in parts] == [int(r.sum()) for r in slices]
    assert len(_in_threads(lambda rows: 0, 64, 2)) == 2  # a push's round: a slice a thread
    started, release = [], threading.Event()

    def work(rows):
        started.append(len(rows))
        if len(started) == 1:
            raise KeyboardInterrupt
        release.wait(0.5)

    with pytest.raises(KeyboardInterrupt):
        _in_threads(work, 40 * THREAD_SLICE, 1)
    release.set()
    assert len(started) < 40


def test_a_push_still_settling_at_t_end_is_judged_at_a_longer_t_end_not_counted_fatal():
    """The stance example (slowest time constant 0.6 s: v takes ~2.1 s to fall by 1e-3) with
    its tilt bounded at 0.6 rad, pushed on the trunk: with t_end 1 s every run that will
    recover is still settling at t_end; run longer, each direction's threshold is the one
    t_end 5 s gives (a fall ends at the bound long before either), and the runs continued are
    counted. Basin stability over the legs' tilt likewise: t_end 0.5 s gives t_end 5 s's
    outcome for every draw."""
    stance = str(ROOT / "configs/examples/stance_ankle_hip.yaml")
    limits = "simulation.limits.theta=[0.6,0.6,3.2]"
    directions = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    found = {}
    for t_end in (1.0, 5.0):
        config = load_config(stance, [limits, f"simulation.t_end={t_end}", "simulation.n_samples=101"])
        found[t_end] = push_analysis(config, "force", directions=directions, point=[0, 0, 0.2], body="trunk")
    assert np.all(np.isfinite(found[5.0].threshold)) and np.all(found[5.0].threshold > 10.0)
    np.testing.assert_allclose(found[1.0].threshold, found[5.0].threshold, rtol=2e-3)
    assert found[1.0].continued > 0 and found[1.0].continued_to > 2.0 and found[5.0].continued == 0
    draws = {}
    for t_end in (0.5, 5.0):
        config = load_config(stance, [limits, f"simulation.t_end={t_end}", "simulation.n_samples=51"])
        draws[t_end] = basin_stability(config, ranges=["initial_state.legs.theta.0=-0.5:0.5"], draws=40, seed=3)
    assert 0 < draws[5.0].recovered.sum() < 40
    np.testing.assert_array_equal(draws[0.5].recovered, draws[5.0].recovered)
