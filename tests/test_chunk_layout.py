"""Sweeps with ``--layout chunk``: one HDF5 file per chunk of runs (rbstab.io.chunk).

The chunk layout must hold exactly what the run layout holds (same bits, same index),
resume from either, keep failures and errors per run, and be readable by xarray, the
report and ``rbstab show``.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import yaml

from rbstab.io.chunk import (ChunkWriter, StoreRow, read_chunk_columns, read_chunk_rows, read_chunk_series,
                             summary_columns)
from rbstab.io.hdf5 import SUMMARY_VARIABLES, read_attributes, summary_stride
from rbstab.sweep import expand, run_chunk, run_sweep, spec_from_mapping
from rbstab.sweep.worker import RunTask, WorkerOptions
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
SHORT = ["simulation.t_end=0.2", "simulation.n_samples=201"]
LOCKING = {"theta": [0.0, 1.5, 0.0], "omega": [0.0, 30.0, 0.0]}

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def spec(n: int, name: str = "chk", grid: bool = False, seed: int = 7):
    data = {
        "name": name,
        "base": str(CASE3),
        "random": {"n": n, "seed": seed,
                   "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}},
    }
    if grid:
        data["grid"] = {"controller.k_c": [[12300, 12300, 9840], [20000, 20000, 15000]]}
    return spec_from_mapping(data, overrides=SHORT)


def chunk_files(folder: Path) -> list[Path]:
    return sorted((folder / "runs").glob("chunk-*.h5"))


def test_chunk_layout_holds_what_run_files_hold(tmp_path):
    s = spec(3, grid=True)
    runs = expand(s)
    by_run = run_sweep(s, tmp_path / "run", jobs=2, progress=False, layout="run")
    by_chunk = run_sweep(s, tmp_path / "chunk", jobs=2, chunk_size=2, layout="chunk", progress=False)
    assert by_chunk.counts["success"] == by_run.counts["success"] == 6
    files = chunk_files(by_chunk.directory)
    assert len(files) == by_chunk.n_chunks == 3  # 6 runs of any kind, at most 2 per chunk
    assert not list((by_chunk.directory / "runs").glob("r*.h5"))

    ir = pd.read_csv(by_run.index_path)
    ic = pd.read_csv(by_chunk.index_path)
    assert list(ic.columns) == list(ir.columns)
    same = [c for c in ir.columns if c not in ("wall_time", "file", "file_row")]
    pd.testing.assert_frame_equal(ir[same], ic[same])
    assert all(f.startswith("runs/chunk-") for f in ic["file"])

    for entry in ic.itertuples():
        path, row = by_chunk.directory / entry.file, int(entry.file_row)
        run_file = by_run.directory / "runs" / f"{entry.run_id}.h5"
        attrs = read_attributes(run_file)
        chunk_row = read_chunk_rows(path)[row]
        assert chunk_row["run_id"] == entry.run_id and chunk_row["run"] == entry.run
        for key in ("variant", "status", "message", "config_hash", "solver_nfev", "solver_status"):
            assert chunk_row[key] == attrs[key], key
        config = yaml.safe_load(attrs["config"])
        del config["name"]
        assert json.loads(chunk_row["config"]) == config
        summary = summary_columns({k[8:]: v for k, v in attrs.items() if k.startswith("summary_")})
        # a figure with no value: NaN in the run file, None in the store's row
        np.testing.assert_equal({k: np.nan if chunk_row[k] is None else chunk_row[k] for k in summary}, summary)
        with h5py.File(run_file, "r") as fr, h5py.File(path, "r") as fc:
            variables = [k for k in fr if k not in ("time", "axis")]
            assert set(variables) <= set(fc)
            assert np.array_equal(fr["time"][()], fc["time"][()])
            for key in variables:  # the same bits
                assert np.array_equal(fr[key][()], fc[key][row]), key
                assert fc[key].attrs["units"] == fr[key].attrs["units"]


def test_chunk_file_opens_in_xarray_with_a_run_dimension(tmp_path):
    xr = pytest.importorskip("xarray")
    s = spec(5)
    out = run_sweep(s, tmp_path, jobs=1, layout="chunk", store="thinned", progress=False)
    (path,) = chunk_files(out.directory)
    runs = expand(s)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        stride = summary_stride(201)
        assert dict(ds.sizes) == {"run": 5, "time": len(range(0, 201, stride)), "axis": 3}
        assert set(SUMMARY_VARIABLES) - {"controller_state"} <= set(ds.data_vars)
        assert ds["lyapunov"].dims == ("run", "time")
        assert ds["final_omega_x"].dims == ("run",)
        assert ds["final_omega_x"].attrs["units"] == "rad s-1" and ds["final_omega_x"].attrs["long_name"]
        assert list(ds["run"].values) == [r.index for r in runs]
        assert list(ds["run_id"].values) == [r.run_id for r in runs]
        assert ds["omega_0"].attrs["config_key"] == "initial_state.omega.0" and "omega_0" in ds.coords
        assert ds.attrs["store"] == "thinned" and ds["omega"].attrs["units"] == "rad s-1"
        series = read_chunk_series(path, 2, ["lyapunov"])
        assert np.array_equal(series["lyapunov"], ds["lyapunov"].values[2])


def test_chunk_resume_and_layout_switch(tmp_path):
    small, large = spec(4, "res"), spec(7, "res")
    first = run_sweep(small, tmp_path, jobs=2, layout="chunk", progress=False)
    assert first.counts["success"] == 4 and len(chunk_files(first.directory)) == 2
    again = run_sweep(large, tmp_path, jobs=2, layout="chunk", progress=False)
    assert (again.n_skipped, again.n_executed, again.counts["success"]) == (4, 3, 7)
    # a lost chunk file: only its runs run again
    lost = chunk_files(again.directory)[0]
    n_lost = len(read_chunk_rows(lost))
    lost.unlink()
    redo = run_sweep(large, tmp_path, jobs=2, layout="chunk", progress=False)
    assert (redo.n_skipped, redo.n_executed) == (7 - n_lost, n_lost)
    # results of either layout count for the other
    switched = run_sweep(large, tmp_path, jobs=2, layout="run", progress=False)
    assert (switched.n_skipped, switched.n_executed) == (7, 0)
    # a chunk file holding no run of the spec is reported as stale, never read as a result
    other = run_sweep(spec(2, "res2", seed=8), tmp_path, jobs=1, layout="chunk", progress=False)
    stray = chunk_files(other.directory)[0]
    stray.rename(again.directory / "runs" / stray.name)
    again = run_sweep(large, tmp_path, jobs=1, layout="chunk", progress=False)
    assert again.stale_files == [stray.name] and again.n_executed == 0


def test_chunk_worker_keeps_failures_and_errors_per_run(tmp_path):
    runs = expand(spec(3))
    folder = tmp_path / "runs"
    tasks = [RunTask(r.run_id, r.config.resolved, str(folder / f"{r.run_id}.h5"), r.index) for r in runs]
    locking = copy.deepcopy(runs[1].config.resolved)
    locking["initial_state"].update(LOCKING)
    tasks[1] = RunTask(runs[1].run_id, locking, tasks[1].path, 1)
    bad = RunTask("r9999-deadbeef", {"name": "r9999-deadbeef", "body": {}}, str(folder / "r9999-deadbeef.h5"), 3)
    for engine in ("compiled", "scipy"):
        result = run_chunk([*tasks, bad], WorkerOptions(engine=engine, layout="chunk"))
        status = dict(zip(result.frame["run_id"], result.frame["status"]))
        assert status == {runs[0].run_id: "success", runs[1].run_id: "failed", runs[2].run_id: "success",
                          bad.run_id: "error"}
        assert bad.run_id in result.tracebacks
        (name,) = set(result.frame["file"])
        path = folder / name
        rows = {row["run_id"]: row for row in read_chunk_rows(path)}
        assert rows[bad.run_id]["status"] == "error" and "ConfigError" in rows[bad.run_id]["message"]
        assert rows[runs[1].run_id]["message"].startswith("gimbal lock")
        # the result carries each row as the file holds it, but what the index takes from
        # the table of runs (base, coordinates) and the config text, creation time, store
        for row in result.frame.to_dict("records"):
            stored = rows[row["run_id"]]
            assert set(row) == set(stored) - {"base", "config", "store"}
            for key, value in row.items():
                absent = value is None or value != value  # None or NaN: no value (an error row's figures)
                assert value == stored[key] or (absent and (stored[key] is None or stored[key] != stored[key])), key
        with h5py.File(path, "r") as f:  # the error row holds no data
            assert np.isnan(f["lyapunov"][rows[bad.run_id]["file_row"]]).all()
        Path(path).unlink()


def test_chunk_writer_is_atomic(tmp_path):
    target = tmp_path / "chunk-x.h5"
    with pytest.raises(RuntimeError, match="boom"):
        with ChunkWriter(target, [StoreRow(0, "r0"), StoreRow(1, "r1")]) as writer:
            writer.add_error("r0", "no result")
            raise RuntimeError("boom")
    assert not target.exists() and not list(tmp_path.iterdir())
    with pytest.raises(ValueError, match="no result for 1 run"):
        with ChunkWriter(target, [StoreRow(0, "r0"), StoreRow(1, "r1")]) as writer:
            writer.add_error("r0", "no result")
    assert not target.exists()


def test_chunk_writer_refuses_traces_of_another_shape(tmp_path):
    """A run whose trace has another shape than the file's is refused by name (not spread
    over the row), and nothing is left behind."""
    import dataclasses
    import warnings

    from rbstab.config import load_config
    from rbstab.simulator import simulate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # W001 of Case 3's inertia
        config = load_config(CASE3, ["simulation.n_samples=101", "simulation.t_end=0.1"])
    good = simulate(config)
    bad = dataclasses.replace(good, outputs={**good.outputs, "theta": good.outputs["theta"][0]})
    target = tmp_path / "chunk-x.h5"
    with pytest.raises(ValueError, match=r"run r1: 'theta' has shape \(3,\)"):
        with ChunkWriter(target, [StoreRow(0, "r0"), StoreRow(1, "r1")], store="full") as writer:
            writer.add("r0", good)
            writer.add("r1", bad)
    assert not target.exists() and not list(tmp_path.iterdir())


def _case3_block(k: int, n_samples: int = 101, t_end: float = 0.1):
    """(configs, RunBlock) of k short Case 3 runs of different initial Omega."""
    import warnings

    from rbstab.config import load_config
    from rbstab.simulator import simulate_blocks

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # W001 of Case 3's inertia
        config = load_config(CASE3, [f"simulation.n_samples={n_samples}", f"simulation.t_end={t_end}"])
    configs = [config.with_initial_state({"omega": [16.0 + j, 32.0, -16.0]}) for j in range(k)]
    (indices, block), = simulate_blocks(configs)
    assert indices == list(range(k))
    return configs, block


@pytest.mark.parametrize("store", ["thinned", "full", "summary"])
def test_chunk_writer_block_of_runs_writes_what_each_run_alone_writes(tmp_path, monkeypatch, store):
    """add_block (a block's traces copied at once, its values kept as columns) gives the
    file and the rows that add of each run gives, also for a block whose rows are not
    consecutive and one that does not fit in what is left of the write buffer."""
    from rbstab.io import chunk

    monkeypatch.setattr(chunk, "WRITE_BYTES", 1)  # a buffer of WRITE_BLOCK rows: flushes inside a block
    monkeypatch.setattr(chunk, "WRITE_BLOCK", 4)
    _, block = _case3_block(6)
    ids = [f"r{i}" for i in range(7)]
    rows = [StoreRow(i, ids[i], "case3", {"omega_0": 16.0 + i}) for i in range(7)]
    order = [[5, 0, 3], [1, 2, 4]]  # run j of the block is row order[...]
    with ChunkWriter(tmp_path / "chunk-a.h5", rows, store=store) as writer:
        for first, part in zip((0, 3), order):  # runs 0-2 of the block, then 3-5
            writer.add_block([ids[i] for i in part], _block_part(block, [first, first + 1, first + 2]))
        writer.add_error(ids[6], "it raised")
        by_block = writer.columns()
    with ChunkWriter(tmp_path / "chunk-b.h5", rows, store=store) as writer:
        by_run = [writer.add(ids[i], block.result(j)) for j, i in enumerate(order[0] + order[1])]
        by_run.append(writer.add_error(ids[6], "it raised"))
    by_run.sort(key=lambda r: r["run"])
    drop = ("file", "created", "wall_time", "config", "store")
    # the columns of the rows added as blocks are the rows added one by one ("" or NaN
    # where a row has no value: the error row's figures)
    assert set(by_block) - set(drop) == set(by_run[0]) - set(drop)

    def value(v):
        return "absent" if v is None or v != v or v == "" else v

    for name, column in by_block.items():
        if name not in drop:
            assert [value(v) for v in column.tolist()] == [value(r.get(name)) for r in by_run], name
    read = [read_chunk_rows(tmp_path / f"chunk-{x}.h5", data=True) for x in "ab"]
    drop = ("file", "created", "wall_time")
    assert [{k: v for k, v in r.items() if k not in drop} for r in read[0]] == \
        [{k: v for k, v in r.items() if k not in drop} for r in read[1]]
    # columns() is what read_chunk_columns reads back
    back = read_chunk_columns(tmp_path / "chunk-a.h5")
    assert list(back.columns) == list(by_block)
    for name in back.columns:
        assert back[name].tolist() == by_block[name].tolist() or \
            np.array_equal(back[name].to_numpy(dtype=float), by_block[name], equal_nan=True), name
    assert [r["run_id"] for r in read[0]] == ids and read[0][6]["status"] == "error"
    names = ["lyapunov", "theta", "constraint_error"]
    a, b = (read_chunk_series(tmp_path / f"chunk-{x}.h5", None, names) for x in "ab")
    for name in names:
        if store == "summary":
            assert a[name] is None and b[name] is None
            continue
        np.testing.assert_array_equal(a[name], b[name])
        assert np.isnan(a[name][6]).all()
        stride = round((len(block.time) - 1) / (len(a["time"]) - 1))
        for j, i in enumerate(order[0] + order[1]):
            np.testing.assert_array_equal(a[name][i], block.outputs[name][j, ::stride])


def _block_part(block, js):
    """The runs ``js`` of a RunBlock, as a RunBlock."""
    import dataclasses

    return dataclasses.replace(
        block, configs=[block.configs[j] for j in js], outputs={n: v[js] for n, v in block.outputs.items()},
        summaries={n: v[js] for n, v in block.summaries.items()},
        solver={n: np.asarray(v)[js] for n, v in block.solver.items()},
        timing={n: v[js] for n, v in block.timing.items()}, wall_time=block.wall_time[js],
        **{k: [getattr(block, k)[j] for j in js] for k in ("status", "message", "switching", "variants")})


def test_chunk_writer_block_that_is_refused_adds_none_of_its_runs(tmp_path):
    """A block with a run that is not a row, a run given twice or traces of another shape
    raises ValueError and adds none of its runs: they can still be added one by one."""
    import dataclasses

    _, block = _case3_block(2)
    rows = [StoreRow(0, "r0"), StoreRow(1, "r1")]
    bad = dataclasses.replace(block, outputs={**block.outputs, "theta": block.outputs["theta"][:, :50]})
    with ChunkWriter(tmp_path / "chunk-x.h5", rows, store="full") as writer:
        writer.add("r0", block.result(0))
        with pytest.raises(ValueError, match="r0"):
            writer.add_block(["r1", "r0"], block)  # r0 is there already
        with pytest.raises(ValueError, match="twice"):
            writer.add_block(["r1", "r1"], block)
        with pytest.raises(ValueError, match=r"run r1: 'theta' has shape"):
            writer.add_block(["r1"], _block_part(bad, [1]))
        writer.add("r1", block.result(1))
    read = read_chunk_rows(tmp_path / "chunk-x.h5", data=True)
    assert [r["status"] for r in read] == ["success", "success"]
    series = read_chunk_series(tmp_path / "chunk-x.h5", None, ["theta"])
    np.testing.assert_array_equal(series["theta"], block.outputs["theta"])


@pytest.mark.parametrize("store", ["thinned", "full"])
def test_chunk_writer_keeps_no_view_of_a_run_it_holds(tmp_path, store):
    """A run's outputs are views of a block shared with other runs (simulate_many's
    post-processing); the writer copies what it keeps until its next write, so the block is
    freed when the caller drops it (a view would pin it: ~300 MB a 512-run file)."""
    import dataclasses
    import gc
    import warnings
    import weakref

    from rbstab.config import load_config
    from rbstab.simulator import simulate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # W001 of Case 3's inertia
        config = load_config(CASE3, ["simulation.n_samples=101", "simulation.t_end=0.1"])
    result = simulate(config)
    rows = [StoreRow(0, "r0"), StoreRow(1, "r1")]
    with ChunkWriter(tmp_path / "chunk-x.h5", rows, store=store) as writer:
        columns = [np.asarray(v, dtype=float).reshape(len(result.time), -1) for v in result.outputs.values()]
        block = np.concatenate(columns, axis=1)  # every output of the run side by side
        edges = np.cumsum([0] + [c.shape[1] for c in columns])
        shared = dataclasses.replace(result, outputs={
            k: block[:, lo:hi].reshape(np.shape(v)) for (k, v), lo, hi in zip(result.outputs.items(), edges, edges[1:])})
        assert all(np.shares_memory(v, block) for v in shared.outputs.values())
        alive = weakref.ref(block)
        writer.add("r0", shared)
        del block, shared
        gc.collect()
        assert alive() is None
        writer.add("r1", result)
    for row in (0, 1):  # what was kept is the run's trace
        series = read_chunk_series(tmp_path / "chunk-x.h5", row, ["lyapunov", "theta"])
        step = round((len(result.time) - 1) / (len(series["time"]) - 1))
        for name in ("lyapunov", "theta"):
            np.testing.assert_array_equal(series[name], result.outputs[name][::step])


def test_report_and_show_read_chunk_sweeps(tmp_path):
    s = spec(3)
    out = run_sweep(s, tmp_path / "sweeps", jobs=1, layout="chunk", progress=False)
    run_layout = run_sweep(s, tmp_path / "plain", jobs=1, progress=False, layout="run")
    from rbstab.report.load import load_inputs

    inputs = load_inputs([out.directory])
    (sweep,) = inputs.sweeps
    assert [r.name for r in sweep.runs] == sweep.run_ids
    reference = load_inputs([run_layout.directory]).sweeps[0]
    for a, b in zip(sweep.runs, reference.runs):
        assert a.config == {k: v for k, v in b.config.items() if k != "name"}
        np.testing.assert_equal(a.summary, b.summary)  # NaN: a figure with no value
        assert a.status == b.status
        sa, sb = a.series("lyapunov", "omega"), b.series("lyapunov", "omega")
        for key in sb:
            assert np.array_equal(sa[key], sb[key]), key
    (path,) = chunk_files(out.directory)
    direct = load_inputs([path]).runs
    assert [r.name for r in direct] == sweep.run_ids

    report = CliRunner().invoke(cli, ["report", str(out.directory), "-o", str(tmp_path / "report")])
    assert report.exit_code == 0, report.output
    assert (tmp_path / "report" / "index.html").is_file()
    shown = CliRunner().invoke(cli, ["show", str(path)])
    assert shown.exit_code == 0, shown.output
    assert "store file: 3 runs" in shown.output
    shown = CliRunner().invoke(cli, ["show", str(out.directory)])
    assert shown.exit_code == 0 and "chk: 3 runs, 3 still settling" in shown.output  # by outcome
    assert all(run_id in shown.output for run_id in sweep.run_ids)


def test_chunk_bytes_for_workers_without_the_sweep_folder(tmp_path):
    """Dask workers return the chunk file's bytes; the parent writes them once."""
    runs = expand(spec(3))
    folder = tmp_path / "runs"
    tasks = [RunTask(r.run_id, r.config.resolved, str(folder / f"{r.run_id}.h5")) for r in runs]
    result = run_chunk(tasks, WorkerOptions(engine="compiled", layout="chunk", return_bytes=True))
    assert not folder.exists()  # nothing written where the worker runs
    ((path, data),) = result.data.items()
    assert Path(path).parent == folder and Path(path).name == result.frame["file"][0]
    folder.mkdir()
    Path(path).write_bytes(data)
    rows = read_chunk_rows(path)
    assert [row["run_id"] for row in rows] == [r.run_id for r in runs]
    assert list(result.frame["config_hash"]) == [row["config_hash"] for row in rows]


