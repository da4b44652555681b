"""``rbstab report``: end to end through the CLI, values checked against the result files.

The runs are made with ``rbstab run configs/paper/*.yaml`` (shortened to 0.5 s and 201
samples). The sweeps are made with
``rbstab sweep`` on small grids over case 2; one row of a run whose worker raised is added
to a copy of an ``index.csv`` by hand, since no configuration makes a worker raise.
"""

from __future__ import annotations

import html.parser
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from conftest import PAPER_CONFIGS, ROOT
from rbstab.io.chunk import read_chunk_rows
from rbstab.io.hdf5 import read_summary
from rbstab.report import (
    DEFAULT_METRICS,
    DEFAULT_SETTLE_E,
    DEFAULT_SETTLE_OMEGA,
    ReportInputError,
    SettleThresholds,
    allowed_metrics,
    default_report_name,
    load_inputs,
)
from rbstab.report.build import DPI_RANGE
from rbstab.report.figures import DPI, FIGURE_FORMATS
from rbstab.report.paper import PAPER_CASES, compare_with_paper
from rbstab.report.tables import settling_time, sweep_table, validate_metrics
from rbstab.sweep.folder import write_summary
from rbstab_cli import report as report_cli
from rbstab_cli.main import cli

SHORT = ["--set", "simulation.n_samples=201", "--set", "simulation.t_end=0.5"]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: theta_2 this close to pi/2 with omega_2 = +32 rad/s hits the gimbal-lock event at once
GIMBAL_THETA_2 = 1.5697


def _invoke(*args: str):
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=True)
    return result


def _ok(result):
    assert result.exit_code == 0, (result.output, result.exception)
    return result


def _clean_error(result, *fragments: str) -> str:
    """A user error: exit status 1, ``Error:`` message, no traceback."""
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit), result.exception  # not an uncaught error
    assert "Traceback" not in result.output
    assert "Error:" in result.output
    for fragment in fragments:
        assert fragment in result.output, result.output
    return result.output


class _Images(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.src: list[str] = []
        self.href: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.src.append(attrs["src"])
        if tag == "a" and "href" in attrs:
            self.href.append(attrs["href"])


def _images(index: Path) -> _Images:
    parser = _Images()
    parser.feed(index.read_text(encoding="utf-8"))
    return parser


def _assert_png(path: Path) -> None:
    from PIL import Image

    assert path.is_file(), path
    assert path.read_bytes()[:8] == PNG_SIGNATURE, path
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        assert im.size[0] > 300 and im.size[1] > 200


def _md_table(text: str, title: str) -> list[list[str]]:
    """Rows (without the header) of the markdown table whose bold title is ``title``."""
    lines = text.splitlines()
    i = lines.index(f"**{title}**")
    rows = []
    for line in lines[i + 4 :]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split(" | ")])
    return rows


# -- fixtures ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def paper_runs(tmp_path_factory) -> list[Path]:
    assert len(PAPER_CONFIGS) == 3, PAPER_CONFIGS
    out = tmp_path_factory.mktemp("runs")
    _ok(_invoke("run", *PAPER_CONFIGS, "-o", out, *SHORT))
    files = sorted(out.glob("*.h5"))
    assert [f.stem for f in files] == sorted(PAPER_CASES)
    return files


