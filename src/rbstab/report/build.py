"""Build a report folder from run files and sweep folders (what ``rbstab report`` calls).

Order of work, so that bad input never leaves anything behind:

1. validate the options (metric names, thresholds, formats);
2. read and check every input (:func:`rbstab.report.load.load_inputs`);
3. check the output folder: it may be absent, empty, or hold an earlier report
   (``report.json``) of the same inputs, which is then replaced (of other inputs: only
   with ``overwrite``); anything else is refused;
4. write everything into a temporary folder beside the target and rename it into place.

Layout of the report folder::

    index.html            the page (--format html, default): tables, figures, notes, and an
                          animation of each run given directly, its frames embedded
    index.md              the same page as markdown (--format md)
    summary.md            the tables of the page
    summary.csv           one row per run (direct runs and the runs of every sweep)
    sweep_<name>.csv      per sweep: index.csv plus the chosen metrics
    (analysis files of ``rbstab analyze`` add their sections: rbstab.report.analysis)
    figures/*.png|pdf|svg every figure, in each format asked (--figure-format)
    report.json           what the report was built from (inputs, options, version)
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..diagnostics import OUTCOMES, outcome
from ..io.metadata import provenance_attributes
from ..layout import SATURATION_FLAGS, SUMMARY_FIGURES
from ..sweep.folder import index_outcomes
from .analysis import analysis_sections, split_inputs
from .figures import DPI, FIGURE_FORMATS, RUN_FIGURES, FigureWriter, comparison_figures, has_limits
from .load import ReportInputs, RunData, SweepData, load_inputs, safe_filename
from .paper import PAPER_DOCS, compare_with_paper
from .render import Animation, Section, Table, render_html, render_markdown, render_tables_markdown
from .studies import split_studies, study_sections
from .sweep_figures import sweep_figures
from .tables import (
    DEFAULT_METRICS,
    MAX_REST_CHECKS,
    NOT_CHECKED,
    REST_AWAY,
    SETTLED,
    UNSTABLE_REST,
    SettleThresholds,
    check_member_metrics,
    differing_parameters,
    format_value,
    metric_column,
    metric_label,
    rest_words,
    run_rate_check_reason,
    runs_table,
    sweep_table,
    validate_metrics,
)
from .workers import Task, draw

__all__ = [
    "ReportOptions",
    "ReportError",
    "build_report",
    "default_report_name",
    "report_title",
    "REPORTS_ROOT",
    "MAX_TABLE_ROWS",
    "FIGURE_FORMATS",
    "DPI_RANGE",
    "ANIMATION_FRAMES",
    "ANIMATION_FRAMES_RANGE",
    "MAX_ANIMATIONS",
]

#: Parent of the default report folders.
REPORTS_ROOT = Path("results") / "reports"
#: Rows of a sweep's index shown on the page (the CSV always has all).
MAX_TABLE_ROWS = 500
#: Marker file of a report folder.
MANIFEST = "report.json"
FORMATS = ("html", "md")
#: Resolutions allowed for the PNG files (``--dpi``) [dots per inch].
DPI_RANGE = (50, 600)
#: Frames of the animation of each run (``--animation-frames``), evenly in time: at the
#: default size about 22 kB each in the page.
ANIMATION_FRAMES = 100
#: Runs given directly that the page animates (the first ones; about 2 MB each at the default).
MAX_ANIMATIONS = 12
#: Frames an animation of a report may have (``--animation-frames``; 0: no animations).
ANIMATION_FRAMES_RANGE = (2, 500)
#: Longest default folder name made of the inputs' names (longer: the first two and a hash).
MAX_NAME = 80


class ReportError(ValueError):
    """Raised for options or an output folder that a report cannot use."""


@dataclass(frozen=True)
class ReportOptions:
    """Options of a report.

    Attributes
    ----------
    formats : tuple of str
        Page formats: ``"html"`` (``index.html``) and/or ``"md"`` (``index.md``).
    metrics : tuple of str
        Metrics plotted against the varied parameters of sweeps
        (:func:`rbstab.report.tables.allowed_metrics`).
    settle : SettleThresholds
        Thresholds of the settling time (|E| [m], |Omega| [rad/s]).
    title : str or None
        Title of the page; None: what the report compares (:func:`report_title`).
    figure_formats : tuple of str
        Figure files, of :data:`FIGURE_FORMATS` (``png``, ``pdf``, ``svg``).
    dpi : int
        Resolution of the PNG files [dots per inch], within :data:`DPI_RANGE`.
    animation_frames : int
        Frames of the animation of each run given directly (evenly in time, embedded in
        ``index.html``; the first :data:`MAX_ANIMATIONS` runs), within
        :data:`ANIMATION_FRAMES_RANGE`; 0: no animations.
    jobs : int or None
        Processes that draw the figures and animations of the runs given directly (at most
        one per figure or animation; :mod:`rbstab.report.workers`), >= 1; None: as many
        as the CPUs this process may use (what ``rbstab report`` does without ``-j``).
        The default 1 draws them in this process. The files are the same whatever the
        number. From a Python script, a report with more than one job must be built under
        ``if __name__ == "__main__":`` (each new process runs the script again).
    """

    formats: tuple[str, ...] = ("html",)
    metrics: tuple[str, ...] = DEFAULT_METRICS
    settle: SettleThresholds = field(default_factory=SettleThresholds)
    title: str | None = None
    figure_formats: tuple[str, ...] = ("png",)
    dpi: int = DPI
    animation_frames: int = ANIMATION_FRAMES
    jobs: int | None = 1


def _input_name(path: Path, runs: Sequence[RunData]) -> str:
    """A file name for one input: a folder's name, an analysis file's name without
    ``.nc``, the run name of a run file, the stem of a store file."""
    from ..analysis.dataset import SUFFIX  # heavy: numba (the rbstab.analysis package)

    if path.is_dir():
        return safe_filename(path.resolve().name)
    if path.name.endswith(SUFFIX):
        return safe_filename(path.name.removesuffix(".nc"))
    mine = [r.name for r in runs if r.path.resolve() == path.resolve()]
    return safe_filename(mine[0] if len(mine) == 1 else path.stem)


def default_report_name(inputs: ReportInputs, given: Sequence[str | os.PathLike] | None = None) -> str:
    """Folder name of a report under ``results/reports/``, made of the inputs' names.

    Each input (``given``, default ``inputs.paths``) is named as :func:`_input_name` says
    (``case3_embedded`` for ``results/case3_embedded.h5``, ``gains_case3`` for a sweep
    folder); one input gives its name, several their sorted names joined by ``_vs_``
    (``case1_permanent_vs_case2_visco_elastic``). When that is longer than
    :data:`MAX_NAME` characters or names repeat: the first two names, the number of the
    others and the start of the SHA-256 of the sorted resolved paths
    (``a_vs_b_and_4_more-1f2e3d4c``). The same inputs in any order give the same name.
    """
    paths = [Path(p) for p in (given if given is not None else inputs.paths)]
    names = sorted(_input_name(p, inputs.runs) for p in dict.fromkeys(p.resolve() for p in paths))
    if len(names) == 1:
        return names[0]
    joined = "_vs_".join(names)
    if len(joined) <= MAX_NAME and len(set(names)) == len(names):
        return joined
    digest = hashlib.sha256("\n".join(sorted(str(p.resolve()) for p in paths)).encode()).hexdigest()[:8]
    more = f"_and_{len(names) - 2}_more" if len(names) > 2 else ""
    return f"{names[0][:32]}_vs_{names[1][:32]}{more}-{digest}"


def _enumerate(items: Sequence[str], limit: int = 4) -> str:
    """``a``, ``a and b``, ``a, b and c``; past ``limit`` items ``a, b, c and 5 more``."""
    items = list(items)
    if len(items) > limit:
        items = [*items[: limit - 1], f"{len(items) - limit + 1} more"]
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def report_title(inputs: ReportInputs, analyses: Sequence[Path] = (), studies: Sequence[Path] = ()) -> str:
    """The default title of a report: what it compares, e.g. ``rbstab report:
    case1_permanent, case2_visco_elastic and case3_embedded``, ``rbstab report: sweep
    gains_case3``, ``rbstab report: stability analyses of case1_permanent and ...``."""
    from ..analysis.dataset import SUFFIX  # heavy: numba (the rbstab.analysis package)

    parts = []
    if inputs.runs:
        parts.append(_enumerate([r.label for r in inputs.runs]))
    if inputs.sweeps:
        parts.append(("sweeps " if len(inputs.sweeps) > 1 else "sweep ") + _enumerate([s.name for s in inputs.sweeps]))
    if analyses:
        names = [p.name.removesuffix(SUFFIX) for p in analyses]
        parts.append(f"stability analys{'e' if len(names) > 1 else 'i'}s of {_enumerate(names)}")
    if studies:
        parts.append(("studies " if len(studies) > 1 else "study ") + _enumerate([_input_name(p, []) for p in studies]))
    return "rbstab report: " + ("; ".join(parts) or "no inputs")


def _check_output(target: Path, paths: Sequence[Path] = (), overwrite: bool = True) -> None:
    if target.exists() and not target.is_dir():
        raise ReportError(f"{target}: exists and is not a folder")
    if target.is_dir() and any(target.iterdir()) and not (target / MANIFEST).is_file():
        raise ReportError(
            f"{target}: folder exists, is not empty and is not an rbstab report (no {MANIFEST}); "
            "choose another -o"
        )
    if overwrite or not (target / MANIFEST).is_file():
        return
    try:
        before = json.loads((target / MANIFEST).read_text(encoding="utf-8")).get("inputs") or []
    except (OSError, ValueError, AttributeError):
        before = []
    # the same set of inputs (in any order): rebuilt in place; any other set (another run of
    # the same name, an input more or fewer) is another comparison: refused unless overwrite
    before_set = {str(p) for p in before}
    now_set = {str(p) for p in paths}
    if before and before_set != now_set:
        missing = sorted(before_set - now_set)
        added = sorted(now_set - before_set)
        parts = []
        if missing:
            parts.append("only there: " + _shown(missing))
        if added:
            parts.append("only here: " + _shown(added))
        raise ReportError(
            f"{target} holds a report of other inputs ({'; '.join(parts) or 'unknown'}): not replaced; "
            "--overwrite (overwrite=True) replaces it, -o DIR writes elsewhere"
        )


def _shown(paths: Sequence[str], limit: int = 3) -> str:
    return ", ".join(paths[:limit]) + (f" and {len(paths) - limit} more" if len(paths) > limit else "")


# -- tables ---------------------------------------------------------------------------

def _f(value, digits: int = 4) -> str:
    return format_value(value, digits)


def _vec(row, prefix: str, members: dict | None = None) -> str:
    """A table cell of the 3-vector figure ``prefix`` of a row of :func:`runs_table`: one
    body's ``[a, b, c]``; a chain's (``members``, :attr:`RunData.members`) each body's or
    joint's, ``legs [a, b, c]; trunk [...]``."""
    if members is None:
        values = [row.get(f"{prefix}_{i}", np.nan) for i in (1, 2, 3)]
        return "-" if all(not np.isfinite(v) for v in values) else _f(values)
    cells = []
    for name in members[SUMMARY_FIGURES[prefix].member]:
        values = [row.get(f"{prefix}_{name}_{axis}", np.nan) for axis in "xyz"]
        if any(np.isfinite(v) for v in values):
            cells.append(f"{name} {_f(values)}")
    return "; ".join(cells) or "-"


