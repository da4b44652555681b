"""Saturating actuators (|N_i|, |H_i|, |Lambda_i| limited; clip or smooth): the compiled
physics against an independent plain-numpy model, the analytic dv/dt with the delivered
controls against the derivative of v, and the basin edge of a torque-limited inverted
pendulum against the tilt where the saturated torque balances gravity."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from conftest import paper_body, paper_gains
from reference import Model
from rbstab.variants.paper import paper_form
from rbstab.engine import integrate_runs
from rbstab.model import RigidBody, Saturation
from rbstab.variants import VARIANTS

ALL = sorted(VARIANTS)
SHAPES = ["clip", "smooth"]


def _saturated(name, shape, gravity=(0.0, 0.0, -10.0), **limits):
    sat = Saturation(torque_n=np.array(limits.get("torque_n", [40.0, 60.0, np.inf])),
                     force_h=np.array(limits.get("force_h", [150.0, np.inf, 300.0])),
                     constraint_force=np.array(limits.get("constraint_force",
                                                          [np.inf, 200.0, 250.0] if name != "permanent"
                                                          else [np.inf] * 3)),
                     shape=shape)
    gains = dataclasses.replace(paper_gains(), saturation=sat)
    return VARIANTS[name](paper_body(gravity), gains)


def _states(variant, rng, n=30):
    y = rng.normal(scale=0.2, size=(n, variant.layout.size))
    y[:, 3:6] = rng.normal(scale=5.0, size=(n, 3))
    return y


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("name", ALL)
def test_saturated_rhs_is_the_plain_numpy_model(name, shape, rng):
    """The compiled right-hand side with limits on N, H and Lambda against tests/reference.py
    (np.clip / tanh of its own controls) at random states, where the limits are active."""
    variant = _saturated(name, shape)
    reference = Model(name, variant.body, variant.gains)
    unlimited = Model(name, variant.body, dataclasses.replace(variant.gains, saturation=None))
    y = _states(variant, rng)
    compiled = variant.rhs(0.0, y)
    differs = 0
    for yi, fi in zip(y, compiled):
        expected = reference.rhs(0.0, yi)
        np.testing.assert_allclose(fi, expected, rtol=1e-12, atol=1e-10 * np.abs(expected).max())
        differs += not np.allclose(expected, unlimited.rhs(0.0, yi))
    assert differs == len(y)  # the limits act at every state drawn


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("name", ALL)
def test_delivered_dv_dt_is_the_derivative_of_v(name, shape, rng):
    """Pointwise: the analytic dv/dt (the paper's rate plus the power of the saturation
    deficit) equals (v(y + h f) - v(y - h f)) / 2h, and differs from the paper's unsaturated
    rate there (the bookkeeping is needed)."""
    variant = _saturated(name, shape)
    unlimited = VARIANTS[name](variant.body, dataclasses.replace(variant.gains, saturation=None))
    y = _states(variant, rng)
    f = variant.rhs(0.0, y)
    h = 1e-7
    numerical = (variant.lyapunov(y + h * f) - variant.lyapunov(y - h * f)) / (2 * h)
    analytic = variant.evaluate(y)["lyapunov_rate"]
    np.testing.assert_allclose(analytic, numerical, rtol=1e-5, atol=1e-5 * np.abs(analytic).max())
    paper = unlimited.evaluate(y)["lyapunov_rate"]
    assert np.max(np.abs(paper - analytic)) > 1e-3 * np.abs(analytic).max()


@pytest.mark.parametrize("name", ALL)
def test_delivered_outputs_respect_the_limits(name, rng):
    """The stored N, H and Lambda are the delivered ones: within their limits, at them where
    the command exceeds them (clip)."""
    variant = _saturated(name, "clip")
    out = variant.evaluate(_states(variant, rng))
    sat = variant.gains.saturation
    for key, limit in (("torque_n", sat.torque_n), ("force_h", sat.force_h), ("constraint_force", sat.constraint_force)):
        if name in ("permanent", "free") and key == "constraint_force":
            continue  # the pin's reaction; no constraint force
        assert np.all(np.abs(out[key]) <= limit * (1 + 1e-15)), key
        finite = np.isfinite(limit)
        assert np.any(np.isclose(np.abs(out[key][..., finite]), limit[finite], rtol=1e-15)), key


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("name", ALL)
def test_saturation_flags_mark_the_axes_commanded_at_their_limits(name, shape, rng):
    """The stored flags are 1 exactly where tests/reference.py's commanded N, H, Lambda are
    at or beyond their limits (clip: where the delivered value is the limit); Lambda of
    ``permanent``, the pin's reaction, is never flagged."""
    variant = _saturated(name, shape)
    reference = Model(name, variant.body, variant.gains)
    y = _states(variant, rng)
    out = variant.evaluate(y)
    sat = variant.gains.saturation
    expected = {key: [] for key in ("torque_n", "force_h", "constraint_force")}
    for j in range(len(y)):
        theta, omega = out["theta"][j], out["omega"][j]
        n_c, h_c = reference.commanded_controls(theta, omega, out["position"][j], out["velocity"][j])
        d = out["controller_state"][j] if "controller_state" in out else np.zeros(3)
        lam_c = (np.zeros(3) if name == "permanent" else
                 reference.commanded_constraint(out["constraint_error"][j], out["constraint_rate"][j], d)[0])
        expected["torque_n"].append(np.abs(n_c) >= sat.torque_n)
        expected["force_h"].append(np.abs(h_c) >= sat.force_h)
        expected["constraint_force"].append((np.abs(lam_c) >= sat.constraint_force) & (name != "permanent"))
    for key, flags in expected.items():
        np.testing.assert_array_equal(out[f"{key}_saturated"], np.array(flags, dtype=float), err_msg=key)
        if shape == "clip":
            at_limit = np.abs(out[key]) == sat.__getattribute__(key)
            np.testing.assert_array_equal(out[f"{key}_saturated"] == 1.0, at_limit if name != "permanent"
                                          or key != "constraint_force" else np.zeros_like(at_limit), err_msg=key)
    assert np.any(out["torque_n_saturated"] == 1.0) and np.any(out["torque_n_saturated"] == 0.0)


