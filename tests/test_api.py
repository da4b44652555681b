"""The Python API (rbstab.api): what a notebook calls, checked against the files the CLI writes."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

import rbstab
from conftest import PAPER_CONFIGS, ROOT
from rbstab.config import ConfigError
from rbstab.io.hdf5 import NotAResultFile

CASE1, CASE2, CASE3 = PAPER_CONFIGS
SHORT = {"simulation.t_end": 0.2, "simulation.n_samples": 21}
#: Global attributes that differ between two writes of one run.
MOMENTARY = ("created", "command_line", "history", "wall_time")


def test_import_is_light_and_lists_the_api():
    code = ("import sys, rbstab; names = dir(rbstab); "
            "print(sorted(m for m in ('numpy', 'xarray', 'numba', 'scipy', 'h5py', 'pandas', 'pydantic') "
            "if m in sys.modules)); print(names)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    heavy, names = out.splitlines()
    assert heavy == "[]"
    for name in ("load_config", "simulate", "run", "open_result", "sweep_dataset", "open_sweep", "write_report",
                 "analyze"):
        assert f"'{name}'" in names, name


def test_functions_are_functions_and_modules_modules():
    """rbstab.simulate is rbstab.api.simulate; the subpackages are plain modules that keep
    their names however they are imported."""
    import inspect
    import types

    import rbstab.api as api
    import rbstab.sweep.runner as runner
    from rbstab.simulator import RunResult, solve_tree

    assert rbstab.simulate is api.simulate and inspect.isfunction(rbstab.simulate)
    assert rbstab.sweep_dataset is api.sweep_dataset and rbstab.write_report is api.write_report
    assert list(inspect.signature(rbstab.simulate).parameters)[:2] == ["config", "overrides"]
    assert list(inspect.signature(rbstab.write_report).parameters)[:2] == ["inputs", "output"]
    for module in (rbstab.simulator, rbstab.sweep, rbstab.report):
        assert type(module) is types.ModuleType and not callable(module)
    assert rbstab.simulator.solve_tree is solve_tree and rbstab.simulator.RunResult is RunResult
    assert runner.__name__ == "rbstab.sweep.runner" and rbstab.sweep.load_spec is not None
    assert type(rbstab) is types.ModuleType
    with pytest.raises(AttributeError, match="no attribute 'simulat'"):
        rbstab.simulat


def test_load_config_from_a_file_a_mapping_or_a_config():
    from_file = rbstab.load_config(CASE3, ["simulation.t_end=0.5", "initial_state.omega.0=5"])
    from_mapping_overrides = rbstab.load_config(CASE3, {"simulation.t_end": 0.5, "initial_state.omega.0": 5})
    assert from_file.resolved == from_mapping_overrides.resolved
    assert from_file.simulation.t_end == 0.5 and from_file.initial_state["body"]["omega"][0] == 5
    again = rbstab.load_config(from_file.resolved)
    assert again.resolved == from_file.resolved
    derived = rbstab.load_config(from_file, {"body.mass": 30.0})
    assert derived.chain.bodies[0].mass == 30.0 and from_file.chain.bodies[0].mass == 41.0
    unnamed = {k: v for k, v in from_file.resolved.items() if k != "name"}
    assert rbstab.load_config(unnamed).name == "run"
    assert rbstab.load_config(unnamed, name="mine").name == "mine"


def test_load_config_errors_name_the_key_and_the_value():
    with pytest.raises(ConfigError) as caught:
        rbstab.load_config(CASE1, {"body.mass": -1, "simulation.n_samples": 1})
    text = str(caught.value)
    assert "'body.mass': found -1" in text and "'simulation.n_samples': found 1" in text
    with pytest.raises(ConfigError, match="found int; expected a path, a mapping or a RunConfig"):
        rbstab.load_config(3)
    with pytest.raises(ConfigError, match="config file not found"):
        rbstab.load_config(ROOT / "no-such.yaml")


def _assert_same_content(a, b):
    """Same variables, dimensions, values and attributes (up to MOMENTARY)."""
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        assert a[name].dims == b[name].dims, name
        assert a[name].attrs == b[name].attrs, name
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert set(a.attrs) == set(b.attrs)
    for key in set(a.attrs) - set(MOMENTARY):
        np.testing.assert_array_equal(a.attrs[key], b.attrs[key], err_msg=key)


def test_simulate_gives_what_the_result_file_holds(tmp_path):
    config = rbstab.load_config(CASE3, SHORT)
    ds = rbstab.simulate(config)
    path = rbstab.run(config, tmp_path)
    assert path == tmp_path / "case3_embedded.h5"
    _assert_same_content(ds, rbstab.open_result(path))
    assert ds.sizes == {"time": 21, "axis": 3}
    assert ds.theta.dims == ("time", "axis") and ds.lyapunov.dims == ("time",)
    assert ds.lyapunov.attrs["units"] == "J" and ds.time.attrs["units"] == "s"
    assert ds.attrs["status"] == "success" and ds.attrs["name"] == "case3_embedded"
    assert "rbstab.simulate()" in ds.attrs["command_line"]
    # the terms of v add up to v: the data, not only the names, are the run's
    terms = sum(ds[k] for k in ("lyapunov_translational", "lyapunov_rotational", "lyapunov_constraint",
                                "lyapunov_gravity"))
    np.testing.assert_allclose(terms, ds.lyapunov, rtol=1e-12, atol=1e-9)


def test_simulate_a_pure_sign_law_run_keeps_its_switchings(tmp_path):
    config = rbstab.load_config(ROOT / "configs" / "examples" / "sliding.yaml",
                                {"controller.boundary_layer": 0, "simulation.t_end": 0.1, "simulation.n_samples": 11})
    ds = rbstab.simulate(config)
    assert "switching" in ds.dims and ds.switching_time.attrs["units"] == "s"
    _assert_same_content(ds, rbstab.open_result(rbstab.run(config, tmp_path)))


def test_a_failed_run_is_data():
    ds = rbstab.simulate(CASE2, {"initial_state.theta": [0, 1.5695, 0], "initial_state.omega": [0, 50, 0], **SHORT})
    assert ds.attrs["status"] == "failed" and "gimbal" in ds.attrs["message"]
    assert np.isnan(ds.lyapunov.values[-1])


def test_run_refuses_to_replace_another_configs_result(tmp_path):
    path = rbstab.run(CASE1, tmp_path, overrides=SHORT)
    before = path.read_bytes()
    assert rbstab.check_overwrite(rbstab.load_config(CASE1, SHORT), path) == "identical"
    other = {**SHORT, "initial_state.omega.0": 5}
    with pytest.raises(rbstab.ResultExistsError) as caught:
        rbstab.run(CASE1, tmp_path, overrides=other)
    assert "(initial_state.omega.0: 16.0 -> 5)" in str(caught.value)
    assert "--overwrite" in str(caught.value) and caught.value.path == path
    assert path.read_bytes() == before
    # the run limits are not part of the identity: a rerun with another max_wall_time is the same run
    assert rbstab.run(CASE1, tmp_path, overrides={**SHORT, "simulation.max_wall_time": 50}) == path
    rbstab.run(CASE1, tmp_path, overrides=other, overwrite=True)
    assert rbstab.open_result(path).omega.values[0, 0] == 5.0


def test_run_refuses_a_file_that_is_not_a_result(tmp_path):
    (tmp_path / "case1_permanent.h5").write_text("notes")
    with pytest.raises(rbstab.ResultExistsError, match="not a readable rbstab result"):
        rbstab.run(CASE1, tmp_path, overrides=SHORT)
    assert (tmp_path / "case1_permanent.h5").read_text() == "notes"


def test_open_result_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such result file"):
        rbstab.open_result(tmp_path / "missing.h5")
    (tmp_path / "x.h5").write_bytes(b"not hdf5")
    with pytest.raises(NotAResultFile, match="not an HDF5 file"):
        rbstab.open_result(tmp_path / "x.h5")


def _spec():
    return {"name": "api_sweep", "base": str(CASE3), "grid": {"body.mass": [30.0, 50.0]}}


def test_sweep_returns_the_sweep_as_a_dataset(tmp_path):
    ds = rbstab.sweep_dataset(_spec(), tmp_path, overrides=SHORT, jobs=1, grid=True)
    assert ds.sizes["mass"] == 2 and list(ds.mass.values) == [30.0, 50.0]
    assert set(ds.status.values.ravel()) == {"success"}
    assert ds.attrs["folder"] == str(tmp_path / "api_sweep")
    assert (tmp_path / "api_sweep" / "index.csv").is_file()
    again = rbstab.execute_sweep(_spec(), tmp_path, overrides=SHORT, jobs=1)  # resumed: nothing to run
    assert again.n_skipped == 2 and again.n_executed == 0


def test_sweep_option_mistakes_are_refused_before_anything_runs(tmp_path):
    with pytest.raises(ValueError, match="connect_timeout: only for executor 'dask'"):
        rbstab.execute_sweep(_spec(), tmp_path, connect_timeout=1.0)
    with pytest.raises(ValueError, match="scheduler: found 'tcp://127.0.0.1:1' with executor 'local'"):
        rbstab.execute_sweep(_spec(), tmp_path, executor="local", scheduler="tcp://127.0.0.1:1")
    from rbstab.sweep import SweepSpecError

    with pytest.raises(SweepSpecError, match="body.mass"):
        rbstab.execute_sweep({**_spec(), "grid": {"body.mass": [-1.0]}}, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_report_from_python(tmp_path):
    path = rbstab.run(CASE1, tmp_path / "runs", overrides=SHORT)
    folder = rbstab.write_report(path, tmp_path / "report", formats=("md",))
    assert (folder / "index.md").is_file() and "case1_permanent" in (folder / "summary.md").read_text()
    with pytest.raises(TypeError, match=r"unknown option colour; expected some of formats, metrics"):
        rbstab.write_report(path, tmp_path / "r2", colour="red")


def test_every_warning_code_is_documented_in_the_readme():
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Warnings"):]
    section = section[: section.index("\n## ", 1)] if "\n## " in section[1:] else section
    documented = set(re.findall(r"`(W\d{3})`", section))
    assert documented == set(rbstab.WARNING_CODES)
