"""A sweep as a table of runs: design tables, column validation against the config schema,
large explicit specs, dry runs, configurations rebuilt from the store, damaged files.

Runs are short (t_end = 0.2 s, 201 samples).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

import rbstab
from rbstab.variants.paper import paper_form
from rbstab.config import ConfigError, config_from_mapping
from rbstab.sweep import SweepSpecError, expand, load_spec, plan_table, resolved_config, run_sweep, spec_from_mapping
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
SHORT = ["simulation.t_end=0.2", "simulation.n_samples=201"]

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def _validated_alone(resolved: dict):
    """(config, None) or (None, its problems) of one run validated by the schema alone."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return config_from_mapping(resolved), None
        except ConfigError as exc:
            return None, exc.errors


def test_design_table_from_csv_dataframe_and_mapping(tmp_path):
    """Columns named by dotted keys, vector entries key[i] and matrix entries key[i,j] set
    those entries; the others come from the base. A CSV file, a DataFrame and a mapping of
    arrays give the same runs and ids."""
    design = pd.DataFrame({"body.mass": [30.0, 45.0, 50.0], "body.inertia[0,0]": [9.0, 10.0, 11.0],
                           "body.inertia[1,1]": [7.0, 8.0, 9.0], "initial_state.omega[1]": [20.0, 30.0, 40.0],
                           "controller.variant": ["embedded", "visco_elastic", "embedded"]})
    design.to_csv(tmp_path / "design.csv", index=False)
    spec = {"name": "design", "base": str(CASE3), "table": "design.csv"}
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    from_file = expand(load_spec(tmp_path / "spec.yaml"))
    from_frame = expand(spec_from_mapping({**spec, "table": design}))
    from_mapping = expand(spec_from_mapping({**spec, "table": {k: design[k].to_numpy() for k in design}}))
    assert [r.run_id for r in from_file] == [r.run_id for r in from_frame] == [r.run_id for r in from_mapping]
    run = from_file[1]
    assert paper_form(run.config).body.mass == 45.0 and run.config.chain.joints[0].variant == "visco_elastic"
    assert paper_form(run.config).body.inertia.tolist() == [[10.0, 0.0, 0.0], [0.0, 8.0, 0.0], [0.0, 0.0, 0.4]]
    assert run.config.initial_state["body"]["omega"].tolist() == [16.0, 30.0, -16.0]
    assert [r.config.chain.joints[0].variant for r in from_file] == ["embedded", "visco_elastic", "embedded"]
    # from the command line, with a dry run: nothing written
    result = CliRunner().invoke(cli, ["sweep", str(CASE3), "--table", str(tmp_path / "design.csv"), "--dry-run",
                                      "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "case3_embedded: 3 runs (dry run" in result.output and "inertia_0_0 (body.inertia.0.0)" in result.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("columns, expected", [
    ({"body.mass": [1.0], "bad name!": [2.0]}, "column 'bad name!': unknown section 'bad name!'"),
    ({"body.mass": [1.0, 2.0], "body.inertia[0,0]": [1.0]}, "columns of different lengths"),
    ({"body.mass": []}, "a table without rows"),
])
def test_design_table_errors_name_the_column(columns, expected):
    with pytest.raises(SweepSpecError, match=expected.replace("(", r"\(").replace("[", r"\[")):
        spec_from_mapping({"name": "t", "base": str(CASE3), "table": columns})
    with pytest.raises(SweepSpecError, match="column 'body.mass' overlaps 'grid.body.mass'"):
        spec_from_mapping({"name": "t", "base": str(CASE3), "table": {"body.mass": [1.0]},
                           "grid": {"body.mass": [2.0]}})


def test_column_validation_refuses_what_the_schema_refuses():
    """The runs the column checks refuse are exactly those that validating each run alone
    refuses, with its messages: bounds, finiteness and magnitude, (semi-)definite matrices,
    the gimbal-lock margin and the weight held by the springs."""
    rng = np.random.default_rng(3)
    n = 60
    mass = rng.choice([41.0, -1.0, 0.0, 2e12, np.nan], size=n, p=[0.6, 0.1, 0.1, 0.1, 0.1])
    theta_1 = rng.choice([0.0, 1.5, 1.5705, 1.6], size=n)
    k_t_2_2 = rng.choice([3280.0, 0.0, -5.0], size=n)
    inertia_0_1 = rng.choice([0.0, 0.5, 100.0], size=n)  # 100: not positive definite
    table = {"body.mass": mass, "initial_state.theta[1]": theta_1, "controller.k_t[2]": k_t_2_2,
             "body.inertia[0,1]": inertia_0_1, "body.inertia[1,0]": inertia_0_1}
    base = yaml.safe_load(CASE3.read_text())
    base["body"]["gravity"] = [0.0, 0.0, -9.81]  # the weight must be held: K_t = 0 along z is refused
    spec = spec_from_mapping({"name": "v", "base": base, "table": table})
    expected = {}
    labels = {}
    for i in range(n):
        data = yaml.safe_load(CASE3.read_text())
        data["body"]["gravity"] = [0.0, 0.0, -9.81]
        data["body"]["mass"] = float(mass[i])
        data["initial_state"]["theta"] = [0.0, float(theta_1[i]), 0.0]
        data["controller"]["k_t"][2] = float(k_t_2_2[i])
        data["body"]["inertia"] = [[10.0, inertia_0_1[i], 0.0], [inertia_0_1[i], 8.0, 0.0], [0.0, 0.0, 0.4]]
        data["name"] = "x"
        config, problems = _validated_alone(data)
        if problems:
            expected[i] = problems
        labels[i] = f"run r{i:04d} (base case3_embedded"
    assert 0 < len(expected) < n
    with pytest.raises(SweepSpecError) as info:
        plan_table(spec)
    lines = info.value.errors
    assert lines[0] == f"{len(expected)} of {n} runs have an invalid configuration; nothing was run"
    listed = sorted(expected)[:10]
    for i in listed:
        mine = [line.split("): ", 1)[1] for line in lines[1:] if line.startswith(labels[i])]
        assert mine == expected[i], i
    assert lines[-1] == f"... and {len(expected) - 10} more invalid runs"


def test_a_trees_initial_state_columns_refuse_what_the_schema_refuses():
    """A tree's sweep over initial states and a parameter, its initial states checked as
    columns: the runs refused are exactly those that validating each run alone refuses,
    with its messages: a body's and a joint's relative theta_2 at the gimbal lock (the
    ankle's grounded legs, the hip's trunk on them), non-finite and huge entries, and a mass
    out of bounds."""
    from rbstab.config.yaml_io import read_yaml_file

    rng = np.random.default_rng(7)
    n = 80
    legs_1 = rng.choice([0.0, 0.7, 1.5707, 1.6], size=n)
    trunk = np.stack([rng.choice([0.0, np.nan, 3e12], size=n, p=[0.8, 0.1, 0.1]),
                      rng.choice([0.0, 0.8, 1.5, -0.8707], size=n), np.zeros(n)], axis=1)  # legs 0.7: hip at lock
    mass = rng.choice([47.46, -1.0], size=n, p=[0.9, 0.1])
    path = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    table = {"initial_state.legs.theta[1]": legs_1, "initial_state.trunk.theta[0]": np.full(n, 0.03),
             "initial_state.trunk.theta[1]": trunk[:, 1],
             "initial_state.trunk.omega[0]": trunk[:, 0], "bodies.trunk.mass": mass}
    def base():  # without the example's admissible region, which most of these states leave
        data = read_yaml_file(path)
        del data["simulation"]["limits"]
        return data

    spec = spec_from_mapping({"name": "v", "base": base(), "table": table})
    expected = {}
    for i in range(n):
        data = base()
        data["initial_state"]["legs"]["theta"][1] = float(legs_1[i])
        data["initial_state"]["trunk"]["theta"][:2] = [0.03, float(trunk[i, 1])]
        data["initial_state"]["trunk"]["omega"] = [float(trunk[i, 0]), 0.0, 0.0]
        data["bodies"][1]["mass"] = float(mass[i])
        _, problems = _validated_alone(data)
        if problems:
            expected[i] = problems
    assert 10 < len(expected) < n - 10
    with pytest.raises(SweepSpecError) as info:
        plan_table(spec)
    lines = info.value.errors
    assert lines[0] == f"{len(expected)} of {n} runs have an invalid configuration; nothing was run"
    for i in sorted(expected)[:10]:
        assert [line.split("): ", 1)[1] for line in lines[1:] if line.startswith(f"run r{i:04d} ")] == expected[i], i


def test_a_10000_run_zip_spec_is_read_and_planned(tmp_path):
    """An explicit design of 10,000 runs (mass, inertia matrix, K_c, L_c, K_t, Omega per
    run), as a design-of-experiments tool writes it, is within the YAML reader's limits;
    an alias bomb of fewer characters is not."""
    rng = np.random.default_rng(0)
    n = 10_000
    inertia = np.zeros((n, 3, 3))
    inertia[:, [0, 1, 2], [0, 1, 2]] = rng.uniform([9, 7, 3], [11, 9, 5], size=(n, 3))
    inertia[:, 0, 1] = inertia[:, 1, 0] = rng.uniform(-0.5, 0.5, size=n)

    def rows(a):
        return "[" + ", ".join("[" + ", ".join(f"{x:.6g}" for x in r.ravel()) + "]" if r.ndim == 1 else
                               "[" + ", ".join("[" + ", ".join(f"{x:.6g}" for x in q) + "]" for q in r) + "]"
                               for r in a) + "]"

    zipped = {"body.mass": "[" + ", ".join(f"{x:.6g}" for x in rng.uniform(30, 50, n)) + "]",
              "body.inertia": rows(inertia),
              "controller.k_c": rows(rng.uniform(4000, 13000, (n, 3))),
              "controller.l_c": rows(rng.uniform(400, 700, (n, 3))),
              "controller.k_t": rows(rng.uniform(3000, 5000, (n, 3))),
              "initial_state.omega": rows(rng.normal([16, 32, -16], 4, (n, 3)))}
    text = f"name: doe\nbase: {CASE3}\nzip:\n" + "".join(f"  {k}: {v}\n" for k, v in zipped.items())
    (tmp_path / "doe.yaml").write_text(text)
    spec = load_spec(tmp_path / "doe.yaml")
    table = plan_table(spec)
    assert table.n == n and table.columns["body.inertia"].shape == (n, 3, 3)
    assert len(set(table.ids())) == n
    bomb = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 7):  # 9^7 ~ 4.8e6 values once expanded, from ~250 bytes
        bomb.append(f"{chr(97 + i)}: &{chr(97 + i)} [" + ", ".join([f"*{chr(96 + i)}"] * 9) + "]")
    (tmp_path / "bomb.yaml").write_text("\n".join(bomb))
    with pytest.raises(SweepSpecError, match="values once aliases are expanded"):
        load_spec(tmp_path / "bomb.yaml")


