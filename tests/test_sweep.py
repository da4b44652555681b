"""Parameter sweeps: spec expansion and validation, end-to-end runs, resume, Dask.

Runs are short (t_end = 0.2 s, 201 samples) so that the whole file stays fast.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from rbstab.variants.paper import paper_form
from rbstab.io.chunk import read_chunk_rows
from rbstab.sweep import (
    SweepBusyError,
    SweepSpecError,
    expand,
    load_spec,
    run_chunk,
    run_sweep,
    spec_from_mapping,
)
from rbstab.sweep.executors import ExecutorError
from rbstab.sweep.worker import RunTask, WorkerOptions
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "configs" / "paper" / "case1_permanent.yaml"
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
SHORT = ["simulation.t_end=0.2", "simulation.n_samples=201"]
# theta_2 close to pi/2 and a fast spin about axis 2: gimbal lock within milliseconds
LOCKING_THETA = [0.0, 1.5, 0.0]
LOCKING_OMEGA = [0.0, 30.0, 0.0]

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def case3_data(**sim) -> dict:
    data = yaml.safe_load(CASE3.read_text())
    data["simulation"].update({"t_end": 0.2, "n_samples": 201, **sim})
    return data


def write_spec(tmp_path: Path, spec: dict, name: str = "spec.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def data_equal(a: Path, b: Path) -> None:
    """Every variable and every attribute but provenance/timing equal, bit for bit."""
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        assert set(fa) == set(fb)
        for key in fa:
            x, y = fa[key][()], fb[key][()]
            assert x.dtype == y.dtype and x.shape == y.shape, key
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), key
        skip = {"created", "command_line", "history", "wall_time", "rbstab_digest"}  # the digest covers provenance
        assert set(fa.attrs) == set(fb.attrs)
        for key in set(fa.attrs) - skip:
            x, y = np.asarray(fa.attrs[key]), np.asarray(fb.attrs[key])
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), key


# -- spec expansion ---------------------------------------------------------------------------


def full_spec() -> dict:
    return {
        "name": "expansion",
        "base": case3_data(),
        "grid": {
            "controller.k_c": [[4100, 4100, 3280], [12300, 12300, 9840], [36900, 36900, 29520]],
            "controller.variant": ["visco_elastic", "embedded"],
        },
        "zip": {"initial_state.omega.0": [10.0, 20.0], "initial_state.theta.2": [0.0, 0.1]},
        "random": {
            "n": 4,
            "seed": 7,
            "params": {
                "body.mass": {"uniform": [20.5, 61.5]},
                "initial_state.v": {"normal": {"mean": [0.0, 1.0, -1.0], "std": 0.5}},
            },
        },
    }


def test_grid_zip_random_count_order_and_ids():
    spec = spec_from_mapping(full_spec())
    runs = expand(spec)
    assert spec.n_runs == len(runs) == 4 * 3 * 2 * 2
    ids = [r.run_id for r in runs]
    assert len(set(ids)) == len(ids)
    assert all(len(i) == len("r0000-") + 8 and i.startswith(f"r{n:04d}-") for n, i in enumerate(ids))
    assert all(r.config.name == r.run_id for r in runs)
    # order: random sample slowest, then grid (last key fastest), zip fastest
    assert [r.params["initial_state.omega.0"] for r in runs[:4]] == [10.0, 20.0, 10.0, 20.0]
    assert [r.params["controller.variant"] for r in runs[:4]] == ["visco_elastic"] * 2 + ["embedded"] * 2
    assert len({r.params["body.mass"] for r in runs[:12]}) == 1
    assert runs[12].params["body.mass"] != runs[0].params["body.mass"]
    # the varied values reach the validated configs
    for r in runs:
        assert r.config.chain.joints[0].variant == r.params["controller.variant"]
        assert r.config.resolved["controller"]["k_c"] == r.params["controller.k_c"]
        assert paper_form(r.config).body.mass == r.params["body.mass"]
        assert r.config.initial_state["body"]["velocity"].tolist() == r.params["initial_state.v"]
        assert r.config.initial_state["body"]["omega"][0] == r.params["initial_state.omega.0"]
        assert r.config.initial_state["body"]["omega"][1:].tolist() == [32.0, -16.0]  # untouched entries
        assert r.config.initial_state["body"]["theta"][2] == r.params["initial_state.theta.2"]
    # the id ends with the first 8 hex digits of the run's identity (its base and its values)
    for r in runs:
        assert len(r.config_hash) == 32 and r.config_hash.startswith(r.run_id.split("-")[1])
    # the same values give the same identity; another base value another one
    assert [r.config_hash for r in runs] == [r.config_hash for r in expand(spec_from_mapping(full_spec()))]
    other = full_spec()
    other["base"]["body"]["mass"] = 40.0
    assert not {r.config_hash for r in runs} & {r.config_hash for r in expand(spec_from_mapping(other))}


def test_random_reproducible_from_seed_and_prefix_stable():
    a = expand(spec_from_mapping(full_spec()))
    b = expand(spec_from_mapping(full_spec()))
    assert [r.run_id for r in a] == [r.run_id for r in b]
    assert [r.params for r in a] == [r.params for r in b]
    other = full_spec()
    other["random"]["seed"] = 8
    c = expand(spec_from_mapping(other))
    assert [r.params["body.mass"] for r in c] != [r.params["body.mass"] for r in a]
    # more samples append runs: the first ones keep their values and ids
    more = full_spec()
    more["random"]["n"] = 6
    d = expand(spec_from_mapping(more))
    assert len(d) == 6 * 12
    assert [r.run_id for r in d[: len(a)]] == [r.run_id for r in a]


def test_distributions_bounds_shapes_and_moments():
    spec = {
        "name": "dists",
        "base": case3_data(),
        "random": {
            "n": 400,
            "seed": 1,
            "params": {
                "body.mass": {"log_uniform": [20.0, 80.0]},
                "body.inertia": {"scale_uniform": [0.5, 1.5]},
                "initial_state.omega": {"uniform": [[10, 20, -30], [12, 40, -20]]},
                "initial_state.v": {"normal": {"mean": [0.0, 1.0, -1.0], "std": [0.1, 0.2, 0.3]}},
                "controller.variant": {"choice": ["visco_elastic", "embedded"]},
            },
        },
    }
    runs = expand(spec_from_mapping(spec))
    mass = np.array([r.params["body.mass"] for r in runs])
    factor = np.array([r.params["body.inertia:scale"] for r in runs])
    inertia = np.array([r.params["body.inertia"] for r in runs])
    omega = np.array([r.params["initial_state.omega"] for r in runs])
    v = np.array([r.params["initial_state.v"] for r in runs])
    assert np.all((mass >= 20) & (mass <= 80))
    assert np.mean(np.log(mass)) == pytest.approx(np.log(40.0), abs=4 * np.log(4) / np.sqrt(12 * 400))
    # one factor scales the whole inertia: its shape is kept
    assert factor.shape == (400,) and np.all((factor >= 0.5) & (factor <= 1.5))
    np.testing.assert_allclose(inertia, factor[:, None] * np.array([10.0, 8.0, 0.4]), rtol=1e-15)
    assert np.all(omega >= [10, 20, -30]) and np.all(omega <= [12, 40, -20])
    # sample means within 4 standard errors
    assert np.all(np.abs(omega.mean(axis=0) - [11, 30, -25]) <= 4 * np.array([2, 20, 10]) / np.sqrt(12 * 400))
    assert np.all(np.abs(v.mean(axis=0) - [0, 1, -1]) <= 4 * np.array([0.1, 0.2, 0.3]) / np.sqrt(400))
    np.testing.assert_allclose(v.std(axis=0), [0.1, 0.2, 0.3], rtol=0.2)
    variants = {r.config.chain.joints[0].variant for r in runs}
    assert variants == {"visco_elastic", "embedded"}


def test_dotted_keys_into_default_lists_and_matrices():
    base = case3_data()
    del base["initial_state"]["omega"]  # omega left at its default (zeros)
    base["controller"]["k_t"] = [[4100, 0, 0], [0, 4100, 0], [0, 0, 3280]]
    spec = {
        "name": "dotted",
        "base": base,
        "grid": {"initial_state.omega.1": [5.0, 7.0], "controller.k_t.2.2": [3000, 3500]},
    }
    runs = expand(spec_from_mapping(spec))
    assert len(runs) == 4
    assert runs[3].config.initial_state["body"]["omega"].tolist() == [0.0, 7.0, 0.0]
    assert paper_form(runs[3].config).gains.k_t[2, 2] == 3500 and paper_form(runs[3].config).gains.k_t[0, 0] == 4100
    assert runs[0].params == {"initial_state.omega.1": 5.0, "controller.k_t.2.2": 3000}


def test_bad_combination_is_reported_with_run_id_and_key(tmp_path):
    spec = {
        "name": "bad",
        "base": str(CASE3),
        "grid": {"controller.variant": ["embedded", "sliding"], "body.mass": [41.0, -1.0]},
    }
    with pytest.raises(SweepSpecError) as info:
        expand(spec_from_mapping(spec))
    text = str(info.value)
    assert "3 of 4 runs have an invalid configuration; nothing was run" in text
    # sliding needs k_s, which the base lacks; mass -1 is invalid for both variants
    assert "run r0001 (base case3_embedded; controller.variant='embedded', body.mass=-1.0)" in text
    assert "config key 'body.mass': found -1.0; expected a number > 0 (kg)" in text
    assert "run r0002 (base case3_embedded; controller.variant='sliding', body.mass=41.0)" in text
    assert "config key 'controller.k_s': missing" in text
    assert "run r0000" not in text

    # through the CLI: exit 1, no traceback, nothing written
    path = write_spec(tmp_path, spec)
    result = CliRunner().invoke(cli, ["sweep", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert "invalid sweep spec" in result.output and "controller.k_s" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "change, expected",
    [
        ({"zip": {"body.mass": [30, 40], "initial_state.omega.0": [1, 2, 3]}},
         "the lists have different lengths (body.mass: 2, initial_state.omega.0: 3)"),
        ({"grid": {"body.mass": 41}}, "sweep key 'grid.body.mass': found 41; expected a non-empty list of values"),
        ({"grid": {"body.mass": []}}, "sweep key 'grid.body.mass': found []; expected a non-empty list"),
        ({"random": {"n": 2, "params": {"body.mass": {"gauss": [1, 2]}}}},
         "sweep key 'random.params.body.mass.gauss': unknown key (allowed: uniform, normal, log_uniform, scale_uniform, scale_log_uniform, choice)"),
        ({"random": {"n": 2, "params": {"body.mass": {"uniform": [5, 1]}}}}, "lo > hi"),
        ({"random": {"n": 2, "params": {"body.mass": {"normal": {"mean": 1}}}}},
         "sweep key 'random.params.body.mass.normal.std': missing; expected a number >= 0"),
        ({"random": {"n": -1}}, "sweep key 'random.n': found -1; expected an integer >= 0"),
        ({"grids": {}}, "sweep key 'grids': unknown key; did you mean 'grid'?"),
        ({"grid": {"initial_state.omega": [[1, 2, 3]]}, "zip": {"initial_state.omega.0": [1]}},
         "sweep key 'zip.initial_state.omega.0': found 'initial_state.omega.0'; expected a key varied in one place only (overlaps 'grid.initial_state.omega'"),
        ({"name": "a b"}, "sweep key 'name': found 'a b'; expected letters, digits"),
        ({"base": "missing.yaml"}, "config file not found"),
        ({"convergence": {"lyapunov_ratio": 2}}, "'convergence.lyapunov_ratio': found 2; expected a number in (0, 1)"),
        ({"grid": {"a..b": [1]}}, "sweep key 'grid.a..b': segment 2 of 3 is empty (a doubled, leading or trailing '.')"),
        ({"grid": {"initial_state.theta.x": [1]}},
         "sweep key 'grid.initial_state.theta.x': 'initial_state.theta' is a list of 3; index it with 0..2, not 'x'"),
        ({"zip": {"body.1.mass": [1]}}, "sweep key 'zip.body.1.mass': 'body' is a mapping, not a list; it has no '1'"),
        ({"random": {"n": 2, "params": {"body.mass": {"uniform": [1, 2], "choice": [1]}}}},
         "sweep key 'random.params.body.mass': found {'uniform': [1, 2], 'choice': [1]}; expected a mapping with "
         "exactly one distribution"),
        ({"random": {"n": 2}}, "sweep key 'random.params': found {}; expected at least one parameter"),
        ({"random": {"n": 2, "params": {"body.mass": {"normal": {"mean": [1, 2], "std": [1, 2, 3]}}}}},
         "mean has shape (2,) and std (3,), which do not broadcast"),
        ({"random": {"n": 2, "params": {"body.mass": {"log_uniform": [0, 2]}}}}, "all > 0 (lo <= 0)"),
        ({"random": {"seeds": 1}}, "sweep key 'random.seeds': unknown key; did you mean 'random.seed'?"),
    ],
)
def test_invalid_spec_messages(tmp_path, change, expected):
    spec = {"name": "s", "base": str(CASE3), **change}
    path = write_spec(tmp_path, spec)
    with pytest.raises(SweepSpecError) as info:
        load_spec(path)
    assert expected in str(info.value)
    assert str(path) in str(info.value)


def test_overrides_apply_to_bases_and_spec(tmp_path):
    spec = {"name": "ov", "base": [str(CASE1), str(CASE3)], "grid": {"controller.k_r": [[400, 400, 320]]}}
    path = write_spec(tmp_path, spec)
    loaded = load_spec(path, ["simulation.t_end=0.3", "sweep.grid.body.mass=[30, 50]", "sweep.name=renamed"])
    runs = expand(loaded)
    assert loaded.name == "renamed" and len(runs) == 4
    assert [r.base for r in runs] == ["case1_permanent"] * 2 + ["case3_embedded"] * 2
    assert {r.config.simulation.t_end for r in runs} == {0.3}
    assert [paper_form(r.config).body.mass for r in runs] == [30.0, 50.0, 30.0, 50.0]
    with pytest.raises(SweepSpecError, match="the sweep varies 'controller.k_r'"):
        load_spec(path, ["controller.k_r=[1, 1, 1]"])


def test_shipped_example_specs():
    gains = expand(load_spec(ROOT / "configs" / "sweeps" / "gains.yaml"))
    assert len(gains) == 6
    assert [(r.config.chain.joints[0].variant, r.params["controller.k_c"][0]) for r in gains[:2]] == [
        ("visco_elastic", 4100), ("embedded", 4100)
    ]
    robust = expand(load_spec(ROOT / "configs" / "sweeps" / "robustness.yaml"))
    assert len(robust) == 200
    assert {r.base for r in robust} == {"case1_permanent", "case3_embedded"}
    for a, b in zip(robust[::2], robust[1::2]):  # paired: the same factors for both cases
        assert (a.base, b.base) == ("case1_permanent", "case3_embedded")
        assert a.params == b.params
        assert 0.5 <= a.params["body.mass:scale"] <= 1.5
        assert paper_form(a.config).body.mass == 41.0 * a.params["body.mass:scale"]
        assert paper_form(a.config).gains.k_r.tolist() == paper_form(b.config).gains.k_r.tolist()  # gains fixed


def test_dry_run_lists_runs_and_writes_nothing(tmp_path):
    path = write_spec(tmp_path, {"name": "dry", "base": str(CASE3), "grid": {"body.mass": [30.0, 50.0]}})
    result = CliRunner().invoke(cli, ["sweep", str(path), "-o", str(tmp_path / "out"), "--dry-run"])
    assert result.exit_code == 0, result.output
    ids = [r.run_id for r in expand(load_spec(path))]
    assert f"{ids[1]}  base=case3_embedded  body.mass=50.0" in result.output
    # one digest line, not one per run, with its code
    assert result.output.count("warning: W001 body.inertia") == 1 and "(2 of 2 runs)" in result.output
    assert not (tmp_path / "out").exists()


def test_worker_turns_exceptions_into_records(tmp_path):
    bad = RunTask("r0000-deadbeef", {"name": "r0000-deadbeef", "body": {}}, str(tmp_path / "x.h5"))
    result = run_chunk([bad], WorkerOptions())
    ((status, message),) = zip(result.frame["status"], result.frame["message"])
    assert status == "error" and "ConfigError" in message and "ConfigError" in result.tracebacks[bad.run_id]
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.filterwarnings("error::pandas.errors.Pandas4Warning")
def test_converged_definition(tmp_path):
    """The index's ``converged`` column is rbstab.convergence.converged of the stored row."""
    from rbstab.sweep import plan_table
    from rbstab.sweep.folder import read_index, write_table_index

    table = plan_table(spec_from_mapping({"name": "c", "base": str(CASE3),
                                          "grid": {"body.mass": [40.0, 41.0, 42.0, 43.0, 44.0]}}))
    stored = pd.DataFrame({"run": range(5), "run_id": table.ids(),
                           "status": ["success", "success", "failed", "success", "success"],
                           "lyapunov_initial": [100.0] * 5, "lyapunov_final": [0.09, 0.11, 0.0, float("nan"), -50.0],
                           "message": [""] * 5, "file": [f"r{k}.h5" for k in range(5)]})
    write_table_index(tmp_path, table, stored, {}, name="c", ratio=1e-3)
    (tmp_path / "sweep.yaml").write_text("name: c\n")
    got = list(read_index(tmp_path)["converged"])
    assert got == [True, False, False, False, False]  # r4 fell below the equilibrium's v: not there


