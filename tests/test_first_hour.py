"""What a new user meets in the first hour: converged beside success, reasons with every
check, unreliable sensitivity indices flagged, self-describing sweep coordinates, scripts
that would re-run themselves, outputs that would replace each other, and the small ones."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import rbstab
from conftest import PAPER_CONFIGS
from rbstab_cli.main import cli

CASE1, CASE2, CASE3 = PAPER_CONFIGS
SHORT = ["--set", "simulation.t_end=0.2", "--set", "simulation.n_samples=21"]


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


# -- converged beside success ------------------------------------------------------------------


def test_run_and_show_say_whether_the_run_converged(tmp_path):
    moving = invoke("run", CASE2, "-o", tmp_path, *SHORT, "--no-warn", "W001", "--json")
    assert moving.exit_code == 0, moving.output
    assert "case2_visco_elastic: success, still settling (" in moving.stderr
    assert json.loads(moving.stdout)["converged"] is False
    assert json.loads(moving.stdout)["outcome"] == "still settling"
    settled = invoke("run", CASE2, "-o", tmp_path, "--set", "name=long", "--no-warn", "W001")
    assert "long: success, converged (" in settled.stdout
    shown = invoke("show", tmp_path / "case2_visco_elastic.h5")
    assert "status     success, still settling:" in shown.stdout


def test_robustness_speaks_of_converged_by_t_end_and_suggests_a_longer_t_end(tmp_path):
    from rbstab.analysis import robustness
    from rbstab.analysis.text import describe_robustness
    from rbstab.sweep import run_sweep, spec_from_mapping

    base = rbstab.load_config(CASE1, ["simulation.t_end=0.3", "simulation.n_samples=31"]).resolved
    spec = spec_from_mapping({"name": "short", "base": base, "grid": {"body.mass": [35.0, 41.0, 47.0]}})
    run_sweep(spec, tmp_path, jobs=1, progress=False)
    result = robustness(tmp_path / "short")
    (group,) = result.groups
    assert group.n_stable == 0 and group.t_end_hint is not None
    assert group.t_end_hint["settling_time"] > 0.3
    text = "\n".join(describe_robustness(result))
    assert "0 of 3 converged by t_end" in text and "stable =" not in text
    assert "t_end = 0.3 s may be too short" in text and "asymptotically stable" in text


# -- reasons with every check ------------------------------------------------------------------


def test_a_failed_rate_check_says_why_and_what_to_do(tmp_path):
    result = invoke("run", CASE1, "-o", tmp_path, "--no-warn", "W001", "--set", "simulation.t_end=20",
                    "--set", "simulation.n_samples=101")
    assert result.exit_code == 0, result.output
    line = result.stdout
    assert "rate check fail (largest |analytic - numerical dv/dt|" in line
    assert "at t = " in line and "the samples (spacing 0.2 s) do not resolve the fastest mode at rest" in line
    suggested = int(line.split("simulation.n_samples=")[1].split()[0])
    again = invoke("run", CASE1, "-o", tmp_path, "--no-warn", "W001", "--set", "simulation.t_end=20",
                   "--set", f"simulation.n_samples={suggested}", "--overwrite")
    assert "rate check pass" in again.stdout  # the fix it names works
    shown = invoke("show", tmp_path / "case1_permanent.h5", "--json")
    assert json.loads(shown.stdout)["rate_check_reason"] is None


def test_rate_check_reason_names_the_solver_noise_when_that_is_the_cause():
    from rbstab.diagnostics import rate_check_reason

    summary = {"lyapunov_rate_check": "fail", "lyapunov_rate_mismatch": 2.0, "lyapunov_rate_mismatch_relative": 0.01}
    assert "tighten it" in rate_check_reason(summary, n_samples=2001, t_end=2.0, rtol=1e-6)
    assert rate_check_reason({"lyapunov_rate_check": "pass"}, n_samples=2001, t_end=2.0, rtol=1e-8) == ""


# -- sensitivity that does not lie -------------------------------------------------------------


@pytest.fixture(scope="module")
def heavy_tailed():
    """A Sobol' design of the test_studies factors and a metric spanning nine decades."""
    from rbstab.studies.sensitivity import _attributes, analyze_results, plan_sensitivity
    from test_studies import FREE, VARY

    plan = plan_sensitivity(rbstab.load_config(FREE), VARY, n=64,
                            metrics=["lyapunov_final", "log10:lyapunov_final", "rank:lyapunov_final"])
    u = plan.unit
    y = 1e-9 * 10 ** (9 * u[:, 1] ** 4) * (1 + u[:, 2])
    results = xr.Dataset({"lyapunov_final": ("run", y, {"units": "J"}),
                          "status": ("run", np.full(len(y), "success"))})
    ds = analyze_results(plan, results)
    ds.attrs.update(_attributes(plan, results, 200, 0.95, None))
    return ds


