"""Studies (rbstab.studies): Sobol' and Morris sensitivity, tuning by Optuna, their CLI.

The body is the free variant without gravity (its gains K_c, L_c do not enter the model:
Lambda = 0), slightly spun and moving, integrated for 1 s with coarse tolerances so that
the hundreds of runs of a study take seconds.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from rbstab_cli.main import cli

import rbstab
from rbstab.simulator import simulate_many
from rbstab.studies import StudyInputError, read_sensitivity, read_tuning, sensitivity_analysis, tune

FREE = {
    "name": "free_study",
    "body": {"mass": 41.0, "inertia": [10.0, 8.0, 4.0], "attachment_point": [0.15, 0.10, -0.42]},
    "controller": {"variant": "free", "k_t": [4100, 4100, 3280], "l_t": [210, 210, 140], "k_r": [400, 400, 320],
                   "l_r": [60, 60, 42], "k_c": [1000, 1000, 1000]},
    "initial_state": {"omega": [1.0, 1.0, 1.0], "v": [0.5, 0.3, 0.2]},
    "simulation": {"t_end": 1.0, "n_samples": 51, "method": "DOP853", "rtol": 1e-6, "atol": 1e-9},
}
#: Factors: K_c (not in the model), L_t and L_r (damping gains, each with an optimum near
#: critical damping), as factors of the base gains.
VARY = ["controller.k_c=scale_uniform:[0.5,2]", "controller.l_t=scale_uniform:[1,16]",
        "controller.l_r=scale_uniform:[1,16]"]
#: v(t_end), then one figure of the translation (damped by L_t alone) and one of the
#: rotation (damped by L_r): the latter two have a clear most important factor.
METRICS = ["lyapunov_final", "final_velocity_x", "final_omega_x"]
CLEAR = {"final_velocity_x": "controller.l_t:scale", "final_omega_x": "controller.l_r:scale"}


@pytest.fixture(scope="module")
def config():
    return rbstab.load_config(FREE)


@pytest.fixture(scope="module")
def sobol(config, tmp_path_factory):
    """A Sobol' study run through the CLI (--json), and its file."""
    out = tmp_path_factory.mktemp("sobol")
    path = out / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(config.resolved))
    args = ["sensitivity", str(path), "-n", "64", "-o", str(out), "-j", "2", "--json", "-q", "--no-progress",
            *[f"--vary={v}" for v in VARY], *[f"--metric={m}" for m in METRICS]]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return [json.loads(line) for line in result.stdout.splitlines()], read_sensitivity(out / "free_study")


def test_k_c_does_not_enter_the_free_variant(config):
    """Two runs whose K_c differ fourfold give the same figures, bit for bit."""
    other = rbstab.load_config(config, {"controller.k_c": [4000, 4000, 4000]})
    (_, a), (_, b) = simulate_many([config, other])
    assert a.summary == b.summary


def test_sobol_finds_no_effect_of_a_factor_outside_the_model(sobol):
    records, ds = sobol
    assert [r["metric"] for r in records] == METRICS == ds["metric"].values.tolist()
    assert ds.attrs["n_runs"] == 64 * (3 + 2)
    for m, record in enumerate(records):
        factors = record["factors"]
        assert factors["controller.k_c:scale"]["ST"] < 0.02
        assert max(f["ST"] for f in factors.values()) > 0.2  # the metric does depend on the gains
        s1 = ds["S1"].values[m]
        assert np.sum(s1) <= 1 + np.sqrt(np.sum(ds["S1_conf"].values[m] ** 2))
        np.testing.assert_allclose(ds["ST"].values[m], [f["ST"] for f in factors.values()])


def test_morris_ranks_the_factors_as_sobol(config, sobol, tmp_path):
    _, sobol_ds = sobol
    ds = sensitivity_analysis(config, VARY, n=16, method="morris", metrics=METRICS, output=tmp_path, jobs=2)
    assert ds.attrs["n_runs"] == 16 * (3 + 1)
    for metric, first in CLEAR.items():
        st = sobol_ds["ST"].sel(metric=metric).values
        conf = sobol_ds["ST_conf"].sel(metric=metric).values
        order = np.argsort(-st)
        assert st[order[0]] - conf[order[0]] > st[order[1]] + conf[order[1]], "the case has a clear first"
        assert sobol_ds["factor"].values[order[0]] == first
        mu_star = ds["mu_star"].sel(metric=metric).values
        assert np.argmax(mu_star) == order[0]
        assert mu_star[0] == 0.0  # K_c: no elementary effect at all


# -- tuning ----------------------------------------------------------------------------------------

TUNE_VARY = ["controller.l_t=scale_uniform:[0.5,8]", "controller.l_r=scale_uniform:[0.5,8]"]


def _grid(config, n=31):
    """lyapunov_final on the n x n grid of the two damping factors of TUNE_VARY."""
    factors = np.linspace(0.5, 8.0, n)
    l_t, l_r = (np.asarray(config.resolved["controller"][k], dtype=float) for k in ("l_t", "l_r"))
    configs = [rbstab.load_config(config, {"controller.l_t": (l_t * a).tolist(), "controller.l_r": (l_r * b).tolist()})
               for a in factors for b in factors]
    return np.array([r.summary["lyapunov_final"] for _, r in simulate_many(configs, full=False)]).reshape(n, n)


