"""Stability analysis (rbstab.analysis) against closed forms, an independent model and simulation.

- the free body at the origin without gravity: eigenvalues are the roots of
  m s^2 + l_t s + k_t (per axis) and J_i s^2 + l_r,i s + k_r,i (B = I at Theta = 0); the
  Hessians of v and dv/dt are block-diagonal in the gains;
- the pinned inverted pendulum (R vertical, K_t = L_t = 0): J_p,i s^2 + l_r,i s +
  (k_r,i - m g L) = 0 on the tilt axes, unstable when k_r < m g L, confirmed by simulation;
- the Jacobian against the complex step of the independent numpy model (tests/reference.py)
  and against plain central differences;
- the paper's cases asymptotically stable with their certificates holding.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import PAPER_CONFIGS, ROOT, paper_body, paper_gains
from paper_model import VariantModel, linearise
from reference import Model
from scipy.optimize import linear_sum_assignment

from rbstab.variants.paper import paper_form
from rbstab.analysis import BasinAxis, analyze, basin_map, certify
from rbstab.analysis.basin import time_to_converge
from rbstab.analysis.derivatives import directional_derivative, hessian, jacobian, richardson
from rbstab.analysis.linearise import linearise_config, modes, verdict
from rbstab.analysis.runs import check_entries
from rbstab.config import load_config
from rbstab.kinematics import GIMBAL_LOCK_ANGLE
from rbstab.model import Gains
from rbstab.simulator import simulate
from rbstab.variants import VARIANTS

D = np.diag


def _match(found: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """|found - expected| after pairing each eigenvalue with its nearest (an assignment)."""
    rows, cols = linear_sum_assignment(np.abs(found[:, None] - expected[None, :]))
    return np.abs(found[rows] - expected[cols])


def _quadratic_roots(a, b, c) -> np.ndarray:
    return np.roots([a, b, c]).astype(complex)


def _inverted_pendulum(k_r=100.0, overrides=()):
    """Case 1 with the pivot straight below the COM, no translational feedback."""
    return load_config(ROOT / "configs/paper/case1_permanent.yaml", [
        "body.attachment_point=[0, 0, -0.42]", "controller.k_t=[0, 0, 0]", "controller.l_t=[0, 0, 0]",
        f"controller.k_r=[{k_r}, {k_r}, {k_r}]", *overrides])


# -- derivatives -------------------------------------------------------------------------------------


def test_richardson_extrapolates_a_smooth_derivative_to_round_off():
    x = np.array([0.3, -1.2])

    def f(y):
        return np.stack([np.sin(y[:, 0]) * np.exp(y[:, 1]), y[:, 0] ** 3 * y[:, 1]], axis=1)

    jac, error = jacobian(f, x)
    exact = np.array([[np.cos(0.3) * np.exp(-1.2), np.sin(0.3) * np.exp(-1.2)], [3 * 0.09 * -1.2, 0.027]])
    np.testing.assert_allclose(jac, exact, rtol=1e-11, atol=1e-14)
    assert np.all(error < 1e-9)
    hess, _ = hessian(lambda y: np.sin(y[:, 0]) * np.exp(y[:, 1]), x)
    s, c, e = np.sin(0.3), np.cos(0.3), np.exp(-1.2)
    np.testing.assert_allclose(hess, [[-s * e, c * e], [c * e, s * e]], rtol=1e-10)
    rate, _ = directional_derivative(lambda y: (y ** 2).sum(axis=1), np.array([[1.0, 2.0]]), np.array([[3.0, -1.0]]), 1.0)
    np.testing.assert_allclose(rate, [2 * (3.0 - 2.0)], rtol=1e-13)
    # a table that does not converge keeps its largest error estimate
    value, err = richardson(np.array([[1.0], [5.0], [-3.0]]))
    assert err[0] > 1.0


# -- linearisation ----------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_free_body_eigenvalues_are_the_per_axis_closed_forms(seed):
    rng = np.random.default_rng(seed)
    body = paper_body()
    if seed:
        body = type(body)(float(rng.uniform(5, 80)), D(rng.uniform(0.3, 12, 3)), body.attachment_point,
                          np.zeros(3))
    k_t, l_t, k_r, l_r = (rng.uniform(50, 5000, 3) if seed else np.diag(g) for g in
                          (paper_gains().k_t, paper_gains().l_t, paper_gains().k_r, paper_gains().l_r))
    gains = Gains(k_t=D(k_t), l_t=D(l_t), k_r=D(k_r), l_r=D(l_r))
    lin = linearise(VARIANTS["free"](body, gains))
    j = np.diag(body.inertia)
    expected = np.concatenate(
        [_quadratic_roots(body.mass, l_t[i], k_t[i]) for i in range(3)]
        + [_quadratic_roots(j[i], l_r[i], k_r[i]) for i in range(3)])
    assert np.all(lin.equilibrium == 0) and lin.is_rest_point
    assert np.all(_match(lin.eigenvalues, expected) <= 1e-10 * np.abs(expected))
    assert lin.verdict == "asymptotically stable"
    real = lin.eigenvalues.real
    assert np.all(np.diff(real) <= 0), "sorted by real part, descending"


def test_inverted_pendulum_closed_form_unstable_and_confirmed_by_simulation():
    config = _inverted_pendulum(k_r=100.0)  # k_r < m g L = 41 * 10 * 0.42 = 172.2 N m/rad: it falls
    lin = linearise(paper_form(config))
    j_p = np.diag(paper_form(config).body.pivot_inertia)
    m_g_l = 41.0 * 10.0 * 0.42
    expected = np.concatenate([_quadratic_roots(j_p[i], 60.0 if i < 2 else 42.0, 100.0 - (m_g_l if i < 2 else 0.0))
                               for i in range(3)])
    assert np.all(lin.equilibrium == 0) and lin.is_rest_point
    assert np.all(_match(lin.eigenvalues, expected) <= 1e-9 * np.abs(expected).max())
    assert lin.verdict == "unstable"
    # the growing root's e-folding time; no time constant anywhere for it, none negative
    growing = expected[np.argmax(expected.real)].real
    assert lin.shortest_e_folding_time == pytest.approx(1.0 / growing, rel=1e-9)
    assert np.isnan(lin.slowest_time_constant) and np.isnan(lin.time_constant[0])
    assert np.all(np.isnan(lin.time_constant) == (lin.eigenvalues.real > 0)) and np.nanmin(lin.time_constant) > 0
    assert np.all(np.isnan(lin.e_folding_time) == (lin.eigenvalues.real < 0))
    # a small tilt about y' (the axis of the least pivot inertia: the fastest-growing mode) grows by e every
    # e-folding time (~1 s) while it is small: the body leaves the neighbourhood
    tilted = _inverted_pendulum(100.0, ["simulation.t_end=8"]).with_initial_state({"theta": [0.0, 0.01, 0.0]})
    result = simulate(tilted)
    theta = result.outputs["theta"]
    grown = np.interp([1.0, 1.0 + lin.shortest_e_folding_time], result.time, theta[:, 1])
    assert grown[1] / grown[0] == pytest.approx(np.e, rel=0.01)  # |theta_2| < 0.06 rad: sin nearly linear
    assert np.nanmax(np.abs(theta)) > 0.5 or not result.ok
    # the same pendulum held up by k_r > m g L is stable, with the same closed form
    stiff = linearise(paper_form(_inverted_pendulum(k_r=400.0)))
    expected = np.concatenate([_quadratic_roots(j_p[i], 60.0 if i < 2 else 42.0, 400.0 - (m_g_l if i < 2 else 0.0))
                               for i in range(3)])
    assert np.all(_match(stiff.eigenvalues, expected) <= 1e-9 * np.abs(expected).max())
    assert stiff.verdict == "asymptotically stable"


def _complex_step_jacobian(rhs, y, h=1e-30):
    columns = []
    for j in range(len(y)):
        yc = y.astype(complex)
        yc[j] += 1j * h
        columns.append(rhs(0.0, yc).imag / h)
    return np.array(columns).T


@pytest.mark.parametrize("name, gravity, phi", [
    ("free", (0, 0, -10), 0.0), ("permanent", (0, 0, -10), 0.0), ("sliding", (0, 0, 0), 5e-3),
    ("sliding", (0, 0, -10), 1e-4), ("visco_elastic", (0, 0, -10), 0.0), ("embedded", (0, 0, 0), 0.0),
])
def test_jacobian_matches_the_complex_step_of_the_reference_model_and_finite_differences(name, gravity, phi, rng):
    body, gains = paper_body(gravity), paper_gains(boundary_layer=phi)
    variant = VARIANTS[name](body, gains)
    reference = Model(name, body, gains).rhs
    y_e = variant.equilibrium
    near = y_e + 0.05 * rng.standard_normal(y_e.shape)  # the method applies anywhere, not only at rest
    for y in (y_e, near):
        jac, error = jacobian(lambda z: variant.rhs(0.0, z), y)
        exact = _complex_step_jacobian(reference, y)
        scale = np.abs(exact).max()
        assert np.abs(jac - exact).max() <= 1e-9 * scale
        assert np.abs(jac - exact).max() <= 100 * error.max() + 1e-12 * scale  # the estimate is honest
        h = 1e-7 * (1 + np.abs(y))
        plain = np.array([(variant.rhs(0, y + h[j] * np.eye(len(y))[j]) - variant.rhs(0, y - h[j] * np.eye(len(y))[j]))
                          / (2 * h[j]) for j in range(len(y))]).T
        assert np.abs(jac - plain).max() <= 1e-5 * scale
    lin = linearise(variant)
    assert lin.is_rest_point and lin.verdict == "asymptotically stable"


def test_modes_and_verdict():
    s = np.array([-3 + 4j, -3 - 4j, -2.0, 0.0, 1e-9, 0.5 + 2j])
    omega_n, zeta, tau, e_fold = modes(s, 1e-6)
    np.testing.assert_allclose(omega_n[:3], [5, 5, 2])
    np.testing.assert_allclose(zeta[:3], [0.6, 0.6, 1.0])
    np.testing.assert_allclose(tau[:3], [1 / 3, 1 / 3, 0.5])
    assert np.all(np.isnan(tau[3:])) and np.isnan(zeta[3])  # zero, within the tolerance, growing: no time constant
    assert np.all(np.isnan(e_fold[:5])) and e_fold[5] == pytest.approx(2.0)  # only a growing mode e-folds
    assert modes(s, 1e-12)[3][4] == pytest.approx(1e9)  # beyond a finer tolerance 1e-9 1/s grows
    assert verdict(s[:5], 1e-6) == "marginal"
    assert verdict(s[:5], 1e-12) == "unstable"
    assert verdict(s[:3], 1e-6) == "asymptotically stable"


def test_semidefinite_stiffness_is_marginal():
    body, gains = paper_body(), paper_gains(k_r=D([400.0, 0.0, 320.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lin = linearise(VARIANTS["free"](body, gains))
    assert lin.verdict == "marginal"
    assert np.min(np.abs(lin.eigenvalues)) <= lin.tolerance
    # no time scale: neither a time constant nor an e-folding time, and no mode within the tolerance has one
    assert np.isnan(lin.slowest_time_constant) and np.isnan(lin.shortest_e_folding_time)
    zero = np.abs(lin.eigenvalues.real) <= lin.tolerance
    assert zero.any() and np.all(np.isnan(lin.time_constant[zero])) and np.all(np.isnan(lin.e_folding_time))
    assert np.all(np.isfinite(lin.time_constant[~zero]))


# -- certificate -----------------------------------------------------------------------------------------


def test_free_body_certificate_closed_forms():
    body, gains = paper_body(), paper_gains()
    variant = VARIANTS["free"](body, gains)
    lin = linearise(variant)
    cert = certify(VariantModel(variant), lin, gimbal_margin=1e-3, n_samples=2000)
    # v = Theta'K_r Theta/2 + Omega'J Omega/2 + X'K_t X/2 + m V'V/2 (eq 25)
    expected = np.zeros((12, 12))
    for k, block in enumerate((gains.k_r, body.inertia, gains.k_t, body.mass * np.eye(3))):
        expected[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = block
    np.testing.assert_allclose(cert.lyapunov_hessian, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    rate = np.zeros((12, 12))
    rate[3:6, 3:6] = -2 * gains.l_r
    rate[9:12, 9:12] = -2 * gains.l_t
    np.testing.assert_allclose(cert.rate_hessian, rate, rtol=1e-9, atol=1e-9 * np.abs(rate).max())
    assert cert.positive_definite and cert.rate_definiteness == "negative semi-definite"
    assert cert.lasalle_observable and cert.holds and cert.argument == "LaSalle"
    # at rest on theta_2 = +-(pi/2 - margin) the least v is k_r,2 theta_2^2 / 2
    limit = GIMBAL_LOCK_ANGLE - 1e-3
    assert cert.boundary_level == pytest.approx(0.5 * 400.0 * limit ** 2, rel=1e-9)
    assert cert.sublevel == pytest.approx(cert.boundary_level)
    assert cert.rate_mismatch < 1e-6
    assert np.all(cert.sample_rate[~cert.sample_outside] <= 1e-6 * (np.abs(cert.sample_rate_analytic) + 1))


def test_certificate_fails_with_negative_damping():
    """dv/dt > 0 near the equilibrium (L_r < 0, bypassing validation): the check must see it."""
    body, gains = paper_body(), paper_gains(l_r=D([-60.0, 60.0, 42.0]))
    variant = VARIANTS["free"](body, gains)
    lin = linearise(variant)
    assert lin.verdict == "unstable"
    cert = certify(VariantModel(variant), lin, gimbal_margin=1e-3, n_samples=2000)
    assert cert.rate_definiteness == "indefinite" and not cert.holds
    assert cert.sublevel_bound in ("dv/dt > 0 at a sampled state", "dv/dt > 0 at a state found by the local search")
    assert cert.sublevel <= cert.sublevel_sampled < 1e-3 * cert.boundary_level
    assert cert.worst_rate > 0


def test_inverted_pendulum_v_is_not_positive_definite():
    variant = paper_form(_inverted_pendulum(k_r=100.0))
    cert = certify(VariantModel(variant), linearise(variant), gimbal_margin=1e-3, n_samples=100)
    assert not cert.positive_definite and cert.hessian_min_eigenvalue < 0
    assert not cert.holds and cert.sublevel == 0.0


def test_boundary_level_with_gravity_matches_a_direct_minimisation():
    from scipy.optimize import minimize

    config = load_config(ROOT / "configs/paper/case1_permanent.yaml")
    variant = paper_form(config)
    lin = linearise(variant)
    h_v, _ = hessian(variant.lyapunov, lin.equilibrium)
    limit = GIMBAL_LOCK_ANGLE - 1e-3
    found = VariantModel(variant).boundary_level(lin.equilibrium, h_v, limit)
    direct = min(
        minimize(lambda q, s=side: variant.lyapunov(np.array([q[0], s, q[1], 0, 0, 0]))[()], [0.0, 0.0],
                 method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12}).fun
        for side in (limit, -limit))
    assert found == pytest.approx(direct, rel=1e-8)


@pytest.mark.parametrize("path", PAPER_CONFIGS, ids=lambda p: p.stem)
def test_paper_cases_are_asymptotically_stable_with_certificates(path):
    result = analyze(path, samples=2000)
    lin, cert = result.linearisation, result.certificate
    assert result.verdict == "asymptotically stable" and lin.is_rest_point
    assert cert.holds and cert.argument == "LaSalle"
    assert abs(cert.lyapunov_equilibrium) < 1e-9
    assert cert.rate_mismatch < 1e-6 and cert.sublevel > 0
    assert cert.sublevel <= cert.boundary_level
    # the simulation from the paper's initial state converges, on the time scale of the slowest mode
    ttc = result.settling["time_to_converge"]
    assert np.isfinite(ttc) and 0.3 * result.linear_settling_time < ttc < 3 * result.linear_settling_time
    record = result.to_json()
    assert [record[k] for k in ("name", "variant", "verdict")] == [result.name, result.variant, result.verdict]
    assert np.all(np.diff([re for re, _ in record["eigenvalues"]]) <= 0)


def test_sign_law_is_analysed_with_a_boundary_layer():
    config = load_config(ROOT / "configs/examples/sliding.yaml", ["controller.boundary_layer=0"])
    with pytest.raises(ValueError, match="no linearisation"):
        linearise_config(config)
    result = analyze(config, boundary_layer=2e-3, certificate=False, simulate=False)
    assert paper_form(result.analysed).gains.boundary_layer == 2e-3 and paper_form(result.config).gains.boundary_layer == 0
    assert "does not exist" in result.notes[0]
    assert result.to_json()["analysed_boundary_layer"] == 2e-3
    # the linearised sliding force is a spring K_s / phi at C: stiffer phi, faster modes
    faster = analyze(config, boundary_layer=1e-3, certificate=False, simulate=False)
    assert np.abs(faster.linearisation.eigenvalues).max() > np.abs(result.linearisation.eigenvalues).max()
    with pytest.raises(ValueError, match="boundary-layer"):
        analyze(ROOT / "configs/paper/case3_embedded.yaml", boundary_layer=1e-3)


# -- basin ---------------------------------------------------------------------------------------------


def test_time_to_converge():
    t = np.linspace(0, 1, 11)
    v = np.array([1, 0.5, 1e-4, 2e-3, 1e-4, 1e-5, 0, 0, 0, 0, 0], float)
    assert time_to_converge(t, v, 1e-3) == pytest.approx(0.4)
    assert np.isnan(time_to_converge(t, np.full(11, 1.0), 1e-3))
    assert np.isnan(time_to_converge(t, np.r_[v[:-1], np.nan], 1e-3))


def test_basin_axis_parsing():
    axis = BasinAxis.parse("initial_state.omega.0=-60:60:41")
    assert axis.block == "omega" and axis.index == 0 and len(axis.values) == 41 and axis.units == "rad s-1"
    for bad, match in [("initial_state.omega.0=-60:60", "KEY=lo:hi:n"), ("controller.k_t.0=1:2:3", "not one entry of an initial state"),
                       ("initial_state.omega.3=1:2:3", "'initial_state.omega' is a list of 3; index it with 0..2, not '3'"),
                       ("initial_state.omega=1:2:3", "not one entry of an initial state"), ("initial_state.omega.1=2:1:3", "lo < hi"),
                       ("initial_state.omega.1=1:2:1", "n >= 2"), ("initial_state.omega.1=a:2:3", "numbers")]:
        with pytest.raises(ValueError, match=match):
            BasinAxis.parse(bad)
    # whether the configuration's state has the entry: one body's variant's blocks, no body's name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        permanent = load_config(ROOT / "configs" / "paper" / "case1_permanent.yaml")
    for key, match in [("initial_state.x.0", r"'initial_state.x' is not a state of this variant \(its states: theta, omega\)"),
                       ("initial_state.legs.theta.0", "names a body of a chain")]:
        with pytest.raises(ValueError, match=match):
            check_entries(permanent, [BasinAxis.parse(f"{key}=-1:1:3")])
    check_entries(permanent, [axis])


def test_basin_of_the_inverted_pendulum():
    """Unstable upright pendulum: only the equilibrium itself stays; the estimate is empty."""
    config = _inverted_pendulum(20.0, ["simulation.t_end=4", "initial_state.omega=[0, 0, 0]"])  # grows at 1.7 1/s
    axes = [BasinAxis.parse("initial_state.theta.0=-0.1:0.1:3"), BasinAxis.parse("initial_state.theta.2=-0.1:0.1:3")]
    basin = basin_map(config, axes, n_samples=31)
    assert basin.outcome.shape == (3, 3)
    assert basin.outcome[1, 1] == 0  # the equilibrium
    assert np.all(basin.outcome[[0, 2], :] != 0)  # tilted about x: it falls
    assert basin.lyapunov_initial[1, 1] == pytest.approx(0.0, abs=1e-12)


def test_basin_map_inside_the_sublevel_estimate():
    config = load_config(ROOT / "configs/paper/case3_embedded.yaml")
    result = analyze(config, samples=1000, basin=["initial_state.omega.0=-20:20:5", "initial_state.omega.1=-20:20:5"],
                     basin_samples=101, jobs=1)
    basin = result.basin
    assert basin.outcome.shape == (5, 5) and np.all(basin.outcome == 0)
    assert np.all((basin.time_to_converge > 0) & (basin.time_to_converge <= 2.0))
    inside = result.basin_inside()
    assert inside["converged"] > 0 and inside["converged"] == sum(inside.values())
    # v at the grid's initial states: 0.5 Omega'J Omega with omega_3 = -16 (eq 25)
    w0, w1 = np.meshgrid(basin.axes[0].values, basin.axes[1].values, indexing="ij")
    np.testing.assert_allclose(basin.lyapunov_initial, 0.5 * (10 * w0 ** 2 + 8 * w1 ** 2 + 0.4 * 256), rtol=1e-12)
