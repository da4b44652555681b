"""The summary's rate check: analytic dv/dt against the numerical derivative of v.

It passes when max |analytic - numerical| <= 1e-3 P, P = max(max |analytic|, E / T)
(E the run's energy scale, T its duration; docs/physics.md). The floor E / T keeps a
conservative run (zero gains: analytic dv/dt = 0) from failing on the noise of the
numerical derivative; a wrong analytic rate must still fail.
"""

import copy
import warnings

import numpy as np
import pytest

from rbstab.config import PhysicalPlausibilityWarning, config_from_mapping, load_config
from rbstab.simulator import simulate
from rbstab.summary import LYAPUNOV_RATE_TOLERANCE, numerical_rate, summarize

from conftest import ROOT

TERMS = ("lyapunov_translational", "lyapunov_rotational", "lyapunov_constraint", "lyapunov_gravity")

ZERO = [0.0, 0.0, 0.0]
TUMBLING = {
    "name": "tumbling",
    "body": {"mass": 41.0, "inertia": [10.0, 8.0, 0.4], "attachment_point": [0.15, 0.10, -0.42]},
    "controller": {
        "variant": "free",
        **{g: ZERO for g in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d")},
        "l_d": [1200.0, 1200.0, 840.0],
        "k_s": 0.0,
    },
    "initial_state": {"omega": [16.0, 32.0, -16.0], "v": [0.5, -0.2, 0.1]},
    "simulation": {"t_end": 1.0, "n_samples": 1001},  # rtol 1e-8, DOP853: the defaults
}


def conservative_run(variant, gravity=ZERO):
    data = copy.deepcopy(TUMBLING)
    data["controller"]["variant"] = variant
    data["body"]["gravity"] = list(gravity)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Table 1's inertia, and the zero gains' note
        return simulate(config_from_mapping(data))


def energy_scale(outputs):
    return np.max(sum(np.abs(outputs[k]) for k in TERMS))


@pytest.mark.parametrize(
    "variant, gravity",
    [
        ("free", ZERO),  # torque-free tumbling
        ("visco_elastic", ZERO),
        ("embedded", ZERO),
        ("sliding", ZERO),  # K_s = 0
        ("permanent", ZERO),  # spinning top about a fixed point, no gravity
        ("permanent", [0.0, 0.0, -10.0]),  # passive pendulum
    ],
)
def test_a_conservative_run_passes_the_rate_check(variant, gravity):
    run = conservative_run(variant, gravity)
    assert run.status == "success"
    out, s = run.outputs, run.summary
    v = out["lyapunov"]
    assert np.ptp(v) < 1e-6 * np.max(np.abs(v))  # conserved: v is energy here
    assert np.max(np.abs(out["lyapunov_rate"])) < 1e-8  # the analytic dv/dt: 0 up to rounding
    # the numerical derivative is noise far above that: without the floor the check fails
    mismatch = s["lyapunov_rate_mismatch"]
    assert mismatch > 1e3 * np.max(np.abs(out["lyapunov_rate"]))
    assert s["lyapunov_rate_check"] == "pass"
    reference = energy_scale(out) / run.time[-1]  # E / T [W]
    assert s["lyapunov_rate_mismatch_relative"] == pytest.approx(mismatch / reference, rel=1e-12)
    assert s["lyapunov_rate_mismatch_relative"] < 0.5 * LYAPUNOV_RATE_TOLERANCE


def with_rate(run, rate):
    return summarize(run.time, {**run.outputs, "lyapunov_rate": rate})


def test_a_wrong_analytic_rate_of_a_conservative_run_fails():
    run = conservative_run("free")
    out = run.outputs
    assert run.summary["lyapunov_rate_check"] == "pass"
    # a variant whose dv/dt claims a damping L_r its dynamics does not apply
    omega = out["omega"]
    l_r = np.array([60.0, 60.0, 42.0])
    assert with_rate(run, -np.sum(l_r * omega**2, axis=1))["lyapunov_rate_check"] == "fail"
    # the floor is tol E / T, no more: a bias of twice that fails, of a third passes
    floor = LYAPUNOV_RATE_TOLERANCE * energy_scale(out) / run.time[-1]
    assert run.summary["lyapunov_rate_mismatch"] < floor / 3
    bias = np.full_like(out["lyapunov_rate"], 2 * floor)
    assert with_rate(run, out["lyapunov_rate"] + bias)["lyapunov_rate_check"] == "fail"
    small = with_rate(run, out["lyapunov_rate"] + bias / 6)
    assert small["lyapunov_rate_check"] == "pass"


def test_the_floor_does_not_weaken_the_check_of_a_damped_run():
    with pytest.warns(PhysicalPlausibilityWarning):  # Table 1's inertia
        config = load_config(
            ROOT / "configs/paper/case3_embedded.yaml", ["simulation.t_end=1", "simulation.n_samples=1001"]
        )
    run = simulate(config)
    out, s = run.outputs, run.summary
    peak = np.max(np.abs(out["lyapunov_rate"]))
    assert energy_scale(out) / run.time[-1] < 0.1 * peak  # the floor is inactive here
    assert s["lyapunov_rate_check"] == "pass"
    assert s["lyapunov_rate_mismatch_relative"] == pytest.approx(s["lyapunov_rate_mismatch"] / peak)
    # an analytic rate 1 % off fails
    assert with_rate(run, 1.01 * out["lyapunov_rate"])["lyapunov_rate_check"] == "fail"


def test_floor_on_synthetic_samples():
    # v constant (E = 100 J) plus noise of 1e-7 J over T = 2 s; analytic dv/dt = 0
    rng = np.random.default_rng(5)
    time = np.linspace(0.0, 2.0, 401)
    v = 100.0 + 1e-7 * rng.standard_normal(time.size)
    outputs = {
        "lyapunov": v[None],
        "lyapunov_rate": np.zeros((1, time.size)),
        "lyapunov_rate_numerical": numerical_rate(time, v)[None],
        "lyapunov_rotational": v[None],
        "lyapunov_translational": np.zeros((1, time.size)),
        "constraint_error": np.zeros((1, time.size, 3)),
    }
    s = summarize(time, {k: x[0] for k, x in outputs.items()})
    assert s["lyapunov_rate_mismatch"] > 0
    assert s["lyapunov_rate_mismatch_relative"] == pytest.approx(s["lyapunov_rate_mismatch"] / 50.0)
    assert s["lyapunov_rate_check"] == "pass"
    # the terms' magnitudes, not v: 1e4 J that cancel to v = 100 J raise the floor 200x
    outputs["lyapunov_gravity"] = np.full((1, time.size), -1e4)
    outputs["lyapunov_rotational"] = v[None] + 1e4
    s2 = summarize(time, {k: x[0] for k, x in outputs.items()})
    assert s2["lyapunov_rate_mismatch_relative"] == pytest.approx(s["lyapunov_rate_mismatch_relative"] / 201, rel=1e-6)


def numpy_figures(time, outputs, checked=None):
    """The summary figures by numpy's reductions over whole arrays (the reference of the
    compiled one-pass kernel): (max |E| by axis, max dv/dt, largest rise of v above its
    running minimum, mismatch, reference power P) of each row."""
    v, rate = outputs["lyapunov"], outputs["lyapunov_rate"]
    error = np.abs(outputs["constraint_error"])
    difference = np.abs(rate - outputs["lyapunov_rate_numerical"])
    if checked is not None:
        difference = np.where(checked, difference, 0.0)
    energy = np.max(sum(np.abs(outputs[k]) for k in TERMS), axis=1)
    power = np.maximum(np.max(np.abs(rate), axis=1), energy / (time[-1] - time[0]))
    return (np.max(error, axis=1), np.max(rate, axis=1), np.max(v - np.minimum.accumulate(v, axis=1), axis=1),
            np.max(difference, axis=1), np.where(power == 0.0, 1.0, power))


@pytest.mark.parametrize("with_checked", [False, True])
def test_summary_figures_are_numpys_reductions(with_checked):
    """summarize_many's figures (one compiled pass over each run's samples) are, bit for
    bit, numpy's reductions: NaN propagated by max, v's running minimum, the magnitudes of
    v's terms summed in order, the unchecked samples' mismatch counted as 0."""
    from rbstab.summary import summarize_many

    rng = np.random.default_rng(3)
    k, n = 7, 50
    time = np.linspace(0.0, 2.0, n)
    outputs = {key: rng.normal(size=(k, n)) * 10.0 ** rng.integers(-3, 4) for key in TERMS}
    outputs["lyapunov"] = sum(outputs[key] for key in TERMS)
    outputs["lyapunov"][2] = np.sort(outputs["lyapunov"][2])[::-1]  # non-increasing: no rise
    outputs["lyapunov_rate"] = rng.normal(size=(k, n))
    outputs["lyapunov_rate"][4] = 0.0  # P from the energy scale alone
    outputs["lyapunov_rate_numerical"] = outputs["lyapunov_rate"] + 1e-4 * rng.normal(size=(k, n))
    outputs["constraint_error"] = rng.normal(size=(k, n, 3))
    outputs["constraint_error"][1, 7, 2] = np.nan  # a NaN inside the finite samples of v
    outputs["lyapunov_rate"][3, 11] = np.nan
    checked = rng.random((k, n)) < 0.8 if with_checked else None
    error, max_rate, rise, mismatch, power = numpy_figures(time, outputs, checked)
    for j, summary in enumerate(summarize_many(time, outputs, checked)):
        np.testing.assert_array_equal(summary["max_abs_constraint_error"], error[j])
        np.testing.assert_array_equal(summary["max_lyapunov_rate"], max_rate[j])
        np.testing.assert_array_equal(summary["max_lyapunov_increase"], rise[j])
        np.testing.assert_array_equal(summary["lyapunov_rate_mismatch"], mismatch[j])
        np.testing.assert_array_equal(summary["lyapunov_rate_mismatch_relative"], mismatch[j] / power[j])
        assert summary["lyapunov_initial"] == outputs["lyapunov"][j, 0]
        assert summary["lyapunov_final"] == outputs["lyapunov"][j, -1]
        n_checked = n if checked is None else int(checked[j].sum())
        assert summary.get("lyapunov_rate_checked", 1.0) == n_checked / n
    assert np.isnan(error[1, 2]) and np.isnan(max_rate[3]) and rise[2] == 0.0


def test_a_streamed_tree_run_without_samples_has_no_figures():
    """The figures of tree runs the GPU never started (a launch's deadline): their
    accumulators as the kernel leaves them (no sample taken) and a NaN last state give NaN
    for every figure, per member for the per-member ones, but t_final (the grid's start) and
    the time v rose (0 s), as the CPU's table of a run without a finite sample, and no rate
    check."""
    from rbstab.summary import (ACCUMULATOR_SIZE, MEMBER_SLOTS, short_stencils, stencil_weights, stream_finish,
                                stream_member_start, stream_start, tree_stream_table)

    time = np.linspace(0.0, 1.0, 11)
    first, weights = stencil_weights(time)
    acc, members = np.empty((2, ACCUMULATOR_SIZE)), np.empty((2, 2, MEMBER_SLOTS))
    for k in range(2):  # what the kernel does for a run it does not start
        stream_start(acc[k])
        stream_member_start(members[k])
        stream_finish(acc[k], first, weights, short_stencils(time), np.empty(0), 1)
    last = np.full((2, 27), np.nan)
    d_at = np.array([-1, 24])  # the second joint embedded: its D after the two bodies' 24 states
    table = tree_stream_table(time, acc, members, last, 2, d_at)
    assert table["t_final"].tolist() == table["time_lyapunov_rising"].tolist() == [0.0, 0.0]
    for key, value in table.items():
        if key == "lyapunov_rate_check":
            assert value.tolist() == ["n/a", "n/a"]
        elif key not in ("t_final", "time_lyapunov_rising"):
            assert np.isnan(value).all(), key
    assert table["final_theta"].shape == table["max_abs_constraint_error"].shape == (2, 2, 3)
    assert table["final_controller_state"].shape == table["fraction_saturated_torque_n"].shape == (2, 2, 3)


def test_balance_figures_are_their_definitions():
    """settling_time, com_excursion and peak_sway of k runs of a two-body tree, against their
    definitions written out with numpy: the first sample time after which every |E_j| <=
    SETTLE_E and every |Omega_i| <= SETTLE_OMEGA (NaN for a run not settled at its end, or
    stopped early), the largest |c - c(0)| of the whole-body centre of mass c = sum m_i X_i /
    sum m_i, and the largest part of it perpendicular to gravity (NaN without gravity);
    NaN for both without the bodies' records."""
    from rbstab.layout import SETTLE_E, SETTLE_OMEGA
    from rbstab.model import PARAMETERS
    from rbstab.summary import summarize_many

    rng = np.random.default_rng(5)
    k, n = 4, 60
    time = np.linspace(0.0, 3.0, n)
    outputs = {key: rng.normal(size=(k, n)) for key in TERMS}
    outputs["lyapunov"] = sum(outputs[key] for key in TERMS)
    outputs["lyapunov_rate"] = outputs["lyapunov_rate_numerical"] = rng.normal(size=(k, n))
    decay = np.exp(-3.0 * time)[None, :, None, None]
    outputs["omega"] = 0.5 * rng.normal(size=(k, n, 2, 3)) * decay
    outputs["constraint_error"] = 0.05 * rng.normal(size=(k, n, 2, 3)) * decay
    outputs["omega"][1, -1, 1, 0] = 0.1  # the trunk still turning at the end: not settled
    outputs["position"] = rng.normal(size=(k, n, 2, 3)) * 0.1 + np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 1.2]])
    for key in ("lyapunov", "omega", "constraint_error", "position"):
        outputs[key][3, 40:] = np.nan  # run 3 stopped at its 40th sample
    params = np.zeros((k, 2), dtype=PARAMETERS)
    params["mass"] = [[22.5, 47.5], [10.0, 1.0], [3.0, 3.0], [70.0, 5.0]]
    gravity = np.array([[0.0, 0.0, -9.81], [0.0, -9.81, 0.0], [0.0, 0.0, 0.0], [3.0, 0.0, -9.0]])
    params["weight"] = params["mass"][:, :, None] * gravity[:, None, :]

    largest_e = np.linalg.norm(outputs["constraint_error"], axis=-1).max(axis=-1)
    largest_omega = np.linalg.norm(outputs["omega"], axis=-1).max(axis=-1)
    mass = params["mass"]
    centre = np.einsum("ki,knij->knj", mass, outputs["position"]) / mass.sum(axis=1)[:, None, None]
    moved = centre - centre[:, :1]
    for j, summary in enumerate(summarize_many(time, outputs, params=params)):
        taken = 40 if j == 3 else n
        inside = (largest_e[j, :taken] <= SETTLE_E) & (largest_omega[j, :taken] <= SETTLE_OMEGA)
        if j in (1, 3):
            assert np.isnan(summary["settling_time"]), j
        else:
            assert inside[-1] and not inside.all()
            assert summary["settling_time"] == time[np.flatnonzero(~inside)[-1] + 1]
        d = moved[j, :taken]
        np.testing.assert_allclose(summary["com_excursion"], np.linalg.norm(d, axis=1).max(), rtol=1e-13)
        if j == 2:
            assert np.isnan(summary["peak_sway"])  # no gravity: no horizontal
        else:
            up = gravity[j] / np.linalg.norm(gravity[j])
            horizontal = d - np.outer(d @ up, up)
            np.testing.assert_allclose(summary["peak_sway"], np.linalg.norm(horizontal, axis=1).max(), rtol=1e-12)
            assert summary["peak_sway"] < summary["com_excursion"]
    for summary in summarize_many(time, outputs):  # without the records: no centre of mass
        assert np.isnan(summary["com_excursion"]) and np.isnan(summary["peak_sway"])