@pytest.mark.parametrize("key, values", [
    # the rules the schema and the column checks share (rbstab.config.schema): each value
    # just inside and just outside its limit
    ("initial_state.theta.1", [np.pi / 2 - 1e-3 - 1e-9, np.pi / 2 - 1e-3, np.pi / 2 - 1e-3 + 1e-9, -1.0]),
    ("simulation.gimbal_margin", [1e-3, 0.499, 0.5, 0.0]),
    ("simulation.n_samples", [2, 2001, 2_000_000_000_001, 1]),
    ("simulation.max_step", [2.0 / 1_000_000, 2.0 / 1_000_000 * (1 - 1e-9), 1.0, -1.0]),
    ("body.mass", [1e-9, 0.0, 1e12, 1.1e12]),
])
def test_a_rule_refuses_the_same_values_in_a_config_and_in_a_sweep(key, values):
    """A value a configuration refuses is refused in a sweep's run, and only then; the
    sweep names the run, the key, the value and what is allowed, as the config does."""
    base = yaml.safe_load(CASE3.read_text())
    base["simulation"] = {**(base.get("simulation") or {}), "t_end": 2.0, "max_steps": 1_000_000}
    refused = {}
    for i, value in enumerate(values):
        data = yaml.safe_load(yaml.safe_dump(base))
        section, name, *index = key.split(".")
        if index:
            data[section][name][int(index[0])] = value
        else:
            data.setdefault(section, {})[name] = value
        try:
            config_from_mapping(data)
        except ConfigError as exc:
            refused[i] = exc.errors
    assert 0 < len(refused) < len(values)
    spec = spec_from_mapping({"name": "t", "base": base, "zip": {key: values}})
    with pytest.raises(SweepSpecError) as info:
        plan_table(spec)
    lines = info.value.errors
    assert lines[0].startswith(f"{len(refused)} of {len(values)} runs have an invalid configuration")
    for i, problems in refused.items():
        mine = [line.split("): ", 1)[1] for line in lines[1:] if line.startswith(f"run r{i:04d} ")]
        assert mine == problems and f"{key}=" in next(line for line in lines if line.startswith(f"run r{i:04d} "))


