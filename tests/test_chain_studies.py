"""Studies of chains (rbstab sensitivity, rbstab tune, tune --over): the chain's keys (a body
or a joint by index or name, an initial state by body name), its figures per joint, each
run's figures those of simulate on the run's configuration, and the refusals.

The runs are short (0.5 s, 51 samples, coarse tolerances: ~10 ms each) so that a study of a
few dozen runs takes a second or two.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rbstab_cli.main import cli

import rbstab
from rbstab.config.loader import config_from_mapping, load_config
from rbstab.simulator import simulate
from rbstab.studies import StudyInputError, read_sensitivity, tune
from rbstab.layout import SUMMARY_FIGURES as SUMMARY_QUANTITIES
from rbstab.studies.design import Members, check_metrics, expand_metrics, members_of, nominal_figures
from rbstab.studies.sensitivity import plan_sensitivity
from rbstab.studies.tuning import plan_tuning
from rbstab.sweep.validate import key_path

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = ROOT / "configs" / "examples" / "double_pendulum.yaml"
STANCE = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
SHORT = ["simulation.t_end=0.5", "simulation.n_samples=51", "simulation.rtol=1e-6", "simulation.atol=1e-9"]
SET = [a for s in SHORT for a in ("--set", s)]
#: The lower rod's mass and the upper rod's initial angle, the one by index, the other by name.
PENDULUM_VARY = ["bodies.1.mass=uniform:[0.5,2]", "initial_state.upper.theta.0=uniform:[0.3,0.9]"]
#: The hip's sway damping L_r[0] [N m s/rad] of the stance: v(0.5 s) is least near 50 (critical
#: damping), larger with less damping (it swings) and with more (it creeps).
HIP_DAMPING = [10, 25, 50, 100, 200, 400]


def _alone(config, values: dict):
    """simulate of ``config`` with the dotted keys of ``values`` set (one run alone)."""
    data = copy.deepcopy(config.resolved)
    for key, value in values.items():
        key_path(key, data).set(data, value)
    return simulate(config_from_mapping(data))


def test_the_chain_metrics_are_the_figures_of_a_chain_run():
    """A chain's study metrics are every numeric figure of its run, per body or joint (and
    axis) as a sweep's columns name them, with their values."""
    config = load_config(PENDULUM, SHORT)
    figures, run = nominal_figures(config), simulate(config).summary
    assert figures["max_abs_constraint_error_elbow_z"] == run["max_abs_constraint_error"][1][2]
    assert figures["final_theta_lower_z"] == run["final_theta"][1][2]
    assert figures["fraction_saturated_torque_n_shoulder_x"] == run["fraction_saturated_torque_n"][0][0]
    np.testing.assert_equal(figures["time_lyapunov_rising"], run["time_lyapunov_rising"])
    assert figures["lyapunov_final"] == run["lyapunov_final"] and figures["converged"] in (0.0, 1.0)
    names = {"body": ("upper", "lower"), "joint": ("shoulder", "elbow")}
    expected = {"converged"}
    for key, value in run.items():
        if key == "lyapunov_rate_check":
            continue
        members = names[SUMMARY_QUANTITIES[key].member] if np.ndim(value) else ("",)
        axes = "xyz" if np.ndim(value) == 2 else ("",)
        expected |= {"_".join(w for w in (key, m, a) if w) for m in members for a in axes}
    assert set(figures) == expected


def test_a_chain_metric_names_its_columns_by_member_and_axis():
    """<figure>[_<member>][_<axis>]: a name leaving out the member or the axis stands for
    each of its columns, in the tree's order; a member the tree lacks, or a figure of the
    pure sign law, is refused."""
    members = Members(("upper", "lower"), ("shoulder", "elbow"))
    available = ["final_theta_lower_x", "final_theta_upper_x", "final_theta_upper_y", "lyapunov_final",
                 "max_abs_constraint_error_elbow_x", "max_abs_constraint_error_shoulder_x"]
    expand = lambda name: expand_metrics([name], available, members=members)  # noqa: E731
    assert expand("final_theta") == ["final_theta_upper_x", "final_theta_upper_y", "final_theta_lower_x"]
    assert expand("final_theta_x") == ["final_theta_upper_x", "final_theta_lower_x"]
    assert expand("final_theta_upper") == ["final_theta_upper_x", "final_theta_upper_y"]
    assert expand("max_abs_constraint_error") == ["max_abs_constraint_error_shoulder_x",
                                                  "max_abs_constraint_error_elbow_x"]
    assert expand("lyapunov_final") == ["lyapunov_final"]
    check_metrics(["final_theta_lower_z", "fraction_saturated_torque_n_elbow", "converged"], members=members)
    with pytest.raises(StudyInputError, match="no body 'torso'"):
        check_metrics(["final_theta_torso_x"], members=members)
    with pytest.raises(StudyInputError, match="not a summary figure"):
        check_metrics(["switching_count"], members=members)
    check_metrics(["switching_count", "final_theta_x"])  # one body's runs: the sign law's figure, a component