def test_unreliable_sobol_indices_are_flagged_with_the_reason(heavy_tailed, tmp_path):
    from rbstab.studies import metric_records
    from rbstab.studies.files import write_study_file
    from rbstab_cli.sensitivity import _describe

    ds = heavy_tailed
    assert ds["metric"].values.tolist() == ["lyapunov_final", "log10:lyapunov_final", "rank:lyapunov_final"]
    raw = metric_records(ds)[0]
    l_t = raw["factors"]["controller.l_t:scale"]
    assert l_t["S1"] > 1.05 and l_t["S1_unreliable"] and l_t["ST_unreliable"]  # SALib's estimate, flagged
    assert not raw["factors"]["controller.k_c:scale"]["S1_unreliable"]
    assert raw["decades"] > 8 and "heavy tails" in raw["note"] and "log10:NAME" in raw["note"]
    logged = metric_records(ds)[1]
    assert logged["units"] == "1" and 0.8 < logged["factors"]["controller.l_t:scale"]["S1"] < 1.05
    assert "(!)" in _describe(raw)
    path = write_study_file(ds, tmp_path / "study" / "sensitivity.nc")
    back = rbstab.studies.read_sensitivity(path)
    assert int(back["S1_unreliable"].values[0, 1]) == 1 and "heavy tails" in str(back["note"].values[0])
    report = invoke("report", path, "-o", tmp_path / "report", "--format", "md")
    assert report.exit_code == 0, report.output
    page = (tmp_path / "report" / "index.md").read_text()
    assert "Warning: lyapunov_final: unreliable indices" in page and "(!)" in page


def test_an_unknown_metric_transform_is_refused():
    from rbstab.studies import StudyInputError
    from rbstab.studies.sensitivity import plan_sensitivity
    from test_studies import FREE, VARY

    with pytest.raises(StudyInputError, match=r"--metric 'sqrt:lyapunov_final': unknown transform 'sqrt'"):
        plan_sensitivity(rbstab.load_config(FREE), VARY, n=8, metrics=["sqrt:lyapunov_final"])


# -- coordinates that describe themselves -------------------------------------------------------


def test_open_sweep_coordinates_carry_units_long_name_and_config_key(tmp_path):
    result = invoke("sweep", CASE2, "--grid", "body.mass=30,40", "--grid", "controller.k_c:scale=0.5:1:2", "-o",
                    tmp_path, "-j", "1", *SHORT, "--no-warn", "all", "--no-progress")
    assert result.exit_code == 0, result.output
    for grid in (False, True):
        ds = rbstab.open_sweep(tmp_path / "case2_visco_elastic", grid=grid)
        assert ds["mass"].attrs == {"long_name": "mass m of the body", "config_key": "body.mass", "units": "kg"}
        assert ds["k_c_0"].attrs["units"] == "N m-1" and ds["k_c_0"].attrs["config_key"] == "controller.k_c.0"
    assert ds.sizes["mass"] == 2 and ds.sizes["k_c_0"] == 2
    np.testing.assert_allclose(ds["k_c_0"].values, [2050.0, 4100.0])  # Case 2's K_c x 0.5 and x 1


# -- scripts -------------------------------------------------------------------------------------


