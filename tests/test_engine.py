"""The compiled engine step by step against scipy: tableaus, step counts, failures that end."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import initial_blocks, paper_body, paper_gains
from rbstab.config import load_config
from rbstab.engine import GROUPS, METHODS, integrate_runs, status, tableaus
from rbstab.variants import VARIANTS

GRAVITY = {"free": (0.0, 0.0, -10.0), "permanent": (0.0, 0.0, -10.0)}


def test_rk_tableaus_are_scipys():
    """rbstab.engine.tableaus (so workers need not import scipy.integrate) holds exactly the
    installed scipy's numbers and messages."""
    from scipy.integrate._ivp import dop853_coefficients, rk
    from scipy.integrate._ivp.base import OdeSolver
    from scipy.integrate._ivp.ivp import MESSAGES

    for method in METHODS:
        ours, theirs = tableaus.TABLEAUS[method], getattr(rk, method)
        for key in ("order", "error_estimator_order", "n_stages"):
            assert getattr(ours, key) == getattr(theirs, key), (method, key)
        keys = ["C", "A", "B"] + (["E3", "E5", "D"] if method == "DOP853" else ["E", "P"])
        for key in keys:
            np.testing.assert_array_equal(getattr(ours, key), getattr(theirs, key), err_msg=f"{method}.{key}")
    for key in ("A", "C"):
        np.testing.assert_array_equal(getattr(tableaus.DOP853_EXTENDED, key), getattr(dop853_coefficients, key))
    assert (tableaus.SAFETY, tableaus.MIN_FACTOR, tableaus.MAX_FACTOR) == (rk.SAFETY, rk.MIN_FACTOR, rk.MAX_FACTOR)
    assert status.SUCCESS_MESSAGE == MESSAGES[0]
    assert status.TOO_SMALL_STEP_MESSAGE == OdeSolver.TOO_SMALL_STEP



def test_status_table_names_every_code_once():
    """Each code of rbstab.engine.status is a distinct int named as its constant (those of
    the admissible region LEFT_REGION + 3 j + i, named by their quantity and axis), and its
    message fills every field of its template."""
    region = [code for code in status.STATUSES if status.limit_of(code) is not None]
    assert region == [status.LEFT_REGION + k for k in range(15)]
    assert [status.STATUSES[code][0] for code in region] == [
        f"LEFT_REGION_{name.upper()}_{i}" for name in ("theta", "omega", "position", "velocity", "constraint_error")
        for i in range(3)]
    codes = {name: getattr(status, name) for code, (name, _) in status.STATUSES.items() if code not in region}
    assert sorted(codes.values()) == sorted(set(status.STATUSES) - set(region)) and len(set(codes.values())) == len(codes)
    assert all(status.STATUSES[code][0] == name for name, code in codes.items())
    for code in status.STATUSES:
        text = status.status_message(code, 0.25, 1e-3, 50, 2.0, max_switchings=7, resolution=1e-9)
        # a run that stopped says where; one that ended well, or never started, has no stop to name
        assert "{" not in text and ("0.25" in text) == (code not in (status.SUCCESS, status.NOT_STARTED))
    assert status.status_message(status.STEP_LIMIT, 0.25, 1e-3, 50).startswith("step limit: 50 steps")
    with pytest.raises(KeyError):
        status.status_message(99, 0.0, 1e-3)
    # a tree's codes: each bound and each gimbal lock of each of its 8 bodies and joints, each read back alone
    bounds = [status.limit_status(j, i, b) for b in range(8) for j in range(5) for i in range(3)]
    locks = [status.gimbal_status(b, joint) for b in range(8) for joint in (False, True)]
    assert len(set(bounds + locks)) == len(bounds) + len(locks) and not set(bounds + locks) & set(codes.values())
    assert [status.gimbal_of(c) for c in locks] == [(b, joint) for b in range(8) for joint in (False, True)]
    assert all(status.limit_of(c) is None for c in locks) and all(status.gimbal_of(c) is None for c in bounds)


