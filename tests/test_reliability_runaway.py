"""Every run ends: runs that would never finish end as ``failed`` with the reason, on
both engines, and a sweep records them and goes on (docs/reliability.md)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from rbstab.config import config_from_mapping, load_config
from rbstab.simulator import simulate
from rbstab.sweep import run_sweep, spec_from_mapping

from conftest import ROOT
from test_reliability_faults import SerialExecutor

CASE3 = yaml.safe_load((ROOT / "configs" / "paper" / "case3_embedded.yaml").read_text())
#: Omega of 1e12 rad/s: allowed (at the magnitude limit), but the steps it needs are ~1e-13 s.
RUNAWAY = [1e12, 0.0, 0.0]


def _config(omega=(16.0, 32.0, -16.0), **simulation):
    data = {**CASE3, "initial_state": {**CASE3.get("initial_state", {}), "omega": list(omega)},
            "simulation": {**CASE3.get("simulation", {}), "t_end": 0.5, "n_samples": 51, **simulation}}
    return config_from_mapping(data)


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_run_that_cannot_reach_t_end_stops_at_its_step_limit(engine):
    result = simulate(_config(RUNAWAY, max_steps=200), engine=engine)
    assert result.status == "failed"
    assert result.message.startswith("step limit: 200 steps taken (simulation.max_steps), reaching only t = ")
    assert float(result.message.rsplit("t = ", 1)[1].split()[0]) < 1e-6  # far from t_end


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_run_past_its_wall_time_limit_stops(engine):
    result = simulate(_config(RUNAWAY, max_wall_time=0.05), engine=engine)
    assert result.status == "failed" and result.message.startswith("timeout: the run exceeded 0.05 s of wall time")
    assert result.wall_time < 2.0
    ok = simulate(_config(), engine=engine, timeout=60.0)  # a budget a run meets changes nothing
    assert ok.ok
    np.testing.assert_equal(ok.summary, simulate(_config(), engine=engine).summary)


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_trees_run_stops_at_its_limits_with_one_bodys_messages(engine):
    """A tree's run, on the compiled driver and on the scipy reference, stops at
    ``simulation.max_steps`` and past its wall-time limit, with the words one body's runs
    end with."""
    stance = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    steps = simulate(load_config(stance, ["simulation.max_steps=20"]), engine=engine)
    assert steps.status == "failed"
    assert steps.message.startswith("step limit: 20 steps taken (simulation.max_steps), reaching only t = ")
    slow = simulate(load_config(stance, ["simulation.t_end=1000", "simulation.n_samples=11"]), engine=engine,
                    timeout=0.05)
    assert slow.status == "failed" and slow.message.startswith("timeout: the run exceeded 0.05 s of wall time")


@pytest.mark.parametrize("name", ["paper/case3_embedded", "examples/saturated_push", "examples/stance_ankle_hip"])
def test_a_stopped_run_keeps_its_samples_and_both_engines_stop_at_one_step(name):
    """At ``simulation.max_steps`` the scipy reference stops where the compiled driver
    stops (the end of the last step allowed), with the samples up to there: one body, one
    body with an impulse and a pulse (W to the stop), a tree. Past a wall-time limit it
    keeps its samples too."""
    config = load_config(ROOT / "configs" / f"{name}.yaml", ["simulation.max_steps=20"])
    runs = {engine: simulate(config, engine=engine) for engine in ("compiled", "scipy")}
    compiled, scipy = runs["compiled"], runs["scipy"]
    assert scipy.status == compiled.status == "failed"
    assert scipy.message.startswith("step limit: 20 steps taken")
    t_stop = float(scipy.message.rsplit("t = ", 1)[1].split()[0])
    assert t_stop == pytest.approx(float(compiled.message.rsplit("t = ", 1)[1].split()[0]), rel=1e-5)
    kept = np.isfinite(scipy.outputs["lyapunov"])
    assert np.array_equal(kept, np.isfinite(compiled.outputs["lyapunov"]))
    assert kept[0] and kept.sum() == np.sum(scipy.time <= t_stop) < scipy.time.size
    for key in ("lyapunov", "disturbance_work"):
        assert np.allclose(scipy.outputs[key][kept], compiled.outputs[key][kept], rtol=1e-6, atol=1e-9)
    slow = simulate(load_config(ROOT / "configs" / f"{name}.yaml", ["simulation.t_end=1000"]), engine="scipy",
                    timeout=0.05)
    assert slow.message.startswith("timeout") and 0 < np.isfinite(slow.outputs["lyapunov"]).sum() < slow.time.size


def test_a_stop_inside_a_window_without_samples_keeps_the_samples_before_it():
    """A step limit met inside the pulse's window (2.5 to 2.55 s) when no sample lies in it:
    scipy's segment returns no sample (``sol.y`` an empty list); the run stops failed where
    the compiled driver stops, with the samples before the window (past the saturation's
    kinks the two engines' steps differ in the last digits, so each is read on its own)."""
    overrides = ["simulation.t_end=1000", "simulation.n_samples=11", "simulation.max_steps=102"]
    config = load_config(ROOT / "configs" / "examples" / "saturated_push.yaml", overrides)
    runs = {engine: simulate(config, engine=engine) for engine in ("compiled", "scipy")}
    stops = [float(run.message.rsplit("t = ", 1)[1].split()[0]) for run in runs.values()]
    assert all(run.message.startswith("step limit: 102 steps taken") for run in runs.values())
    assert all(2.5 < stop < 2.55 for stop in stops)
    for run in runs.values():
        assert np.isfinite(run.outputs["lyapunov"]).tolist() == [True] + [False] * 10


def test_a_first_step_failure_is_a_failed_run(monkeypatch):
    """A state that is NaN at once: scipy's engine fails before its first sample (``sol.y``
    is then an empty list), a failed run of NaN rows."""
    from rbstab.simulator import solve_tree
    from rbstab.variants import chain as C

    config = load_config(ROOT / "configs" / "paper" / "case3_embedded.yaml",
                         ["simulation.t_end=0.5", "simulation.n_samples=51", "simulation.method=RK45"])
    start = C.initial_state(config)
    start[3] = np.nan  # Omega_1

    monkeypatch.setattr(C, "initial_state", lambda config: start)
    trajectory = solve_tree(config)
    assert trajectory.status == "failed" and trajectory.states.shape[0] == 51
    assert np.isnan(trajectory.states).all()


def test_a_sweep_records_a_runaway_run_and_goes_on(tmp_path):
    base = {**CASE3, "simulation": {**CASE3.get("simulation", {}), "t_end": 0.2, "n_samples": 21,
                                    "max_steps": 500}}
    spec = spec_from_mapping({"name": "runaway", "base": base,
                              "grid": {"initial_state.omega": [[16, 32, -16], RUNAWAY, [10, 20, -10]]}})
    outcome = run_sweep(spec, tmp_path, executor=SerialExecutor(), progress=False)
    assert outcome.counts == {"success": 2, "failed": 1, "error": 0, "pending": 0}
    (run_id, status, message), = outcome.problems
    assert status == "failed" and message.startswith("step limit: 500 steps")
