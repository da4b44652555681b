"""Report figures: formats and resolution, the per-run figures (forces, terms of v, phase
portraits), logarithmic scales, the page title and the default folder name."""

from __future__ import annotations

import html.parser
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import ROOT
from rbstab.report import ReportError, ReportOptions, build_report, default_report_name, load_inputs
from rbstab.report.figures import FigureWriter, run_figures, set_scale
from rbstab_cli.main import cli

SHORT = ["--set", "simulation.n_samples=201", "--set", "simulation.t_end=0.5"]
PAPER = ROOT / "configs" / "paper"

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


def _ok(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=True)
    assert result.exit_code == 0, (result.output, result.exception)
    return result


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """case 1 (permanent, gravity: a term of v changes sign) and case 3 (embedded), 0.5 s."""
    out = tmp_path_factory.mktemp("runs")
    _ok("run", PAPER / "case1_permanent.yaml", PAPER / "case3_embedded.yaml", "-o", out, *SHORT)
    return {"case1": out / "case1_permanent.h5", "case3": out / "case3_embedded.h5"}


class _Page(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.src, self.href, self.title, self.h1 = [], [], [], []
        self._in = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self._in = tag
        if tag == "img":
            self.src.append(attrs["src"])
        if tag == "a":
            self.href.append(attrs["href"])

    def handle_data(self, data):
        if self._in in ("title", "h1"):
            getattr(self, self._in).append(data)

    def handle_endtag(self, tag):
        self._in = None


def _page(folder: Path) -> _Page:
    page = _Page()
    page.feed((folder / "index.html").read_text(encoding="utf-8"))
    return page


# -- formats and resolution --------------------------------------------------------------------------

def test_every_figure_in_every_format_asked_at_the_resolution_asked(runs, tmp_path):
    from PIL import Image

    out = tmp_path / "fig"
    _ok("report", runs["case3"], "-o", out, "--figure-format", "png,pdf", "--figure-format", "svg", "--dpi", "220")
    stems = sorted({p.stem for p in (out / "figures").iterdir()})
    assert {f"case3_embedded_{k}" for k in ("rotational", "translational", "lyapunov", "forces", "phase")} <= set(stems)
    page = _page(out)
    for stem in stems:
        png, pdf, svg = (out / "figures" / f"{stem}.{ext}" for ext in ("png", "pdf", "svg"))
        assert pdf.read_bytes()[:5] == b"%PDF-" and b"<svg" in svg.read_bytes()[:2000]
        with Image.open(png) as im:
            assert round(im.info["dpi"][0]) == 220
        assert f"figures/{stem}.png" in page.src  # the page shows the PNG and links every file
        assert {f"figures/{stem}.{ext}" for ext in ("png", "pdf", "svg")} <= set(page.href)
    manifest = json.loads((out / "report.json").read_text())
    assert manifest["figure_formats"] == ["png", "pdf", "svg"] and manifest["dpi"] == 220
    assert len(manifest["figures"]) == 3 * len(stems)
    assert manifest["provenance"]["Conventions"] == "CF-1.10"


def _one_figure():
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.0, 3.0))
    fig.subplots().plot([0, 1], [1, 0])
    return fig


def test_resolution_scales_the_png(tmp_path):
    from PIL import Image

    widths = {}
    for dpi in (60, 120):
        written = FigureWriter(_figures(tmp_path / str(dpi)), dpi=dpi).save(_one_figure(), "f", "t", "c")
        with Image.open(tmp_path / str(dpi) / written.path) as im:
            widths[dpi] = im.size[0]
    assert widths == {60: 240, 120: 480}  # 4 inches


def test_pdf_alone_still_gives_the_page_an_image(tmp_path):
    from rbstab.report.render import Section, render_html, render_markdown

    written = FigureWriter(_figures(tmp_path), formats=("pdf",)).save(_one_figure(), "f", "t", "c")
    assert written.path == "figures/f.png" and written.files == ("figures/f.pdf",)
    assert (tmp_path / written.path).is_file() and (tmp_path / "figures/f.pdf").read_bytes()[:5] == b"%PDF-"
    page = _Page()
    page.feed(render_html("t", [], [Section("s", "s", [written])]))
    assert page.src == ["figures/f.png"] and "figures/f.pdf" in page.href
    assert "[PDF](figures/f.pdf)" in render_markdown("t", [], [Section("s", "s", [written])])
    svg = FigureWriter(_figures(tmp_path / "svg"), formats=("svg", "pdf")).save(_one_figure(), "f", "t", "c")
    assert svg.path == "figures/f.svg" and svg.files == ("figures/f.svg", "figures/f.pdf")