def _pendulum_falls(theta_1: float, n_max: float) -> bool:
    """Whether the pinned inverted pendulum (R = (0, 0, -L), gravity, K_t = L_t = 0,
    |N_1| <= n_max) let go at rest at tilt theta_1 falls (ends beyond a right angle)."""
    m, length = 2.0, 0.5
    body = RigidBody(m, np.diag([0.05, 0.05, 0.01]), np.array([0.0, 0.0, -length]), np.array([0.0, 0.0, -9.81]))
    zero = np.zeros((3, 3))
    big = np.inf
    gains = dataclasses.replace(paper_gains(), k_t=zero, l_t=zero, k_r=np.diag([200.0, 200.0, 50.0]),
                                l_r=np.diag([10.0, 10.0, 2.0]),
                                saturation=Saturation(np.array([n_max, big, big]), np.full(3, big), np.full(3, big)))
    variant = VARIANTS["permanent"](body, gains)
    y0 = np.zeros((1, 6))
    y0[0, 0] = theta_1
    sol = integrate_runs([variant.code], variant.parameters, y0, [[4.0, 1e-10, 1e-12, np.inf, 0.0, 10**7, np.inf]],
                         method="DOP853", n_samples=401)
    final = sol.samples[0, -1]
    return not (abs(final[0]) < 1e-3) if np.all(np.isfinite(final)) else True


