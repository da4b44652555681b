"""Report pages of studies (``rbstab sensitivity``, ``rbstab tune``).

Sensitivity: the method and its runs, a table of the indices and one bar chart per metric
(first-order and total Sobol' indices, or Morris mu* beside sigma, with the bootstrap
confidence intervals as error bars). Tuning: the objectives and constraints, the objective
against the trial (feasible, infeasible and failed trials; the best so far), the Pareto
front for two objectives, and the best trials with their parameters.

The files are read with :mod:`rbstab.studies` (the modules that write them).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..kinds import SENSITIVITY, TUNING, kind_of
from .figures import DPI, FigureFile, FigureWriter, units_text
from .load import ReportInputError, safe_filename
from .render import Section, Table
from .tables import format_value

__all__ = ["split_studies", "study_sections"]

#: The kinds of input this module draws.
STUDY_KINDS = (SENSITIVITY, TUNING)
#: Best trials listed in a tuning section.
BEST_ROWS = 10


def split_studies(paths: Sequence[str | os.PathLike]) -> tuple[list[Path], list]:
    """(study files or folders, the other inputs) of a report."""
    studies, others = [], []
    for raw in paths:
        is_study = Path(raw).exists() and any(k.can_open(Path(raw)) for k in STUDY_KINDS)
        (studies if is_study else others).append(Path(raw) if is_study else raw)
    return studies, others


def study_sections(paths: Sequence[Path], out: FigureWriter) -> list[Section]:
    """The sections of every study, figures written by ``out``.

    Raises
    ------
    ReportInputError
        If a study's file cannot be read.
    """
    sections, problems = [], []
    for path in paths:
        try:
            kind = kind_of(path, STUDY_KINDS)
            ds = kind.open(Path(path))
        except (OSError, ValueError) as exc:
            problems.append(f"{path}: {exc}")
            continue
        sections.append(_sensitivity_section(ds, out) if kind is SENSITIVITY else _tuning_section(ds, out))
    if problems:
        raise ReportInputError(problems)
    return sections


def _f(value, digits: int = 3) -> str:
    return format_value(value, digits)


def _name(ds) -> str:
    return Path(ds.attrs["path"]).parent.name


# -- sensitivity ----------------------------------------------------------------------------------


def _sensitivity_section(ds, out: FigureWriter) -> Section:
    name, method = _name(ds), ds.attrs["method"]
    s = Section(f"Sensitivity study {name} ({method})", f"sensitivity-{safe_filename(name)}")
    vary = json.loads(ds.attrs["vary"])
    s.blocks.append([
        f"{ds.attrs['n_runs']} runs ({ds.attrs['n_failed']} failed), N = {ds.attrs['n']}, seed {ds.attrs['seed']}; "
        f"confidence intervals: {ds.attrs['num_resamples']} bootstrap resamples at level {ds.attrs['conf_level']:g}",
        "varied: " + "; ".join(f"{k} {json.dumps(v)}" for k, v in vary.items()),
        f"file: {ds.attrs['path']}",
    ])
    notes = [f"{metric}: {note}" for metric, note in zip(ds["metric"].values.tolist(),
                                                         ds["note"].values.tolist() if "note" in ds else [])
             if note]
    if notes:
        s.blocks.append([f"Warning: {n} (hatched bars without fill in the figure, (!) in the table)"
                         for n in notes])
    s.blocks.append(_sensitivity_figure(ds, out, name))
    s.blocks.append(_sensitivity_table(ds))
    return s


def _sensitivity_table(ds) -> Table:
    keys = ["S1", "ST"] if ds.attrs["method"] == "sobol" else ["mu_star", "sigma"]
    rows = []
    for m, metric in enumerate(ds["metric"].values.tolist()):
        for i, factor in enumerate(ds["factor"].values.tolist()):
            cells = [metric, factor]
            for k in keys:
                half = ds[f"{k}_conf"].values[m, i] if f"{k}_conf" in ds else None
                flag = f"{k}_unreliable" in ds and bool(ds[f"{k}_unreliable"].values[m, i])
                cells.append(_f(ds[k].values[m, i]) + (f" ± {_f(half, 2)}" if half is not None else "")
                             + (" (!)" if flag else ""))
            rows.append(cells)
    return Table("Indices", ["metric", "factor", *keys], rows)


def _sensitivity_figure(ds, out: FigureWriter, name: str) -> FigureFile:
    from matplotlib.figure import Figure  # matplotlib: only when a figure is drawn, as report/figures.py

    from ..studies.sensitivity import RELIABLE_RANGE  # heavy: pandas, xarray (only with a study)

    sobol = ds.attrs["method"] == "sobol"
    metrics = ds["metric"].values.tolist()
    factors = ds["factor"].values.tolist()
    columns = min(3, len(metrics))
    rows = -(-len(metrics) // columns)
    fig = Figure(figsize=(4.2 * columns, 0.6 + (1.0 + 0.35 * len(factors)) * rows), dpi=DPI, layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, columns, squeeze=False).ravel())
    y = np.arange(len(factors))
    bars = [("S1", "first order", -0.2), ("ST", "total", 0.2)] if sobol else [("mu_star", "mu*", -0.2),
                                                                              ("sigma", "sigma", 0.2)]
    for ax, (m, metric) in zip(axes, enumerate(metrics)):
        for c, (k, label, shift) in enumerate(bars):
            err = ds[f"{k}_conf"].values[m] if f"{k}_conf" in ds else None
            values = np.asarray(ds[k].values[m], dtype=float)
            bad = np.asarray(ds[f"{k}_unreliable"].values[m], dtype=bool) if f"{k}_unreliable" in ds else \
                np.zeros(len(factors), dtype=bool)
            color = f"C{c}"
            ax.barh((y + shift)[~bad], values[~bad], height=0.38, xerr=None if err is None else err[~bad],
                    capsize=2, label=label, color=color)
            if bad.any():  # unreliable: an empty hatched bar, clipped to the range of an index
                lo, hi = RELIABLE_RANGE
                ax.barh((y + shift)[bad], np.clip(values[bad], lo, hi), height=0.38, fill=False, hatch="///",
                        edgecolor=color, label=f"{label} (unreliable)")
        ax.set_yticks(y, factors, fontsize=7)
        ax.invert_yaxis()
        units = units_text(str(ds["units"].values[m]))
        ax.set_title(metric + (f" [{units}]" if units and not sobol else ""), fontsize=9)
        ax.grid(axis="x", alpha=0.3)
        if sobol:
            if "S1_unreliable" in ds and (ds["S1_unreliable"].values[m].any() or ds["ST_unreliable"].values[m].any()):
                ax.set_xlim(*RELIABLE_RANGE)  # an unreliable index's interval would set the scale
            else:
                ax.set_xlim(min(0.0, ax.get_xlim()[0]), max(1.0, ax.get_xlim()[1]))
    for ax in axes[len(metrics):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7)
    what = ("first-order (S1) and total (ST) Sobol' indices" if sobol else
            "Morris mu* (mean absolute elementary effect, per unit of the factor's range) and sigma")
    return out.save(fig, f"sensitivity_{safe_filename(name)}", f"{name}: {what}",
                    f"One panel per metric: {what} of each factor, with the bootstrap confidence intervals "
                    "as error bars; an index flagged unreliable (outside [-0.05, 1.05] or its interval wider "
                    "than 0.5) is an empty hatched bar without error bar, clipped to that range.")


# -- tuning ----------------------------------------------------------------------------------------


def _tuning_section(ds, out: FigureWriter) -> Section:
    name = _name(ds)
    objectives = json.loads(ds.attrs["objectives"])
    constraints = json.loads(ds.attrs["constraints"])
    best = json.loads(ds.attrs["best"])
    states = ds["state"].values.astype(str)
    s = Section(f"Tuning study {name}", f"tuning-{safe_filename(name)}")
    s.blocks.append([
        "objectives: " + ", ".join(f"{d} {m}" for m, d in objectives)
        + ("; subject to " + ", ".join(constraints) if constraints else ""),
        f"{int((states == 'complete').sum())} complete trials, {int((states == 'fail').sum())} failed, "
        f"{int(ds['feasible'].values.astype(bool).sum())} feasible"
        + (f"; each trial a batch of {ds.attrs['bodies']} bodies (quantile {ds.attrs['quantile']:g})"
           if ds.attrs["bodies"] else ""),
        f"file: {ds.attrs['path']}",
    ])
    s.blocks.append(_objective_figure(ds, out, name, objectives))
    s.blocks.append(_search_figure(ds, out, name, objectives))
    if len(objectives) == 2:
        s.blocks.append(_pareto_figure(ds, out, name, objectives, best))
    s.blocks.append(_best_table(ds, objectives, best))
    return s


def _objective_figure(ds, out: FigureWriter, name: str, objectives) -> FigureFile:
    from matplotlib.figure import Figure  # matplotlib: only when a figure is drawn, as report/figures.py

    trial = ds["trial"].values
    feasible = ds["feasible"].values.astype(bool)
    complete = ds["state"].values.astype(str) == "complete"
    fig = Figure(figsize=(7.5, 3.2 * len(objectives)), dpi=DPI, layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(objectives), 1, squeeze=False).ravel())
    for ax, (metric, direction) in zip(axes, objectives):
        value = ds[metric].values.astype(float)
        ax.plot(trial[feasible], value[feasible], "o", ms=3, color="C0", label="feasible")
        ax.plot(trial[complete & ~feasible], value[complete & ~feasible], "x", ms=4, color="C3", label="infeasible")
        best = np.where(feasible, value if direction == "minimize" else -value, np.inf)
        running = np.minimum.accumulate(best) * (1 if direction == "minimize" else -1)
        ax.step(trial, np.where(np.isfinite(running), running, np.nan), where="post", color="k", lw=1,
                label="best so far")
        if np.all(value[complete] > 0) and np.ptp(value[complete]) > 0 and value[complete].max() > 30 * value[complete].min():
            ax.set_yscale("log")
        units = units_text(str(ds[metric].attrs.get("units", "")))
        ax.set_ylabel(metric + (f" [{units}]" if units else ""), fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("trial")
    axes[0].legend(fontsize=7)
    return out.save(fig, f"tuning_{safe_filename(name)}_objective", f"{name}: objective against trial",
                    "Each trial's objective (the batch's worst case or quantile with --over); black: the best "
                    "feasible value so far. Failed trials are not drawn.")


#: Trials a parallel-coordinates view of a study draws: its best (feasible) ones.
SEARCH_BEST = 50


def _wide(values: np.ndarray) -> bool:
    """Whether positive values span enough (30x) for a log axis."""
    return bool(len(values) and np.all(values > 0) and values.max() > 30 * values.min())


def _searched(ds, parameters: Sequence[str]) -> list[str]:
    """The design columns that vary independently: of the entries of one key that a single
    factor scales together (``scale_uniform``, ``scale_log_uniform``), the first stands for
    them all."""
    kept: list[str] = []
    for p in parameters:
        values = ds[p].values.astype(float)
        key = p.split("[")[0]
        same = [q for q in kept if q.split("[")[0] == key]
        if any(_proportional(values, ds[q].values.astype(float)) for q in same):
            continue
        kept.append(p)
    return kept


def _proportional(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``a`` is a constant multiple of ``b`` over the trials where both are finite."""
    ok = np.isfinite(a) & np.isfinite(b) & (b != 0)
    if not ok.any():
        return False
    ratio = a[ok] / b[ok]
    return bool(np.allclose(ratio, ratio[0], rtol=1e-9, atol=0.0))