@pytest.mark.parametrize("args, message", [
    (["--figure-format", "png,gif"], "gif"),
    (["--dpi", "10"], "10"),
    (["--dpi", "5000"], "5000"),
])
def test_bad_figure_options_are_refused_before_anything_is_written(runs, tmp_path, args, message):
    result = CliRunner().invoke(cli, ["report", str(runs["case3"]), "-o", str(tmp_path / "r"), *args])
    assert result.exit_code == 2 and message in result.output and "Traceback" not in result.output
    assert not (tmp_path / "r").exists()


def test_library_refuses_bad_figure_options(runs, tmp_path):
    for options in (ReportOptions(figure_formats=("jpg",)), ReportOptions(dpi=1), ReportOptions(title="  ")):
        with pytest.raises(ReportError):
            build_report([runs["case3"]], tmp_path / "r", options)
    assert not (tmp_path / "r").exists()


# -- title and folder ----------------------------------------------------------------------------------

@pytest.fixture
def no_rendering(monkeypatch):
    """Figures are drawn but not rendered to files, animations left out (what a test of the page needs, faster);
    drawn in this process, where these patches hold (not in worker processes)."""
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: None)
    monkeypatch.setattr("rbstab.report.build._animation", lambda run, frames: "")
    monkeypatch.setattr("rbstab.report.build._jobs", lambda options: 1)


def test_title_is_what_the_report_compares_unless_given(runs, tmp_path, no_rendering):
    default = build_report([runs["case3"], runs["case1"]], tmp_path / "a")
    page = _page(default)
    expected = "rbstab report: case3_embedded and case1_permanent"
    assert page.title == [expected] and page.h1 == [expected]
    given = build_report([runs["case3"]], tmp_path / "b", ReportOptions(title="Figure 7 & friends"))
    assert _page(given).title == ["Figure 7 & friends"]
    assert json.loads((given / "report.json").read_text())["title"] == "Figure 7 & friends"


def test_default_folder_is_named_after_the_inputs(runs, tmp_path, monkeypatch, no_rendering):
    monkeypatch.chdir(tmp_path)
    _ok("report", runs["case1"], runs["case3"])
    assert (tmp_path / "results/reports/case1_permanent_vs_case3_embedded/index.html").is_file()
    # the same name twice, or too long a name: the first two names and a hash of the paths
    other = tmp_path / "other"
    other.mkdir()
    (other / "case3_embedded.h5").write_bytes(runs["case3"].read_bytes())
    twice = default_report_name(load_inputs([runs["case3"], other / "case3_embedded.h5"]))
    assert twice.startswith("case3_embedded_vs_case3_embedded-") and len(twice.rsplit("-", 1)[1]) == 8
    folders = [tmp_path / f"{'x' * 30}{i}" for i in range(4)]
    for folder in folders:
        folder.mkdir()
        (folder / "r.h5").write_bytes(runs["case1"].read_bytes())
    long = default_report_name(load_inputs(folders))
    assert long.startswith(f"{'x' * 30}0_vs_{'x' * 30}1_and_2_more-") and len(long) < 100


# -- the figures of a run --------------------------------------------------------------------------------

def test_run_figures_show_forces_terms_of_v_on_a_log_axis_and_phase_portraits(runs, tmp_path, monkeypatch):
    import matplotlib.figure

    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    inputs = load_inputs([runs["case1"], runs["case3"]])
    by_name = {r.name: r for r in inputs.runs}
    captions = {}
    for run in inputs.runs:
        captions.update({f.path: f.caption for f in run_figures(run, FigureWriter(tmp_path))})
    assert all(isinstance(f, matplotlib.figure.Figure) for f in saved.values())
    lyapunov = saved["case1_permanent_lyapunov"].axes[0]
    assert lyapunov.get_yscale() == "log"  # v and its terms over decades
    labels = [line.get_label() for line in lyapunov.get_lines()]
    assert "$v$" in labels and any("|v_g|" in label for label in labels)  # gravity changes sign: |v_g|
    forces = saved["case3_embedded_forces"].axes
    assert [ax.get_ylabel().split(" $")[0] for ax in forces] == ["constraint force", "feedback force", "feedback torque"]
    assert {ax.get_yscale() for ax in forces} <= {"symlog", "linear"}
    lam = by_name["case3_embedded"].series("constraint_force")["constraint_force"]
    np.testing.assert_array_equal(forces[0].get_lines()[0].get_ydata(), lam[:, 0])  # the stored values, drawn
    assert len(saved["case3_embedded_phase"].axes) == 6  # Theta-Omega and E-F, per component
    assert len(saved["case1_permanent_phase"].axes) == 3  # permanent: E = 0, no E-F portraits
    assert "E_i against its rate F_i" in captions["figures/case3_embedded_phase.png"]