@pytest.fixture(scope="module")
def paper_report(paper_runs, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("reports") / "paper"
    _ok(_invoke("report", *paper_runs, "-o", folder, "--format", "html", "--format", "md"))
    return folder


def _sweep(folder: Path, name: str, grid: dict, n_fell: int, *options: str) -> Path:
    """Run ``rbstab sweep`` on a grid over case 2 (0.5 s, 201 samples); its folder."""
    spec = folder / f"{name}.yaml"
    spec.write_text(yaml.safe_dump({"name": name, "base": str(ROOT / "configs" / "paper" / "case2_visco_elastic.yaml"),
                                    "grid": grid}, sort_keys=False))
    result = _invoke("sweep", spec, "-o", folder / "sweeps", "-j", "2", "--no-progress", *SHORT, *options)
    assert isinstance(result.exception, (SystemExit, type(None))), result.exception  # no crash
    assert result.exit_code == 0, (result.output, result.exception)  # a run that fell is a result
    line = next(x for x in result.output.splitlines() if x.startswith(f"{name}: ") and " skipped, " in x)  # counts by outcome
    assert (f"{n_fell} fell" in line) == bool(n_fell) and "could not be computed" not in line, line
    assert (folder / "sweeps" / name / "index.csv").is_file()
    return folder / "sweeps" / name


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory) -> dict[str, Path]:
    """Two small sweeps of case 2 (``rbstab sweep``), each with one gimbal-lock failure.

    ``grid`` (store files): theta_2(0) in {0, GIMBAL_THETA_2} x omega_2(0) in {32, -32} rad/s; only
    (GIMBAL_THETA_2, +32) fails. ``line`` (a file per run): theta_2(0) in {0, 0.3, GIMBAL_THETA_2} at
    omega_2 = 32. ``with_error``: ``line`` plus a row as ``rbstab sweep`` writes it for a
    run whose worker raised (status ``error``, no file), added to its index.csv by hand
    (without index.arrow: a folder as written before it).
    """
    root = tmp_path_factory.mktemp("sweeps")
    grid = _sweep(root, "grid", {"initial_state.theta.1": [0.0, GIMBAL_THETA_2],
                                 "initial_state.omega.1": [32.0, -32.0]}, n_fell=1)
    line = _sweep(root, "line", {"initial_state.theta.1": [0.0, 0.3, GIMBAL_THETA_2]}, 1, "--layout", "run")
    with_error = root / "with_error"
    shutil.copytree(line, with_error)
    index = pd.read_csv(with_error / "index.csv", dtype=str, keep_default_na=False)
    extra = {c: "" for c in index.columns}
    extra.update({"run_id": "r9999-deadbeef", "run": "3", "base": index["base"][0], "theta_1": "0.6",
                  "status": "error", "converged": "False", "message": "worker raised MemoryError"})
    pd.concat([index, pd.DataFrame([extra])]).to_csv(with_error / "index.csv", index=False)
    (with_error / "index.arrow").unlink()
    summary = with_error / "sweep_summary.json"  # its checksum of the index, updated as rbstab would
    write_summary(summary, json.loads(summary.read_text()))
    return {"grid": grid, "line": line, "with_error": with_error}


def _run_id(sweep: Path, theta_2: float, omega_2: float | None = None) -> str:
    index = pd.read_csv(sweep / "index.csv")
    hit = index["theta_1"] == theta_2
    if omega_2 is not None:
        hit &= index["omega_1"] == omega_2
    (run_id,) = index.loc[hit, "run_id"]
    return run_id


# -- the report of the three paper cases --------------------------------------------------

def test_paper_report_files_exist_and_every_image_is_a_valid_png(paper_report):
    for name in ("index.html", "index.md", "summary.md", "summary.csv", "report.json"):
        assert (paper_report / name).is_file(), name
    parser = _images(paper_report / "index.html")
    # per run: rotational, translational, Lyapunov, forces, phase; comparison: 3 overlays + norms
    assert len(parser.src) == 3 * 5 + 4
    for case in PAPER_CASES:
        for kind in ("rotational", "translational", "lyapunov", "forces", "phase"):
            assert f"figures/{case}_{kind}.png" in parser.src, (case, kind)
    assert len(set(parser.src)) == len(parser.src)
    for src in parser.src:
        assert not src.startswith(("/", "file:", "http")), src  # relative: the folder can move
        _assert_png(paper_report / src)
    on_disk = {f"figures/{p.name}" for p in (paper_report / "figures").iterdir()}
    assert on_disk == set(parser.src)  # no figure left out of the page
    md_images = [line.split("](")[1].rstrip(")") for line in (paper_report / "index.md").read_text().splitlines()
                 if line.startswith("![")]
    assert sorted(md_images) == sorted(parser.src)
    manifest = json.loads((paper_report / "report.json").read_text())
    assert manifest["settle_e"] == DEFAULT_SETTLE_E and manifest["settle_omega"] == DEFAULT_SETTLE_OMEGA
    assert len(manifest["runs"]) == 3


def test_summary_csv_has_one_row_per_run_with_the_values_stored_in_the_files(paper_runs, paper_report):
    table = pd.read_csv(paper_report / "summary.csv", engine="python")
    assert len(table) == 3
    assert sorted(table["run"]) == sorted(PAPER_CASES)
    for row in table.to_dict("records"):
        path = Path(row["file"])
        info = read_summary(path)
        s = info["summary"]
        assert row["variant"] == info["variant"] and row["status"] == info["status"] == "success"
        for block in ("theta", "omega", "position", "velocity"):
            assert [row[f"final_{block}_{i}"] for i in (1, 2, 3)] == s[f"final_{block}"]
        assert [row[f"max_abs_constraint_error_{i}"] for i in (1, 2, 3)] == s["max_abs_constraint_error"]
        for key in ("t_final", "lyapunov_initial", "lyapunov_final", "max_lyapunov_rate", "lyapunov_rate_mismatch"):
            assert row[key] == s[key], key
        assert row["lyapunov_rate_check"] == s["lyapunov_rate_check"]
        assert row["nfev"] == info["solver"]["nfev"] and row["wall_time"] == info["wall_time"]
        assert row["t_final"] == 0.5
        # settling time, recomputed here from the stored series through xarray
        import xarray as xr

        with xr.open_dataset(path, engine="h5netcdf") as ds:
            t = ds["time"].values
            inside = (np.linalg.norm(ds["constraint_error"].values, axis=1) <= DEFAULT_SETTLE_E) & (
                np.linalg.norm(ds["omega"].values, axis=1) <= DEFAULT_SETTLE_OMEGA
            )
        expected = np.nan if not inside[-1] else t[max(i for i in range(len(t)) if not inside[i]) + 1]
        np.testing.assert_equal(row["settling_time"], expected)
    # parameters that differ between the three cases: the variant and gravity at least,
    # never the name (the row label) nor what all three share
    assert {"controller.variant", "body.gravity"} <= set(table.columns)
    assert "name" not in table.columns and "body.mass" not in table.columns
    assert dict(zip(table["run"], table["controller.variant"])) == {
        k: c.variant for k, c in PAPER_CASES.items()
    }


