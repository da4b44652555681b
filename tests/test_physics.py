"""Physics checked by physics: conservation, Lyapunov rates, independent formulations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import initial_blocks, paper_body, paper_gains, settings
from paper_model import evaluate_outputs, solve
from reference import Model, permanent_full_state_rhs
from rbstab.kinematics import rotation_matrix
from rbstab.layout import FULL_BODY
from rbstab.summary import numerical_rate
from rbstab.variants import VARIANTS, Permanent

ALL = sorted(VARIANTS)
GRAVITY = [(0.0, 0.0, 0.0), (0.0, 0.0, -10.0)]


def _variant(name, gravity=(0.0, 0.0, 0.0), **gains):
    return VARIANTS[name](paper_body(gravity), paper_gains(**gains))


def _random_states(variant, rng, n=40):
    y = rng.normal(scale=0.2, size=(n, variant.layout.size))
    y[:, 3:6] = rng.normal(scale=5.0, size=(n, 3))  # omega
    return y


def test_torque_free_body_conserves_energy_and_angular_momentum():
    """All gains zero, no gravity: kinetic energy and inertial angular momentum are constant."""
    zero = np.zeros((3, 3))
    variant = VARIANTS["free"](paper_body(), paper_gains(k_t=zero, l_t=zero, k_r=zero, l_r=zero))
    y0 = variant.initial_state(initial_blocks(omega=(1.0, 3.0, -2.0)) | {"velocity": np.array([0.3, -0.1, 0.2])})
    sol = solve_ivp(variant.rhs, (0, 5.0), y0, method="DOP853", rtol=1e-11, atol=1e-12, dense_output=True)
    y = sol.sol(np.linspace(0, 5.0, 501)).T
    q = FULL_BODY.split(y)
    body = variant.body
    energy = 0.5 * np.einsum("ni,ij,nj->n", q["omega"], body.inertia, q["omega"]) + 0.5 * body.mass * np.sum(
        q["velocity"] ** 2, axis=1
    )
    momentum = np.einsum("nij,nj->ni", rotation_matrix(q["theta"]), q["omega"] @ body.inertia.T)
    np.testing.assert_allclose(energy, energy[0], rtol=1e-9)
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), atol=1e-9 * np.abs(momentum[0]).max())
    # the body really tumbles: a test that a frozen body would pass is worthless
    assert np.ptp(q["omega"], axis=0).max() > 1.0


@pytest.mark.parametrize("gravity", GRAVITY)
@pytest.mark.parametrize("name", ALL)
def test_analytic_lyapunov_rate_is_the_derivative_of_v_along_the_flow(name, gravity, rng):
    """Pointwise, at random states: dv/dt == (v(y + h f) - v(y - h f)) / 2h."""
    variant = _variant(name, gravity)
    y = _random_states(variant, rng)
    f = variant.rhs(0.0, y)
    h = 1e-7
    numerical = (variant.lyapunov(y + h * f) - variant.lyapunov(y - h * f)) / (2 * h)
    analytic = variant.evaluate(y)["lyapunov_rate"]
    np.testing.assert_allclose(analytic, numerical, rtol=1e-5, atol=1e-5 * np.abs(analytic).max())
    assert np.all(analytic <= 0.0)


@pytest.mark.parametrize("name", ALL)
def test_rhs_of_one_state_matches_the_stacked_rhs(name, rng):
    variant = _variant(name, (0.0, 0.0, -10.0))
    y = _random_states(variant, rng, n=5)
    stacked = variant.rhs(0.0, y)
    for yi, fi in zip(y, stacked):
        np.testing.assert_allclose(variant.rhs(0.0, yi), fi, rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("name", ALL)
def test_v_along_a_trajectory_never_increases_and_matches_its_rate(name):
    variant = _variant(name)
    y0 = variant.initial_state(initial_blocks())
    time, states, status, message, _ = solve(variant, y0, settings(t_end=1.0, n_samples=1001))
    assert status == "success", message
    out = evaluate_outputs(variant, time, states)
    v, rate = out["lyapunov"], out["lyapunov_rate"]
    assert v[-1] < 0.05 * v[0]  # it converges, so the check below is not vacuous
    assert np.max(np.diff(v)) <= 1e-9 * v[0]
    assert np.max(rate) <= 0.0
    mismatch = np.abs(out["lyapunov_rate_numerical"] - rate).max()
    assert mismatch <= 2e-3 * np.abs(rate).max()


@pytest.mark.parametrize("name", ALL)
def test_equilibrium_under_gravity_is_a_rest_point_with_zero_v(name):
    variant = _variant(name, (0.0, 0.0, -10.0))
    y_eq = variant.equilibrium
    assert np.abs(variant.rhs(0.0, y_eq)).max() < 1e-6
    assert abs(float(variant.lyapunov(y_eq))) < 1e-8
    assert np.abs(y_eq).max() > 1e-4  # gravity does move it
    # a nearby rest state has larger v: it is a minimum
    rng = np.random.default_rng(1)
    for _ in range(10):
        y = y_eq + rng.normal(scale=1e-3, size=y_eq.shape)
        y[3:6] = 0.0
        if variant.layout.size > 6:
            y[9:12] = 0.0
        assert variant.lyapunov(y) > 0.0


@pytest.mark.parametrize("name", ALL)
def test_all_records_equilibria_at_once_are_each_records_descent(name, rng, monkeypatch):
    """h of 60 records (masses, gains and attachment points varied, some torques clipped)
    found all at once (rbstab.variants.registry.record_offsets: Newton's method on every
    record together from 0, a record by itself where that finds no minimum) is the h of the
    minimum of each record's stored energy downhill from 0 (BFGS and a root polish) to 1e-12
    of its scale, and a record alone gets the bits it gets in the batch."""
    from rbstab.variants import base
    from rbstab.variants.registry import VARIANTS, record_offset, record_offsets

    variant = _variant(name, (0.0, 0.0, -10.0))
    records = np.repeat(variant.parameters, 60)
    records["mass"] *= rng.uniform(0.5, 1.5, 60)
    records["weight"] = records["mass"][:, None] * np.array([0.0, 0.0, -10.0])
    records["k_r"] *= rng.uniform(0.3, 2.0, 60)[:, None, None]
    records["attachment_point"] += rng.normal(scale=0.1, size=(60, 3))
    clipped = rng.random(60) < 0.3
    records["saturation"][clipped], records["torque_limit"][clipped] = 1.0, 5.0
    records["torque_floor"][clipped] = -5.0
    gravity = np.repeat([[0.0, 0.0, -10.0]], 60, axis=0)
    ours = record_offsets(records, gravity, name)
    _, alone, found = base.rest_equilibria(VARIANTS[name], records[7:8])
    assert not found[0] or alone[0] == ours[7]
    with monkeypatch.context() as m:  # every record by the descent
        m.setattr(base, "rest_equilibria", lambda cls, r: (None, np.full(len(r), np.nan), np.zeros(len(r), bool)))
        theirs = np.array([record_offset(r, g, name) for r, g in zip(records, gravity)])
    assert np.ptp(theirs) > 0.1 * np.abs(theirs).max()  # the records differ
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12 * np.abs(theirs).max())


@pytest.mark.parametrize("name", ALL)
def test_newton_finds_the_equilibria_of_light_bodies_where_round_off_bounds_the_residual(name, rng, monkeypatch):
    """Bodies of 1-2 kg on the paper's stiff gains under gravity: the rest accelerations'
    residual stops at round-off above the absolute 1e-13 (measured 1.4e-13 - 4.5e-12), and
    Newton's method on all records at once still finds every minimum (its step below 1e-12
    of the configuration), the descent's h to 1e-12 of its scale."""
    from rbstab.variants import base
    from rbstab.variants.registry import VARIANTS, record_offset

    variant = _variant(name, (0.0, 0.0, -9.5))
    records = np.repeat(variant.parameters, 30)
    records["mass"] = rng.uniform(1.0, 2.0, 30)
    records["weight"] = records["mass"][:, None] * np.array([0.0, 0.0, -9.5])
    _, ours, found = base.rest_equilibria(VARIANTS[name], records)
    assert found.all()
    with monkeypatch.context() as m:  # every record by the descent
        m.setattr(base, "rest_equilibria", lambda cls, r: (None, np.full(len(r), np.nan), np.zeros(len(r), bool)))
        theirs = np.array([record_offset(r, [0.0, 0.0, -9.5], name) for r in records])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12 * np.abs(theirs).max())