def test_settling_time_sway_and_excursion_are_metrics_of_both_studies():
    """The balance figures (settling time [s], peak sway and centre-of-mass excursion [m]) are
    metrics of a chain's and of one body's studies: accepted by rbstab sensitivity's
    --metric and rbstab tune's --minimize and --subject-to, one column each, with the run's
    values."""
    balance = ["settling_time", "peak_sway", "com_excursion"]
    config = load_config(STANCE, SHORT)
    check_metrics(balance, members=Members(("legs", "trunk"), ("ankle", "hip")))
    check_metrics(balance)
    assert plan_sensitivity(config, ["joints.hip.l_r.0=uniform:[50,100]"], n=4, metrics=balance).metrics == tuple(balance)
    plan_tuning(config, ["joints.hip.l_r.0=uniform:[50,100]"], minimize=["settling_time"],
                subject_to=["peak_sway<=0.05", "com_excursion<=0.05"])
    figures, run = nominal_figures(config), simulate(config).summary
    assert expand_metrics(balance, list(figures), members=members_of(config)) == balance
    for name in balance:
        np.testing.assert_equal(figures[name], run[name])
    assert 0.0 < run["peak_sway"] <= run["com_excursion"] < 0.05  # the lean's centimetre, back upright


def test_sensitivity_of_a_chain_gives_each_rows_figures_of_simulate_chain(tmp_path):
    out = tmp_path / "studies"
    args = ["sensitivity", str(PENDULUM), "-n", "8", *SET, "-o", str(out), "-j", "1", "--json", "-q",
            "--no-progress", *[f"--vary={v}" for v in PENDULUM_VARY]]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    records = {r["metric"]: r for r in map(json.loads, result.stdout.splitlines())}
    # the default metrics: max |E_j,i| of each joint and axis, v(t_end), the largest dv/dt, converged
    errors = [f"max_abs_constraint_error_{joint}_{axis}" for joint in ("shoulder", "elbow") for axis in "xyz"]
    assert list(records) == [*errors, "lyapunov_final", "max_lyapunov_rate", "converged"]
    assert records["max_abs_constraint_error_elbow_z"]["units"] == "m" and records["lyapunov_final"]["units"] == "J"
    assert set(records["lyapunov_final"]["factors"]) == {"bodies.1.mass", "initial_state.upper.theta.0"}
    assert records["lyapunov_final"]["n_runs"] == 32 and records["lyapunov_final"]["n_nonfinite"] == 0
    ds = read_sensitivity(out / "double_pendulum")
    assert list(ds["metric"].values) == list(records)

    config = load_config(PENDULUM, SHORT)
    plan = plan_sensitivity(config, PENDULUM_VARY, n=8)  # the same design, drawn again
    runs = rbstab.open_sweep(out / "double_pendulum" / "sweep")
    assert runs.sizes["run"] == len(plan.design) == 32
    for i, row in plan.design.iterrows():
        alone = _alone(config, row.to_dict())
        assert runs["lyapunov_final"].values[i] == alone.summary["lyapunov_final"]
        assert runs["max_lyapunov_rate"].values[i] == alone.summary["max_lyapunov_rate"]
        for j, joint in enumerate(("shoulder", "elbow")):
            for k, axis in enumerate("xyz"):
                assert (runs[f"max_abs_constraint_error_{joint}_{axis}"].values[i]
                        == alone.summary["max_abs_constraint_error"][j][k])