def test_method_tables_hold_each_tableau_zero_padded():
    """The compiled engine's per-method tables (rbstab.engine.rk) are the tableaus of
    rbstab.engine.tableaus, each in its method's row, zero beyond it."""
    from rbstab.engine import method_number, rk

    def row(table, method, expected):
        got = table[method_number(method)]
        window = tuple(slice(0, n) for n in expected.shape)
        np.testing.assert_array_equal(got[window], expected, err_msg=method)
        rest = got.copy()
        rest[window] = 0.0
        assert not rest.any(), method

    assert rk.METHODS == METHODS and METHODS[rk.DOP853] == "DOP853"
    for method in METHODS:
        t, m = tableaus.TABLEAUS[method], method_number(method)
        assert (rk.N_STAGES[m], rk.ERROR_ORDER[m]) == (t.n_stages, t.error_estimator_order)
        row(rk.RK_B, method, t.B)
        if method == "DOP853":
            row(rk.RK_A, method, tableaus.DOP853_EXTENDED.A)
            assert (rk.STAGE_ROWS[m], rk.INTERPOLANT_ROWS[m]) == (16, 7)
            for ours, theirs in ((rk.DOP853_E3, t.E3), (rk.DOP853_E5, t.E5), (rk.DOP853_D, t.D)):
                np.testing.assert_array_equal(ours, theirs)
        else:
            row(rk.RK_A, method, t.A)
            row(rk.RK_E, method, t.E)
            row(rk.RK_P, method, t.P)
            assert (rk.STAGE_ROWS[m], rk.INTERPOLANT_ROWS[m]) == (t.n_stages + 1, t.P.shape[1])
    with pytest.raises(ValueError, match="method: found 'Radau'"):
        method_number("Radau")


def _variant(name):
    return VARIANTS[name](paper_body(GRAVITY.get(name, (0.0, 0.0, 0.0))), paper_gains())


def _settings(k, t_end=0.5, rtol=1e-6, atol=1e-8, max_step=np.inf, margin=1e-3):
    return np.tile([[t_end, rtol, atol, max_step, margin]], (k, 1))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_same_steps_and_samples_as_solve_ivp(name, method):
    """Each run takes the right-hand-side evaluations solve_ivp takes (same error norm,
    initial step and step control) and samples the same dense output, to the tolerance's scale."""
    variant = _variant(name)
    spins = [(16.0, 32.0, -16.0), (3.0, -7.0, 11.0)]
    y0 = np.stack([variant.initial_state(initial_blocks(omega=w)) for w in spins])
    t = np.linspace(0.0, 0.5, 101)
    sol = integrate_runs([variant.code] * 2, np.repeat(variant.parameters, 2), y0, _settings(2), method=method,
                         n_samples=len(t))
    for k in range(2):
        ref = solve_ivp(variant.rhs, (0.0, 0.5), y0[k], method=method, t_eval=t, rtol=1e-6, atol=1e-8)
        assert sol.status[k] == 0 and ref.status == 0
        if name == "sliding":  # tanh(E / 5 mm) is stiff: round-off decides a few step rejections
            assert abs(sol.nfev[k] - ref.nfev) <= 0.03 * ref.nfev, (sol.nfev[k], ref.nfev)
        else:
            assert sol.nfev[k] == ref.nfev, (sol.nfev[k], ref.nfev)
        scale = np.abs(ref.y).max()
        np.testing.assert_allclose(sol.samples[k], ref.y.T, atol=10 * 1e-6 * scale)


def test_max_step_is_honoured_like_scipy():
    variant = _variant("embedded")
    y0 = variant.initial_state(initial_blocks())[None]
    sol = integrate_runs([variant.code], variant.parameters, y0, _settings(1, max_step=1e-3), method="RK45",
                         n_samples=11)
    ref = solve_ivp(variant.rhs, (0.0, 0.5), y0[0], method="RK45", rtol=1e-6, atol=1e-8, max_step=1e-3)
    assert sol.n_steps[0] >= 500 and sol.nfev[0] == ref.nfev


@pytest.mark.parametrize("bad", [np.nan, 1e200])
def test_non_finite_runs_end_failed_and_the_others_do_not_notice(bad):
    """A NaN initial state or an overflowing one ends as a failure (no endless loop), and the
    run beside it gets the bits it gets alone."""
    variant = _variant("visco_elastic")
    good = variant.initial_state(initial_blocks())
    broken = good.copy()
    broken[3] = bad
    sol = integrate_runs([variant.code] * 2, np.repeat(variant.parameters, 2), np.stack([broken, good]),
                         _settings(2), method="DOP853", n_samples=11)
    alone = integrate_runs([variant.code], variant.parameters, good[None], _settings(1), method="DOP853", n_samples=11)
    assert sol.status[0] in (-1, -2) and sol.status[1] == 0
    assert np.isnan(sol.samples[0, -1]).all()
    assert np.array_equal(sol.samples[1], alone.samples[0])