def test_random_keys_draw_from_their_own_streams():
    """Each random key has its own stream of the seed: adding a key leaves the others'
    values as they were, and the first samples do not depend on random.n."""
    one = {"name": "r", "base": str(CASE3), "random": {"n": 50, "seed": 4, "params": {
        "body.mass": {"uniform": [30, 50]}}}}
    two = {**one, "random": {**one["random"], "params": {**one["random"]["params"],
                                                         "controller.k_c": {"scale_uniform": [0.5, 2]}}}}
    more = {**two, "random": {**two["random"], "n": 80}}
    a, b, c = (plan_table(spec_from_mapping(s)) for s in (one, two, more))
    assert np.array_equal(a.columns["body.mass"], b.columns["body.mass"])
    assert np.array_equal(b.columns["controller.k_c"], c.columns["controller.k_c"][:50])
    assert b.ids() == c.ids()[:50]


def test_dry_run_prints_ranges_and_the_first_and_last_runs(tmp_path):
    args = ["sweep", str(CASE3), "--random", "body.mass=uniform:[30,50]", "-n", "2000", "--store", "summary",
            "--dry-run", "-o", str(tmp_path / "out")]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert "case3_embedded: 2000 runs (dry run: nothing run or written)" in result.output
    assert "mass (body.mass): 30" in result.output and "... 1990 more runs" in result.output
    assert "store ~" in result.output and "wall time ~" in result.output
    table = plan_table(load_spec(CASE3, ["sweep.random.params.body.mass={uniform: [30, 50]}", "sweep.random.n=2000"]))
    ids = table.ids()
    assert ids[0] in result.output and ids[-1] in result.output and ids[1000] not in result.output
    every = CliRunner().invoke(cli, [*args, "-v"])
    assert ids[1000] in every.output
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweeps")
    spec = spec_from_mapping({"name": "small", "base": str(CASE3), "grid": {
        "controller.variant": ["visco_elastic", "embedded"], "controller.k_c.2": [3000.0, 3500.0, 4000.0]}},
        overrides=SHORT)
    run_sweep(spec, out, jobs=2, chunk_size=2, progress=False)
    return spec, out / "small"


