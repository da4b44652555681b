"""Studies (rbstab.studies): Sobol' and Morris sensitivity, tuning by Optuna, their CLI.

The body is the free variant without gravity (its gains K_c, L_c do not enter the model:
Lambda = 0), slightly spun and moving, integrated for 1 s with coarse tolerances so that
the hundreds of runs of a study take seconds.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rbstab_cli.main import cli

import rbstab
from rbstab.simulator import simulate_many
from rbstab.studies import (StudyInputError, optuna_storage, read_sensitivity, read_tuning, sensitivity_analysis,
                            tune)

ROOT = Path(__file__).resolve().parents[1]
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
    np.testing.assert_equal(a.summary, b.summary)  # NaN (no value) equal too


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


#: A multimodal two-gain problem: the damping gains L_t, L_r of Case 2 over four decades
#: each (one log-scaled factor per gain vector), minimizing v(t_end). Its 31 x 31 log grid
#: has three local minima, two of them near the upper corner.
CASE2 = "configs/paper/case2_visco_elastic.yaml"
CASE2_VARY = ["controller.l_t=scale_log_uniform:[0.01,100]", "controller.l_r=scale_log_uniform:[0.01,100]"]


@pytest.fixture(scope="module")
def case2_grid():
    """v(t_end) of Case 2 on the 31 x 31 log grid of CASE2_VARY's factors (one batch)."""
    import pandas as pd
    from scipy.ndimage import minimum_filter

    from rbstab.studies.batch import run_generation

    config = rbstab.load_config(ROOT / CASE2)
    factors = np.geomspace(0.01, 100, 31)
    l_t, l_r = (np.asarray(config.resolved["controller"][k], dtype=float) for k in ("l_t", "l_r"))
    rows = [{**{f"controller.l_t[{i}]": l_t[i] * a for i in range(3)},
             **{f"controller.l_r[{i}]": l_r[i] * b for i in range(3)}} for a in factors for b in factors]
    grid = run_generation(config.resolved, pd.DataFrame(rows)).figures["lyapunov_final"].reshape(31, 31)
    assert np.sum(grid == minimum_filter(grid, size=3)) >= 2, "the problem is multimodal"
    return config, grid


@pytest.mark.parametrize("sampler", ["tpe", "cmaes"])
def test_tune_reaches_the_log_grids_best_for_every_seed(case2_grid, sampler, tmp_path):
    config, grid = case2_grid
    for seed in range(4):
        result = tune(config, CASE2_VARY, trials=240, minimize=["lyapunov_final"], output=tmp_path, seed=seed,
                      storage="memory", sampler=sampler, name=f"s{seed}")
        assert result.n_trials == 240 == len(result.trials)
        assert result.best_values[0] <= 1.02 * grid.min(), (seed, result.best_values[0] / grid.min())


def test_a_generation_is_one_engine_batch(config, tmp_path, monkeypatch):
    """40 trials in generations of 16 over 4 bodies: three batches of 64, 64 and 32 runs."""
    import rbstab.simulator

    calls = []
    batch = rbstab.simulator.simulate_batch

    def counted(runs, rows=None, **kwargs):
        if kwargs.get("configs") is None:  # a study's batch (simulate_blocks passes the configs it runs)
            calls.append(len(runs) if rows is None else len(rows))
        return batch(runs, rows, **kwargs)

    monkeypatch.setattr(rbstab.simulator, "simulate_batch", counted)
    result = tune(config, TUNE_VARY, trials=40, minimize=["lyapunov_final"], output=tmp_path, storage="memory",
                  generation=16, startup=16, over=["body.mass=scale_uniform:[0.9,1.1]"], over_n=4)
    assert result.n_trials == 40
    assert calls == [64, 64, 32]


def test_tune_with_jobs_integrates_each_generation_in_threads_with_the_same_trials(config, tmp_path, monkeypatch):
    """-j 2 on the compiled engine: each generation in two threads of this process (no
    worker process), and the same trials as in this process alone."""
    import threading

    import rbstab.studies.batch

    names = []
    part = rbstab.studies.batch.integrate_part

    def recorded(item, engine="compiled"):
        names.append(threading.current_thread().name)
        return part(item, engine)

    monkeypatch.setattr(rbstab.studies.batch, "integrate_part", recorded)
    common = dict(trials=32, minimize=["lyapunov_final"], storage="memory", generation=16, startup=16)
    alone = tune(config, TUNE_VARY, output=tmp_path / "one", **common)
    assert names and all(n == threading.main_thread().name for n in names)
    names.clear()
    threaded = tune(config, TUNE_VARY, output=tmp_path / "two", jobs=2, **common)
    assert len(names) == 4 and all(n.startswith("rbstab") for n in names)  # 2 generations x 2 slices
    assert (tmp_path / "one" / "free_study" / "trials.csv").read_text() == \
        (tmp_path / "two" / "free_study" / "trials.csv").read_text()
    assert threaded.best_values == alone.best_values