def test_a_reused_sample_buffer_holds_each_runs_samples_and_nan_after_a_stop():
    """The rows a run does not reach (after a gimbal lock) are NaN and every other row is
    its own sample, whatever the buffer held before (a worker reuses one buffer)."""
    variant = _variant("embedded")
    good = variant.initial_state(initial_blocks())
    locking = variant.initial_state(initial_blocks(theta=[0.0, 1.5, 0.0], omega=[0.0, 30.0, 0.0]))
    y0 = np.stack([locking, good])
    fresh = integrate_runs([variant.code] * 2, np.repeat(variant.parameters, 2), y0, _settings(2), method="DOP853",
                           n_samples=51)
    buffer = np.full((3, 51, good.size), 7.0)
    used = integrate_runs([variant.code] * 2, np.repeat(variant.parameters, 2), y0, _settings(2), method="DOP853",
                          n_samples=51, out=buffer)
    assert used.status.tolist() == [1, 0] and np.shares_memory(used.samples, buffer)
    stop = int(np.argmax(np.isnan(fresh.samples[0, :, 0])))
    assert 0 < stop < 51 and np.isnan(used.samples[0, stop:]).all()
    np.testing.assert_array_equal(used.samples, fresh.samples)
    assert not (used.samples == 7.0).any()


def test_step_limit_ends_a_run():
    variant = _variant("embedded")
    y0 = variant.initial_state(initial_blocks())[None]
    sol = integrate_runs([variant.code], variant.parameters, y0, _settings(1), method="RK23", n_samples=11, max_steps=50)
    assert sol.status[0] == -3 and sol.n_steps[0] == 50 and 0 < sol.t_stop[0] < 0.5


def test_samples_into_a_given_buffer():
    """integrate_runs(out=...) fills the first rows of the caller's buffer (the bits of a new
    array) and refuses a buffer that cannot hold the samples, naming ``out``."""
    variant = _variant("embedded")
    y0 = variant.initial_state(initial_blocks())[None]
    fresh = integrate_runs([variant.code], variant.parameters, y0, _settings(1), method="DOP853", n_samples=11)
    buffer = np.full((3, 11, y0.shape[1]), 7.0)
    sol = integrate_runs([variant.code], variant.parameters, y0, _settings(1), method="DOP853", n_samples=11,
                         out=buffer)
    assert np.shares_memory(sol.samples, buffer) and sol.samples.shape == (1, 11, y0.shape[1])
    assert np.array_equal(sol.samples, fresh.samples) and (buffer[1:] == 7.0).all()
    read_only = buffer.copy()
    read_only.setflags(write=False)
    for bad in (np.empty((1, 12, y0.shape[1])), np.empty((0, 11, y0.shape[1])), buffer.astype(np.float32),
                read_only, buffer[:, ::2], [[0.0]]):
        with pytest.raises(ValueError, match="out: found"):
            integrate_runs([variant.code], variant.parameters, y0, _settings(1), method="DOP853", n_samples=11,
                           out=bad)


_UNWARMED = r"""
import sys, warnings
import numba
from rbstab.engine import warm_up
warm_up(sys.argv[1])
from rbstab.config import load_config
from rbstab.simulator import simulate


def signatures():
    found = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("rbstab"):
            for attr, value in list(vars(module).items()):
                if isinstance(value, numba.core.registry.CPUDispatcher):
                    found[f"{value.py_func.__module__}.{attr}"] = len(value.signatures)
    return found


before = signatures()
warnings.simplefilter("ignore")
short = ["simulation.t_end=0.01", "simulation.n_samples=3"]
for path in sys.argv[3:]:
    simulate(load_config(path, short))
if sys.argv[2]:  # the first config's analysis and a sweep of two runs over the key sys.argv[2]
    import tempfile
    from pathlib import Path

    import rbstab
    from rbstab.analysis import analyze
    from rbstab.sweep.executors import ThreadExecutor

    analyze(load_config(sys.argv[3], short), samples=200, falsification_runs=2)
    out = Path(tempfile.mkdtemp())
    (out / "spec.yaml").write_text(f"name: s\nbase: {sys.argv[3]}\ngrid:\n  {sys.argv[2]}: [1.0, 2.0]\n"
                                   "  simulation.t_end: [0.01]\n")
    rbstab.execute_sweep(out / "spec.yaml", out, executor=ThreadExecutor(1))
after = signatures()
print(sorted(name for name, count in after.items() if count > before.get(name, 0)))
"""