def _search_figure(ds, out: FigureWriter, name: str, objectives) -> FigureFile:
    """Where the study searched: one varied value, the objective against it; two, the trials
    over their plane coloured by the (first) objective; more, the parallel coordinates of
    the best feasible trials, each value on its range."""
    from matplotlib import colormaps  # matplotlib: only when a figure is drawn, as report/figures.py
    from matplotlib.cm import ScalarMappable  # the same
    from matplotlib.colors import LogNorm, Normalize  # the same
    from matplotlib.figure import Figure  # the same

    parameters = _searched(ds, json.loads(ds.attrs["parameters"]))
    metric, direction = objectives[0]
    complete = ds["state"].values.astype(str) == "complete"
    value = ds[metric].values.astype(float)
    ok = complete & np.isfinite(value)
    score = np.where(ok, value if direction == "minimize" else -value, np.inf)
    best = int(np.argmin(score)) if ok.any() else None
    norm = LogNorm() if _wide(value[ok]) else Normalize()
    units = units_text(str(ds[metric].attrs.get("units", "")))
    label = metric + (f" [{units}]" if units else "")
    columns = [ds[p].values.astype(float) for p in parameters]
    fig = Figure(figsize=(6.5, 4.5), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    if len(parameters) <= 2:
        x = columns[0]
        y = columns[1] if len(parameters) == 2 else value
        coloured = len(parameters) == 2  # two parameters: the objective as colour; one: it is the y axis
        drawn = ax.scatter(x[ok], y[ok], c=value[ok] if coloured else "C0", s=10, norm=norm if coloured else None,
                           cmap=("viridis_r" if direction == "minimize" else "viridis") if coloured else None)
        if best is not None:
            ax.plot(x[best], y[best], "*", ms=14, color="C3", label=f"best: trial {int(ds['trial'].values[best])}")
            ax.legend(fontsize=8)
        for axis, values, p in ((ax.xaxis, x, parameters[0]),
                                (ax.yaxis, y, parameters[1] if len(parameters) == 2 else label)):
            (ax.set_xscale if axis is ax.xaxis else ax.set_yscale)("log" if _wide(values[ok]) else "linear")
        ax.set_xlabel(parameters[0])
        ax.set_ylabel(parameters[1] if len(parameters) == 2 else label)
        if len(parameters) == 2:
            fig.colorbar(drawn, ax=ax, label=label)
        caption = ("Every completed trial over the two varied values, coloured by the objective; red star: the "
                   "best." if len(parameters) == 2 else "Every completed trial's objective against the varied value.")
    else:
        shown = np.argsort(score)[: min(SEARCH_BEST, int(ok.sum()))]
        lo = np.array([np.nanmin(c[ok]) for c in columns])
        hi = np.array([np.nanmax(c[ok]) for c in columns])
        scaled = np.array([(c - a) / (b - a) if b > a else np.full_like(c, 0.5) for c, a, b in zip(columns, lo, hi)])
        mapper = norm if len(shown) else Normalize()
        cmap = colormaps["viridis_r" if direction == "minimize" else "viridis"]
        if len(shown):
            mapper.autoscale(value[shown])
        for j in shown[::-1]:  # the best drawn last, on top
            ax.plot(range(len(parameters)), scaled[:, j], color=cmap(mapper(value[j])), lw=1, alpha=0.8)
        ax.set_xticks(range(len(parameters)), parameters, rotation=30, ha="right", fontsize=7)
        ax.set_ylabel("value on its range (0: lowest tried, 1: highest)")
        fig.colorbar(ScalarMappable(norm=mapper, cmap=cmap), ax=ax, label=label)
        caption = (f"The best {len(shown)} completed trials, each a line through its varied values (each on the "
                   "range the study tried), coloured by the objective.")
    ax.grid(alpha=0.3)
    return out.save(fig, f"tuning_{safe_filename(name)}_search", f"{name}: where the study searched", caption)


def _pareto_figure(ds, out: FigureWriter, name: str, objectives, best: Sequence[int]) -> FigureFile:
    from matplotlib.figure import Figure  # matplotlib: only when a figure is drawn, as report/figures.py

    (a, _), (b, _) = objectives
    feasible = ds["feasible"].values.astype(bool)
    fig = Figure(figsize=(6.0, 4.5), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    ax.plot(ds[a].values[feasible], ds[b].values[feasible], "o", ms=3, color="0.6", label="feasible trials")
    front = ds.sel(trial=list(best))
    ax.plot(front[a].values, front[b].values, "o-", ms=5, color="C0", label="Pareto front")
    ax.set_xlabel(a)
    ax.set_ylabel(b)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return out.save(fig, f"tuning_{safe_filename(name)}_pareto", f"{name}: Pareto front",
                    "The feasible trials over the two objectives; blue: the trials no other trial beats in both.")


def _best_table(ds, objectives, best: Sequence[int]) -> Table:
    parameters = json.loads(ds.attrs["parameters"])
    metrics = [m for m, _ in objectives]
    if len(objectives) == 1:
        metric, direction = objectives[0]
        ok = ds.isel(trial=np.flatnonzero(ds["feasible"].values.astype(bool)))
        order = np.argsort(ok[metric].values if direction == "minimize" else -ok[metric].values)[:BEST_ROWS]
        shown = ok.isel(trial=order)
    else:
        shown = ds.sel(trial=list(best)[:BEST_ROWS])
    rows = [[str(int(t)), *(_f(shown[m].values[i], 5) for m in metrics), *(_f(shown[p].values[i], 5) for p in parameters)]
            for i, t in enumerate(shown["trial"].values)]
    title = "Best trials" if len(objectives) == 1 else "Trials of the Pareto front"
    return Table(title, ["trial", *metrics, *parameters], rows,
                 note="best.yaml in the study folder holds the first row's values")
