"""rbstab sweep of chains: keys of bodies, joints and initial states by name or index, store
files holding what rbstab run writes (traces along body and joint), the index with the joints'
figures under their names, resume, open_sweep over the grid, and the refusals (a key of another
kind or naming no body, a spec mixing chains and one-body configs, store files of different
chains' traces, an invalid value)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr
import yaml
from click.testing import CliRunner

import rbstab
from rbstab.sweep.folder import parameter_name
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
STANCE = str(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml")
SHORT = ["--set", "simulation.t_end=0.5", "--set", "simulation.n_samples=501"]
GRID = ["--grid", "initial_state.trunk.theta.0=-0.1,0.1", "--grid", "joints.hip.k_r.0=400,600"]


def largest_error(index, *joints):
    """max |E_j,i| over the axes of the joints ``joints``, from a chain sweep's columns."""
    return index[[f"max_abs_constraint_error_{j}_{a}" for j in joints for a in "xyz"]].abs().max(axis=1)


def test_a_chain_sweep_writes_what_rbstab_run_writes_and_resumes(tmp_path):
    out = tmp_path / "results"
    args = ["sweep", STANCE, *GRID, *SHORT, "--store", "full", "-j", "1", "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    folder = out / "stance_ankle_hip"
    index = pd.read_csv(folder / "index.csv")
    assert index["variant"].tolist() == ["chain"] * 4 and set(index["status"]) == {"success"}
    assert {"trunk_theta_0", "hip_k_r_0", "max_abs_constraint_error_ankle_x", "max_abs_constraint_error_hip_z"
            } <= set(index.columns)  # per joint and axis, as one body's per axis
    assert (largest_error(index, "hip") < 1e-8).all()  # a permanent joint: rounding
    assert {"final_theta_trunk_x", "fraction_saturated_torque_n_ankle_x", "fraction_saturated_force_h_legs_z",
            "time_lyapunov_rising"} <= set(index.columns)  # every figure of one body's runs, per body or joint
    assert sorted(zip(index["trunk_theta_0"], index["hip_k_r_0"])) == [(-0.1, 400), (-0.1, 600), (0.1, 400), (0.1, 600)]

    row = index.iloc[3]
    one = tmp_path / "one"
    alone = CliRunner().invoke(cli, ["run", STANCE, *SHORT, "--set", f"initial_state.trunk.theta.0={row.trunk_theta_0}",
                                     "--set", f"joints.hip.k_r.0={row.hip_k_r_0}", "-o", str(one)])
    assert alone.exit_code == 0, alone.output
    assert Path(row.file).name.startswith("chunk-")  # store files: the runs' traces along body and joint
    stored = rbstab.open_sweep(folder)
    assert list(stored["joint"].values) == ["ankle", "hip"] and list(stored["body"].values) == ["legs", "trunk"]
    assert stored["theta"].dims == ("run", "time", "body", "axis")
    assert stored["constraint_error"].dims == ("run", "time", "joint", "axis")
    a = stored.sel(run=row.run)
    with xr.open_dataset(one / "stance_ankle_hip.h5", engine="h5netcdf") as b:
        assert b["theta"].dims == ("time", "body", "axis")
        for name in ("theta", "omega", "joint_theta", "torque_n", "constraint_error", "lyapunov",
                     "lyapunov_rate"):
            np.testing.assert_array_equal(a[name].values, b[name].values)
        assert b.attrs["summary_lyapunov_final"] == pytest.approx(row.lyapunov_final, rel=1e-12)

    again = CliRunner().invoke(cli, args)
    assert again.exit_code == 0, again.output
    assert "4 skipped" in again.output or "skipped 4" in again.output, again.output
    ds = rbstab.open_sweep(folder, grid=True)
    assert dict(ds.sizes) == {"trunk_theta_0": 2, "hip_k_r_0": 2, "time": 501, "body": 2, "joint": 2, "axis": 3}
    assert ds["lyapunov_final"].sel(trunk_theta_0=row.trunk_theta_0, hip_k_r_0=row.hip_k_r_0) == pytest.approx(
        row.lyapunov_final, rel=1e-12)

    report = CliRunner().invoke(cli, ["report", str(folder), "-o", str(tmp_path / "report")])
    assert report.exit_code == 0, report.output
    assert (tmp_path / "report" / "figures" / "sweep_stance_ankle_hip_heatmap_lyapunov_final.png").exists()
    lines = (tmp_path / "report" / "summary.md").read_text().splitlines()  # the store rows' per-joint figures
    cells = lambda line: [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]  # noqa: E731  (not at "\\|")
    header = cells(next(line for line in lines if line.startswith("| run_id")))
    values = cells(next(line for line in lines if line.startswith(f"| {row.run_id}")))
    largest = float(values[next(i for i, name in enumerate(header) if name.startswith("max \\|E\\|"))])
    assert largest == pytest.approx(largest_error(index, "ankle", "hip")[3], rel=1e-3)

    # a joint's own figure, and a figure over the joints, as --metric; a joint the chain lacks refused in one line
    metrics = ["--metric", "max_abs_constraint_error_hip", "--metric", "max_abs_constraint_error",
               "--metric", "fraction_saturated_torque_n_x", "--metric", "max_abs_constraint_error_hip_z"]
    by_joint = CliRunner().invoke(cli, ["report", str(folder), *metrics, "-o", str(tmp_path / "by_joint")])
    assert by_joint.exit_code == 0, by_joint.output
    table = pd.read_csv(tmp_path / "by_joint" / "sweep_stance_ankle_hip.csv")
    np.testing.assert_array_equal(table["report:max_abs_constraint_error_hip"], largest_error(index, "hip"))
    np.testing.assert_array_equal(table["report:max_abs_constraint_error_hip_z"], index["max_abs_constraint_error_hip_z"])
    np.testing.assert_array_equal(table["report:max_abs_constraint_error"],  # the largest over the joints
                                  largest_error(index, "ankle", "hip"))
    np.testing.assert_array_equal(table["report:fraction_saturated_torque_n_x"],  # the largest over the joints
                                  index[["fraction_saturated_torque_n_ankle_x", "fraction_saturated_torque_n_hip_x"]
                                        ].max(axis=1))
    knee = CliRunner().invoke(cli, ["report", str(folder), "--metric", "max_abs_constraint_error_knee", "-o",
                                    str(tmp_path / "knee")])
    assert knee.exit_code != 0 and "Traceback" not in knee.output and not (tmp_path / "knee").exists()
    assert "'max_abs_constraint_error_knee'" in knee.output and "max_abs_constraint_error_hip" in knee.output, knee.output


def test_a_chain_sweep_of_summaries_writes_store_files_with_the_run_layouts_figures(tmp_path):
    """--store summary: the runs of a chain go into store files (the default layout), one
    integration call for the runs of one chain; the index's figures are those of a file
    per run, bit for bit, two chains share the files, and a rerun skips every run."""
    spec = tmp_path / "two.yaml"
    spec.write_text(f"name: two\nbase: [{STANCE}, {ROOT / 'configs' / 'examples' / 'double_pendulum.yaml'}]\n"
                    "grid:\n  simulation.rtol: [1.0e-8, 1.0e-7]\n")
    indexes = {}
    for layout in ("chunk", "run"):
        out = tmp_path / layout
        args = ["sweep", str(spec), *SHORT, "--store", "summary", "-j", "1", "-o", str(out)]
        result = CliRunner().invoke(cli, args + ([] if layout == "chunk" else ["--layout", "run"]))
        assert result.exit_code == 0, result.output
        indexes[layout] = pd.read_csv(out / "two" / "index.csv")
        files = sorted(p.name for p in (out / "two" / "runs").iterdir())
        assert all(name.startswith("chunk-") for name in files) == (layout == "chunk"), files
    chunk, run = indexes["chunk"], indexes["run"]
    assert chunk["run_id"].tolist() == run["run_id"].tolist() and set(chunk["status"]) == {"success"}
    figures = [c for c in run.columns if c.startswith(("max_abs_constraint_error_", "lyapunov_",
                                                       "final_", "fraction_saturated_", "time_lyapunov_rising"))]
    assert {"max_abs_constraint_error_hip_x", "max_abs_constraint_error_elbow_z", "lyapunov_final", "final_omega_trunk_z",
            "fraction_saturated_torque_n_hip_y", "time_lyapunov_rising"} <= set(figures)
    pd.testing.assert_frame_equal(chunk[figures], run[figures])
    again = CliRunner().invoke(cli, ["sweep", str(spec), *SHORT, "--store", "summary", "-j", "1", "-o",
                                     str(tmp_path / "chunk")])
    assert again.exit_code == 0 and ("4 skipped" in again.output or "skipped 4" in again.output), again.output
    ds = rbstab.open_sweep(tmp_path / "chunk" / "two")
    np.testing.assert_array_equal(ds["lyapunov_final"].values, chunk["lyapunov_final"].values)


def test_a_summary_stores_settling_time_is_the_summary_figure_the_traces_give(tmp_path):
    """A chain sweep stored without traces (--store summary) has the settling time of each
    run's summary figure (every sample taken as it ran) in its report, the same as the
    report takes from the traces of a thinned store at the default thresholds; at other
    thresholds it has none."""
    from rbstab.report import load_inputs
    from rbstab.report.tables import SettleThresholds, sweep_table

    grid = ["--grid", "joints.hip.l_r.0=100,140", "--set", "simulation.t_end=3", "--set", "simulation.n_samples=201"]
    tables = {}
    for store in ("thinned", "summary"):
        result = CliRunner().invoke(cli, ["sweep", STANCE, *grid, "--store", store, "-j", "1", "-o", str(tmp_path / store)])
        assert result.exit_code == 0, result.output
        (sweep,) = load_inputs([tmp_path / store / "stance_ankle_hip"]).sweeps
        tables[store] = sweep_table(sweep, ["settling_time"], SettleThresholds())
        if store == "summary":
            other = sweep_table(sweep, ["settling_time"], SettleThresholds(e=0.001))
            assert other["report:settling_time"].isna().all()
    thinned, summary = tables["thinned"], tables["summary"]
    assert thinned["report:rest"].tolist() == summary["report:rest"].tolist() == ["settled", "settled"]
    np.testing.assert_array_equal(summary["report:settling_time"], thinned["report:settling_time"])
    np.testing.assert_array_equal(summary["report:settling_time"], summary["settling_time"])
    assert (summary["settling_time"] > 0.2).all()


def test_a_chain_settles_when_every_joint_and_body_has():
    from rbstab.report.tables import SettleThresholds, settling_time

    time = np.linspace(0.0, 1.0, 11)
    error = np.zeros((11, 2, 3))
    error[:4, 0, 0] = 1.0  # joint 0 settles at t = 0.4
    error[:7, 1, 2] = 1.0  # joint 1 at t = 0.7
    omega = np.zeros((11, 3, 3))
    omega[:6, 2, 1] = 1.0  # body 2 at t = 0.6
    thresholds = SettleThresholds(e=0.1, omega=0.1)
    assert settling_time(time, error, omega, thresholds) == pytest.approx(0.7)
    omega[:9, 0, 0] = 1.0
    assert settling_time(time, error, omega, thresholds) == pytest.approx(0.9)
    error[-1, 1, 1] = np.nan  # a failed run's last sample
    assert np.isnan(settling_time(time, error, omega, thresholds))


def test_the_parameter_names_of_a_chains_keys_name_the_body_or_joint():
    assert parameter_name("joints.hip.k_c.0") == "hip_k_c_0"
    assert parameter_name("joints.ankle.saturation.torque_n.0") == "ankle_torque_n_0"
    assert parameter_name("bodies.1.mass") == "bodies_1_mass"
    assert parameter_name("bodies.trunk.mass") == "trunk_mass"
    assert parameter_name("initial_state.trunk.theta.0") == "trunk_theta_0"
    assert parameter_name("initial_state.theta.0") == "theta_0"  # one body's, as before
    assert parameter_name("controller.k_c.0") == "k_c_0"


def test_a_chains_parameters_have_the_units_and_names_of_the_quantities_they_set():
    """A sweep's coordinates over a chain's keys carry the units of the one-body key of the
    same quantity and say whose it is; a scale factor is dimensionless."""
    from rbstab.layout import parameter_attributes

    assert parameter_attributes("bodies.trunk.mass") == {"long_name": "mass m of the body (body trunk)",
                                                         "config_key": "bodies.trunk.mass", "units": "kg"}
    assert parameter_attributes("joints.hip.k_r.0")["units"] == "N m rad-1"
    assert "(joint hip) [0]" in parameter_attributes("joints.hip.k_r.0")["long_name"]
    assert parameter_attributes("initial_state.legs.theta.0")["units"] == "rad"
    assert parameter_attributes("joints.ankle.child_point.2")["units"] == "m"
    assert parameter_attributes("gravity.2")["units"] == "m s-2"
    assert parameter_attributes("bodies.trunk.mass:scale")["units"] == "1"
    for key in ("bodies.trunk.name", "joints.hip.parent"):  # no quantity: the key as its name, no units
        assert parameter_attributes(key) == {"long_name": key, "config_key": key}


def _mixed(tmp_path):
    spec = tmp_path / "mixed.yaml"
    spec.write_text(f"name: mixed\nbase: [{STANCE}, {ROOT / 'configs' / 'paper' / 'case1_permanent.yaml'}]\n"
                    "grid:\n  simulation.t_end: [0.5, 1.0]\n")
    return [str(spec)]


def _two_chains_in_store_files(tmp_path):
    spec = tmp_path / "two.yaml"
    spec.write_text(f"name: two\nbase: [{STANCE}, {ROOT / 'configs' / 'examples' / 'double_pendulum.yaml'}]\n"
                    "grid:\n  simulation.rtol: [1.0e-8, 1.0e-7]\n")
    return [str(spec), "--layout", "chunk"]


@pytest.mark.parametrize("args, expected", [
    (["--grid", "joints.knee.k_r.0=1,2"], "'knee'"),
    (["--grid", "controller.k_r.0=1,2"], "the bases are chains"),
    (["--grid", "initial_state.torso.theta.0=0,0.1"], "'torso'"),
    (_two_chains_in_store_files, "layout: found 'chunk'"),
    (["--grid", "simulation.t_end=0.5,1"], "simulation.t_end, simulation.n_samples: found 2 different sample grids"),
    (["--grid", "bodies.legs.mass=20,-1"], "bodies.legs.mass"),
    (_mixed, "all chains or all one-body configs"),
], ids=["joint", "one-body-key", "body", "chunk-two-chains", "chunk-two-grids", "value", "mixed"])
def test_a_chain_sweep_refuses_in_one_line_and_writes_nothing(args, expected, tmp_path):
    out = tmp_path / "results"
    command = ["sweep", *args(tmp_path)] if callable(args) else ["sweep", STANCE, *args]
    result = CliRunner().invoke(cli, [*command, "-o", str(out)])
    assert result.exit_code != 0
    assert "Traceback" not in result.output and expected in result.output, result.output
    assert not out.exists()


def test_two_chains_share_a_sweep_and_show_names_each_ones_joints(tmp_path):
    spec = tmp_path / "two.yaml"
    spec.write_text(f"name: two\nbase: [{STANCE}, {ROOT / 'configs' / 'examples' / 'double_pendulum.yaml'}]\n"
                    "grid:\n  simulation.t_end: [0.2, 0.4]\n")
    out = tmp_path / "results"
    result = CliRunner().invoke(cli, ["sweep", str(spec), "--set", "simulation.n_samples=201", "-j", "1",
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    index = pd.read_csv(out / "two" / "index.csv")
    assert index["base"].tolist() == ["stance_ankle_hip"] * 2 + ["double_pendulum"] * 2
    stance, pendulum = index.iloc[:2], index.iloc[2:]
    assert stance["max_abs_constraint_error_hip_x"].notna().all() and stance["max_abs_constraint_error_elbow_x"].isna().all()
    assert pendulum["max_abs_constraint_error_elbow_x"].notna().all() and pendulum["max_abs_constraint_error_hip_x"].isna().all()
    shown = CliRunner().invoke(cli, ["show", str(out / "two")])
    assert shown.exit_code == 0, shown.output
    for rid, row in zip(index["run_id"], index.itertuples()):
        line = next(text for text in shown.output.splitlines() if text.strip().startswith(rid))
        largest = max(v for k, v in row._asdict().items() if k.startswith("max_abs_constraint_error_") and v == v)
        assert f"{largest:.6g}" in line, line


def test_a_chain_sweep_on_a_dask_cluster_writes_the_local_sweeps_files(tmp_path):
    """A sweep of chains on a Dask cluster: its index and its runs' traces (store files,
    through open_sweep) are those of the local sweep."""
    pytest.importorskip("distributed", reason='the dask executor needs "distributed" (pip install ".[dask]")')
    from distributed import LocalCluster

    args = ["sweep", STANCE, "--grid", "initial_state.trunk.theta.0=-0.1,0.1", *SHORT, "--no-progress"]
    local = CliRunner().invoke(cli, [*args, "-j", "1", "-o", str(tmp_path / "local")])
    assert local.exit_code == 0, local.output
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        result = CliRunner().invoke(cli, [*args, "--scheduler", cluster.scheduler_address, "-o", str(tmp_path / "dask")])
    assert result.exit_code == 0 and "Dask scheduler" in result.output, result.output
    folders = [tmp_path / where / "stance_ankle_hip" for where in ("local", "dask")]
    ia, ib = (pd.read_csv(f / "index.csv").drop(columns=["wall_time", "file"]) for f in folders)  # files: own names
    pd.testing.assert_frame_equal(ia, ib)
    a, b = (rbstab.open_sweep(f) for f in folders)
    assert a["theta"].dims == ("run", "time", "body", "axis")
    for name in ("theta", "constraint_error", "lyapunov"):
        np.testing.assert_array_equal(a[name].values, b[name].values)


@pytest.mark.parametrize("layout", ["chunk", "run"])
def test_a_report_draws_a_thinned_chain_run(layout, tmp_path):
    """A thinned store keeps what a chain run's report draws (each joint's Theta_j, N_j,
    Lambda_j and v's terms besides one body's variables), in store files and in a file per
    run: the report of a run's file draws its four figures (Lambda_j and N_j without H) and
    the norms |E_j|, |Omega| against the settling thresholds (no phase portraits: the store
    holds no Omega_j)."""
    out = tmp_path / "results"
    result = CliRunner().invoke(cli, ["sweep", STANCE, "--grid", "initial_state.trunk.theta.0=0.1", *SHORT,
                                      "--layout", layout, "-j", "1", "-o", str(out)])
    assert result.exit_code == 0, result.output
    (file,) = (out / "stance_ankle_hip" / "runs").iterdir()
    report = CliRunner().invoke(cli, ["report", str(file), "-o", str(tmp_path / "report")])
    assert report.exit_code == 0, report.output
    drawn = sorted(p.name.rpartition("_")[2] for p in (tmp_path / "report" / "figures").iterdir())
    assert drawn == ["forces.png", "lyapunov.png", "norms.png", "rotational.png", "translational.png"], drawn
    import pandas as pd

    summary = pd.read_csv(tmp_path / "report" / "summary.csv")  # a row per chain run, its figures per joint
    assert len(summary) == 1 and summary["variant"][0] == "chain" and summary["status"][0] == "success"
    assert {"lyapunov_final", "max_abs_constraint_error_ankle_x", "max_abs_constraint_error_hip_z", "final_theta_trunk_x",
            "fraction_saturated_torque_n_ankle_x", "fraction_saturated_force_h_legs_z"} <= set(summary.columns)
    assert largest_error(summary, "hip")[0] < 1e-6


def test_a_chain_sweeps_report_names_the_keys_that_differ_as_the_sweep_does(tmp_path):
    """The report's runs table (summary.csv) has a column per configuration key that differs
    between the runs, named as ``--set`` and the sweep name it (a tree's bodies and joints
    by name) and holding each run's value: ``bodies.trunk.mass``, ``joints.hip.k_r``, not
    the whole ``bodies`` and ``joints`` lists."""
    out = tmp_path / "results"
    result = CliRunner().invoke(cli, ["sweep", STANCE, "--grid", "bodies.trunk.mass=40,50", "--grid",
                                      "joints.hip.k_r.0=400,600", *SHORT, "-j", "1", "-o", str(out)])
    assert result.exit_code == 0, result.output
    report = CliRunner().invoke(cli, ["report", str(out / "stance_ankle_hip"), "-o", str(tmp_path / "report")])
    assert report.exit_code == 0, report.output
    summary = pd.read_csv(tmp_path / "report" / "summary.csv")
    assert sorted(summary["bodies.trunk.mass"]) == [40.0, 40.0, 50.0, 50.0]
    assert sorted(summary["joints.hip.k_r"].str.split(",").str[0].str.strip("[ ").astype(float)) == [400, 400, 600, 600]
    assert not {"bodies", "joints"} & set(summary.columns)


def test_a_chain_sweep_over_initial_states_refuses_what_the_schema_refuses():
    """Runs that differ only in their initial states are checked as config_from_mapping
    checks them (the schema, each body's and each joint's gimbal lock, simulation.limits):
    the runs refused are exactly those that validating each run alone refuses, with its
    messages."""
    import yaml

    rng = np.random.default_rng(5)
    n = 60
    legs_theta_1 = rng.choice([0.0, 0.8, 1.6], size=n, p=[0.6, 0.3, 0.1])
    trunk_theta_1 = rng.choice([0.0, -0.8, 0.3], size=n, p=[0.6, 0.2, 0.2])  # -0.8 after 0.8: the hip at gimbal lock
    legs_omega_0 = rng.choice([0.0, 1.0, 3.0, np.nan], size=n, p=[0.6, 0.2, 0.1, 0.1])  # 3 > the bound 2
    base = yaml.safe_load(Path(STANCE).read_text())
    base["simulation"]["limits"] = {"omega": 2.0}
    table = {"initial_state.legs.theta.1": legs_theta_1, "initial_state.trunk.theta.1": trunk_theta_1,
             "initial_state.legs.omega.0": legs_omega_0}

    def written(data, i):
        data["initial_state"]["legs"]["theta"][1] = float(legs_theta_1[i])
        data["initial_state"]["trunk"]["theta"][1] = float(trunk_theta_1[i])
        data["initial_state"]["legs"]["omega"] = [float(legs_omega_0[i]), 0.0, 0.0]

    _refused_as_each_run_alone(base, table, written, kinds=4)


def _refused_as_each_run_alone(base: dict, table: dict, written, kinds: int) -> None:
    """A sweep of ``base`` over the columns ``table`` is refused listing exactly the runs
    that validating each alone refuses (run i: ``base`` with ``written(data, i)``'s values),
    each with its messages; at least ``kinds`` different problems among them."""
    import copy
    import warnings

    from rbstab.config import ConfigError, config_from_mapping
    from rbstab.sweep import SweepSpecError, plan_table, spec_from_mapping

    n = len(next(iter(table.values())))
    expected = {}
    for i in range(n):
        data = copy.deepcopy(base)
        data["name"] = "x"
        written(data, i)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                config_from_mapping(data)
            except ConfigError as exc:
                expected[i] = exc.errors
    assert 0 < len(expected) < n and len({tuple(p) for p in expected.values()}) >= kinds
    with pytest.raises(SweepSpecError) as info:
        plan_table(spec_from_mapping({"name": "v", "base": base, "table": table}))
    lines = info.value.errors
    assert lines[0] == f"{len(expected)} of {n} runs have an invalid configuration; nothing was run"
    for i in sorted(expected)[:10]:
        label = f"run r{i:04d} (base {base['name']}"
        assert [line.split("): ", 1)[1] for line in lines[1:] if line.startswith(label)] == expected[i], i


def test_a_chain_sweeps_parameter_columns_refuse_exactly_the_runs_each_validated_alone_refuses():
    """The columns of a chain's parameters (a body's mass and inertia, a joint's
    gains and limits, gravity) are checked at once against their fields' rules, beside an
    initial-state key: the runs refused are exactly those that validating each run alone
    refuses, with its messages."""
    import yaml

    from rbstab.config.paths import parse_any_key

    rng = np.random.default_rng(7)
    n = 80

    def some(good, bad):  # mostly good values, now and then a bad one
        return np.where(rng.random(n) < 0.9, good, rng.choice(bad, size=n))

    table = {"bodies.trunk.mass": some(rng.uniform(40, 55, n), [0.0, -3.0, np.nan]),
             "bodies.legs.inertia.1": some(rng.uniform(1.5, 2.0, n), [-0.1, 0.0]),
             "joints.1.l_r.2": some(rng.uniform(10, 30, n), [-1.0]),
             "joints.hip.k_r.0": some(rng.uniform(400, 600, n), [-5.0, np.inf]),
             "joints.ankle.saturation.torque_n.1": some(rng.uniform(100, 200, n), [0.0]),
             "gravity.2": some(rng.uniform(-10, -9, n), [np.nan]),
             "initial_state.legs.theta.1": some(np.zeros(n), [1.6]),
             "joints.hip.theta_ref.1": some(rng.uniform(-0.2, 0.2, n), [1.6, 1.5705]),
             "joints.hip.passive.theta_ref.1": some(rng.uniform(-0.2, 0.2, n), [-1.5705]),
             "joints.hip.passive.l_r.0": some(rng.uniform(0, 20, n), [-1.0]),
             "joints.ankle.saturation.torque_n_lower.2": some(rng.uniform(-200, -100, n), [0.0, 5.0])}
    base = yaml.safe_load(Path(STANCE).read_text())
    base["joints"][0]["saturation"] = {"torque_n": 150.0, "torque_n_lower": [-150.0, -150.0, -150.0]}
    base["joints"][1]["theta_ref"] = [0.0, 0.0, 0.0]  # an entry is set where the list is written
    base["joints"][1]["passive"] = {"l_r": [10.0, 10.0, 10.0], "theta_ref": [0.0, 0.0, 0.0]}

    def written(data, i):
        for key, column in table.items():
            parse_any_key(key).set(data, float(column[i]))

    _refused_as_each_run_alone(base, table, written, kinds=5)


def test_a_one_body_trees_sweep_refuses_the_runs_whose_weight_nothing_holds_as_each_alone():
    """One body on a ``free`` joint written as a tree: a run whose K_t leaves the weight
    unheld under gravity is refused as validating it alone refuses it (as in one body's
    spelling), beside a bad mass; with no gravity the same K_t is accepted."""
    import warnings

    from rbstab.config import load_config
    from rbstab.config.loader import tree_resolved
    from rbstab.config.paths import parse_any_key

    rng = np.random.default_rng(3)
    n = 60
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base = tree_resolved(load_config(ROOT / "configs" / "examples" / "free_gravity.yaml").resolved)
    table = {"bodies.body.k_t.2": np.where(rng.random(n) < 0.7, rng.uniform(2000, 4000, n), 0.0),
             "bodies.body.mass": np.where(rng.random(n) < 0.9, rng.uniform(30, 50, n), 0.0),
             "gravity.2": np.where(rng.random(n) < 0.6, -9.81, 0.0)}

    def written(data, i):
        for key, column in table.items():
            parse_any_key(key).set(data, float(column[i]))

    _refused_as_each_run_alone(base, table, written, kinds=2)


def test_a_chain_sweeps_batch_is_each_runs_compiled_chain_bit_for_bit():
    """A worker's batch of a chain sweep's runs (records, parent points, initial states and h
    built from the table's columns, no configuration per run) holds, for every run, what
    compile_chain, the loader's placement and rest_offset give its validated configuration,
    bit for bit: keys of bodies, joints (gains, points, limits, reference postures, passive torques; by name or
    position), gravity,
    disturbances, the admissible region and initial states; whole vectors and matrices (a
    grid's axes) as entries."""
    import copy
    import warnings

    from rbstab.config import config_from_mapping
    from rbstab.config.yaml_io import read_yaml_file
    from rbstab.engine.batch import RunBatch
    from rbstab.model import set_limits
    from rbstab.sweep import plan_table, spec_from_mapping
    from rbstab.variants import chain as C

    rng = np.random.default_rng(3)
    n = 4
    stance = read_yaml_file(STANCE)
    pushed, bent = copy.deepcopy(stance), copy.deepcopy(stance)
    bent["joints"][1]["theta_ref"] = [0.0, 0.1, 0.0]
    bent["joints"][0]["passive"] = {"k_r": [300.0, 200.0, 50.0], "theta_ref": [0.0, 0.05, 0.0]}
    bent["joints"][1]["saturation"] = {"torque_n": [200.0, 150.0, 100.0], "torque_n_lower": -80.0}
    pushed["simulation"]["limits"] = {"theta": 0.6}
    pushed["disturbances"] = [
        {"kind": "impulse", "quantity": "torque", "value": [0, 5, 0], "start": 0.3, "body": "trunk"},
        {"kind": "step", "value": [1, 0, 0], "start": 0.1, "body": "legs", "point": [0, 0, 0.1]}]
    cases = [
        (stance, {"bodies.trunk.mass": rng.uniform(40, 55, n), "initial_state.legs.theta.0": rng.uniform(-.1, .1, n)}),
        (bent, {"bodies.0.mass": rng.uniform(20, 25, n), "joints.1.l_r.2": rng.uniform(10, 30, n),  # by position
                "joints.hip.theta_ref.1": rng.uniform(-.2, .2, n), "joints.ankle.passive.k_r.1": rng.uniform(0, 400, n),
                "joints.0.passive.theta_ref.1": rng.uniform(-.1, .1, n),
                "joints.hip.saturation.torque_n_lower": rng.uniform(-90, -50, n)}),
        (stance, {"joints.hip.k_r.0": rng.uniform(400, 600, n), "joints.hip.child_point.2": rng.uniform(-.35, -.3, n),
                  "gravity.2": rng.uniform(-10, -9, n), "joints.ankle.saturation.torque_n.0": rng.uniform(100, 200, n),
                  "initial_state.trunk.omega.1": rng.uniform(-.1, .1, n)}),
        (pushed, {"disturbances.0.value.1": rng.uniform(1, 9, n), "disturbances.1.start": rng.uniform(0, 1, n),
                  "bodies.legs.inertia.0": rng.uniform(1.5, 2.0, n), "simulation.limits.theta.0": rng.uniform(.5, .7, n)}),
    ]
    whole = {"gravity": [[0, 0, -9.0], [0, 0, -10.0]], "joints.hip.k_r": [[400, 400, 300], [500, 450, 350]],
             "bodies.trunk.saturation.force_h": [200.0, 300.0]}  # whole vectors and matrices, a grid's axes
    cases.append((stance, whole))
    for base, table in cases:
        design = {"grid": table} if table is whole else {"table": table}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            planned = plan_table(spec_from_mapping({"name": "v", "base": base, **design}))
        part = planned.slice(np.arange(planned.n))
        batch = part.batch()
        assert isinstance(batch, RunBatch) and batch.compiled.all() and not batch.one_body.any()
        for j in range(planned.n):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                config = config_from_mapping(part.resolved(j))
            compiled = C.compile_chain(config.chain)
            records = compiled.params.copy()
            set_limits(records, config.simulation.limits)
            assert batch.params[j].tobytes() == records.tobytes(), (table, j)
            np.testing.assert_array_equal(batch.ppoints[j], compiled.ppoints)
            np.testing.assert_array_equal(batch.y0[j, :batch.n_state[j]], C.initial_state(config))
            assert batch.offset[j] == compiled.offset and batch.n_samples[j] == config.simulation.n_samples


@pytest.mark.parametrize("grid, runs", [
    ({"bodies.trunk.inertia.2": [0.42, 7.0, 8.0]}, "2 of 3 runs"),  # one moment, the body by its name
    ({"bodies.1.inertia": [[2.97, 2.97, 0.42], [1.0, 1.0, 3.0]]}, "1 of 2 runs"),  # the whole, by its position
])
def test_a_chain_sweep_warns_of_each_runs_inertia_once_with_its_count(grid, runs, tmp_path):
    """A body's inertia varied in a chain's sweep is checked run by run (the template's is
    valid): one warning line for the body's key, with how many runs break the triangle
    inequality and the first one's moments, as one body's sweep warns; the legs, not
    varied, have none."""
    spec = tmp_path / "inertia.yaml"
    spec.write_text(yaml.safe_dump({"name": "inertia", "base": STANCE, "grid": grid}))
    result = CliRunner().invoke(cli, ["sweep", str(spec), "--dry-run", "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if "W001" in line]
    assert len(lines) == 1, result.output
    assert "bodies.1.inertia ('trunk')" in lines[0] and "triangle inequality" in lines[0] and runs in lines[0], lines


def test_robustness_of_a_tree_sweep_that_ends_too_soon_suggests_a_longer_t_end(tmp_path):
    """A tree's sweep whose runs reach t_end still settling gets the hint a one-body sweep
    gets: t_end from the slowest time constant of the tree's linearisation at rest."""
    from rbstab.analysis import robustness
    from rbstab.analysis.text import describe_robustness
    from rbstab.sweep import run_sweep, spec_from_mapping

    base = rbstab.load_config(STANCE, ["simulation.t_end=0.3", "simulation.n_samples=31"]).resolved
    spec = spec_from_mapping({"name": "short", "base": base, "grid": {"bodies.trunk.mass": [30.0, 34.0]}})
    run_sweep(spec, tmp_path, jobs=1, progress=False)
    (group,) = robustness(tmp_path / "short").groups
    assert group.n_stable == 0 and group.t_end_hint is not None
    assert group.t_end_hint["settling_time"] > 0.3 and group.t_end_hint["tau"] > 0
    assert "t_end = 0.3 s may be too short" in "\n".join(describe_robustness(robustness(tmp_path / "short")))


def test_a_sweep_of_the_sign_law_gives_one_bodys_figures_in_either_spelling(tmp_path):
    """The pure sign law swept over K_s in the tree's spelling of one body (its runs go event
    by event, outside the compiled batch) gives the figures the one-body spelling's sweep
    gives, run for run: one model whatever the spelling."""
    import sys
    import warnings

    sys.path.insert(0, str(ROOT / "tests"))
    from conftest import tree_spelling
    from rbstab.sweep import run_sweep, spec_from_mapping

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        body = rbstab.load_config(ROOT / "configs" / "examples" / "sliding.yaml",
                                  ["controller.boundary_layer=0", "simulation.t_end=0.2", "simulation.n_samples=41"])
    tree = tree_spelling(body)
    for name, base, key in (("body", body.resolved, "controller.k_s"), ("tree", tree.resolved, "joints.controller.k_s")):
        run_sweep(spec_from_mapping({"name": name, "base": base, "grid": {key: [300.0, 600.0]}}), tmp_path, jobs=1,
                  progress=False)
    a, b = (pd.read_csv(tmp_path / name / "index.csv") for name in ("body", "tree"))
    assert list(a["status"]) == list(b["status"]) == ["success", "success"]
    for figure in ("lyapunov_final", "lyapunov_initial", "max_lyapunov_rate", "switching_count"):
        columns = sorted(c for c in a.columns if c.startswith(figure))
        assert columns, figure
        for column in columns:  # one body's <figure>_x is its tree's <figure>_controller_x
            tree_column = column if column == figure else f"{figure}_controller{column[len(figure):]}"
            np.testing.assert_array_equal(a[column].to_numpy(), b[tree_column].to_numpy(), err_msg=column)



def test_a_sweep_compiles_the_one_body_kernels_where_a_run_may_be_the_paper_one_body():
    """A sweep asks for the one-body kernel group (before its workers start) for a one-body
    base and for a tree base of one body (its runs may be the paper's one body: joint points
    equal), not for a tree of several bodies."""
    from conftest import PAPER_CONFIGS
    from rbstab.config import config_from_mapping
    from rbstab.sweep import spec_from_mapping

    one_tree = {"name": "one_tree", "gravity": [0, 0, 0],
                "bodies": [{"name": "b", "mass": 1.0, "inertia": [1.0, 1.0, 1.0]}],
                "joints": [{"name": "j", "parent": "ground", "child": "b", "variant": "visco_elastic",
                            "parent_point": [0, 0, 0], "child_point": [0, 0, 0], "k_r": [1, 1, 1],
                            "l_r": [1, 1, 1], "k_c": [1, 1, 1], "l_c": [1, 1, 1]}]}
    found = {}
    for name, base, key in (("paper", rbstab.load_config(PAPER_CONFIGS[0]).resolved, "body.mass"),
                            ("stance", rbstab.load_config(STANCE).resolved, "bodies.trunk.mass"),
                            ("one_tree", config_from_mapping(one_tree).resolved, "bodies.b.mass")):
        spec = spec_from_mapping({"name": "s", "base": base, "grid": {key: [1.0, 2.0]}})
        found[name] = (spec.may_run_one_body, spec.is_chain)
    assert found == {"paper": (True, False), "stance": (False, True), "one_tree": (True, True)}