def test_torque_limited_inverted_pendulum_has_its_basin_edge_where_torque_balances_gravity():
    """From rest, the torque-limited pinned inverted pendulum recovers below the tilt
    arcsin(N_max / (m g L)), where the saturated torque balances gravity, and falls above it."""
    m, g, length, n_max = 2.0, 9.81, 0.5, 4.0
    edge = math.asin(n_max / (m * g * length))
    assert not _pendulum_falls(edge - 0.01, n_max)
    assert _pendulum_falls(edge + 0.01, n_max)
    assert not _pendulum_falls(0.5, np.inf)  # without the limit the feedback holds it


# -- the configuration ----------------------------------------------------------------------------------
CASE2 = str(Path(__file__).resolve().parents[1] / "configs" / "paper" / "case2_visco_elastic.yaml")


def _load(*overrides):
    import warnings

    import rbstab

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rbstab.load_config(CASE2, list(overrides))


def test_saturation_keys_give_the_limits():
    """A number limits every axis, a list each one, a missing limit none; no section: no limits."""
    config = _load("controller.saturation={torque_n: 120, force_h: [800, 700, .inf], shape: smooth}")
    sat = paper_form(config).gains.saturation
    np.testing.assert_array_equal(sat.torque_n, [120.0] * 3)
    np.testing.assert_array_equal(sat.force_h, [800.0, 700.0, np.inf])
    np.testing.assert_array_equal(sat.constraint_force, [np.inf] * 3)
    assert sat.shape == "smooth"
    record = paper_form(config).parameters[0]
    assert record["saturation"] == 2.0 and record["torque_limit"].tolist() == [120.0] * 3
    assert paper_form(_load()).gains.saturation is None and paper_form(_load()).parameters[0]["saturation"] == 0.0


@pytest.mark.parametrize("override, found", [
    ("controller.saturation.torque_n=0", "found 0"),
    ("controller.saturation.torque_n=-5", "found -5"),
    ("controller.saturation.torque_n=.nan", "found nan"),
    ("controller.saturation.force_h=[1, 2]", "2 entries, not 3"),
    ("controller.saturation.constraint_force=[1, -2, 3]", "entry [1]"),
    ("controller.saturation.shape=tanh", "expected one of clip, smooth"),
    ("controller.saturation.torque=5", "has no 'torque'; did you mean 'controller.saturation.torque_n'?"),
])
def test_bad_limits_are_refused_in_one_line(override, found):
    from rbstab.config import ConfigError

    with pytest.raises(ConfigError) as info:
        _load(override)
    (line,) = info.value.errors
    key = override.partition("=")[0]
    assert key in line and found in line, line


@pytest.mark.parametrize("overrides, reason", [
    (["controller.variant=permanent"], "the pin's reaction"),
    (["controller.variant=sliding", "controller.k_s=500", "controller.boundary_layer=0"], "controller.k_s"),
])
def test_a_limit_on_a_force_no_actuator_delivers_is_refused(overrides, reason):
    from rbstab.config import ConfigError

    with pytest.raises(ConfigError) as info:
        _load("controller.saturation.constraint_force=100", *overrides)
    assert any("controller.saturation.constraint_force" in line and reason in line for line in info.value.errors)


def test_the_shipped_saturated_pendulum_recovers_below_its_edge_and_falls_above():
    """configs/examples/saturated_pendulum.yaml: back to rest from 0.3 rad, going over from 0.45 rad
    (its edge: arcsin(4 N m / (2 kg 9.81 m/s^2 0.5 m)) = 0.42 rad), the rate check passing."""
    import warnings

    import rbstab

    path = Path(__file__).resolve().parents[1] / "configs" / "examples" / "saturated_pendulum.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        held = rbstab.simulate(rbstab.load_config(path))
        fell = rbstab.simulate(rbstab.load_config(path, ["initial_state.theta=[0.45,0,0]"]))
    assert abs(float(held["theta"][-1, 0])) < 1e-6
    assert np.max(np.abs(fell["theta"].values[:, 0])) > math.pi  # over, through hanging down, and beyond
    assert float(np.max(np.abs(held["torque_n"].values[:, 0]))) == 4.0
    numerical, analytic = held["lyapunov_rate_numerical"].values, held["lyapunov_rate"].values
    assert np.nanmax(np.abs(numerical - analytic)) <= 1e-3 * np.max(np.abs(analytic))