def test_a_one_body_run_uses_only_the_kernels_the_engine_group_warms():
    """rbstab run of a paper case compiles (or loads) the engine group before its first run
    (rbstab.engine.ensure_compiled): its runs, every law and the permanent joint's reduced
    samples expanded, then call no kernel the group left out (one would be compiled inside
    the first run, its wall time and the user's wait: ~10 s); an analysis (with the
    analysis group) and a sweep's runs neither."""
    import subprocess
    import sys

    from conftest import ROOT

    paths = [str(p) for p in sorted((ROOT / "configs" / "paper").glob("*.yaml"))]
    paths.append(str(ROOT / "configs" / "examples" / "sliding.yaml"))
    parts = ",".join((*GROUPS["engine"], *GROUPS["analysis"]))
    found = subprocess.run([sys.executable, "-c", _UNWARMED, parts, "body.mass", *paths],
                           capture_output=True, text=True, check=True)
    assert found.stdout.strip() == "[]", found.stdout + found.stderr


def test_one_body_written_as_a_tree_uses_only_the_kernels_the_engine_group_warms(tmp_path):
    """The paper's one body written as a tree (bodies, joints) is the one body the engine
    group compiles for (rbstab.engine.kernel_groups): its runs (the pinned body's state
    reduced from the tree's, its centre of pressure under gravity), its analysis and a
    sweep's runs call no kernel the group leaves out, as in one body's spelling."""
    import subprocess
    import sys

    import yaml

    from conftest import ROOT, tree_spelling

    paths = []
    for name in ("paper/case1_permanent", "paper/case3_embedded", "examples/saturated_pendulum"):
        path = tmp_path / f"{name.partition('/')[2]}.yaml"
        path.write_text(yaml.safe_dump(tree_spelling(load_config(ROOT / "configs" / f"{name}.yaml")).resolved))
        paths.append(str(path))
    parts = ",".join((*GROUPS["engine"], *GROUPS["analysis"]))
    found = subprocess.run([sys.executable, "-c", _UNWARMED, parts, "bodies.body.mass", *paths],
                           capture_output=True, text=True, check=True)
    assert found.stdout.strip() == "[]", found.stdout + found.stderr


