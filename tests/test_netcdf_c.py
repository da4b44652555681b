"""netCDF-C reads every file rbstab writes: run files (one body's and a tree's; a tree's
file written before is read by rbstab as before), sweep store files (``runs/chunk-*.h5``, one body's and a tree's), analysis files (one body's and
a tree's with the push, basin and basin stability parts, a sweep's robustness, a spec's
recovery curves) and the files of studies (``sensitivity.nc``, ``tuning.nc``).

The files are written through h5py and h5netcdf; they are meant to be netCDF-4, which the
netCDF-C library (that of ``ncdump``, NCO, CDO, R's ncdf4, Julia's NCDatasets, ...) reads.
netCDF-C is reached here through its Python binding ``netCDF4`` (whose wheels bundle
libnetcdf): every variable with the dimensions, attributes and values that h5py and
h5netcdf read, the Fletcher-32 checksums honoured, and xarray's ``netcdf4`` engine giving
the same Dataset as its ``h5netcdf`` engine. Where a file says ``Conventions = "CF-..."``,
its ``units`` are UDUNITS strings and text has none. The ``ncdump`` binary is used when on PATH.
"""

from __future__ import annotations

import copy
import json
import re
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

try:  # any ImportError: not installed, or a wheel whose libnetcdf does not load
    import netCDF4
except ImportError as exc:
    pytest.skip(f"netCDF4 (the Python binding of netCDF-C) cannot be imported ({exc}): pip install -e '.[test]'",
                allow_module_level=True)