def test_markdown_and_html_show_one_row_per_run_with_the_same_values(paper_runs, paper_report):
    md = (paper_report / "summary.md").read_text()
    page = (paper_report / "index.html").read_text()
    rows = _md_table(md, "Constraint error and Lyapunov function")
    assert [r[0] for r in rows] == [p.stem for p in paper_runs]
    for row, path in zip(rows, paper_runs):
        s = read_summary(path)["summary"]
        assert row[3] == f"{s['lyapunov_initial']:.4g}" and row[4] == f"{s['lyapunov_final']:.4g}"
        assert row[1] == "[" + ", ".join(f"{v:.4g}" for v in s["max_abs_constraint_error"]) + "]"
        assert f"<td>{row[4]}</td>" in page
    runs = _md_table(md, "Runs: identity, solver statistics, status")
    assert [(r[0], r[2], r[3]) for r in runs] == [(p.stem, PAPER_CASES[p.stem].variant, "success") for p in paper_runs]
    assert "Runs: identity, solver statistics, status" in page  # the page holds the same tables


def test_paper_comparison_shows_printed_values_differences_and_points_to_the_docs(paper_runs, paper_report):
    md = (paper_report / "summary.md").read_text()
    assert "docs/physics.md" in md and "The paper's printed results" in md
    assert "The paper's printed results" in (ROOT / "docs" / "physics.md").read_text()  # the pointer resolves
    rows = _md_table(md, "case1_permanent against the printed values (difference = ours - printed)")
    assert [r[2] for r in rows] == ["0.092", "-0.1221", "0.0003", "0.0359", "0.0215", "-0.0099"]
    assert "ends at t = 0.5 s" in md  # the shortened runs are flagged as not like for like
    comparisons = {c.case.key: c for c in compare_with_paper(load_inputs(paper_runs).runs)}
    assert set(comparisons) == set(PAPER_CASES)
    c2 = comparisons["case2_visco_elastic"]
    s2 = read_summary(c2.run.path)["summary"]
    printed = [*PAPER_CASES["case2_visco_elastic"].final["position"]]
    assert [r["printed"] for r in c2.rows[:3]] == printed
    assert [r["ours"] for r in c2.rows[:3]] == s2["final_position"]
    for r in c2.rows:
        assert r["difference"] == r["ours"] - r["printed"]
    assert any("case2_visco_elastic" in note for note in comparisons["case3_embedded"].notes)


def _normalised_page(folder: Path) -> str:
    """index.html without what differs from one build to the next: the time it was made and
    the players' random element ids (matplotlib's HTMLWriter)."""
    page = (folder / "index.html").read_text()
    page = re.sub(r"Created \S+ by rbstab", "Created ... by rbstab", page)
    return re.sub(r"(?<![0-9a-f])[0-9a-f]{32}(?![0-9a-f])", "ID", page)


def test_a_report_drawn_by_worker_processes_equals_one_drawn_in_one_process(paper_runs, tmp_path, monkeypatch):
    """-j 2 (the figures and animations drawn in two processes) gives the same figure files,
    byte for byte, and the same page as one process. On a machine of one CPU (the default
    -j 1) every figure is drawn in the command's process: no worker process is started."""
    from rbstab.sweep import executors

    one, two = tmp_path / "j1", tmp_path / "j2"
    with monkeypatch.context() as patch:
        patch.setattr(executors, "default_jobs", lambda: 1)  # what a machine of one CPU gives
        patch.setattr(executors, "LocalExecutor", None)  # no worker process is started
        _ok(_invoke("report", *paper_runs[:2], "-o", one, "--animation-frames", "3"))
    _ok(_invoke("report", *paper_runs[:2], "-o", two, "-j", 2, "--animation-frames", "3"))
    names = sorted(p.name for p in (one / "figures").iterdir())
    assert names == sorted(p.name for p in (two / "figures").iterdir()) and len(names) == 2 * 5 + 4
    for name in names:
        assert (one / "figures" / name).read_bytes() == (two / "figures" / name).read_bytes(), name
    assert _normalised_page(one).count("data:image/jpeg;base64,") == 2 * 3
    assert _normalised_page(one) == _normalised_page(two)
    assert (one / "summary.csv").read_bytes() == (two / "summary.csv").read_bytes()
    manifests = [json.loads((f / "report.json").read_text()) for f in (one, two)]
    assert manifests[0]["figures"] == manifests[1]["figures"]