def test_free_equilibrium_is_K_t_inverse_G():
    variant = _variant("free", (0.0, 0.0, -10.0))
    body, gains = variant.body, variant.gains
    x_e = np.linalg.solve(gains.k_t, body.weight)
    np.testing.assert_allclose(variant.equilibrium[6:9], x_e, atol=1e-7)
    np.testing.assert_allclose(variant.lyapunov_offset, 0.5 * body.weight @ x_e, rtol=1e-9)


@pytest.mark.parametrize("gravity", GRAVITY)
def test_permanent_reduced_and_full_state_formulations_agree(gravity):
    """The 6-state reduced system (eq 21, compiled) and the 12-state body with Lambda of
    eq 15 (plain numpy, tests/reference.py)."""
    reduced = Permanent(paper_body(gravity), paper_gains(l_t=np.diag([210.0, 210, 140])))
    full_rhs, full_force = permanent_full_state_rhs(reduced.body, reduced.gains)
    y0 = reduced.initial_state(initial_blocks())
    t = np.linspace(0, 1.0, 201)
    kw = dict(method="DOP853", rtol=1e-11, atol=1e-12, t_eval=t)
    sol_r = solve_ivp(reduced.rhs, (0, 1.0), y0, **kw)
    sol_f = solve_ivp(full_rhs, (0, 1.0), reduced.full_state(y0), **kw)
    np.testing.assert_allclose(sol_f.y.T, reduced.full_state(sol_r.y.T), atol=1e-7)
    # in the 12-state formulation nothing pins C by construction: it stays put by physics
    y_f = sol_f.y.T
    r = reduced.body.attachment_point
    point_c = y_f[:, 6:9] + np.einsum("nij,j->ni", rotation_matrix(y_f[:, 0:3]), r) - r
    assert np.abs(point_c).max() < 1e-8
    # and the two constraint forces agree
    lam_r = reduced.evaluate(sol_r.y.T)["constraint_force"]
    lam_f = np.array([full_force(y) for y in y_f])
    np.testing.assert_allclose(lam_f, lam_r, atol=1e-6 * np.abs(lam_r).max())