from rbstab.config import load_config  # noqa: E402
from rbstab.config.loader import config_from_mapping  # noqa: E402
from rbstab.config.yaml_io import read_yaml_file  # noqa: E402
from rbstab.io.chunk import ChunkWriter, StoreRow  # noqa: E402
from rbstab.io.hdf5 import read_attributes, read_dataset, read_summary, result_dataset, write_result  # noqa: E402
from rbstab.results import plain  # noqa: E402
from rbstab.simulator import simulate  # noqa: E402
from rbstab.sweep import run_sweep, spec_from_mapping  # noqa: E402
from rbstab_cli.main import cli  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
SLIDING = ROOT / "configs" / "examples" / "sliding.yaml"
SHORT = ["simulation.t_end=0.2", "simulation.n_samples=201"]
#: HDF5 bookkeeping of dimension scales and netCDF-C's own attributes, which netCDF-C
#: does not show as attributes.
HIDDEN = {"CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "_Netcdf4Dimid", "_Netcdf4Coordinates",
          "_NCProperties"}

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def _plain(value):
    """An attribute or element as a comparable Python value (text as str)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray) and value.dtype.kind in "OSU":
        return [_plain(x) for x in value.ravel().tolist()]
    return value


def _same(a, b) -> bool:
    a, b = _plain(a), _plain(b)
    if isinstance(a, (str, list)) or isinstance(b, (str, list)):
        return a == b
    # netCDF attributes are 1-D: a scalar written by h5py reads as itself or as one element
    return np.array_equal(np.atleast_1d(a), np.atleast_1d(b), equal_nan=True)


def _dimension_only(ds) -> bool:
    """Whether a dataset is a netCDF dimension that has no variable (netCDF-C's mark)."""
    return ds.is_scale and str(_plain(ds.attrs.get("NAME", b""))).startswith("This is a netCDF dimension but not")


def _h5_attrs(obj) -> dict:
    return {k: obj.attrs[k] for k in obj.attrs if k not in HIDDEN}


def assert_netcdf_c_reads(path: Path, *, attribute_order: bool = True, checksums: bool = True) -> None:
    """netCDF-C opens ``path`` as netCDF-4 and reads every variable as h5py does: on the
    dimensions of the HDF5 dimension scales attached to it, with the same shapes, types,
    attributes and values (NaN where NaN), text as str, Fletcher-32 on every non-empty
    numeric variable (``checksums``: the files of runs and stores have them); xarray's
    ``netcdf4`` engine gives the Dataset its ``h5netcdf`` engine gives. rbstab's files are
    flat: no groups (a file with one would need each group compared too). ``attribute_order``:
    also the order the attributes were written in (netCDF-C numbers them by HDF5's creation
    order, which only a dataset made with ``track_order`` keeps)."""
    import xarray as xr

    with h5py.File(path, "r") as h5, netCDF4.Dataset(path) as nc:
        assert not nc.groups and not any(isinstance(h5[k], h5py.Group) for k in h5), "a group: compare it too"
        nc.set_auto_mask(False)
        assert nc.data_model == "NETCDF4"
        datasets = [k for k in h5 if isinstance(h5[k], h5py.Dataset)]
        names = [k for k in datasets if not _dimension_only(h5[k])]  # a dimension without a variable is no variable
        assert sorted(nc.variables) == sorted(names)
        scales = {k: h5[k].shape[0] for k in datasets if h5[k].is_scale}
        dimids = {int(h5[k].attrs["_Netcdf4Dimid"]): k for k in scales if "_Netcdf4Dimid" in h5[k].attrs}
        assert {k: len(d) for k, d in nc.dimensions.items()} == scales
        expected = _h5_attrs(h5)
        assert list(nc.ncattrs()) == list(expected) or not attribute_order
        assert sorted(nc.ncattrs()) == sorted(expected)
        for key, value in expected.items():
            assert _same(nc.getncattr(key), value), f"global attribute {key}"
        for name in names:
            var, ds = nc.variables[name], h5[name]
            # a dimension's coordinate is its scale; any other dataset has scales attached; a
            # variable of more dimensions named as its first (an analysis file's push_direction)
            # is that dimension's scale, its dimensions in _Netcdf4Coordinates
            if ds.is_scale and ds.ndim > 1:
                dims = tuple(dimids[int(i)] for i in ds.attrs["_Netcdf4Coordinates"])
            else:
                dims = (name,) if ds.is_scale else tuple(d[0].name.rpartition("/")[2] if len(d) else
                                                         f"(no scale on axis {i})" for i, d in enumerate(ds.dims))
            assert var.dimensions == dims, name
            assert var.shape == ds.shape, name
            expected = _h5_attrs(ds)
            if attribute_order:
                assert list(var.ncattrs()) == list(expected), name
            assert sorted(var.ncattrs()) == sorted(expected), name
            for key, value in expected.items():
                assert _same(var.getncattr(key), value), f"{name}:{key}"
            if ds.dtype == np.dtype("S1") and ds.ndim == 2:  # characters (run, string): NC_CHAR, text by _Encoding
                assert var.dtype == np.dtype("S1") and var.filters()["fletcher32"], name
                text = [x.decode() for x in np.ascontiguousarray(ds[...]).view(f"S{ds.shape[1]}").ravel().tolist()]
                assert _plain(np.asarray(var[...], dtype=object)) == text, name
            elif ds.dtype.kind in "OS":  # variable-length UTF-8 text: NC_STRING
                assert var.dtype is str, name
                assert _plain(np.asarray(var[...], dtype=object)) == _plain(ds[...]), name
            else:
                assert var.dtype == ds.dtype, name
                np.testing.assert_array_equal(var[...], ds[...], err_msg=name)  # NaN equals NaN
                assert var.filters()["fletcher32"] or ds.size == 0 or not checksums, name
    with xr.open_dataset(path, engine="h5netcdf") as a, xr.open_dataset(path, engine="netcdf4") as b:
        xr.testing.assert_identical(a.load(), b.load())


# -- store files ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    """A 4-run sweep (a vector parameter on a grid x a random one) in each store, 2 files each."""
    out = tmp_path_factory.mktemp("netcdf_c")
    spec = {"name": "ncc", "base": str(CASE3),
            "grid": {"controller.k_c": [[12300, 12300, 9840], [20000, 20000, 15000]]},
            "random": {"n": 2, "seed": 3, "params": {"initial_state.omega.0": {"uniform": [10, 20]}}}}
    return {store: run_sweep(spec_from_mapping({**spec, "name": f"ncc_{store}"}, overrides=SHORT), out, jobs=1,
                             chunk_size=2, layout="chunk", store=store, progress=False)
            for store in ("thinned", "full", "summary")}


def _files(outcome) -> list[Path]:
    return sorted((outcome.directory / "runs").glob("chunk-*.h5"))


@pytest.mark.parametrize("store", ["thinned", "full", "summary"])
def test_netcdf_c_reads_each_store_file(sweeps, store):
    files = _files(sweeps[store])
    assert len(files) == 2
    index = pd.read_csv(sweeps[store].index_path)
    params = ["k_c_0", "k_c_1", "k_c_2", "omega_0"]
    for path in files:
        assert_netcdf_c_reads(path)
        with netCDF4.Dataset(path) as nc:
            n = len(nc.dimensions["run"])
            sizes = {"run": n, "axis": 3, **({} if store == "summary" else {"time": 201})}
            # and the text's character dimensions, string<width>
            assert {k: len(d) for k, d in nc.dimensions.items() if not k.startswith("string")} == sizes
            assert all(len(d) == int(k[len("string"):]) for k, d in nc.dimensions.items() if k.startswith("string"))
            assert not any(d.isunlimited() for d in nc.dimensions.values())
            assert nc.getncattr("store") == store and nc.getncattr("rbstab_format") == "rbstab-sweep-3"
            # the traces (h5py datasets with dimension scales attached) on their dimensions
            traces = [k for k, v in nc.variables.items() if "time" in v.dimensions and k != "time"]
            if store == "summary":
                assert not traces
            else:
                assert nc["theta"].dimensions == ("run", "time", "axis")
                assert nc["lyapunov"].dimensions == ("run", "time")
                assert ("constraint_force" in traces) == (store == "full")
                assert nc["lyapunov"].ncattrs() == ["units", "long_name", "description", "coordinates"]
                assert nc["lyapunov"].units == "J" and nc["time"].units == "s"
                assert nc["time"][-1] == pytest.approx(0.2)
                assert np.isfinite(nc["theta"][...]).all()
            # per-run variables and coordinates, with units and long_name
            for name in (*params, "template", "lyapunov_final", "final_omega_x", "solver_nfev"):
                assert nc[name].dimensions == ("run",), name
            for name in ("run_id", "base", "variant", "status", "message"):  # text: characters
                assert nc[name].dimensions[0] == "run" and nc[name].dimensions[1].startswith("string"), name
            assert nc["run"].dtype == np.int64
            assert nc["lyapunov_final"].units == "J" and nc["lyapunov_final"].long_name == "v(t_end)"
            assert nc["final_omega_x"].units == "rad s-1"
            assert nc["final_omega_x"].long_name.endswith(", x component")
            assert nc["k_c_0"].config_key == "controller.k_c.0"
            for name in ("lyapunov_final", "status", *(traces[:1])):
                assert set(nc[name].coordinates.split()) == {"run_id", "base", "variant", *params}
            # the values index.csv holds for the same runs; text readable
            rows = index.set_index("run_id").loc[list(nc["run_id"][...])]
            assert list(nc["run"][...]) == list(rows["run"])
            assert list(nc["status"][...]) == ["success"] * n
            for name in ("lyapunov_final", "k_c_0", "omega_0", "solver_nfev"):
                np.testing.assert_allclose(nc[name][...], rows[name].to_numpy(), rtol=1e-12, err_msg=name)
            # the configurations once, as an attribute: the same text as h5py reads
            with h5py.File(path, "r") as h5:
                templates = json.loads(nc.getncattr("run_templates"))
                assert templates == json.loads(h5.attrs["run_templates"])
            assert templates[int(nc["template"][0])]["controller"]["variant"] == "embedded"


def test_xarray_netcdf4_engine_combines_the_store_files(sweeps):
    import xarray as xr

    out = sweeps["thinned"]
    index = pd.read_csv(out.index_path)
    with xr.open_mfdataset(_files(out), engine="netcdf4") as ds:  # default arguments
        assert list(ds["run"].values) == [0, 1, 2, 3]
        assert {"run_id", "k_c_0", "omega_0"} <= set(ds.coords)
        assert ds["lyapunov"].dims == ("run", "time")
        assert list(ds["run_id"].values) == list(index["run_id"])
        np.testing.assert_array_equal(ds["lyapunov_final"].values, index["lyapunov_final"].to_numpy())


def test_netcdf_c_reads_failed_and_error_rows_and_non_ascii_text(tmp_path):
    ok = simulate(load_config(CASE3, SHORT))
    locked = simulate(load_config(CASE3, [*SHORT, "initial_state.theta=[0, 1.5, 0]", "initial_state.omega=[0, 30, 0]"]))
    assert (ok.status, locked.status) == ("success", "failed")
    rows = [StoreRow(i, f"r000{i}-x", "Fall β", {"omega_1": w}) for i, w in enumerate([32.0, 30.0, 31.0])]
    message = "ConfigError: Ω ≠ 0 — «bad»"
    path = tmp_path / "chunk-r0000-x-0.h5"
    with ChunkWriter(path, rows, store="full", parameters={"omega_1": "initial_state.omega.1"},
                     sweep="démo Ω") as writer:
        writer.add("r0000-x", ok)
        writer.add_error("r0002-x", message)
        writer.add("r0001-x", locked)
    assert_netcdf_c_reads(path)
    with netCDF4.Dataset(path) as nc:
        assert nc.getncattr("sweep") == "démo Ω"
        assert list(nc["base"][...]) == ["Fall β"] * 3
        assert list(nc["status"][...]) == ["success", "failed", "error"]
        messages = list(nc["message"][...])
        assert messages[2] == message and messages[1].startswith("gimbal lock")
        assert list(nc["omega_1"][...]) == [32.0, 30.0, 31.0]
        v = np.ma.filled(nc["lyapunov"][...], np.nan)
        assert np.isfinite(v[0]).all() and np.isnan(v[2]).all()  # the error row holds no data
        assert np.isfinite(v[1, 0]) and np.isnan(v[1, -1])  # NaN after the failed run's last sample
        assert np.isnan(nc["lyapunov_final"][2])


def test_netcdf_c_refuses_a_damaged_chunk(sweeps, tmp_path):
    """Fletcher-32 is checked by netCDF-C too: a changed byte in a trace or a per-run
    value raises instead of reading wrong numbers."""
    for name in ("lyapunov", "lyapunov_final"):
        path = tmp_path / f"{name}.h5"
        shutil.copyfile(_files(sweeps["thinned"])[0], path)
        with h5py.File(path, "r") as h5:
            where = h5[name].id.get_chunk_info(0)
        with open(path, "r+b") as f:
            f.seek(where.byte_offset + where.size // 2)
            byte = f.read(1)[0]
            f.seek(-1, 1)
            f.write(bytes([byte ^ 0xFF]))
        with netCDF4.Dataset(path) as nc:
            nc["theta"][...]  # untouched variables still read
            with pytest.raises(RuntimeError, match="HDF error"):
                nc[name][...]


# -- run files ------------------------------------------------------------------------------------


@pytest.mark.parametrize("store", ["full", "thinned", "summary"])
def test_netcdf_c_reads_a_run_file(tmp_path, store):
    result = simulate(load_config(CASE3, SHORT))
    path = write_result(result, tmp_path / "case3.h5", store=store)
    # run files are written without attribute creation order: netCDF-C lists a variable's
    # attributes in HDF5's own order (the values are the same)
    assert_netcdf_c_reads(path, attribute_order=False)
    with netCDF4.Dataset(path) as nc:
        assert nc.getncattr("status") == "success" and nc.getncattr("variant") == "embedded"
        np.testing.assert_array_equal(nc.getncattr("summary_final_omega"), result.summary["final_omega"])
        if store == "summary":  # a dimension of length 0 is netCDF's unlimited dimension
            assert len(nc.dimensions["time"]) == 0 and "theta" not in nc.variables
            return
        assert {k: len(d) for k, d in nc.dimensions.items()} == {"time": 201, "axis": 3}
        assert nc["theta"].dimensions == ("time", "axis") and nc["lyapunov"].dimensions == ("time",)
        assert nc["lyapunov"].units == "J" and nc["time"].units == "s"
        assert list(nc["axis"][...]) == ["x", "y", "z"]
        np.testing.assert_array_equal(nc["lyapunov"][...], result.outputs["lyapunov"])
        np.testing.assert_array_equal(nc["omega"][...], result.outputs["omega"])


def test_netcdf_c_reads_a_sign_law_run_file_with_its_switchings(tmp_path):
    result = simulate(load_config(SLIDING, ["controller.boundary_layer=0", "simulation.t_end=0.1",
                                            "simulation.n_samples=101"]))
    assert len(result.switching.time) >= 1
    path = write_result(result, tmp_path / "sliding.h5")
    assert_netcdf_c_reads(path, attribute_order=False)
    with netCDF4.Dataset(path) as nc:
        assert len(nc.dimensions["switching"]) == len(result.switching.time)
        assert nc["switching_time"].dimensions == ("switching",) and nc["switching_time"].units == "s"
        assert nc["sliding_mode"].dimensions == ("time", "axis")
        np.testing.assert_array_equal(nc["switching_time"][...], result.switching.time)


# -- a tree's run files ----------------------------------------------------------------------------

EXAMPLES = ROOT / "configs" / "examples"
#: A tree's run kept short.
TREE_SHORT = {"t_end": 0.2, "n_samples": 21}
#: A tree's run file written before its per-body and per-joint summary figures were stored
#: flattened (as 2-D attributes, which netCDF-C does not open): configs/examples/stance_ankle_hip.yaml
#: with simulation.t_end=0.1 and n_samples=11.
OLD_CHAIN_RUN = Path(__file__).resolve().parent / "data" / "chain_run_file_e43b44e.h5"


def _example(name: str) -> dict:
    return read_yaml_file(EXAMPLES / f"{name}.yaml")


def _trees() -> dict[str, dict]:
    """Trees of each kind, as mappings: two bodies with saturated joint torques (the stance),
    an embedded joint (the knee), one body in the bodies/joints spelling, three bodies
    pushed by disturbances."""
    stance = _example("stance_ankle")
    one = {"name": "one_tree", "gravity": stance["body"]["gravity"],
           "bodies": [{"name": "body", "mass": stance["body"]["mass"], "inertia": stance["body"]["inertia"]}],
           "joints": [{"name": "ankle", "parent": "ground", "parent_point": [0.0, 0.0, 0.0], "child": "body",
                       "child_point": stance["body"]["attachment_point"], "variant": "permanent",
                       "k_r": stance["controller"]["k_r"], "l_r": stance["controller"]["l_r"]}],
           "initial_state": {"body": {"theta": stance["initial_state"]["theta"]}}}
    three = copy.deepcopy(_example("double_pendulum"))
    three["name"] = "three_pushed"
    three["bodies"].append({"name": "hand", "mass": 0.5, "inertia": [0.01, 0.01, 0.001]})
    three["joints"].append({"name": "wrist", "parent": "lower", "parent_point": [0.0, 0.0, -0.5], "child": "hand",
                            "child_point": [0.0, 0.0, 0.1], "variant": "permanent", "k_r": [1, 1, 1],
                            "l_r": [0.1, 0.1, 0.1]})
    three["initial_state"]["hand"] = {"theta": [0.2, 0.0, 0.0]}
    three["disturbances"] = [
        {"kind": "impulse", "quantity": "torque", "value": [0, 0.5, 0], "start": 0.05, "body": "hand"},
        {"kind": "step", "value": [1, 0, 0], "start": 0.1, "body": "upper", "point": [0, 0, 0.1]}]
    trees = {"saturated": _example("stance_ankle_hip"), "embedded": _example("knee"), "one_body": one,
             "three_pushed": three}
    for tree in trees.values():
        tree["simulation"] = {**tree.get("simulation", {}), **TREE_SHORT}
    return trees


@pytest.fixture(scope="module")
def tree_runs():
    return {name: simulate(config_from_mapping(tree)) for name, tree in _trees().items()}


def _equal(a, b) -> bool:
    """Summary figures equal, NaN where NaN, a list as its array."""
    try:
        np.testing.assert_equal(a, b)
    except AssertionError:
        return False
    return True


@pytest.mark.parametrize("store", ["full", "thinned", "summary"])
@pytest.mark.parametrize("tree", ["saturated", "embedded", "one_body", "three_pushed"])
def test_netcdf_c_reads_a_chain_run_file(tree_runs, tree, store, tmp_path):
    """A tree's run file is netCDF-4: its figures per body or joint (n_members, 3) are 1-D
    attributes with their shapes in shape_of_summary, and read back in their shape."""
    result = tree_runs[tree]
    assert result.status == "success", result.message
    chain = result.config.chain
    path = write_result(result, tmp_path / f"{tree}.h5", store=store)
    assert_netcdf_c_reads(path, attribute_order=False)
    with netCDF4.Dataset(path) as nc:
        assert nc.getncattr("rbstab_format") == "rbstab-chain-run-1"
        assert {k: len(nc.dimensions[k]) for k in ("body", "joint")} == {"body": chain.size,
                                                                         "joint": len(chain.joint_names)}
        shapes = json.loads(nc.getncattr("shape_of_summary"))
        assert shapes["final_theta"] == [chain.size, 3]
        assert shapes["max_abs_constraint_error"] == [len(chain.joint_names), 3]
        assert set(shapes) == {k for k, v in result.summary.items() if np.ndim(v) == 2}
        for key, shape in shapes.items():
            np.testing.assert_array_equal(np.reshape(nc.getncattr(f"summary_{key}"), shape), result.summary[key])
    # as rbstab reads it: the run's figures in their shape, the attributes of the run in memory
    assert _equal(read_summary(path)["summary"], plain(result.summary))
    attrs = read_attributes(path)
    assert "shape_of_summary" not in attrs and _equal(attrs["summary_final_theta"], result.summary["final_theta"])
    if store == "full":
        ds, memory = read_dataset(path), result_dataset(result)
        assert set(ds.attrs) == set(memory.attrs)
        for key in (k for k in memory.attrs if k.startswith("summary_")):
            assert _equal(ds.attrs[key], memory.attrs[key]), key
            assert np.shape(ds.attrs[key]) == np.shape(memory.attrs[key]), key


def test_a_chain_run_file_written_before_reads_as_one_written_now(tmp_path):
    """A tree's file of 2-D summary attributes (as rbstab wrote them before) reads as before:
    read_attributes, read_summary, read_dataset and rbstab show give its figures in the shape
    they give a file written now, with the values the file holds."""
    with h5py.File(OLD_CHAIN_RUN, "r") as h5:
        stored = {k: h5.attrs[k] for k in h5.attrs if k.startswith("summary_")}
        assert "shape_of_summary" not in h5.attrs and stored["summary_final_theta"].shape == (2, 3)
    result = simulate(load_config(EXAMPLES / "stance_ankle_hip.yaml", ["simulation.t_end=0.1",
                                                                       "simulation.n_samples=11"]))
    new = write_result(result, tmp_path / "stance_ankle_hip.h5")
    old_attrs, new_attrs = read_attributes(OLD_CHAIN_RUN), read_attributes(new)
    # the balance figures came later: a file written before has the others
    later = {f"summary_{name}" for name in ("settling_time", "peak_sway", "com_excursion", "cop_excursion")}
    assert set(old_attrs) == set(new_attrs) - later
    old_ds, new_ds = read_dataset(OLD_CHAIN_RUN), read_dataset(new)
    assert set(old_ds.attrs) == set(new_ds.attrs) - later
    for key, value in stored.items():
        assert _equal(old_attrs[key], plain(value)) and _equal(old_ds.attrs[key], value), key
        assert np.shape(old_attrs[key]) == np.shape(new_attrs[key]), key
        assert np.shape(old_ds.attrs[key]) == np.shape(new_ds.attrs[key]), key
        assert type(old_ds.attrs[key]) is type(new_ds.attrs[key]), key
    later_names = {k[len("summary_"):] for k in later}
    assert read_summary(OLD_CHAIN_RUN)["summary"].keys() == read_summary(new)["summary"].keys() - later_names
    shown = [CliRunner().invoke(cli, ["show", str(p)]) for p in (OLD_CHAIN_RUN, new)]
    assert all(r.exit_code == 0 for r in shown), [r.output for r in shown]
    lines = [[line.split()[0] for line in r.output.splitlines()[1:] if line.startswith("  ")] for r in shown]
    assert lines[0] == [name for name in lines[1] if name not in later_names]  # the same figures, each on its line
    final = [next(line for line in r.output.splitlines() if line.strip().startswith("final_theta")) for r in shown]
    assert "legs [" in final[0] and "trunk [" in final[0] and final[0].count("[") == final[1].count("[")


# -- every other kind of file ------------------------------------------------------------------------


def _rbstab(*args: str) -> None:
    result = CliRunner().invoke(cli, [*args, "-q"], catch_exceptions=False)
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def files(sweeps, tmp_path_factory) -> dict[str, Path]:
    """One file of each kind the run files and one body's stores above leave out, each with
    every part it can have: a tree's store file; the analysis files of one body and of a tree
    (certificate, basin map, pushes, basin stability; one body's also verified); a sweep's
    robustness; a spec's recovery curves; the studies' files."""
    out = tmp_path_factory.mktemp("kinds")
    found = {}
    tree = run_sweep(spec_from_mapping({"name": "tree", "base": str(EXAMPLES / "stance_ankle_hip.yaml"),
                                        "grid": {"joints.hip.k_r.0": [400.0, 500.0]}},
                                       overrides=[f"simulation.{k}={v}" for k, v in TREE_SHORT.items()]),
                     out, jobs=1, chunk_size=2, layout="chunk", store="thinned", progress=False)
    (found["tree_store"],) = _files(tree)
    pendulum, stance = str(EXAMPLES / "saturated_pendulum.yaml"), str(EXAMPLES / "stance_ankle_hip.yaml")
    _rbstab("analyze", pendulum, "-o", str(out), "--samples", "300", "-j", "1", "--set", "simulation.n_samples=201",
            "--push", "torque", "--push-directions", "4", "--push-tol", "1e-2", "--basin",
            "initial_state.omega.0=-1:1:3", "--basin", "initial_state.omega.1=-1:1:2", "--basin-samples", "51",
            "--basin-stability", "initial_state.omega.0=-1:1", "-n", "4", "--verify")
    found["analysis"] = out / "saturated_pendulum.analysis.nc"
    _rbstab("analyze", stance, "-o", str(out), "--samples", "200", "-j", "1", "--set", "simulation.t_end=1",
            "--push", "torque", "--push-body", "trunk", "--push-directions", "3", "--push-tol", "1e-2", "--basin",
            "initial_state.legs.theta.0=-0.1:0.1:3", "--basin", "initial_state.trunk.theta.0=-0.1:0.1:2",
            "--basin-samples", "51", "--basin-stability", "initial_state.trunk.theta.0=-0.1:0.1", "-n", "4")
    found["chain_analysis"] = out / "stance_ankle_hip.analysis.nc"
    _rbstab("analyze", "--robustness", str(sweeps["full"].directory), "-o", str(out))
    found["robustness"] = out / "ncc_full.robustness.analysis.nc"
    spec = out / "limits.yaml"
    spec.write_text(f"name: limits\nbase: {pendulum}\ngrid:\n  controller.k_r.0: [200.0, 300.0]\n")
    _rbstab("analyze", str(spec), "-o", str(out), "--set", "simulation.n_samples=201", "--push", "torque",
            "--push-direction", "1,0,0", "--push-tol", "1e-2", "-j", "1", "--samples", "300")
    found["recovery"] = out / "limits.recovery.analysis.nc"
    short = [a for k, v in TREE_SHORT.items() for a in ("--set", f"simulation.{k}={v}")]
    _rbstab("sensitivity", str(EXAMPLES / "double_pendulum.yaml"), "-n", "4", *short, "-o", str(out), "-j", "1",
            "--no-progress", "--vary=bodies.1.mass=uniform:[0.5,2]",
            "--vary=initial_state.upper.theta.0=uniform:[0.3,0.9]")
    found["sensitivity"] = out / "double_pendulum" / "sensitivity.nc"
    _rbstab("tune", stance, "--trials", "4", "--generation", "4", "--vary", "joints.hip.l_r.0=uniform:[25,100]",
            "--minimize", "lyapunov_final", *short, "-o", str(out))
    found["tuning"] = out / "stance_ankle_hip" / "tuning.nc"
    return found


#: Some variables of each kind of :func:`files`: each part it was made with.
PARTS = {"tree_store": ["theta", "joint_theta", "final_theta_trunk_x"],
         "analysis": ["jacobian", "basin_outcome", "push_threshold", "stability_value", "sublevel_verified_box"],
         "chain_analysis": ["equilibrium_theta", "lyapunov_hessian", "basin_outcome", "push_threshold",
                            "stability_value"],
         "robustness": ["stable_fraction", "run_value"], "recovery": ["push_minimum", "controller.k_r.0"],
         "sensitivity": ["S1", "ST"], "tuning": ["lyapunov_final", "joints.hip.l_r.0"]}


@pytest.mark.parametrize("kind", list(PARTS))
def test_netcdf_c_reads_each_other_kind_of_file(files, kind):
    path = files[kind]
    assert_netcdf_c_reads(path, attribute_order=False, checksums=kind == "tree_store")
    with netCDF4.Dataset(path) as nc:
        assert set(PARTS[kind]) <= set(nc.variables), set(PARTS[kind]) - set(nc.variables)


#: A UDUNITS-2 string as rbstab writes them: "1", or symbols of SI units, each with an
#: integer power, separated by spaces (``N m s``, ``rad s-1``, ``N m rad-1``).
UDUNITS = re.compile(r"1|(?:(?:kg|m|s|rad|N|J|W|Hz)(?:-?[1-9])?)(?: (?:kg|m|s|rad|N|J|W|Hz)(?:-?[1-9])?)*")
#: Variables of analysis files whose entries are in different units (per state, per parameter).
MIXED_UNITS = ("jacobian", "jacobian_error", "lyapunov_hessian", "rate_hessian", "threshold", "run_value",
               "stability_value", "stability_low", "stability_threshold_low")


def test_units_are_udunits_where_a_file_claims_cf(files, sweeps, tree_runs, tmp_path):
    """Every file says Conventions = "CF-1.10": each numeric variable's units (where it has
    one: a variable whose entries are in different units has none) is a UDUNITS string; text
    has no units (CF 3.1)."""
    paths = [*files.values(), _files(sweeps["thinned"])[0],
             write_result(simulate(load_config(CASE3, SHORT)), tmp_path / "case3.h5"),
             write_result(tree_runs["three_pushed"], tmp_path / "three.h5")]
    for path in paths:
        with netCDF4.Dataset(path) as nc:
            assert nc.getncattr("Conventions") == "CF-1.10", path
            for name, var in nc.variables.items():
                units = getattr(var, "units", None)
                if var.dtype is str or var.dtype.kind == "S":
                    assert units is None, f"{path.name}: {name} is text, with units {units!r}"
                elif units is not None:
                    assert UDUNITS.fullmatch(units), f"{path.name}: {name}: units {units!r}"
            for name in set(MIXED_UNITS) & set(nc.variables):
                assert "units" not in nc[name].ncattrs(), f"{path.name}: {name} (entries in different units)"


# -- ncdump ---------------------------------------------------------------------------------------


@pytest.mark.skipif(shutil.which("ncdump") is None, reason="no ncdump on PATH (netCDF-C's tools, e.g. apt-get install netcdf-bin)")
def test_ncdump_prints_a_store_file_and_a_run_file(sweeps, tmp_path):
    store = _files(sweeps["thinned"])[0]
    header = subprocess.run(["ncdump", "-h", str(store)], capture_output=True, text=True, check=True).stdout
    for line in ("run = 2 ;", "time = 201 ;", "axis = 3 ;", "double theta(run, time, axis) ;",
                 "double lyapunov(run, time) ;", "string run_id(run) ;", "double lyapunov_final(run) ;",
                 'string lyapunov_final:units = "J" ;', "string :rbstab_format = \"rbstab-sweep-2\" ;"):
        assert line in header, line
    data = subprocess.run(["ncdump", "-v", "run_id,status", str(store)], capture_output=True, text=True,
                          check=True).stdout
    with h5py.File(store, "r") as h5:
        assert all(f'"{r}"' in data for r in h5["run_id"].asstr()[...])
    run = write_result(simulate(load_config(CASE3, SHORT)), tmp_path / "case3.h5")
    header = subprocess.run(["ncdump", "-h", str(run)], capture_output=True, text=True, check=True).stdout
    assert "double theta(time, axis) ;" in header and "string :rbstab_format = \"rbstab-run-1\" ;" in header