def test_a_runs_config_is_rebuilt_from_the_store(small_sweep):
    """resolved_config and rbstab show --run give each run's configuration as the plan made
    it (validated alone it is the same), as YAML a config file takes."""
    spec, folder = small_sweep
    runs = expand(spec)
    for run in runs:
        rebuilt = resolved_config(folder, run.run_id)
        assert rebuilt["name"] == run.run_id
        config, problems = _validated_alone(rebuilt)
        assert problems is None and config.resolved == run.config.resolved
    result = CliRunner().invoke(cli, ["show", str(folder), "--run", runs[4].run_id])
    assert result.exit_code == 0, result.output
    shown = yaml.safe_load(result.output)
    assert shown["controller"]["variant"] == "embedded" and shown["controller"]["k_c"][2] == 3500.0
    bad = CliRunner().invoke(cli, ["show", str(folder), "--run", "r9999-nothere"])
    assert bad.exit_code == 1 and "no run 'r9999-nothere'" in bad.output and "Traceback" not in bad.output


def test_damaged_store_files_of_any_kind_are_set_aside_and_their_runs_redone(tmp_path):
    """A store file truncated or emptied (a crash, a full disk) is renamed *.damaged and its
    runs are run again; open_sweep and xarray.open_mfdataset of runs/*.h5 then work."""
    import xarray as xr

    from rbstab import open_sweep

    spec = spec_from_mapping({"name": "dmg", "base": str(CASE3), "grid": {"body.mass": [40.0, 41.0, 42.0, 43.0,
                                                                                         44.0, 45.0]}},
                             overrides=SHORT)
    first = run_sweep(spec, tmp_path, jobs=2, chunk_size=2, progress=False)
    assert first.counts["success"] == 6
    runs = tmp_path / "dmg" / "runs"
    files = sorted(runs.glob("chunk-*.h5"))
    assert len(files) == 3
    files[0].write_bytes(files[0].read_bytes()[:2000])  # truncated
    files[1].write_bytes(b"")  # emptied
    again = run_sweep(spec, tmp_path, jobs=2, chunk_size=2, progress=False)
    assert sorted(name for name, _ in again.damaged) == sorted(p.name for p in files[:2])
    assert (again.n_skipped, again.n_executed, again.counts["success"]) == (2, 4, 6)
    assert again.stale_files == []
    assert sorted(p.name for p in runs.glob("*.damaged")) == sorted(p.name + ".damaged" for p in files[:2])
    ds = open_sweep(tmp_path / "dmg")
    assert ds.sizes["run"] == 6 and np.isfinite(ds.lyapunov.values).all()
    with xr.open_mfdataset(sorted(runs.glob("*.h5")), engine="h5netcdf") as mf:
        assert mf.sizes["run"] == 6 and sorted(mf["run"].values) == list(range(6))


