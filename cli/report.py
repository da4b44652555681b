"""``rbstab report``: tables and figures comparing run files and sweep folders."""

from __future__ import annotations

import click

from .console import get_console
from .options import console_options

# Defaults repeated here (not imported) so that ``rbstab --help`` does not import the
# report package; tests/test_report.py checks they equal rbstab.report's.
_SETTLE_E = 0.005
_SETTLE_OMEGA = 0.05
_METRICS = ("settling_time", "peak_sway", "com_excursion", "cop_excursion", "max_abs_constraint_error",
            "lyapunov_final")
_FIGURE_FORMATS = ("png", "pdf", "svg")
_DPI = 110
_DPI_RANGE = (50, 600)
_ANIMATION_FRAMES = 100
_ANIMATION_FRAMES_RANGE = (2, 500)


def _figure_formats(ctx, param, values) -> tuple[str, ...]:
    """``--figure-format png,pdf`` (repeatable): the formats, each once, in order."""
    formats = [f.strip().lower() for value in values for f in value.split(",") if f.strip()]
    bad = [f for f in formats if f not in _FIGURE_FORMATS]
    if bad:
        raise click.BadParameter(f"{', '.join(bad)}: expected a comma list of {', '.join(_FIGURE_FORMATS)}")
    return tuple(dict.fromkeys(formats)) or ("png",)


@click.command("report")
@click.argument("inputs", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False),
    default=None,
    help="Report folder [default: results/reports/<name>: the run's name or the folder's name for "
    "one input, their names joined by _vs_ for several]. An existing report there of the same inputs (in "
    "any order) is rebuilt; one of other inputs (another run of the same name, an input more or fewer) "
    "only with --overwrite.",
)
@click.option("--overwrite", is_flag=True,
              help="Replace a report of other inputs in the report folder (without it: refused).")
@click.option(
    "--title",
    default=None,
    metavar="TEXT",
    help="Title of the page [default: what the report compares, e.g. 'rbstab report: case1_permanent "
    "and case3_embedded'].",
)
@click.option(
    "--format",
    "formats",
    type=click.Choice(["html", "md"]),
    multiple=True,
    default=("html",),
    show_default=True,
    help="Page format: index.html and/or index.md (summary.md and summary.csv are always written). Repeatable.",
)
@click.option(
    "--figure-format",
    "figure_formats",
    multiple=True,
    metavar="LIST",
    callback=_figure_formats,
    help="Figure files: a comma list of png, pdf, svg (e.g. png,pdf); repeatable [default: png]. "
    "The page shows the PNG (the SVG if only SVG and PDF are asked).",
)
@click.option(
    "--dpi",
    type=click.IntRange(*_DPI_RANGE),
    default=_DPI,
    show_default=True,
    help="Resolution of the PNG figures [dots per inch]; PDF and SVG are vector files.",
)
@click.option(
    "--metric",
    "metrics",
    multiple=True,
    metavar="NAME",
    help="Summary figure plotted against the varied parameters of sweeps. Repeatable "
    f"[default: {', '.join(_METRICS)}]. An unknown name lists the allowed ones.",
)
@click.option(
    "--settle-e",
    type=click.FloatRange(min=0.0, min_open=True),
    default=_SETTLE_E,
    show_default=True,
    metavar="M",
    help="Settling threshold on |E|, the norm of the constraint error [m].",
)
@click.option(
    "--settle-omega",
    type=click.FloatRange(min=0.0, min_open=True),
    default=_SETTLE_OMEGA,
    show_default=True,
    metavar="RAD_PER_S",
    help="Settling threshold on |Omega|, the norm of the angular velocity [rad/s].",
)
@click.option(
    "--animation-frames",
    type=click.IntRange(0, _ANIMATION_FRAMES_RANGE[1]),
    default=_ANIMATION_FRAMES,
    show_default=True,
    metavar="N",
    envvar="RBSTAB_ANIMATION_FRAMES",
    help="Frames of the 3D animation of each run given directly, embedded in index.html (about 22 kB "
    f"each; {_ANIMATION_FRAMES_RANGE[0]} to {_ANIMATION_FRAMES_RANGE[1]}; 0: none, as --no-animations). "
    "Also $RBSTAB_ANIMATION_FRAMES.",
)
@click.option(
    "--no-animations",
    "no_animations",
    is_flag=True,
    help="Leave the animations out (a smaller page, built faster).",
)
@click.option(
    "-j", "--jobs", type=click.IntRange(min=1), default=None, metavar="N",
    help="Processes drawing the figures and animations of the runs  [default: all CPUs].",
)
@console_options
def report(inputs, output, overwrite, title, formats, figure_formats, dpi, metrics, settle_e, settle_omega,
           animation_frames, no_animations, jobs) -> None:
    """Compare INPUT... (run files *.h5, sweep folders, folders of run files, analysis files *.analysis.nc).

    Writes index.html (tables, the paper's figures and a 3D animation per run, overlays of
    the runs, sweep plots, the comparison with the paper's printed values, the stability analyses of
    rbstab analyze), summary.md, summary.csv and
    figures/*.png (or .pdf, .svg). Every input is checked before anything is written.
    """
    # heavy: numpy
    from rbstab.report import ReportError, ReportInputError, ReportOptions, SettleThresholds, build_report
    from rbstab.sweep.executors import ExecutorError  # heavy: multiprocessing

    options = ReportOptions(
        formats=tuple(dict.fromkeys(formats)),
        metrics=tuple(metrics) if metrics else _METRICS,
        settle=SettleThresholds(e=settle_e, omega=settle_omega),
        title=title,
        figure_formats=figure_formats,
        dpi=dpi,
        animation_frames=0 if no_animations else animation_frames,
        jobs=jobs,  # None: every CPU this process may use
    )
    if options.animation_frames == 1:
        raise click.BadParameter(f"found 1; expected 0 (no animations) or {_ANIMATION_FRAMES_RANGE[0]} to "
                                 f"{_ANIMATION_FRAMES_RANGE[1]}", param_hint="--animation-frames")
    try:
        folder = build_report(inputs, output, options, overwrite=overwrite)
    except ReportInputError as exc:
        raise click.ClickException("cannot build the report:\n" + "\n".join(f"  {p}" for p in exc.problems))
    except (ReportError, ExecutorError) as exc:
        raise click.ClickException(str(exc))
    page = "index.html" if "html" in options.formats else "index.md"
    get_console().out(f"report: {folder / page}")
