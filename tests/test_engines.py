"""The compiled engine against the scipy reference: every variant, mixed chunks, failures, sweeps.

``simulate_many`` integrates runs with the compiled engine (:mod:`rbstab.engine`);
``simulate(config, engine="scipy")`` is one ``solve_ivp`` call per run. Both use the
variant's compiled right-hand side (there is no second model), so what is compared here is
the integration: the compiled runs must give the scipy trajectories within a tolerance
scaled by rtol (in practice they agree to round-off: the same steps are taken).

Runs are short (t_end = 0.3 s, 301 samples) so that the file stays fast.
"""

from __future__ import annotations

import copy
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from rbstab.variants.paper import paper_form
from rbstab import simulator as simulate_module
from rbstab.config import apply_overrides, config_from_mapping, parse_yaml
from rbstab.layout import is_chain
from rbstab.io.hdf5 import SUMMARY_VARIABLES, read_attributes, read_summary, summary_stride, write_run
from rbstab.simulator import simulate, simulate_many
from rbstab.summary import LYAPUNOV_RATE_TOLERANCE, numerical_rate
from rbstab.sweep.folder import index_part, row_from_attributes
from rbstab.sweep import expand, run_sweep, spec_from_mapping
from rbstab.sweep.runner import resolve_engine
from rbstab.sweep.worker import RunTask, WorkerOptions, _group_configs, run_chunk
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = [p for p in sorted((ROOT / "configs" / "paper").glob("*.yaml")) + sorted((ROOT / "configs" / "examples").glob("*.yaml"))
           if not is_chain(yaml.safe_load(p.read_text(encoding="utf-8")))]  # one-body configs (chains: test_chain_config.py)
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
SHORT = ["simulation.t_end=0.3", "simulation.n_samples=301", "simulation.rtol=1e-6", "simulation.atol=1e-8"]
SPINS = [[16.0, 32.0, -16.0], [20.0, 25.0, -10.0], [5.0, -12.0, 30.0], [-14.0, 36.0, 3.0]]
# theta_2 close to pi/2 and a fast spin about axis 2: gimbal lock within milliseconds
LOCKING = {"theta": [0.0, 1.5, 0.0], "omega": [0.0, 30.0, 0.0]}

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def base_data(path: Path, overrides=()) -> dict:
    """The config at ``path`` over SHORT's 0.3 s, without an admissible region; its disturbances
    (configs/examples/saturated_push.yaml) start at the same fraction of the run."""
    data = parse_yaml(path.read_text())
    data.get("simulation", {}).pop("limits", None)  # the spins leave a stance's region: compared over all of SHORT
    t_end = data.get("simulation", {}).get("t_end", 1.0)
    starts = [f"disturbances.{i}.start={d.get('start', 0.0) * 0.3 / t_end}"
              for i, d in enumerate(data.get("disturbances") or ())]
    return apply_overrides(data, [*SHORT, *starts, *overrides])


def configs_with_spins(data: dict, spins=SPINS, **initial) -> list:
    out = []
    for k, omega in enumerate(spins):
        d = copy.deepcopy(data)
        d["name"] = f"run{k}"
        d.setdefault("initial_state", {})["omega"] = omega
        d["initial_state"].update(initial)
        out.append(config_from_mapping(d))
    return out


def max_diff(a, b) -> float:
    return float(np.nanmax(np.abs(a - b))) if np.isfinite(b).any() else 0.0


def assert_close(batch, ref, rtol, sensitivity=()):
    """Every output of ``batch`` within 50 rtol (relative to its scale) of ``ref``; or, for
    a discontinuous right-hand side, within 10x of how far scipy itself moves when the
    initial state moves by one ulp (``sensitivity``: scipy results from such moves; the
    farthest counts, since one move alone can happen to land close)."""
    assert batch.status == ref.status, (batch.message, ref.message)
    assert batch.message == ref.message
    for key, value in ref.outputs.items():
        scale = max(1.0, float(np.nanmax(np.abs(value))))
        tol = 50 * rtol * scale
        if key == "lyapunov_rate_numerical" and len(ref.time) > 1:  # differences of v: its error over the step
            tol = max(tol, 50 * rtol * float(np.nanmax(np.abs(ref.outputs["lyapunov"]))) / float(np.min(np.diff(ref.time))))
        for moved in sensitivity:
            tol = max(tol, 10 * max_diff(moved.outputs[key], value))
        assert np.array_equal(np.isnan(batch.outputs[key]), np.isnan(value)), key
        assert max_diff(batch.outputs[key], value) <= tol, (key, max_diff(batch.outputs[key], value), tol)


