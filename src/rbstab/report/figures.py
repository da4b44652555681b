"""Figures of a report (matplotlib, Agg canvas: no display needed, no pyplot state).

Per run, the figures of the paper (Figs 3-7): rotational states Theta, Omega; translational
states X, V (and D for ``embedded``) with the constraint error E; the Lyapunov function v
with its analytic and numerical rates. For several runs the same quantities overlaid,
one colour per run, and the norms |E|, |Omega| against the settling thresholds. For a
sweep, the chosen metrics against each varied parameter (a heatmap where two vary).

Every function writes PNG files and returns :class:`FigureFile` records (file name
relative to the report folder, title, caption). Units on the axes are the ``units``
attributes stored in the result files.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .load import RunData, SweepData, safe_filename
from .tables import SettleThresholds, metric_column, metric_label

__all__ = ["FigureFile", "run_figures", "switching_figure", "comparison_figures", "sweep_figures", "DPI"]

#: Resolution of the PNG files [dots per inch].
DPI = 110

#: Mathtext symbol of each plotted variable (the vector; components use :data:`COMPONENTS`).
SYMBOLS = {
    "theta": r"\Theta",
    "omega": r"\Omega",
    "position": "X",
    "velocity": "V",
    "controller_state": "D",
    "constraint_error": "E",
    "lyapunov": "v",
    "lyapunov_rate": r"\dot v",
}
#: Words for each plotted variable (axis labels say both).
WORDS = {
    "theta": "Euler angles",
    "omega": "angular velocity",
    "position": "COM position",
    "velocity": "COM velocity",
    "controller_state": "controller state",
    "constraint_error": "constraint error",
    "lyapunov": "Lyapunov function",
    "lyapunov_rate": "Lyapunov rate",
}
#: Mathtext symbol of the components of a variable, where it differs from :data:`SYMBOLS`.
COMPONENTS = {"theta": r"\theta"}
_LINESTYLES = ("-", "--", ":")
#: A constraint error below this [m] is drawn on a +-1 mm axis and labelled round-off.
ROUND_OFF_E = 1e-9


@dataclass(frozen=True)
class FigureFile:
    """One PNG of the report.

    Attributes
    ----------
    path : str
        File name relative to the report folder (``figures/<name>.png``).
    title : str
        Short title (HTML/markdown heading and alt text).
    caption : str
        What the figure shows, one or two sentences.
    """

    path: str
    title: str
    caption: str


def _units_text(units: str) -> str:
    """CF-style units (``rad s-1``) as they read on an axis (``rad/s``)."""
    return {"rad s-1": "rad/s", "m s-1": "m/s", "s-1": "1/s"}.get(units, units)


def _label(run: RunData, var: str, component: int | None = None) -> str:
    sym = SYMBOLS[var] if component is None else f"{COMPONENTS.get(var, SYMBOLS[var])}_{component + 1}"
    return f"{WORDS[var]} ${sym}$ [{_units_text(run.units(var))}]"


def _new_figure(rows: int, cols: int = 1, width: float = 9.0, row_height: float = 2.4, sharex: bool = True):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, row_height * rows + 0.6), dpi=DPI, layout="constrained")
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    return fig, axes


def _save(fig, folder: Path, name: str) -> str:
    rel = f"figures/{name}.png"
    try:
        fig.savefig(folder / rel, format="png", dpi=DPI)
    except ValueError:  # a text from the data (a run's name with '$') that is not valid mathtext
        _plain_texts(fig)
        fig.savefig(folder / rel, format="png", dpi=DPI)
    return rel


def _plain_texts(fig) -> None:
    """Show every text of ``fig`` that mathtext cannot parse as it is written."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    renderer = FigureCanvasAgg(fig).get_renderer()
    for text in fig.findobj(Text):
        try:
            text.get_window_extent(renderer)
        except ValueError:
            text.set_parse_math(False)