def test_a_sweep_compiles_a_trees_kernels_where_a_run_may_be_another_model_than_the_papers_one_body(tmp_path):
    """A sweep's kernel groups follow its runs' physics, not their spelling
    (SweepSpec.may_run_tree): a tree's kernels for a base of two bodies, for one body held
    elsewhere than at its own point, and where the sweep varies its joint's point or lower
    torque limit; not for the paper's one body in either spelling with its gains, limits,
    mass and initial state varied. Scipy's methods' kernels (SweepSpec.may_run_scipy) where a
    run goes to them."""
    import yaml

    from conftest import ROOT, tree_spelling
    from rbstab.sweep.spec import spec_from_mapping

    case1 = ROOT / "configs" / "paper" / "case1_permanent.yaml"
    tree = tree_spelling(load_config(case1)).resolved
    (tmp_path / "tree.yaml").write_text(yaml.safe_dump(tree))
    tree["joints"][0]["parent_point"] = [0.0, 0.0, 0.1]
    (tmp_path / "held_elsewhere.yaml").write_text(yaml.safe_dump(tree))

    def may_run_tree(base, grid):
        return spec_from_mapping({"name": "s", "base": str(base), "grid": grid}).may_run_tree

    kept = {"joints.controller.k_r.0": [100.0, 200.0], "joints.controller.saturation.torque_n": [50.0],
            "bodies.body.mass": [1.0, 2.0], "initial_state.body.theta.0": [0.1], "gravity.2": [-9.0]}
    assert not may_run_tree(case1, {"controller.k_r.0": [100.0, 200.0], "body.attachment_point.2": [0.1, 0.2]})
    assert not may_run_tree(tmp_path / "tree.yaml", kept)
    assert may_run_tree(tmp_path / "tree.yaml", {"joints.controller.child_point.2": [0.1, 0.2]})
    assert may_run_tree(tmp_path / "tree.yaml", {"joints.controller.saturation.torque_n_lower": [-5.0]})
    assert may_run_tree(tmp_path / "held_elsewhere.yaml", {"bodies.body.mass": [1.0, 2.0]})
    assert may_run_tree(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", {"bodies.trunk.mass": [60.0]})
    # scipy's methods' kernels where a run goes to them: the engine scipy, a method the compiled engine leaves out
    spec = spec_from_mapping({"name": "s", "base": str(case1), "grid": {"controller.k_r.0": [100.0]}})
    assert not spec.may_run_scipy() and not spec.may_run_scipy("compiled") and spec.may_run_scipy("scipy")
    assert spec_from_mapping({"name": "s", "base": str(case1), "grid": {"simulation.method": ["RK45", "Radau"]}}
                             ).may_run_scipy()
    assert spec_from_mapping({"name": "s", "base": str(case1), "grid": {"controller.k_r.0": [100.0]}},
                             overrides=["simulation.method=BDF"]).may_run_scipy()


_SCIPY_UNWARMED = r"""
import sys, warnings
import numba
from rbstab.config import load_config
from rbstab.engine import GROUPS, kernel_groups, warm_up
from rbstab.simulator import simulate

warnings.simplefilter("ignore")
short = ["simulation.t_end=0.01", "simulation.n_samples=3"]
runs = [(load_config(p, short + extra), engine) for p in sys.argv[1:]
        for extra, engine in (([], "scipy"), (["simulation.method=Radau"], "compiled"))]
wanted = {}
for config, engine in runs:
    for group, on in kernel_groups([config], engine).items():
        wanted[group] = wanted.get(group, False) or on
names = {"one_body": "engine", "chain": "chain", "solve_ivp": "solve_ivp"}
warm_up(",".join(p for group, on in wanted.items() if on for p in GROUPS[names[group]]))


def signatures():
    return {f"{v.py_func.__module__}.{a}": len(v.signatures) for name, m in list(sys.modules.items())
            if name.startswith("rbstab") for a, v in list(vars(m).items())
            if isinstance(v, numba.core.registry.CPUDispatcher)}


before = signatures()
for config, engine in runs:
    simulate(config, engine=engine)
after = signatures()
print(sorted(name for name, count in after.items() if count > before.get(name, 0)))
"""


def test_runs_on_scipys_methods_use_only_the_kernels_their_groups_warm(tmp_path):
    """A run on scipy's methods (--engine scipy, an implicit method; one body in either
    spelling, trees) calls no kernel beyond the groups rbstab.engine.kernel_groups names for
    it (the solve_ivp group: the reduced rate, impulses and breakpoints solve_tree calls from
    Python), which the commands compile before the first run."""
    import subprocess
    import sys

    import yaml

    from conftest import ROOT, tree_spelling

    tree = tmp_path / "case1_tree.yaml"
    tree.write_text(yaml.safe_dump(tree_spelling(load_config(ROOT / "configs" / "paper" / "case1_permanent.yaml"))
                                   .resolved))
    paths = [str(ROOT / "configs" / "paper" / "case1_permanent.yaml"), str(tree),
             *(str(ROOT / "configs" / "examples" / f"{name}.yaml") for name in ("stance_ankle_hip", "knee"))]
    found = subprocess.run([sys.executable, "-c", _SCIPY_UNWARMED, *paths], capture_output=True, text=True, check=True)
    assert found.stdout.strip() == "[]", found.stdout + found.stderr


def test_a_tree_run_uses_only_the_kernels_the_chain_group_warms():
    """A tree's run (rbstab run of a chain example: ball joints, visco-elastic and embedded
    point laws, a knee's stiff ligaments), its analysis and a sweep's runs call no kernel
    beyond the chain group's, which a tree-only command compiles without the one-body
    group's."""
    import subprocess
    import sys

    from conftest import ROOT

    paths = [str(ROOT / "configs" / "examples" / f"{name}.yaml") for name in ("stance_ankle_hip", "double_pendulum",
                                                                              "knee")]
    found = subprocess.run([sys.executable, "-c", _UNWARMED, ",".join(GROUPS["chain"]), "bodies.trunk.mass", *paths],
                           capture_output=True, text=True, check=True)
    assert found.stdout.strip() == "[]", found.stdout + found.stderr