# -- every variant ---------------------------------------------------------------------------


VARIANT_CASES = [(p, ()) for p in CONFIGS] + [
    (ROOT / "configs" / "examples" / "sliding.yaml", ("controller.boundary_layer=0.0",)),  # pure sign law
    (CASE3, ("simulation.method=RK45",)),
    (CASE3, ("simulation.method=RK23",)),
]


@pytest.mark.parametrize("path, overrides", VARIANT_CASES,
                         ids=[f"{p.stem}{'-' + o[0] if o else ''}" for p, o in VARIANT_CASES])
def test_compiled_agrees_with_scipy_for_every_variant(path, overrides):
    data = base_data(path, overrides)
    smooth = paper_form(config_from_mapping(data)).smooth
    configs = configs_with_spins(data, SPINS if smooth else SPINS[:2])
    rtol = configs[0].simulation.rtol
    got = dict(simulate_many(configs, engine="compiled"))
    assert sorted(got) == list(range(len(configs)))
    # a clipped actuator's kinks: where the steps land on them decides the error there, and the scipy
    # reference (the one-body tree's rate) rounds otherwise than the compiled engine (one body's own)
    kinked = any(part.saturation is not None and part.saturation.shape == "clip"
                 for part in (*configs[0].chain.bodies, *configs[0].chain.joints))
    for i, config in enumerate(configs):
        ref = simulate(config, engine="scipy")
        assert ref.ok, ref.message
        sensitivity = []
        if not smooth or kinked:  # the pure sign law chatters: round-off decides the switches
            for direction in (np.inf, -np.inf):
                moved = copy.deepcopy(config.resolved)
                moved["initial_state"]["omega"] = np.nextafter(config.initial_state["body"]["omega"], direction).tolist()
                sensitivity.append(simulate(config_from_mapping(moved), engine="scipy"))
        assert_close(got[i], ref, rtol, sensitivity)
        near = [got[i].summary["lyapunov_rate_mismatch_relative"], ref.summary["lyapunov_rate_mismatch_relative"]]
        if not any(LYAPUNOV_RATE_TOLERANCE / 3 <= m <= 3 * LYAPUNOV_RATE_TOLERANCE for m in near):
            # a verdict at its threshold is not comparable: a clipped torque's kinks between sparse
            # samples move the numerical dv/dt by the engines' step placement (stance_ankle's spins)
            assert got[i].summary["lyapunov_rate_check"] == ref.summary["lyapunov_rate_check"]
        assert got[i].name == config.name and got[i].config is config
        assert set(got[i].timing) == {"integration", "postprocess"}


def test_runs_of_any_parameters_share_a_chunk_and_implicit_methods_fall_back(monkeypatch):
    """Runs that differ in gains, body and variant are integrated in one call, each with
    the bits it gets alone; Radau and the pure sign law go through scipy."""
    data = base_data(CASE3)
    stiff = apply_overrides(data, ["controller.k_c=[20000, 20000, 15000]", "body.mass=30"])
    visco = apply_overrides(base_data(ROOT / "configs" / "paper" / "case2_visco_elastic.yaml"), [])
    radau = apply_overrides(data, ["simulation.method=Radau"])
    configs = (configs_with_spins(data, SPINS[:2]) + configs_with_spins(stiff, SPINS[:2])
               + configs_with_spins(visco, SPINS[:1]) + configs_with_spins(radau, SPINS[:1]))
    calls, solo = [], []
    from rbstab.engine import integrate as driver

    real_integrate, real_simulate = driver.integrate_chain_runs, simulate_module.simulate
    monkeypatch.setattr(driver, "integrate_chain_runs",
                        lambda s, y0, *a, **k: calls.append(len(y0)) or real_integrate(s, y0, *a, **k))
    monkeypatch.setattr(simulate_module, "simulate", lambda c, *a, **k: solo.append(c.name) or real_simulate(c, *a, **k))
    got = dict(simulate_many(configs, chunk_size=3))
    # two laws (embedded, visco_elastic): chunks of at most 3 per law
    assert sorted(calls) == [1, 1, 3]
    assert solo == ["run0"] and configs[5].simulation.method == "Radau"
    assert got[5].ok and got[5].solver["njev"] > 0  # the scipy path (an implicit method)
    assert all(r.ok for r in got.values())
    monkeypatch.undo()
    for i in range(5):
        alone = dict(simulate_many([configs[i]]))[0]
        for key, value in got[i].outputs.items():
            assert np.array_equal(alone.outputs[key], value), (i, key)