# -- end to end -------------------------------------------------------------------------------


def test_sweep_end_to_end_rerun_and_failure(tmp_path):
    spec = {
        "name": "e2e",
        "base": str(CASE3),
        "grid": {"controller.variant": ["visco_elastic", "embedded"]},
        "zip": {
            "initial_state.theta": [[0.0, 0.0, 0.0], LOCKING_THETA, [0.0, 0.0, 0.0]],
            "initial_state.omega": [[16.0, 32.0, -16.0], LOCKING_OMEGA, [8.0, 16.0, -8.0]],
        },
    }
    path = write_spec(tmp_path, spec)
    out = tmp_path / "out"
    args = ["sweep", str(path), "-o", str(out), "-j", "2", "--no-progress", *sum((["--set", s] for s in SHORT), [])]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output  # two runs fell (gimbal lock, one per variant): results
    line = next(x for x in result.output.splitlines() if x.startswith("e2e: 6 runs (0 skipped"))  # counts by outcome
    assert ", 2 fell" in line and "could not be computed" not in line, line
    folder = out / "e2e"
    index = pd.read_csv(folder / "index.csv")
    assert len(index) == 6 and list(index["run"]) == list(range(6))
    failed = index[index["status"] == "failed"]
    assert list(failed["run"]) == [1, 4]
    assert failed["message"].str.contains("gimbal lock").all()
    assert (index.loc[index["status"] != "failed", "status"] == "success").all()
    assert not index["converged"].any()  # 0.2 s is too short for v to fall by 1e-3
    assert index["converged"].dtype == bool
    for column in ("variant", "omega_1", "theta_0", "max_abs_constraint_error_x",
                   "lyapunov_final", "wall_time", "solver_nfev", "config_hash", "file_row"):
        assert column in index.columns
    assert "omega_1" in index.columns[: list(index.columns).index("status")]
    summary = json.loads((folder / "sweep_summary.json").read_text())
    assert summary["status"] == {"success": 4, "failed": 2, "error": 0, "pending": 0}
    assert summary["n_runs"] == 6 and summary["fraction_converged"] == 0.0 and summary["n_fell"] == 2
    assert summary["parameters"]["omega_1"] == "initial_state.omega.1"
    # every row of a store file: the run id, hash of its config, the index's values
    runs = expand(load_spec(path, SHORT))
    for run, row in zip(runs, index.itertuples()):
        stored = read_chunk_rows(folder / row.file)[row.file_row]
        assert stored["run_id"] == run.run_id == row.run_id and stored["run"] == run.index
        assert stored["config_hash"] == run.config_hash == row.config_hash
        assert stored["status"] == row.status
        assert stored["max_abs_constraint_error_x"] == row.max_abs_constraint_error_x
    # the resolved spec is re-loadable and gives the same runs
    again = expand(load_spec(folder / "sweep.yaml"))
    assert [r.run_id for r in again] == [r.run_id for r in runs]
    import xarray as xr

    ds = pd.read_csv(folder / "index.csv").set_index("run_id").to_xarray()
    assert isinstance(ds, xr.Dataset) and ds.sizes["run_id"] == 6

    # rerun: everything skipped, files untouched, same exit status
    stamps = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (folder / "runs").glob("*.h5")}
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0
    assert "6 skipped, 0 run now" in result.output
    assert stamps == {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (folder / "runs").glob("*.h5")}
    pd.testing.assert_frame_equal(pd.read_csv(folder / "index.csv"), index)


