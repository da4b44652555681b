"""The pure sign law of ``sliding`` (eq 39, boundary_layer 0): located switchings, Filippov
sliding, and what a run reports.

Checked by physics: a mass under -K_s sgn(x) - c v against its closed form (switching times
from Lambert's W), the equivalent force against the acceleration it must cancel, the
permanent constraint as the limit of a large K_s, v non-increasing, a fine fixed-step
integration of the plain sign law (no events) converging to the event-driven trajectory,
and the boundary-layer law converging to the sign law as phi -> 0.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from scipy.special import lambertw

from conftest import ROOT, initial_blocks, paper_body, paper_gains
from reference import Model, hat, rotation
from rbstab.variants.paper import paper_form, paper_initial_state
from rbstab.config import apply_overrides, config_from_mapping, parse_yaml
from rbstab.engine.switching import CROSSING, SLIDING_ENDS, SLIDING_STARTS, integrate_sign_law
from rbstab.io.hdf5 import read_summary
from rbstab.jit import jit
from rbstab.model import Gains, RigidBody
from rbstab.report.tables import validate_metrics
from rbstab.simulator import simulate, simulate_many
from rbstab.variants import Permanent, Sliding
from rbstab.variants.kernels import SLIDING, state_rate
from rbstab.variants.sliding import MODE_CODES, mode_code, mode_of, mode_rate, mode_rows, stop_at_c
from rbstab_cli.main import cli

SLIDING_EXAMPLE = ROOT / "configs" / "examples" / "sliding.yaml"
SIGN_LAW = ["controller.boundary_layer=0"]

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def example(*overrides):
    return config_from_mapping(apply_overrides(parse_yaml(SLIDING_EXAMPLE.read_text()), [*SIGN_LAW, *overrides]))


def run_settings(**kw):
    import types

    base = dict(t_end=2.0, n_samples=2001, method="DOP853", rtol=1e-8, atol=1e-10, max_step=np.inf, gimbal_margin=1e-3,
                max_steps=1_000_000, max_wall_time=np.inf)
    return types.SimpleNamespace(**{**base, **kw})


def quantities(variant, y, modes):
    """E, F, Lambda, dF/dt of states y (k, 12) in modes (k, 3): shape (k, 4, 3)."""
    y = np.atleast_2d(y)
    out = np.empty((len(y), 12))
    modes = np.ascontiguousarray(np.broadcast_to(modes, (len(y), 3)), dtype=float)
    mode_rows(np.ascontiguousarray(y), variant._parameters_without_offset, modes, out)
    return out.reshape(-1, 4, 3)


# -- the mode law ----------------------------------------------------------------------------------
def test_modes_off_the_surfaces_are_the_sign_law(rng):
    """With sigma = sgn(E), the mode's right-hand side is eq 1 under -K_s sgn(E): the compiled
    kernel of the plain law and the plain-numpy reference model."""
    variant = Sliding(paper_body(), paper_gains(boundary_layer=0.0))
    reference = Model("sliding", variant.body, variant.gains)
    for y in rng.normal(scale=0.3, size=(20, 12)):
        sigma = np.sign(quantities(variant, y, np.ones(3))[0, 0])
        dy, plain = np.empty(12), np.empty(12)
        state_rate(mode_code.py_func(tuple(sigma)), 0.0, y, variant.parameters[0], dy)
        np.testing.assert_allclose(dy, reference.rhs(0.0, y), rtol=1e-12, atol=1e-10)
        state_rate(SLIDING, 0.0, y, variant.parameters[0], plain)
        np.testing.assert_array_equal(dy, plain)
    for code in range(MODE_CODES, MODE_CODES + 27):  # the 27 modes, each its own code
        assert mode_code.py_func(mode_of.py_func(code)) == code and set(mode_of.py_func(code)) <= {-1.0, 0.0, 1.0}


def inverse_mass_at_c(body, theta):
    """W = I/m + (hat(R) A')' J^-1 (hat(R) A'), written from the equations with numpy."""
    a_r = hat(body.attachment_point) @ rotation(theta).T
    return np.eye(3) / body.mass + a_r.T @ np.linalg.solve(body.inertia, a_r)


def test_equivalent_force_cancels_the_acceleration_of_c_on_sliding_axes(rng):
    """Sliding axes: dF_i/dt = 0 along the flow (finite differences of F, not the kernel's
    dF/dt), and Lambda = Lambda_free + W^-1 (-a_free) on them with W from numpy."""
    variant = Sliding(paper_body(), paper_gains(boundary_layer=0.0))
    for y in rng.normal(scale=0.3, size=(10, 12)):
        for mode in ([0, 1, -1], [0, 0, 1], [0, 0, 0], [-1, 0, 1]):
            mode = np.array(mode, float)
            e, f, lam, acc = quantities(variant, y, mode)[0]
            dy = variant_rate(variant, y, mode)
            h = 1e-6
            fd = (quantities(variant, y + h * dy, mode)[0, 1] - quantities(variant, y - h * dy, mode)[0, 1]) / (2 * h)
            np.testing.assert_allclose(fd, acc, atol=1e-5 * (1 + np.abs(acc).max()))
            on = mode == 0
            assert np.all(np.abs(acc[on]) < 1e-9 * (1 + np.abs(lam).max()))
            np.testing.assert_array_equal(lam[~on], -variant.gains.k_s * mode[~on])
            # the free acceleration under the side forces alone, cancelled by W Lambda_eq
            w = inverse_mass_at_c(variant.body, y[0:3])
            free_mode = np.where(on, 1.0, mode)
            a_free = quantities(variant, y, free_mode)[0, 3] - w @ (-variant.gains.k_s * np.where(on, 1.0, 0.0))
            np.testing.assert_allclose(w[np.ix_(on, on)] @ lam[on], -a_free[on], rtol=1e-9, atol=1e-9)


def variant_rate(variant, y, mode):
    dy = np.empty(12)
    mode_rate(y, variant._parameters_without_offset[0], tuple(mode), dy)
    return dy


def test_impulse_at_c_stops_c_and_removes_energy(rng):
    """stop_at_c: F_i = 0 on the chosen axes; the impulse P acts along them only, changes
    m V by P and J Omega by R x A'P, and removes F'W^-1 F / 2 of kinetic energy."""
    body = paper_body()
    variant = Sliding(body, paper_gains(boundary_layer=0.0))
    m, J, r = body.mass, body.inertia, body.attachment_point
    for y in rng.normal(scale=0.5, size=(10, 12)):
        for on in ([True, False, True], [False, True, False], [True, True, True]):
            on = np.array(on)
            out = np.empty(12)
            stop_at_c(y, variant._parameters_without_offset[0], tuple(on), out)
            f_before = quantities(variant, y, np.ones(3))[0, 1]
            f_after = quantities(variant, out, np.ones(3))[0, 1]
            np.testing.assert_allclose(f_after[on], 0.0, atol=1e-12)
            impulse = m * (out[9:12] - y[9:12])
            np.testing.assert_allclose(impulse[~on], 0.0, atol=1e-12)
            np.testing.assert_allclose(J @ (out[3:6] - y[3:6]), np.cross(r, rotation(y[0:3]).T @ impulse), atol=1e-12)
            kinetic = lambda s: 0.5 * m * s[9:12] @ s[9:12] + 0.5 * s[3:6] @ J @ s[3:6]  # noqa: E731
            w = inverse_mass_at_c(body, y[0:3])[np.ix_(on, on)]
            expected = 0.5 * f_before[on] @ np.linalg.solve(w, f_before[on])
            assert kinetic(y) - kinetic(out) == pytest.approx(expected, rel=1e-10)


# -- a mass under -K_s sgn(x) - c v: the closed form ----------------------------------------------
def half_waves(c, k_s, m, u, t_end):
    """Crossing times and velocities of m x'' = -c x' - K_s sgn(x) from x = 0, x' = u.

    Each half wave: with a = c/m, b = K_s/m, q = 1 + a|u|/b, the next crossing comes after
    tau = (q + W_0(-q e^-q)) / a (tau = 2|u|/b for c = 0), at the velocity
    (u + s b/a) e^(-a tau) - s b/a, s = sgn(u) (-u for c = 0).
    """
    a, b = c / m, k_s / m
    t, times, rates = 0.0, [], []
    while True:
        if a == 0:
            tau, u_next = 2 * abs(u) / b, -u
        else:
            q = 1 + a * abs(u) / b
            tau = (q + lambertw(-q * np.exp(-q)).real) / a
            s = np.sign(u)
            u_next = (u + s * b / a) * np.exp(-a * tau) - s * b / a
        if t + tau > t_end:
            return np.array(times), np.array(rates)
        t, u = t + tau, u_next
        times.append(t)
        rates.append(u)


def point_mass(c, k_s=10.0, m=2.0):
    """The body with C at its centre of mass (R = 0): E = X, and each axis is the mass m
    under -K_s sgn(x) - c_i v (K_t = 0, L_t = diag(c)); the rotation stays at rest."""
    zero = np.zeros((3, 3))
    body = RigidBody(m, np.eye(3), np.zeros(3), np.zeros(3))
    return Sliding(body, Gains(k_t=zero, l_t=np.diag(c), k_r=zero, l_r=zero, k_s=k_s, boundary_layer=0.0))


def test_point_mass_switching_times_match_the_closed_form():
    """Undamped (periodic switching), damped and strongly damped axes: every switching time
    to 1e-8 s and F at it to 1e-8 m/s; the strongly damped axis accumulates switchings and
    starts sliding (x = v = 0 from then on) at the first crossing whose next excursion,
    v^2 / (2 (b + a|v|)), is below the resolution."""
    c, u0, t_end, resolution = (0.0, 4.0, 20.0), (0.5, -0.8, 2.0), 1.9, 1e-5
    variant = point_mass(c)
    y0 = np.zeros(12)
    y0[9:12] = u0
    sol = integrate_sign_law(variant, y0, run_settings(t_end=t_end, n_samples=1901, rtol=1e-12, atol=1e-14),
                             resolution=resolution)
    assert sol.status == "success", sol.message
    s = sol.switchings
    caught_axes = []
    for i in range(3):
        times, rates = half_waves(c[i], 10.0, 2.0, u0[i], t_end)
        a, b = c[i] / 2.0, 10.0 / 2.0
        amplitude = rates**2 / (2 * (b + a * np.abs(rates)))
        caught = np.flatnonzero(amplitude <= resolution)
        last = caught[0] if caught.size else len(times) - 1
        mine = (s.axis == i) & (s.kind == CROSSING)
        assert mine.sum() == (last if caught.size else last + 1), i
        np.testing.assert_allclose(s.time[mine], times[: mine.sum()], rtol=0, atol=1e-8)
        np.testing.assert_allclose(s.rate[mine], rates[: mine.sum()], rtol=0, atol=1e-8)
        starts = s.time[(s.axis == i) & (s.kind == SLIDING_STARTS)]
        if caught.size:
            caught_axes.append(i)
            assert starts == pytest.approx([times[last]], abs=1e-8)
            after = sol.time > times[last] + 1e-9
            np.testing.assert_allclose(sol.states[after][:, [6 + i, 9 + i]], 0.0, atol=1e-12)
            assert np.all(sol.modes[after, i] == 0)
        else:
            assert starts.size == 0
    assert caught_axes == [2]  # the strongly damped axis accumulates switchings and is caught
    assert not np.any(s.kind == SLIDING_ENDS)
    np.testing.assert_allclose(sol.states[:, 0:6], 0.0, atol=1e-15)  # no torque: the rotation stays at rest


# -- the sliding example -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def example_run():
    return simulate(example())


def test_sign_law_run_locates_switchings_and_v_never_increases(example_run):
    r = example_run
    assert r.status == "success", r.message
    s = r.summary
    assert "switchings located" in r.message and "resolution" in r.message
    counts = np.array(s["switching_count"])
    assert counts.sum() == np.sum(r.switching.kind == CROSSING) > 100
    assert s["max_lyapunov_increase"] <= 1e-9 * s["lyapunov_initial"]
    assert s["max_lyapunov_rate"] <= 0
    assert s["lyapunov_rate_check"] == "pass" and s["lyapunov_rate_checked"] > 0.2
    # every sample on its piece's side, the force -K_s sigma off the surfaces, |Lambda| <= K_s on them
    e, lam, sigma = r.outputs["constraint_error"], r.outputs["constraint_force"], r.outputs["sliding_mode"]
    k_s = paper_form(r.config).gains.k_s
    side = sigma != 0
    assert np.all((np.sign(e[side]) == sigma[side]) | (np.abs(e[side]) < 1e-12))
    np.testing.assert_array_equal(lam[side], -k_s * sigma[side])
    assert np.all(np.abs(lam[~side]) <= k_s) and np.all(np.abs(e[~side]) < 1e-8)
    assert s["sliding_time"][0] > 0 and np.all(np.array(s["min_switching_interval"]) > 0)


def test_sign_law_run_is_the_plain_sign_law_integrated_finely():
    """Before its switchings accumulate (t <= 0.5 s, where a change of 1e-12 in Omega(0) stays
    below 1e-9 m), the event-driven trajectory is the limit of a fixed-step RK4 integration
    of the plain -K_s sgn(E) (no events): a step 8 times shorter (2e-6 -> 2.5e-7 s) brings it
    more than 4 times closer, to 2e-6 m (the fixed steps straddle the switchings, so the
    reference converges irregularly, at first order or a little better)."""
    config = example("simulation.t_end=0.5", "simulation.n_samples=501")
    run = simulate(config)
    variant = paper_form(config)
    y0 = paper_initial_state(config, variant)
    errors = []
    for n_steps in (250_000, 2_000_000):
        reference = fixed_step_sign_law(variant, y0, 0.5, n_steps, 500)
        errors.append(np.abs(reference[:, 6:9] - run.outputs["position"]).max())
    assert errors[1] < errors[0] / 4 and errors[1] < 2e-6, errors


@jit
def _rk4(y0, p, h, n_steps, every, out):
    y, w = y0.copy(), np.empty_like(y0)
    k = np.empty((4, y0.shape[0]))
    out[0] = y
    for s in range(n_steps):
        state_rate(SLIDING, 0.0, y, p, k[0])
        w[:] = y + 0.5 * h * k[0]
        state_rate(SLIDING, 0.0, w, p, k[1])
        w[:] = y + 0.5 * h * k[1]
        state_rate(SLIDING, 0.0, w, p, k[2])
        w[:] = y + h * k[2]
        state_rate(SLIDING, 0.0, w, p, k[3])
        y += h / 6 * (k[0] + 2 * k[1] + 2 * k[2] + k[3])
        if (s + 1) % every == 0:
            out[(s + 1) // every] = y


def fixed_step_sign_law(variant, y0, t_end, n_steps, n_out):
    """The plain sign law (sgn(E) at every stage, ``kernels.state_rate``) by classical RK4
    with n_steps steps of t_end / n_steps; the state at n_out + 1 even times."""
    out = np.empty((n_out + 1, len(y0)))
    _rk4(np.asarray(y0, float), variant.parameters[0], t_end / n_steps, n_steps, n_steps // n_out, out)
    return out


def test_boundary_layer_converges_to_the_sign_law():
    """tanh(E/phi) -> sgn(E): over the first 0.5 s the distance of the boundary-layer
    trajectory to the sign law's shrinks with phi (1e-2, 1e-3, 1e-4 m), about tenfold."""
    sign = simulate(example("simulation.t_end=0.5", "simulation.n_samples=501"))
    distance = []
    for phi in (1e-2, 1e-3, 1e-4):
        smooth = simulate(example("simulation.t_end=0.5", "simulation.n_samples=501",
                                  f"controller.boundary_layer={phi}"))
        distance.append(np.abs(smooth.outputs["position"] - sign.outputs["position"]).max())
    assert distance[0] > 3 * distance[1] > 9 * distance[2], distance
    assert distance[2] < 2e-4


def test_a_large_force_slides_on_every_axis_and_is_the_permanent_constraint():
    """E = F = 0 at t = 0 and K_s far above what holding C takes: C slides on all three
    surfaces for the whole run and the body moves as the permanent variant's (eq 20, Case 1
    with gravity), Lambda included."""
    body = paper_body((0.0, 0.0, -10.0))
    gains = paper_gains(k_s=1e6, boundary_layer=0.0, l_t=np.diag([210.0, 210, 140]))
    pinned = Permanent(body, gains)
    sliding = Sliding(body, gains)
    blocks = initial_blocks()
    theta0, omega0 = blocks["theta"], blocks["omega"]
    a = rotation(theta0)
    r = body.attachment_point
    y0 = np.concatenate([theta0, omega0, r - a @ r, a @ hat(r) @ omega0])
    settings = run_settings(t_end=1.0, n_samples=101, rtol=1e-10, atol=1e-12)
    sol = integrate_sign_law(sliding, y0, settings)
    assert sol.status == "success" and np.all(sol.modes == 0)
    assert list(sol.switchings.kind) == [SLIDING_STARTS] * 3
    from paper_model import solve

    _, reduced, status, _, _ = solve(pinned, pinned.initial_state(blocks), settings)
    assert status == "success"
    np.testing.assert_allclose(sol.states[:, 0:6], reduced, atol=1e-7 * np.abs(reduced).max())
    lam_sliding = quantities(sliding, sol.states, np.zeros(3))[:, 2]
    lam_pinned = pinned.evaluate(reduced)["constraint_force"]
    np.testing.assert_allclose(lam_sliding, lam_pinned, atol=1e-6 * np.abs(lam_pinned).max())


# -- where the run goes: run, sweeps, failures, files ---------------------------------------------
def test_sign_law_runs_are_routed_in_batches_and_fail_as_data():
    """simulate_many routes a sign-law run beside a smooth one; gimbal lock and a timeout are
    failed runs with their reason, not exceptions."""
    smooth = example("simulation.t_end=0.2", "simulation.n_samples=201", "controller.boundary_layer=0.005")
    sign = example("simulation.t_end=0.2", "simulation.n_samples=201")
    locking = example("simulation.t_end=0.2", "simulation.n_samples=201", "initial_state.theta=[0.0, 1.5, 0.0]",
                      "initial_state.omega=[0.0, 30.0, 0.0]")
    results = dict(simulate_many([smooth, sign, locking]))
    assert results[0].switching is None and results[1].switching is not None
    assert results[1].ok and "switchings located" in results[1].message
    assert results[2].status == "failed" and "gimbal lock" in results[2].message
    assert np.isnan(results[2].outputs["position"][-1]).all()
    timed = simulate(sign, timeout=0.0)
    assert timed.status == "failed" and timed.message.startswith("timeout")


def test_cli_run_show_and_file_of_a_sign_law_run(tmp_path):
    import xarray as xr

    config = tmp_path / "sign.yaml"
    data = apply_overrides(parse_yaml(SLIDING_EXAMPLE.read_text()),
                           [*SIGN_LAW, "simulation.t_end=0.3", "simulation.n_samples=301", "name=sign"])
    config.write_text(yaml.safe_dump(data))
    result = CliRunner().invoke(cli, ["run", str(config), "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    with xr.open_dataset(tmp_path / "sign.h5", engine="h5netcdf") as ds:
        kind = ds["switching_kind"].values
        assert ds["switching_time"].dims == ("switching",) and ds["switching_time"].attrs["units"] == "s"
        assert np.all(np.diff(ds["switching_time"].values) >= 0)
        assert list(ds.attrs["summary_switching_count"]) == [np.sum((ds["switching_axis"].values == i) & (kind == 0))
                                                             for i in range(3)]
        assert ds["sliding_mode"].dims == ("time", "axis")
    shown = CliRunner().invoke(cli, ["show", str(tmp_path / "sign.h5")])
    assert shown.exit_code == 0
    for key in ("switching_count", "sliding_time", "chattering", "switching_resolution", "lyapunov_rate_checked"):
        assert key in shown.output
    summary = read_summary(tmp_path / "sign.h5")["summary"]
    for key, value in summary.items():  # every figure can be a report's metric
        if not isinstance(value, str):
            names = [key] + ([f"{key}_{a}" for a in "xyz"] if isinstance(value, list) else [])
            assert validate_metrics(names) == names
    report = CliRunner().invoke(cli, ["report", str(tmp_path / "sign.h5"), "-o", str(tmp_path / "report"),
                                      "--format", "md"])
    assert report.exit_code == 0, report.output
    page = (tmp_path / "report" / "index.md").read_text()
    assert "Pure sign law (eq 39): switchings located per axis of E" in page
    assert (tmp_path / "report" / "figures" / "sign_switching.png").is_file()


def test_sweep_of_sign_law_runs_stores_the_switching_figures(tmp_path):
    from rbstab.io.chunk import read_chunk_rows
    from rbstab.sweep import run_sweep, spec_from_mapping

    spec = spec_from_mapping({"name": "sign", "base": str(SLIDING_EXAMPLE),
                              "grid": {"controller.k_s": [1500.0, 2500.0]}},
                             overrides=[*SIGN_LAW, "simulation.t_end=0.2", "simulation.n_samples=201"])
    run_sweep(spec, tmp_path, jobs=1, progress=False)
    rows = [row for path in sorted((tmp_path / "sign").rglob("*.h5")) for row in read_chunk_rows(path)]
    assert len(rows) == 2 and all(row["status"] == "success" for row in rows)
    for row in rows:
        assert row["switching_count_x"] >= 1 and row["sliding_time_y"] >= 0