def test_tune_with_jobs_at_a_scripts_top_level_runs_once(config, tmp_path):
    """Threads start no process: a script need not guard tune(jobs=2)."""
    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(config.resolved))
    script = tmp_path / "script.py"
    script.write_text(
        "import rbstab\n"
        "print('top')\n"
        f"r = rbstab.tune(rbstab.load_config({str(path)!r}), {TUNE_VARY!r}, minimize=['lyapunov_final'], trials=16, generation=8,\n"
        f"                startup=8, storage='memory', output={str(tmp_path)!r}, jobs=2)\n"
        "print('trials', r.n_trials)\n")
    done = subprocess.run([sys.executable, "-W", "ignore", str(script)], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("top") == 1 and "trials 16" in done.stdout


def test_a_generation_equals_its_runs_one_by_one(config):
    """The figures of a generation's batch are those of simulate_many, bit for bit."""
    from rbstab.studies.tuning import plan_tuning

    problem = plan_tuning(config, TUNE_VARY, minimize=["lyapunov_final"], subject_to=["final_omega_x<=1"],
                          over=["body.mass=scale_uniform:[0.8,1.2]"], over_n=3)
    trials = [problem.values_of({"controller.l_t:scale": a, "controller.l_r:scale": b})
              for a, b in [(0.5, 1.0), (2.0, 3.0), (7.5, 0.6)]]
    records = problem.evaluate_many(trials)
    for values, record in zip(trials, records):
        runs = [r.summary for _, r in simulate_many(problem.configs(values), full=False)]
        assert record["figures"]["lyapunov_final"] == max(s["lyapunov_final"] for s in runs)
        assert record["figures"]["final_omega_x"] == max(s["final_omega"][0] for s in runs)


def test_an_interrupted_study_resumes_with_every_finished_trial_once(config, tmp_path, monkeypatch):
    import optuna
    import pandas as pd

    import rbstab.studies.batch

    calls = {"n": 0}
    run_generation = rbstab.studies.batch.run_generation

    def interrupted(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt  # in the third generation's batch
        return run_generation(*args, **kwargs)

    monkeypatch.setattr(rbstab.studies.batch, "run_generation", interrupted)
    with pytest.raises(KeyboardInterrupt):
        tune(config, TUNE_VARY, trials=40, minimize=["lyapunov_final"], output=tmp_path, generation=8, startup=8)
    columns = ["number", "params_controller.l_t:scale", "value"]
    before = optuna.load_study(study_name="free_study", storage=optuna_storage(tmp_path / "free_study")) \
        .trials_dataframe()[columns]
    assert len(before) == 16  # two finished generations, stored whole
    monkeypatch.setattr(rbstab.studies.batch, "run_generation", run_generation)
    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(config.resolved))
    args = ["tune", str(path), "--trials", "40", "-o", str(tmp_path), "--minimize", "lyapunov_final", "--json", "-q",
            "--generation", "8", "--startup", "8", *[f"--vary={v}" for v in TUNE_VARY]]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout)
    assert record["n_trials"] == 40 and record["n_failed"] == 0
    table = pd.read_csv(tmp_path / "free_study" / "trials.csv")
    assert table["trial"].tolist() == list(range(40))
    assert (table["state"] == "complete").all()
    after = optuna.load_study(study_name="free_study", storage=optuna_storage(tmp_path / "free_study")) \
        .trials_dataframe()[columns]
    pd.testing.assert_frame_equal(after.iloc[:16], before)
    run = CliRunner().invoke(cli, ["run", str(tmp_path / "free_study" / "best.yaml"), "-o", str(tmp_path / "best"),
                                   "-q"], catch_exceptions=False)
    assert run.exit_code == 0, run.output
    stored_run = rbstab.open_result(tmp_path / "best" / "free_study_best.h5")
    np.testing.assert_allclose(stored_run.attrs["summary_lyapunov_final"], record["best_value"], rtol=1e-12)