def test_scipy_engine_of_simulate_many_is_simulate():
    configs = configs_with_spins(base_data(CASE3), SPINS[:2])
    for i, result in simulate_many(configs, engine="scipy"):
        ref = simulate(configs[i], engine="scipy")
        assert np.array_equal(result.outputs["theta"], ref.outputs["theta"])
    with pytest.raises(ValueError, match="engine"):
        list(simulate_many(configs, engine="numba"))


def test_gimbal_lock_inside_a_chunk_fails_alone_with_the_scipy_message():
    data = base_data(CASE3)
    configs = configs_with_spins(data, SPINS[:3])
    locking = copy.deepcopy(data)
    locking["name"] = "locking"
    locking["initial_state"].update(LOCKING)
    configs.insert(1, config_from_mapping(locking))
    got = dict(simulate_many(configs, engine="compiled"))
    ref = simulate(configs[1], engine="scipy")
    assert ref.status == "failed" and ref.message.startswith("gimbal lock: |theta_2| reached pi/2")
    assert got[1].status == "failed" and got[1].message.startswith("gimbal lock: |theta_2| reached pi/2")
    t_ref = float(ref.message.split("at t = ")[1].split(" s")[0])
    t_got = float(got[1].message.split("at t = ")[1].split(" s")[0])
    assert t_got == pytest.approx(t_ref, rel=1e-4)
    assert np.isnan(got[1].outputs["theta"][-1]).all() and np.isnan(ref.outputs["theta"][-1]).all()
    assert got[1].summary["t_final"] == ref.summary["t_final"]
    assert [got[i].status for i in (0, 2, 3)] == ["success"] * 3


def test_runs_of_other_durations_in_a_chunk_get_their_own_time_axis():
    """A chunk takes runs of any t_end: each run's numerical dv/dt and summary are those it
    gets alone (they use its own sample times)."""
    data = base_data(CASE3)
    short = apply_overrides(data, ["simulation.t_end=0.5"])  # same sample count: one chunk
    configs = configs_with_spins(data, SPINS[:2]) + configs_with_spins(short, SPINS[:2])
    together = dict(simulate_many(configs, chunk_size=4))
    for i, config in enumerate(configs):
        alone = dict(simulate_many([config]))[0]
        assert together[i].time[-1] == config.simulation.t_end
        for key in ("lyapunov", "lyapunov_rate_numerical"):
            assert np.array_equal(alone.outputs[key], together[i].outputs[key]), (i, key)
        np.testing.assert_equal(alone.summary, together[i].summary)  # NaN: a figure with no value
        assert together[i].summary["lyapunov_rate_check"] == "pass"


def test_a_run_gets_the_same_bits_whatever_its_chunk():
    configs = configs_with_spins(base_data(CASE3), SPINS)
    together = dict(simulate_many(configs, engine="compiled"))
    alone = dict(simulate_many(configs[2:3], engine="compiled"))
    pair = dict(simulate_many(configs[1:3], engine="compiled"))
    for other in (alone[0], pair[1]):
        for key, value in together[2].outputs.items():
            assert np.array_equal(other.outputs[key], value), key


def test_outputs_not_full_are_the_full_outputs_but_those_left_out():
    """simulate_many(full=False) (a sweep that stores no more than a thinned store) gives
    every output but LEFT_OUT, each with the bits of the full outputs, and the same
    summaries, for every variant."""
    from rbstab.layout import LEFT_OUT

    configs = [c for path in CONFIGS for c in configs_with_spins(base_data(path), SPINS[:1])]
    assert {c.chain.joints[0].variant for c in configs} >= {"free", "permanent", "sliding", "visco_elastic", "embedded"}
    full = dict(simulate_many(configs))
    lean = dict(simulate_many(configs, full=False))
    for i, config in enumerate(configs):
        assert set(lean[i].outputs) == set(full[i].outputs) - set(LEFT_OUT), config.chain.joints[0].variant
        for key, value in lean[i].outputs.items():
            assert np.array_equal(value, full[i].outputs[key], equal_nan=True), (config.chain.joints[0].variant, key)
        np.testing.assert_equal(lean[i].summary, full[i].summary)