def _runs_sections(runs: Sequence[RunData], df, params: Sequence[str]) -> list[Section]:
    rows = df.to_dict("records")
    members = [run.members for run in runs]
    s = Section("Runs", "runs")
    s.blocks.append(
        "One row per run; values read back from the result files (summary attributes written by "
        "the run). status success: the solver reached t_end. Outcome: "
        + "; ".join(f"{word}: {meaning}" for word, meaning in OUTCOMES.items() if word != "pending")
        + ". Vectors are [component 1, 2, 3]; E, X, V, D in the inertial frame, Omega in the body frame; "
        "a chain's per body (Theta, Omega, X, V) or joint (E_j, D_j), each named."
    )
    s.blocks.append(Table(
        "Runs: identity, solver statistics, status",
        ["run", "file", "variant", "status", "outcome", "t_final [s]", "method", "nfev", "njev", "nlu",
         "wall time [s]", "message"],
        [[r["run"], Path(r["file"]).name, r["variant"], r["status"],
          outcome(r["status"], r["message"], r["lyapunov_initial"], r["lyapunov_final"], r.get("max_lyapunov_increase"),
                  disturbed=bool(run.config.get("disturbances"))),
          _f(r["t_final"]), str(r["method"]),
          _f(r["nfev"]), _f(r["njev"]), _f(r["nlu"]), _f(r["wall_time"], 3), r["message"] if r["status"] != "success" else ""]
         for r, run in zip(rows, runs)],
    ))
    if params:
        s.blocks.append(Table(
            "Parameters that differ between the runs (resolved configurations)",
            ["run", *params],
            [[r["run"], *(_f(r[p], 6) for p in params)] for r in rows],
        ))
    s.blocks.append(Table(
        "Final rotational state (at t_final)",
        ["run", "Theta [rad]", "Omega [rad/s]"],
        [[r["run"], *(_vec(r, f"final_{b}", m) for b in ("theta", "omega"))] for r, m in zip(rows, members)],
    ))
    has_d = any(_vec(r, "final_controller_state", m) != "-" for r, m in zip(rows, members))
    blocks = ("position", "velocity", "controller_state") if has_d else ("position", "velocity")
    s.blocks.append(Table(
        "Final translational state (at t_final)",
        ["run", "X [m]", "V [m/s]", *(["D [m]"] if has_d else [])],
        [[r["run"], *(_vec(r, f"final_{b}", m) for b in blocks)] for r, m in zip(rows, members)],
    ))
    s.blocks.append(Table(
        "Constraint error and Lyapunov function",
        ["run", "max |E| per axis [m]", "settling time [s]", "v(0) [J]", "v(t_end) [J]", "max dv/dt [W]",
         "max |analytic - numerical dv/dt| [W]", "relative", "rate check"],
        [[r["run"], _vec(r, "max_abs_constraint_error", m),
          _f(r["settling_time"]) if r["rest"] == SETTLED else r["rest"],
          _f(r["lyapunov_initial"]), _f(r["lyapunov_final"]), _f(r["max_lyapunov_rate"]),
          _f(r["lyapunov_rate_mismatch"]), _f(r["lyapunov_rate_mismatch_relative"], 3), str(r["lyapunov_rate_check"])]
         for r, m in zip(rows, members)],
    ))
    failed = [f"{run.label}: rate check fail: {reason}" for run in runs if (reason := run_rate_check_reason(run))]
    if failed:
        s.blocks.append(failed)
    switching = _switching_table(runs)
    if switching is not None:
        s.blocks.append(switching)
    limits = _saturation_table(runs)
    if limits is not None:
        s.blocks.append(limits)
    return [s]


