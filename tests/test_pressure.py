"""The net centre of pressure of a tree's joints to the ground and its summary figure
``cop_excursion``: two formulations of the ground's wrench agree (the tree's momentum
balance, :func:`rbstab.variants.tree.tree_reactions`, and one pinned body's eq 20,
:func:`rbstab.variants.kernels.body_pressure`), two feet's net point is their normal-force
weighted mean, and the figure is its definition, for both spellings of one body."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import rbstab
from rbstab.config import config_from_mapping
from rbstab.layout import summary_stride
from rbstab.simulator import simulate

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "configs" / "paper" / "case1_permanent.yaml"


def _load(path, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # case 1's inertia: the paper's, implausible
        return rbstab.load_config(path, list(overrides))


def _excursion(points: np.ndarray, stride: int) -> float:
    """The largest distance of ``points`` (m, 3) at every ``stride``-th from the first."""
    return float(np.linalg.norm(points[::stride] - points[0], axis=1).max())


def _one_body_tree(omega, gravity=(0.0, 0.0, -10.0)):
    """Case 1's body and gains written as a one-body tree (``bodies``/``joints``), 201 samples."""
    return config_from_mapping({
        "name": "case1_tree", "gravity": list(gravity),
        "bodies": [{"name": "b", "mass": 41.0, "inertia": [10.0, 8.0, 6.0], "k_t": [4100, 4100, 3280],
                    "l_t": [210, 210, 140]}],
        "joints": [{"name": "ankle", "parent": "ground", "child": "b", "parent_point": [0.15, 0.10, -0.42],
                    "child_point": [0.15, 0.10, -0.42], "variant": "permanent", "k_r": [400, 400, 320],
                    "l_r": [60, 60, 42]}],
        "initial_state": {"b": {"omega": list(omega)}},
        "simulation": {"t_end": 2.0, "n_samples": 201, "method": "DOP853", "rtol": 1e-9, "atol": 1e-11}})


def test_one_pinned_body_has_the_same_centre_of_pressure_from_eq_20_and_from_its_momentum():
    """A body pinned at C written as a tree: its net centre of pressure, from eq 20's Lambda
    and the feedback torque A N about C (the paper's one body's outputs), is its joint's
    centre of pressure from the tree's momentum balance (the ground's moment from the
    body's accelerations) to 1e-12 m; the one-body spelling's summary figure is the tree's,
    bit for bit, and the largest distance of the trace from its start at a thinned store's
    samples."""
    tree = simulate(_one_body_tree([0.5, 1.0, -0.5]))
    net, joint = tree.outputs["net_centre_of_pressure"], tree.outputs["centre_of_pressure"][:, 0]
    assert np.all(np.isfinite(net))
    np.testing.assert_allclose(net, joint, rtol=0, atol=1e-12)
    assert abs(net[:, 2]).max() < 1e-12  # on the ground plane through the origin
    assert np.ptp(net[:, 0]) > 0.05  # it moves
    body = simulate(_load(CASE1, ["body.inertia=[10, 8, 6]", "initial_state.omega=[0.5, 1.0, -0.5]",
                                  "simulation.n_samples=201", "simulation.rtol=1e-9", "simulation.atol=1e-11"]))
    assert "net_centre_of_pressure" not in body.outputs  # one body's file format
    assert body.summary["cop_excursion"] == tree.summary["cop_excursion"]
    assert tree.summary["cop_excursion"] == pytest.approx(_excursion(net, summary_stride(201)), rel=1e-13)


def test_two_feet_have_the_normal_force_weighted_centre_of_pressure():
    """Two inverted pendulums on the ground (a hinge foot and a ball foot, apart, tilted,
    under a tilted gravity): the net centre of pressure of their summed wrenches is
    sum N_r P_r / sum N_r of the joints' own centres of pressure P_r and normal forces
    N_r = n . Lambda_r (a force plate under both feet), to 1e-12 m; the summary figure is
    its largest distance from its start at every stride-th sample, whatever the samples
    between (a summary-only run takes the net point at those alone)."""
    gravity = np.array([0.4, -0.3, -9.81])
    rod = {"mass": 5.0, "inertia": [0.4, 0.4, 0.02]}
    config = config_from_mapping({
        "name": "two_feet", "gravity": gravity.tolist(),
        "bodies": [{"name": "left", **rod}, {"name": "right", **rod}],
        "joints": [{"name": "left_ankle", "parent": "ground", "child": "left", "parent_point": [0.0, 0.1, 0.0],
                    "child_point": [0.0, 0.0, -0.5], "variant": "hinge", "axis": [1.0, 0.2, 0.0], "k_r": 120.0,
                    "l_r": 8.0},
                   {"name": "right_ankle", "parent": "ground", "child": "right", "parent_point": [0.05, -0.1, 0.02],
                    "child_point": [0.0, 0.0, -0.5], "variant": "ball", "k_r": [120.0, 120.0, 20.0],
                    "l_r": [8.0, 8.0, 1.0]}],
        "initial_state": {"left": {"q": 0.1, "u": -0.5}, "right": {"omega": [0.3, -0.6, 0.2]}},
        "simulation": {"t_end": 1.5, "n_samples": 501, "method": "DOP853", "rtol": 1e-10, "atol": 1e-12}})
    result = simulate(config)
    net, each = result.outputs["net_centre_of_pressure"], result.outputs["centre_of_pressure"]
    up = -gravity / np.linalg.norm(gravity)
    normal = result.outputs["constraint_force"] @ up  # (m, 2)
    assert np.all(normal > 0) and np.all(np.isfinite(each))
    weighted = np.einsum("mj,mjc->mc", normal, each) / normal.sum(axis=1)[:, None]
    np.testing.assert_allclose(net, weighted, rtol=0, atol=1e-12)
    assert abs(net @ up).max() < 1e-12
    stride = summary_stride(501)
    assert stride > 1
    assert result.summary["cop_excursion"] == pytest.approx(_excursion(net, stride), rel=1e-13)
    assert result.summary["cop_excursion"] == pytest.approx(_excursion(net, 1), rel=1e-3)  # the samples between
    brief = next(iter(rbstab.simulator.simulate_blocks([config], keep="none", full=False)))[1]
    assert brief.summaries["cop_excursion"][0] == result.summary["cop_excursion"]


@pytest.mark.parametrize("case", ["no gravity", "free body", "ground pulls"])
def test_without_a_centre_of_pressure_the_figure_is_nan(case):
    """No gravity (no ground plane), a body held by a point law (no joint the ground
    holds), and case 1's spin, whose centrifugal pull lifts the body off the ground
    (n . Lambda < 0 at a sample): the figure is NaN, not a distance."""
    if case == "no gravity":
        config = _one_body_tree([0.5, 1.0, -0.5], gravity=(0.0, 0.0, 0.0))
    elif case == "free body":
        config = _load(ROOT / "configs" / "paper" / "case2_visco_elastic.yaml", ["simulation.n_samples=201"])
    else:
        config = _load(CASE1, ["simulation.n_samples=201"])
    result = simulate(config)
    assert np.isnan(result.summary["cop_excursion"])
    assert np.isfinite(result.summary["lyapunov_final"])
    if case == "ground pulls":
        lam = result.outputs["constraint_force"][:: summary_stride(201)]
        assert np.min(lam[:, 2]) < 0 < np.max(lam[:, 2])  # up along -g: pushes, then pulls
