"""A stiff mode said before it runs (W008)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import ROOT
from rbstab.analysis.stiffness import STABILITY_LIMIT
from rbstab.engine.tableaus import TABLEAUS
from rbstab_cli.main import cli

KNEE = ROOT / "configs" / "examples" / "knee.yaml"
STIFF_KNEE = ["--set", "joints.knee.k_r=[1e11, 1e11, 1e11]"]  # N m/rad: |s| 5.57e6 1/s
SHIPPED = sorted((ROOT / "configs").glob("*/*.yaml"))



def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


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