def test_permanent_reconstruction_is_kinematically_consistent():
    """Reconstructed X, V: V is dX/dt along the trajectory, and C = X + A R stays at R."""
    variant = Permanent(paper_body((0, 0, -10.0)), paper_gains(l_t=np.diag([210.0, 210, 140])))
    time, states, status, _, _ = solve(variant, variant.initial_state(initial_blocks()), settings(t_end=0.5, n_samples=501))
    assert status == "success"
    q = variant.evaluate(states)
    x_dot = np.stack([numerical_rate(time, q["position"][:, k]) for k in range(3)], axis=1)
    np.testing.assert_allclose(x_dot, q["velocity"], atol=1e-5 * np.abs(q["velocity"]).max())
    point_c = q["position"] + np.einsum("nij,j->ni", rotation_matrix(q["theta"]), variant.body.attachment_point)
    np.testing.assert_allclose(point_c, np.broadcast_to(variant.body.attachment_point, point_c.shape), atol=1e-14)


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_gimbal_lock_stops_the_run_with_a_reason(method):
    """A free body tumbling toward theta_2 = pi/2, on scipy's engine (solve_ivp over the
    one-body tree) and the compiled one: the run fails there with the reason, its later rows
    NaN, its angles short of the lock."""
    from rbstab.config import load_config
    from rbstab.simulator import simulate

    config = load_config("configs/paper/case2_visco_elastic.yaml", [
        "controller.variant=free", "initial_state.theta=[0, 1.5, 0]", "initial_state.omega=[0, 20, 0]",
        "simulation.t_end=1.0", "simulation.n_samples=101", f"simulation.method={method}"])
    for engine in ("scipy", "compiled") if method == "DOP853" else ("scipy",):
        result = simulate(config, engine=engine)
        assert result.status == "failed" and "gimbal lock" in result.message, (engine, result.message)
        theta = result.outputs["theta"]
        assert np.isnan(theta[-1]).all()
        assert np.abs(theta[np.isfinite(theta[:, 1]), 1]).max() < np.pi / 2


@pytest.mark.parametrize("gravity", GRAVITY)
@pytest.mark.parametrize("name", ALL + ["sliding_sign_law"])
def test_compiled_rhs_is_the_plain_numpy_model(name, gravity, rng):
    """The compiled right-hand side of every variant against an independent plain-numpy
    transcription of the paper's equations (tests/reference.py), at random states."""
    phi = 0.0 if name == "sliding_sign_law" else 0.005
    name = name.replace("_sign_law", "")
    variant = _variant(name, gravity, boundary_layer=phi)
    reference = Model(name, variant.body, variant.gains)
    y = _random_states(variant, rng, n=20)
    compiled = variant.rhs(0.0, y)
    for yi, fi in zip(y, compiled):
        expected = reference.rhs(0.0, yi)
        np.testing.assert_allclose(fi, expected, rtol=1e-12, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("batch", [(1,), (3,), (2, 3)])
@pytest.mark.parametrize("name", ALL)
def test_stacks_of_any_shape_match_row_by_row(name, batch, rng):
    """rhs and every output of a stack equal those of its rows, bit for bit."""
    variant = _variant(name, (0.0, 0.0, -10.0))
    y = _random_states(variant, rng, n=int(np.prod(batch))).reshape(batch + (variant.layout.size,))
    stacked_rate = variant.rhs(0.0, y)
    stacked = variant.evaluate(y)
    assert stacked_rate.shape == y.shape
    for index in np.ndindex(*batch):
        np.testing.assert_array_equal(variant.rhs(0.0, y[index]), stacked_rate[index])
        single = variant.evaluate(y[index])
        assert single.keys() == stacked.keys()
        for key, value in single.items():
            assert stacked[key][index].shape == value.shape, key
            np.testing.assert_array_equal(stacked[key][index], value, err_msg=key)
