"""The Lyapunov certificate of a chain (rbstab.analysis.certificate.ChainModel), in its independent
coordinates: on the planar double inverted pendulum with joint feedback, H_v and H_r are
those written by hand (H_r semi-definite: the dampers act on the joints' relative rates
only), the analytic dv/dt is the directional derivative of v along the flow, and no run
started inside {v <= c} fails to recover; a one-body chain's level is the one-body
certificate's; a chain whose feedback cannot hold it up has no level, and one with a
negative damper has dv/dt > 0 found next to the rest state."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest
from paper_model import VariantModel, linearise

from rbstab.analysis import analyze
from rbstab.analysis.certificate import certify, level_states
from rbstab.analysis.runs import Runs
from rbstab.analysis.text import describe
from rbstab.analysis.certificate import ChainModel
from rbstab.analysis.linearise import linearise_chain
from rbstab.config.loader import config_from_mapping
from rbstab.variants import chain as C

M1, M2, I1, I2, C1, L1, C2 = 28.0, 42.0, 2.6, 2.3, 0.45, 0.9, 0.3
G = 9.81
K_R, L_R = (800.0, 300.0), (150.0, 40.0)


def _planar(k_r=K_R, l_r=L_R, **simulation):
    """The planar double inverted pendulum of tests/test_chains.py as a config: legs on an
    ankle at the origin (centre of mass C1 above it, hip L1 above it), trunk on the hip
    (centre of mass C2 above it), both joints permanent, feedback stiff about x and z and
    (k_r, l_r) about y, the axis they tilt about (theta_2)."""
    joint = lambda name, parent, child, pp, cp, k, d: {  # noqa: E731
        "name": name, "parent": parent, "parent_point": pp, "child": child, "child_point": cp,
        "variant": "permanent", "k_r": [1e3, k, 1e3], "l_r": [1e2, d, 1e2]}
    data = {
        "name": "planar", "gravity": [0.0, 0.0, -G],
        "bodies": [{"name": "legs", "mass": M1, "inertia": [I1, I1, 0.1]},
                   {"name": "trunk", "mass": M2, "inertia": [I2, I2, 0.4]}],
        "joints": [joint("ankle", "ground", "legs", [0, 0, 0], [0, 0, -C1], k_r[0], l_r[0]),
                   joint("hip", "legs", "trunk", [0, 0, L1 - C1], [0, 0, -C2], k_r[1], l_r[1])],
        "initial_state": {"legs": {"theta": [0.0, 0.05, 0.0]}, "trunk": {"theta": [0.0, -0.05, 0.0]}},
        "simulation": {"t_end": 4.0, "n_samples": 2, "rtol": 1e-7, "atol": 1e-9, **simulation},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return config_from_mapping(data)


@pytest.fixture(scope="module")
def planar():
    config = _planar()
    return config, analyze(config, samples=1000, seed=0)


def test_planar_pendulums_hessians_are_the_closed_forms(planar):
    """H_v in the tilts (theta_2 of legs and trunk) is K - G of the absolute tilts, in their
    rates the mass matrix; H_r is -2 T' L_r T (T: absolute rates to the joints' relative
    rates), zero outside the rates: semi-definite with 6 zero generalised eigenvalues of 12
    (the joints' relative rates are 6), and LaSalle's PBH condition holds."""
    _, result = planar
    cert = result.certificate
    names = [(b, k) for b, k, _, _ in result.coordinates]
    assert names == [("legs", "theta"), ("legs", "omega"), ("trunk", "theta"), ("trunk", "omega")]
    tilt, rate = [1, 7], [4, 10]
    k1, k2 = K_R
    stiffness = np.array([[k1 + k2, -k2], [-k2, k2]]) - np.diag([(M1 * C1 + M2 * L1) * G, M2 * C2 * G])
    mass = np.array([[I1 + M1 * C1**2 + M2 * L1**2, M2 * L1 * C2], [M2 * L1 * C2, I2 + M2 * C2**2]])
    h_v, h_r = cert.lyapunov_hessian, cert.rate_hessian
    np.testing.assert_allclose(h_v[np.ix_(tilt, tilt)], stiffness, rtol=1e-6)
    np.testing.assert_allclose(h_v[np.ix_(rate, rate)], mass, rtol=1e-6)
    assert cert.positive_definite and np.all(np.linalg.eigvalsh(h_v) > 0)
    t = np.array([[1.0, 0.0], [-1.0, 1.0]])
    np.testing.assert_allclose(h_r[np.ix_(rate, rate)], -2 * t.T @ np.diag(L_R) @ t, rtol=1e-6)
    theta = [0, 1, 2, 6, 7, 8]
    assert np.abs(h_r[theta]).max() <= 1e-6 * np.abs(h_r).max()
    mu = cert.rate_eigenvalues
    assert int(np.sum(np.abs(mu) <= 1e-8 * np.abs(mu).max())) == 6 and np.all(mu <= 1e-8 * np.abs(mu).max())
    assert cert.rate_definiteness == "negative semi-definite" and cert.lasalle_observable
    assert cert.holds and cert.argument == "LaSalle"


def test_analytic_rate_is_the_directional_derivative_on_the_samples(planar):
    """At every sample on the constraint manifold the analytic dv/dt equals d/ds
    v(z + s f(z)) (from v alone) to 1e-7 of the state's power scale; the samples reach
    above the domain boundary's level."""
    _, result = planar
    cert = result.certificate
    inside = ~cert.sample_outside
    assert cert.n_samples == 1000 and inside.sum() > 900 and np.nanmax(cert.sample_lyapunov) > cert.boundary_level
    analytic, numerical, v = cert.sample_rate_analytic[inside], cert.sample_rate[inside], cert.sample_lyapunov[inside]
    rho = np.abs(result.linearisation.eigenvalues).max()
    assert np.all(np.abs(numerical - analytic) <= 1e-7 * (np.abs(analytic) + rho * np.abs(v)))
    assert cert.rate_mismatch <= 1e-7 and np.all(analytic <= 1e-9 * rho * v)


def test_no_run_started_inside_the_estimate_fails_to_recover(planar):
    """c is positive, bounded by the domain boundary (no actuator saturates), checked against
    32 runs from {v = c} and the configured start; 32 other states on {v = c} and 32 inside
    (drawn with another seed), each run on the compiled engine over 4 s, stay in the domain
    and end with v below a fifth of its start."""
    config, result = planar
    cert = result.certificate
    assert 0 < cert.sublevel <= cert.boundary_level and cert.sublevel_bound == "domain boundary"
    assert cert.runs_checked == 33 and cert.settled and "checked against 33 runs" in cert.evidence
    compiled = C.compile_chain(config.chain)
    model = ChainModel(compiled, result.coordinates)
    on = level_states(model, result.linearisation, cert, 32, seed=7)
    rng = np.random.default_rng(8)
    z_e = result.linearisation.equilibrium
    inside = z_e + rng.uniform(0.2, 1.0, (32, 1)) * (on[::-1] - z_e)
    x = np.concatenate([on, inside])
    v0 = model.lyapunov(x)
    np.testing.assert_allclose(v0[:32], cert.sublevel, rtol=1e-9)
    assert np.all(v0[32:] < cert.sublevel)
    ok, _, v1 = Runs(config).outcomes(model.states(x))
    assert np.all(ok == 1) and np.all(v1 <= 0.2 * v0), (ok, v1 / v0)  # the pass's rule: in the domain, v falls


@pytest.mark.parametrize("name", ["permanent", "visco_elastic"])
def test_a_one_body_chains_level_is_the_one_body_certificates(name):
    """The one-body chain (its joint the body's law, under gravity) has the single body's
    H_v, boundary level and c (1000 samples, the same seed) to 1e-6."""
    from test_chains import _one_body

    variant, compiled = _one_body(name, (0.0, 0.0, -9.81))
    lin_chain, coordinates = linearise_chain(compiled)
    mine = certify(ChainModel(compiled, coordinates), lin_chain, gimbal_margin=0.1, n_samples=1000)
    theirs = certify(VariantModel(variant), linearise(variant), gimbal_margin=0.1, n_samples=1000)
    np.testing.assert_allclose(mine.lyapunov_hessian, theirs.lyapunov_hessian, rtol=1e-6, atol=1e-6)
    assert mine.boundary_level == pytest.approx(theirs.boundary_level, rel=1e-6)
    assert mine.sublevel == pytest.approx(theirs.sublevel, rel=1e-6) and mine.sublevel > 0
    assert mine.sublevel_bound == theirs.sublevel_bound


def test_a_chain_too_weak_to_stand_has_no_level():
    """With the ankle's stiffness below gravity's the upright rest state is a saddle of v:
    H_v is not positive definite, c = 0, no falsification run is made (the one counted is the
    run from the configured initial state, as one body's)."""
    weak = analyze(_planar(k_r=(400.0, 300.0)), samples=200)
    cert = weak.certificate
    assert weak.verdict == "unstable" and not cert.positive_definite and cert.hessian_min_eigenvalue < 0
    assert cert.sublevel == 0 and not cert.holds and cert.runs_checked == 1
    assert "no sublevel estimate" in "\n".join(describe(weak))


def test_a_negative_damper_is_found(planar):
    """A hip damper of -5 N m s/rad about the tilt axis: dv/dt > 0 next to the rest state,
    the certificate does not hold (the test can fail)."""
    base = _planar()
    hip = dataclasses.replace(base.chain.joints[1], l_r=np.diag([1e2, -5.0, 1e2]))  # the schema refuses it
    config = dataclasses.replace(base, chain=dataclasses.replace(base.chain, joints=(base.chain.joints[0], hip)))
    bad = analyze(config, samples=500, falsification_runs=0).certificate
    good = planar[1].certificate
    assert bad.positive_definite and bad.rate_definiteness == "indefinite" and not bad.holds
    assert bad.sublevel < 1e-3 * good.sublevel


def test_rbstab_analyze_gives_a_chains_certificate(tmp_path):
    """The stance example: the certificate printed and in --json (worst_state named by the
    independent coordinates), c positive, bounded by a clipped torque (dv/dt > 0 found by
    the local search), below the domain boundary; --no-certificate leaves it out."""
    from click.testing import CliRunner

    from rbstab.analysis import read_analysis
    from rbstab_cli.main import cli

    path = "configs/examples/stance_ankle_hip.yaml"
    result = CliRunner().invoke(cli, ["analyze", path, "--samples", "500", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "certificate: holds (LaSalle)" in result.output
    assert "inner estimate of the region of attraction" in result.output
    found = CliRunner().invoke(cli, ["analyze", path, "--samples", "500", "--json", "-o", str(tmp_path)])
    record = json.loads(found.stdout.strip().splitlines()[-1])
    c = record["certificate"]
    assert record["kind"] == "chain" and c["positive_definite"] and c["n_samples"] == 500
    assert 0 < c["sublevel"] < c["boundary_level"] and c["sublevel_bound"].startswith("dv/dt > 0")
    assert len(c["worst_state"]) == len(c["coordinates"]) == 12 and c["coordinates"][0] == "legs.theta.0"
    assert c["runs_checked"] >= 33 and c["sublevel_estimate"].startswith("estimate (sampled, 500 states")
    written = read_analysis(tmp_path / "stance_ankle_hip.analysis.nc")  # its file holds the same certificate
    assert float(written["sublevel"].values) == c["sublevel"] and written["sample_lyapunov"].size == 500
    none = CliRunner().invoke(cli, ["analyze", path, "--no-certificate", "--json", "-o", str(tmp_path)])
    assert "certificate" not in json.loads(none.stdout.strip().splitlines()[-1])
    assert "sublevel" not in read_analysis(tmp_path / "stance_ankle_hip.analysis.nc")


KNEE = "configs/examples/knee.yaml"


def _knee(*overrides):
    from rbstab.config.loader import load_config

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_config(KNEE, list(overrides))


def test_the_knees_slow_run_does_not_lower_c():
    """The knee example: the run from the configured start (the shank lifted 1.2 rad, inside
    {v <= c}) is still settling at its t_end of 5 s (v above 0.1 % of its start, never
    above c); run longer it converges, so c stays the domain boundary's level."""
    from rbstab.simulator import simulate

    config = _knee()
    cert = analyze(config, samples=200, falsification_runs=0).certificate
    assert cert.sublevel == cert.boundary_level and cert.sublevel_bound == "domain boundary"
    v = simulate(config).outputs["lyapunov"]
    assert v[-1] > 1e-3 * v[0] and v.max() <= cert.sublevel  # the premise: slow, never above c
    assert cert.runs_checked == 1 and "had not converged by t_end = 5 s" in cert.notes[0]


def test_a_knee_run_that_leaves_its_admissible_region_lowers_c():
    """The knee with |omega_i| <= 3 rad/s as its admissible region: the shank's swing from
    inside {v <= c} leaves it; c is lowered below the start and the note says why."""
    config = _knee("simulation.limits.omega=[3,3,3]")
    result = analyze(config, samples=200, falsification_runs=0)
    cert = result.certificate
    assert cert.sublevel < result.initial_lyapunov < cert.boundary_level
    assert cert.sublevel_bound.startswith("a simulated run from inside")
    assert "failed: left the admissible region" in cert.notes[0]
