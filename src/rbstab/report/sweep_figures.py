"""Figures of a sweep: the chosen metrics against the varied parameters.

With two varied parameters on a grid, one heatmap per metric; otherwise, for each varied
parameter, one panel per metric against it. Written by a
:class:`rbstab.report.figures.FigureWriter`. Every axis names its parameter as ``--grid``
does, with units (:func:`parameter_label`); a metric spanning decades is drawn on a
logarithmic or symmetric-log scale (:func:`rbstab.report.figures.value_scale`); a metric
at round-off in every run, or with no value, is not drawn (:func:`left_out`).
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..layout import display_units, parameter_attributes, slide_parts
from .figures import FigureFile, FigureWriter, colour_norm, new_figure, set_scale, value_scale
from .load import SweepData, safe_filename
from .tables import REST_AWAY, UNSTABLE_REST, metric_column, metric_label, metric_units

__all__ = ["sweep_figures", "parameter_label", "left_out", "ROUND_OFF"]

#: Heatmaps with more cells than this are not annotated with their values.
MAX_ANNOTATED_CELLS = 144
#: A metric of physical units (not dimensionless, not a time) whose every value is at most
#: this in magnitude, in its SI units (m, J, rad, W, ...), is round-off (:func:`left_out`):
#: e.g. max |E| of a ``permanent`` joint, which reduced coordinates hold (~1e-16 m).
ROUND_OFF = 1e-12


def parameter_label(sweep: SweepData, name: str) -> str:
    """The axis label of a sweep's parameter ``name`` (of :attr:`SweepData.axes`): the
    config entry it sets, as ``--grid`` names it, and its units
    (:func:`rbstab.layout.parameter_attributes`), e.g. ``joints.ankle.k_r.0 [N m/rad]``;
    the entry alone where it has none or is dimensionless (``variant``, ``body.mass:scale``)."""
    entry = sweep.entries.get(name, name)
    units = display_units(parameter_attributes(entry, slide_parts(sweep.spec)).get("units"))
    return f"{entry} [{units}]" if units and units != "1" else entry


def left_out(name: str, values) -> str | None:
    """Why a sweep's metric ``name`` is not drawn, from its ``values`` over the successful
    runs (NaN: none): no value in any run, or round-off in every run (its units physical,
    not ``1`` nor ``s``, and every magnitude at most :data:`ROUND_OFF`). None: it is drawn;
    ``settling_time`` and ``settled`` always are (their cells say how each run ended)."""
    if name in _REST_METRICS:
        return None
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return f"{metric_label(name)}: no successful run has a value of it; not drawn."
    units, peak = metric_units(name), float(np.abs(v).max())
    if units not in ("1", "s") and peak <= ROUND_OFF:
        return (f"{metric_label(name)}: round-off in every run (largest magnitude {peak:.2g} {units}, at most "
                f"{ROUND_OFF:g} {units}); not drawn.")
    return None


def _axis_values(values) -> tuple[np.ndarray, list[str] | None]:
    """Numeric positions of parameter values and, if categorical, their tick labels."""
    import pandas as pd  # heavy: pandas

    num = pd.to_numeric(pd.Series(values), errors="coerce")
    if num.notna().all():
        return num.to_numpy(dtype=float), None
    cats = sorted(dict.fromkeys(str(v) for v in values), key=_natural_key)
    pos = {c: i for i, c in enumerate(cats)}
    return np.array([pos[str(v)] for v in values], dtype=float), cats


def _natural_key(text: str) -> tuple:
    """Sort key: the numbers in ``text`` (so ``[4100, ...]`` sorts before ``[12300, ...]``)."""
    numbers = re.findall(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", text)
    return (tuple(float(n) for n in numbers), text)


def _is_grid(x: np.ndarray, y: np.ndarray) -> bool:
    """True when the (x, y) pairs are distinct and fill at least half of their grid."""
    pairs = set(zip(x.tolist(), y.tolist()))
    cells = len(set(x.tolist())) * len(set(y.tolist()))
    return len(pairs) == len(x) and cells <= 2500 and len(pairs) >= 0.5 * cells


def _groups(table, exclude: str) -> np.ndarray:
    """A label per run from the columns ``base`` and ``variant`` that vary (and are not
    ``exclude``, the plotted parameter): the colour groups of a sweep's scatter plots."""
    columns = [c for c in ("base", "variant") if c != exclude and c in table.columns
               and table[c].astype(str).nunique() > 1]
    if not columns:
        return np.full(len(table), "", dtype=object)
    return table[columns].astype(str).agg(" / ".join, axis=1).to_numpy(dtype=object)


