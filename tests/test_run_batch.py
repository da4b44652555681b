"""A table of runs as one batch of arrays (:func:`rbstab.engine.batch_from_table`): its
parameter records, initial states and settings are, bit for bit, those each run's
validated configuration gives, for every variant; and the sweep's columnar worker path
writes the same values as the per-run path."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from rbstab.variants.paper import paper_form, paper_initial_state
from rbstab.config import config_from_mapping
from rbstab.engine import METHODS, RunBatch, batch_from_table
from rbstab.engine.batch import MAX_STATE, NOT_COMPILED
from rbstab.layout import VARIANT_CODES
from rbstab.engine.settings import settings_rows
from rbstab.simulator import is_sign_law, uses_compiled_engine
from rbstab.sweep import SweepSpecError, plan_table, spec_from_mapping

ROOT = Path(__file__).resolve().parents[1]
BASES = [ROOT / "configs" / "paper" / f"{name}.yaml" for name in ("case1_permanent", "case2_visco_elastic",
                                                                   "case3_embedded")]
BASES += [ROOT / "configs" / "examples" / f"{name}.yaml" for name in ("sliding", "free_gravity")]


def _design(n: int, seed: int) -> dict:
    """Random values of keys every base takes (a zip): whole matrices, entries, vectors,
    settings."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, 3, 3)) * 0.3
    inertia = np.einsum("nij,nkj->nik", a, a) + np.diag([10.0, 8.0, 4.0])  # SPD, not diagonal
    return {
        "body.mass": rng.uniform(20, 60, n).tolist(),
        "body.inertia": inertia.tolist(),
        "body.attachment_point.2": rng.uniform(-0.5, -0.3, n).tolist(),
        "body.gravity.2": rng.choice([0.0, -9.81, -10.0], n).tolist(),
        "controller.k_t.1": rng.uniform(3000, 5000, n).tolist(),
        "controller.l_r": rng.uniform(40, 80, (n, 3)).tolist(),
        "initial_state.omega": rng.normal([16, 32, -16], 4, (n, 3)).tolist(),
        "initial_state.theta.0": rng.uniform(-0.5, 0.5, n).tolist(),
        "simulation.rtol": rng.choice([1e-6, 1e-8], n).tolist(),
    }


def _expected(resolved: dict):
    """(record, initial state, settings row, compiled) of a run through its validated config."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = config_from_mapping(resolved)
    variant = paper_form(config)
    return (variant.parameters[0], paper_initial_state(config, variant), settings_rows([config.simulation])[0],
            uses_compiled_engine(config) and not is_sign_law(config), config)


def _check(table, rows, timeout=None) -> RunBatch:
    part = table.slice(rows)
    batch = part.batch(timeout)
    assert isinstance(batch, RunBatch) and len(batch) == len(rows)
    for j in range(len(rows)):
        record, y0, settings, compiled, config = _expected(part.resolved(j))
        assert batch.params[j, 0].tobytes() == record.tobytes(), f"run {j}: {config.chain.joints[0].variant}"
        assert batch.offset[j] == record["lyapunov_offset"] and batch.one_body[j]
        assert batch.codes[j] == VARIANT_CODES[config.chain.joints[0].variant] and batch.ppoints[j, 0].tobytes() == record["attachment_point"].tobytes()
        size = len(y0)
        assert batch.n_state[j] == size and batch.y0[j, :size].tobytes() == y0.tobytes()
        assert not batch.y0[j, size:].any() and batch.y0.shape[1] == MAX_STATE
        expected = settings.copy()
        if timeout is not None:
            expected[6] = timeout
        assert batch.settings_rows([j])[0].tobytes() == expected.tobytes()
        assert batch.compiled[j] == compiled
        method = config.simulation.method
        assert batch.settings["method"][j] == (METHODS.index(method) if method in METHODS else NOT_COMPILED)
        assert batch.n_samples[j] == config.simulation.n_samples
    return batch


@pytest.mark.parametrize("seed", [0, 1])
def test_batch_records_are_those_of_each_runs_config(seed):
    n = 6
    spec = spec_from_mapping({"name": "b", "base": [str(b) for b in BASES], "zip": _design(n, seed)})
    table = plan_table(spec)
    assert set(table.variant) == {"permanent", "visco_elastic", "embedded", "sliding", "free"}
    rng = np.random.default_rng(seed)
    _check(table, np.sort(rng.choice(table.n, size=20, replace=False)))
    _check(table, np.arange(0, table.n, 3), timeout=5.0)


def test_batch_of_grid_scale_entries_and_other_methods():
    """scale_uniform of whole gains, grid keys of entries, a sign-law base and methods the
    compiled engine does not have (not compiled)."""
    sign_law = yaml.safe_load(BASES[3].read_text())
    sign_law["name"], sign_law["controller"]["boundary_layer"] = "sign_law", 0.0
    spec = spec_from_mapping({
        "name": "g", "base": [str(BASES[2]), str(BASES[3]), sign_law],
        "grid": {"simulation.method": ["DOP853", "RK45", "Radau"], "controller.k_r.2": [300, 350.5]},
        "random": {"n": 3, "seed": 4, "params": {"controller.k_t": {"scale_uniform": [0.7, 1.4]},
                                                 "initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}},
    })
    table = plan_table(spec)
    batch = _check(table, np.arange(table.n))
    assert batch.compiled.sum() < table.n and batch.compiled.any()


def test_empty_batch():
    spec = spec_from_mapping({"name": "e", "base": str(BASES[2]), "grid": {"body.mass": [30.0, 40.0]}})
    batch = plan_table(spec).slice(np.arange(0)).batch()
    assert len(batch) == 0 and batch.y0.shape == (0, MAX_STATE)


def test_worker_batch_path_writes_what_the_per_run_path_writes(tmp_path, monkeypatch):
    """A slice with batch runs and runs that go alone (Radau, the pure sign law): the index
    rows and the store file's variables are those of the per-run path, bit for bit."""
    import xarray as xr

    import rbstab.sweep.worker as worker

    sign_law = yaml.safe_load(BASES[3].read_text())
    sign_law["name"], sign_law["controller"]["boundary_layer"] = "sign_law", 0.0
    spec = spec_from_mapping({
        "name": "w", "base": [str(BASES[0]), str(BASES[2]), str(BASES[4]), sign_law],
        "grid": {"simulation.method": ["DOP853", "RK23", "Radau"]},
        "random": {"n": 2, "seed": 5, "params": {"body.mass": {"scale_uniform": [0.8, 1.2]}}},
    }, overrides=["simulation.t_end=0.05", "simulation.n_samples=51"])
    table = plan_table(spec)
    part = table.slice(np.arange(table.n))
    assert 0 < part.batch().compiled.sum() < table.n
    found = {}
    for path in ("batch", "per-run"):
        if path == "per-run":
            monkeypatch.setattr(worker, "_table_batch", lambda part, options: None)
        folder = tmp_path / path
        folder.mkdir()
        options = worker.WorkerOptions(engine="compiled", store="full", layout="chunk",
                                       parameters=table.parameters(), sweep="w")
        result = worker.run_table_chunk(part, options, str(folder))
        (store,) = folder.glob("chunk-*.h5")
        with xr.open_dataset(store, engine="h5netcdf") as ds:
            found[path] = (result.frame.drop(columns=["wall_time", "created", "file"]).sort_values("run_id")
                           .reset_index(drop=True), ds.drop_vars("wall_time").load())
    (frame_a, ds_a), (frame_b, ds_b) = found["batch"], found["per-run"]
    assert (frame_a["status"] == "success").all()
    import pandas as pd

    pd.testing.assert_frame_equal(frame_a, frame_b, check_exact=True)
    xr.testing.assert_identical(ds_a.drop_attrs(), ds_b.drop_attrs())