def test_analyze_says_there_is_no_equilibrium_when_the_limits_cannot_hold_the_weight():
    """A free body whose |H_z| limit is below its weight m g has no rest point: analyze says
    so in one line, naming the control and its limit, instead of a verdict."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    rbstab_cli = Path(sys.executable).parent / "rbstab"
    done = subprocess.run([str(rbstab_cli), "analyze", str(root / "configs" / "examples" / "free_gravity.yaml"),
                           "--set", "controller.saturation.force_h=[1000,1000,100]", "--no-simulation"],
                          capture_output=True, text=True, cwd=root)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    (line,) = [x for x in done.stderr.splitlines() if x.startswith("Error:")]
    assert "no equilibrium" in line and "|force_h_3| = 410 N > its limit 100 N" in line, line


def test_time_with_dv_dt_positive_is_a_summary_figure():
    """Where the theorem holds (no limits) v never rises: time_lyapunov_rising is 0; where
    the saturated torque cannot hold the pendulum it is the time dv/dt > 0 on the samples."""
    import warnings

    import rbstab

    path = Path(__file__).resolve().parents[1] / "configs" / "examples" / "saturated_pendulum.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fell = rbstab.simulate(rbstab.load_config(path, ["initial_state.theta=[0.45,0,0]"]))
        paper = rbstab.simulate(rbstab.load_config(CASE2))
    rate = fell["lyapunov_rate"].values
    spacing = float(fell["time"][1] - fell["time"][0])
    assert fell.attrs["summary_time_lyapunov_rising"] == np.sum(rate > 0) * spacing > 0.5
    assert paper.attrs["summary_time_lyapunov_rising"] == 0.0


def test_saturated_time_fractions_are_summary_figures():
    """fraction_saturated_<control> is, per axis, the fraction of the samples where the
    control is flagged at its limit: for the clipped pendulum that falls, where |N_1| is
    the limit 4 N m (most of the run); 0 for the paper's case without limits."""
    import warnings

    import rbstab

    path = Path(__file__).resolve().parents[1] / "configs" / "examples" / "saturated_pendulum.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fell = rbstab.simulate(rbstab.load_config(path, ["initial_state.theta=[0.45,0,0]"]))
        paper = rbstab.simulate(rbstab.load_config(CASE2))
    at_limit = np.abs(fell["torque_n"].values) == 4.0
    fraction = fell.attrs["summary_fraction_saturated_torque_n"]
    np.testing.assert_array_equal(fraction, at_limit.mean(axis=0))
    assert fraction[0] > 0.5 and fraction[1] == fraction[2] == 0.0
    for key in ("torque_n", "force_h", "constraint_force"):
        assert list(paper.attrs[f"summary_fraction_saturated_{key}"]) == [0.0, 0.0, 0.0]


def test_analyze_names_an_actuator_saturated_at_rest():
    """A free body whose smooth |H_z| limit barely exceeds its weight rests where the
    commanded H_z is far beyond the limit: analyze notes it (the linearisation has the
    actuator's slope there) and still gives a verdict."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    rbstab_cli = Path(sys.executable).parent / "rbstab"
    done = subprocess.run([str(rbstab_cli), "analyze", str(root / "configs" / "examples" / "free_gravity.yaml"),
                           "--set", "controller.saturation={force_h: [1000, 1000, 411], shape: smooth}",
                           "--no-simulation", "--no-certificate", "--json", "-o", "out"],
                          capture_output=True, text=True, cwd=Path(__import__("tempfile").mkdtemp()))
    assert done.returncode == 0, done.stderr
    assert "at the equilibrium the actuators saturate (|force_h_3| = " in done.stdout
    assert ">= its limit 411" in done.stdout and "smooth actuator's slope" in done.stdout