#: The summary figures of the table of runs with actuators' limits or disturbances.
SATURATION_FIGURES = ("max_lyapunov_increase", "time_lyapunov_rising",
                      *(figure for _, figure in SATURATION_FLAGS.values()))


def _saturation_table(runs: Sequence[RunData]) -> Table | None:
    """The runs with actuators' limits (one body's controller.saturation, a chain's joints'
    and bodies') or disturbances: how much v rose, how long dv/dt > 0, and per axis of N, H,
    Lambda the fraction of the time at the limit (a chain's per joint or body; None if no
    run has limits or disturbances); headers from the table of quantities."""
    rows = [r for r in runs if r.config.get("disturbances") or has_limits(r)]
    if not rows:
        return None
    figures = [SUMMARY_FIGURES[name] for name in SATURATION_FIGURES]
    return Table(
        "Saturating actuators and disturbances: where v rises, and the time each axis of N, H, Lambda spends at "
        "its limit (docs/saturation.md, docs/disturbances.md)",
        ["run", "limits", "disturbances",
         *(q.symbol if q.units == "1" else f"{q.symbol} [{q.display_units}]" for q in figures)],
        [[r.label, _run_limits_text(r),
          ", ".join(f"{d.get('kind')} at {d.get('start', 0)} s" + (f" on {d['body']}" if d.get("body") else "")
                    for d in r.config.get("disturbances") or ()) or "-",
          *(_figure_cell(r, q.name) for q in figures)] for r in rows],
    )