def test_numerical_rate_is_exact_for_degree_6_and_of_6th_order():
    """The 7-point stencils differentiate polynomials of degree <= 6 exactly on any grid
    (here non-uniform), and the error of a smooth signal falls as h^6."""
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0.0, 2.0, 40))
    coefficients = rng.standard_normal(7)
    poly = np.polynomial.Polynomial(coefficients)
    np.testing.assert_allclose(numerical_rate(t, poly(t)), poly.deriv()(t), rtol=0, atol=1e-8)
    errors = []
    for n in (101, 201):
        t = np.linspace(0.0, 2.0, n)
        errors.append(np.abs(numerical_rate(t, np.sin(5 * t)) - 5 * np.cos(5 * t)).max())
    assert errors[0] / errors[1] > 2**6 * 0.7, errors


def test_numerical_rate_is_the_stencil_sum_in_order():
    """The compiled stencil gives the bits of sum_j w[i, j] v[first[i] + j] taken in the order
    j = 0, 1, ... (numpy, a term at a time), at the ends (one-sided) as in the middle."""
    from rbstab.summary import stencil_weights

    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0.0, 2.0, 60))
    v = rng.standard_normal((3, 60)) * 10.0 ** rng.uniform(-3, 3, (3, 1))
    first, weights = stencil_weights(t)
    expected = weights[:, 0] * v[:, first]
    for j in range(1, weights.shape[1]):
        expected += weights[:, j] * v[:, first + j]
    assert np.array_equal(numerical_rate(t, v), expected)


def test_numerical_rate_of_rows_equals_numerical_rate_row_by_row():
    t = np.linspace(0.0, 1.0, 101)
    rng = np.random.default_rng(0)
    v = np.cumsum(rng.standard_normal((5, 101)), axis=1)
    v[3, 60:] = np.nan  # a failed run's tail
    v[4, 1:] = np.nan  # one finite sample: no derivative
    got = numerical_rate(t, v)
    for i in range(5):
        assert np.array_equal(got[i], numerical_rate(t, v[i]), equal_nan=True)
    assert np.isfinite(got[3, :60]).all() and np.isnan(got[3, 60:]).all()
    assert np.isnan(got[4]).all()
    short = numerical_rate(t[:4], v[:, :4])
    assert np.array_equal(short[0], numerical_rate(t[:4], v[0, :4]))


# -- the sweep engine ------------------------------------------------------------------------