def test_a_generation_is_stored_whole_despite_ctrl_c():
    import os
    import signal

    from rbstab.studies.tuning import _deferred_interrupt

    done = []
    with pytest.raises(KeyboardInterrupt):
        with _deferred_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
            done.append(1)
    assert done == [1]


def test_two_processes_on_one_study_share_its_trials(config, tmp_path):
    """Two processes run one study (its SQLite journal) at once: together they reach the trials asked,
    each stores whole generations, every trial is stored once (numbers 0..n-1), and the
    study's files hold every stored trial, best.yaml the best of them."""
    import os
    import subprocess
    import sys

    import optuna
    import pandas as pd
    import yaml

    data = {**config.resolved, "simulation": {**config.resolved["simulation"], "t_end": 0.2, "n_samples": 5}}
    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(data))
    # Each process loads the engine, says it is ready and waits for the other before tuning: a
    # process that starts while the other has already finished every trial shares nothing.
    script = ("import sys, time, pathlib, rbstab, rbstab.engine\n"
              "if __name__ == '__main__':\n"
              "    rbstab.engine.ensure_compiled(sign_law=True)\n"
              "    folder = pathlib.Path(sys.argv[2])\n"
              "    (folder / ('ready-' + sys.argv[3])).touch()\n"
              "    while len(list(folder.glob('ready-*'))) < 2:\n"
              "        time.sleep(0.05)\n"
              "    rbstab.tune(rbstab.load_config(sys.argv[1]), %r, trials=24, minimize=['lyapunov_final'],\n"
              "                output=sys.argv[2], name='shared', seed=int(sys.argv[3]), generation=4, startup=4)\n"
              % TUNE_VARY)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(rbstab.__file__).parents[1]),
                                                        os.environ.get("PYTHONPATH", "")])}
    processes = [subprocess.Popen([sys.executable, "-c", script, str(path), str(tmp_path), str(seed)], env=env,
                                  stderr=subprocess.PIPE, text=True) for seed in (1, 2)]
    for process in processes:
        assert process.wait(timeout=300) == 0, process.stderr.read()
    study = optuna.load_study(study_name="shared", storage=optuna_storage(tmp_path / "shared"))
    trials = study.get_trials()
    assert [t.number for t in trials] == list(range(len(trials)))
    assert all(t.state == optuna.trial.TrialState.COMPLETE for t in trials)
    assert 24 <= len(trials) <= 24 + 4  # the other process's generation running at the end finishes too
    by_process = {}
    for t in trials:
        by_process.setdefault(t.user_attrs["process"], []).append(t.number)
    assert len(by_process) == 2 and all(len(n) % 4 == 0 for n in by_process.values())  # whole generations
    table = pd.read_csv(tmp_path / "shared" / "trials.csv")
    assert table["trial"].tolist() == list(range(len(trials)))
    np.testing.assert_array_equal(table["lyapunov_final"], [t.values[0] for t in trials])
    best = min(trials, key=lambda t: t.values[0])
    text = (tmp_path / "shared" / "best.yaml").read_text()
    assert text.startswith(f"# best trial {best.number} of tuning study shared")
    gains = yaml.safe_load(text)["controller"]
    np.testing.assert_allclose(gains["l_t"], np.asarray(data["controller"]["l_t"]) * best.params["controller.l_t:scale"])


def test_a_journal_transaction_is_stored_whole_or_not_at_all(tmp_path):
    """Appends inside a transaction are read back by its own process before the commit, by
    another connection only after it, and not at all after a rollback."""
    from rbstab.studies.storage import SQLiteJournal

    path = tmp_path / "journal.db"
    writer, reader = SQLiteJournal(path), SQLiteJournal(path)
    writer.append_logs([{"op_code": 0}])
    with writer.transaction():
        writer.append_logs([{"op_code": 1}])
        writer.append_logs([{"op_code": 2}, {"op_code": 3}])
        assert [log["op_code"] for log in writer.read_logs(1)] == [1, 2, 3]
        assert reader.read_logs(0) == [{"op_code": 0}]
    assert [log["op_code"] for log in reader.read_logs(2)] == [2, 3]
    with pytest.raises(KeyboardInterrupt):
        with writer.transaction():
            writer.append_logs([{"op_code": 4}])
            raise KeyboardInterrupt
    assert len(SQLiteJournal(path).read_logs(0)) == 4