def test_tune_on_a_chain_reaches_the_grids_best_and_its_trials_are_simulate_chains(tmp_path):
    config = load_config(STANCE, SHORT)
    grid = {d: _alone(config, {"joints.hip.l_r.0": d}).summary for d in HIP_DAMPING}
    v = {d: s["lyapunov_final"] for d, s in grid.items()}
    best = min(v, key=v.get)
    assert best not in (HIP_DAMPING[0], HIP_DAMPING[-1])  # an optimum inside the grid
    result = tune(config, [f"joints.hip.l_r.0=choice:{HIP_DAMPING}"], minimize=["lyapunov_final"],
                  subject_to=["max_abs_constraint_error_hip_z<=1e-6"], trials=16, generation=8, storage="memory",
                  output=tmp_path)
    assert result.n_trials == 16 and result.n_failed == 0
    assert result.best_params == {"joints.hip.l_r.0": best} and result.best_values == [v[best]]
    for _, row in result.trials.iterrows():
        damping = row["joints.hip.l_r.0"]
        assert row["lyapunov_final"] == v[damping]
        assert row["max_abs_constraint_error_hip_z"] == grid[damping]["max_abs_constraint_error"][1][2]
    # best.yaml is a chain's config that rbstab run takes: it gives the best trial's value
    again = load_config(tmp_path / "stance_ankle_hip" / "best.yaml")
    assert again.resolved["joints"][1]["l_r"][0] == best
    assert simulate(again).summary["lyapunov_final"] == v[best]
    assert rbstab.studies.read_tuning(tmp_path / "stance_ankle_hip")["max_abs_constraint_error_hip_z"].attrs["units"] == "m"


OVER = ["bodies.trunk.mass=scale_uniform:[0.95,1.05]", "bodies.0.mass=uniform:[21,23]"]


def test_tune_over_uncertain_chain_bodies_takes_the_worst_of_simulate_chains_runs():
    config = load_config(STANCE, SHORT)
    problem = plan_tuning(config, ["joints.hip.l_r.0=uniform:[25,100]"], minimize=["lyapunov_final"],
                          subject_to=["max_abs_constraint_error_hip_z<=1"], over=OVER, over_n=3)
    masses = [(b["bodies.0.mass"], b["bodies.trunk.mass"]) for b in problem.bodies]
    assert len(set(masses)) == 3 and all(21 <= a <= 23 and 45 <= b <= 50 for a, b in masses)
    trials = [problem.values_of({"joints.hip.l_r.0": d}) for d in (30.0, 80.0)]
    for values, record in zip(trials, problem.evaluate_many(trials)):
        runs = [simulate(c).summary for c in problem.configs(values)]
        assert [[b.mass for b in c.chain.bodies] for c in problem.configs(values)] == [list(m) for m in masses]
        assert record["figures"]["lyapunov_final"] == max(s["lyapunov_final"] for s in runs)
        assert record["figures"]["max_abs_constraint_error_hip_z"] == max(s["max_abs_constraint_error"][1][2]
                                                                          for s in runs)


def test_tune_over_a_chain_from_the_command_line(tmp_path):
    out = tmp_path / "studies"
    args = ["tune", str(STANCE), "--trials", "4", "--generation", "4", "--vary", "joints.hip.l_r.0=uniform:[25,100]",
            "--minimize", "lyapunov_final", *[f"--over={o}" for o in OVER], "--over-n", "3", *SET, "-o", str(out),
            "--json", "-q"]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout.splitlines()[-1])
    assert record["n_trials"] == 4 and record["n_failed"] == 0 and set(record["best_params"]) == {"joints.hip.l_r.0"}
    tuning = rbstab.studies.read_tuning(out / "stance_ankle_hip")
    assert tuning.attrs["bodies"] == 3
    assert load_config(out / "stance_ankle_hip" / "best.yaml").resolved["bodies"][1]["mass"] == 47.46  # nominal


# -- refused input -------------------------------------------------------------------------------