def test_a_thinned_store_run_has_the_figures_its_file_allows(tmp_path, no_rendering):
    spec = tmp_path / "s.yaml"
    spec.write_text(f"name: s\nbase: {PAPER / 'case3_embedded.yaml'}\ngrid:\n  body.mass: [40, 41]\n")
    _ok("sweep", spec, "-o", tmp_path / "sweeps", "-j", "1", "--no-progress", *SHORT)
    (chunk,) = sorted((tmp_path / "sweeps" / "s" / "runs").glob("chunk-*.h5"))
    run = load_inputs([chunk]).runs[0]
    kinds = [f.path.split("_", 1)[1] for f in run_figures(run, FigureWriter(_figures(tmp_path)))]
    assert kinds == ["rotational.png", "translational.png", "lyapunov.png", "phase.png"]  # no forces stored


def _figures(folder: Path) -> Path:
    (folder / "figures").mkdir(parents=True, exist_ok=True)
    return folder


# -- scales ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("values, scale", [
    (np.exp(-np.linspace(0, 10, 200)) * 1e4, "log"),  # positive, over four decades
    (np.r_[0.0, np.exp(-np.linspace(0, 10, 200))], "log"),  # zeros are not drawn on it
    (np.exp(-np.linspace(0, 10, 200)) * np.cos(np.linspace(0, 40, 200)), "symlog"),  # a decaying oscillation
    (np.sin(np.linspace(0, 20, 200)), "linear"),  # no decay
    (np.linspace(1.0, 50.0, 200), "linear"),  # less than two decades
    (np.r_[np.zeros(400), -np.linspace(3.0, 30.0, 200)], "linear"),  # one axis acted on, two at zero: one decade
    (np.zeros(10), "linear"),
    (np.full(10, np.nan), "linear"),
])
def test_set_scale_uses_a_log_axis_only_where_values_span_decades(values, scale):
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    ax.plot(values)
    assert set_scale(ax, values) == scale
    assert ax.get_yscale() == scale


# -- saturating actuators and disturbances -----------------------------------------------------------------

EXAMPLE = ROOT / "configs" / "examples" / "saturated_push.yaml"


def _spans(ax, gid: str) -> list[tuple[float, float]]:
    """The (t0, t1) of the spans of ``ax`` whose gid is ``gid``."""
    return sorted((float(p.get_x()), float(p.get_x() + p.get_width())) for p in ax.patches if p.get_gid() == gid)