def _colours(n: int) -> list:
    from matplotlib import colormaps

    if n <= 10:
        return [colormaps["tab10"](i) for i in range(n)]
    if n <= 20:
        return [colormaps["tab20"](i) for i in range(n)]
    return [colormaps["viridis"](x) for x in np.linspace(0, 0.95, n)]


def _mark_failure(ax, run: RunData) -> None:
    """Whole planned time span on the x axis; for a failed run a red line at its last sample."""
    t = run.series()["time"]
    if len(t) > 1:
        ax.set_xlim(t[0], t[-1])
    if not run.ok:
        t_final = float(run.summary.get("t_final", np.nan))
        if np.isfinite(t_final):
            ax.axvline(t_final, color="red", lw=0.8, ls=":")


def _marker(values: np.ndarray) -> str | None:
    """A marker for series with few finite samples (a run that failed early), else None."""
    finite = np.isfinite(values).reshape(len(values), -1).all(axis=1).sum()
    return "o" if finite < 20 else None


def run_figures(run: RunData, folder: Path) -> list[FigureFile]:
    """The paper's figures for one run, written to ``folder/figures/``.

    Parameters
    ----------
    run : RunData
    folder : Path
        Report folder (``figures/`` must exist).

    Returns
    -------
    list of FigureFile
        ``<label>_rotational.png`` (Theta [rad], Omega [rad/s] against t [s]; cf. the
        paper's Figs 3, 4, 6), ``<label>_translational.png`` (X [m], V [m/s], D [m] for
        ``embedded``, E [m]; Figs 5, 7), ``<label>_lyapunov.png`` (v [J]; analytic and
        numerical dv/dt [W] overlaid; their difference [W]); for a run of the pure sign
        law, also ``<label>_switching.png`` (:func:`switching_figure`).
    """
    stem = safe_filename(run.label)
    out = []
    status = "" if run.ok else f" - FAILED (last sample t = {run.summary.get('t_final', float('nan')):.4g} s)"

    # rotational states
    s = run.series("theta", "omega")
    fig, axes = _new_figure(2)
    for ax, var in zip(axes[:, 0], ("theta", "omega")):
        for k in range(3):
            ax.plot(s["time"], s[var][:, k], ls=_LINESTYLES[k], marker=_marker(s[var]),
                    label=f"${COMPONENTS.get(var, SYMBOLS[var])}_{k + 1}$")
        ax.set_ylabel(_label(run, var))
        ax.legend(title=run.label, loc="upper right", fontsize=8, title_fontsize=8, ncols=3)
        ax.grid(alpha=0.3)
        _mark_failure(ax, run)
    axes[-1, 0].set_xlabel("time $t$ [s]")
    fig.suptitle(f"{run.label} ({run.variant}): rotational states{status}", fontsize=11)
    out.append(FigureFile(_save(fig, folder, f"{stem}_rotational"), f"{run.label}: rotational states",
                          "Euler angles Theta and body angular velocity Omega against time (cf. the paper's Figs 3, 4, 6)."))

    # translational states and constraint error
    names = ["position", "velocity"] + (["controller_state"] if "controller_state" in run.series("controller_state") else [])
    names.append("constraint_error")
    s = run.series(*names)
    fig, axes = _new_figure(len(names))
    for ax, var in zip(axes[:, 0], names):
        for k in range(3):
            ax.plot(s["time"], s[var][:, k], ls=_LINESTYLES[k], marker=_marker(s[var]),
                    label=f"${COMPONENTS.get(var, SYMBOLS[var])}_{k + 1}$")
        ax.set_ylabel(_label(run, var), fontsize=9)
        ax.legend(title=run.label, loc="upper right", fontsize=8, title_fontsize=8, ncols=3)
        ax.grid(alpha=0.3)
        _mark_failure(ax, run)
    peak = float(np.nanmax(np.abs(s["constraint_error"]))) if np.isfinite(s["constraint_error"]).any() else np.nan
    if peak <= ROUND_OFF_E:
        # E is zero up to round-off (permanent): show it on a physical scale, say so
        ax = axes[-1, 0]
        ax.set_ylim(-1e-3, 1e-3)
        ax.text(0.02, 0.1, f"max |E| = {peak:.2g} m: zero to round-off (axis limits +-1 mm)",
                transform=ax.transAxes, fontsize=8, color="0.3")
    axes[-1, 0].set_xlabel("time $t$ [s]")
    extra = " (X, V reconstructed from Theta, Omega: C is fixed, E = 0)" if run.variant == "permanent" else ""
    fig.suptitle(f"{run.label} ({run.variant}): translational states and constraint error{status}", fontsize=11)
    out.append(FigureFile(_save(fig, folder, f"{stem}_translational"), f"{run.label}: translational states and constraint",
                          "Centre-of-mass position X and velocity V (inertial frame), "
                          + ("controller state D, " if "controller_state" in names else "")
                          + f"and the constraint error E = X + A R - R against time (cf. the paper's Figs 5, 7){extra}."))

    # Lyapunov function and its rates
    s = run.series("lyapunov", "lyapunov_rate", "lyapunov_rate_numerical")
    fig, axes = _new_figure(3)
    t = s["time"]
    axes[0, 0].plot(t, s["lyapunov"], color="k", marker=_marker(s["lyapunov"]), label="$v$")
    axes[0, 0].set_ylabel(_label(run, "lyapunov"))
    axes[1, 0].plot(t, s["lyapunov_rate"], color="C0", lw=2.2, alpha=0.6, marker=_marker(s["lyapunov_rate"]),
                    label=r"$\dot v$ analytic")
    axes[2, 0].set_ylabel(rf"analytic $-$ numerical [{_units_text(run.units('lyapunov_rate'))}]", fontsize=9)
    if "lyapunov_rate_numerical" in s:
        axes[1, 0].plot(t, s["lyapunov_rate_numerical"], color="C3", ls="--", lw=1.0,
                        marker=_marker(s["lyapunov_rate_numerical"]), label=r"$\dot v$ numerical")
        axes[2, 0].plot(t, s["lyapunov_rate"] - s["lyapunov_rate_numerical"], color="C3", lw=0.9,
                        label=r"$\dot v_{analytic} - \dot v_{numerical}$")
    axes[1, 0].set_ylabel(_label(run, "lyapunov_rate"))
    for ax in axes[:, 0]:
        ax.legend(title=run.label, loc="upper right", fontsize=8, title_fontsize=8)
        ax.grid(alpha=0.3)
        _mark_failure(ax, run)
    axes[-1, 0].set_xlabel("time $t$ [s]")
    check = run.summary.get("lyapunov_rate_check", "?")
    fig.suptitle(f"{run.label} ({run.variant}): Lyapunov function and its rate (check: {check}){status}", fontsize=11)
    out.append(FigureFile(_save(fig, folder, f"{stem}_lyapunov"), f"{run.label}: Lyapunov function",
                          "v, its analytic rate dv/dt (solid) and the numerical derivative of v along the samples "
                          "(dashed), and their difference (cf. the paper's Figs 3, 4, 6)."))
    switching = switching_figure(run, folder)
    return out + ([switching] if switching else [])


