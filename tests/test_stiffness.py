"""A stiff mode said before it runs (W008), and the rate check's samples against the fastest mode."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from conftest import ROOT
from rbstab.analysis.stiffness import STABILITY_LIMIT
from rbstab.config.schema import MAX_SAMPLES
from rbstab.diagnostics import rate_check_reason
from rbstab.engine.tableaus import TABLEAUS
from rbstab_cli.main import cli

KNEE = ROOT / "configs" / "examples" / "knee.yaml"
STIFF_KNEE = ["--set", "joints.knee.k_r=[1e11, 1e11, 1e11]"]  # N m/rad: |s| 5.57e6 1/s
SHIPPED = sorted((ROOT / "configs").glob("*/*.yaml"))

#: A standing triple inverted pendulum (ankle, knee, hip; segments of a 70 kg, 1.75 m adult
#: after Winter's table, both legs together, their lateral offset of 0.09 m in J_y and J_z),
#: with the default samples (2001) over 5 s: its fastest mode, |s| 826 1/s, is not resolved.
TRIPLE = {
    "name": "triple",
    "gravity": [0.0, 0.0, -9.81],
    "bodies": [{"name": "shanks", "mass": 6.51, "inertia": [0.110, 0.163, 0.066]},
               {"name": "thighs", "mass": 14.0, "inertia": [0.270, 0.383, 0.15]},
               {"name": "trunk", "mass": 47.46, "inertia": [2.97, 2.97, 0.42]}],
    "joints": [
        {"name": "ankle", "parent": "ground", "parent_point": [0, 0, 0], "child": "shanks",
         "child_point": [0, 0, -0.244], "variant": "permanent", "k_r": [1500, 1500, 100], "l_r": [300, 300, 30]},
        {"name": "knee", "parent": "shanks", "parent_point": [0, 0, 0.186], "child": "thighs",
         "child_point": [0, 0, -0.243], "variant": "permanent", "k_r": [1000, 1000, 100], "l_r": [100, 100, 20]},
        {"name": "hip", "parent": "thighs", "parent_point": [0, 0, 0.186], "child": "trunk",
         "child_point": [0, 0, -0.316], "variant": "permanent", "k_r": [500, 500, 100], "l_r": [100, 100, 20]},
    ],
    "initial_state": {"shanks": {"theta": [0.03, 0, 0]}, "thighs": {"theta": [0, 0, 0]},
                      "trunk": {"theta": [-0.05, 0, 0]}},
    "simulation": {"t_end": 5.0},
}
#: What the triple pendulum's failed rate check says (the fastest mode's time constant, the samples).
UNRESOLVED = ("likely the samples (spacing 0.0025 s) do not resolve the fastest mode at rest (time constant "
              "1/|s| 0.0012 s): 28001 samples resolve it, e.g. --set simulation.n_samples=28001")
#: A failed rate check's reason: the mismatch against the tolerance, then the fix.
REASON = re.compile(r"rate check fail: largest \|analytic - numerical dv/dt\| \S+ W = \S+ P > 0.001 P; likely .*"
                    r"--set simulation\.n_samples=\d+")


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def triple(tmp_path_factory):
    path = tmp_path_factory.mktemp("triple") / "triple.yaml"
    path.write_text(yaml.safe_dump(TRIPLE), encoding="utf-8")
    return path


@pytest.mark.parametrize("method", sorted(STABILITY_LIMIT))
def test_stability_limits_are_the_edges_of_the_methods_stability_regions(method):
    """|R(-x)| <= 1 up to the limit and > 1 just beyond, R the stability function of the tableau."""
    t = TABLEAUS[method]
    n = len(t.B)
    a = np.zeros((n, n))
    a[:, : t.A.shape[1]] = t.A[:n]

    def gain(x):
        return abs(1.0 - x * t.B @ np.linalg.solve(np.eye(n) + x * a, np.ones(n)))

    limit = STABILITY_LIMIT[method]
    assert all(gain(x) <= 1.0 + 1e-12 for x in np.linspace(0.01, 0.998 * limit, 400))
    assert gain(1.002 * limit) > 1.0


def test_a_stiff_gain_is_warned_before_it_runs_with_its_time_constant_and_an_implicit_method(tmp_path):
    result = invoke("run", KNEE, "-o", tmp_path, *STIFF_KNEE, "--set", "simulation.max_steps=200")
    assert result.exit_code == 3, result.output  # stopped at the step limit, as the warning said
    lines = [line for line in result.stderr.splitlines() if "W008" in line]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("warning: W008 simulation.method: the fastest mode at rest, |s| 5.57e+06 1/s "
                               "(time constant 1/|s| 1.8e-07 s), holds DOP853 to steps of ~1.1e-06 s: ~4.4e+06 steps "
                               "to t_end 5 s, more than simulation.max_steps 200: it stops before t_end"), lines
    assert lines[0].endswith("--set simulation.method=Radau"), lines
    assert result.output.index("W008") < result.output.index("knee: failed")  # before the run
    quiet = invoke("validate", KNEE, *STIFF_KNEE, "--set", "simulation.method=Radau")
    assert quiet.exit_code == 0 and "W008" not in quiet.stderr, quiet.output
    assert "W008" not in invoke("validate", KNEE, *STIFF_KNEE, "--no-warn", "W008").stderr


def test_no_shipped_config_or_sweep_is_warned_stiff():
    result = invoke("validate", *SHIPPED)
    assert result.exit_code == 0, result.output
    assert "ok: sweep robustness" in result.stdout and "ok: knee" in result.stdout
    assert "W008" not in result.stderr


def test_a_sweep_warns_once_per_template_before_it_runs(tmp_path):
    grid = ["--grid", "joints.knee.k_r.0=1e11,2e11", "--grid", "simulation.method=DOP853,RK45"]
    planned = invoke("sweep", KNEE, *STIFF_KNEE, *grid, "--dry-run")
    assert planned.exit_code == 0, planned.output
    lines = [line for line in planned.stderr.splitlines() if "W008" in line]
    assert len(lines) == 2, planned.stderr  # 4 runs, 2 templates (one per method)
    assert "holds DOP853 to steps" in lines[0] and "(base knee, run r0000-" in lines[0]
    assert "holds RK45 to steps" in lines[1] and "(base knee, run r0001-" in lines[1]
    ran = invoke("sweep", KNEE, *STIFF_KNEE, "--grid", "joints.knee.k_r.0=1e11,2e11",
                 "--set", "simulation.max_steps=100", "-o", tmp_path, "-j", "1")
    assert ran.exit_code == 3, ran.output  # both stopped at the step limit: not computed
    assert ran.stderr.count("W008") == 1 and ran.stderr.index("W008") < ran.stderr.index("2 runs on 1 local process")


def test_a_rate_check_that_does_not_resolve_the_fastest_mode_says_so_and_what_to_set(triple, tmp_path):
    result = invoke("run", triple, "-o", tmp_path)
    assert result.exit_code == 0, result.output
    assert "rate check fail (largest |analytic - numerical dv/dt| 0.862 W = 0.09 P > 0.001 P at t = 0 s; " \
           f"{UNRESOLVED} (docs/physics.md))" in result.stdout
    assert "rate check pass" in invoke("run", triple, "-o", tmp_path, "--set", "simulation.n_samples=28001",
                                        "--overwrite").stdout


def test_a_fastest_mode_no_run_can_sample_gives_the_longest_t_end_that_resolves_it():
    failed = {"lyapunov_rate_check": "fail", "lyapunov_rate_mismatch": 3.4e13, "lyapunov_rate_mismatch_relative": 1.0}
    reason = rate_check_reason(failed, n_samples=10001, t_end=5.0, rtol=1e-9, fastest=5.57e6)
    assert reason.endswith(f"which takes 1.9e+08 samples, more than a run holds ({MAX_SAMPLES}): set "
                           "simulation.t_end <= 0.27 s, or a softer gain (docs/physics.md)"), reason
    resolved = rate_check_reason(failed, n_samples=10001, t_end=5.0, rtol=1e-9, fastest=100.0)  # 0.05 of 1/|s|
    assert resolved == rate_check_reason(failed, n_samples=10001, t_end=5.0, rtol=1e-9)
    assert "too sparse" in resolved


def test_every_listing_of_a_failed_rate_check_gives_its_reason(triple, tmp_path):
    import rbstab

    swept = invoke("sweep", triple, "--grid", "bodies.trunk.mass=40,47.46", "-o", tmp_path, "-j", "1")
    assert swept.exit_code == 0, swept.output
    folder = tmp_path / "triple"
    store = next((folder / "runs").glob("chunk-*.h5"))
    for shown in (invoke("show", folder), invoke("show", store)):
        assert shown.exit_code == 0, shown.output
        lines = shown.stdout.splitlines()
        failed = [i for i, line in enumerate(lines) if line.rstrip().endswith("  fail")]
        assert len(failed) == 2, shown.stdout
        assert all(REASON.search(lines[i + 1]) for i in failed), shown.stdout
    run = invoke("run", triple, "-o", tmp_path / "runs")
    assert run.exit_code == 0, run.output
    report = rbstab.write_report(tmp_path / "runs" / "triple.h5", tmp_path / "report", formats=("md",), jobs=1)
    summary = (report / "summary.md").read_text()
    assert f"- triple: rate check fail: largest \\|analytic - numerical dv/dt\\| 0.862 W = 0.09 P > 0.001 P at " \
           f"t = 0 s; {UNRESOLVED}".replace("|s|", "\\|s\\|") in summary