def test_resume_reruns_only_stale_or_corrupt_files_and_timeout(tmp_path):
    spec = spec_from_mapping(
        {"name": "resume", "base": str(CASE3), "grid": {"initial_state.omega.0": [10.0, 12.0, 14.0]}},
        overrides=SHORT,
    )
    first = run_sweep(spec, tmp_path, jobs=1, progress=False, layout="run")
    assert first.counts["success"] == 3 and first.n_executed == 3
    runs_dir = tmp_path / "resume" / "runs"
    names = sorted(p.name for p in runs_dir.glob("*.h5"))
    reference = tmp_path / "reference.h5"
    reference.write_bytes((runs_dir / names[2]).read_bytes())
    (runs_dir / names[0]).write_bytes((runs_dir / names[1]).read_bytes())  # other config
    (runs_dir / names[2]).write_bytes(b"not an HDF5 file")  # corrupt
    (runs_dir / ".r0001-x.h5.abc.tmp").write_bytes(b"partial")  # left by a killed writer
    second = run_sweep(spec, tmp_path, jobs=1, progress=False, layout="run")
    assert (second.n_skipped, second.n_executed) == (1, 2)
    assert second.counts["success"] == 3
    assert not list(runs_dir.glob(".*.tmp"))
    data_equal(runs_dir / names[2], reference)
    # --retry-failed with a tiny per-run timeout: a failed run is data, the sweep goes on
    third = run_sweep(spec, tmp_path, jobs=1, progress=False, retry_failed=True, timeout=1e-9, layout="run")
    assert third.n_skipped == 3  # all succeeded before: nothing to retry
    other = spec_from_mapping(
        {"name": "timeout", "base": str(CASE3), "grid": {"initial_state.omega.0": [10.0, 12.0]}},
        overrides=SHORT,
    )
    timed = run_sweep(other, tmp_path, jobs=2, progress=False, timeout=1e-9)
    assert timed.counts == {"success": 0, "failed": 2, "error": 0, "pending": 0}
    assert all("timeout" in message for _, _, message in timed.problems)


