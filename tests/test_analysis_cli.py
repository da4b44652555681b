"""``rbstab analyze`` end to end: JSON records, analysis files, errors, robustness of a sweep, report pages."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
from conftest import ROOT

from rbstab.analysis import read_analysis, robustness, wilson_interval
from rbstab.analysis.robustness import separation
from rbstab_cli.main import cli

CASE1 = str(ROOT / "configs/paper/case1_permanent.yaml")
CASE3 = str(ROOT / "configs/paper/case3_embedded.yaml")
SLIDING = str(ROOT / "configs/examples/sliding.yaml")


def _invoke(*args):
    return CliRunner().invoke(cli, ["analyze", *args], catch_exceptions=False)


def _strict(text: str) -> dict:
    """A JSON record, refusing NaN and Infinity (not JSON)."""
    def refuse(name):
        raise ValueError(f"{name} in a JSON record")

    return json.loads(text, parse_constant=refuse)


def test_json_records_and_files(tmp_path):
    out = tmp_path / "analysis"
    result = _invoke(CASE1, CASE3, "-o", str(out), "--json", "--samples", "500", "--basin",
                     "initial_state.omega.0=-30:30:3", "--basin", "initial_state.omega.1=-30:30:3", "-j", "1")
    assert result.exit_code == 0, result.output
    records = [_strict(line) for line in result.stdout.splitlines()]
    assert [r["name"] for r in records] == ["case1_permanent", "case3_embedded"]
    for r in records:
        assert {"name", "variant", "equilibrium", "eigenvalues", "verdict"} <= set(r)
        assert r["verdict"] == "asymptotically stable" and r["certificate"]["holds"]
        real = [re for re, _ in r["eigenvalues"]]
        assert real == sorted(real, reverse=True) and len(real) == len(r["equilibrium"])
        assert r["basin"]["shape"] == [3, 3]
    assert len(records[0]["equilibrium"]) == 6 and records[0]["equilibrium"][0] != 0  # reduced state, gravity
    assert "asymptotically stable" in result.stderr  # the text goes to stderr with --json
    ds = read_analysis(out / "case3_embedded.analysis.nc")
    assert ds.attrs["verdict"] == "asymptotically stable" and ds.attrs["rbstab_format"] == "rbstab-analysis-1"
    mixed = {"jacobian", "jacobian_error", "lyapunov_hessian", "rate_hessian", "hessian_min_eigenvalue"}
    for name, var in ds.data_vars.items():  # CF units on numbers whose entries share them (not per state), not text
        assert "long_name" in var.attrs, name
        assert ("units" in var.attrs) == (var.dtype.kind in "fiub" and name not in mixed), name
    assert ds["equilibrium_omega"].attrs["units"] == "rad s-1"
    assert ds["basin_outcome"].shape == (3, 3) and ds["basin_x"].attrs["config_key"] == "initial_state.omega.0"
    s = ds["eigenvalue_real"].values + 1j * ds["eigenvalue_imag"].values
    np.testing.assert_allclose(s, [complex(*e) for e in records[1]["eigenvalues"]])
    with xr.open_dataset(out / "case1_permanent.analysis.nc", engine="h5netcdf") as plain:  # a netCDF-4 file
        assert plain.sizes["state"] == 6


def test_sign_law_says_the_linearisation_does_not_exist(tmp_path):
    result = _invoke(SLIDING, "--set", "controller.boundary_layer=0", "-o", str(tmp_path), "--json",
                     "--no-certificate", "--no-simulation", "--boundary-layer", "0.002")
    assert result.exit_code == 0, result.output
    record = _strict(result.stdout)
    assert record["analysed_boundary_layer"] == 0.002
    assert "linearisation does not exist" in record["notes"][0]
    assert "linearisation does not exist" in result.stderr


@pytest.mark.parametrize("args, message", [
    (["--basin", "initial_state.omega.0=-1:1:3"], "exactly twice"),
    (["--basin", "initial_state.x.0=-1:1:3", "--basin", "initial_state.omega.0=-1:1:3"], "not a state of this variant"),
    (["--basin", "initial_state.omega.0=1:-1:3", "--basin", "initial_state.omega.1=-1:1:3"], "lo < hi"),
    (["--set", "controller.k_r=[1, 2]"], "controller.k_r"),
    (["--boundary-layer", "0.001"], "not the pure sign law"),
    ([SLIDING, "--boundary-layer", "0.001"], "case1_permanent: --boundary-layer"),  # checked before any runs
    (["--robustness", "."], "not a sweep folder"),
])
def test_bad_input_is_a_clear_error_and_writes_nothing(tmp_path, args, message):
    result = CliRunner().invoke(cli, ["analyze", CASE1, "-o", str(tmp_path / "out"), *args])
    assert result.exit_code != 0
    assert message in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists()


def test_wilson_interval_and_separation():
    lo, hi = wilson_interval(7, 10, 0.95)  # the textbook example: 0.3968 .. 0.8922
    assert lo == pytest.approx(0.39677, abs=1e-4) and hi == pytest.approx(0.89221, abs=1e-4)
    assert wilson_interval(0, 20) == (0.0, pytest.approx(0.16113, abs=1e-4))
    assert wilson_interval(20, 20)[1] == 1.0
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, 200)
    stable = x > 0.4
    s = separation("k", x, stable)
    assert s.auc == 1.0 and s.stable_side == "above" and s.balanced_accuracy == 1.0
    assert x[~stable].max() < s.threshold < x[stable].min()
    noise = separation("noise", rng.uniform(0, 1, 200), stable)
    assert abs(noise.auc - 0.5) < 0.15 and noise.strength < 0.3
    # AUC against the brute force over all pairs
    a, b = x[stable], x[~stable]
    brute = np.mean((a[:, None] > b[None, :]) + 0.5 * (a[:, None] == b[None, :]))
    assert separation("k", np.round(x, 1), stable).auc == pytest.approx(
        np.mean((np.round(a, 1)[:, None] > np.round(b, 1)[None, :]) + 0.5 * (np.round(a, 1)[:, None] ==
                                                                             np.round(b, 1)[None, :])))
    assert brute == 1.0


@pytest.fixture(scope="module")
def pendulum_sweep(tmp_path_factory):
    """A sweep over K_r of the pinned inverted pendulum: unstable below k_r = m g L = 172 N m/rad."""
    from rbstab.config import load_config
    from rbstab.sweep import run_sweep, spec_from_mapping

    base = load_config(CASE1, ["body.attachment_point=[0, 0, -0.42]", "controller.k_t=[0, 0, 0]",
                               "controller.l_t=[0, 0, 0]", "initial_state.omega=[0.5, 0.5, 0]",
                               "simulation.t_end=10", "simulation.n_samples=101"]).resolved
    spec = spec_from_mapping({"name": "pendulum", "base": base, "grid": {}, "zip": {},
                              "random": {"n": 24, "seed": 1, "params": {
                                  "controller.k_r": {"scale_uniform": [0.1, 1.5]},
                                  "body.mass": {"scale_uniform": [0.9, 1.1]}}}})
    folder = tmp_path_factory.mktemp("sweeps")
    run_sweep(spec, folder, jobs=1, progress=False)
    return folder / "pendulum"


def test_robustness_of_a_sweep(pendulum_sweep, tmp_path):
    result = robustness(pendulum_sweep)
    (group,) = result.groups
    assert group.n_runs == 24 and 0 < group.n_stable < 24
    lo, hi = group.interval
    assert lo < group.fraction < hi
    best = group.separations[0]
    assert best.parameter in ("k_r_scale", "k_r_0", "k_r_1", "k_r_2") and best.stable_side == "above"
    assert best.auc > 0.9
    # the linearisation agrees: k_r above m g L (172 N m/rad for m = 41 kg) holds the pendulum up
    assert best.balanced_accuracy > 0.9
    # the sweep's own 'converged' (|v(t_end)| <= ratio |v(0)|) does not count the fallen pendulums (v < 0)
    assert group.n_disagree == 0
    cli_result = _invoke("--robustness", str(pendulum_sweep), "-o", str(tmp_path), "--json")
    assert cli_result.exit_code == 0, cli_result.output
    record = _strict(cli_result.stdout)
    assert record["kind"] == "robustness" and record["groups"][0]["n_stable"] == group.n_stable
    ds = read_analysis(tmp_path / "pendulum.robustness.analysis.nc")
    assert ds.attrs["kind"] == "robustness" and ds["auc"].sizes["parameter"] >= 2
    # a threshold only where it explains which runs converged: k_r's does, the mass's (+-10 %) does not
    by_name = {s["parameter"]: s for s in record["groups"][0]["separations"]}
    assert by_name[best.parameter]["explains"] and by_name[best.parameter]["stable_side"] == "above"
    weak = [s for s in group.separations if s.rule.balanced_accuracy < 0.9]
    assert weak and all(not by_name[s.parameter]["explains"] for s in weak)
    text = _invoke("--robustness", str(pendulum_sweep), "-o", str(tmp_path / "text"))
    lines = {line.split(":")[0].strip(): line for line in text.output.splitlines() if line.startswith("    ")}
    assert f"converged where x > " in lines[best.parameter], lines
    assert all("no threshold (best: balanced accuracy" in lines[s.parameter] for s in weak), lines
    j = list(ds["parameter"].values).index(best.parameter)
    assert str(ds["rule_side"].values[0, j]) == "above" and bool(ds["rule_explains"].values[0, j])


def test_a_run_at_rest_beside_an_unstable_equilibrium_is_not_stable(tmp_path):
    """The inverted pendulum started upright at rest never moves: v stays 0 and converges
    by the rule, but with K_r below m g L = 172 N m/rad its rest state is unstable. Robustness
    counts such runs as unstable rests, not stable; with K_r above it they are stable."""
    from rbstab.config import load_config
    from rbstab.sweep import run_sweep, spec_from_mapping

    base = load_config(CASE1, ["body.attachment_point=[0, 0, -0.42]", "controller.k_t=[0, 0, 0]",
                               "controller.l_t=[0, 0, 0]", "initial_state.omega=[0, 0, 0]",
                               "simulation.t_end=1", "simulation.n_samples=11"]).resolved
    k_r = [80.0, 120.0, 400.0, 480.0]
    spec = spec_from_mapping({"name": "upright", "base": base, "grid": {},
                              "zip": {"controller.k_r.0": k_r, "controller.k_r.1": k_r}})
    run_sweep(spec, tmp_path, jobs=1, progress=False)
    result = robustness(tmp_path / "upright")
    (group,) = result.groups
    assert (group.n_runs, group.n_stable, group.n_unstable_rest) == (4, 2, 2)
    assert group.n_disagree == 0  # the sweep's own 'converged' says all 4: v never left 0
    assert group.separations and all(s.rule.explains and s.rule.side == "above" and 120 < s.rule.low < 400
                                     for s in group.separations)
    text = _invoke("--robustness", str(tmp_path / "upright"), "-o", str(tmp_path / "out"))
    assert "2 more converged beside an unstable rest state" in text.output, text.output


def test_report_pages(tmp_path, pendulum_sweep):
    out = tmp_path / "analysis"
    assert _invoke(CASE3, "-o", str(out), "--samples", "300", "-j", "1", "--basin", "initial_state.omega.0=-20:20:3",
                   "--basin", "initial_state.omega.1=-20:20:3", "--robustness", str(pendulum_sweep)).exit_code == 0
    report = tmp_path / "report"
    result = CliRunner().invoke(cli, ["report", str(out), "-o", str(report), "--format", "html", "--format", "md"])
    assert result.exit_code == 0, result.output
    page = (report / "index.md").read_text()
    for text in ("Stability analysis: case3_embedded", "Eigenvalues of the Jacobian", "Lyapunov certificate",
                 "basin map", "Robustness: sweep pendulum", "Parameters that separate"):
        assert text in page, text
    figures = {p.name for p in (report / "figures").glob("*.png")}
    assert {"analysis_case3_embedded_poles.png", "analysis_case3_embedded_basin.png",
            "analysis_case3_embedded_sampled_rate.png", "robustness_pendulum.png"} <= figures
    manifest = json.loads((report / "report.json").read_text())
    assert len(manifest["analyses"]) == 2


def test_unstable_configuration_is_reported_not_refused(tmp_path):
    result = _invoke(CASE1, "-o", str(tmp_path), "--json", "--samples", "100", "--set", "name=pendulum",
                     "--set", "body.attachment_point=[0, 0, -0.42]", "--set", "controller.k_t=[0, 0, 0]",
                     "--set", "controller.l_t=[0, 0, 0]", "--set", "controller.k_r=[100, 100, 100]")
    assert result.exit_code == 0, result.output  # the verdict is data
    record = _strict(result.stdout)
    assert record["verdict"] == "unstable" and record["eigenvalues"][0][0] > 0
    assert record["certificate"]["holds"] is False and record["certificate"]["sublevel"] == 0.0
    # its time scale is the growing mode's e-folding time 1/Re(s), in the text, the record and the file;
    # no time constant for it, none negative
    e_fold = 1.0 / record["eigenvalues"][0][0]
    assert record["shortest_e_folding_time"] == pytest.approx(e_fold) and record["slowest_time_constant"] is None
    growing = [re > 0 for re, _ in record["eigenvalues"]]
    assert [t is None for t in record["time_constant"]] == growing
    assert [t is not None for t in record["e_folding_time"]] == growing
    assert min(t for t in record["time_constant"] + record["e_folding_time"] if t is not None) > 0
    assert f"unstable: e-folding time {e_fold:.4g} s" in result.stderr
    ds = read_analysis(tmp_path / "pendulum.analysis.nc")
    assert ds.attrs["verdict"] == "unstable"
    assert np.isnan(ds["slowest_time_constant"]) and float(ds["shortest_e_folding_time"]) == pytest.approx(e_fold)
    assert np.isnan(ds["time_constant"][0]) and float(ds["e_folding_time"][0]) == pytest.approx(e_fold)
    assert np.isnan(ds["linear_settling_time"]) and ds["e_folding_time"].attrs["units"] == "s"
    report = tmp_path / "report"
    shown = CliRunner().invoke(cli, ["report", str(tmp_path / "pendulum.analysis.nc"), "-o", str(report),
                                     "--format", "md"])
    assert shown.exit_code == 0, shown.output
    page = (report / "index.md").read_text()
    assert f"- unstable: e-folding time {e_fold:.4g} s; simulation from the configured initial state: not converged" \
        in page and "slowest" not in page
    assert "| tau [s] | e-folding time [s] |" in page and f"| - | {e_fold:.4g} |" in page


def test_marginal_configuration_has_no_time_scale(tmp_path):
    """No rotational stiffness nor damping about the twist axis of the stance example: two
    zero eigenvalues, a marginal verdict, no time constant or e-folding time for them, and
    none for the equilibrium: text, record and file."""
    result = _invoke(str(ROOT / "configs/examples/stance_ankle.yaml"), "-o", str(tmp_path), "--json",
                     "--no-certificate", "--set", "controller.k_r=[1300, 1300, 0]",
                     "--set", "controller.l_r=[350, 350, 0]")
    assert result.exit_code == 0, result.output
    record = _strict(result.stdout)
    assert record["verdict"] == "marginal"
    zero = [abs(re) <= record["tolerance"] for re, _ in record["eigenvalues"]]
    assert sum(zero) == 2 and not record["eigenvalues"][0][0] > record["tolerance"]
    assert [t is None for t in record["time_constant"]] == zero and all(t is None for t in record["e_folding_time"])
    assert record["slowest_time_constant"] is None and record["shortest_e_folding_time"] is None
    assert "  marginally stable (a zero or imaginary eigenvalue); the simulation" in result.stderr
    assert "time constant" not in result.stderr and "e-folding time" not in result.stderr
    ds = read_analysis(tmp_path / "stance_ankle.analysis.nc")
    assert ds.attrs["verdict"] == "marginal"
    assert np.isnan(ds["slowest_time_constant"]) and np.isnan(ds["shortest_e_folding_time"])
    tau = ds["time_constant"].values
    assert np.isnan(tau[zero]).all() and np.isfinite(tau[~np.array(zero)]).all()