@pytest.mark.parametrize("args, words", [
    (["sensitivity", "--vary", "joints.knee.k_r.0=uniform:[1,2]"],
     ["--vary 'joints.knee.k_r.0=uniform:[1,2]'", "no 'knee'", "by name: shoulder, elbow"]),
    (["sensitivity", "--vary", "initial_state.torso.theta.0=uniform:[0,0.1]"],
     ["--vary", "found 'torso'", "expected one of upper, lower"]),
    (["sensitivity", "--vary", "controller.k_r.0=uniform:[1,2]"],
     ["--vary", "unknown section 'controller'", "allowed: name, gravity, bodies, joints"]),
    (["sensitivity", "--vary", "bodies.1.mass=uniform:[1,2]", "--metric", "max_abs_constraint_error_knee"],
     ["--metric 'max_abs_constraint_error_knee'", "no joint 'knee'", "joints: shoulder, elbow"]),
    (["sensitivity", "--vary", "bodies.1.mass=uniform:[1,2]", "--metric", "final_theta_torso_x"],
     ["--metric 'final_theta_torso_x'", "no body 'torso'", "allowed for a chain: converged", "bodies: upper, lower"]),
    (["tune", "--vary", "bodies.1.mass=uniform:[1,2]", "--minimize", "max_abs_constraint_error"],
     ["--minimize 'max_abs_constraint_error'", "per joint", "max_abs_constraint_error_shoulder"]),
    (["tune", "--vary", "bodies.1.mass=uniform:[1,2]", "--minimize", "lyapunov_final",
      "--subject-to", "max_abs_constraint_error_z<=0.1"], ["--subject-to", "several columns",
                                                          "max_abs_constraint_error_elbow_z"]),
    (["tune", "--vary", "bodies.1.mass=uniform:[1,2]", "--minimize", "lyapunov_final",
      "--over", "bodies.5.mass=uniform:[1,2]"], ["--over 'bodies.5.mass=uniform:[1,2]'", "no '5'", "upper, lower"]),
    (["tune", "--vary", "joints.elbow.k_r=scale_uniform:[1,2]", "--minimize", "lyapunov_final"],
     ["--vary", "'joints.elbow.k_r'", "found no value", "a number or a list of numbers"]),
    (["tune", "--vary", "bodies.upper.mass=uniform:[1,2]", "--vary", "bodies.0.mass=uniform:[1,2]",
      "--minimize", "lyapunov_final"], ["--vary", "given twice", "bodies.upper.mass and bodies.0.mass"]),
    (["tune", "--vary", "bodies.1.mass=uniform:[-1,2]", "--minimize", "lyapunov_final"],
     ["--vary", "lower ends", "'bodies.1.mass': found -1.0; expected a number > 0"]),
], ids=["joint", "body", "one-body-key", "metric-joint", "metric-body", "per-joint-objective",
        "constraint-of-columns", "over-body", "scale-unset", "twice", "corner"])
def test_bad_chain_study_options_are_refused_in_one_line_and_nothing_is_written(tmp_path, args, words):
    out = tmp_path / "out"
    n = ["-n", "8"] if args[0] == "sensitivity" else ["--trials", "4"]
    result = CliRunner().invoke(cli, [args[0], str(PENDULUM), *n, *args[1:], *SET, "-o", str(out)])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    problems = [line for line in result.output.splitlines() if line.startswith("  ")]
    assert result.output.startswith("Error: invalid study\n") and len(problems) == 1, result.output
    for word in words:
        assert word in problems[0], problems[0]
    assert not out.exists()


def test_a_chain_study_from_python_lists_every_problem():
    config = load_config(PENDULUM, SHORT)
    with pytest.raises(StudyInputError) as info:
        plan_sensitivity(config, ["joints.knee.l_r.0=uniform:[1,2]", "bodies.lower.mass=choice:[]"], n=8,
                         metrics=["max_abs_constraint_error_hip"])
    assert len(info.value.errors) == 3, info.value.errors
    assert np.all([e.startswith(("--vary", "--metric")) for e in info.value.errors])


def test_a_chain_study_on_cuda_runs_there_or_says_why(tmp_path):
    """A chain's study takes the engine asked for (its runs batched there), as one body's:
    without a GPU, --engine cuda is one line and a non-zero exit, not a quiet CPU run."""
    from rbstab.engine.registry import get_engine

    try:
        get_engine("cuda").check_available()
        pytest.skip("a GPU is usable here: the CUDA tests cover it")
    except Exception:
        pass
    args = ["sensitivity", str(PENDULUM), "-n", "4", *SET, "-o", str(tmp_path / "studies"), "-j", "1", "-q",
            "--no-progress", "--engine", "cuda", *[f"--vary={v}" for v in PENDULUM_VARY]]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code != 0 and "--engine cuda found no usable NVIDIA GPU" in result.output
    assert "Traceback" not in result.output