def test_worker_processes_return_results_in_order_and_raise_a_tasks_error():
    from rbstab.report.workers import Task, draw

    tasks = [Task(pow, (2, i)) for i in range(7)]
    assert draw(tasks) == draw(tasks, 2) == [2**i for i in range(7)]  # here, and in two processes
    with pytest.raises(ValueError, match="invalid literal"):
        draw([Task(pow, (2, 3)), Task(int, ("not a number",))], 2)


def test_the_worker_processes_fork_server_imports_each_module_it_preloads():
    """``set_forkserver_preload`` silently skips a name that fails to import: each must."""
    import importlib

    from rbstab.report.workers import PRELOAD

    for name in PRELOAD:
        importlib.import_module(name)


def test_jobs_must_be_a_positive_number(paper_runs, tmp_path):
    from rbstab.report import ReportError, ReportOptions, build_report

    for jobs in (0, -1, 1.5, "2"):
        with pytest.raises(ReportError, match="jobs: found"):
            build_report(paper_runs[:1], tmp_path / "r", ReportOptions(jobs=jobs))
    result = _invoke("report", paper_runs[0], "-o", tmp_path / "r", "-j", "0")
    assert result.exit_code == 2 and "-j" in result.output
    assert not (tmp_path / "r").exists()


def test_a_run_is_a_paper_case_only_with_the_cases_variant(paper_runs, tmp_path):
    config = ROOT / "configs" / "paper" / "case1_permanent.yaml"
    _ok(_invoke("run", config, "-o", tmp_path, *SHORT, "--set", "controller.variant=free"))
    inputs = load_inputs([tmp_path / "case1_permanent.h5", paper_runs[1]])
    assert [c.case.key for c in compare_with_paper(inputs.runs)] == ["case2_visco_elastic"]


# -- sweeps -------------------------------------------------------------------------------

def test_sweep_report_lists_failures_plots_metrics_and_the_stable_fraction(sweeps, tmp_path):
    out = tmp_path / "report"
    _ok(_invoke("report", sweeps["grid"], sweeps["with_error"], "-o", out, "--format", "md",
                "--metric", "max_abs_constraint_error", "--metric", "settling_time"))
    md = (out / "index.md").read_text()
    # failed runs with their messages (from index.csv: the file's message, or the worker's)
    failed = _md_table(md, "Runs of grid that did not reach t_end")
    assert [r[0] for r in failed] == [_run_id(sweeps["grid"], GIMBAL_THETA_2, 32.0)]
    assert "gimbal lock" in failed[0][-1] and failed[0][-2] == "fell"
    failed = _md_table(md, "Runs of with_error that did not reach t_end")
    assert [(r[0], r[-3], r[-2]) for r in failed] == [(_run_id(sweeps["line"], GIMBAL_THETA_2), "failed", "fell"),
                                                      ("r9999-deadbeef", "error", "could not be computed")]
    assert "worker raised MemoryError" in failed[1][-1]
    # the stable fraction, as the sweep recorded it (converged column)
    index = pd.read_csv(sweeps["grid"] / "index.csv")
    n_conv = int(index["converged"].sum())
    assert f"converged, as the sweep recorded it): {n_conv} of 4" in md
    # two varied parameters on a grid: heatmaps; one varied parameter: metric plots
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures == [
        "sweep_grid_heatmap_max_abs_constraint_error.png",
        "sweep_grid_heatmap_settling_time.png",
        "sweep_with_error_theta_1.png",
    ]
    for name in figures:
        _assert_png(out / "figures" / name)
    # metrics in the sweep table are those of the store files (the index's columns)
    table = pd.read_csv(out / "sweep_grid.csv", engine="python")
    for row in table.to_dict("records"):
        s = read_chunk_rows(sweeps["grid"] / row["file"])[row["file_row"]]
        if row["status"] == "success":
            assert row["report:max_abs_constraint_error"] == max(s[f"max_abs_constraint_error_{a}"] for a in "xyz")
    line = pd.read_csv(out / "sweep_with_error.csv")
    assert len(line) == 4
    assert np.isnan(line.loc[line["run_id"] == "r9999-deadbeef", "report:max_abs_constraint_error"]).all()
    # summary.csv: one row per run file of every sweep
    assert len(pd.read_csv(out / "summary.csv")) == 4 + 3