def sweep_figures(sweep: SweepData, table, metrics: Sequence[str], out: FigureWriter) -> list[FigureFile | str]:
    """Metrics of a sweep against its varied parameters.

    Parameters
    ----------
    sweep : SweepData
    table : pandas.DataFrame
        :func:`rbstab.report.tables.sweep_table` of the sweep (one row per run).
    metrics : sequence of str
        Metric names (:func:`rbstab.report.tables.allowed_metrics`).
    out : FigureWriter

    Returns
    -------
    list of FigureFile or str
        With two varied parameters on a grid (distinct pairs filling at least half of the
        grid) one heatmap per metric (``sweep_<name>_heatmap_<metric>``, failed cells
        hatched; colours on a log scale where the values span decades, a symmetric-log one
        about zero, diverging, where their signs mix too); otherwise, for each varied
        parameter, ``sweep_<name>_<parameter>`` with one panel per metric (successful runs
        as dots coloured by base / variant where those vary, failed runs as red crosses on
        the lower edge; the same scales on the metric's axis). Parameter axes are labelled
        by :func:`parameter_label`. Empty when no parameter varies. A metric that
        :func:`left_out` leaves out has no heatmap or panel: a sentence saying why follows
        the figures. ``converged`` as a metric gives a map of 1 (converged) and 0, ``settled``
        one of 1 (settled) and 0; their cells and those of ``settling_time`` are labelled
        with how the run ended (``report:rest``: not settled, rest away from equilibrium,
        unstable rest), and in the panels the runs at rest but not settled are marked on
        the lower edge.
    """
    if not sweep.varied:
        return []
    ok = (table["status"].astype(str) == "success").to_numpy()
    notes = {name: left_out(name, table[metric_column(name)].to_numpy(dtype=float)[ok]) for name in metrics}
    drawn = [name for name in metrics if notes[name] is None]
    grid = _Grid.of(sweep, table)
    if grid is not None:
        figures = [_heatmap(sweep, grid, table, name, out) for name in drawn]
    else:
        figures = [_parameter_figure(sweep, table, param, drawn, out) for param in sweep.varied] if drawn else []
    return [*figures, *(note for note in notes.values() if note)]


# -- two parameters on a grid: heatmaps ------------------------------------------------------------

@dataclass(frozen=True)
class _Grid:
    """Two varied parameters whose runs fill a grid: run positions and the cell values."""

    names: tuple[str, str]
    x: np.ndarray
    y: np.ndarray
    labels: tuple[list[str], list[str]]

    @classmethod
    def of(cls, sweep: SweepData, table) -> "_Grid | None":
        if len(sweep.varied) != 2:
            return None
        (x, xcats), (y, ycats) = (_axis_values(table[p]) for p in sweep.varied)
        if not _is_grid(x, y):
            return None
        xs, ys = np.unique(x), np.unique(y)
        return cls(tuple(sweep.varied), x, y, (xcats or [f"{v:g}" for v in xs], ycats or [f"{v:g}" for v in ys]))

    def cells(self, values: np.ndarray, failed: np.ndarray, words: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, dict]:
        """(value per cell, failed per cell, the cells that have a run -> the word of the
        run there, from ``words``, else ""), rows along y."""
        xs, ys = np.unique(self.x), np.unique(self.y)
        grid = np.full((len(ys), len(xs)), np.nan)
        bad = np.zeros_like(grid, dtype=bool)
        present = {}
        for k, (xi, yi, value, f) in enumerate(zip(self.x, self.y, values, failed)):
            i, j = int(np.searchsorted(ys, yi)), int(np.searchsorted(xs, xi))
            bad[i, j] |= bool(f)
            present[i, j] = "" if words is None else str(words[k])
            if not f:
                grid[i, j] = value
        return grid, bad, present


def _heatmap(sweep: SweepData, g: _Grid, table, name: str, out: FigureWriter) -> FigureFile:
    failed = (table["status"].astype(str) != "success").to_numpy()
    rest = name in _REST_METRICS and "report:rest" in table.columns
    grid, bad, present = g.cells(table[metric_column(name)].to_numpy(dtype=float), failed,
                                 table["report:rest"].to_numpy(dtype=object) if rest else None)
    fig, axes = new_figure(1, width=8.0, row_height=5.0)
    ax = axes[0, 0]
    scale = value_scale(grid)
    mesh = ax.imshow(grid, origin="lower", aspect="auto", cmap="RdBu_r" if scale == "symlog" else "viridis",
                     norm=colour_norm(grid))
    if np.isfinite(grid).any():
        fig.colorbar(mesh, ax=ax, label=metric_label(name) + ("" if scale == "linear" else f" ({scale} scale)"))
    _annotate_cells(ax, mesh, grid, bad, present, words=name == "settled")
    ax.set_xticks(range(grid.shape[1]), g.labels[0], rotation=30, fontsize=8)
    ax.set_yticks(range(grid.shape[0]), g.labels[1], fontsize=8)
    p1, p2 = g.names
    ax.set_xlabel(parameter_label(sweep, p1))
    ax.set_ylabel(parameter_label(sweep, p2))
    fig.suptitle(f"sweep {sweep.name}: {metric_label(name)}", fontsize=11)
    colours = {"log": "colours on a logarithmic scale; ",
               "symlog": "colours on a symmetric-log scale about zero (red positive, blue negative); "}.get(scale, "")
    return out.save(fig, f"sweep_{safe_filename(sweep.name)}_heatmap_{safe_filename(name)}",
                    f"{sweep.name}: {name} over {p1} and {p2}",
                    f"{metric_label(name)} for each pair of values of {parameter_label(sweep, p1)} and "
                    f"{parameter_label(sweep, p2)}; {colours}hatched red cells: failed runs; "
                    + ("cells labelled with how the run ended (not settled, rest away from equilibrium: at rest "
                       "but v not converged, unstable rest: at rest at a linearly unstable rest state); "
                       if rest else "'n/a': the metric is undefined for that run; ") + "blank: no run.")


