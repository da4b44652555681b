"""The compiled driver on trees (rbstab.engine.systems): it takes solve_ivp's steps on a
tree's rate, a one-body tree on it moves as the one-body engine's body, and a
disturbance's work, integrated with the state, is what v gains without damping."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from conftest import tree_spelling
from rbstab.variants.paper import paper_form
from rbstab.config import load_config
from rbstab.config.loader import config_from_mapping, load_config
from rbstab.engine.integrate import integrate_chain_runs, integrate_tree_chunk
from rbstab.engine.settings import settings_records, settings_rows
from rbstab.engine import method_number
from rbstab.engine.systems import tree_rows, tree_system
from rbstab.layout import LYAPUNOV_TERMS
from rbstab.simulator import simulate
from rbstab.variants import chain as C

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["stance_ankle_hip", "double_pendulum"])
def test_the_compiled_driver_takes_solve_ivps_steps_on_a_chain(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(ROOT / "configs" / "examples" / f"{name}.yaml",
                                 ["simulation.t_end=1.0", "simulation.n_samples=201"])
    reference = simulate(config, engine="scipy")
    compiled = simulate(config, engine="compiled")
    assert compiled.status == reference.status == "success"
    # the same steps: solve_ivp's numpy and the driver's loops sum a step's stages in another
    # order, so an error ratio within rounding of 1 may be a rejected step in one of them
    stages = 12 if config.simulation.method == "DOP853" else 6
    assert abs(compiled.solver["nfev"] - reference.solver["nfev"]) <= stages
    for key in ("theta", "omega", "position", "velocity", "lyapunov"):
        scale = 1.0 + np.abs(reference.outputs[key]).max()
        np.testing.assert_allclose(compiled.outputs[key], reference.outputs[key], rtol=0, atol=1e-9 * scale,
                                   err_msg=key)


ONE_BODY = ["paper/case1_permanent.yaml", "paper/case2_visco_elastic.yaml", "paper/case3_embedded.yaml",
            "examples/stance_ankle.yaml", "examples/saturated_push.yaml", "examples/sliding.yaml",
            "examples/free_gravity.yaml"]


def _one_body(path, *overrides):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_config(ROOT / "configs" / path, ["simulation.t_end=3.0", "simulation.n_samples=301", *overrides])


@pytest.mark.parametrize("path", ONE_BODY)
def test_one_bodys_two_spellings_are_one_model(path):
    """A one-body config and the same body written as a tree (bodies, joints) are one model,
    for all five laws, saturation, disturbances (an impulse and a pulse) and limits: the same
    state at every sample, bit for bit, the same steps and the same disturbances' work, and
    the same outputs of it, bit for bit: E, F, Lambda, N, H, their saturation flags, v, its
    four terms (eq 25's in both files) and dv/dt; a permanent joint's X, V (placed from
    Theta) to rounding."""
    config = _one_body(path, "simulation.limits.omega=[40, 40, 40]")
    tree = tree_spelling(config)
    body, chain = simulate(config), simulate(tree)
    assert body.status == chain.status == "success"
    assert body.solver["nfev"] == chain.solver["nfev"]
    blocks = ("theta", "omega") if config.chain.joints[0].variant == "permanent" else ("theta", "omega", "position", "velocity")
    for key in blocks:
        np.testing.assert_array_equal(chain.outputs[key][:, 0], body.outputs[key], err_msg=key)
    if config.chain.joints[0].variant == "embedded":
        np.testing.assert_array_equal(chain.outputs["controller_state"][:, 0], body.outputs["controller_state"])
    if "disturbance_work" in body.outputs:
        np.testing.assert_array_equal(chain.outputs["disturbance_work"], body.outputs["disturbance_work"])
    # the tree's outputs are one body's, computed by its compiled outputs from the same state
    for key in ("constraint_error", "constraint_rate", "constraint_force", "torque_n", "force_h", "torque_n_saturated",
                "force_h_saturated", "constraint_force_saturated", "lyapunov", "lyapunov_rate", "disturbance_power",
                *LYAPUNOV_TERMS):
        found = chain.outputs[key] if key.startswith(("lyapunov", "disturbance")) else chain.outputs[key][:, 0]
        np.testing.assert_array_equal(found, body.outputs[key], err_msg=key)
    for key in ("position", "velocity"):  # a permanent joint's: the tree's placement of the same Theta
        expected = body.outputs[key]
        np.testing.assert_allclose(chain.outputs[key][:, 0], expected, rtol=0, atol=1e-13 * (1.0 + np.abs(expected).max()),
                                   err_msg=key)


def test_one_batch_takes_both_spellings_and_each_run_is_the_run_alone():
    """One batch of one-body configs and trees mixed (a permanent and an embedded body, the
    stance and the knee): each run's result, through simulate_many, is its simulate() alone,
    bit for bit, and each keeps its spelling's outputs (one body's (m, 3), a tree's (m, n, 3))."""
    from rbstab.engine.batch import batch_of
    from rbstab.simulator import simulate_many

    paths = ["paper/case1_permanent", "examples/stance_ankle_hip", "paper/case3_embedded", "examples/knee"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        configs = [load_config(ROOT / "configs" / f"{p}.yaml", ["simulation.t_end=0.5", "simulation.n_samples=51"])
                   for p in paths]
    batch = batch_of(configs)
    assert batch.one_body.tolist() == [True, False, True, False] and batch.compiled.all()
    assert batch.params.shape == (4, 2) and batch.n_state.tolist() == [6, 24, 15, 27]
    together = dict(simulate_many(configs))
    for i, config in enumerate(configs):
        alone = simulate(config)
        assert together[i].status == alone.status == "success"
        assert together[i].outputs.keys() == alone.outputs.keys()
        for key, value in alone.outputs.items():
            np.testing.assert_array_equal(together[i].outputs[key], value, err_msg=f"{config.name}: {key}")
        assert together[i].outputs["theta"].ndim == (2 if batch.one_body[i] else 3)


def test_the_pure_sign_law_runs_alike_in_both_spellings_of_one_body(tmp_path):
    """The pure sign law (boundary_layer 0) is the paper's one body's: written as a tree held
    at its own point it runs event by event as written as one body, the same bits in a tree's
    names and shapes (a body and a joint axis of one), the same switchings, a tree's file;
    its analysis replaces the sign law by the same boundary layer; in any other tree it is
    refused in one line."""
    import xarray as xr

    from rbstab.analysis.analyze import analyze
    from rbstab.config import ConfigError
    from rbstab.io.hdf5 import write_result

    body = _one_body("examples/sliding.yaml", "controller.boundary_layer=0", "simulation.t_end=0.4")
    tree = tree_spelling(body)
    alone, as_tree = simulate(body), simulate(tree)
    assert as_tree.outputs["theta"].shape == (len(as_tree.time), 1, 3)
    for key, value in alone.outputs.items():
        got = as_tree.outputs[key]
        np.testing.assert_array_equal(got[:, 0] if got.ndim == 3 else got, value, err_msg=key)
    np.testing.assert_array_equal(as_tree.outputs["joint_theta"], as_tree.outputs["theta"])
    for name in ("time", "axis", "kind"):
        np.testing.assert_array_equal(getattr(as_tree.switching, name), getattr(alone.switching, name))
    np.testing.assert_array_equal(as_tree.summary["switching_count"], np.asarray(alone.summary["switching_count"])[None])
    assert np.sum(alone.summary["switching_count"]) > 0
    np.testing.assert_array_equal(as_tree.summary["final_theta"], np.asarray(alone.summary["final_theta"])[None])
    write_result(as_tree, tmp_path / "tree.h5")
    with xr.open_dataset(tmp_path / "tree.h5") as ds:
        assert ds["theta"].dims == ("time", "body", "axis") and ds.sizes["switching"] == len(alone.switching.time)
    a, b = (analyze(c, samples=200, simulate=False) for c in (body, tree))
    assert b.notes[0] == a.notes[0] and "pure sign law" in a.notes[0]
    np.testing.assert_array_equal(b.linearisation.eigenvalues, a.linearisation.eigenvalues)
    moved = dict(tree.resolved, joints=[dict(tree.resolved["joints"][0], parent_point=[0.0, 0.0, 0.0])])
    with pytest.raises(ConfigError, match=r"joints.controller.boundary_layer': found 0; expected a boundary layer "
                                          r"> 0 \[m\] in a chain \(the pure sign law is integrated event by event "
                                          r"for one body held to the ground at its own point only"):
        config_from_mapping(moved)


@pytest.mark.parametrize("path", ONE_BODY)
def test_the_general_tree_rate_is_one_bodys_rate(path):
    """The tree's rate in reduced coordinates (composite rigid bodies, Cholesky; the general
    formulation, which the compiled driver leaves for one body's own) equals one body's rate
    (a permanent joint: eq 21 on Theta_j, Omega_j; any other law: eq 1 with its Lambda, then
    dD/dt) to rounding at every sample of the body's run; and the scipy reference, which
    integrates the tree with it, moves the body as the one-body engine to the solver's
    tolerance."""
    from rbstab.variants import tree as T

    config = _one_body(path)
    sim = config.simulation
    body = simulate(config)
    variant = paper_form(config)
    y = np.ascontiguousarray(np.column_stack([body.outputs[b] for b in variant.layout.blocks]))
    time = np.ascontiguousarray(body.time)
    compiled = C.compile_chain(config.chain, offset=0.0)
    layout = T.tree_layout(compiled)
    assert layout.n_r == y.shape[1]  # the one-body state is the tree's reduced state
    work = T.tree_work(1, compiled.n_states)
    found = np.empty_like(y)
    for k in range(len(time)):
        T.tree_rate(time[k], y[k], *compiled.args, *layout.args, found[k], work)
    expected = variant.rhs(time[:, None], y)
    scale = 1.0 + np.abs(expected).max(axis=0)
    assert np.max(np.abs(found - expected) / scale) < 1e-11
    # the compiled driver on the general rate (integrate_chain_runs takes one body's): the same
    # steps, so the same motion to the solver's tolerance, with the disturbances' work
    system = tree_system(compiled, sim.limits)
    params, ppoints, tree_of = tree_rows(system, 1)
    settings = settings_records(settings_rows([sim]), method_number(sim.method))
    samples, work_done = np.empty((1, sim.n_samples, y.shape[1])), np.empty((1, sim.n_samples))
    ends = (np.empty(1, dtype=np.int64), np.empty(1), np.empty(1, dtype=np.int64), np.empty(1, dtype=np.int64))
    integrate_tree_chunk(system._replace(params=params, ppoints=ppoints), tree_of, y[:1].copy(), settings, samples,
                         work_done, ends)
    assert ends[0][0] == 0
    scale = 1.0 + np.abs(y).max(axis=0)
    assert np.max(np.abs(samples[0] - y) / scale) < 10 * sim.rtol
    if "disturbance_work" in body.outputs:
        work = body.outputs["disturbance_work"]
        np.testing.assert_allclose(work_done[0], work, rtol=0, atol=10 * sim.rtol * (1.0 + np.abs(work).max()))


def _pulsed_chain(l_r):
    """Two bodies on permanent (ball) joints under gravity with joint springs, damping
    ``l_r``, and a pulse of force on the lower body from 0.2 s to 0.5 s."""
    return config_from_mapping({
        "name": "pulsed", "gravity": [0, 0, -9.81],
        "bodies": [{"name": "upper", "mass": 2.0, "inertia": [0.2, 0.2, 0.05]},
                   {"name": "lower", "mass": 1.5, "inertia": [0.1, 0.1, 0.03]}],
        "joints": [{"name": "shoulder", "parent": "ground", "parent_point": [0, 0, 0], "child": "upper",
                    "child_point": [0, 0, 0.4], "variant": "permanent", "k_r": [30, 30, 5], "l_r": [l_r] * 3},
                   {"name": "elbow", "parent": "upper", "parent_point": [0, 0, -0.4], "child": "lower",
                    "child_point": [0, 0, 0.3], "variant": "permanent", "k_r": [20, 20, 5], "l_r": [l_r] * 3}],
        "initial_state": {"upper": {"theta": [0.2, 0.0, 0.0]}},
        "disturbances": [{"kind": "pulse", "value": [0.0, 4.0, 1.0], "point": [0.0, 0.05, -0.2], "start": 0.2,
                          "duration": 0.3, "body": "lower"}],
        "simulation": {"t_end": 1.0, "n_samples": 101, "method": "DOP853", "rtol": 1e-10, "atol": 1e-12},
    })


def test_a_sweep_over_a_chains_parameters_is_one_call_and_each_run_is_the_run_alone(monkeypatch):
    """Runs of stance chains with other masses, gains, a parent point and an admissible
    region (one structure, every run another chain) go through the compiled driver in one
    call, each run with its own tree; each run's status, message, outputs and summary are
    those of the run alone, bit for bit (the region's run leaves it)."""
    import rbstab.engine.integrate as integrate
    from rbstab.simulator import simulate_blocks

    overrides = [[], ["bodies.trunk.mass=40.0", "joints.hip.k_r=[700, 700, 100]"],
                 ["joints.hip.parent_point=[0, 0.02, 0.4]"],
                 ["simulation.limits.theta=[0.101, 1.0, 1.0]", "initial_state.trunk.omega=[-0.5, 0, 0]"]]
    configs = [load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml",
                               ["simulation.t_end=0.3", "simulation.n_samples=31",
                                "initial_state.trunk.theta=[-0.1, 0.02, 0]", *extra]) for extra in overrides]
    calls = []
    original = integrate.integrate_tree_chunk
    monkeypatch.setattr(integrate, "integrate_tree_chunk", lambda system, *args: calls.append(len(system.params))
                        or original(system, *args))
    (members, block), = simulate_blocks(configs, keep="all")
    assert members == [0, 1, 2, 3] and calls == [4]  # one call, four trees
    assert block.status == ["success"] * 3 + ["failed"] and "trunk" in block.message[3]
    for i, config in enumerate(configs):
        (_, alone), = simulate_blocks([config], keep="all")
        assert alone.message == [block.message[i]]
        for key, values in alone.outputs.items():
            assert np.array_equal(values[0], block.outputs[key][i], equal_nan=True), key
        for key, values in alone.summaries.items():
            assert np.asarray(values[0]).tobytes() == np.asarray(block.summaries[key][i]).tobytes(), key


def test_a_pulses_work_on_a_chain_is_what_v_gains_without_damping():
    """No damping, no saturation: v(t) - v(0) = W(t), the disturbance's work, integrated
    by the driver with the state; with damping v gains less. The pulse's edges are
    breakpoints: W is flat outside [0.2, 0.5] s."""
    for l_r, exact in ((0.0, True), (2.0, False)):
        config = _pulsed_chain(l_r)
        sim = config.simulation
        compiled = C.compile_chain(config.chain)
        sol = integrate_chain_runs(tree_system(compiled), C.initial_state(config)[None], settings_rows([sim]),
                                   method=sim.method, n_samples=sim.n_samples)
        assert sol.status[0] == 0
        time = np.linspace(0.0, sim.t_end, sim.n_samples)
        v = C.evaluate(compiled, time, sol.samples[0])["lyapunov"]
        work = sol.work[0]
        assert abs(work[-1]) > 0.05  # the pulse does work
        np.testing.assert_array_equal(work[time <= 0.2], 0.0)
        assert np.ptp(work[time >= 0.5]) == 0.0
        if exact:
            np.testing.assert_allclose(v - v[0], work, atol=1e-8 * (1 + work[-1]))
        else:
            assert v[-1] - v[0] < work[-1] - 1e-3


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_chain_runs_outputs_carry_its_disturbances_work_and_power(engine):
    """A chain run's outputs (what its file holds) carry the disturbances' power P_d, their
    work W and the windows' edges; without damping v - W stays v(0), on both engines, and W
    is the time integral of P_d (trapezoids over the pulse)."""
    from rbstab.simulator import simulate

    result = simulate(_pulsed_chain(0.0), engine=engine)
    out, time = result.outputs, result.time
    assert result.status == "success"
    w, p = out["disturbance_work"], out["disturbance_power"]
    assert w.shape == p.shape == out["disturbance_edges"].shape == time.shape
    assert abs(w[-1]) > 0.05 and np.ptp(w[time >= 0.5]) == 0.0
    np.testing.assert_allclose(out["lyapunov"] - w, out["lyapunov"][0], atol=1e-7 * (1 + abs(w[-1])))
    inside = (time >= 0.2) & (time <= 0.5)
    assert np.trapezoid(p[inside], time[inside]) == pytest.approx(w[-1], rel=2e-2)
    assert list(np.unique(out["disturbance_edges"])) == [0.0, 1.0, 2.0]


def test_a_chains_basin_map_runs_each_point_as_rbstab_run_would():
    """Each grid point of a chain's basin map is the run of the configuration with that
    initial state (the bodies the config places re-placed on their joints: a tilt of the
    legs carries the trunk); the same outcome and v(t_end)."""
    from rbstab.analysis import BasinAxis, basin_map

    overrides = ["simulation.t_end=1.5", "simulation.n_samples=151", "simulation.limits.theta=[0.6, 0.6, 3.2]"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", overrides)
    axes = [BasinAxis.parse("initial_state.legs.theta.0=-0.5:0.5:3"), BasinAxis.parse("initial_state.trunk.omega.0=-4:4:3")]
    found = basin_map(config, axes, n_samples=151)
    assert found.outcome.shape == (3, 3) and found.counts()["failed"] >= 1  # a fall leaves the region
    assert found.outcome[1, 1] < 2 and found.lyapunov_final[1, 1] < 0.1 * found.lyapunov_initial[1, 1]  # it recovers
    for i, j in ((0, 2), (1, 1), (2, 0)):
        theta, omega = float(axes[0].values[i]), float(axes[1].values[j])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            point = load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml",
                                    [*overrides, f"initial_state.legs.theta=[{theta!r}, 0, 0]",
                                     f"initial_state.trunk.omega=[{omega!r}, 0, 0]"])
        np.testing.assert_allclose(found.initial_states[i, j], C.initial_state(point), atol=1e-14)
        result = simulate(point)
        assert (result.status == "success") == (found.outcome[i, j] < 2)
        if result.status == "success":
            assert found.lyapunov_final[i, j] == pytest.approx(result.outputs["lyapunov"][-1], rel=1e-12, abs=1e-14)


def _arm(root: str, pulse: float | None = None):
    """Two bodies, the upper on a ``root`` joint to the ground (permanent: a pendulum;
    free: floating), the lower on a permanent elbow; a pulse of force 2/pulse N along
    (1, 2, 0.5) for ``pulse`` seconds at the lower body's point (0.05, 0, -0.2)."""
    data = {
        "name": "arm", "gravity": [0, 0, -9.81],
        "bodies": [{"name": "upper", "mass": 2.0, "inertia": [0.2, 0.18, 0.05]},
                   {"name": "lower", "mass": 1.5, "inertia": [0.1, 0.09, 0.03]}],
        "joints": [{"name": "shoulder", "parent": "ground", "parent_point": [0, 0, 0], "child": "upper",
                    "child_point": [0, 0, 0.4], "variant": root, "k_r": [30, 30, 5], "l_r": [1, 1, 1]},
                   {"name": "elbow", "parent": "upper", "parent_point": [0, 0, -0.4], "child": "lower",
                    "child_point": [0, 0, 0.3], "variant": "permanent", "k_r": [20, 20, 5], "l_r": [1, 1, 1]}],
        "initial_state": {"upper": {"theta": [0.3, -0.2, 0.1]}, "lower": {"theta": [-0.4, 0.3, 0.0]}},
        "simulation": {"t_end": 1.0, "n_samples": 2, "method": "DOP853", "rtol": 1e-12, "atol": 1e-14},
    }
    if pulse is not None:
        data["disturbances"] = [{"kind": "pulse", "value": [2 / pulse, 4 / pulse, 1 / pulse],
                                 "point": [0.05, 0.0, -0.2], "start": 0.0, "duration": pulse, "body": "lower"}]
        data["simulation"]["t_end"] = pulse
    return config_from_mapping(data)


def test_a_push_on_a_chain_keeps_its_joints_and_is_the_limit_of_short_pulses():
    """The impulse P = (2, 4, 1) N s at a point of the lower body: the permanent joints'
    dE_j/dt stay 0; a floating chain's momentum jumps by P and its angular momentum about
    the origin by (X + A R) x P; dT is the kinetic energy's jump; and the state after a
    pulse of the same impulse over ever shorter times, integrated, approaches the jump."""
    from rbstab.kinematics import rotation_matrix

    push, point = np.array([2.0, 4.0, 1.0]), np.array([0.05, 0.0, -0.2])
    for root in ("permanent", "free"):
        config = _arm(root)
        compiled = C.compile_chain(config.chain)
        y0 = C.initial_state(config)
        y0[3:6] = [0.5, -0.3, 0.2]  # moving already
        y0 = C.place(compiled, y0, np.ones(2, bool), np.ones(2, bool))
        y = y0.copy()
        energy = C.chain_push(y, *compiled.args[:4], 1, point, push, False)
        out = C.evaluate(compiled, np.zeros(2), np.array([y0, y]))
        kinetic = out["lyapunov_translational"] + out["lyapunov_rotational"]  # a push moves no configuration
        assert energy == pytest.approx(kinetic[1] - kinetic[0], rel=1e-12)
        np.testing.assert_array_equal(y[:3], y0[:3])  # the configuration does not move
        assert np.abs(out["constraint_rate"][1, 1]).max() < 1e-12  # the elbow holds
        if root == "permanent":
            assert np.abs(out["constraint_rate"][1, 0]).max() < 1e-12
            continue
        masses = np.array([b.mass for b in config.chain.bodies])
        momentum = [(masses[:, None] * s.reshape(-1, 12)[:2, 9:12]).sum(axis=0) for s in (y0, y)]
        np.testing.assert_allclose(momentum[1] - momentum[0], push, atol=1e-12)

        def angular(s):
            total = np.zeros(3)
            for i, body in enumerate(config.chain.bodies):
                a = rotation_matrix(s[12 * i: 12 * i + 3])
                total += np.cross(s[12 * i + 6: 12 * i + 9], body.mass * s[12 * i + 9: 12 * i + 12])
                total += a @ (np.asarray(body.inertia) @ s[12 * i + 3: 12 * i + 6])
            return total
        arm = y0[18:21] + rotation_matrix(y0[12:15]) @ point
        np.testing.assert_allclose(angular(y) - angular(y0), np.cross(arm, push), atol=1e-12)
    config = _arm("permanent")
    compiled = C.compile_chain(config.chain)
    y = C.initial_state(config)
    C.chain_push(y, *compiled.args[:4], 1, point, push, False)
    errors = []
    for pulse in (1e-3, 1e-4):
        pulsed = _arm("permanent", pulse)
        sol = integrate_chain_runs(tree_system(C.compile_chain(pulsed.chain)), C.initial_state(pulsed)[None],
                                   settings_rows([pulsed.simulation]), method="DOP853", n_samples=2)
        errors.append(np.abs(sol.samples[0, -1] - y).max())
    assert errors[1] < 0.15 * errors[0] and errors[1] < 0.02  # first order in the pulse's length


@pytest.mark.parametrize("at", [0.0, 1.5])
def test_a_chains_smallest_fatal_push_is_where_a_short_pulse_starts_to_topple_it(at):
    """The stance example pushed on the trunk at t0: each direction's threshold from the jump
    (chain_push) against an independent formulation, the chain at rest from t = 0 and a 0.1 ms
    pulse of the same impulse from t0 integrated as a disturbance: 3 % below it the body
    recovers, 3 % above it falls."""
    import yaml

    from rbstab.analysis.push import push_analysis

    source = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    limits = "simulation.limits.theta=[0.6, 0.6, 3.2]"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(source, [limits])
    directions = np.array([[0.0, -1.0, 0.0], [0.6, 0.8, 0.0]])
    point = [0.0, 0.0, 0.2]
    found = push_analysis(config, "force", directions=directions, body="trunk", point=point, at=at, jobs=2)
    assert np.isfinite(found.threshold).all() and found.body == "trunk" and found.at == at
    data = yaml.safe_load(source.read_text())
    data["simulation"]["limits"] = {"theta": [0.6, 0.6, 3.2]}
    from rbstab.analysis.push import Pushes

    equilibrium = Pushes(config, "force", body="trunk", point=point).equilibrium
    data["initial_state"] = {b: {"theta": equilibrium[12 * i: 12 * i + 3].tolist()}
                             for i, b in enumerate(config.chain.body_names)}
    for u, threshold in zip(directions, found.threshold):
        for factor, falls in ((0.97, False), (1.03, True)):
            pulse = 1e-4
            data["disturbances"] = [{"kind": "pulse", "value": (factor * threshold * u / pulse).tolist(), "point": point,
                                     "start": at, "duration": pulse, "body": "trunk"}]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = simulate(config_from_mapping(data))
            assert (result.status == "failed") == falls, (u, factor, result.message)


def test_a_chain_pushed_at_t0_keeps_its_own_disturbances_and_t0_is_inside_the_run():
    """A chain's push is one more impulse entry of its disturbances: pushed at t0 = 0.5 s
    with a pulse of its own from 0.1 s, the pushed run is the run of the configuration
    with that impulse entry written in it (the same recovery verdict and v(t_end)); a t0
    past t_end and an unknown body are refused in one line."""
    from rbstab.analysis.push import Pushes
    from rbstab.analysis.runs import Runs

    source = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    pulse = 'disturbances=[{kind: pulse, value: [0, 20, 0], start: 0.1, duration: 0.1, body: trunk}]'
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(source)
        pulsed = load_config(source, [pulse, "simulation.limits.theta=[0.6, 0.6, 3.2]"])
    with pytest.raises(ValueError, match=r"--push-at: found 9; expected a time in \[0, simulation.t_end\)"):
        Pushes(config, "torque", body="trunk", at=9.0)
    with pytest.raises(ValueError, match=r"--push-body: found 'arms'; expected the body of the chain that is pushed "
                                         r"\(legs, trunk\)"):
        Pushes(config, "torque", body="arms")
    pushes = Pushes(pulsed, "torque", body="trunk", at=0.5, jobs=2)
    vectors = np.array([[0.0, 5.0, 0.0], [0.0, 400.0, 0.0]])
    recovered = pushes.recovered(vectors)
    assert recovered.tolist() == [True, False]  # a small push recovers, a large one topples the trunk
    data = pulsed.resolved
    for vector, verdict in zip(vectors, recovered):
        entry = {"kind": "impulse", "quantity": "torque", "value": vector.tolist(), "start": 0.5, "body": "trunk"}
        own = config_from_mapping({**pushes.config.resolved, "disturbances": [*data["disturbances"], entry]})
        ok, _, v = Runs(own).outcomes(C.initial_state(own)[None])
        assert bool(ok[0] == 1 and abs(v[0]) <= pushes.ratio * pushes.energy(vector)[0] + 1e-12) == verdict


def test_a_tree_of_one_body_is_pushed_without_naming_its_body(tmp_path):
    """A tree of one body has one body to push: ``--push-body`` may be left out (its body by
    default), with the verdicts and the text of the push named."""
    import yaml
    from click.testing import CliRunner

    from rbstab.analysis.push import Pushes
    from rbstab.config.loader import tree_resolved
    from rbstab_cli.main import cli

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one = load_config(ROOT / "configs" / "examples" / "stance_ankle.yaml", ["simulation.t_end=2"])
    tree = tree_spelling(one)
    default, named = Pushes(tree, "torque"), Pushes(tree, "torque", body="body")
    assert default.body == named.body == "body"
    vectors = np.array([[0.0, 5.0, 0.0], [0.0, 400.0, 0.0]])
    assert default.recovered(vectors).tolist() == named.recovered(vectors).tolist() == [True, False]
    path = tmp_path / "tree.yaml"
    path.write_text(yaml.safe_dump(tree_resolved(one.resolved)))
    args = ["analyze", str(path), "--push", "torque", "--push-direction", "0,1,0", "--no-certificate", "-j", "1"]
    texts = [CliRunner().invoke(cli, [*args, *extra, "-o", str(tmp_path / str(i))])
             for i, extra in enumerate(([], ["--push-body", "body"]))]
    assert all(t.exit_code == 0 for t in texts), texts[0].output
    assert texts[0].output.replace(str(tmp_path / "0"), "") == texts[1].output.replace(str(tmp_path / "1"), "")


def test_an_impulse_in_a_chain_config_is_the_push_applied_where_it_starts():
    """An impulse on the lower body at 0.3 s (and a torque impulse at t = 0): the compiled
    driver and the scipy reference (a new solve_ivp from each impulse) agree; the sample at
    0.3 s shows the state just after it; v and the disturbances' work W jump there by the
    push's dT, computed from the state just before it."""
    config = _arm("permanent")
    data = config.resolved
    data = {**data, "disturbances": [
        {"kind": "impulse", "quantity": "force", "value": [2.0, 4.0, 1.0], "point": [0.05, 0.0, -0.2], "start": 0.3,
         "body": "lower"},
        {"kind": "impulse", "quantity": "torque", "value": [0.0, 0.5, 0.0], "start": 0.0, "body": "upper"}],
        "simulation": {**data["simulation"], "t_end": 0.6, "n_samples": 61, "rtol": 1e-10, "atol": 1e-12}}
    config = config_from_mapping(data)
    compiled = C.compile_chain(config.chain)
    reference = simulate(config, engine="scipy")
    result = simulate(config, engine="compiled")
    assert result.status == reference.status == "success"
    assert result.summary["lyapunov_rate_check"] == "pass"  # the stencils across the impulses left out
    np.testing.assert_allclose(result.outputs["theta"], reference.outputs["theta"], atol=1e-8)
    np.testing.assert_allclose(result.outputs["lyapunov"], reference.outputs["lyapunov"], rtol=1e-8, atol=1e-10)
    sim = config.simulation
    sol = integrate_chain_runs(tree_system(compiled), C.initial_state(config)[None], settings_rows([sim]),
                               method=sim.method, n_samples=sim.n_samples)
    at = 30  # t = 0.3 s
    quiet = config_from_mapping({**data, "disturbances": data["disturbances"][1:],
                                       "simulation": {**data["simulation"], "t_end": 0.3, "n_samples": 31}})
    before = integrate_chain_runs(tree_system(C.compile_chain(quiet.chain)), C.initial_state(quiet)[None],
                                  settings_rows([quiet.simulation]), method=sim.method, n_samples=31).samples[0, -1]
    y = before.copy()
    energy = C.chain_push(y, *compiled.args[:4], 1, np.array([0.05, 0.0, -0.2]), np.array([2.0, 4.0, 1.0]), False)
    np.testing.assert_allclose(sol.samples[0, at], y, atol=1e-9)
    assert sol.work[0, at] - sol.work[0, at - 1] == pytest.approx(energy, rel=1e-6)  # W jumps by dT, only there
    v = C.evaluate(compiled, np.linspace(0, 0.6, 61), sol.samples[0])["lyapunov"]
    v_before = C.lyapunov(compiled, before)[0]
    assert v[at] - v_before == pytest.approx(energy, rel=1e-9, abs=1e-12)


def test_v_of_a_chain_is_zero_at_its_undisturbed_rest_whenever_a_disturbance_starts():
    """v's zero (h) is fixed by the chain's undisturbed rest state: a constant torque on the
    trunk of the stance example from t = 0 and the same from t = 1 s give the same v(0),
    which is v(0) without it; and a run started at that rest, the torque starting at 1 s,
    has v = 0 until then."""
    from rbstab.simulator import simulate

    step = "disturbances=[{{kind: step, quantity: torque, body: trunk, value: [5, 0, 0], start: {}}}]"
    stance = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    short = ["simulation.t_end=2.0", "simulation.n_samples=21"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        configs = {name: load_config(stance, [*short, *extra]) for name, extra in (
            ("none", []), ("at 0", [step.format(0.0)]), ("at 1", [step.format(1.0)]))}
    v0 = {name: simulate(config).outputs["lyapunov"][0] for name, config in configs.items()}
    assert v0["at 0"] == v0["at 1"] == v0["none"] > 0.0
    compiled = C.compile_chain(configs["at 1"].chain)
    rest, _ = C.rest_state(compiled)
    sol = integrate_chain_runs(tree_system(compiled), rest[None], settings_rows([configs["at 1"].simulation]),
                               method="DOP853", n_samples=21)
    v = C.evaluate(compiled, np.linspace(0.0, 2.0, 21), sol.samples[0])["lyapunov"]
    assert np.abs(v[:10]).max() < 1e-9 and v[-1] > 1e-3  # at rest until the torque starts, then moved


@pytest.mark.parametrize("path, body", [("examples/knee.yaml", 1), ("examples/saturated_push.yaml", 0)])
def test_the_analysis_runs_an_implicit_methods_states_one_at_a_time(path, body):
    """The analysis's runs from chosen states (basin maps, the certificate's checks,
    pushes) of a configuration with an implicit method, which no batch takes, run one at a
    time on the scipy engine: a tree's and one body's give the outcomes (reached t_end, v(0),
    v(t_end)) of the same runs integrated by DOP853 in a batch, a push's value (the
    disturbance of the given body and entry) included."""
    from rbstab.analysis.runs import Runs

    push = (['disturbances=[{body: shank, kind: impulse, quantity: torque, value: [1, 0, 0], start: 0.2}]'] if body
            else ["disturbances.0.start=0.2", "disturbances.1.start=0.6"])
    settings = ["simulation.t_end=1.0", "simulation.n_samples=11", "simulation.rtol=1e-10", "simulation.atol=1e-12",
                "simulation.limits.omega=[20, 20, .inf]", *push]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs = {method: Runs(load_config(ROOT / "configs" / path, [*settings, f"simulation.method={method}"]))
                for method in ("Radau", "DOP853")}
    states = runs["DOP853"].initial_state[None].repeat(3, axis=0)
    states[1, 3:6] += 0.5  # a spin
    pushes = np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [60.0, 0.0, 0.0]])  # the last one fatal for both
    one, batch = (r.outcomes(states, disturbance=(body, 0, pushes)) for r in (runs["Radau"], runs["DOP853"]))
    assert one.shape == batch.shape == (3, 3)
    assert np.array_equal(one[0], batch[0]) and one[0].tolist() == [1.0, 1.0, 0.0]
    assert np.allclose(one[1], batch[1], rtol=1e-12, atol=0.0)
    assert np.allclose(one[2, :2], batch[2, :2], rtol=1e-6, atol=1e-9 * np.abs(batch[1]).max())
    assert np.isnan(one[2, 2]) and np.isnan(batch[2, 2])


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_trees_solver_counts_are_one_bodys(engine):
    """A tree's run reports the solver counts one body's does (scipy's nfev, njev, nlu and
    solver_status, the compiled driver's steps too): an implicit method's Jacobians and LU
    decompositions counted, the compiled driver's status code (a step limit: STEP_LIMIT)."""
    from rbstab.engine.status import STEP_LIMIT

    examples, short = ROOT / "configs" / "examples", ["simulation.t_end=0.2", "simulation.n_samples=21"]
    knee = simulate(load_config(examples / "knee.yaml", short), engine=engine)
    body = simulate(load_config(examples / "free_gravity.yaml", short), engine=engine)
    assert set(knee.solver) == set(body.solver)
    radau = simulate(load_config(examples / "knee.yaml", [*short, "simulation.method=Radau"]), engine=engine)
    assert radau.ok and radau.solver["njev"] > 0 and radau.solver["nlu"] > 0
    stopped = simulate(load_config(examples / "knee.yaml", [*short, "simulation.max_steps=5"]), engine=engine)
    assert stopped.solver["solver_status"] == (STEP_LIMIT if engine == "compiled" else 1)  # scipy: a terminal event


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_tree_leaves_its_region_falling_through_a_bound_or_thrown_out_by_an_impulse(engine):
    """The stance example's trunk starts on its bound of theta (|theta_1| = 0.05 rad) and
    moves inward: the run goes on to t_end, as one body's would (a region is left falling
    through a bound). A trunk pushed at t = 1 s past its bound of omega (0.5 rad/s) stops
    there, at the impulse, on either engine, and the message names the trunk (the body that
    crossed its bound, not the one nearest it at the last sample before)."""
    stance = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    on_bound = simulate(load_config(stance, ["simulation.limits.theta=[0.05,0.05,3]", "simulation.t_end=1",
                                             "simulation.n_samples=101"]), engine=engine)
    assert on_bound.ok, on_bound.message
    pushed = simulate(load_config(stance, [
        "simulation.limits.omega=[0.5,0.5,0.5]", "simulation.t_end=2", "simulation.n_samples=201",
        "disturbances=[{kind: impulse, body: trunk, value: [0, 60, 0], point: [0, 0, 0.3], start: 1.0}]"]),
        engine=engine)
    assert pushed.status == "failed" and pushed.message.endswith("reached simulation.limits.omega = 0.5 rad/s at t = 1 s"), pushed.message
    assert pushed.message.startswith("left the admissible region: |Omega_1| of ")
    assert "|Omega_1| of trunk reached" in pushed.message
    assert np.isfinite(pushed.outputs["lyapunov"][:100]).all() and np.isnan(pushed.outputs["lyapunov"][100:]).all()


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_only_the_angles_a_tree_integrates_meet_gimbal_lock(engine):
    """Two bodies on permanent joints set turning about y at 3 rad/s, no gravity, no gains,
    gimbal_margin 0.3 rad: the lower body's own Euler angles pass theta_2 = pi/2 - 0.3,
    which its permanent joint's Theta_j (from 0.6 rad, the state's) does not, and the run
    goes on, on either engine; straight (a rigid rotation about a principal axis through
    the fixed point) with the upper body started at 1.0 rad, the upper body's Theta, the
    ground joint's Theta_j, reaches the margin and the run stops there, at
    (pi/2 - 0.3 - 1.0) / 3 s. Its message names the joint whose angle locked: the shoulder;
    the elbow, where the lower body starts bent 1.2 rad and turning, the upper at rest."""
    from rbstab.engine.status import SUCCESS, gimbal_status

    limit = np.pi / 2 - 0.3

    def config_of(upper, bend, spin=3.0):
        return config_from_mapping({
            "name": "turning", "gravity": [0, 0, 0],
            "bodies": [{"name": "upper", "mass": 2.0, "inertia": [0.2, 0.2, 0.05]},
                       {"name": "lower", "mass": 1.5, "inertia": [0.1, 0.1, 0.03]}],
            "joints": [{"name": "shoulder", "parent": "ground", "parent_point": [0, 0, 0], "child": "upper",
                        "child_point": [0, 0, 0.4], "variant": "permanent", "k_r": [0, 0, 0], "l_r": [0, 0, 0]},
                       {"name": "elbow", "parent": "upper", "parent_point": [0, 0, -0.4], "child": "lower",
                        "child_point": [0, 0, 0.3], "variant": "permanent", "k_r": [0, 0, 0], "l_r": [0, 0, 0]}],
            "initial_state": {"upper": {"theta": [0.0, upper, 0.0], "omega": [0.0, spin, 0.0]},
                              "lower": {"theta": [0.0, upper + bend, 0.0], "omega": [0.0, 3.0, 0.0]}},
            "simulation": {"t_end": 0.2, "n_samples": 201, "method": "DOP853", "rtol": 1e-10, "atol": 1e-12,
                           "gimbal_margin": 0.3},
        })

    def run(upper, bend):
        config = config_of(upper, bend)
        if engine == "scipy":
            return simulate(config, engine="scipy")
        compiled = C.compile_chain(config.chain, offset=0.0)
        sim = config.simulation
        return integrate_chain_runs(tree_system(compiled), C.initial_state(config)[None], settings_rows([sim]),
                                    method=sim.method, n_samples=sim.n_samples)

    on, locked = run(0.5, 0.6), run(1.0, 0.0)
    if engine == "scipy":
        assert on.status == "success" and locked.status == "failed" and "gimbal" in locked.message
        lower = on.outputs["theta"][:, 1, 1]
        t_stop = locked.time[np.isfinite(locked.outputs["lyapunov"])][-1]
    else:
        assert on.status[0] == SUCCESS and locked.status[0] == gimbal_status(0, True)  # the shoulder's Theta_j
        lower = on.samples[0, :, 13]
        t_stop = locked.t_stop[0]
    assert np.abs(lower).max() > limit + 0.1  # the lower body's own angles passed the margin
    assert t_stop == pytest.approx((limit - 1.0) / 3.0, abs=0.002)
    for (upper, bend, spin), joint in (((1.0, 0.0, 3.0), "shoulder"), ((0.0, 1.2, 0.0), "elbow")):
        result = simulate(config_of(upper, bend, spin), engine=engine)
        assert result.status == "failed"
        assert result.message.startswith(f"gimbal lock: |theta_2| of joint {joint}'s Theta_j reached pi/2 - 0.3 rad")