def _figure_cell(run: RunData, name: str) -> str:
    """A table cell of the summary figure ``name``: as it is, or a chain's per body or joint
    (``ankle [a, b, c]; hip [...]``)."""
    value, members = run.summary.get(name), run.members
    if members is None or value is None or np.ndim(value) < 2:
        return _f(value, 3)
    return "; ".join(f"{m} {_f(v, 3)}" for m, v in zip(members[SUMMARY_FIGURES[name].member], value))


def _run_limits_text(run: RunData) -> str:
    """A run's actuators' limits as its config gives them: one body's ``torque_n 4, clip``, a
    chain's by joint and body (``ankle: torque_n [120, 120, inf], clip``)."""
    if run.members is None:
        return _limits_text((run.config.get("controller") or {}).get("saturation"))
    held = [m for m in [*(run.config.get("joints") or ()), *(run.config.get("bodies") or ())]
            if isinstance(m, dict) and m.get("saturation")]
    return "; ".join(f"{m.get('name')}: {_limits_text(m['saturation'])}" for m in held) or "-"


def _limits_text(saturation) -> str:
    """A run's actuators' limits as the config gives them, e.g. ``torque_n 4, clip``."""
    if not saturation:
        return "-"
    keys = [f"{k} {saturation[k]}" for k in ("torque_n", "force_h", "constraint_force") if saturation.get(k) is not None]
    return ", ".join([*keys, str(saturation.get("shape", "clip"))])