def test_an_executor_passed_in_stays_open_for_the_next_sweep(tmp_path):
    """run_sweep closes an executor it made, never one it was given: a session's second
    sweep finds the workers started (and gives the same results)."""
    from rbstab.sweep.executors import LocalExecutor

    with LocalExecutor(2) as ex:
        first = run_sweep(spec(4, "warm1"), tmp_path, executor=ex, layout="chunk", store="summary", progress=False)
        pool = ex._pool
        assert pool is not None  # still running
        second = run_sweep(spec(4, "warm2"), tmp_path, executor=ex, layout="chunk", store="summary", progress=False)
        assert ex._pool is pool  # the same worker processes
    assert ex._pool is None  # closed by its owner
    assert first.counts == second.counts == {"success": 4, "failed": 0, "error": 0, "pending": 0}
    a = pd.read_csv(tmp_path / "warm1" / "index.csv")
    b = pd.read_csv(tmp_path / "warm2" / "index.csv")
    np.testing.assert_array_equal(a["final_omega_x"], b["final_omega_x"])


def test_open_sweep_gives_the_runs_and_the_grid_with_missing_runs_as_nan(tmp_path):
    xr = pytest.importorskip("xarray")
    from rbstab import open_sweep
    from rbstab.sweep import rebuild_index

    s = spec_from_mapping({"name": "grid", "base": str(CASE3),
                           "grid": {"controller.k_c": [[12300, 12300, 9840], [20000, 20000, 15000]],
                                    "controller.variant": ["visco_elastic", "embedded"]}}, overrides=SHORT)
    out = run_sweep(s, tmp_path, jobs=2, chunk_size=1, progress=False)
    files = chunk_files(out.directory)
    assert len(files) == 4
    # combined by the run coordinate, as docs/sweeps.md reads them, also under xarray's coming defaults
    coming = {"use_new_combine_kwarg_defaults": True} if "use_new_combine_kwarg_defaults" in xr.get_options() else {}
    with xr.set_options(**coming), xr.open_mfdataset(files, engine="h5netcdf", join="outer",
                                                     compat="no_conflicts") as ds:
        assert list(ds["run"].values) == [0, 1, 2, 3] and {"k_c_0", "variant", "run_id"} <= set(ds.coords)
    index = pd.read_csv(out.index_path)
    ds = open_sweep(out.directory)
    assert ds.sizes["run"] == 4 and list(ds["run_id"].values) == list(index["run_id"])
    assert hasattr(ds["lyapunov"].data, "dask")  # lazy
    for name in ("lyapunov_final", "max_abs_constraint_error_x", "k_c_0", "status", "converged"):
        assert list(ds[name].values) == list(index[name]), name
    first = read_chunk_rows(files[0])[0]["run"]
    files[0].unlink()
    rebuild_index(s, tmp_path)
    grid = open_sweep(out.directory, grid=True)
    assert grid["lyapunov_final"].dims == ("k_c_0", "variant")
    assert list(grid["k_c_0"].values) == [12300, 20000]
    assert list(grid["variant"].values) == ["visco_elastic", "embedded"]
    i, j = divmod(first, 2)
    assert grid["status"].values[i, j] == "pending" and np.isnan(grid["lyapunov_final"].values[i, j])
    ok = index.loc[index["run"] == 3].iloc[0]
    assert grid["lyapunov_final"].values[1, 1] == ok["lyapunov_final"]
    assert grid["lyapunov"].dims == ("time", "k_c_0", "variant") or "k_c_0" in grid["lyapunov"].dims


