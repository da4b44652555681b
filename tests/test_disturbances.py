"""Disturbances (impulse, pulse, step, sine, noise): the compiled physics against the plain
numpy reference, the energy bookkeeping (v(t) - v(0) = integral of dv/dt; v - W never rises
with unsaturated gains), impulses as velocity jumps at exact breakpoints (the limit of ever
shorter pulses; momentum and angular momentum jumps), the noise's RMS and band, and bad
input refused in one line."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reference import NOISE_TONES, disturbed_rates, hat, impulse_jump, noise_phases, noise_value, rotation
from rbstab.variants.paper import paper_form
from rbstab.config import ConfigError, config_from_mapping
from rbstab.model import Disturbance
from rbstab.simulator import simulate

FULL = ["free", "visco_elastic", "embedded", "sliding"]


def _mapping(variant="visco_elastic", disturbances=(), t_end=2.0, n_samples=401, theta=(0.1, -0.05, 0.2),
             gravity=(0.0, 0.0, -9.81), rtol=1e-10, atol=1e-12):
    ctrl = {"variant": variant, "k_t": [20, 20, 20], "l_t": [8, 8, 8], "k_r": [5, 5, 5], "l_r": [1, 1, 1]}
    if variant in ("visco_elastic", "embedded", "sliding"):
        ctrl.update(k_c=[300, 300, 300], l_c=[30, 30, 30])
    if variant == "embedded":
        ctrl.update(k_d=[200, 200, 200], l_d=[20, 20, 20])
    if variant == "sliding":
        ctrl.update(k_s=50.0, boundary_layer=0.01)
    data = {"name": "pushed", "body": {"mass": 2.0, "inertia": [0.2, 0.3, 0.4], "attachment_point": [0, 0, 0.3],
                                      "gravity": list(gravity)},
            "controller": ctrl, "initial_state": {"theta": list(theta), "omega": [0.3, -0.2, 0.1]},
            "simulation": {"t_end": t_end, "n_samples": n_samples, "rtol": rtol, "atol": atol}}
    if disturbances:
        data["disturbances"] = [dict(d) for d in disturbances]
    return data


PUSHES = [
    {"kind": "pulse", "value": [0, 5, 1], "point": [0, 0.1, 0.2], "start": 0.3, "duration": 0.2},
    {"kind": "sine", "quantity": "torque", "value": [0.3, 0, 0.1], "frequency": 2.0, "phase": 0.5, "start": 0.1},
    {"kind": "step", "value": [1, 0, 0], "point": [0.1, 0, 0], "start": 1.0},
    {"kind": "impulse", "value": [0.2, 0.5, 0], "point": [0, 0, 0.2], "start": 0.75},
]
NOISE = {"kind": "noise", "rms": [3.0, 1.0, 2.0], "band": [0.5, 5.0], "point": [0, 0.1, 0.2], "seed": 11,
         "start": 0.1}


@pytest.mark.parametrize("name", ["free", "permanent", "visco_elastic", "embedded", "sliding"])
def test_state_rate_adds_what_the_numpy_reference_adds(name):
    """dOmega/dt and dV/dt gain J^-1 (T + R_p x A'F) and F / m (reference.py) at random
    states and times (full state); for permanent the pinned body's J_p. A pulse, a sine, a
    step and a noise (reference.py sums its sines one by one)."""
    config = config_from_mapping(_mapping(name, [*PUSHES[:3], NOISE]))
    plain = config_from_mapping(_mapping(name))
    variant, undisturbed = paper_form(config), paper_form(plain)
    rng = np.random.default_rng(4)
    for t in (0.35, 0.2, 1.3, 0.05):
        y = rng.normal(size=variant.layout.size) * 0.3
        delta = variant.rhs(t, y) - undisturbed.rhs(t, y)
        theta = y[:3]
        if name == "permanent":
            from reference import disturbance_wrench
            body = paper_form(config).body
            force, torque = disturbance_wrench(paper_form(config).gains.disturbances, theta, t)
            r = np.asarray(body.attachment_point)
            j_p = body.inertia - body.mass * hat(r) @ hat(r)
            expected = np.linalg.solve(j_p, torque - np.cross(r, rotation(theta).T @ force))
            np.testing.assert_allclose(delta[3:6], expected, rtol=1e-11, atol=1e-12)
            continue
        d_omega, d_v = disturbed_rates(paper_form(config).body, paper_form(config).gains.disturbances, theta, t)
        np.testing.assert_allclose(delta[3:6], d_omega, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(delta[9:12], d_v, rtol=1e-11, atol=1e-12)
        np.testing.assert_array_equal(delta[:3], 0.0)


def test_a_disturbance_window_between_two_samples_runs_on_both_engines():
    """Windows with no sample inside (a pulse shorter than the sample spacing, a push between
    two samples): the scipy reference integrates them (it raised on a window without a
    sample) and agrees with the compiled engine at the samples, W included."""
    config = config_from_mapping(_mapping("visco_elastic", PUSHES[:1] + PUSHES[3:], t_end=2.0, n_samples=3))
    a, b = (simulate(config, engine=engine) for engine in ("compiled", "scipy"))
    assert a.status == b.status == "success", b.message
    for key in ("theta", "lyapunov", "disturbance_work"):
        np.testing.assert_allclose(b.outputs[key], a.outputs[key], rtol=1e-8, atol=1e-10)
    assert b.outputs["disturbance_work"][-1] != 0.0


@pytest.mark.parametrize("name", ["free", "permanent", "visco_elastic", "embedded"])
def test_v_minus_w_never_rises_and_engines_agree(name):
    """With unsaturated gains dv/dt = -dissipation + P, so v - W never increases (every kind,
    impulses included); the scipy path takes the compiled engine's steps (same breakpoints).
    W is two formulations of one integral (the compiled engine integrates it with the state,
    the scipy path by 5-point Gauss-Legendre along its steps): they agree to 1e-9 of max |W|."""
    config = config_from_mapping(_mapping(name, PUSHES))
    results = {engine: simulate(config, engine=engine) for engine in ("compiled", "scipy")}
    for r in results.values():
        assert r.status == "success", r.message
        v, w = r.outputs["lyapunov"], r.outputs["disturbance_work"]
        assert np.max(np.diff(v - w)) <= 1e-9 * np.max(np.abs(v))
        assert np.any(w != 0.0)
    a, b = results["compiled"], results["scipy"]
    assert a.solver["nfev"] == b.solver["nfev"]
    for key in ("theta", "omega", "lyapunov"):
        np.testing.assert_allclose(a.outputs[key], b.outputs[key], rtol=1e-9, atol=1e-11)
    w = b.outputs["disturbance_work"]
    np.testing.assert_allclose(a.outputs["disturbance_work"], w, rtol=0, atol=1e-9 * np.max(np.abs(w)))


def test_energy_identity_to_1e_8():
    """v(t) - v(0) equals the integral of the analytic dv/dt (with the disturbance's power)
    to 1e-8 of the variation of v: a smooth sine torque and force from t = 0."""
    pushes = [{"kind": "sine", "quantity": "torque", "value": [0.4, 0.2, 0.1], "frequency": 1.5, "start": 0.0},
              {"kind": "sine", "value": [2, 1, 0], "point": [0.05, 0, 0.1], "frequency": 0.7, "start": 0.0}]
    config = config_from_mapping(_mapping("visco_elastic", pushes, n_samples=4001, rtol=1e-12, atol=1e-14))
    r = simulate(config)
    from scipy.integrate import cumulative_simpson

    t, v, rate = r.time, r.outputs["lyapunov"], r.outputs["lyapunov_rate"]
    integral = cumulative_simpson(rate, x=t, initial=0.0)
    scale = np.max(v) - np.min(v)
    assert np.max(np.abs(v - v[0] - integral)) <= 1e-8 * scale
    # and W is the integral of P
    w = cumulative_simpson(r.outputs["disturbance_power"], x=t, initial=0.0)
    assert np.max(np.abs(r.outputs["disturbance_work"] - w)) <= 1e-8 * np.max(np.abs(w))


@pytest.mark.parametrize("quantity", ["force", "torque"])
@pytest.mark.parametrize("name", ["free", "permanent"])
def test_impulse_jumps_the_velocities(name, quantity):
    """The samples at the impulse's start show the state just after it: dV = P/m and the
    angular momentum about the centre of mass A J Omega jumps by (A R_p) x P (force) or A L
    (torque); permanent: J_p dOmega = (R_p - R) x A'P. W jumps by the kinetic energy's jump."""
    push = {"kind": "impulse", "quantity": quantity, "value": [0.3, -0.5, 0.2], "start": 0.5}
    if quantity == "force":
        push["point"] = [0.05, 0.0, 0.2]
    data = _mapping(name, [push], t_end=1.0, n_samples=201, gravity=(0, 0, 0))
    config = config_from_mapping(data)
    r = simulate(config)
    j = 100  # t = 0.5
    assert r.time[j] == 0.5
    plain = simulate(config_from_mapping(_mapping(name, (), t_end=0.5, n_samples=101, gravity=(0, 0, 0))))
    before = {k: plain.outputs[k][-1] for k in ("theta", "omega", "velocity")}
    np.testing.assert_allclose(r.outputs["theta"][j], before["theta"], atol=1e-12)
    d = paper_form(config).gains.disturbances[0]
    d_omega, d_v = impulse_jump(paper_form(config).body, d, before["theta"], permanent=name == "permanent")
    np.testing.assert_allclose(r.outputs["omega"][j] - before["omega"], d_omega, rtol=1e-9, atol=1e-11)
    if name == "free":
        np.testing.assert_allclose(r.outputs["velocity"][j] - before["velocity"], d_v, rtol=1e-9, atol=1e-11)
        a = rotation(before["theta"])
        jump_l = a @ paper_form(config).body.inertia @ (r.outputs["omega"][j] - before["omega"])
        expected = np.cross(a @ d.point, d.value) if quantity == "force" else a @ d.value
        np.testing.assert_allclose(jump_l, expected, rtol=1e-9, atol=1e-11)
    dw = r.outputs["disturbance_work"][j] - r.outputs["disturbance_work"][j - 1]
    dv = r.outputs["lyapunov"][j] - before_v(plain)
    assert dw == pytest.approx(dv, rel=1e-7, abs=1e-10)


def before_v(result):
    return result.outputs["lyapunov"][-1]


def test_an_impulse_is_the_limit_of_ever_shorter_pulses():
    """A pulse P/d over [t0, t0 + d) tends to the impulse P as d -> 0, the error ~ d."""
    def final(push):
        r = simulate(config_from_mapping(_mapping("visco_elastic", [push], t_end=1.0, n_samples=101)))
        return np.concatenate([r.outputs["theta"][-1], r.outputs["omega"][-1], r.outputs["velocity"][-1]])

    p = np.array([0.3, 0.6, -0.2])
    impulse = final({"kind": "impulse", "value": p.tolist(), "point": [0, 0.1, 0.2], "start": 0.3})
    errors = []
    for d in (4e-3, 2e-3, 1e-3):
        pulse = final({"kind": "pulse", "value": (p / d).tolist(), "point": [0, 0.1, 0.2], "start": 0.3,
                       "duration": d})
        errors.append(np.max(np.abs(pulse - impulse)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 1.7) & (ratios < 2.3)), (errors, ratios)


def test_noise_rms_and_band():
    """The multisine's RMS over a long window is within 5 % of the request on each axis, its
    spectrum inside the band, and it is the same for the same seed."""
    push = {"kind": "noise", "rms": [5.0, 2.0, 0.0], "band": [0.5, 5.0], "seed": 7, "start": 0.0}
    config = config_from_mapping(_mapping("free", [push], gravity=(0, 0, 0)))
    plain = paper_form(config_from_mapping(_mapping("free", (), gravity=(0, 0, 0))))
    variant = paper_form(config)
    dt, n = 0.01, 2 ** 15  # 327 s
    y = np.zeros((n, 12))
    t = np.arange(n) * dt
    force = np.array([variant.rhs(ti, y[0])[9:12] - plain.rhs(ti, y[0])[9:12] for ti in t]) * paper_form(config).body.mass
    rms = np.sqrt(np.mean(force ** 2, axis=0))
    np.testing.assert_allclose(rms[:2], [5.0, 2.0], rtol=0.05)
    assert rms[2] == 0.0
    spectrum = np.abs(np.fft.rfft(force[:, 0] * np.hanning(n))) ** 2
    f = np.fft.rfftfreq(n, dt)
    outside = spectrum[(f < 0.4) | (f > 5.1)].sum() / spectrum.sum()
    assert outside < 1e-3
    again = paper_form(config_from_mapping(_mapping("free", [push], gravity=(0, 0, 0))))
    np.testing.assert_array_equal(again.rhs(3.3, y[0]), variant.rhs(3.3, y[0]))


def test_noise_is_its_sines_summed_one_by_one():
    """The compiled noise (its sines' phasors by a recurrence, their phases from a table)
    equals the plain sum of the sines of reference.py to 2e-13 of the RMS over tau in
    [0, 10] s, axis by axis; seeds and axes draw other phases, and an axis of RMS 0 is 0."""
    push = dict(NOISE, start=0.5, rms=[3.0, 0.0, 2.0], seed=2 ** 31 - 1)
    config = config_from_mapping(_mapping("free", [push], t_end=12.0, gravity=(0, 0, 0)))
    plain = paper_form(config_from_mapping(_mapping("free", (), t_end=12.0, gravity=(0, 0, 0))))
    variant, d = paper_form(config), paper_form(config).gains.disturbances[0]
    y = np.zeros(12)
    t = np.random.default_rng(3).uniform(0.5, 10.5, 400)
    got = np.array([variant.rhs(ti, y)[9:12] - plain.rhs(ti, y)[9:12] for ti in t]) * paper_form(config).body.mass
    expected = np.array([noise_value(d, ti) for ti in t])
    assert np.all(np.abs(got - expected) <= 2e-13 * np.array(push["rms"])), np.max(np.abs(got - expected), axis=0)
    assert np.max(np.abs(expected[:, 0])) > 3.0 and np.all(got[:, 1] == 0.0)
    phases = np.array([noise_phases(seed, axis) for seed in (0, 1, 2) for axis in range(3)])
    assert phases.shape == (9, NOISE_TONES)
    differ = np.abs(np.angle(np.exp(1j * (phases[:, None] - phases[None]))))  # every pair, tone by tone
    assert np.all(differ.max(axis=2) + np.eye(9) > 0.1)


@pytest.mark.parametrize(("push", "key", "found"), [
    ({"kind": "shove", "value": [1, 0, 0]}, "disturbances.0.kind", "'shove'"),
    ({"kind": "step", "quantity": "moment", "value": [1, 0, 0]}, "disturbances.0.quantity", "'moment'"),
    ({"kind": "step", "value": [1, 0, 0], "start": 3.0}, "disturbances.0.start", "3.0"),
    ({"kind": "step", "value": [1, 0, 0], "start": -1.0}, "disturbances.0.start", "-1.0"),
    ({"kind": "pulse", "value": [1, 0, 0]}, "disturbances.0.duration", "nothing"),
    ({"kind": "noise", "rms": 1.0, "band": [5.0, 1.0], "seed": 1}, "disturbances.0.band", "[5.0, 1.0]"),
    ({"kind": "noise", "rms": 1.0, "band": [-1.0, 1.0], "seed": 1}, "disturbances.0.band", "[-1.0, 1.0]"),
    ({"kind": "noise", "rms": 1.0, "band": [1.0, 2.0]}, "disturbances.0.seed", "nothing"),
    ({"kind": "step", "quantity": "torque", "value": [1, 0, 0], "point": [0, 0, 1]}, "disturbances.0.point",
     "[0, 0, 1]"),
    ({"kind": "step", "value": [1, 0]}, "disturbances.0.value", "[1, 0]"),
])
def test_bad_disturbances_are_refused_in_one_line(push, key, found):
    with pytest.raises(ConfigError) as info:
        config_from_mapping(_mapping("free", [push]))
    lines = info.value.errors
    assert len(lines) == 1, lines
    assert f"'{key}'" in lines[0] and found in lines[0] and "expected" in lines[0], lines[0]


def test_too_many_disturbances_and_the_sign_law_are_refused():
    with pytest.raises(ConfigError) as info:
        config_from_mapping(_mapping("free", [PUSHES[2]] * 5))
    assert len(info.value.errors) == 1 and "at most 4" in info.value.errors[0]
    data = _mapping("sliding", [PUSHES[2]])
    data["controller"]["boundary_layer"] = 0.0
    with pytest.raises(ConfigError) as info:
        config_from_mapping(data)
    assert len(info.value.errors) == 1 and "sign law" in info.value.errors[0]


def test_cli_refuses_a_bad_disturbance_and_writes_nothing(tmp_path):
    import yaml

    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_mapping("free", [{"kind": "pulse", "value": [1, 0, 0]}])))
    out = tmp_path / "out"
    cli = Path(sys.executable).parent / "rbstab"
    done = subprocess.run([str(cli), "run", str(path), "--output", str(out)], capture_output=True, text=True)
    assert done.returncode == 1, done.stderr
    assert "disturbances.0.duration" in done.stderr
    assert not out.exists() or not any(out.iterdir())


def test_batch_records_carry_the_disturbances_as_columns():
    """A sweep's batch gives the validated configuration's record bit for bit, and a column
    ``disturbances.0.value.1`` sets that entry."""
    from rbstab.engine.batch import batch_from_table

    config = config_from_mapping(_mapping("visco_elastic", PUSHES))
    batch = batch_from_table([config.resolved], ["disturbances.0.value.1"],
                             {"disturbances.0.value.1": np.array([5.0, 7.0])}, np.array([0, 0]))
    assert batch.params[0, 0].tobytes() == paper_form(config).parameters[0].tobytes()
    assert batch.params[1, 0]["disturbance_value"][0, 1] == 7.0


def test_analysis_linearises_the_undisturbed_dynamics_and_samples_the_disturbed():
    """A step force from t = 0: the equilibrium, the linearisation and the certificate's
    Hessians are those of the same body without it (a rest point, the same eigenvalues bit
    for bit; at t = 0 the disturbed right-hand side is not at rest there), while the
    certificate's sampled dv/dt includes the step's power F'V, which is positive near the
    equilibrium: the sampled sublevel estimate shrinks to where dv/dt > 0 was sampled (and
    the local search and the runs from {v = c} may lower it further)."""
    from rbstab.analysis.analyze import analyze

    pushed = config_from_mapping(_mapping(disturbances=[{"kind": "step", "value": [0, 6, 0], "point": [0, 0, 0.1]}]))
    calm = config_from_mapping(_mapping())
    a, b = (analyze(c, samples=300, simulate=False) for c in (pushed, calm))
    assert np.max(np.abs(paper_form(pushed).rhs(0.0, a.linearisation.equilibrium))) > 1.0  # not at rest, pushed
    assert a.linearisation.is_rest_point
    np.testing.assert_array_equal(a.linearisation.eigenvalues, b.linearisation.eigenvalues)
    np.testing.assert_array_equal(a.certificate.rate_hessian, b.certificate.rate_hessian)
    assert any("undisturbed dynamics" in n and "(step)" in n for n in a.notes)
    assert not any("undisturbed" in n for n in b.notes)
    assert b.certificate.sublevel_bound == "domain boundary"
    assert a.certificate.sublevel_bound != "domain boundary"
    assert a.certificate.sublevel <= a.certificate.sublevel_sampled < 1e-3 * b.certificate.sublevel


EXAMPLE = Path(__file__).resolve().parents[1] / "configs" / "examples" / "saturated_push.yaml"


def _sweep(tmp_path, name: str, body: str, *sets: str):
    spec = tmp_path / f"{name}.yaml"
    spec.write_text(f"name: {name}\nbase: {EXAMPLE}\n{body}")
    cli = Path(sys.executable).parent / "rbstab"
    return subprocess.run([str(cli), "sweep", str(spec), "-o", str(tmp_path / "out"), "-j", "1", "--no-progress",
                           "--set", "simulation.n_samples=2001", *sets], capture_output=True, text=True)


def test_a_sweep_varies_a_push_and_a_torque_limit_end_to_end(tmp_path):
    """The shipped saturated push swept over the impulse (disturbances.0.value.0, a grid) and
    the torque limit (controller.saturation.torque_n), and zipped over the whole impulse and
    3 limits, with an admissible region of 1.2 rad: the values are columns; a lower limit
    saturates longer, and the strong push with the 3 N m limit (below m g L sin of the tilt
    it reaches) falls while 6 N m holds it (without the region it swings over and back up,
    and converges)."""
    import pandas as pd

    fall = ("--set", "simulation.limits.theta=[1.2, 1.2, .inf]")  # past it the pendulum has fallen
    done = _sweep(tmp_path, "grid", "grid:\n  disturbances.0.value.0: [0.2, 1.0]\n"
                                    "  controller.saturation.torque_n: [3.0, 6.0]\n", *fall)
    assert done.returncode == 0, done.stderr
    index = pd.read_csv(tmp_path / "out" / "grid" / "index.csv").set_index(["value_0", "torque_n"])
    assert len(index) == 4 and index["outcome"].to_dict() == {
        (0.2, 3.0): "converged", (0.2, 6.0): "converged", (1.0, 3.0): "fell", (1.0, 6.0): "converged"}
    fraction = index["fraction_saturated_torque_n_x"]
    assert fraction[0.2, 3.0] > fraction[0.2, 6.0] and fraction[1.0, 3.0] > fraction[1.0, 6.0] > fraction[0.2, 6.0]
    assert index["converged"].to_dict() == {(0.2, 3.0): True, (0.2, 6.0): True, (1.0, 3.0): False, (1.0, 6.0): True}
    done = _sweep(tmp_path, "zipped", "zip:\n  disturbances.0.value: [[0.2, 0, 0], [1.0, 0, 0]]\n"
                                      "  controller.saturation.torque_n: [[3, 3, .inf], [6, 6, .inf]]\n", *fall)
    assert done.returncode == 0, done.stderr
    zipped = pd.read_csv(tmp_path / "out" / "zipped" / "index.csv")
    assert zipped[["value_0", "torque_n_0"]].values.tolist() == [[0.2, 3.0], [1.0, 6.0]]
    np.testing.assert_array_equal(zipped["fraction_saturated_torque_n_x"],
                                  [fraction[0.2, 3.0], fraction[1.0, 6.0]])


@pytest.mark.parametrize("body, key, found", [
    ("grid:\n  disturbances.1.start: [1.0, 9.0]\n", "disturbances.1.start", "9.0"),  # after t_end = 5 s
    ("grid:\n  simulation.t_end: [5.0, 2.0]\n", "disturbances.1.start", "2.5"),  # the pulse's start, after 2 s
    ("zip:\n  disturbances.1.duration: [0.05, -0.1]\n", "disturbances.1.duration", "-0.1"),
    ("grid:\n  controller.saturation.torque_n: [3.0, -6.0]\n", "controller.saturation.torque_n", "-6.0"),
])
def test_a_sweep_refuses_a_bad_push_or_limit_in_one_line_naming_the_key(tmp_path, body, key, found):
    """The column checks (sweep/validate.py, the schema's rules) flag the bad run, the schema
    names it: one line for the one bad run of two, with the key and the value; nothing run."""
    done = _sweep(tmp_path, "bad", body)
    assert done.returncode != 0 and "Traceback" not in done.stderr
    lines = [line for line in done.stderr.splitlines() if "config key" in line]
    assert len(lines) == 1 and f"'{key}'" in lines[0] and f"found {found}" in lines[0], done.stderr
    assert "1 of 2 runs have an invalid configuration; nothing was run" in done.stderr
    assert not (tmp_path / "out" / "bad" / "runs").exists() or not any((tmp_path / "out" / "bad" / "runs").iterdir())


def test_the_rate_check_leaves_out_the_stencils_across_a_push_and_stays_a_check():
    """v jumps at an impulse and dv/dt at a pulse's edges: a 7-point stencil across one is
    no derivative. The check compares the samples whose stencil lies between two edges
    (disturbance_edges equal at its ends): (RATE_STENCIL - 1) samples fewer per edge inside
    the run; the pushed example passes there (it failed by 70 P across the impulse). It
    still fails when the analytic dv/dt lacks the disturbances' power."""
    import warnings

    from rbstab.summary import LYAPUNOV_RATE_TOLERANCE, RATE_STENCIL, _within_one_piece, summarize

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = simulate(__import__("rbstab").load_config(EXAMPLE))  # dense: the clipped torque has kinks
    edges = result.outputs["disturbance_edges"]
    assert list(np.unique(edges)) == [0.0, 1.0, 2.0, 3.0]  # the impulse, the pulse's start and end
    within = _within_one_piece(result.time, edges[None])[0]
    assert np.sum(~within) == 3 * (RATE_STENCIL - 1)
    assert result.summary["lyapunov_rate_check"] == "pass"
    assert result.summary["lyapunov_rate_mismatch_relative"] <= LYAPUNOV_RATE_TOLERANCE
    jumped = np.abs(result.outputs["lyapunov_rate"] - result.outputs["lyapunov_rate_numerical"])
    assert np.max(jumped[~within]) > 10 * result.summary["lyapunov_rate_mismatch"]  # what is left out
    wrong = dict(result.outputs, lyapunov_rate=result.outputs["lyapunov_rate"] - result.outputs["disturbance_power"])
    assert summarize(result.time, wrong)["lyapunov_rate_check"] == "fail"