def _switching_table(runs: Sequence[RunData]) -> Table | None:
    """Per axis of E, the switching figures of the runs of the pure sign law (None if none)."""
    rows = [r for r in runs if "switching_count" in r.summary]
    if not rows:
        return None
    keys = ("switching_count", "sliding_time", "sliding_starts", "min_switching_interval", "chattering")
    return Table(
        "Pure sign law (eq 39): switchings located per axis of E (docs/sliding.md)",
        ["run", "crossings", "sliding time [s]", "sliding starts", "shortest interval [s]", "chattering [N/s]",
         "resolution [m]", "rate-checked samples"],
        [[r.label, *(_f(r.summary[k]) for k in keys), _f(r.summary.get("switching_resolution")),
          _f(r.summary.get("lyapunov_rate_checked"), 3)] for r in rows],
    )


def _paper_section(runs: Sequence[RunData]) -> Section | None:
    comparisons = compare_with_paper(runs)
    if not comparisons:
        return None
    s = Section("Comparison with the paper", "paper")
    s.blocks.append(
        "Runs named after a paper case (and of its variant) beside the values printed in section 6 of "
        "the paper. They do not match, and rbstab does not tune anything to make them match: the printed "
        "paper has typos in B (eq 1) and eq 21 and omits parameters, so its printed numbers cannot be "
        f"reached by the consistent equations. The differences are explained in {PAPER_DOCS}."
    )
    for comp in comparisons:
        sub = Section(f"{comp.case.title}: {comp.run.label}", f"paper-{safe_filename(comp.run.label)}", level=3)
        sub.blocks.append(f"Paper: {comp.case.claim}.")
        if comp.rows:
            sub.blocks.append(Table(
                f"{comp.run.label} against the printed values (difference = ours - printed)",
                ["quantity", "units", "printed", "ours", "difference"],
                [[r["quantity"], r["units"], _f(r["printed"]), _f(r["ours"]), _f(r["difference"], 3)] for r in comp.rows],
            ))
        if comp.notes:
            sub.blocks.append(comp.notes)
        s.blocks.append(sub)
    return s


def _truthy(value) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, float, np.number)):
        return bool(np.isfinite(value) and value != 0)
    return str(value).strip().lower() in ("true", "1", "yes")