def test_open_sweep_maps_index_arrow_and_falls_back_to_the_csv(small_sweep):
    """open_sweep reads index.arrow (checked against sweep_summary.json) and gives what the
    CSV gives; without its checksum it reads index.csv; a damaged one is refused."""
    import json
    import shutil

    import xarray as xr

    from rbstab import open_sweep
    from rbstab.io.integrity import DamagedResultError
    from rbstab.sweep.folder import INDEX_ARROW_FILE, SUMMARY_FILE

    _, folder = small_sweep
    assert (folder / INDEX_ARROW_FILE).is_file()
    mapped = open_sweep(folder)
    copy = folder.parent / "small-csv"
    shutil.copytree(folder, copy)
    summary = json.loads((copy / SUMMARY_FILE).read_text())
    del summary["index_arrow_sha256"]
    (copy / SUMMARY_FILE).write_text(json.dumps(summary))
    parsed = open_sweep(copy)
    xr.testing.assert_identical(mapped.drop_attrs(), parsed.drop_attrs())
    for name in mapped.variables:  # the CSV reads 3000.0 back as an integer; the Arrow file keeps the float
        kinds = {mapped[name].dtype.kind, parsed[name].dtype.kind}
        assert kinds <= {"f", "i"} or mapped[name].dtype == parsed[name].dtype, name
    assert mapped["run_id"].values.tolist() == parsed["run_id"].values.tolist()
    grid = open_sweep(folder, grid=True)
    assert dict(grid.sizes)["k_c_2"] == 3
    damaged = folder.parent / "small-damaged"
    shutil.copytree(folder, damaged)
    data = bytearray((damaged / INDEX_ARROW_FILE).read_bytes())
    data[len(data) // 2] ^= 1
    (damaged / INDEX_ARROW_FILE).write_bytes(bytes(data))
    with pytest.raises(DamagedResultError, match="index.arrow"):
        open_sweep(damaged)


@pytest.fixture(scope="module")
def index_folders(tmp_path_factory):
    """Sweep folders whose index has every kind of value: a real sweep with a failed run
    (gimbal lock: rate check "n/a", no controller state for visco_elastic, whole-number
    floats); one of runs that succeeded, failed, raised (error) or were not run
    (pending), with quoted text and absent files; one whose runs have no message."""
    from rbstab.sweep.folder import write_table_index

    out = tmp_path_factory.mktemp("indexes")
    spec = spec_from_mapping({"name": "mixed", "base": str(CASE3), "grid": {
        "initial_state.theta": [[0.0, 1.5, 0.0], [0.0, 0.0, 0.0]], "initial_state.omega": [[0.0, 30.0, 0.0]],
        "controller.variant": ["visco_elastic", "embedded"]}}, overrides=SHORT)
    outcome = run_sweep(spec, out, jobs=1, chunk_size=2, progress=False)
    assert outcome.counts["failed"] >= 1 and outcome.counts["success"] >= 1
    table = plan_table(spec_from_mapping({"name": "ix", "base": str(CASE3), "grid": {
        "controller.variant": ["embedded", "visco_elastic"], "body.mass": [40.0, 41.0, 42.0]}}))
    ids = table.ids()
    stored = pd.DataFrame({
        "run": [0, 1, 2, 3], "run_id": ids[:4], "status": ["success", "success", "failed", "success"],
        "message": ['m0, "quoted"', "", "n/a", "NA"], "wall_time": [0.5, 1.5, 2.5, 3.5],
        "lyapunov_initial": [10.0] * 4, "lyapunov_final": [0.1, 5.0, None, 0.05],
        "lyapunov_rate_check": ["pass", "", "n/a", None], "file": [None] * 4, "file_row": [None] * 4})
    written = out / "ix"
    written.mkdir()
    write_table_index(written, table, stored, {ids[4]: "ValueError: boom"}, name="ix", ratio=0.01)
    (written / "sweep.yaml").write_text("name: ix\n")
    quiet = out / "quiet"  # no message at all: an empty column of the CSV
    quiet.mkdir()
    write_table_index(quiet, table, pd.DataFrame({"run": range(6), "run_id": ids, "status": "success", "message": "",
                                                  "lyapunov_initial": 1.0, "lyapunov_final": 0.5}),
                      {}, name="quiet", ratio=0.01)
    (quiet / "sweep.yaml").write_text("name: quiet\n")
    return [out / "mixed", written, quiet]


def _without(folder: Path, into: Path, name: str, checksum: str | None = None) -> Path:
    """A copy of ``folder`` in ``into`` without its file ``name`` (and the summary's
    ``checksum``)."""
    import json
    import shutil

    copy = into / f"{folder.name}-without-{name}{'-' + checksum if checksum else ''}"
    shutil.copytree(folder, copy)
    (copy / name).unlink()
    if checksum:
        summary = json.loads((copy / "sweep_summary.json").read_text())
        del summary[checksum]
        (copy / "sweep_summary.json").write_text(json.dumps(summary))
    return copy


@pytest.mark.filterwarnings("error::pandas.errors.Pandas4Warning")
@pytest.mark.parametrize("which", [0, 1, 2])
def test_read_index_reads_index_arrow_as_it_reads_the_csv(index_folders, which, tmp_path):
    """read_index reads index.arrow (a folder without index.csv still reads) and gives the
    frame index.csv gives, dtypes included, but float columns of whole numbers, which the
    CSV gives as integers; text such as "n/a" or "NA" is text in both. A folder without
    index.arrow (an older one, or one whose file is gone) reads from index.csv."""
    from pandas.testing import assert_frame_equal

    from rbstab.sweep.folder import read_index

    folder = index_folders[which]
    mapped = read_index(_without(folder, tmp_path, "index.csv"))
    parsed = read_index(_without(folder, tmp_path, "index.arrow", "index_arrow_sha256"))  # an older folder
    assert_frame_equal(read_index(_without(folder, tmp_path, "index.arrow")), parsed)
    assert_frame_equal(read_index(folder), mapped)
    whole = [c for c in parsed if parsed[c].dtype.kind == "i" and mapped[c].dtype.kind == "f"]
    assert all((mapped[c] == mapped[c].round()).all() for c in whole)
    assert_frame_equal(mapped, parsed.astype(dict.fromkeys(whole, float)), check_exact=True)
    assert str(mapped["run_id"].dtype) == str(mapped["message"].dtype) == "str" and mapped["converged"].dtype == bool
    assert not mapped["message"].isna().any()
    if which == 0:
        assert "n/a" in set(mapped["lyapunov_rate_check"]) and mapped["final_controller_state_x"].isna().any()
        assert whole  # theta_0, theta_2: 0.0 in every run
    elif which == 1:
        assert list(mapped["status"]) == ["success", "success", "failed", "success", "error", "pending"]
        assert list(mapped["message"][:5]) == ['m0, "quoted"', "", "n/a", "NA", "ValueError: boom"]
        assert list(mapped["lyapunov_rate_check"].fillna("-")) == ["pass", "-", "n/a", "-", "-", "-"]
        assert mapped["file"].isna().all() and mapped["file"].dtype == mapped["file_row"].dtype == float
    else:
        assert list(mapped["message"]) == [""] * 6


def test_a_damaged_index_arrow_is_refused(index_folders, tmp_path):
    """read_index and rbstab show DIR refuse an index.arrow that does not match its
    checksum, naming the file; verify=False reads it."""
    import shutil

    from rbstab.io.integrity import DamagedResultError
    from rbstab.sweep.folder import read_index

    import struct

    import pyarrow.ipc as ipc

    damaged = tmp_path / "damaged"
    shutil.copytree(index_folders[0], damaged)  # index.csv intact
    data = bytearray((damaged / "index.arrow").read_bytes())
    value = ipc.open_file(bytes(data)).read_all().column("lyapunov_final")[0].as_py()
    at = bytes(data).index(struct.pack("<d", value))  # a bit of a value flipped: the file still reads
    data[at] ^= 1
    (damaged / "index.arrow").write_bytes(bytes(data))
    with pytest.raises(DamagedResultError, match=r"index\.arrow: does not match its checksum"):
        read_index(damaged)
    assert len(read_index(damaged, verify=False)) == 4
    shown = CliRunner().invoke(cli, ["show", str(damaged)])
    assert shown.exit_code == 1 and "index.arrow: does not match its checksum" in shown.output, shown.output



def test_open_sweep_grid_of_a_full_factorial_table(tmp_path):
    """A table of every (mass, K_t) combination opens as a grid over its columns (K_t's two
    entries, which vary together, as one axis); a table missing or repeating a combination
    gets one line naming it."""
    import pandas as pd

    from rbstab.sweep.spec import spec_from_mapping

    base = {"controller": {"variant": "free", "k_t": [4100, 4100, 3280], "l_t": [210, 210, 140],
                           "k_r": [400, 400, 320], "l_r": [60, 60, 42]},
            "initial_state": {"v": [0.5, 0.3, 0.2]},
            "body": {"mass": 41.0, "inertia": [10.0, 8.0, 4.0], "attachment_point": [0.15, 0.10, -0.42]},
            "simulation": {"t_end": 0.2, "n_samples": 11, "rtol": 1e-6, "atol": 1e-9}}
    rows = [{"body.mass": m, "controller.k_t.0": k, "controller.k_t.1": 2 * k} for m in (30.0, 40.0)
            for k in (1000.0, 2000.0, 3000.0)]
    for name, frame in [("full", rows), ("missing", rows[:-1]), ("repeated", rows + rows[:1])]:
        run_sweep(spec_from_mapping({"name": name, "base": base, "table": pd.DataFrame(frame)}), tmp_path,
                  jobs=1, progress=False)
    ds = rbstab.open_sweep(tmp_path / "full", grid=True)
    assert dict(ds["lyapunov_final"].sizes) == {"mass": 2, "k_t_0": 3}
    assert ds["k_t_1"].dims == ("k_t_0",) and ds["k_t_1"].values.tolist() == [2000.0, 4000.0, 6000.0]
    flat = rbstab.open_sweep(tmp_path / "full")
    assert ds["lyapunov_final"].values.ravel().tolist() == flat["lyapunov_final"].values.tolist()
    with pytest.raises(ValueError, match=r"not a grid over mass, k_t_0: the combination \(mass=40, k_t_0=3000\) "
                                         r"is missing"):
        rbstab.open_sweep(tmp_path / "missing", grid=True)
    with pytest.raises(ValueError, match=r"the combination \(mass=30, k_t_0=1000\) appears 2 times"):
        rbstab.open_sweep(tmp_path / "repeated", grid=True)


# -- index.csv only up to CSV_INDEX_MAX_RUNS runs, or when asked ----------------------------------


def _sweep(tmp_path, *args):
    return CliRunner().invoke(cli, ["sweep", str(CASE3), "--grid", "body.mass=40,41,42", "-o", str(tmp_path),
                                    "-j", "1", "--no-progress", *[a for s in SHORT for a in ("--set", s)], *args])


def test_index_csv_is_written_up_to_the_threshold_or_when_asked(tmp_path, monkeypatch):
    """Above CSV_INDEX_MAX_RUNS runs (patched to 2 here) a sweep writes index.arrow alone
    (an index.csv of an earlier invocation is removed, the summary names index.arrow and has
    no index_sha256); --index csv writes the CSV too, the text it writes at or below the
    threshold; rbstab show, read_index, open_sweep and the report read the folder either
    way, and --index arrow leaves the CSV out of a small sweep."""
    import json

    from rbstab.sweep import folder as sweep_folder
    from rbstab.sweep.folder import is_sweep_folder, open_sweep, read_index

    folder = tmp_path / "case3_embedded"
    small = _sweep(tmp_path)  # 3 runs, at most the threshold
    assert small.exit_code == 0, small.output
    assert f"index   {folder / 'index.csv'}" in small.output
    csv_text = (folder / "index.csv").read_bytes()
    arrow_bytes = (folder / "index.arrow").read_bytes()
    assert json.loads((folder / "sweep_summary.json").read_text())["index"] == "index.csv"

    monkeypatch.setattr(sweep_folder, "CSV_INDEX_MAX_RUNS", 2)
    large = _sweep(tmp_path)  # 3 runs, above it: the runs are done, the index rebuilt without the CSV
    assert large.exit_code == 0, large.output
    assert f"index   {folder / 'index.arrow'}" in large.output
    assert not (folder / "index.csv").exists() and (folder / "index.arrow").read_bytes() == arrow_bytes
    summary = json.loads((folder / "sweep_summary.json").read_text())
    assert summary["index"] == "index.arrow" and "index_sha256" not in summary and "index_arrow_sha256" in summary
    assert is_sweep_folder(folder) and len(read_index(folder)) == 3 and open_sweep(folder).sizes["run"] == 3
    shown = CliRunner().invoke(cli, ["show", str(folder)])
    assert shown.exit_code == 0 and "3 runs" in shown.output, shown.output
    from rbstab.report.load import load_sweep

    assert [r.name for r in load_sweep(folder).runs] == list(read_index(folder)["run_id"])  # what the report reads

    asked = _sweep(tmp_path, "--index", "csv")
    assert asked.exit_code == 0, asked.output
    assert (folder / "index.csv").read_bytes() == csv_text and (folder / "index.arrow").read_bytes() == arrow_bytes
    assert json.loads((folder / "sweep_summary.json").read_text())["index"] == "index.csv"

    monkeypatch.undo()
    arrow_only = _sweep(tmp_path, "--index", "arrow")
    assert arrow_only.exit_code == 0 and not (folder / "index.csv").exists(), arrow_only.output
    bad = _sweep(tmp_path, "--index", "parquet")
    assert bad.exit_code == 2 and "'parquet' is not one of 'csv', 'arrow'" in bad.output
    assert "Traceback" not in bad.output


def test_an_index_value_not_allowed_is_refused_before_anything_runs(tmp_path):
    spec = spec_from_mapping({"name": "bad-index", "base": str(CASE3)}, overrides=SHORT)
    with pytest.raises(ValueError, match=r"index: found 'text'; expected one of csv, arrow"):
        run_sweep(spec, tmp_path, jobs=1, progress=False, index="text")
    assert not (tmp_path / "bad-index").exists()
