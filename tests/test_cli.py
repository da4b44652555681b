"""The command line end to end: paper configs -> HDF5 files read back with xarray."""

from __future__ import annotations

import hashlib
import warnings

import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner
import yaml

from conftest import PAPER_CONFIGS, ROOT
from rbstab.io.hdf5 import read_summary
from rbstab_cli.main import cli

VECTOR_VARIABLES = [
    "theta", "omega", "position", "velocity", "constraint_error", "constraint_rate",
    "constraint_force", "force_h", "torque_n",
]
SCALAR_VARIABLES = [
    "lyapunov", "lyapunov_rate", "lyapunov_rate_numerical", "lyapunov_translational",
    "lyapunov_rotational", "lyapunov_constraint", "lyapunov_gravity",
]


@pytest.fixture(scope="module")
def paper_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    result = CliRunner().invoke(cli, ["run", *map(str, PAPER_CONFIGS), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out, result.output


def test_paper_configs_exist():
    names = sorted(p.stem for p in PAPER_CONFIGS)
    assert names == ["case1_permanent", "case2_visco_elastic", "case3_embedded"]


def test_run_writes_one_file_per_paper_case(paper_results):
    out, output = paper_results
    for stem in ("case1_permanent", "case2_visco_elastic", "case3_embedded"):
        assert (out / f"{stem}.h5").is_file()
        assert f"{stem}: success" in output
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*"))


@pytest.mark.parametrize("stem", ["case1_permanent", "case2_visco_elastic", "case3_embedded"])
def test_result_opens_in_xarray_with_units_and_descriptions(paper_results, stem):
    out, _ = paper_results
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = xr.open_dataset(out / f"{stem}.h5", engine="h5netcdf")
    with ds:
        assert set(ds.dims) == {"time", "axis"}
        assert list(ds.axis.values) == ["x", "y", "z"]
        assert ds.time.attrs["units"] == "s"
        for name in VECTOR_VARIABLES:
            assert ds[name].dims == ("time", "axis"), name
        for name in SCALAR_VARIABLES:
            assert ds[name].dims == ("time",), name
        for name, var in ds.data_vars.items():
            assert var.attrs["units"] and var.attrs["description"], name
        assert ("controller_state" in ds) == (stem == "case3_embedded")
        assert ds.sizes["time"] == 2001
        for key in ("config", "rbstab_version", "git_commit", "command_line", "created", "solver_nfev", "wall_time"):
            assert key in ds.attrs, key
        # the Lyapunov trace: dv/dt <= 0 everywhere, v non-increasing, analytic == numerical
        rate = ds.lyapunov_rate.values
        v = ds.lyapunov.values
        assert rate.max() <= 1e-9 * np.abs(rate).max()
        assert np.diff(v).max() <= 1e-9 * v[0]
        assert v[-1] < 1e-3 * v[0]
        assert ds.attrs["summary_lyapunov_rate_check"] == "pass"
        np.testing.assert_allclose(ds.lyapunov_rate_numerical, rate, atol=1e-3 * np.abs(rate).max())
        # the sum of the terms is v
        terms = sum(ds[k].values for k in ("lyapunov_translational", "lyapunov_rotational", "lyapunov_constraint", "lyapunov_gravity"))
        np.testing.assert_allclose(terms, v, rtol=1e-12, atol=1e-9)


def test_summary_attributes_match_the_data(paper_results):
    out, _ = paper_results
    path = out / "case3_embedded.h5"
    info = read_summary(path)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        np.testing.assert_allclose(info["summary"]["max_abs_constraint_error"], np.abs(ds.constraint_error).max("time"))
        np.testing.assert_allclose(info["summary"]["final_theta"], ds.theta[-1])
        assert info["summary"]["max_lyapunov_rate"] == pytest.approx(float(ds.lyapunov_rate.max()))
    assert info["status"] == "success" and info["variant"] == "embedded"


def test_case1_pivot_stays_fixed(paper_results):
    out, _ = paper_results
    with xr.open_dataset(out / "case1_permanent.h5", engine="h5netcdf") as ds:
        assert float(np.abs(ds.constraint_error).max()) < 1e-12
        assert float(np.abs(ds.constraint_force).max()) > 100.0  # the pivot does work to hold C


def test_show_prints_the_summary(paper_results):
    out, _ = paper_results
    result = CliRunner().invoke(cli, ["show", str(out / "case2_visco_elastic.h5")])
    assert result.exit_code == 0, result.output
    assert "visco_elastic" in result.output and "max_abs_constraint_error" in result.output


def test_show_rejects_a_file_that_is_not_a_result(tmp_path):
    bogus = tmp_path / "x.h5"
    bogus.write_bytes(b"not hdf5")
    result = CliRunner().invoke(cli, ["show", str(bogus), str(tmp_path / "missing.h5")])
    assert result.exit_code != 0
    assert "not an HDF5 file" in result.output and "no such result file" in result.output
    assert "Traceback" not in result.output


def test_validate_accepts_every_shipped_config():
    configs = sorted((ROOT / "configs").glob("*/*.yaml"))
    configs = [c for c in configs if c.parent.name in ("paper", "examples")]
    result = CliRunner().invoke(cli, ["validate", *map(str, configs)])
    assert result.exit_code == 0, result.output
    assert result.output.count("ok:") == len(configs)


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_bad_config_exits_nonzero_without_traceback_and_keeps_results(tmp_path):
    config = PAPER_CONFIGS[0]
    good = CliRunner().invoke(cli, ["run", str(config), "-o", str(tmp_path), "--set", "simulation.t_end=0.05", "--set", "simulation.n_samples=51"])
    assert good.exit_code == 0, good.output
    written = tmp_path / f"{config.stem}.h5"
    before = _digest(written)
    bad = CliRunner().invoke(cli, ["run", str(config), "-o", str(tmp_path), "--set", "body.mass=-1"])
    assert bad.exit_code != 0
    assert "body.mass" in bad.output and "-1" in bad.output
    assert "Traceback" not in bad.output and bad.exception is None or isinstance(bad.exception, SystemExit)
    assert _digest(written) == before


def test_one_bad_config_means_nothing_runs(tmp_path):
    runner = CliRunner()
    bad = tmp_path / "bad.yaml"
    bad.write_text((PAPER_CONFIGS[0]).read_text().replace("variant: permanent", "variant: permanant"))
    result = runner.invoke(cli, ["run", str(PAPER_CONFIGS[1]), str(bad), "-o", str(tmp_path / "out")])
    assert result.exit_code != 0
    assert "permanant" in result.output
    assert not (tmp_path / "out").exists()


def test_gimbal_lock_run_is_written_as_failed_and_is_a_result(tmp_path):
    result = CliRunner().invoke(
        cli,
        [
            "run", str(PAPER_CONFIGS[1]), "-o", str(tmp_path), "--set", "name=locked",
            "--set", "initial_state.theta=[0, 1.5, 0]", "--set", "initial_state.omega=[0, 40, 0]",
            "--set", "controller.k_r=[1, 1, 1]", "--set", "simulation.t_end=0.5", "--set", "simulation.n_samples=51",
        ],
    )
    assert result.exit_code == 0, result.output  # it fell: a result of its physics, not a fault
    assert "locked: failed, fell (" in result.output and "gimbal lock" in result.output
    info = read_summary(tmp_path / "locked.h5")
    assert info["status"] == "failed" and "gimbal lock" in info["message"]


def test_method_option_and_set_override(tmp_path):
    result = CliRunner().invoke(
        cli,
        ["run", str(PAPER_CONFIGS[2]), "-o", str(tmp_path), "--method", "Radau", "--set", "name=radau",
         "--set", "simulation.t_end=0.1", "--set", "simulation.n_samples=11", "--set", "simulation.rtol=1e-6"],
    )
    assert result.exit_code == 0, result.output
    with xr.open_dataset(tmp_path / "radau.h5", engine="h5netcdf") as ds:
        assert "method: Radau" in ds.attrs["config"]
        assert ds.sizes["time"] == 11


def test_interrupted_write_leaves_no_file(tmp_path, monkeypatch):
    import h5py

    from rbstab.config import load_config
    from rbstab.io.hdf5 import write_result
    from rbstab.simulator import simulate

    config = load_config(PAPER_CONFIGS[1], ["simulation.t_end=0.02", "simulation.n_samples=5"])
    result = simulate(config)

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(h5py.h5ds, "attach_scale", boom)  # mid-write: datasets exist
    with pytest.raises(KeyboardInterrupt):
        write_result(result, tmp_path / "x.h5")
    assert list(tmp_path.iterdir()) == []


def test_a_run_that_fails_at_once_has_no_rate_check(tmp_path):
    result = CliRunner().invoke(
        cli,
        ["run", str(PAPER_CONFIGS[1]), "-o", str(tmp_path), "--set", "name=instant",
         "--set", "initial_state.theta=[0, 1.5695, 0]", "--set", "initial_state.omega=[0, 50, 0]",
         "--set", "simulation.t_end=0.5", "--set", "simulation.n_samples=51"],
    )
    assert result.exit_code == 0, result.output  # it fell at once
    info = read_summary(tmp_path / "instant.h5")
    assert info["status"] == "failed"
    assert info["summary"]["lyapunov_rate_check"] == "n/a"


def _console_script(*args: str, cwd=None):
    """The installed ``rbstab`` entry point (``rbstab_cli.main:main``) in a subprocess."""
    import subprocess
    import sys

    code = "import sys; from rbstab_cli.main import main; sys.argv[0] = 'rbstab'; main()"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd)


def test_console_script_passes_on_exit_status_and_flushes_output(tmp_path):
    """The console script passes on the command's exit status and everything it printed."""
    version = _console_script("--version")
    assert version.returncode == 0 and "rbstab, version" in version.stdout

    missing = _console_script("validate", str(tmp_path / "missing.yaml"))
    assert missing.returncode != 0
    assert "config file not found" in missing.stderr and "Traceback" not in missing.stderr

    out = tmp_path / "out"
    run = _console_script("run", str(ROOT / "configs" / "paper" / "case1_permanent.yaml"), "-o", str(out),
                          "--set", "simulation.t_end=0.1", "--set", "simulation.n_samples=21")
    assert run.returncode == 0, run.stderr
    assert "case1_permanent" in run.stdout
    summary = read_summary(out / "case1_permanent.h5")
    assert summary["status"] == "success" and summary["summary"]["t_final"] == pytest.approx(0.1)


def test_sweep_chunk_size_help_gives_the_defaults():
    """``rbstab sweep --help`` states the chunk sizes the sweep takes by default."""
    from click.testing import CliRunner

    from rbstab.engine.registry import get_engine
    from rbstab.sweep.runner import STORE_CHUNK_SIZE, SUMMARY_CHUNK_SIZE
    from rbstab_cli.main import cli

    text = " ".join(CliRunner().invoke(cli, ["sweep", "--help"]).output.split())
    assert (f"[default: {STORE_CHUNK_SIZE} runs a store file, {SUMMARY_CHUNK_SIZE} with --store summary" in text)
    assert (f"{get_engine('compiled').chunk_size} with the compiled engine, {get_engine('scipy').chunk_size} "
            "with scipy]") in text


def test_analyze_compiles_what_an_analysis_adds_to_the_engine(tmp_path, monkeypatch):
    """rbstab analyze asks for the analysis's kernels (the tree's rest state and rates) with
    the one-body group for the paper's one body, and for the tree's group (not the one
    body's) for a tree."""
    import rbstab.engine

    asked = []
    monkeypatch.setattr(rbstab.engine, "ensure_compiled", lambda say=None, **groups: asked.append(groups))
    for config, chain in ((PAPER_CONFIGS[0], False), (ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", True)):
        asked.clear()
        result = CliRunner().invoke(cli, ["analyze", str(config), "--no-certificate", "--no-simulation", "-o",
                                          str(tmp_path / config.stem)])
        assert result.exit_code == 0, result.output
        assert asked[0] == {"one_body": not chain, "chain": chain, "solve_ivp": False, "analysis": True}, config.name


def test_run_compiles_the_kernel_groups_of_the_models_it_runs(tmp_path, monkeypatch):
    """rbstab run asks for the one-body group where a model is the paper's one body, in
    either spelling, and for the tree's group only where a model is another tree (a paper
    case's cold start compiles the one-body group and the analysis's rest state, which its
    W008 check linearises; a tree's, the tree's group alone), for the sign law's only
    where a one-body config has it, and for scipy's methods' kernels only where a run goes to
    them (an implicit method)."""
    import rbstab.engine

    asked = []
    monkeypatch.setattr(rbstab.engine, "ensure_compiled", lambda say=None, **groups: asked.append(groups))
    short = ["--set", "simulation.t_end=0.01", "--set", "simulation.n_samples=3"]
    one_body = {"one_body": True, "sign_law": False, "chain": False, "solve_ivp": False, "analysis": True}
    tree = {"one_body": False, "sign_law": False, "chain": True, "solve_ivp": False, "analysis": True}
    as_tree = tmp_path / "as_tree.yaml"  # the paper's one body written as a tree: its model is one body's
    as_tree.write_text(yaml.safe_dump({
        "name": "as_tree", "gravity": [0, 0, 0],
        "bodies": [{"name": "b", "mass": 1.0, "inertia": [1.0, 1.0, 1.0]}],
        "joints": [{"name": "j", "parent": "ground", "child": "b", "variant": "visco_elastic",
                    "parent_point": [0, 0, 0], "child_point": [0, 0, 0], "k_r": [1, 1, 1], "l_r": [1, 1, 1],
                    "k_c": [1, 1, 1], "l_c": [1, 1, 1]}]}))
    for config, expected in ((PAPER_CONFIGS[0], one_body), (ROOT / "configs" / "examples" / "sliding.yaml", one_body),
                             (ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", tree), (as_tree, one_body)):
        asked.clear()
        result = CliRunner().invoke(cli, ["run", str(config), *short, "-o", str(tmp_path / config.stem)])
        assert result.exit_code == 0, result.output
        assert asked[0] == expected, config.name  # the command's own call, before any run
    asked.clear()
    result = CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "examples" / "sliding.yaml"), *short,
                                      "--set", "controller.boundary_layer=0", "-o", str(tmp_path / "sign")])
    assert result.exit_code == 0, result.output
    assert asked[0] == {**one_body, "sign_law": True}
    stance = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    for config, expected in ((PAPER_CONFIGS[0], one_body), (stance, tree)):
        asked.clear()
        result = CliRunner().invoke(cli, ["run", str(config), *short, "--method", "Radau", "-o", str(tmp_path / "r")])
        assert result.exit_code == 0, result.output
        assert asked[0] == {**expected, "solve_ivp": True}, config.name