def _sweep_section(sweep: SweepData, table, metrics: Sequence[str], figures, settle: SettleThresholds) -> Section:
    s = Section(f"Sweep {sweep.name}", f"sweep-{safe_filename(sweep.name)}")
    n = len(table)
    ok = table["status"].astype(str) == "success"
    ended = index_outcomes(table)
    facts = [
        f"folder: {sweep.path}",
        f"{n} runs: " + ", ".join(f"{int((ended == word).sum())} {word}" for word in OUTCOMES if (ended == word).any()),
        "parameters: " + (", ".join(sweep.parameters) or "none found in index.csv"),
        "varied: " + (", ".join(f"{p} ({table[p].astype(str).nunique()} values)" for p in sweep.varied) or "none"),
    ]
    if "converged" in table.columns:
        stable = int(sum(_truthy(v) and st for v, st in zip(table["converged"], ok)))
        facts.append(f"stable (status success and converged, as the sweep recorded it): {stable} of {n} = {stable / n:.0%}")
    rest = table["report:rest"].astype(str)
    settled = int((rest == SETTLED).sum())
    facts.append(
        f"settled (|E| <= {settle.e:g} m and |Omega| <= {settle.omega:g} rad/s until t_end, v converged, the rest "
        f"state not linearly unstable): {settled} of {n} = {settled / n:.0%}"
    )
    away, unstable = int((rest == REST_AWAY).sum()), int((rest == UNSTABLE_REST).sum())
    if away or unstable:
        facts.append(f"at rest but not settled: {away} {REST_AWAY} (v not converged), {unstable} {UNSTABLE_REST} "
                     "(the linearisation at the rest state unstable)")
    unchecked = int(((table["report:rest_state"].astype(str) == NOT_CHECKED) & (rest == SETTLED)).sum())
    if unchecked:
        facts.append(f"{unchecked} runs otherwise settled have a configuration beyond the {MAX_REST_CHECKS} distinct "
                     "ones whose rest state the report linearises: counted as settled on v alone (report:rest_state "
                     f"'{NOT_CHECKED}')")
    missing = sum(r is None for r in sweep.runs)
    if missing:
        facts.append(f"{missing} rows of index.csv have no result file: their metrics are blank")
    s.blocks.append(facts)
    failed = table[~ok]
    if len(failed):
        s.blocks.append(Table(
            f"Runs of {sweep.name} that did not reach t_end",
            ["run_id", *sweep.varied, "status", "outcome", "message"],
            [[str(r["run_id"]), *(_f(r[p], 6) for p in sweep.varied), str(r["status"]), str(word), str(r["message"])]
             for r, word in zip(failed.to_dict("records"), ended[~ok.to_numpy()])],
        ))
    else:
        s.blocks.append("Every run reached t_end.")
    if not sweep.varied:
        s.blocks.append("No parameter varies between the runs of this sweep: no metric plots.")
    s.blocks.extend(figures)
    shown = table.head(MAX_TABLE_ROWS)
    metric_cols = [metric_column(m) for m in metrics]
    cols = ["run_id", *sweep.varied, "status", *metric_cols, "report:rest"]
    if "converged" in table.columns:
        cols.insert(cols.index("status") + 1, "converged")
    headers = ["run_id", *sweep.varied, "status", *(["converged"] if "converged" in table.columns else []),
               *(metric_label(m) for m in metrics), "at t_end"]
    note = f"sweep_{safe_filename(sweep.name)}.csv holds every column of index.csv plus these metrics"
    if n > MAX_TABLE_ROWS:
        note = f"first {MAX_TABLE_ROWS} of {n} runs; " + note
    s.blocks.append(Table(
        f"Index of {sweep.name} (metrics read back from the run files)",
        headers,
        [[_f(r[c]) if not isinstance(r[c], str) else r[c] for c in cols] for r in shown.to_dict("records")],
        note=note,
    ))
    return s


# -- the report -------------------------------------------------------------------------

def _check_options(options: ReportOptions) -> None:
    """Raise ReportError for a page format, figure format or resolution that is not allowed."""
    bad = [f for f in options.formats if f not in FORMATS]
    if bad or not options.formats:
        raise ReportError(f"unknown format {bad}; allowed: {', '.join(FORMATS)}")
    bad = [f for f in options.figure_formats if f not in FIGURE_FORMATS]
    if bad or not options.figure_formats:
        raise ReportError(f"unknown figure format {bad}; allowed: {', '.join(FIGURE_FORMATS)}")
    if not (isinstance(options.dpi, (int, np.integer)) and DPI_RANGE[0] <= options.dpi <= DPI_RANGE[1]):
        raise ReportError(f"dpi: found {options.dpi!r}; expected a whole number from {DPI_RANGE[0]} to {DPI_RANGE[1]}")
    frames, (low, high) = options.animation_frames, ANIMATION_FRAMES_RANGE
    if not (isinstance(frames, (int, np.integer)) and (frames == 0 or low <= frames <= high)):
        raise ReportError(f"animation_frames: found {frames!r}; expected 0 (no animations) or a whole number "
                          f"from {low} to {high}")
    if options.jobs is not None and not (isinstance(options.jobs, (int, np.integer)) and options.jobs >= 1):
        raise ReportError(f"jobs: found {options.jobs!r}; expected a whole number >= 1 (processes), or None (every CPU)")
    if options.title is not None and not options.title.strip():
        raise ReportError("title: found an empty title; give some text or leave it out")


