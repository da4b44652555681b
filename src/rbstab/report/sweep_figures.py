"""Figures of a sweep: the chosen metrics against the varied parameters.

With two varied parameters on a grid, one heatmap per metric; otherwise, for each varied
parameter, one panel per metric against it. Written by a
:class:`rbstab.report.figures.FigureWriter`.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .figures import FigureFile, FigureWriter, new_figure
from .load import SweepData, safe_filename
from .tables import REST_AWAY, UNSTABLE_REST, metric_column, metric_label

__all__ = ["sweep_figures"]

#: Heatmaps with more cells than this are not annotated with their values.
MAX_ANNOTATED_CELLS = 144


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


def sweep_figures(sweep: SweepData, table, metrics: Sequence[str], out: FigureWriter) -> list[FigureFile]:
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
    list of FigureFile
        With two varied parameters on a grid (distinct pairs filling at least half of the
        grid) one heatmap per metric (``sweep_<name>_heatmap_<metric>``, failed cells
        hatched); otherwise, for each varied parameter, ``sweep_<name>_<parameter>`` with
        one panel per metric (successful runs as dots coloured by base / variant where
        those vary, failed runs as red crosses on the lower edge). Empty when no parameter
        varies. ``converged`` as a metric gives a map of 1 (converged) and 0, ``settled``
        one of 1 (settled) and 0; their cells and those of ``settling_time`` are labelled
        with how the run ended (``report:rest``: not settled, rest away from equilibrium,
        unstable rest), and in the panels the runs at rest but not settled are marked on
        the lower edge.
    """
    grid = _Grid.of(sweep, table)
    if grid is not None:
        return [_heatmap(sweep, grid, table, name, out) for name in metrics]
    return [_parameter_figure(sweep, table, param, metrics, out) for param in sweep.varied]


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
    from matplotlib.colors import LogNorm  # heavy: matplotlib

    failed = (table["status"].astype(str) != "success").to_numpy()
    rest = name in _REST_METRICS and "report:rest" in table.columns
    grid, bad, present = g.cells(table[metric_column(name)].to_numpy(dtype=float), failed,
                                 table["report:rest"].to_numpy(dtype=object) if rest else None)
    fig, axes = new_figure(1, width=8.0, row_height=5.0)
    ax = axes[0, 0]
    mesh = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis", norm=LogNorm() if _use_log(grid.ravel()) else None)
    if np.isfinite(grid).any():
        fig.colorbar(mesh, ax=ax, label=metric_label(name))
    _annotate_cells(ax, mesh, grid, bad, present, words=name == "settled")
    ax.set_xticks(range(grid.shape[1]), g.labels[0], rotation=30, fontsize=8)
    ax.set_yticks(range(grid.shape[0]), g.labels[1], fontsize=8)
    p1, p2 = g.names
    ax.set_xlabel(p1)
    ax.set_ylabel(p2)
    fig.suptitle(f"sweep {sweep.name}: {metric_label(name)}", fontsize=11)
    return out.save(fig, f"sweep_{safe_filename(sweep.name)}_heatmap_{safe_filename(name)}",
                    f"{sweep.name}: {name} over {p1} and {p2}",
                    f"{metric_label(name)} for each pair of values of {p1} and {p2}; hatched red cells: failed runs; "
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
            r, g, b, _ = mesh.cmap(mesh.norm(grid[i, j]))
            ink = "k" if 0.299 * r + 0.587 * g + 0.114 * b > 0.5 else "w"
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
    if _use_log(y[ok]):
        ax.set_yscale("log")
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
    axes[-1, 0].set_xlabel(param)
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