def test_a_script_calling_a_parallel_api_at_its_top_level_is_refused_before_anything(tmp_path):
    out = tmp_path / "written"
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent(f"""
        import rbstab
        print("top")
        rbstab.run({str(CASE2)!r}, {str(out)!r}, overrides=["simulation.t_end=0.1", "simulation.n_samples=11"])
        rbstab.analyze({str(CASE2)!r}, certificate=False, simulate=False, basin_samples=16, jobs=2,
                       basin=["initial_state.omega.0=-5:5:9", "initial_state.omega.1=-5:5:9"])  # threads: runs
        print("analysed")
        rbstab.sweep_dataset({str(CASE2.parents[1] / "sweeps" / "gains.yaml")!r}, {str(out)!r}, jobs=2)
        print("never")
    """))
    done = subprocess.run([sys.executable, "-W", "ignore", str(script)], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert done.returncode == 1 and done.stdout.count("top") == 1 and "never" not in done.stdout
    assert "analysed" in done.stdout, done.stderr
    assert f"rbstab.sweep_dataset() at the top level of {script} (line 8)" in done.stderr
    assert 'if __name__ == "__main__":' in done.stderr and "nothing was run" in done.stderr


def test_the_same_call_under_the_guard_is_not_refused(tmp_path):
    script = tmp_path / "guarded.py"
    script.write_text(textwrap.dedent("""
        from rbstab.sweep.executors import refuse_at_script_top_level
        if __name__ == "__main__":
            refuse_at_script_top_level()
            print("ok")
    """))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "ok" in done.stdout, done.stderr


def test_the_kernels_a_batch_calls_from_python_release_the_gil():
    from rbstab.engine.integrate import integrate_chunk
    from rbstab.summary import _apply_stencil
    from rbstab.variants.kernels import run_outputs

    assert all(f.targetoptions.get("nogil") for f in (integrate_chunk, run_outputs, _apply_stencil))


def test_the_thread_executor_yields_every_result_and_error_as_data_from_threads_of_this_process():
    import multiprocessing
    import threading

    from rbstab.sweep.executors import ThreadExecutor

    def work(item, power):
        if item == 3:
            raise ValueError("three")
        return item**power, threading.current_thread().name

    with ThreadExecutor(2) as executor:
        executor.plan(7)
        out = {item: (result, exc) for item, result, exc in executor.imap_unordered(work, range(7), 2)}
    assert sorted(out) == list(range(7)) and not multiprocessing.active_children()
    assert isinstance(out[3][1], ValueError) and out[3][0] is None
    assert all(out[i][0][0] == i**2 and out[i][0][1].startswith("rbstab") for i in out if i != 3)


# -- no silent replacement -------------------------------------------------------------------------


def test_a_report_of_other_inputs_is_not_replaced_and_the_same_inputs_rebuild_it(tmp_path):
    """The same set of inputs (in any order) rebuilds the report; a subset, a superset or
    another set of them is another comparison: refused, naming the folder and the inputs
    that differ, the report left as it was; --overwrite replaces it."""
    assert invoke("run", CASE1, CASE2, "-o", tmp_path, *SHORT, "-qq").exit_code == 0
    one, two = tmp_path / "case1_permanent.h5", tmp_path / "case2_visco_elastic.h5"
    out = tmp_path / "report"
    fast = ["-o", out, "--format", "md", "--no-animations", "-q"]
    assert invoke("report", one, two, *fast).exit_code == 0
    before = (out / "report.json").read_text()
    fewer = invoke("report", one, *fast)
    assert fewer.exit_code == 1 and f"{out} holds a report of other inputs" in fewer.stderr
    assert f"only there: {two.resolve()}" in fewer.stderr and "only here" not in fewer.stderr
    assert "--overwrite" in fewer.stderr and "-o DIR" in fewer.stderr and "Traceback" not in fewer.output
    assert (out / "report.json").read_text() == before
    rebuilt = invoke("report", two, one, *fast)  # the same inputs, another order
    assert rebuilt.exit_code == 0, rebuilt.output
    assert sorted(json.loads((out / "report.json").read_text())["inputs"]) == sorted(json.loads(before)["inputs"])
    assert invoke("report", one, *fast, "--overwrite").exit_code == 0
    more = invoke("report", one, two, *fast)
    assert more.exit_code == 1 and f"only here: {two.resolve()}" in more.stderr
    other = invoke("report", two, *fast)
    assert other.exit_code == 1 and f"only here: {two.resolve()}" in other.stderr
    assert f"only there: {one.resolve()}" in other.stderr and "Traceback" not in other.output
    assert json.loads((out / "report.json").read_text())["inputs"] == [str(one.resolve())]


def test_a_cli_sweep_with_another_grid_does_not_replace_the_first(tmp_path):
    common = ["-o", tmp_path, "-j", "1", *SHORT, "--no-warn", "all", "--no-progress", "-q"]
    assert invoke("sweep", CASE2, "--grid", "body.mass=30,40", *common).exit_code == 0
    index = (tmp_path / "case2_visco_elastic" / "index.csv").read_text()
    assert invoke("sweep", CASE2, "--grid", "body.mass=30,40", *common).exit_code == 0  # the same: resumes
    other = invoke("sweep", CASE2, "--grid", "body.mass=50,60", *common)
    assert other.exit_code == 1 and "holds a sweep with 2 of its 2 runs not in this one" in other.stderr
    assert "--overwrite" in other.stderr and "sweep.name" in other.stderr
    assert (tmp_path / "case2_visco_elastic" / "index.csv").read_text() == index
    assert invoke("sweep", CASE2, "--grid", "body.mass=50,60", *common, "--overwrite").exit_code == 0


# -- the smaller ones ------------------------------------------------------------------------------


def test_grid_ranges(tmp_path):
    from rbstab_cli.sweep import grid_values

    assert grid_values("body.mass", "30:60:4") == "30.0,40.0,50.0,60.0"
    assert grid_values("simulation.rtol", "log:1e-10:1e-6:5") == "1e-10,1e-09,1e-08,1e-07,1e-06"
    assert grid_values("body.mass", "30,41") == "30,41"
    bad = invoke("sweep", CASE2, "--grid", "body.mass=log:0:60:4", "-o", tmp_path, "--dry-run")
    assert bad.exit_code == 1 and "--grid body.mass=log:0:60:4: expected LO:HI:N" in bad.stderr
    assert "Traceback" not in bad.output and not (tmp_path / "case2_visco_elastic").exists()


def test_wall_time_is_the_runs_own_without_loading_the_kernels(tmp_path):
    result = invoke("run", CASE1, CASE2, "-o", tmp_path, *SHORT, "--no-warn", "W001", "--json", "-v")
    walls = [json.loads(line)["wall_time"] for line in result.stdout.splitlines()]
    assert "compiled kernels loaded in" in result.stderr
    assert walls[0] < 0.1, walls  # was ~0.3-0.7 s: numba's cache and scipy.optimize loaded in the first run


def test_a_closed_pipe_ends_quietly(tmp_path):
    assert invoke("run", CASE2, "-o", tmp_path, *SHORT, "-qq").exit_code == 0
    show = subprocess.Popen([sys.executable, "-m", "rbstab", "show", str(tmp_path), str(tmp_path),
                             str(tmp_path / "case2_visco_elastic.h5")], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    show.stdout.readline()
    show.stdout.close()  # as `| head -1` does
    _, err = show.communicate(timeout=120)
    assert show.returncode == 0 and b"Broken pipe" not in err, err


def test_quiet_show_keeps_the_results(tmp_path):
    assert invoke("run", CASE2, "-o", tmp_path, *SHORT, "-qq").exit_code == 0
    quiet = invoke("show", tmp_path / "case2_visco_elastic.h5", "-q")
    assert "status     success" in quiet.stdout
    assert invoke("show", tmp_path / "case2_visco_elastic.h5", "-qq").stdout == ""


def test_round_off_prints_as_zero_and_no_sublevel_line_without_an_estimate():
    from rbstab.analysis.text import format_state
    from rbstab.layout import FULL_BODY

    y = np.zeros(12)
    y[0], y[1] = 7.3633e-23, 0.25
    assert format_state(FULL_BODY, y).startswith("theta (0, 0.25, 0) rad")
    unstable = rbstab.analyze(rbstab.load_config(CASE1, ["body.attachment_point=[0, 0, -0.42]",
                                                         "controller.k_r=[10, 10, 10]"]),
                              basin=["initial_state.omega.0=-1:1:3", "initial_state.omega.1=-1:1:3"],
                              basin_samples=21, samples=200)
    from rbstab.analysis.text import describe

    lines = describe(unstable)
    assert not any("inside the sublevel estimate: 0 points, all converged" in line for line in lines)


def test_an_initial_angle_beyond_two_pi_warns(tmp_path):
    result = invoke("validate", CASE2, "--set", "initial_state.theta=[45, 0, 0]", "--no-warn", "W001")
    assert result.exit_code == 0
    assert "warning: W005 initial_state.theta: theta[0] = 45 rad (7.16 turns)" in result.stderr
    assert "W005" not in invoke("validate", CASE2, "--no-warn", "W001").stderr


def test_summary_md_is_plain_markdown(tmp_path):
    from rbstab.report.render import _md_escape

    assert _md_escape("converged: v(t_end) <= 0.001 v(0), it's K_r > m g L") == \
        "converged: v(t_end) <= 0.001 v(0), it's K_r > m g L"
    assert _md_escape("<script>") == "&lt;script&gt;"  # what markdown would read as HTML stays text
    assert invoke("run", CASE2, "-o", tmp_path, *SHORT, "-qq").exit_code == 0
    assert invoke("report", tmp_path / "case2_visco_elastic.h5", "-o", tmp_path / "r", "--no-animations",
                  "-q").exit_code == 0
    text = (tmp_path / "r" / "summary.md").read_text()
    assert "&lt;" not in text and "&#x27;" not in text and "&amp;" not in text


def test_a_tuned_value_at_the_edge_of_its_range_warns_and_values_have_units(tmp_path):
    from rbstab.studies.design import parse_vary
    from rbstab.studies.tuning import edge_warnings
    from test_studies import FREE

    config = rbstab.load_config(FREE)
    varied = parse_vary(["controller.l_t=scale_uniform:[0.5,4]", "body.mass=uniform:[30,50]"], config.resolved)
    base = np.asarray(config.resolved["controller"]["l_t"], dtype=float)
    best = {**{f"controller.l_t[{i}]": 3.99 * b for i, b in enumerate(base)}, "body.mass": 40.0}
    (line,) = edge_warnings(varied, best)
    assert line.startswith("W006 controller.l_t:scale: the best value 3.99 lies at the upper edge")
    assert edge_warnings(varied, {**best, **{f"controller.l_t[{i}]": 2 * b for i, b in enumerate(base)}}) == []
    path = tmp_path / "free.yaml"
    path.write_text(rbstab.config.dump_yaml(config.resolved))
    result = invoke("tune", path, "--trials", "3", "-o", tmp_path, "--minimize", "lyapunov_final",
                    "--vary", "body.mass=uniform:[30,50]", "--storage", "memory")
    assert result.exit_code == 0, result.output
    assert " J" in result.stdout.split("best trial")[1].splitlines()[0]  # the best value with its units
    assert "body.mass = " in result.stdout and " kg" in result.stdout


def test_the_report_says_converged_beside_the_status(tmp_path):
    assert invoke("run", CASE2, "-o", tmp_path, *SHORT, "-qq").exit_code == 0
    assert invoke("report", tmp_path / "case2_visco_elastic.h5", "-o", tmp_path / "r", "--format", "md",
                  "--no-animations", "-q").exit_code == 0
    page = (tmp_path / "r" / "index.md").read_text()
    assert "| status | outcome |" in page and "| success | still settling |" in page


def test_analyze_does_not_replace_the_analysis_of_another_configuration(tmp_path):
    fast = ["--no-certificate", "--no-simulation", "-o", tmp_path, "-q"]
    assert invoke("analyze", CASE2, *fast).exit_code == 0
    path = tmp_path / "case2_visco_elastic.analysis.nc"
    before = path.read_bytes()
    other = invoke("analyze", CASE2, *fast, "--set", "body.mass=50")
    assert other.exit_code == 1 and "holds the analysis of a different configuration" in other.stderr
    assert "--overwrite" in other.stderr and path.read_bytes() == before
    assert invoke("analyze", CASE2, *fast).exit_code == 0  # the same configuration: replaced
    assert invoke("analyze", CASE2, *fast, "--set", "body.mass=50", "--overwrite").exit_code == 0


def test_a_study_of_other_inputs_is_not_replaced(tmp_path):
    from rbstab.studies import StudyInputError, sensitivity_analysis
    from test_studies import FREE

    config = rbstab.load_config(FREE)
    first = sensitivity_analysis(config, ["body.mass=uniform:[30,50]"], n=4, metrics=["lyapunov_final"],
                                 output=tmp_path, jobs=1)
    before = open(first.attrs["path"], "rb").read()
    with pytest.raises(StudyInputError, match=r"holds a study of other inputs \(vary differ\): not replaced"):
        sensitivity_analysis(config, ["body.mass=uniform:[30,60]"], n=4, metrics=["lyapunov_final"], output=tmp_path,
                             jobs=1)
    assert open(first.attrs["path"], "rb").read() == before
    sensitivity_analysis(config, ["body.mass=uniform:[30,50]"], n=4, metrics=["final_omega_x"], output=tmp_path,
                         jobs=1)  # the same runs again: resumed
    sensitivity_analysis(config, ["body.mass=uniform:[30,60]"], n=4, metrics=["lyapunov_final"], output=tmp_path,
                         jobs=1, overwrite=True)