def test_a_study_in_optunas_relational_sqlite_file_resumes_there(config, tmp_path):
    """A folder holding a study.db (Optuna's relational storage) and no journal resumes in it."""
    import optuna

    folder = tmp_path / "free_study"
    folder.mkdir()
    url = f"sqlite:///{folder / 'study.db'}"
    tune(config, TUNE_VARY, trials=4, minimize=["lyapunov_final"], output=tmp_path, generation=4, startup=4,
         storage=url)
    result = tune(config, TUNE_VARY, trials=8, minimize=["lyapunov_final"], output=tmp_path, generation=4, startup=4)
    assert result.storage == url and result.n_trials == 8
    assert not (folder / "journal.db").exists()
    assert len(optuna.load_study(study_name="free_study", storage=url).trials) == 8


def test_scale_log_uniform_scales_a_whole_gain_vector(config):
    from rbstab.studies.design import parse_vary

    (v,) = parse_vary(["controller.l_t=scale_log_uniform:[0.01,100]"], config.resolved)
    assert v.factors == ["controller.l_t:scale"]
    values = v.from_unit(np.array([[0.0], [0.5], [1.0]]))
    np.testing.assert_allclose(values, np.outer([0.01, 1.0, 100.0], [210, 210, 140]))


def test_tune_on_the_cuda_simulator_equals_the_compiled_engine(tmp_path):
    """The same study (seed, generations) on the compiled engine and on the CUDA simulator
    (``NUMBA_ENABLE_CUDASIM=1``, a process of its own) gives the same trials, bit for bit."""
    import os
    import subprocess
    import sys

    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(FREE))
    rbstab_cli = str(Path(sys.executable).parent / "rbstab")
    tables = {}
    for engine in ("compiled", "cuda"):
        env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1" if engine == "cuda" else "0"}
        done = subprocess.run([rbstab_cli, "tune", str(path), "--trials", "6", "--generation", "3", "--startup", "3",
                               "--engine", engine, "-o", str(tmp_path / engine), "--minimize", "lyapunov_final", "-q",
                               "--subject-to", "final_omega_x<=1", *[f"--vary={v}" for v in TUNE_VARY]],
                              env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        tables[engine] = (tmp_path / engine / "free_study" / "trials.csv").read_text()
    assert tables["compiled"] == tables["cuda"]


# -- bad input ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("args, words", [
    (["sensitivity", "-n", "64", "--vary", "controller.k_q=uniform:[1,2]"], ["--vary", "'controller' has no 'k_q'", "allowed: variant, k_t"]),
    (["tune", "--trials", "5", "--vary", "initial_state.omega.x=uniform:[1,2]", "--minimize", "lyapunov_final"],
     ["--vary", "'initial_state.omega' is a list of 3; index it with 0..2, not 'x'"]),
    (["tune", "--trials", "5", "--vary", "body.mass=uniform:[30,50]", "--over", "disturbances.0.start=uniform:[0,1]",
      "--minimize", "lyapunov_final"], ["--over", "'disturbances' is not set, so it has no entry '0'"]),
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
    assert figures == ["sensitivity_free_study.png", "tuning_free_study_objective.png", "tuning_free_study_pareto.png",
                       "tuning_free_study_search.png"]
    page = (out / "summary.md").read_text()
    assert "where the study searched" in (out / "index.html").read_text()
    assert "Sensitivity study free_study (sobol)" in page and "Trials of the Pareto front" in page


def test_a_constant_metric_gets_one_line_and_no_indices(tmp_path):
    """A free body whose rotation starts at rest: its final Omega_x is the same (0) in every run."""
    from rbstab.studies.sensitivity import CONSTANT

    path = tmp_path / "rest.yaml"
    path.write_text(rbstab.config.dump_yaml({**FREE, "initial_state": {"v": [0.5, 0.3, 0.2]}}))
    args = ["sensitivity", str(path), "-n", "8", "-o", str(tmp_path), "-j", "1", "--json", "--no-progress",
            "--vary=controller.l_t=scale_uniform:[1,4]", "--vary=controller.k_t=scale_uniform:[0.5,2]",
            "--metric=final_omega_x", "--metric=final_velocity_x"]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
    constant, varying = lines
    assert constant["reason"] == CONSTANT and varying["reason"] is None
    assert all(v["ST"] is None and v["S1"] is None for v in constant["factors"].values())
    assert all(v["ST"] is not None for v in varying["factors"].values())
    assert f"final_omega_x [rad s-1] (sobol, 32 runs): {CONSTANT}" in result.output
    ds = read_sensitivity(tmp_path / "free_study")
    assert ds["reason"].values.tolist() == [CONSTANT, ""]