def switching_figure(run: RunData, folder: Path) -> FigureFile | None:
    """The located events of a pure-sign-law run (None for other runs): per axis of E, the
    crossings of E_i = 0 against time with the sliding intervals shaded, and the histogram
    of the intervals between successive crossings (log scale) -- the chattering."""
    s = run.series("switching_time", "switching_axis", "switching_kind")
    if "switching_time" not in s:
        return None
    t, axis, kind = s["switching_time"], s["switching_axis"].astype(int), s["switching_kind"].astype(int)
    t_final = float(run.summary.get("t_final", np.nan))
    fig, axes = _new_figure(1, 2, width=13.0, row_height=3.2, sharex=False)
    raster, histogram = axes[0]
    for i in range(3):
        crossings = t[(axis == i) & (kind == 0)]
        raster.vlines(crossings, i - 0.35, i + 0.35, color=f"C{i}", lw=0.4)
        starts, ends = t[(axis == i) & (kind == 1)], t[(axis == i) & (kind == 2)]
        for a, b in zip(starts, np.r_[ends, np.full(len(starts) - len(ends), t_final)]):
            raster.axvspan(a, b, ymin=(i + 0.1) / 3, ymax=(i + 0.9) / 3, color=f"C{i}", alpha=0.25, lw=0)
        gaps = np.diff(crossings)
        if gaps.size and np.all(gaps > 0):
            bins = np.logspace(np.log10(gaps.min()), np.log10(gaps.max()) + 1e-9, 40)
            histogram.hist(gaps, bins=bins, histtype="step", color=f"C{i}",
                           label=f"$E_{i + 1}$: {crossings.size} crossings")
    raster.set_yticks([0, 1, 2], ["$E_1$", "$E_2$", "$E_3$"])
    raster.set_ylim(-0.5, 2.5)
    raster.set_xlabel("time $t$ [s]")
    raster.set_title("crossings of $E_i = 0$ (lines), sliding on it (shaded)", fontsize=9)
    histogram.set_xscale("log")
    histogram.set_xlabel("interval between successive crossings [s]")
    histogram.set_ylabel("count")
    if histogram.get_legend_handles_labels()[0]:
        histogram.legend(fontsize=8)
    for ax in (raster, histogram):
        ax.grid(alpha=0.3)
    resolution = run.summary.get("switching_resolution", float("nan"))
    fig.suptitle(f"{run.label} ({run.variant}, pure sign law): switchings, resolution {resolution:g} m", fontsize=11)
    return FigureFile(_save(fig, folder, f"{safe_filename(run.label)}_switching"), f"{run.label}: switchings",
                      "Located crossings of each surface E_i = 0 against time, the intervals where C slid on it "
                      "(equivalent force), and the histogram of the intervals between successive crossings "
                      "(the chattering; see docs/sliding.md).")