def test_sweep_parameters_are_the_varied_columns_of_the_index(sweeps):
    inputs = load_inputs([sweeps["grid"], sweeps["with_error"]])
    grid, line = inputs.sweeps
    assert grid.varied == ["theta_1", "omega_1"]
    assert line.varied == ["theta_1"]
    assert [r is None for r in line.runs] == [False, False, False, True]
    assert inputs.runs == []


def test_list_parameters_are_grouped_for_grids_and_split_for_random_draws():
    from rbstab.report.load import _parameter_axes

    index = pd.DataFrame({
        "run_id": ["a", "b", "c", "d"], "run": [0, 1, 2, 3], "base": ["case3"] * 4,
        "k_c_0": [4100, 4100, 12300, 12300], "k_c_1": [4100, 4100, 12300, 12300],
        "k_c_2": [3280, 3280, 9840, 9840],
        "omega_0": [1.0, 2.0, 3.0, 4.0], "omega_1": [5.0, 6.0, 7.0, 8.0],
        "omega_2": [-16.0] * 4,
        "mass": [40.0, 41.0, 42.0, 43.0], "mass_scale": [0.97, 1.0, 1.02, 1.05],
        "variant": ["embedded"] * 4, "status": ["success"] * 4, "converged": [True] * 4, "lyapunov_final": [1.0] * 4,
    })
    parameters = {"k_c_0": "controller.k_c.0", "k_c_1": "controller.k_c.1", "k_c_2": "controller.k_c.2",
                  "omega_0": "initial_state.omega.0", "omega_1": "initial_state.omega.1",
                  "omega_2": "initial_state.omega.2", "mass": "body.mass", "mass_scale": "body.mass:scale"}
    axes = _parameter_axes(index, parameters, {"initial_state.omega", "body.mass"})
    assert list(axes) == ["controller.k_c", "omega_0", "omega_1", "mass_scale"]
    assert list(axes["controller.k_c"]) == ["[4100, 4100, 3280]"] * 2 + ["[12300, 12300, 9840]"] * 2


# -- options, errors, defaults ---------------------------------------------------------------

def test_every_summary_figure_is_an_allowed_metric(paper_runs):
    summary = read_summary(paper_runs[2])["summary"]  # embedded: every state block
    for key, value in summary.items():
        if isinstance(value, str):
            continue
        names = [key] + ([f"{key}_{i}" for i in "xyz"] if isinstance(value, list) else [])
        assert validate_metrics(names) == names
    assert set(DEFAULT_METRICS) <= set(allowed_metrics())


def test_unknown_metric_is_refused_with_the_allowed_names_and_nothing_written(paper_runs, tmp_path):
    out = _clean_error(_invoke("report", paper_runs[0], "-o", tmp_path / "r", "--metric", "max_e"),
                       "unknown metric 'max_e'", "lyapunov_final", "settling_time")
    assert "max_abs_constraint_error_z" in out
    assert not (tmp_path / "r").exists()


def _not_a_result(tmp_path: Path) -> Path:
    import h5py

    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["x"] = np.arange(3.0)
        f.attrs["title"] = "someone else's data"
    return path


@pytest.mark.parametrize("kind", ["missing", "foreign_hdf5", "not_hdf5", "empty_folder"])
def test_bad_input_gives_a_clear_error_and_writes_nothing(kind, paper_runs, tmp_path):
    bad, expected = {
        "missing": (tmp_path / "nope.h5", "no such file or folder"),
        "foreign_hdf5": (None, "not an rbstab run result"),
        "not_hdf5": (ROOT / "configs" / "paper" / "case1_permanent.yaml", "not an HDF5 file"),
        "empty_folder": (tmp_path / "empty", "empty folder"),
    }[kind]
    if kind == "foreign_hdf5":
        bad = _not_a_result(tmp_path)
    if kind == "empty_folder":
        bad.mkdir()
    before = sorted(tmp_path.rglob("*"))
    out = tmp_path / "reports" / "r"
    result = _invoke("report", paper_runs[0], bad, "-o", out)  # a good input beside the bad one
    _clean_error(result, str(bad), expected)
    assert str(paper_runs[0]) not in result.output  # only the bad input is named
    assert sorted(tmp_path.rglob("*")) == before  # no report folder, no temporary folder


def test_every_bad_input_is_listed_at_once(tmp_path):
    (tmp_path / "empty").mkdir()
    result = _invoke("report", tmp_path / "a.h5", _not_a_result(tmp_path), tmp_path / "empty", "-o", tmp_path / "r")
    _clean_error(result, "a.h5", "other.h5", "empty folder")
    assert not (tmp_path / "r").exists()