def test_open_sweep_traces_match_each_file_for_any_selection_of_runs(tmp_path):
    """The lazy traces over several store files give each run's own rows, for slices,
    scattered and reversed selections, and a single run."""
    from rbstab import open_sweep
    from rbstab.io.chunk import StoreTrace

    out = run_sweep(spec(5), tmp_path, jobs=1, chunk_size=2, layout="chunk", store="full", progress=False)
    assert len(chunk_files(out.directory)) == 3
    index = pd.read_csv(out.index_path).sort_values("run")
    own = np.stack([read_chunk_series(out.directory / r.file, int(r.file_row), ["omega"])["omega"]
                    for r in index.itertuples()])
    ds = open_sweep(out.directory)
    np.testing.assert_array_equal(ds["omega"].values, own)
    np.testing.assert_array_equal(ds["omega"].isel(run=[4, 0, 2]).values, own[[4, 0, 2]])
    segments = [(str(out.directory / r.file), [int(r.file_row)]) for r in index.itertuples()]
    direct = StoreTrace("omega", segments[::-1], own.shape[1:])  # one segment a run, in reverse
    np.testing.assert_array_equal(direct[:], own[::-1])
    np.testing.assert_array_equal(direct[1], own[3])
    np.testing.assert_array_equal(direct[[3, 1], 5, 1:], own[[1, 3], 5, 1:])