def _overlay(runs: Sequence[RunData], variables: Sequence[str], folder: Path, name: str, title: str) -> str:
    colours = _colours(len(runs))
    fig, axes = _new_figure(len(variables), 3, width=13.0, row_height=2.5)
    for r, var in enumerate(variables):
        for run, colour in zip(runs, colours):
            s = run.series(var)
            if var not in s:
                continue
            for k in range(3):
                axes[r, k].plot(s["time"], s[var][:, k], color=colour, lw=1.2, label=run.label)
        for k in range(3):
            ax = axes[r, k]
            ax.set_ylabel(_label(runs[0], var, k), fontsize=9)
            ax.grid(alpha=0.3)
    for k in range(3):
        axes[-1, k].set_xlabel("time $t$ [s]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(runs), 4), fontsize=9)
    fig.suptitle(title, fontsize=11)
    return _save(fig, folder, name)


def comparison_figures(runs: Sequence[RunData], folder: Path, thresholds: SettleThresholds) -> list[FigureFile]:
    """Overlays of several runs (one colour per run), written to ``folder/figures/``.

    Parameters
    ----------
    runs : sequence of RunData
        At least one; the overlays of states are drawn for two or more.
    folder : Path
        Report folder.
    thresholds : SettleThresholds
        Drawn on the norms figure.

    Returns
    -------
    list of FigureFile
        ``compare_rotational.png`` (Theta_k [rad], Omega_k [rad/s], one column per
        component), ``compare_translational.png`` (X_k [m], V_k [m/s], E_k [m]),
        ``compare_lyapunov.png`` (v [J], log scale when positive; dv/dt [W] analytic
        solid / numerical dashed),
        and ``norms.png`` (|E| [m] and |Omega| [rad/s], log scale, with the settling
        thresholds), which is also drawn for a single run.
    """
    out = []
    if len(runs) >= 2:
        out.append(FigureFile(_overlay(runs, ("theta", "omega"), folder, "compare_rotational", "Rotational states"),
                              "Comparison: rotational states", "Theta and Omega of every run, one column per component."))
        out.append(FigureFile(_overlay(runs, ("position", "velocity", "constraint_error"), folder, "compare_translational",
                                       "Translational states and constraint error"),
                              "Comparison: translational states and constraint error",
                              "X, V and the constraint error E of every run, one column per component."))
        colours = _colours(len(runs))
        fig, axes = _new_figure(2, width=11.0, row_height=2.8)
        for run, colour in zip(runs, colours):
            s = run.series("lyapunov", "lyapunov_rate", "lyapunov_rate_numerical")
            axes[0, 0].plot(s["time"], s["lyapunov"], color=colour, label=run.label)
            axes[1, 0].plot(s["time"], s["lyapunov_rate"], color=colour, label=f"{run.label} analytic")
            if "lyapunov_rate_numerical" in s:
                axes[1, 0].plot(s["time"], s["lyapunov_rate_numerical"], color=colour, ls="--", lw=0.9,
                                label=f"{run.label} numerical")
        axes[0, 0].set_ylabel(_label(runs[0], "lyapunov"))
        v_all = np.concatenate([r.series("lyapunov")["lyapunov"] for r in runs])
        v_all = v_all[np.isfinite(v_all)]
        if v_all.size and np.all(v_all > 0):
            axes[0, 0].set_yscale("log")
        axes[1, 0].set_ylabel(_label(runs[0], "lyapunov_rate"))
        for ax in axes[:, 0]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, ncols=2 if len(runs) > 3 else 1, loc="upper right")
        axes[-1, 0].set_xlabel("time $t$ [s]")
        fig.suptitle("Lyapunov function and its rate (analytic solid, numerical dashed)", fontsize=11)
        out.append(FigureFile(_save(fig, folder, "compare_lyapunov"), "Comparison: Lyapunov function",
                              "v (log scale where every v is positive) and dv/dt of every run; the numerical rate (dashed) "
                              "should lie on the analytic one."))
    # norms against the settling thresholds
    colours = _colours(len(runs))
    fig, axes = _new_figure(2, width=11.0, row_height=2.8)
    floor = {0: thresholds.e * 1e-4, 1: thresholds.omega * 1e-4}
    for run, colour in zip(runs, colours):
        s = run.series("constraint_error", "omega")
        for row, var in enumerate(("constraint_error", "omega")):
            norm = np.linalg.norm(s[var], axis=1)
            axes[row, 0].plot(s["time"], np.maximum(norm, floor[row]), color=colour, label=run.label)
    for row, (var, limit) in enumerate((("constraint_error", thresholds.e), ("omega", thresholds.omega))):
        ax = axes[row, 0]
        ax.set_yscale("log")
        ax.axhline(limit, color="k", ls="--", lw=0.9, label=f"threshold {limit:g} {_units_text(runs[0].units(var))}")
        ax.set_ylabel(f"$|{SYMBOLS[var]}|$ [{_units_text(runs[0].units(var))}]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time $t$ [s]")
    fig.suptitle("Norms of the constraint error and of the angular velocity (settling thresholds dashed)", fontsize=11)
    out.append(FigureFile(_save(fig, folder, "norms"), "Constraint error and angular velocity norms",
                          f"|E| and |Omega| (Euclidean norms, log scale; values below {floor[0]:g} m and "
                          f"{floor[1]:g} rad/s drawn at those floors). A run has settled once both stay under "
                          "the dashed thresholds."))
    return out