def test_incomplete_sweep_folder_is_refused(tmp_path, sweeps):
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "sweep.yaml").write_text((sweeps["grid"] / "sweep.yaml").read_text())
    _clean_error(_invoke("report", broken, "-o", tmp_path / "r"), "incomplete sweep folder (no index.csv)")
    assert not (tmp_path / "r").exists()


def test_output_folder_that_is_not_a_report_is_never_replaced(paper_runs, tmp_path):
    precious = tmp_path / "data"
    precious.mkdir()
    (precious / "notes.txt").write_text("keep me")
    _clean_error(_invoke("report", paper_runs[0], "-o", precious), "not an rbstab report")
    assert [p.name for p in precious.iterdir()] == ["notes.txt"]


def test_report_of_a_failed_run_goes_to_the_default_folder(sweeps, tmp_path, monkeypatch):
    run_id = _run_id(sweeps["line"], GIMBAL_THETA_2)
    failed = sweeps["line"] / "runs" / f"{run_id}.h5"
    monkeypatch.chdir(tmp_path)
    result = _ok(_invoke("report", failed))
    folder = tmp_path / "results" / "reports" / run_id  # the run's name
    assert f"report: {Path('results/reports') / run_id / 'index.html'}" in result.output
    md = (folder / "summary.md").read_text()
    row = _md_table(md, "Runs: identity, solver statistics, status")[0]
    assert row[3] == "failed" and "gimbal lock" in row[-1]
    settle = _md_table(md, "Constraint error and Lyapunov function")[0]
    assert settle[2] == "not settled"
    for src in _images(folder / "index.html").src:
        _assert_png(folder / src)


def test_a_second_report_into_the_same_folder_replaces_the_first(sweeps, tmp_path):
    out = tmp_path / "reports" / "line"
    _ok(_invoke("report", sweeps["line"], "-o", out, "--metric", "lyapunov_final"))
    (out / "stale.txt").write_text("from an earlier report")
    _ok(_invoke("report", sweeps["line"], "-o", out, "--metric", "max_lyapunov_rate"))
    assert not (out / "stale.txt").exists()
    assert json.loads((out / "report.json").read_text())["metrics"] == ["max_lyapunov_rate"]
    assert [p.name for p in out.parent.iterdir()] == ["line"]  # no temporary or old folder left


def test_default_report_name(paper_runs, sweeps):
    assert default_report_name(load_inputs([paper_runs[0]])) == "case1_permanent"
    assert default_report_name(load_inputs([sweeps["grid"]])) == "grid"
    several = default_report_name(load_inputs(paper_runs))
    assert several == "case1_permanent_vs_case2_visco_elastic_vs_case3_embedded"  # named after the inputs
    assert several == default_report_name(load_inputs(paper_runs[::-1]))  # order does not matter
    assert default_report_name(load_inputs(paper_runs[:2])) == "case1_permanent_vs_case2_visco_elastic"
    mixed = default_report_name(load_inputs([paper_runs[2], sweeps["grid"]]))
    assert mixed == "case3_embedded_vs_grid"


def test_load_inputs_raises_one_error_listing_every_problem(tmp_path):
    with pytest.raises(ReportInputError) as info:
        load_inputs([tmp_path / "a.h5", tmp_path / "b.h5"])
    assert len(info.value.problems) == 2


def test_settling_time_is_the_first_time_after_which_both_norms_stay_under_their_thresholds():
    t = np.linspace(0.0, 1.0, 11)
    e = np.zeros((11, 3))
    omega = np.zeros((11, 3))
    th = SettleThresholds(e=0.01, omega=0.1)
    assert settling_time(t, e, omega, th) == 0.0
    e[:4, 0] = 0.02  # |E| too large until t = 0.3
    omega[6, 1] = 0.2  # one late excursion of |Omega| at t = 0.6
    assert settling_time(t, e, omega, th) == pytest.approx(0.7)
    e[:, :] = 0.006  # |E| = 0.0104 > 0.01: the norm counts, not each component
    assert np.isnan(settling_time(t, e, omega, th))
    omega[-1, 2] = np.nan  # a failed run's NaN tail never settles
    assert np.isnan(settling_time(t, np.zeros((11, 3)), omega, th))


def test_cli_defaults_are_the_library_defaults():
    assert report_cli._SETTLE_E == DEFAULT_SETTLE_E
    assert report_cli._SETTLE_OMEGA == DEFAULT_SETTLE_OMEGA
    assert report_cli._METRICS == DEFAULT_METRICS
    assert report_cli._FIGURE_FORMATS == FIGURE_FORMATS
    assert report_cli._DPI == DPI and report_cli._DPI_RANGE == DPI_RANGE