@pytest.mark.parametrize("engine", ["compiled", "scipy"])
def test_a_gimbal_lock_names_the_body_that_reached_it_not_the_one_furthest_at_the_last_sample(engine):
    """Two bodies, each on a free joint to the ground, no gravity, no gains: 'tilted' rests
    at theta_2 = 1.0 rad, 'spinner' starts at 0 turning about y at 3 rad/s and reaches
    pi/2 - 0.3 rad at (pi/2 - 0.3) / 3 = 0.42 s. Sampled at 0, 0.5 and 1 s, the last sample
    before the stop is the start, where 'tilted' is the one nearer the lock; the message
    names the spinner on both engines (the compiled driver's status code names it)."""
    config = config_from_mapping({
        "name": "two_free", "gravity": [0, 0, 0],
        "bodies": [{"name": "tilted", "mass": 2.0, "inertia": [0.2, 0.2, 0.05]},
                   {"name": "spinner", "mass": 1.5, "inertia": [0.1, 0.1, 0.03]}],
        "joints": [{"name": "a", "parent": "ground", "parent_point": [0, 0, 0], "child": "tilted",
                    "child_point": [0, 0, 0], "variant": "free", "k_r": [0, 0, 0], "l_r": [0, 0, 0]},
                   {"name": "b", "parent": "ground", "parent_point": [1, 0, 0], "child": "spinner",
                    "child_point": [0, 0, 0], "variant": "free", "k_r": [0, 0, 0], "l_r": [0, 0, 0]}],
        "initial_state": {"tilted": {"theta": [0.0, 1.0, 0.0]}, "spinner": {"omega": [0.0, 3.0, 0.0]}},
        "simulation": {"t_end": 1.0, "n_samples": 3, "method": "DOP853", "rtol": 1e-10, "atol": 1e-12,
                       "gimbal_margin": 0.3},
    })
    result = simulate(config, engine=engine)
    assert result.status == "failed"
    assert result.message.startswith("gimbal lock: |theta_2| of body spinner's Theta reached pi/2 - 0.3 rad at t = ")
    assert float(result.message.split("at t = ")[1].split(" s")[0]) == pytest.approx((np.pi / 2 - 0.3) / 3, rel=1e-5)


def test_a_basin_map_across_the_gimbal_lock_reads_alike_in_both_spellings_of_one_body():
    """Case 2's body tilted through |theta_2| = pi/2 - gimbal_margin in its one-body and its
    tree spelling: the same outcomes, times and v at every point, and the same words for the
    points outside the domain (the body's own Euler angles, whichever way it is written)."""
    from rbstab.analysis.basin import OUTSIDE, BasinAxis, basin_map

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one = load_config(ROOT / "configs" / "paper" / "case2_visco_elastic.yaml")
        tree = tree_spelling(one)
    maps = [basin_map(config, [BasinAxis.parse(f"initial_state.{body}theta.1=-2:2:5"),
                               BasinAxis.parse(f"initial_state.{body}omega.0=-5:5:3")], n_samples=101)
            for config, body in ((one, ""), (tree, "body."))]
    for name in ("outcome", "time_to_converge", "lyapunov_initial", "lyapunov_final"):
        np.testing.assert_array_equal(getattr(maps[0], name), getattr(maps[1], name), err_msg=name)
    assert maps[0].messages == maps[1].messages == {OUTSIDE: 6}