def _axis_values(values) -> tuple[np.ndarray, list[str] | None]:
    """Numeric positions of parameter values and, if categorical, their tick labels."""
    import pandas as pd

    num = pd.to_numeric(pd.Series(values), errors="coerce")
    if num.notna().all():
        return num.to_numpy(dtype=float), None
    cats = list(dict.fromkeys(str(v) for v in values))
    cats.sort(key=_natural_key)
    pos = {c: i for i, c in enumerate(cats)}
    return np.array([pos[str(v)] for v in values], dtype=float), cats


def _natural_key(text: str) -> tuple:
    """Sort key: the numbers in ``text`` (so ``[4100, ...]`` sorts before ``[12300, ...]``)."""
    import re

    numbers = re.findall(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", text)
    return (tuple(float(n) for n in numbers), text)


def _is_grid(x: np.ndarray, y: np.ndarray) -> bool:
    """True when the (x, y) pairs are distinct and fill at least half of their grid."""
    pairs = set(zip(x.tolist(), y.tolist()))
    cells = len(set(x.tolist())) * len(set(y.tolist()))
    return len(pairs) == len(x) and cells <= 2500 and len(pairs) >= 0.5 * cells


def _use_log(values: np.ndarray) -> bool:
    v = values[np.isfinite(values)]
    return v.size > 1 and np.all(v > 0) and v.max() / v.min() > 100


def _groups(table, exclude: str) -> np.ndarray:
    """A label per run from the columns ``base`` and ``variant`` that vary (and are not
    ``exclude``, the plotted parameter): the colour groups of a sweep's scatter plots."""
    columns = [c for c in ("base", "variant") if c != exclude and c in table.columns
               and table[c].astype(str).nunique() > 1]
    if not columns:
        return np.full(len(table), "", dtype=object)
    return table[columns].astype(str).agg(" / ".join, axis=1).to_numpy(dtype=object)


def sweep_figures(sweep: SweepData, table, metrics: Sequence[str], folder: Path) -> list[FigureFile]:
    """Metrics of a sweep against its varied parameters, written to ``folder/figures/``.

    Parameters
    ----------
    sweep : SweepData
    table : pandas.DataFrame
        :func:`rbstab.report.tables.sweep_table` of the sweep (one row per run).
    metrics : sequence of str
        Metric names (:func:`rbstab.report.tables.allowed_metrics`).
    folder : Path
        Report folder.

    Returns
    -------
    list of FigureFile
        With two varied parameters on a grid (distinct pairs filling at least half of the
        grid) one heatmap per metric (``sweep_<name>_heatmap_<metric>.png``, failed cells
        hatched); otherwise, for each
        varied parameter, ``sweep_<name>_<parameter>.png`` with one panel per metric
        (successful runs as dots coloured by base / variant where those vary, failed runs
        as red crosses on the lower edge). Empty when no parameter varies. ``converged``
        as a metric gives a map of 1 (converged) and 0.
    """
    stem = f"sweep_{safe_filename(sweep.name)}"
    failed = (table["status"].astype(str) != "success").to_numpy()
    out = []
    grid2 = None
    if len(sweep.varied) == 2:
        x, xcats = _axis_values(table[sweep.varied[0]])
        y, ycats = _axis_values(table[sweep.varied[1]])
        if _is_grid(x, y):
            grid2 = (x, xcats, y, ycats)
    if grid2 is not None:
        p1, p2 = sweep.varied
        x, xcats, y, ycats = grid2
        xs, ys = np.unique(x), np.unique(y)
        from matplotlib.colors import LogNorm
        from matplotlib.patches import Rectangle

        for name in metrics:
            col = metric_column(name)
            grid = np.full((len(ys), len(xs)), np.nan)
            present = set(zip(x.tolist(), y.tolist()))
            bad = np.zeros_like(grid, dtype=bool)
            for xi, yi, val, f in zip(x, y, table[col].to_numpy(dtype=float), failed):
                i, j = int(np.searchsorted(ys, yi)), int(np.searchsorted(xs, xi))
                if f:
                    bad[i, j] = True
                else:
                    grid[i, j] = val
            fig, axes = _new_figure(1, width=8.0, row_height=5.0)
            ax = axes[0, 0]
            norm = LogNorm() if _use_log(grid.ravel()) else None
            mesh = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis", norm=norm)
            if np.isfinite(grid).any():
                fig.colorbar(mesh, ax=ax, label=metric_label(name))
            undefined = "not settled" if name == "settling_time" else "n/a"
            for i in range(len(ys)):
                for j in range(len(xs)):
                    if bad[i, j]:
                        ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="xx", edgecolor="red", lw=0))
                        ax.text(j, i, "failed", ha="center", va="center", color="red", fontsize=8,
                                bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85})
                    elif grid.size > 144:
                        continue
                    elif np.isfinite(grid[i, j]):
                        r, g, b, _ = mesh.cmap(mesh.norm(grid[i, j]))
                        ink = "k" if 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "w"
                        ax.text(j, i, f"{grid[i, j]:.3g}", ha="center", va="center", fontsize=8, color=ink)
                    elif (xs[j], ys[i]) in present:
                        ax.text(j, i, undefined, ha="center", va="center", fontsize=8, color="0.3")
            ax.set_xticks(range(len(xs)), xcats if xcats else [f"{v:g}" for v in xs], rotation=30, fontsize=8)
            ax.set_yticks(range(len(ys)), ycats if ycats else [f"{v:g}" for v in ys], fontsize=8)
            ax.set_xlabel(p1)
            ax.set_ylabel(p2)
            fig.suptitle(f"sweep {sweep.name}: {metric_label(name)}", fontsize=11)
            out.append(FigureFile(_save(fig, folder, f"{stem}_heatmap_{safe_filename(name)}"),
                                  f"{sweep.name}: {name} over {p1} and {p2}",
                                  f"{metric_label(name)} for each pair of values of {p1} and {p2}; "
                                  "hatched red cells: failed runs; 'n/a' or 'not settled': the metric is undefined "
                                  "for that run; blank: no run."))
        return out
    from matplotlib.transforms import blended_transform_factory

    for param in sweep.varied:
        x, cats = _axis_values(table[param])
        fig, axes = _new_figure(len(metrics), width=9.0, row_height=2.6)
        for ax, name in zip(axes[:, 0], metrics):
            y = table[metric_column(name)].to_numpy(dtype=float)
            ok = ~failed
            order = np.argsort(x[ok], kind="stable")
            style = "o-" if len(sweep.varied) == 1 else "o"
            groups = _groups(table, exclude=param)
            for k, label in enumerate(dict.fromkeys(groups[ok][order])):
                mine = groups[ok][order] == label
                ax.plot(x[ok][order][mine], y[ok][order][mine], style, ms=4, color=f"C{k % 10}",
                        label=label or "success")
            if failed.any():
                trans = blended_transform_factory(ax.transData, ax.transAxes)
                ax.plot(x[failed], np.full(failed.sum(), 0.03), "x", color="red", ms=8, mew=2,
                        transform=trans, label="failed", clip_on=False)
            if _use_log(y[ok]):
                ax.set_yscale("log")
            ax.set_ylabel(metric_label(name), fontsize=9)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc="best")
            if cats:
                ax.set_xticks(range(len(cats)), cats, rotation=20, fontsize=8)
        axes[-1, 0].set_xlabel(param)
        others = [p for p in sweep.varied if p != param]
        note = f" (other varied parameters mixed: {', '.join(others)})" if others else ""
        title = textwrap.fill(f"sweep {sweep.name}: metrics against {param}{note}", width=110)
        fig.suptitle(title, fontsize=11 if "\n" not in title else 9)
        out.append(FigureFile(_save(fig, folder, f"{stem}_{safe_filename(param)}"),
                              f"{sweep.name}: metrics against {param}",
                              f"{', '.join(metrics)} against {param}{note}; red crosses on the lower edge: failed runs "
                              "(status failed, error or pending). A successful run without a value (e.g. not settled) "
                              "has no point."))
    return out