def test_tune_finds_the_grids_best_within_a_quarter_of_its_runs(config, tmp_path):
    grid = _grid(config)
    i, j = np.unravel_index(np.argmin(grid), grid.shape)
    assert 0 < i < 30 and 0 < j < 30, "the optimum is interior"
    budget = grid.size // 4  # 240 trials of one run each
    result = tune(config, TUNE_VARY, trials=budget, minimize=["lyapunov_final"], output=tmp_path, seed=0,
                  storage="memory")
    assert result.n_trials == budget == len(result.trials)
    assert result.best_values[0] <= 1.02 * grid.min()


def test_best_yaml_reproduces_the_best_value_and_a_study_resumes(config, tmp_path, monkeypatch):
    from rbstab.studies.tuning import TuningProblem

    calls = {"n": 0}
    evaluate = TuningProblem.evaluate

    def interrupted(self, values):
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt
        return evaluate(self, values)

    monkeypatch.setattr(TuningProblem, "evaluate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        tune(config, TUNE_VARY, trials=6, minimize=["lyapunov_final"], output=tmp_path)
    monkeypatch.setattr(TuningProblem, "evaluate", evaluate)
    args = ["tune", "-", "--trials", "6", "-o", str(tmp_path), "--minimize", "lyapunov_final", "--json", "-q",
            *[f"--vary={v}" for v in TUNE_VARY]]
    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(config.resolved))
    args[1] = str(path)
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout)
    assert record["n_trials"] == 6 and record["n_failed"] == 1  # 3 before the interrupt, 3 after it
    ds = read_tuning(tmp_path / "free_study")
    assert ds["trial"].values.tolist() == list(range(7))
    assert ds["state"].values.tolist()[3] == "fail"
    run = CliRunner().invoke(cli, ["run", str(tmp_path / "free_study" / "best.yaml"), "-o", str(tmp_path / "best"),
                                   "-q"], catch_exceptions=False)
    assert run.exit_code == 0, run.output
    stored = rbstab.open_result(tmp_path / "best" / "free_study_best.h5")
    np.testing.assert_allclose(stored.attrs["summary_lyapunov_final"], record["best_value"], rtol=1e-12)


# -- bad input ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("args, words", [
    (["sensitivity", "-n", "64", "--vary", "controller.k_q=uniform:[1,2]"], ["--vary", "controller.k_q", "config key"]),
    (["sensitivity", "-n", "64", "--vary", "body.mass=unifrm:[1,2]"], ["--vary", "unifrm", "uniform, normal"]),
    (["sensitivity", "-n", "60", "--vary", "body.mass=uniform:[30,50]"], ["-n 60", "power of 2"]),
    (["sensitivity", "-n", "64", "--vary", "body.mass=uniform:[30,50]", "--metric", "lyapunov_fnal"],
     ["--metric", "lyapunov_fnal", "did you mean 'lyapunov_final'"]),
    (["tune", "--trials", "5", "--vary", "body.mass=uniform:[30,50]", "--minimize", "lyapunov_final",
      "--subject-to", "max_abs_constraint_error_z<0.1"], ["--subject-to", "METRIC<=VALUE"]),
    (["tune", "--trials", "5", "--vary", "body.mass=normal:[1]", "--minimize", "lyapunov_final"],
     ["--vary", "'normal' is not allowed", "uniform, log_uniform"]),
    (["tune", "--trials", "5", "--vary", "controller.k_t=scale_uniform:[-1,2]", "--minimize", "lyapunov_final"],
     ["--vary", "lower ends", "controller.k_t"]),
    (["tune", "--trials", "5", "--vary", "body.mass=uniform:[30,50]", "--minimize", "max_abs_constraint_error"],
     ["--minimize", "3-vector", "max_abs_constraint_error_z"]),
])
def test_bad_options_are_refused_before_anything_runs(tmp_path, args, words):
    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(FREE))
    result = CliRunner().invoke(cli, [args[0], str(path), *args[1:], "-o", str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in result.output
    assert not (tmp_path / "out" / "free_study" / "sweep").exists()


def test_invalid_vary_from_python_lists_every_problem(config):
    with pytest.raises(StudyInputError) as info:
        sensitivity_analysis(config, ["body.mass", "controller.k_t=choice:[]"], n=64)
    assert len(info.value.errors) == 2


def test_report_draws_studies(config, sobol, tmp_path):
    _, ds = sobol
    tune(config, TUNE_VARY, trials=4, minimize=["lyapunov_final"], maximize=["max_lyapunov_rate"], output=tmp_path,
         storage="memory")
    out = tmp_path / "report"
    result = CliRunner().invoke(cli, ["report", ds.attrs["path"], str(tmp_path / "free_study"), "-o", str(out), "-q"],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.output
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures == ["sensitivity_free_study.png", "tuning_free_study_objective.png", "tuning_free_study_pareto.png"]
    page = (out / "summary.md").read_text()
    assert "Sensitivity study free_study (sobol)" in page and "Trials of the Pareto front" in page