def test_the_exit_status_says_whether_every_run_was_computed(tmp_path):
    """0 when every run was computed, whatever its physics (test_sweep_end_to_end_rerun_and_failure:
    runs that fell); 3 when runs could not be computed (a wall-time limit), naming how many;
    errors count as not computed."""
    from rbstab.sweep.runner import SweepOutcome

    spec = {"name": "limits", "base": str(CASE3), "grid": {"initial_state.omega.0": [10.0, 12.0]}}
    path = write_spec(tmp_path, spec)
    sets = sum((["--set", s] for s in SHORT), [])
    done = CliRunner().invoke(cli, ["sweep", str(path), "-o", str(tmp_path / "ok"), "--no-progress", *sets])
    assert done.exit_code == 0, done.output
    timed = CliRunner().invoke(cli, ["sweep", str(path), "-o", str(tmp_path / "t"), "--no-progress", "--timeout",
                                     "1e-9", *sets])
    assert timed.exit_code == 3, timed.output
    assert ": 2 could not be computed (" in timed.output
    assert "2 of 2 runs could not be computed" in timed.output and "Traceback" not in timed.output
    outcome = SweepOutcome("x", tmp_path, 7, counts={"success": 2, "failed": 4, "error": 1}, n_fell=3)
    assert (outcome.n_failed, outcome.n_not_computed) == (5, 2)


