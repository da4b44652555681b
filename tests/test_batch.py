"""Tests of the batched Runge-Kutta engine (rbstab.batch) against solo scipy solves.

Paper parameters (physics notes, Table 1): m = 41 kg, J = diag(10, 8, 0.4) kg m^2,
R = (0.15, 0.10, -0.42) m; case-2/3 gains; sliding K_s = 2000 N, phi = 0.005 m;
permanent with g = (0, 0, -10) m/s^2 and L_t = diag(210, 210, 140).
Short horizons keep the file fast: the solo scipy reference is the slow part.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from rbstab.batch import (
    SUCCESS_MESSAGE,
    SUPPORTED_METHODS,
    TOO_SMALL_STEP_MESSAGE,
    BatchSolution,
    integrate_batch,
    integrate_many,
    iter_chunks,
)
from rbstab.model import Gains, RigidBody
from rbstab.variants import VARIANTS

D = np.diag
OMEGA0 = np.array([16.0, 32.0, -16.0])
VARIANT_NAMES = ("free", "permanent", "sliding", "visco_elastic", "embedded")



def test_rk_tableaus_are_scipys():
    """rbstab.rk_tableaus (the batch engine's copy, so workers need not import
    scipy.integrate) holds exactly the installed scipy's numbers and messages."""
    from scipy.integrate._ivp import dop853_coefficients
    from scipy.integrate._ivp import rk
    from scipy.integrate._ivp.base import OdeSolver
    from scipy.integrate._ivp.ivp import MESSAGES

    from rbstab import rk_tableaus

    for method in SUPPORTED_METHODS:
        ours, theirs = rk_tableaus.TABLEAUS[method], getattr(rk, method)
        for key in ("order", "error_estimator_order", "n_stages"):
            assert getattr(ours, key) == getattr(theirs, key), (method, key)
        keys = ["C", "A", "B"] + (["E3", "E5", "D"] if method == "DOP853" else ["E", "P"])
        for key in keys:
            np.testing.assert_array_equal(getattr(ours, key), getattr(theirs, key), err_msg=f"{method}.{key}")
        assert set(vars(ours)) == {"order", "error_estimator_order", "n_stages", *keys}
    for key in ("A", "C"):
        np.testing.assert_array_equal(getattr(rk_tableaus.DOP853_EXTENDED, key), getattr(dop853_coefficients, key))
    assert rk_tableaus.DOP853_EXTENDED.N_STAGES_EXTENDED == dop853_coefficients.N_STAGES_EXTENDED
    assert rk_tableaus.DOP853_EXTENDED.INTERPOLATOR_POWER == dop853_coefficients.INTERPOLATOR_POWER
    assert (rk_tableaus.SAFETY, rk_tableaus.MIN_FACTOR, rk_tableaus.MAX_FACTOR) == (rk.SAFETY, rk.MIN_FACTOR, rk.MAX_FACTOR)
    assert rk_tableaus.SUCCESS_MESSAGE == MESSAGES[0]
    assert rk_tableaus.TOO_SMALL_STEP_MESSAGE == OdeSolver.TOO_SMALL_STEP

def make_variant(name: str):
    gravity = np.array([0.0, 0.0, -10.0]) if name in ("permanent", "free") else np.zeros(3)
    body = RigidBody(41.0, D([10.0, 8.0, 0.4]), np.array([0.15, 0.10, -0.42]), gravity)
    kw = dict(
        k_t=D([4100.0, 4100.0, 3280.0]),
        l_t=D([210.0, 210.0, 140.0]) if name == "permanent" else D([200.0, 200.0, 140.0]),
        k_r=D([400.0, 400.0, 320.0]),
        l_r=D([60.0, 60.0, 42.0]),
    )
    if name == "visco_elastic":
        kw.update(k_c=D([4100.0, 4100.0, 3280.0]), l_c=D([200.0, 200.0, 140.0]))
    elif name == "embedded":
        k_c, l_c = D([12300.0, 12300.0, 9840.0]), D([600.0, 600.0, 420.0])
        kw.update(k_c=k_c, l_c=l_c, k_d=k_c, l_d=2 * l_c)
    elif name == "sliding":
        kw.update(k_s=2000.0, boundary_layer=0.005)
    return VARIANTS[name](body, Gains(**kw))


