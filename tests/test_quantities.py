"""The table of quantities (rbstab.layout) against what the kernels write and the files hold.

Each output's offset and size in :data:`rbstab.layout.OUTPUTS` must be the columns the
compiled ``outputs`` kernel fills with that quantity: checked by computing every output
independently (the plain-numpy model of ``reference.py`` and the paper's v) at random states of
every variant and reading it back from the columns the table names. Every variable of a
run file, and every summary figure, takes its units and long name from the table.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import paper_body, paper_gains
from reference import Model, hat, permanent_full_state_rhs, rotation
from rbstab.config import load_config
from rbstab.io.hdf5 import read_attributes, write_result
from rbstab.layout import LEFT_OUT, LYAPUNOV_TERMS, N_OUTPUTS, OUTPUTS, QUANTITIES, SUMMARY_FIGURES, VARIANT_CODES, display_units
from rbstab.simulator import simulate
from rbstab.variants import VARIANTS
from rbstab.variants.kernels import run_outputs

ROOT = Path(__file__).resolve().parents[1]
GRAVITY = (0.0, 0.0, -9.81)

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def _expected(variant, y):
    """Every output of state ``y`` by name, from the plain-numpy model of ``reference.py``
    (A, B, E, F, N, H, Lambda, dD/dt) and the paper's v and dv/dt (eqs 25, 29-46)."""
    body, g = variant.body, variant.gains
    model = Model(variant.name, body, g)
    blocks = variant.layout.split(y)
    theta, omega = blocks["theta"], blocks["omega"]
    a, r = rotation(theta), body.attachment_point
    if "position" in blocks:
        x, v = blocks["position"], blocks["velocity"]
    else:  # permanent: C fixed, X = R - A R, V = A hat(R) Omega (eq 32)
        x, v = r - a @ r, a @ hat(r) @ omega
    d = blocks.get("controller_state", np.zeros(3))
    e, f = x + a @ r - r, v - a @ hat(r) @ omega
    n, h = model.controls(theta, omega, x, v)
    if variant.name == "permanent":  # Lambda that holds C, solved from eq 15
        lam, d_rate = permanent_full_state_rhs(body, g)[1](np.concatenate([theta, omega, x, v])), np.zeros(3)
    else:
        lam, d_rate = model.constraint(e, f, d)
    stored = {"visco_elastic": 0.5 * e @ g.k_c @ e,  # eqs 41, 42
              "embedded": 0.5 * (e - d) @ g.k_c @ (e - d) + 0.5 * d @ g.k_d @ d,  # eqs 44, 45
              "sliding": g.k_s * g.boundary_layer * np.sum(np.log(np.cosh(e / g.boundary_layer)))}
    dissipated = {"visco_elastic": f @ g.l_c @ f, "embedded": f @ g.l_c @ f + d_rate @ g.l_d @ d_rate}  # eqs 43, 46
    out = {"theta": theta, "omega": omega, "position": x, "velocity": v, "controller_state": d,
           "constraint_error": e, "constraint_rate": f, "constraint_force": lam, "force_h": h, "torque_n": n,
           "lyapunov_translational": 0.5 * body.mass * v @ v + 0.5 * x @ g.k_t @ x,
           "lyapunov_rotational": 0.5 * omega @ body.inertia @ omega + 0.5 * theta @ g.k_r @ theta,
           "lyapunov_constraint": stored.get(variant.name, 0.0),
           "lyapunov_gravity": -x @ (body.mass * body.gravity) + variant.lyapunov_offset,
           "lyapunov_rate": -(v @ g.l_t @ v + omega @ g.l_r @ omega + dissipated.get(variant.name, 0.0))}
    out["lyapunov"] = sum(out[t] for t in LYAPUNOV_TERMS)
    out["disturbance_power"] = out["disturbance_work"] = out["disturbance_edges"] = 0.0  # no disturbances
    # (tests/test_disturbances.py)
    for flags in ("torque_n_saturated", "force_h_saturated", "constraint_force_saturated"):
        out[flags] = np.zeros(3)  # no limits (tests/test_saturation.py)
    return out


@pytest.mark.parametrize("name", sorted(VARIANT_CODES))
def test_each_output_is_where_the_table_says_the_kernel_writes_it(name, rng):
    variant = VARIANTS[name](paper_body(GRAVITY), paper_gains())
    states = rng.normal(scale=0.3, size=(5, variant.layout.size))
    out = np.full((N_OUTPUTS, 1, len(states)), np.nan)
    run_outputs(np.array([variant.code]), variant.parameters, np.zeros((1, states.shape[0])), states[None], out, True)
    assert np.all(np.isfinite(out)), "a column of the outputs is not written"
    for j, y in enumerate(states):
        expected = _expected(variant, y)
        assert set(expected) == set(OUTPUTS)
        for q in OUTPUTS.values():
            got = out[q.columns, 0, j].reshape(np.shape(expected[q.name]))
            scale = max(1.0, float(np.max(np.abs(expected[q.name]))))
            np.testing.assert_allclose(got, expected[q.name], rtol=1e-9, atol=1e-9 * scale, err_msg=q.name)
    lean = np.full_like(out, np.nan)
    run_outputs(np.array([variant.code]), variant.parameters, np.zeros((1, states.shape[0])), states[None], lean, False)
    left_out = np.zeros(N_OUTPUTS, dtype=bool)
    for q in LEFT_OUT:  # but a pinned body's Lambda and N, which its centre of pressure reads
        left_out[OUTPUTS[q].columns] = not (name == "permanent" and q in ("constraint_force", "torque_n"))
    assert np.all(np.isnan(lean[left_out])) and np.array_equal(lean[~left_out], out[~left_out])


def test_outputs_tile_a_row_without_gaps():
    columns = [c for q in OUTPUTS.values() for c in range(q.columns.start, q.columns.stop)]
    assert columns == list(range(N_OUTPUTS))


@pytest.mark.parametrize("config, changes", [
    ("configs/paper/case3_embedded.yaml", []),
    ("configs/examples/sliding.yaml", ["controller.boundary_layer=0"]),
])
def test_stored_variables_and_summary_figures_take_units_and_names_from_the_table(config, changes, tmp_path):
    result = simulate(load_config(ROOT / config, ["simulation.t_end=0.1", "simulation.n_samples=101", *changes]))
    path = write_result(result, tmp_path / "run.h5", command_line="rbstab run x.yaml")
    with h5py.File(path, "r") as f:
        assert set(f) <= set(QUANTITIES)
        for name, var in f.items():
            attrs = {k: v.decode() if isinstance(v, bytes) else v for k, v in var.attrs.items()}
            q = QUANTITIES[name]
            assert attrs.get("units") == q.units, name
            assert (attrs["long_name"], attrs["description"]) == (q.long_name, q.description), name
    units = json.loads(read_attributes(path)["units_of_summary"])
    assert set(units) <= set(SUMMARY_FIGURES)
    assert units == {name: SUMMARY_FIGURES[name].units or "" for name in units}


@pytest.mark.parametrize("cf, shown", [("rad s-1", "rad/s"), ("s-1", "1/s"), ("N s-1", "N/s"), ("N m", "N m"),
                                       ("1", "1"), ("J", "J"), (None, "")])
def test_display_units_put_negative_powers_under_a_slash(cf, shown):
    assert display_units(cf) == shown