def test_busy_folder_is_refused(tmp_path):
    from rbstab.sweep.runner import _lock

    spec = spec_from_mapping({"name": "busy", "base": str(CASE3)}, overrides=SHORT)
    (tmp_path / "busy").mkdir()
    with _lock(tmp_path / "busy"):
        with pytest.raises(SweepBusyError, match="another rbstab sweep"):
            run_sweep(spec, tmp_path, jobs=1, progress=False)


# -- Dask ---------------------------------------------------------------------------------------


def test_dask_executor_gives_identical_results(tmp_path):
    pytest.importorskip("distributed", reason='the dask executor needs "distributed" (pip install ".[dask]")')
    from distributed import LocalCluster

    spec = {
        "name": "dask",
        "base": str(CASE3),
        "grid": {"controller.variant": ["visco_elastic", "embedded"]},
        "zip": {"initial_state.theta": [[0.0, 0.0, 0.0], LOCKING_THETA],
                "initial_state.omega": [[16.0, 32.0, -16.0], LOCKING_OMEGA]},
    }
    path = write_spec(tmp_path, spec)
    sets = sum((["--set", s] for s in SHORT), [])
    local = CliRunner().invoke(cli, ["sweep", str(path), "-o", str(tmp_path / "local"), "-j", "2", "--no-progress", *sets])
    assert local.exit_code == 0, local.output
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        result = CliRunner().invoke(
            cli, ["sweep", str(path), "-o", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address,
                  "--no-progress", *sets],
        )
    assert result.exit_code == 0, result.output
    assert "Dask scheduler" in result.output
    # store files written by the parent from the workers' bytes: the same runs, the same bits
    ia = pd.read_csv(tmp_path / "local" / "dask" / "index.csv").drop(columns=["wall_time", "file"])
    ib = pd.read_csv(tmp_path / "dask" / "dask" / "index.csv").drop(columns=["wall_time", "file"])
    pd.testing.assert_frame_equal(ia, ib)
    from rbstab import open_sweep

    da, db = open_sweep(tmp_path / "local" / "dask"), open_sweep(tmp_path / "dask" / "dask")
    assert da.sizes["run"] == 4 and np.array_equal(da.lyapunov.values, db.lyapunov.values, equal_nan=True)