def build_report(
    inputs: Sequence[str | os.PathLike],
    output: str | os.PathLike | None = None,
    options: ReportOptions | None = None,
    *,
    overwrite: bool = False,
) -> Path:
    """Build a report folder from run files and sweep folders.

    Parameters
    ----------
    inputs : sequence of path-like
        Run files (``*.h5``), sweep folders (``sweep.yaml`` + ``index.csv``) and plain
        folders of run files, in any mix.
    output : path-like, optional
        Report folder; default ``results/reports/<name>``, ``<name>`` made of the inputs'
        names (:func:`default_report_name`). If it exists it must be empty or an earlier
        report of the same inputs in any order, which is rebuilt (of other inputs: only
        with ``overwrite``).
    options : ReportOptions, optional
    overwrite : bool
        Replace an earlier report of other inputs (else refused: ReportError).

    Returns
    -------
    Path
        The report folder.

    Raises
    ------
    ReportInputError
        If an input is missing, not an rbstab result, an empty folder or a broken sweep
        (every problem listed); nothing is written.
    ReportError
        If an option is invalid or the output folder cannot be used; nothing is written.
    rbstab.sweep.ExecutorError
        If the processes drawing the figures die (killed, out of memory); nothing is written.
    """
    options = options or ReportOptions()
    try:
        metrics = validate_metrics(options.metrics)
    except ValueError as exc:
        raise ReportError(str(exc)) from None
    _check_options(options)

    given = list(inputs)
    studies, inputs = split_studies(given)  # study files and folders (rbstab sensitivity, tune)
    analyses, inputs = split_inputs(inputs)  # analysis files (rbstab analyze) and the rest
    data = load_inputs(inputs) if inputs or not (analyses or studies) else ReportInputs([], [], [])
    try:
        check_member_metrics(metrics, data.sweeps)
    except ValueError as exc:
        raise ReportError(str(exc)) from None
    data.paths.extend(p.resolve() for p in [*analyses, *studies])
    target = Path(output) if output is not None else REPORTS_ROOT / default_report_name(data, given)
    _check_output(target, data.paths, overwrite)

    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        umask = os.umask(0)
        os.umask(umask)
        tmp.chmod(0o777 & ~umask)  # mkdtemp makes it private; a report is an ordinary folder
        _write(data, tmp, options, metrics, analyses, studies)
        old = None
        if target.exists():
            old = target.parent / f".{target.name}.old-{os.getpid()}"
            os.replace(target, old)
        os.replace(tmp, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target


def _write(data: ReportInputs, folder: Path, options: ReportOptions, metrics: Sequence[str],
           analyses: Sequence[Path] = (), studies: Sequence[Path] = ()) -> None:
    """Every file of the report into ``folder`` (module docstring)."""
    (folder / "figures").mkdir()
    out = FigureWriter(folder, tuple(dict.fromkeys(options.figure_formats)), int(options.dpi))
    runs = list(data.runs)
    params = differing_parameters(runs)
    frames = options.animation_frames if "html" in options.formats else 0
    sections = _direct_run_sections(runs, params, out, options.settle, frames, _jobs(options)) if runs else []
    for sweep in data.sweeps:
        sections.append(_sweep_section_with_files(sweep, metrics, out, options.settle))
    sections += analysis_sections(analyses, out)
    sections += study_sections(studies, out)
    _write_summary_csv(data, params, folder, options.settle)
    title = options.title or report_title(data, analyses, studies)
    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    _write_pages(folder, title, _intro(data, created, options.settle), _flatten(sections), options.formats)
    _write_manifest(folder, data, analyses, options, metrics, title, created)


def _jobs(options: ReportOptions) -> int:
    """Processes that draw the figures: ``options.jobs``, or the CPUs this process may use."""
    if options.jobs is not None:
        return int(options.jobs)
    from ..sweep.executors import default_jobs  # heavy: multiprocessing

    return default_jobs()


def _direct_run_sections(runs: Sequence[RunData], params: Sequence[str], out: FigureWriter,
                         settle: SettleThresholds, frames: int = 0, jobs: int = 1) -> list[Section]:
    """Tables, the comparison with the paper, comparison figures and each run's animation
    (``frames`` > 0) and figures, these drawn in ``jobs`` processes (:func:`rbstab.report.workers.draw`)."""
    sections = _runs_sections(runs, runs_table(runs, settle, params), params)
    paper = _paper_section(runs)
    if paper is not None:
        sections.append(paper)
    animated = runs[:MAX_ANIMATIONS] if frames else []
    # the longest tasks first (comparison ~1 s, animations ~1 s, a run's figure ~0.2 s): the processes end together
    tasks = [Task(comparison_figures, (runs, out, settle)), *(Task(_animation, (run, frames)) for run in animated),
             *(Task(make, (run, out)) for run in runs for make in RUN_FIGURES)]
    drawn = iter(draw(tasks, jobs))
    cmp = Section("Comparison figures" if len(runs) > 1 else "Constraint error and angular velocity", "comparison")
    cmp.blocks.extend(next(drawn))
    animations = [next(drawn) for _ in animated]
    per_run = Section("Figures of each run", "figures")
    for i, run in enumerate(runs):
        sub = Section(f"{run.label} ({run.variant}, {run.status})", f"run-{safe_filename(run.label)}", level=3)
        if not run.ok:
            sub.blocks.append(f"FAILED: {run.message}")
        if i < len(animations):
            sub.blocks.append(animations[i])
        elif frames:
            sub.blocks.append(f"No animation: the page animates the first {MAX_ANIMATIONS} runs "
                              f"(rbstab animate {run.path}{'' if run.row is None else ' --run ' + run.name} animates this one).")
        sub.blocks.extend(f for f in (next(drawn) for _ in RUN_FIGURES) if f is not None)
        per_run.blocks.append(sub)
    return [*sections, cmp, per_run]


def _animation(run: RunData, frames: int) -> Animation | str:
    """The animation of a run (:func:`rbstab.report.animate.report_animation`)."""
    # late: rbstab.report.animate imports numba (through rbstab.kinematics), heavy for a report without animations
    from .animate import report_animation

    return report_animation(run, frames)


def _sweep_section_with_files(sweep: SweepData, metrics: Sequence[str], out: FigureWriter,
                              settle: SettleThresholds) -> Section:
    """A sweep's section, its ``sweep_<name>.csv`` and its figures."""
    table = sweep_table(sweep, metrics, settle)
    table.to_csv(out.folder / f"sweep_{safe_filename(sweep.name)}.csv", index=False)
    return _sweep_section(sweep, table, metrics, sweep_figures(sweep, table, metrics, out), settle)


def _write_summary_csv(data: ReportInputs, params: Sequence[str], folder: Path, settle: SettleThresholds) -> None:
    """``summary.csv``: every run, direct and swept, one row each."""
    import pandas as pd  # heavy: pandas

    all_runs = list(data.all_runs)
    all_params = list(dict.fromkeys([*params, *differing_parameters(all_runs)]))
    (runs_table(all_runs, settle, all_params) if all_runs else pd.DataFrame()).to_csv(folder / "summary.csv",
                                                                                      index=False)


def _intro(data: ReportInputs, created: str, settle: SettleThresholds) -> list[str]:
    return [
        f"Created {created} by rbstab {__version__} from {len(data.paths)} input(s): "
        + ", ".join(str(p) for p in data.paths) + ".",
        f"Settling time: the first sample time after which |E| <= {settle.e:g} m and |Omega| <= "
        f"{settle.omega:g} rad/s (Euclidean norms) hold until the end of the run. {rest_words(settle)} "
        "Tables: summary.csv (every run, full precision), summary.md.",
    ]


def _write_pages(folder: Path, title: str, intro: Sequence[str], sections: Sequence[Section],
                 formats: Sequence[str]) -> None:
    if "html" in formats:
        (folder / "index.html").write_text(render_html(title, intro, sections), encoding="utf-8")
    if "md" in formats:
        (folder / "index.md").write_text(render_markdown(title, intro, sections), encoding="utf-8")
    (folder / "summary.md").write_text(render_tables_markdown(title, intro, sections), encoding="utf-8")


def _write_manifest(folder: Path, data: ReportInputs, analyses: Sequence[Path], options: ReportOptions,
                    metrics: Sequence[str], title: str, created: str) -> None:
    manifest = {
        "rbstab_report": 1,
        "rbstab_version": __version__,
        "created": created,
        "title": title,
        "inputs": [str(p) for p in data.paths],
        "runs": [str(r.path) for r in data.runs],
        "sweeps": [str(s.path) for s in data.sweeps],
        "analyses": [str(p) for p in analyses],
        "formats": list(options.formats),
        "figure_formats": list(dict.fromkeys(options.figure_formats)),
        "dpi": int(options.dpi),
        "animation_frames": int(options.animation_frames) if "html" in options.formats else 0,
        "metrics": list(metrics),
        "settle_e": options.settle.e,
        "settle_omega": options.settle.omega,
        "figures": sorted(str(p.relative_to(folder)) for p in (folder / "figures").iterdir()),
        "provenance": provenance_attributes(title, created=created),
    }
    (folder / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")


def _flatten(sections: Sequence[Section]) -> list[Section]:
    """Sub-sections stored as blocks become sections of their own, in document order."""
    out: list[Section] = []
    for s in sections:
        out.append(Section(s.title, s.anchor, [], s.level))
        for block in s.blocks:
            if isinstance(block, Section):
                out.extend(_flatten([block]))
            else:
                out[-1].blocks.append(block)
    return out