def initial_states(variant, n: int) -> np.ndarray:
    """Case initial conditions with the spin scaled by 1, 1.05, 0.95, ... per run."""
    y0 = np.zeros((n, variant.layout.size))
    scale = 1.0 + 0.05 * np.array([0, 1, -1, 2, -2, 3])[:n]
    y0[:, variant.layout.slice("omega")] = OMEGA0 * scale[:, None]
    y0[:, variant.layout.slice("theta")] = 0.01 * np.arange(n)[:, None] * np.array([1.0, -1.0, 0.5])
    return y0


def solo(variant, y0, t_end, method, rtol, atol):
    return solve_ivp(variant.rhs, (0.0, t_end), y0, method=method, rtol=rtol, atol=atol, dense_output=True)


@pytest.fixture(scope="module", params=VARIANT_NAMES)
def variant(request):
    return make_variant(request.param)


@pytest.mark.parametrize("method", ["RK45", "DOP853"])
def test_batch_matches_solo_solve_ivp(variant, method):
    t_end = 0.05 if variant.name == "sliding" else 0.1
    rtol, atol = 1e-8, 1e-10
    y0 = initial_states(variant, 3)
    sol = integrate_batch(variant, y0, t_end, 6, method=method, rtol=rtol, atol=atol)
    assert isinstance(sol, BatchSolution)
    assert sol.y.shape == (3, 6, variant.layout.size)
    np.testing.assert_array_equal(sol.t, np.linspace(0.0, t_end, 6))
    assert list(sol.status) == [0, 0, 0]
    assert sol.message == [SUCCESS_MESSAGE] * 3
    np.testing.assert_array_equal(sol.t_final, t_end)
    for i in range(3):
        ref = solo(variant, y0[i], t_end, method, rtol, atol)
        expected = ref.sol(sol.t).T
        # same steps, same interpolant: agreement to round-off, far below the tolerance
        np.testing.assert_allclose(sol.y[i], expected, rtol=0, atol=1e-9 * np.abs(expected).max())
        np.testing.assert_allclose(sol.y_final[i], ref.y[:, -1], rtol=0, atol=1e-9 * np.abs(ref.y).max())
        assert sol.n_steps[i] == ref.t.size - 1
        if method == "RK45":
            assert sol.nfev[i] == ref.nfev
        else:  # dense-output extras only for the steps holding samples
            assert sol.nfev[i] <= ref.nfev


@pytest.mark.parametrize("method", ["RK45", "DOP853"])
def test_samples_of_a_run_do_not_depend_on_its_company(method):
    """Runs whose steps hold different numbers of samples (the dense output is evaluated
    for sorted rows, a few samples at a time): each run's samples are bit for bit those
    it gets integrated alone."""
    variant = make_variant("embedded")
    y0 = initial_states(variant, 6)
    y0[:, variant.layout.slice("omega")] *= np.array([1.0, 3.0, 0.3, 2.0, 0.6, 1.5])[:, None]
    together = integrate_batch(variant, y0, 0.05, 301, method=method, rtol=1e-6, atol=1e-8)
    for i in range(6):
        alone = integrate_batch(variant, y0[i : i + 1], 0.05, 301, method=method, rtol=1e-6, atol=1e-8)
        np.testing.assert_array_equal(together.y[i], alone.y[0])
        np.testing.assert_array_equal(together.y_final[i], alone.y_final[0])


@pytest.mark.parametrize("method", ["RK45", "DOP853"])
def test_many_samples_per_step(method):
    """Dense sampling far finer than the steps (several samples per step, some steps
    with none): every sample comes from the interpolant of the step holding it."""
    variant = make_variant("visco_elastic")
    y0 = initial_states(variant, 3)
    sol = integrate_batch(variant, y0, 0.05, 301, method=method, rtol=1e-6, atol=1e-8)
    assert np.all(sol.n_steps < 100)
    for i in range(3):
        expected = solo(variant, y0[i], 0.05, method, 1e-6, 1e-8).sol(sol.t).T
        np.testing.assert_allclose(sol.y[i], expected, rtol=0, atol=1e-9 * np.abs(expected).max())