def test_dask_missing_gives_install_hint(monkeypatch):
    from rbstab.sweep.executors import DaskExecutor

    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ExecutorError, match=r'pip install "rbstab\[dask\]"'):
        DaskExecutor("tcp://127.0.0.1:1")


def test_dask_unreachable_scheduler_is_a_clean_cli_error(tmp_path):
    pytest.importorskip("distributed", reason='the dask executor needs "distributed" (pip install ".[dask]")')
    path = write_spec(tmp_path, {"name": "nosched", "base": str(CASE3)})
    from rbstab.sweep import executors

    original = executors.DaskExecutor.__init__

    def quick(self, address=None, **kw):
        original(self, address, connect_timeout=1.0)

    import unittest.mock as mock

    with mock.patch.object(executors.DaskExecutor, "__init__", quick):
        result = CliRunner().invoke(cli, ["sweep", str(path), "-o", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:9"])
    assert result.exit_code == 4  # a fault of the machine
    assert "cannot connect to the Dask scheduler at tcp://127.0.0.1:9" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "o").exists()


def test_a_late_invalid_run_stops_the_sweep_before_anything_runs(tmp_path):
    """The whole run table is validated before anything is written: an invalid run at the
    end of the list stops the sweep with nothing run; the fixed spec runs every run."""
    masses = [41.0, 42.0, 43.0, 44.0, -1.0, 46.0]
    spec = {"name": "late", "base": str(CASE3), "grid": {"body.mass": masses}}
    loaded = spec_from_mapping(spec, overrides=SHORT)
    with pytest.raises(SweepSpecError) as info:
        run_sweep(loaded, tmp_path, jobs=1, chunk_size=2, progress=False)
    text = str(info.value)
    assert "1 of 6 runs have an invalid configuration; nothing was run" in text
    assert "run r0004 (base case3_embedded; body.mass=-1.0): config key 'body.mass': found -1.0" in text
    assert not (tmp_path / "late").exists()
    fixed = spec_from_mapping({**spec, "grid": {"body.mass": masses[:4] + [45.0, 46.0]}}, overrides=SHORT)
    again = run_sweep(fixed, tmp_path, jobs=1, chunk_size=2, progress=False)
    assert (again.n_skipped, again.n_executed, again.counts["success"]) == (0, 6, 6)
    assert again.stale_files == []


def test_parameter_columns_and_time_grids_come_from_the_table():
    from rbstab.sweep import plan_table
    from rbstab.sweep.folder import parameter_columns

    for path in ("gains.yaml", "robustness.yaml"):
        loaded = load_spec(ROOT / "configs" / "sweeps" / path)
        runs, table = expand(loaded), plan_table(loaded)
        assert list(table.parameters().items()) == list(parameter_columns(r.params for r in runs).items())
        assert table.time_grids() == {(r.config.simulation.t_end, r.config.simulation.n_samples) for r in runs}
    varied = spec_from_mapping({"name": "t", "base": str(CASE3), "grid": {"simulation.t_end": [0.1, 0.2]}})
    assert len(plan_table(varied).time_grids()) == 2


def test_sweep_size_and_base_files_are_bounded(tmp_path):
    """A spec of more than MAX_RUNS runs is refused before anything is planned (with the
    memory it would take), and a base that is not a regular file is refused in words."""
    from rbstab.sweep.spec import MAX_RUNS

    huge = {"name": "huge", "base": str(CASE3),
            "random": {"n": MAX_RUNS + 1, "params": {"initial_state.omega": {"uniform": [0, 1]}}}}
    with pytest.raises(SweepSpecError, match=f"the sweep has {MAX_RUNS + 1} runs .*; at most {MAX_RUNS}"):
        spec_from_mapping(huge)
    with pytest.raises(SweepSpecError, match="sweep key 'base': found '/dev/zero'; .*not a regular file"):
        spec_from_mapping({"name": "dev", "base": "/dev/zero"})


def test_sweep_index_is_the_table_and_the_stored_rows(tmp_path):
    """An index row is the run (id, index, base, parameters, variant from the table), its
    stored row but what the index leaves out, its file under runs/ and whether it
    converged; a run without a stored row is an error (with the worker's message) or
    pending. Text with commas and quotes reads back as written."""
    from rbstab.sweep import plan_table
    from rbstab.sweep.folder import read_index, write_table_index

    table = plan_table(spec_from_mapping({"name": "ix", "base": str(CASE3), "grid": {
        "controller.variant": ["embedded", "visco_elastic"], "body.mass": [40.0, 41.0, 42.0]}}))
    ids = table.ids()
    stored = pd.DataFrame({
        "run": [0, 1, 2, 3], "run_id": ids[:4], "variant": ["stale"] * 4,
        "status": ["success", "success", "failed", "success"],
        "message": [f'm{k}, with a "quoted" comma' for k in range(4)], "wall_time": [0.5, 1.5, 2.5, 3.5],
        "lyapunov_initial": [10.0] * 4, "lyapunov_final": [0.1, 5.0, None, 0.05],
        "final_d_x": [0.0, 0.25, 0.5, None], "config": ["{}"] * 4, "created": ["t"] * 4,
        "file": [None, "chunk-1.h5", None, "chunk-3.h5"], "file_row": [None, 0, None, 1]})
    summary, problems = write_table_index(tmp_path, table, stored, {ids[4]: "ValueError: boom"}, name="ix",
                                          ratio=0.01)
    (tmp_path / "sweep.yaml").write_text("name: ix\n")
    index = read_index(tmp_path)
    assert list(index["run_id"]) == ids and list(index["run"]) == list(range(6))
    assert list(index["mass"]) == [40.0, 41.0, 42.0] * 2
    assert list(index["variant"]) == ["embedded"] * 3 + ["visco_elastic"] * 3  # the table's, not the stored row's
    assert list(index["status"]) == ["success", "success", "failed", "success", "error", "pending"]
    assert list(index["converged"]) == [True, False, False, True, False, False]
    assert list(index["file"].fillna("")) == ["", "runs/chunk-1.h5", "", "runs/chunk-3.h5", "", ""]
    assert list(index["message"][:2]) == ['m0, with a "quoted" comma', 'm1, with a "quoted" comma']
    assert index["message"][4] == "ValueError: boom" and index["message"][5].startswith("not run yet")
    assert "config" not in index and "created" not in index
    assert list(index.columns[:4]) == ["run_id", "run", "base", "mass"] and index.columns[4] == "variant"
    assert summary["status"] == {"success": 3, "failed": 1, "error": 1, "pending": 1}
    assert summary["n_converged"] == 2 and summary["parameters"] == {"variant": "controller.variant",
                                                                      "mass": "body.mass"}
    assert problems == [(ids[k], s, m) for k, s, m in zip(range(2, 6), ["failed", "success", "error", "pending"],
                                                          index["message"][2:]) if s != "success"]


def test_index_rows_in_any_order(tmp_path):
    """The index is the same whether the stored rows come in the order of the runs (taken
    as they are) or in any other (gathered); a run's later row counts, also where the
    sweep's chunks are put in the order of their runs (runner._rows_of)."""
    from rbstab.sweep import plan_table
    from rbstab.sweep.folder import write_table_index
    from rbstab.sweep.runner import _rows_of

    table = plan_table(spec_from_mapping({"name": "ix", "base": str(CASE3), "grid": {"body.mass": [40.0, 41.0, 42.0,
                                                                                                   43.0]}}))
    ids = table.ids()

    def rows(runs, final):
        return pd.DataFrame({"run": runs, "run_id": [ids[r] for r in runs], "status": "success", "message": "",
                             "lyapunov_initial": 10.0, "lyapunov_final": final, "solver_nfev": [7 * r for r in runs]})

    def index(name, frames):
        folder = tmp_path / name
        folder.mkdir()
        write_table_index(folder, table, _rows_of(frames), {}, name="ix", ratio=0.01)
        return (folder / "index.csv").read_text(), pd.read_feather(folder / "index.arrow")

    in_order = index("in-order", [rows([0, 1], [1.0, 2.0]), rows([2, 3], [3.0, 4.0])])
    shuffled = index("shuffled", [rows([3, 2], [4.0, 3.0]), rows([1, 0], [2.0, 1.0])])
    later = index("later", [rows([1, 2, 3], [9.0, 9.0, 9.0]), rows([0, 1], [1.0, 2.0]), rows([2, 3], [3.0, 4.0])])
    assert list(in_order[1]["lyapunov_final"]) == [1.0, 2.0, 3.0, 4.0]
    assert list(in_order[1]["solver_nfev"]) == [0, 7, 14, 21]
    for other in (shuffled, later):
        assert other[0] == in_order[0]
        pd.testing.assert_frame_equal(other[1], in_order[1])


def test_run_coordinates_name_every_entry():
    """Vectors, matrices and scale factors of a run's varied values as coordinates."""
    from rbstab.sweep.folder import run_coords

    coords = run_coords({"controller.k_c": [1.0, 2.0, 3.0], "body.inertia": [[1, 0, 0], [0, 2, 0], [0, 0, 3]],
                         "body.mass": 41.0, "body.mass:scale": 1.1, "body.inertia.0:scale": 0.5})
    assert coords["k_c_0"] == ("controller.k_c.0", 1.0) and coords["k_c_2"] == ("controller.k_c.2", 3.0)
    assert coords["inertia_1_1"] == ("body.inertia.1.1", 2) and coords["inertia_2_0"] == ("body.inertia.2.0", 0)
    assert coords["mass"] == ("body.mass", 41.0) and coords["mass_scale"] == ("body.mass:scale", 1.1)
    assert coords["inertia_0_scale"] == ("body.inertia.0:scale", 0.5)
    assert len(coords) == 3 + 9 + 3


@pytest.mark.parametrize("vary", ["initial_state", "controller"])
def test_planned_configs_equal_a_whole_validation_of_each_run(vary):
    """Whether runs share their base's validation (only the initial state varies) or are
    validated one by one, each planned config is what validating that run alone gives:
    the same resolved mapping, hash and physics."""

    from rbstab.config import config_from_mapping

    params = {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}
    if vary == "controller":
        params["controller.k_t"] = {"scale_uniform": [0.5, 2.0]}
    spec = spec_from_mapping({"name": "p", "base": [str(CASE3), str(CASE1)],
                              "grid": {"initial_state.theta.0": [0.0, 0.1]},
                              "random": {"n": 3, "seed": 2, "params": params}})
    runs = expand(spec)
    assert len(runs) == 12 and {r.config.chain.joints[0].variant for r in runs} == {"embedded", "permanent"}
    for run in runs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            alone = config_from_mapping(run.config.resolved)
        assert alone.resolved == run.config.resolved
        assert np.array_equal(paper_form(alone).gains.k_t, paper_form(run.config).gains.k_t)
        assert all(np.array_equal(alone.initial_state["body"][k], run.config.initial_state["body"][k])
               for k in alone.initial_state["body"])
        assert alone.warnings == run.config.warnings