def sweep_spec(n: int, name: str = "eng", extra: dict | None = None):
    data = {
        "name": name,
        "base": str(CASE3),
        "random": {"n": n, "seed": 5,
                   "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}},
        **(extra or {}),
    }
    return spec_from_mapping(data, overrides=SHORT)


def test_group_configs_equal_validated_configs():
    runs = expand(sweep_spec(4))
    tasks = [RunTask(r.run_id, r.config.resolved, "x.h5") for r in runs]
    configs, errors = _group_configs(tasks)
    assert not errors
    for config, run in zip(configs, runs):
        assert config.to_yaml() == run.config.to_yaml()
        assert config.name == run.run_id
        for block, value in run.config.initial_state["body"].items():
            assert np.array_equal(config.initial_state["body"][block], value)
            assert not config.initial_state["body"][block].flags.writeable


def test_runs_of_one_config_share_a_compiled_tree_and_give_each_ones_bits(monkeypatch):
    """A worker's runs that differ only in initial state share one compiled tree (its
    records and equilibrium computed once), and each gets the bits it gets alone, also
    through calls that reuse one buffer of trajectories; gravity makes the equilibrium a
    computed one."""
    spec = sweep_spec(5, extra={"grid": {"body.gravity": [[0.0, 0.0, 0.0], [0.0, 0.0, -9.81]]}})
    runs = expand(spec)
    tasks = [RunTask(r.run_id, r.config.resolved, "x.h5") for r in runs]
    configs, errors = _group_configs(tasks)
    assert not errors
    made = []
    import rbstab.engine.batch as batch

    real = batch.C.compile_chain
    monkeypatch.setattr(batch.C, "compile_chain", lambda chain, **kw: made.append(chain) or real(chain, **kw))
    got = dict(simulate_many(configs, chunk_size=3))  # 4 compiled calls into one buffer
    assert len(made) == 2  # one per gravity
    monkeypatch.undo()
    for i, run in enumerate(runs):
        alone = dict(simulate_many([run.config]))[0]
        assert alone.summary["lyapunov_final"] == got[i].summary["lyapunov_final"]
        for key, value in alone.outputs.items():
            assert np.array_equal(got[i].outputs[key], value, equal_nan=True), (i, key)


def test_compiled_and_scipy_sweeps_give_the_same_index(tmp_path):
    spec = sweep_spec(5, extra={"grid": {"controller.k_c": [[12300, 12300, 9840], [20000, 20000, 15000]]}})
    runs = expand(spec)
    a = run_sweep(spec, tmp_path / "scipy", jobs=2, engine="scipy", progress=False, layout="run")
    b = run_sweep(spec, tmp_path / "compiled", jobs=2, progress=False, layout="run")
    assert (a.engine, b.engine) == ("scipy", "compiled")
    assert b.n_chunks == 2  # consecutive runs, one chunk per worker
    ia, ib = pd.read_csv(a.index_path), pd.read_csv(b.index_path)
    assert list(ia.columns) == list(ib.columns)
    assert (ia["status"] == "success").all() and list(ia["status"]) == list(ib["status"])
    for col in ("run_id", "config_hash", "converged", "lyapunov_rate_check", "file"):
        assert list(ia[col]) == list(ib[col]), col
    numeric = [c for c in ia.columns if c.startswith(("final_", "lyapunov_", "max_", "t_final"))
               and ia[c].dtype.kind == "f"]
    assert numeric
    for col in numeric:
        np.testing.assert_allclose(ib[col], ia[col], rtol=1e-4, atol=1e-9, err_msg=col)
    assert set(b.timing) == {"config", "integration", "postprocess", "config_yaml", "write"}
    assert b.worker_peak_rss is None or b.worker_peak_rss > 10 * 2**20


def test_compiled_resume_and_summary_store(tmp_path):
    spec4, spec7 = sweep_spec(4, "res"), sweep_spec(7, "res")
    first = run_sweep(spec4, tmp_path / "a", jobs=2, store="thinned", layout="run", progress=False)
    assert first.counts["success"] == 4
    again = run_sweep(spec7, tmp_path / "a", jobs=2, store="thinned", layout="run", progress=False)
    assert (again.n_skipped, again.n_executed, again.counts["success"]) == (4, 3, 7)
    clean = run_sweep(spec7, tmp_path / "b", jobs=1, chunk_size=7, store="thinned", layout="run", progress=False)
    full = run_sweep(spec7, tmp_path / "c", jobs=2, store="full", layout="run", progress=False)
    runs = expand(spec7)
    for run in runs:
        a = tmp_path / "a" / "res" / "runs" / f"{run.run_id}.h5"
        b = tmp_path / "b" / "res" / "runs" / f"{run.run_id}.h5"
        c = tmp_path / "c" / "res" / "runs" / f"{run.run_id}.h5"
        with h5py.File(a) as fa, h5py.File(b) as fb, h5py.File(c) as fc:
            for key in fa:  # resumed in other chunks: the same bits
                assert np.array_equal(fa[key][()], fb[key][()]), key
            assert set(fa) == {"time", "axis", *SUMMARY_VARIABLES}
            stride = summary_stride(301)
            assert fa["time"].shape == (301 // stride + 1,)
            assert np.array_equal(fa["lyapunov"][()], fc["lyapunov"][()][::stride])
        sa, sc = read_attributes(a), read_attributes(c)
        assert sa["store"] == "thinned" and "store" not in sc
        np.testing.assert_equal({k: v for k, v in sa.items() if k.startswith("summary_")},
                                {k: v for k, v in sc.items() if k.startswith("summary_")})
    ia = pd.read_csv(tmp_path / "a" / "res" / "index.csv").drop(columns=["wall_time"])
    ic = pd.read_csv(tmp_path / "c" / "res" / "index.csv").drop(columns=["wall_time"])
    pd.testing.assert_frame_equal(ia, ic)
    # a summary file is a result file for show and report
    path = tmp_path / "a" / "res" / "runs" / f"{runs[0].run_id}.h5"
    shown = CliRunner().invoke(cli, ["show", str(path)])
    assert shown.exit_code == 0 and "lyapunov_final" in shown.output
    from rbstab.report.load import load_run

    run = load_run(path)
    assert run.series("lyapunov_rate_numerical")["time"].shape == (301 // summary_stride(301) + 1,)
    np.testing.assert_equal(read_summary(path)["summary"],
                            read_summary(tmp_path / "c" / "res" / "runs" / f"{runs[0].run_id}.h5")["summary"])


def test_worker_compiled_engine_isolates_failures(tmp_path):
    runs = expand(sweep_spec(3))
    tasks = [RunTask(r.run_id, r.config.resolved, str(tmp_path / f"{r.run_id}.h5")) for r in runs]
    locking = copy.deepcopy(runs[1].config.resolved)
    locking["initial_state"].update(LOCKING)
    tasks[1] = RunTask(runs[1].run_id, locking, tasks[1].path)
    bad = RunTask("r9999-deadbeef", {"name": "r9999-deadbeef", "body": {}}, str(tmp_path / "bad.h5"))
    unwritable = RunTask(runs[2].run_id, runs[2].config.resolved, str(tmp_path / "file" / "x.h5"))
    (tmp_path / "file").write_text("not a folder")
    options = WorkerOptions(engine="compiled", layout="run", store="full")
    result = run_chunk([*tasks, bad, unwritable], options)
    rows = result.frame.to_dict("records")
    status = sorted((r["run_id"], r["status"]) for r in rows)  # tasks[2] and unwritable share their run id
    assert status == sorted([(runs[0].run_id, "success"), (runs[1].run_id, "failed"), (runs[2].run_id, "success"),
                             (bad.run_id, "error"), (runs[2].run_id, "error")])
    by_id = {(r["run_id"], r["status"]): r for r in rows}
    assert by_id[runs[1].run_id, "failed"]["message"].startswith("gimbal lock")
    assert "ConfigError" in by_id[bad.run_id, "error"]["message"] and pd.isna(by_id[bad.run_id, "error"]["file"])
    assert not Path(unwritable.path).exists() and by_id[runs[2].run_id, "error"]["message"]
    # a run file's row is its attributes as the index takes them
    stored = index_part(row_from_attributes(read_attributes(tasks[0].path), Path(tasks[0].path).name))
    got = by_id[runs[0].run_id, "success"]
    np.testing.assert_equal({k: v for k, v in got.items() if k in stored}, stored)  # NaN: a figure with no value


def test_the_registry_names_the_compiled_methods():
    """The registry lists the compiled methods without importing numpy: the same as the tableaus'."""
    from rbstab.engine import METHODS
    from rbstab.engine.registry import COMPILED_METHODS, ENGINES

    assert COMPILED_METHODS == METHODS
    assert [name for name, engine in ENGINES.items() if engine.compiled] == ["compiled", "cuda"]
    assert ENGINES["compiled"].takes("DOP853") and not ENGINES["compiled"].takes("DOP853", sign_law=True)
    assert not ENGINES["compiled"].takes("Radau") and not ENGINES["scipy"].takes("DOP853")
    assert ENGINES["compiled"].unavailable() is None and ENGINES["scipy"].unavailable() is None


def test_engine_choice_and_timeout(tmp_path):
    assert resolve_engine(None, None) == "compiled"
    assert resolve_engine(None, 5.0) == "compiled"  # both engines take a per-run wall-time limit
    assert resolve_engine("scipy", 5.0) == "scipy"
    with pytest.raises(ValueError, match="engine"):
        resolve_engine("fast", None)
    spec_path = tmp_path / "s.yaml"
    spec_path.write_text(yaml.safe_dump({"name": "t", "base": str(CASE3), "random": {"n": 1, "seed": 0, "params": {
        "initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 1}}}}}))
    args = ["sweep", str(spec_path), "-o", str(tmp_path / "out"), "--no-progress", "--set", "simulation.t_end=0.05",
            "--set", "simulation.n_samples=11"]
    ok = CliRunner().invoke(cli, [*args, "--engine", "scipy", "--timeout", "30"])
    assert ok.exit_code == 0, ok.output
    assert "scipy engine" in ok.output
    ok = CliRunner().invoke(cli, [*args, "--timeout", "30", "-o", str(tmp_path / "o1")])
    assert ok.exit_code == 0 and "compiled engine" in ok.output, ok.output
    ok = CliRunner().invoke(cli, [*args, "--store", "summary", "--chunk-size", "4", "-o", str(tmp_path / "o2")])
    assert ok.exit_code == 0 and "compiled engine" in ok.output


def test_write_run_returns_what_read_attributes_reads(tmp_path):
    config = configs_with_spins(base_data(CASE3), SPINS[:1])[0]
    result = simulate(config)
    for store in ("full", "summary"):
        attrs = write_run(result, tmp_path / f"{store}.h5", store=store, command_line="x")
        np.testing.assert_equal(attrs, read_attributes(tmp_path / f"{store}.h5"))  # NaN: a figure with no value
    with pytest.raises(ValueError, match="store"):
        write_run(result, tmp_path / "x.h5", store="some")