def test_saturated_push_report_shades_the_limits_marks_the_pushes_and_draws_v_minus_w(tmp_path, monkeypatch):
    """The shipped saturated push: the forces figure shades, on N's panel, exactly the
    intervals where the stored |N_1| is the 4 N m limit (and nothing on the other axes);
    every time panel marks the impulse with a line at 0.5 s and the pulse with a span over
    [2.5, 2.55] s; the Lyapunov figure draws v - W from the stored v and W; the page's table
    gives the saturated time fractions the run file holds."""
    from rbstab.report.figures import saturated_intervals

    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    monkeypatch.setattr("rbstab.report.build._animation", lambda run, frames: "")
    monkeypatch.setattr("rbstab.report.build._jobs", lambda options: 1)
    _ok("run", EXAMPLE, "-o", tmp_path, "--set", "simulation.n_samples=5001")
    (run,) = load_inputs([tmp_path / "saturated_push.h5"]).runs
    s = run.series("torque_n", "lyapunov", "disturbance_work")
    at_limit = np.abs(s["torque_n"][:, 0]) == 4.0
    assert at_limit.any() and not at_limit.all()
    run_figures(run, FigureWriter(tmp_path))
    forces = saved["saturated_push_forces"].axes
    assert len(forces) == 2  # Lambda and N: H is zero throughout (K_t, L_t zero), not drawn
    n_panel = forces[1]
    shaded = _spans(n_panel, "saturated-torque_n-1")
    assert shaded == saturated_intervals(s["time"], at_limit.astype(float)) and len(shaded) >= 2
    starts = [a for a, _ in shaded]
    assert any(0.49 < a < 0.6 for a in starts) and any(2.49 < a < 2.6 for a in starts)  # after each push
    assert not _spans(n_panel, "saturated-torque_n-2")
    limits = sorted(line.get_ydata()[0] for line in n_panel.get_lines() if line.get_gid() == "limit-1")
    assert limits == [-4.0, 4.0]  # N_1 reaches its limit: drawn
    second = [line for line in n_panel.get_lines() if line.get_gid() == "limit-2"]
    assert bool(second) == (np.abs(s["torque_n"][:, 1]).max() >= 2.0)  # where N_2 reaches half of its limit
    assert not [line for line in n_panel.get_lines() if line.get_gid() == "limit-3"]  # N_3 has none
    for name in ("rotational", "translational", "lyapunov", "forces"):
        for ax in saved[f"saturated_push_{name}"].axes:
            (impulse,) = [line for line in ax.get_lines() if line.get_gid() == "disturbance-impulse"]
            assert list(impulse.get_xdata()) == [0.5, 0.5]
            np.testing.assert_allclose(_spans(ax, "disturbance-pulse"), [(2.5, 2.55)])
    (work,) = [line for ax in saved["saturated_push_lyapunov"].axes for line in ax.get_lines()
               if line.get_gid() == "lyapunov-minus-work"]
    np.testing.assert_array_equal(work.get_ydata(), s["lyapunov"] - s["disturbance_work"])
    assert s["disturbance_work"][-1] > 0.0
    folder = build_report([tmp_path / "saturated_push.h5"], tmp_path / "report")
    page = (folder / "index.html").read_text()
    fraction = run.summary["fraction_saturated_torque_n"]
    assert "fraction of time N_i saturated" in page and f"{fraction[0]:.3g}" in page
    assert "impulse at 0.5 s, pulse at 2.5 s" in page


# -- the figures of a sweep --------------------------------------------------------------------------------

#: The stance example's ankle stiffness and hip damping, as its sweep's columns and entries name them.
ANKLE, HIP = "ankle_k_r_0", "hip_l_r_0"
ENTRIES = {ANKLE: "joints.ankle.k_r.0", HIP: "joints.hip.l_r.0"}


def _sweep_table(metrics: dict, varied=(ANKLE, HIP)):
    """A SweepData of a 3 x 3 grid (one varied parameter: a line of 9 runs) and its report
    table, each metric's values given (9 a metric), every run a success."""
    import pandas as pd

    from rbstab.report.load import SweepData

    grid = np.array([(a, h) for h in (20.0, 100.0, 400.0) for a in (700.0, 1000.0, 1300.0)])
    table = pd.DataFrame({ANKLE: grid[:, 0], HIP: grid[:, 1], "status": "success", "report:rest": ""})
    if len(varied) == 1:
        table[HIP] = 100.0
    for name, values in metrics.items():
        table[f"report:{name}"] = values
    axes = {p: table[p] for p in (ANKLE, HIP)}
    sweep = SweepData(Path("sw"), "sw", {}, table, [None] * len(table), [ANKLE, HIP], list(varied), axes, ENTRIES)
    return sweep, table


#: v(t_end) [J] of a chain's sweep: both signs, over decades (the stance's falls end below its zero).
SIGNED = [0.0115, 0.0107, 2.3e-6, -0.0061, 2.0e-4, 8.2e-6, -0.0044, 1.8e-3, 3.2e-5]
#: A centre-of-mass excursion [m] over three decades, and a peak sway [m] within one.
DECADES = [2e-5, 1e-4, 3e-3, 2e-2, 1e-3, 5e-4, 2e-4, 3e-5, 1e-2]
NARROW = [0.022, 0.024, 0.026, 0.0034, 0.0099, 0.012, 0.015, 0.0073, 0.0115]
#: max |E| [m] of permanent joints: rounding.
ROUNDING = [2.2e-16, 2.2e-16, 6.9e-18, 2.2e-16, 0.0, 2.2e-16, 1.1e-16, 2.2e-16, 2.2e-16]