def test_cli_start_up_imports_no_plotting_or_table_library():
    code = (
        "import sys, rbstab_cli.main; "
        "print(sorted(m for m in ('matplotlib', 'pandas', 'xarray', 'h5py', 'rbstab.report') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_settling_times_of_a_store_read_a_file_at_a_time_equal_a_run_at_a_time(sweeps):
    """settle_store_runs (each store file's traces read once) gives each run the settling
    time run_settling_time computes from that run's own series."""
    from rbstab.report.load import load_sweep
    from rbstab.report.tables import run_settling_time, settle_store_runs

    thresholds = SettleThresholds(e=0.5, omega=5.0)
    bulk = load_sweep(sweeps["grid"])
    alone = load_sweep(sweeps["grid"])
    assert any(run is not None and run.row is not None for run in bulk.runs)
    settle_store_runs(bulk.runs, thresholds)
    got = [run_settling_time(run, thresholds) for run in bulk.runs if run is not None]
    want = [run_settling_time(run, thresholds) for run in alone.runs if run is not None]
    np.testing.assert_array_equal(got, want)
    assert np.isfinite(got).sum() >= 1 and np.isnan(got).sum() >= 1  # one settles, the failed one not


# -- settled, and at rest without settling ------------------------------------------------------------

def test_a_leaning_rest_and_an_unstable_rest_are_not_counted_as_settled(tmp_path):
    """The stance example pinned at the ankle without its torque limit: 1300 N m/rad holds
    it upright, 550 N m/rad is below gravity's stiffness m g L = 652 N m/rad, so upright is
    unstable and the body leans over to rest where 550 theta = m g L sin(theta). From 0.1
    rad the weak one comes to rest leaning (under the thresholds, v far from zero): 'rest
    away from equilibrium'; started at rest upright it stays there (v zero throughout, no
    motion): 'unstable rest'. Neither settled, neither has a settling time."""
    from scipy.optimize import brentq

    from rbstab.analysis.linearise import rest_verdict

    spec = tmp_path / "lean.yaml"
    spec.write_text(yaml.safe_dump({"name": "lean", "base": str(ROOT / "configs/examples/stance_ankle.yaml"),
                                    "grid": {"controller.k_r": [[1300, 1300, 200], [550, 1300, 200]],
                                             "initial_state.theta": [[0.1, 0, 0], [0, 0, 0]]}}, sort_keys=False))
    long = ["--set", "controller.saturation=null", "--set", "controller.l_r=[200, 350, 50]",
            "--set", "simulation.t_end=30", "--set", "simulation.n_samples=601",
            "--set", "simulation.limits=null"]  # the lean rests at 0.99 rad, past the example's region
    _ok(_invoke("sweep", spec, "-o", tmp_path / "sweeps", "-j", "1", "--no-progress", *long))
    out = tmp_path / "report"
    _ok(_invoke("report", tmp_path / "sweeps" / "lean", "-o", out, "--format", "md", "-j", "1",
                "--metric", "settling_time", "--metric", "settled"))
    table = pd.read_csv(out / "sweep_lean.csv").set_index(["k_r_0", "theta_0"])
    upright, leaning, weak_upright = (1300, 0.1), (550, 0.1), (550, 0.0)
    # physics: the weak one rests at the leaning equilibrium, the weak upright one never moves
    m_g_l = 70.0 * 9.81 * 0.95
    lean = brentq(lambda th: 550 * th - m_g_l * np.sin(th), 0.5, 1.5)
    runs = {r.name: r for r in load_inputs([tmp_path / "sweeps" / "lean"]).sweeps[0].runs}
    final = {key: runs[table.loc[key, "run_id"]].summary for key in (leaning, weak_upright)}
    assert final[leaning]["final_theta"][0] == pytest.approx(lean, abs=1e-3)
    assert final[weak_upright]["final_theta"] == [0, 0, 0] and final[weak_upright]["lyapunov_final"] == 0
    assert rest_verdict(runs[table.loc[weak_upright, "run_id"]].config) == "unstable"  # 550 < m g L
    assert rest_verdict(runs[table.loc[upright, "run_id"]].config) == "asymptotically stable"
    # both came under the thresholds: what counted them as settled before
    assert table.loc[leaning, "converged"] == False and table.loc[weak_upright, "converged"] == True  # noqa: E712
    rest = table["report:rest"].to_dict()
    assert rest == {upright: "settled", (1300, 0.0): "settled", leaning: "rest away from equilibrium",
                    weak_upright: "unstable rest"}
    assert table["report:settled"].to_dict() == {k: v == "settled" for k, v in rest.items()}
    assert np.isnan(table.loc[[leaning, weak_upright], "report:settling_time"]).all()
    assert np.isfinite(table.loc[[upright], "report:settling_time"]).all()
    page = (out / "index.md").read_text()
    assert "v converged, the rest state not linearly unstable): 2 of 4 = 50%" in page
    assert "at rest but not settled: 1 rest away from equilibrium (v not converged), 1 unstable rest" in page
    index = {(r[1], r[2]): r[-1] for r in _md_table(page, "Index of lean (metrics read back from the run files)")}
    assert index == {("550", "0.1"): "rest away from equilibrium", ("550", "0"): "unstable rest",
                     ("1300", "0.1"): "settled", ("1300", "0"): "settled"}
    summary = pd.read_csv(out / "summary.csv").set_index("run")  # every run, with the default ratio
    assert summary.loc[table.loc[leaning, "run_id"], "rest"] == "rest away from equilibrium"
    assert summary.loc[table.loc[weak_upright, "run_id"], "rest"] == "unstable rest"
    assert np.isnan(summary.loc[table.loc[weak_upright, "run_id"], "settling_time"])


def test_a_chain_beside_a_slowly_unstable_upright_is_an_unstable_rest(tmp_path):
    """The ankle-hip stance with ankle stiffness 705 N m/rad, just below the ~713 that
    gravity and the hip need: upright is unstable, but its growing mode's e-folding time
    (~40 s) is far longer than t_end = 5 s, so from the example's lean the body comes to rest
    near upright with v converged by the sweep's ratio 0.01: an unstable rest, not settled;
    with 1000 N m/rad it settles."""
    from rbstab.analysis.linearise import linearise_config
    from rbstab.config.loader import config_from_mapping

    spec = tmp_path / "upright.yaml"
    spec.write_text(yaml.safe_dump({"name": "upright", "base": str(ROOT / "configs/examples/stance_ankle_hip.yaml"),
                                    "grid": {"joints.ankle.k_r.0": [705, 1000]},
                                    "convergence": {"lyapunov_ratio": 0.01}}, sort_keys=False))
    _ok(_invoke("sweep", spec, "-o", tmp_path / "sweeps", "-j", "1", "--no-progress",
                "--set", "simulation.n_samples=501"))
    sweep = load_inputs([tmp_path / "sweeps" / "upright"]).sweeps[0]
    weak = next(r for r in sweep.runs if r.config["joints"][0]["k_r"][0] == 705)
    growth = linearise_config(config_from_mapping(weak.config, default_name="weak")).eigenvalues[0].real
    assert 0 < growth < 0.2 / 5.0  # grows by less than e^0.2 over t_end
    table = sweep_table(sweep, ["settling_time"], SettleThresholds()).set_index("ankle_k_r_0")
    assert table["converged"].astype(str).eq("True").all()  # by v alone both would count
    assert table["report:rest"].to_dict() == {705: "unstable rest", 1000: "settled"}
    assert table["report:rest_state"].to_dict() == {705: "unstable", 1000: "asymptotically stable"}
    assert table["report:settled"].to_dict() == {705: False, 1000: True}
    assert np.isnan(table.loc[705, "report:settling_time"]) and table.loc[1000, "report:settling_time"] > 0


def test_configuration_keys_are_flattened_as_set_and_sweeps_name_them():
    """The runs table's parameter columns are the keys of --set and of sweeps: mappings by
    their keys, lists of mappings by their entries' names (a tree's bodies and joints) or
    else by position (disturbances), vectors and matrices whole; each key leads to what a
    sweep over it varies."""
    from rbstab.config.paths import parse_any_key
    from rbstab.report.load import flatten_config

    config = {"simulation": {"t_end": 2.0}, "controller": {"k_t": [[1, 0], [0, 1]]},
              "bodies": [{"name": "legs", "mass": 22.5}, {"name": "trunk", "mass": 46.2, "inertia": [3, 3, 0.4]}],
              "disturbances": [{"kind": "impulse", "value": [0, 15, 0]}, {"kind": "pulse", "start": 1.0}]}
    flat = flatten_config(config)
    assert flat == {"simulation.t_end": 2.0, "controller.k_t": [[1, 0], [0, 1]], "bodies.legs.name": "legs",
                    "bodies.legs.mass": 22.5, "bodies.trunk.name": "trunk", "bodies.trunk.mass": 46.2,
                    "bodies.trunk.inertia": [3, 3, 0.4], "disturbances.0.kind": "impulse",
                    "disturbances.0.value": [0, 15, 0], "disturbances.1.kind": "pulse", "disturbances.1.start": 1.0}
    for key in ("bodies.trunk.mass", "disturbances.0.value", "controller.k_t"):
        parse_any_key(key)  # a key of the grammar