def test_batch_of_saturated_runs():
    """The actuators' limits as columns: a limit for every axis, one entry of it, a whole
    vector, and templates with and without limits (and the smooth shape): each run's record
    is its config's, limits included."""
    saturated = yaml.safe_load(BASES[2].read_text())  # Case 3 with limits written as one number
    saturated["name"] = "limited"
    saturated["controller"]["saturation"] = {"torque_n": 120.0, "constraint_force": [2500.0, 2000.0, 3000.0],
                                             "shape": "smooth"}
    spec = spec_from_mapping({
        "name": "s", "base": [str(BASES[1]), saturated],
        "zip": {"controller.saturation.force_h": [[800.0, 700.0, 600.0], [900.0, 900.0, 900.0]]},
    })
    table = plan_table(spec)
    batch = _check(table, np.arange(table.n))
    assert batch.params["saturation"][:, 0].tolist() == [1.0, 1.0, 2.0, 2.0]
    np.testing.assert_array_equal(batch.params["constraint_force_limit"][0, 0], [np.inf] * 3)
    np.testing.assert_array_equal(batch.params["force_limit"][3, 0], [900.0] * 3)
    entry = spec_from_mapping({"name": "e", "base": saturated, "grid": {"controller.saturation.torque_n.1": [80.0, 90.0],
                                                                        "controller.saturation.force_h": [50.0]}})
    batch = _check(plan_table(entry), np.arange(2))
    np.testing.assert_array_equal(batch.params["torque_limit"][1, 0], [120.0, 90.0, 120.0])
    np.testing.assert_array_equal(batch.params["force_limit"][1, 0], [50.0] * 3)
    unlimited_entry = spec_from_mapping({"name": "u", "base": str(BASES[1]),
                                         "grid": {"controller.saturation.torque_n.1": [80.0]}})
    with pytest.raises(SweepSpecError, match="controller.saturation.torque_n' is not set"):
        plan_table(unlimited_entry)


def test_batch_of_limits_and_pushes_varied_where_the_template_has_none():
    """The one-body keys that move to the body (K_t, the limit of H) or to both ends of the
    joint (R) in its one-body tree, limits the template leaves unlimited, a push's value,
    on a pinned body and on a visco-elastic one: each run's record, bit for bit its
    validated configuration's."""
    push = yaml.safe_load((ROOT / "configs" / "examples" / "saturated_push.yaml").read_text())
    held = yaml.safe_load(BASES[1].read_text())
    held["name"] = "held"
    held["controller"]["saturation"] = {"torque_n": 300.0, "constraint_force": [900.0, 900.0, 800.0]}
    held["disturbances"] = push["disturbances"][:1]
    spec = spec_from_mapping({
        "name": "s", "base": [push, held],
        "zip": {"controller.saturation.force_h": [[30.0, 40.0, 50.0], [5.0, 6.0, 7.0], [1e3, 1e3, 1e3]],
                "controller.saturation.torque_n.0": [2.0, 3.0, 5.0],
                "controller.k_t.2": [10.0, 20.0, 30.0],
                "body.attachment_point": [[0.0, 0.0, -0.3], [0.01, 0.02, -0.4], [0.0, 0.1, -0.2]],
                "disturbances.0.value.0": [0.5, 0.8, 1.2]},
    })
    table = plan_table(spec)
    batch = _check(table, np.arange(table.n))
    assert set(batch.params["force_limit"][:, 0, 1]) == {40.0, 6.0, 1e3}
    assert set(batch.params["disturbance_value"][:, 0, 0, 0]) == {0.5, 0.8, 1.2}
