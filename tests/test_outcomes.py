"""How a run ended, in one vocabulary: a fall reads as a fall, a push from rest converges,
a run moving away is told apart from one still settling, in run, show, a sweep's line and
index, and the report (:mod:`rbstab.diagnostics`, :mod:`rbstab.convergence`)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from rbstab.convergence import converged, lyapunov_reference
from rbstab.diagnostics import (CONVERGED, FELL, MOVING_AWAY, NOT_COMPUTED, OUTCOMES, PENDING, SETTLING, outcome,
                                outcomes)
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
STANCE = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
STANCE_ONE = ROOT / "configs" / "examples" / "stance_ankle.yaml"

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


# -- the rule and the words --------------------------------------------------------------------
def test_the_energy_to_lose_is_v0_plus_the_largest_rise():
    """v_ref = max(|v(0)|, v(0) + max rise): v(0) where v never rose (today's rule), the v a
    push gave a body at rest, |v(0)| without the figure (an old index)."""
    assert lyapunov_reference(5.0, 0.0) == 5.0
    assert lyapunov_reference(0.0, 1.5) == 1.5
    assert lyapunov_reference(-2.0, 0.5) == 2.0
    assert lyapunov_reference(3.0, float("nan")) == 3.0
    # a body pushed from rest (v(0) = 0) that lost all but 1e-5 of what the push gave it
    assert not converged(True, 0.0, 1.6e-5)
    assert converged(True, 0.0, 1.6e-5, max_increase=1.6)
    assert not converged(True, 0.0, 1.6e-2, max_increase=1.6)
    # arrays, text (an index read from CSV) and missing entries
    got = converged(np.array([True, True, True]), ["0", "1", "1"], ["1e-5", "1e-4", "0.5"], 1e-3,
                    np.array(["1.0", None, "nan"], dtype=object))
    assert got.tolist() == [True, True, False]


@pytest.mark.parametrize("status, message, v0, v1, rise, word", [
    ("success", None, 10.0, 1e-3, 0.0, CONVERGED),
    ("success", None, 10.0, 0.5, 0.0, SETTLING),
    ("success", None, 10.0, -1.01, 0.0, MOVING_AWAY),
    ("success", None, 0.0, 1.6e-5, 1.6, CONVERGED),
    ("failed", "left the admissible region: |theta_1| of trunk reached simulation.limits.theta = 0.6 rad at t = 6.27 s",
     1.0, 2.0, 1.0, FELL),
    ("failed", "gimbal lock: |theta_2| of body b reached 1.47 rad at t = 0.4 s", 1.0, 2.0, 1.0, FELL),
    ("failed", "solver failed: step size too small at t = 0.1 s", 1.0, 2.0, 0.0, NOT_COMPUTED),
    ("error", "ValueError: x", None, None, None, NOT_COMPUTED),
    ("pending", None, None, None, None, PENDING),
])
def test_each_outcome_from_status_message_and_v(status, message, v0, v1, rise, word):
    assert outcome(status, message, v0, v1, rise) == word
    many = outcomes(np.array([status, "success"], dtype=object), [message, None], [v0, 1.0], [v1, 0.0], [rise, 0.0])
    assert many.tolist() == [word, CONVERGED]
    assert word in OUTCOMES


# -- rbstab run ----------------------------------------------------------------------------------
def test_a_fall_of_the_shipped_stance_example_reads_fell(tmp_path):
    """Leaning 0.35 rad the stance falls: it leaves the example's admissible region, its line
    says fell and the command exits 0 (without the region it swung through the ground and
    read 'success')."""
    result = _run("run", str(STANCE), "-o", str(tmp_path), "--set", "initial_state.legs.theta=[0.35,0,0]")
    assert result.exit_code == 0, result.output
    assert "stance_ankle_hip: failed, fell (" in result.output
    assert "left the admissible region" in result.output


def test_a_run_under_gravity_without_limits_that_does_not_converge_says_why(tmp_path):
    """Without simulation.limits the same fall runs to t_end: not 'converged'; its line
    goes on to say that v rose above v(0) with no disturbance, and W009 names the missing
    admissible region."""
    result = _run("run", str(STANCE), "-o", str(tmp_path), "--set", "initial_state.legs.theta=[0.35,0,0]",
                  "--set", "simulation.limits=null", "--set", "simulation.t_end=2")
    assert result.exit_code == 0, result.output
    line = next(x for x in result.output.splitlines() if x.startswith("stance_ankle_hip: success"))
    assert CONVERGED not in line.split("(")[0]
    assert "without a disturbance" in result.output
    assert "W009 simulation.limits" in result.output
    quiet = _run("run", str(STANCE), "-o", str(tmp_path / "q"), "--no-warn", "W009", "--set",
                 "initial_state.legs.theta=[0.35,0,0]", "--set", "simulation.limits=null", "--set",
                 "simulation.t_end=2")
    assert "W009" not in quiet.output


def _quiet_stance_pushed(tmp_path: Path) -> Path:
    config = yaml.safe_load(STANCE.read_text())
    config["name"] = "quiet_pushed"
    config["initial_state"] = {"legs": {"theta": [0.0, 0.0, 0.0]}, "trunk": {"theta": [0.0, 0.0, 0.0]}}
    config["disturbances"] = [{"kind": "impulse", "body": "trunk", "value": [0.0, -12.0, 0.0], "point": [0, 0, 0.2],
                               "start": 0.5}]
    config["simulation"]["t_end"] = 8.0
    path = tmp_path / "quiet_pushed.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def test_a_push_from_quiet_stance_converges(tmp_path):
    """At rest (v(0) = 0) and pushed at 0.5 s, the body recovers: it converges once it has
    lost all but 0.1 % of what the push gave it (v(0) = 0 alone could never be beaten)."""
    result = _run("run", str(_quiet_stance_pushed(tmp_path)), "-o", str(tmp_path / "out"), "--json")
    assert result.exit_code == 0, result.output
    record = json.loads(next(x for x in result.output.splitlines() if x.startswith("{")))
    s = record["summary"]
    assert abs(s["lyapunov_initial"]) < 1e-9 and s["max_lyapunov_increase"] > 0.1
    assert 0 < s["lyapunov_final"] <= 1e-3 * s["max_lyapunov_increase"]
    assert record["outcome"] == CONVERGED and record["converged"] is True
    shown = _run("show", str(tmp_path / "out" / "quiet_pushed.h5"))
    assert "status     success, converged" in shown.output


# -- sweeps: the line, the index, show --run, the report ---------------------------------------
@pytest.fixture(scope="module")
def stance_sweep(tmp_path_factory):
    """The stance swept over the legs' lean: upright to falling."""
    out = tmp_path_factory.mktemp("sweeps")
    result = _run("sweep", str(STANCE), "-o", str(out), "-j", "1", "--grid",
                  "initial_state.legs.theta.0=0.0,0.05,0.35", "--set", "simulation.t_end=2",
                  "--set", "simulation.n_samples=401")
    assert result.exit_code == 0, result.output
    return out / "stance_ankle_hip", result.output


def test_a_sweeps_line_and_index_count_by_outcome(stance_sweep):
    import pandas as pd

    folder, output = stance_sweep
    index = pd.read_csv(folder / "index.csv")
    assert set(index["outcome"]) <= set(OUTCOMES)
    assert (index["outcome"] == FELL).sum() == 1
    counts = json.loads((folder / "sweep_summary.json").read_text())["outcomes"]
    assert counts[FELL] == 1 and sum(counts.values()) == len(index)
    line = next(x for x in output.splitlines() if x.startswith("stance_ankle_hip: 3 runs (0 skipped"))
    assert f"1 {FELL}" in line and "failed" not in line
    fell_line = next(x for x in output.splitlines() if "left the admissible region" in x)
    assert f": {FELL}: " in fell_line


def test_show_run_gives_a_sweep_runs_status_outcome_and_summary_and_its_config(stance_sweep):
    import pandas as pd

    folder, _ = stance_sweep
    index = pd.read_csv(folder / "index.csv")
    fallen = str(index.loc[index["outcome"] == FELL, "run_id"].iloc[0])
    result = _run("show", str(folder), "--run", fallen)
    assert result.exit_code == 0, result.output
    assert f"# status   failed, {FELL}: left the admissible region" in result.output
    assert "lyapunov_final" in result.output and "[J]" in result.output
    config = yaml.safe_load(result.output)  # the comments aside, a config file
    assert config["initial_state"]["legs"]["theta"][0] == pytest.approx(0.35)


def test_the_reports_sweep_headline_counts_by_outcome(stance_sweep, tmp_path):
    folder, _ = stance_sweep
    result = _run("report", str(folder), "-o", str(tmp_path / "report"), "--format", "md")
    assert result.exit_code == 0, result.output
    page = (tmp_path / "report" / "index.md").read_text()
    headline = next(x for x in page.splitlines() if "3 runs: " in x)
    assert f"1 {FELL}" in headline and "failed" not in headline


# -- the README's commands in the order written -----------------------------------------------
def test_the_readmes_analyze_commands_of_one_name_share_a_configuration():
    """A reader runs the README's commands in order: an `rbstab analyze` of a name already
    analysed with another configuration is refused, so every analyze of one name must
    resolve to the same configuration."""
    from rbstab.config import canonical_config, config_hash, load_config

    seen: dict[str, tuple[str, str]] = {}
    for line in (ROOT / "README.md").read_text().replace("\\\n", " ").splitlines():
        if not line.startswith("rbstab analyze "):
            continue
        words = shlex.split(line.split("  #")[0])
        configs = [w for w in words[2:] if w.endswith(".yaml") and not w.startswith("-")]
        overrides = [words[i + 1] for i, w in enumerate(words) if w == "--set"]
        if "--overwrite" in words or len(configs) != 1 or "*" in configs[0]:
            continue
        config = load_config(ROOT / configs[0], overrides=overrides)
        digest = config_hash(canonical_config(config.resolved))
        if config.name in seen:
            assert seen[config.name][0] == digest, f"{line!r} is refused after {seen[config.name][1]!r}"
        seen.setdefault(config.name, (digest, line))
    assert "stance_ankle_hip" in seen