def test_a_sweeps_heatmaps_have_units_and_scales_for_decades_and_leave_round_off_out(tmp_path, monkeypatch):
    """A heatmap's axes are the entries --grid sets with their units; its colours on a
    symmetric-log scale about zero (a diverging map) where signs mix over decades, a
    logarithmic one where positive values span decades, a linear one otherwise; a metric at
    round-off in every run gets a sentence, no figure."""
    from matplotlib.colors import LogNorm, SymLogNorm

    from rbstab.report.sweep_figures import sweep_figures

    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    metrics = {"lyapunov_final": SIGNED, "com_excursion": DECADES, "peak_sway": NARROW,
               "max_abs_constraint_error": ROUNDING}
    sweep, table = _sweep_table(metrics)
    drawn = sweep_figures(sweep, table, list(metrics), FigureWriter(_figures(tmp_path)))
    notes = [d for d in drawn if isinstance(d, str)]
    assert [f.path for f in drawn if not isinstance(f, str)] == [
        f"figures/sweep_sw_heatmap_{name}.png" for name in ("lyapunov_final", "com_excursion", "peak_sway")]
    assert len(notes) == 1 and notes[0].startswith("max |E| (largest component) [m]: round-off in every run")
    maps = {name: saved[f"sweep_sw_heatmap_{name}"].axes[0] for name in ("lyapunov_final", "com_excursion", "peak_sway")}
    for ax in maps.values():
        assert ax.get_xlabel() == "joints.ankle.k_r.0 [N m/rad]"
        assert ax.get_ylabel() == "joints.hip.l_r.0 [N m s/rad]"
    signed = maps["lyapunov_final"].images[0]
    assert isinstance(signed.norm, SymLogNorm) and signed.norm.vmin == -signed.norm.vmax == -0.0115
    assert signed.get_cmap().name == "RdBu_r"
    assert isinstance(maps["com_excursion"].images[0].norm, LogNorm)
    assert type(maps["peak_sway"].images[0].norm).__name__ == "Normalize"  # within a decade: linear


def test_a_sweeps_panels_have_units_and_scales_for_decades(tmp_path, monkeypatch):
    """With one varied parameter, its axis is labelled with its entry and units, and each
    metric's axis takes the scale of its values."""
    from rbstab.report.sweep_figures import sweep_figures

    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    metrics = {"lyapunov_final": SIGNED, "com_excursion": DECADES, "peak_sway": NARROW}
    sweep, table = _sweep_table(metrics, varied=(ANKLE,))
    sweep_figures(sweep, table, list(metrics), FigureWriter(_figures(tmp_path)))
    axes = saved[f"sweep_sw_{ANKLE}"].axes
    assert [ax.get_yscale() for ax in axes] == ["symlog", "log", "linear"]
    assert axes[-1].get_xlabel() == "joints.ankle.k_r.0 [N m/rad]"
    assert [ax.get_ylabel() for ax in axes] == ["v(t_end) [J]", "COM excursion [m]", "peak sway [m]"]


@pytest.mark.parametrize("name, values, why", [
    ("max_abs_constraint_error", ROUNDING, "round-off in every run"),
    ("max_abs_constraint_error", [*ROUNDING[:-1], 1e-7], None),  # one joint that moves: drawn
    ("lyapunov_final", [1e-13, -4e-14, 0.0], "round-off in every run"),
    ("peak_sway", [np.nan, np.nan], "no successful run has a value"),  # e.g. no gravity
    ("settling_time", [np.nan, np.nan], None),  # not settled anywhere: its cells say how each ended
    ("converged", [0.0, 0.0], None),  # dimensionless: 0 is a value, not round-off
    ("time_lyapunov_rising", [0.0, 0.0], None),  # a time: whole samples
])
def test_a_sweep_metric_is_left_out_when_it_is_round_off_or_has_no_value(name, values, why):
    from rbstab.report.sweep_figures import left_out

    found = left_out(name, values)
    assert (found is None) if why is None else (why in found)