@pytest.mark.parametrize("store, block_bytes", [("thinned", None), ("summary", None), ("full", None), ("full", 1)])
def test_store_data_digest_matches_what_the_file_holds(tmp_path, monkeypatch, store, block_bytes):
    """The writer's data digest (from the arrays it wrote when each variable went in one
    block, else read back) equals the digest of the numbers as HDF5 decodes them."""
    from rbstab.io import chunk
    from rbstab.io.integrity import DATA_DIGEST_ATTR, data_digest

    if block_bytes is not None:  # every trace written in several blocks
        monkeypatch.setattr(chunk, "WRITE_BYTES", block_bytes)
        monkeypatch.setattr(chunk, "WRITE_BLOCK", 2)
    out = run_sweep(spec(5), tmp_path, jobs=1, layout="chunk", store=store, progress=False)
    (path,) = chunk_files(out.directory)
    with h5py.File(path, "r") as f:
        assert f.attrs[DATA_DIGEST_ATTR] == data_digest(f, path)
        numbers = [k for k in f if f[k].dtype.kind == "f" and f[k].ndim >= 2]
        assert numbers or store == "summary"


def test_open_sweep_loads_no_compiler_nor_validator(tmp_path):
    """Reading a sweep needs neither numba (its start-up is ~0.5 s) nor pydantic."""
    import subprocess
    import sys

    out = run_sweep(spec(2), tmp_path, jobs=1, layout="chunk", progress=False)
    code = ("import sys, rbstab; ds = rbstab.open_sweep(sys.argv[1]); assert ds.sizes['run'] == 2; "
            "print(sorted(m for m in ('numba', 'pydantic', 'scipy.integrate') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code, str(out.directory)], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_read_chunk_series_of_every_row_stacks_each_row(tmp_path):
    """row=None reads every run of a store file at once, the rows as one at a time."""
    out = run_sweep(spec(3), tmp_path, jobs=1, layout="chunk", store="thinned", progress=False)
    (path,) = chunk_files(out.directory)
    every = read_chunk_series(path, None, ["omega", "lyapunov"])
    for row in range(3):
        one = read_chunk_series(path, row, ["omega", "lyapunov"])
        np.testing.assert_array_equal(every["omega"][row], one["omega"])
        np.testing.assert_array_equal(every["lyapunov"][row], one["lyapunov"])
    assert every["omega"].shape[0] == 3 and every["units:omega"] == one["units:omega"]


def test_worker_stores_a_block_its_sink_refuses_run_by_run():
    """A block the sink cannot take at once is stored a run at a time; the one run that
    cannot be written is that run's error, the others are stored."""
    from rbstab.sweep.worker import _add_block

    _, block = _case3_block(3)
    tasks = [RunTask(f"r{j}", {}, f"r{j}.h5", j) for j in range(3)]

    class Sink:
        def add_block(self, tasks, block):
            raise ValueError("not at once")

        def add(self, task, result):
            if task.run_id == "r1":
                raise OSError("disk full")
            assert result.outputs["lyapunov"] is not None and result.config is block.configs[int(task.run_id[1])]
            return {"run_id": task.run_id, "status": result.status, "timing": {}}

        def error(self, task, exc):
            return {"run_id": task.run_id, "status": "error", "message": str(exc)}

    records = _add_block(Sink(), tasks, block, config_time=0.5)
    assert [(r["run_id"], r["status"]) for r in records] == [("r0", "success"), ("r1", "error"), ("r2", "success")]
    assert records[0]["timing"]["config"] == 0.5 and "timing" not in records[1]



def test_summary_from_columns_is_the_inverse_of_summary_columns():
    """A run's summary flattened to a sweep's columns and read back gives the same figures:
    one body's per axis, a tree's per body or joint (and axis); an entry the row lacks is
    NaN, and a figure with no column is left out."""
    import warnings

    from rbstab.config import load_config
    from rbstab.io.chunk import summary_columns, summary_from_columns
    from rbstab.layout import is_chain
    from rbstab.simulator import simulate

    root = Path(__file__).resolve().parents[1]
    short = ["simulation.t_end=0.2", "simulation.n_samples=21"]
    for path in (root / "configs" / "paper" / "case3_embedded.yaml", root / "configs" / "examples" / "knee.yaml"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            config = load_config(path, short)
        summary = simulate(config).summary
        chain = config.chain if is_chain(config) else None  # one body's spelling: one body's summary
        names = {} if chain is None else {"joints": chain.joint_names, "bodies": chain.body_names}
        row = summary_columns(summary, **names)
        back = summary_from_columns(row, **names)
        assert list(back) == list(summary)
        for key, value in summary.items():
            assert np.asarray(back[key]).shape == np.asarray(value).shape, key
            np.testing.assert_array_equal(np.asarray(back[key]), np.asarray(value), err_msg=key)
    lacking = dict(row, **{next(c for c in row if c.startswith("final_theta_")): None})
    assert np.isnan(np.asarray(summary_from_columns(lacking, **names)["final_theta"])).sum() == 1
    assert "final_theta" not in summary_from_columns({"lyapunov_final": 1.0}, **names)