#: Metrics whose cells say how the run ended (``report:rest``) where it did not settle.
_REST_METRICS = ("settling_time", "settled")


def _annotate_cells(ax, mesh, grid: np.ndarray, bad: np.ndarray, present: dict, words: bool = False) -> None:
    """Failed cells hatched and labelled; on small grids every cell's value, or its run's
    word (``present``) where it has none (``n/a`` without one), or where ``words`` its word
    beside the value."""
    from matplotlib.patches import Rectangle  # heavy: matplotlib

    for i, j in np.ndindex(grid.shape):
        word = textwrap.fill(present.get((i, j)) or "n/a", 12)
        if bad[i, j]:
            ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="xx", edgecolor="red", lw=0))
            ax.text(j, i, "failed", ha="center", va="center", color="red", fontsize=8,
                    bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85})
        elif grid.size > MAX_ANNOTATED_CELLS:
            continue
        elif np.isfinite(grid[i, j]):
            r, g, b, alpha = mesh.cmap(mesh.norm(grid[i, j]))  # alpha 0: off a log scale (0), not drawn
            ink = "k" if alpha == 0 or 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "w"
            ax.text(j, i, word if words else f"{grid[i, j]:.3g}", ha="center", va="center", fontsize=8, color=ink)
        elif (i, j) in present:
            ax.text(j, i, word, ha="center", va="center", fontsize=8, color="0.3")


# -- otherwise: each metric against each parameter -------------------------------------------------

def _metric_panel(ax, table, param: str, x: np.ndarray, name: str, failed: np.ndarray, style: str) -> None:
    """One metric against one parameter: groups as coloured dots, failed runs as red crosses."""
    from matplotlib.transforms import blended_transform_factory  # heavy: matplotlib

    y = table[metric_column(name)].to_numpy(dtype=float)
    ok = ~failed
    order = np.argsort(x[ok], kind="stable")
    groups = _groups(table, exclude=param)[ok][order]
    for k, label in enumerate(dict.fromkeys(groups)):
        mine = groups == label
        ax.plot(x[ok][order][mine], y[ok][order][mine], style, ms=4, color=f"C{k % 10}", label=label or "success")
    trans = blended_transform_factory(ax.transData, ax.transAxes)
    if failed.any():
        ax.plot(x[failed], np.full(failed.sum(), 0.03), "x", color="red", ms=8, mew=2, transform=trans,
                label="failed", clip_on=False)
    if name in _REST_METRICS and "report:rest" in table.columns:
        for word, marker, colour in ((REST_AWAY, "v", "C1"), (UNSTABLE_REST, "^", "C3")):
            pick = ok & (table["report:rest"].astype(str) == word).to_numpy()
            if pick.any():
                ax.plot(x[pick], np.full(pick.sum(), 0.03), marker, color=colour, ms=7, transform=trans,
                        label=word, clip_on=False)
    set_scale(ax, y[ok])
    ax.set_ylabel(metric_label(name), fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")


def _parameter_figure(sweep: SweepData, table, param: str, metrics: Sequence[str], out: FigureWriter) -> FigureFile:
    failed = (table["status"].astype(str) != "success").to_numpy()
    x, cats = _axis_values(table[param])
    fig, axes = new_figure(len(metrics), width=9.0, row_height=2.6)
    for ax, name in zip(axes[:, 0], metrics):
        _metric_panel(ax, table, param, x, name, failed, "o-" if len(sweep.varied) == 1 else "o")
        if cats:
            ax.set_xticks(range(len(cats)), cats, rotation=20, fontsize=8)
    axes[-1, 0].set_xlabel(parameter_label(sweep, param))
    others = [p for p in sweep.varied if p != param]
    note = f" (other varied parameters mixed: {', '.join(others)})" if others else ""
    title = textwrap.fill(f"sweep {sweep.name}: metrics against {param}{note}", width=110)
    fig.suptitle(title, fontsize=11 if "\n" not in title else 9)
    return out.save(fig, f"sweep_{safe_filename(sweep.name)}_{safe_filename(param)}",
                    f"{sweep.name}: metrics against {param}",
                    f"{', '.join(metrics)} against {param}{note}; red crosses on the lower edge: failed runs "
                    "(status failed, error or pending). A successful run without a value (e.g. not settled) "
                    "has no point; in a panel of settling_time or settled, triangles on the lower edge mark the runs "
                    "at rest but not settled (rest away from equilibrium, unstable rest).")