def test_a_basin_map_without_a_certificate_has_no_contour_in_its_legend(tmp_path, monkeypatch):
    """The basin map's legend names the contour v = c only where it is drawn: not under
    --no-certificate (c NaN), nor where the slice lies inside it; its axes carry the keys'
    units as an axis writes them."""
    import xarray as xr

    from rbstab.report.analysis import _basin_figure

    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    x, y = np.linspace(-1.0, 1.0, 3), np.linspace(-0.1, 0.1, 3)
    ds = xr.Dataset({"basin_outcome": (("bx", "by"), np.array([[0, 1, 2], [0, 0, 1], [0, 0, 0]])),
                     "basin_time_to_converge": (("bx", "by"), np.full((3, 3), 0.5)),
                     "basin_lyapunov_initial": (("bx", "by"), np.add.outer(x ** 2, 10 * y ** 2))},
                    coords={"basin_x": ("bx", x, {"config_key": "initial_state.omega.0", "units": "rad s-1"}),
                            "basin_y": ("by", y, {"config_key": "initial_state.theta.0", "units": "rad"})},
                    attrs={"basin_ratio": 1e-3, "basin_t_end": 1.0})
    for c, contour in ((None, False), (0.5, True), (50.0, False)):
        with_c = ds if c is None else ds.assign(sublevel=c)
        _basin_figure(with_c, FigureWriter(_figures(tmp_path)), f"b{c}", "b")
        ax = saved[f"b{c}_basin"].axes[0]
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert not any("nan" in label for label in labels)
        assert any("sublevel estimate" in label for label in labels) == contour, (c, labels)
        assert ax.get_xlabel() == "initial_state.omega.0 [rad/s]"


def _drawn_example(name: str, tmp_path, monkeypatch) -> tuple[dict, object]:
    """(the figures of a 0.5 s run of configs/examples/<name>.yaml by file stem, the run)."""
    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    _ok("run", ROOT / "configs" / "examples" / f"{name}.yaml", "-o", tmp_path,
        "--set", "simulation.t_end=0.5", "--set", "simulation.n_samples=51")
    run = load_inputs([tmp_path / f"{name}.h5"]).runs[0]
    run_figures(run, FigureWriter(_figures(tmp_path)))
    return saved, run


def test_a_trees_balance_draws_its_centre_of_mass_and_centre_of_pressure(tmp_path, monkeypatch):
    """A tree on the ground gets a balance figure: the whole-body COM and the ankle's centre
    of pressure along x and y (g along -z), and the ground's push n'Lambda beside the total
    weight, as the file holds them; one body's run has none."""
    saved, run = _drawn_example("stance_hinges", tmp_path, monkeypatch)
    s = run.series("com_position", "centre_of_pressure", "constraint_force")
    axes = saved["stance_hinges_balance"].axes
    for k, ax in enumerate(axes[:2]):
        com, cop = (line.get_ydata() for line in ax.get_lines()[:2])
        np.testing.assert_array_equal(com, s["com_position"][:, k])
        np.testing.assert_array_equal(cop, s["centre_of_pressure"][:, 0, k])
        assert "ankle" in ax.get_lines()[1].get_label() and len(ax.get_lines()) == 2  # the only joint to the ground
    push, weight = axes[2].get_lines()[:2]
    np.testing.assert_array_equal(push.get_ydata(), s["constraint_force"][:, 0, 2])
    assert weight.get_ydata()[0] == pytest.approx(9.81 * (6.51 + 14.0 + 47.46), rel=1e-12)
    assert np.ptp(s["centre_of_pressure"][:, 0, 1]) > 0.01  # it moves: the trace is not a flat line
    saved.clear()
    _ok("run", PAPER / "case1_permanent.yaml", "-o", tmp_path, "--set", "simulation.n_samples=51")
    run_figures(load_inputs([tmp_path / "case1_permanent.h5"]).runs[0], FigureWriter(_figures(tmp_path)))
    assert saved and not any(name.endswith("_balance") for name in saved)


def test_a_chains_centre_of_mass_is_drawn_as_its_displacement(tmp_path, monkeypatch):
    """A chain's translational figure draws each body's X - X(0), its start written under
    the axis label: centimetres of sway are not drawn beside the legs' 0.475 m height."""
    saved, run = _drawn_example("stance_ankle_hip", tmp_path, monkeypatch)
    position = run.series("position")["position"]
    axes = saved["stance_ankle_hip_translational"].axes
    for col, body in enumerate(("legs", "trunk")):
        ax = axes[col]  # the first row: the position
        words, start = ax.get_ylabel().split("\n")[1:]
        assert words == "COM position change $X - X(0)$ [m]" and f"{position[0, col, 2]:.3g}" in start
        for k, line in enumerate(ax.get_lines()[:3]):
            np.testing.assert_array_equal(line.get_ydata(), position[:, col, k] - position[0, col, k])
    assert np.ptp(axes[0].get_lines()[2].get_ydata()) < 0.01 < position[0, 0, 2]  # the height moves by millimetres