def test_rk23_supported():
    variant = make_variant("visco_elastic")
    y0 = initial_states(variant, 2)
    sol = integrate_batch(variant, y0, 0.02, 3, method="RK23", rtol=1e-6, atol=1e-8)
    ref = solo(variant, y0[1], 0.02, "RK23", 1e-6, 1e-8)
    expected = ref.sol(sol.t).T
    np.testing.assert_allclose(sol.y[1], expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    assert sol.nfev[1] == ref.nfev


@pytest.mark.parametrize("name", ["embedded", "permanent"])
def test_gimbal_lock_fails_one_run_and_not_the_others(name):
    variant = make_variant(name)
    margin = 1e-3
    y0 = initial_states(variant, 3)
    # run 1 starts 0.05 rad below the lock and spins into it: d(theta_2)/dt = omega_2 (theta_3 = 0)
    y0[1, 0:3] = [0.0, np.pi / 2 - 0.05, 0.0]
    y0[1, 3:6] = [0.0, 20.0, 0.0]
    t_end, n_samples = 0.01, 21
    sol = integrate_batch(variant, y0, t_end, n_samples, method="DOP853", rtol=1e-8, atol=1e-10,
                          gimbal_margin=margin)
    assert list(sol.status) == [0, -1, 0]
    msg = sol.message[1]
    assert msg.startswith("gimbal lock: |theta_2| reached pi/2 - 0.001 rad at t = ")
    assert "B(theta) is singular (eq 5)" in msg
    t_lock = sol.t_final[1]
    assert 0.001 < t_lock < 0.005
    assert f"t = {t_lock:.6g} s" in msg
    # the crossing is located on the interpolant, to near machine precision
    assert abs(abs(sol.y_final[1, 1]) - (np.pi / 2 - margin)) < 1e-9
    after = sol.t > t_lock
    assert np.all(np.isnan(sol.y[1, after]))
    assert np.all(np.isfinite(sol.y[1, ~after]))
    # the same as solve_ivp with a terminal event at the margin: same steps, same crossing
    def lock(t, y):
        return abs(y[1]) - (np.pi / 2 - margin)

    lock.terminal = True
    ref = solve_ivp(variant.rhs, (0.0, t_end), y0[1], method="DOP853", rtol=1e-8, atol=1e-10,
                    dense_output=True, events=lock)
    assert ref.status == 1
    assert abs(ref.t_events[0][0] - t_lock) < 1e-12
    expected = ref.sol(sol.t[~after]).T
    np.testing.assert_allclose(sol.y[1, ~after], expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(sol.y_final[1], ref.y_events[0][0], rtol=0, atol=1e-9)
    # the other runs are unaffected
    for i in (2,):
        ref = solo(variant, y0[i], t_end, "DOP853", 1e-8, 1e-10)
        expected = ref.sol(sol.t).T
        np.testing.assert_allclose(sol.y[i], expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    # without the check the same run is integrated on
    free_run = integrate_batch(variant, y0[1:2], 0.005, 3, method="DOP853", gimbal_margin=None)
    assert free_run.status[0] == 0


def test_gimbal_lock_at_start():
    variant = make_variant("embedded")
    y0 = initial_states(variant, 2)
    y0[0, 1] = -(np.pi / 2 - 1e-4)
    sol = integrate_batch(variant, y0, 0.01, 3, method="RK45")
    assert list(sol.status) == [-1, 0]
    assert sol.message[0].startswith("gimbal lock") and "t = 0 s" in sol.message[0]
    assert sol.t_final[0] == 0.0
    assert np.all(np.isnan(sol.y[0, 1:]))
    np.testing.assert_array_equal(sol.y[0, 0], y0[0])


def test_nan_initial_state_fails_only_that_run():
    variant = make_variant("visco_elastic")
    y0 = initial_states(variant, 3)
    y0[2, 4] = np.nan
    sol = integrate_batch(variant, y0, 0.02, 5, method="DOP853")
    assert list(sol.status) == [0, 0, -1]
    assert sol.message[2].startswith("non-finite state")
    assert np.all(np.isnan(sol.y[2, 1:]))
    assert np.all(np.isfinite(sol.y[:2]))
    clean = integrate_batch(variant, y0[:2], 0.02, 5, method="DOP853")
    np.testing.assert_allclose(sol.y[:2], clean.y, rtol=0, atol=1e-12 * np.abs(clean.y).max())


@pytest.mark.parametrize("method", SUPPORTED_METHODS)
def test_rhs_turning_nan_mid_run(method):
    """A right-hand side that becomes NaN for y_0 > 0.5: scipy's rejections shrink the step
    until it is too small; the run fails there, with a non-finite message, and the samples
    after it are NaN. The other run never reaches the NaN region and succeeds."""

    def fun(t, y):
        out = np.ones_like(y)
        out[y[:, 0] > 0.5] = np.nan
        return out

    y0 = np.array([[0.0, 0.0, 0.0], [-10.0, 1.0, 2.0]])
    sol = integrate_batch(fun, y0, 1.0, 11, method=method, gimbal_margin=None)
    assert list(sol.status) == [-1, 0]
    assert sol.message[0].startswith("non-finite state")
    assert TOO_SMALL_STEP_MESSAGE in sol.message[0]
    assert 0.5 - 1e-6 < sol.t_final[0] <= 0.5
    assert np.all(np.isnan(sol.y[0, sol.t > sol.t_final[0]]))
    ok = sol.t <= sol.t_final[0]
    np.testing.assert_allclose(sol.y[0, ok, 0], sol.t[ok], atol=1e-12)
    np.testing.assert_allclose(sol.y[1, :, 0], -10.0 + sol.t, atol=1e-12)
    assert sol.n_rejected[0] > 0


def test_unsupported_method():
    variant = make_variant("free")
    with pytest.raises(ValueError, match=r"unsupported method 'LSODA'.*RK23, RK45, DOP853"):
        integrate_batch(variant, initial_states(variant, 1), 0.1, 2, method="LSODA")
    with pytest.raises(ValueError, match="supported"):
        integrate_many(variant, initial_states(variant, 1), 0.1, 2, method="Radau")  # eager


def test_argument_errors():
    variant = make_variant("permanent")
    y0 = initial_states(variant, 2)
    with pytest.raises(ValueError, match="layout"):
        integrate_batch(variant, np.zeros((2, 12)), 0.1, 2)
    with pytest.raises(ValueError, match="t_end"):
        integrate_batch(variant, y0, 0.0, 2)
    with pytest.raises(ValueError, match="n_samples"):
        integrate_batch(variant, y0, 0.1, 0)
    with pytest.raises(ValueError, match="gimbal_margin"):
        integrate_batch(variant, y0, 0.1, 2, gimbal_margin=2.0)
    with pytest.raises(ValueError, match="max_step"):
        integrate_batch(variant, y0, 0.1, 2, max_step=0.0)


def test_chunks_and_max_step():
    variant = make_variant("embedded")
    y0 = initial_states(variant, 5)
    assert [list(c) for c in iter_chunks(5, 2)] == [[0, 1], [2, 3], [4]]
    whole = integrate_batch(variant, y0, 0.02, 4, method="RK45", rtol=1e-6, atol=1e-8, max_step=2e-3)
    assert np.all(whole.n_steps >= 10)  # max_step honoured
    seen = []
    for indices, part in integrate_many(variant, y0, 0.02, 4, chunk_size=2, method="RK45", rtol=1e-6,
                                        atol=1e-8, max_step=2e-3):
        seen.extend(indices)
        np.testing.assert_allclose(part.y, whole.y[indices], rtol=0, atol=1e-10 * np.abs(whole.y).max())
        np.testing.assert_array_equal(part.n_steps, whole.n_steps[indices])
    assert seen == list(range(5))
    ref = solve_ivp(variant.rhs, (0, 0.02), y0[3], method="RK45", rtol=1e-6, atol=1e-8, max_step=2e-3)
    assert whole.n_steps[3] == ref.t.size - 1 and whole.nfev[3] == ref.nfev


def test_empty_batch():
    variant = make_variant("free")
    sol = integrate_batch(variant, np.zeros((0, 12)), 1.0, 3)
    assert sol.y.shape == (0, 3, 12) and sol.message == []
