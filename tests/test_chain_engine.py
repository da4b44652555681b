"""The compiled driver on chains (rbstab.engine.systems): it takes solve_ivp's steps on a
chain's rate, a one-body chain on it moves as the one-body engine's body, and a
disturbance's work, integrated with the state, is what v gains without damping."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from rbstab.config import load_config
from rbstab.config.chains import chain_config_from_mapping, chain_of, load_any_config
from rbstab.engine.integrate import integrate_chain_runs, integrate_runs
from rbstab.engine.settings import settings_rows
from rbstab.engine.systems import chain_system
from rbstab.simulator import simulate_chain
from rbstab.variants import chain as C

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["stance_ankle_hip", "double_pendulum"])
def test_the_compiled_driver_takes_solve_ivps_steps_on_a_chain(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_any_config(ROOT / "configs" / "examples" / f"{name}.yaml",
                                 ["simulation.t_end=1.0", "simulation.n_samples=201"])
    reference = simulate_chain(config, engine="scipy")
    compiled = simulate_chain(config, engine="compiled")
    assert compiled.status == reference.status == "success"
    assert compiled.solver["nfev"] == reference.solver["nfev"]  # the same steps
    for key in ("theta", "omega", "position", "velocity", "lyapunov"):
        scale = 1.0 + np.abs(reference.outputs[key]).max()
        np.testing.assert_allclose(compiled.outputs[key], reference.outputs[key], rtol=0, atol=1e-9 * scale,
                                   err_msg=key)


def test_a_one_body_chain_on_the_compiled_driver_moves_as_the_one_body_engines_body():
    """Case 3 (embedded, the body's own equations) and its one-body chain (the chain's
    core), each on the compiled driver: two formulations, the same trajectory."""
    config = load_config(ROOT / "configs" / "paper" / "case3_embedded.yaml")
    sim = config.simulation
    variant = config.make_variant()
    y0 = variant.initial_state(config.initial_state)
    settings = settings_rows([sim])
    body = integrate_runs([variant.code], np.atleast_1d(variant.parameters), y0[None], settings, method=sim.method,
                          n_samples=sim.n_samples)
    compiled = C.compile_chain(chain_of(config), offset=0.0)
    chain = integrate_chain_runs(chain_system(compiled), y0[None], settings, method=sim.method, n_samples=sim.n_samples)
    assert body.status[0] == chain.status[0] == 0
    scale = 1.0 + np.abs(body.samples).max(axis=(0, 1))
    assert np.max(np.abs(chain.samples - body.samples) / scale) < 1e-8


def _pulsed_chain(l_r):
    """Two bodies on permanent (ball) joints under gravity with joint springs, damping
    ``l_r``, and a pulse of force on the lower body from 0.2 s to 0.5 s."""
    return chain_config_from_mapping({
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


def test_a_pulses_work_on_a_chain_is_what_v_gains_without_damping():
    """No damping, no saturation: v(t) - v(0) = W(t), the disturbance's work, integrated
    by the driver with the state; with damping v gains less. The pulse's edges are
    breakpoints: W is flat outside [0.2, 0.5] s."""
    for l_r, exact in ((0.0, True), (2.0, False)):
        config = _pulsed_chain(l_r)
        sim = config.simulation
        compiled = C.compile_chain(config.chain)
        sol = integrate_chain_runs(chain_system(compiled), C.initial_state(config)[None], settings_rows([sim]),
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


def test_a_chains_basin_map_runs_each_point_as_rbstab_run_would():
    """Each grid point of a chain's basin map is the run of the configuration with that
    initial state (the bodies the config places re-placed on their joints: a tilt of the
    legs carries the trunk); the same outcome and v(t_end)."""
    from rbstab.analysis import BasinAxis, chain_basin_map

    overrides = ["simulation.t_end=1.5", "simulation.n_samples=151", "simulation.limits.theta=[0.6, 0.6, 3.2]"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_any_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", overrides)
    axes = [BasinAxis.parse("initial_state.legs.theta.0=-0.5:0.5:3"), BasinAxis.parse("initial_state.trunk.omega.0=-4:4:3")]
    found = chain_basin_map(config, axes, n_samples=151)
    assert found.outcome.shape == (3, 3) and found.counts()["failed"] >= 1  # a fall leaves the region
    assert found.outcome[1, 1] < 2 and found.lyapunov_final[1, 1] < 0.1 * found.lyapunov_initial[1, 1]  # it recovers
    for i, j in ((0, 2), (1, 1), (2, 0)):
        theta, omega = float(axes[0].values[i]), float(axes[1].values[j])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            point = load_any_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml",
                                    [*overrides, f"initial_state.legs.theta=[{theta!r}, 0, 0]",
                                     f"initial_state.trunk.omega=[{omega!r}, 0, 0]"])
        np.testing.assert_allclose(found.initial_states[i, j], C.initial_state(point), atol=1e-14)
        result = simulate_chain(point)
        assert (result.status == "success") == (found.outcome[i, j] < 2)
        if result.status == "success":
            assert found.lyapunov_final[i, j] == pytest.approx(result.outputs["lyapunov"][-1], rel=1e-12, abs=1e-14)
