"""Report blocks of push recovery and basin stability (``rbstab analyze --push``,
``--basin-stability``, and a sweep spec's curves: :mod:`rbstab.analysis.push`,
:mod:`rbstab.analysis.recovery`).

- a configuration's pushes: the smallest fatal push over the sphere of directions (a map in
  azimuth and elevation), and the ladder of the weakest direction;
- its basin stability: the fraction with its interval, the rule of each key that explains
  the outcome (or that no single key does), and the draws over the two keys whose rules
  separate recovering from failing draws best;
- a spec's curves: the smallest fatal push and the estimate from {v <= c} against each varied key,
  and the basin stability with its interval as a band.

Read from the analysis files by the variable names :mod:`rbstab.analysis.dataset` and
:mod:`rbstab.analysis.recovery` document.
"""

from __future__ import annotations

import json

import numpy as np

from .figures import DPI, FigureFile, FigureWriter
from .load import safe_filename
from .render import Section
from .tables import format_value

__all__ = ["push_blocks", "stability_blocks", "recovery_section"]


def _azimuth_elevation(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth atan2(u_y, u_x) and elevation asin(u_z) [deg] of unit vectors (k, 3)."""
    return np.degrees(np.arctan2(u[:, 1], u[:, 0])), np.degrees(np.arcsin(np.clip(u[:, 2], -1.0, 1.0)))


def _threshold_norm(t: np.ndarray):
    """A log colour scale over the thresholds ``t`` (> 0), clipped at their 95th percentile
    where the largest lies more than ten times above it (one hard direction would otherwise
    take the whole scale)."""
    from matplotlib.colors import LogNorm  # heavy: matplotlib

    if not len(t):
        return LogNorm(1.0, 10.0)
    lo, hi = float(np.min(t)), float(np.max(t))
    top = float(np.percentile(t, 95))
    if hi > 10.0 * top and top > lo:
        hi = top
    return LogNorm(lo, hi if hi > lo else lo * 1.01)


def _sphere_figure(ds, out: FigureWriter, stem: str, name: str) -> FigureFile:
    from matplotlib.figure import Figure  # heavy: matplotlib

    units = ds["push_threshold"].attrs.get("units", "")
    kind = ds.attrs.get("push_kind", "")
    u = ds["push_direction"].values
    t = ds["push_threshold"].values
    monotone = ds["push_monotone"].values.astype(bool)
    az, el = _azimuth_elevation(u)
    finite = np.isfinite(t) & (t > 0)
    fig = Figure(figsize=(7.5, 4.8), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    norm = _threshold_norm(t[finite])
    mesh = ax.scatter(az[finite & monotone], el[finite & monotone], c=t[finite & monotone], cmap="viridis_r",
                      norm=norm, s=40, label="threshold")
    if (finite & ~monotone).any():
        ax.scatter(az[finite & ~monotone], el[finite & ~monotone], c=t[finite & ~monotone], cmap="viridis_r",
                   norm=norm, s=40, marker="D", edgecolors="r", label="not monotone")
    if (~np.isfinite(t)).any():
        ax.scatter(az[~np.isfinite(t)], el[~np.isfinite(t)], facecolors="none", edgecolors="0.5", s=40,
                   label="recovered from every rung")
    if "push_refined_direction" in ds and ds.sizes.get("push_refined", 0):
        ra, re = _azimuth_elevation(ds["push_refined_direction"].values)
        ax.scatter(ra, re, c="k", s=6, label="local search")
    ma, me = _azimuth_elevation(ds["push_minimum_direction"].values[None])
    ax.scatter(ma, me, marker="*", s=220, c="r", edgecolors="k",
               label=f"minimum {format_value(float(ds['push_minimum'].values), 4)} {units}")
    clipped = " (log scale, clipped at the 95th percentile)" if norm.vmax < np.max(t[finite], initial=0) else \
        " (log scale)"
    fig.colorbar(mesh, ax=ax, label=f"smallest fatal {kind} push [{units}]{clipped}",
                 extend="max" if "clipped" in clipped else "neither")
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_xlabel("azimuth [deg]")
    ax.set_ylabel("elevation [deg]")
    ax.grid(alpha=0.3)
    fig.legend(fontsize=7, loc="outside lower center", ncols=5)  # below the axes, off the points
    frame = "inertial frame" if kind == "force" else "body frame"
    fig.suptitle(f"{name}: smallest fatal {kind} push by direction ({frame})", fontsize=10)
    return out.save(fig, f"{stem}_push_sphere", f"{name}: smallest fatal push over the directions",
                    "Each direction of the push at its azimuth and elevation, coloured by its smallest fatal "
                    "magnitude (log scale; where one direction lies far above the rest, clipped at the 95th "
                    "percentile, the colour bar says so); diamonds edged red: recovery was not monotone along the ladder; the star: the "
                    "minimum, after the local search (black dots).")


def _ladder_figure(ds, out: FigureWriter, stem: str, name: str) -> FigureFile:
    from matplotlib.figure import Figure  # heavy: matplotlib

    units = ds["push_threshold"].attrs.get("units", "")
    t = ds["push_threshold"].values
    i = int(np.nanargmin(np.where(np.isfinite(t), t, np.nan))) if np.isfinite(t).any() else 0
    ladder = ds["push_ladder"].values[i]
    recovered = ds["push_ladder_recovered"].values[i].astype(bool)
    fig = Figure(figsize=(7.5, 2.8), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    ax.plot(ladder[recovered], np.ones(recovered.sum()), "o", color="#4daf4a", label="recovered")
    ax.plot(ladder[~recovered], np.zeros((~recovered).sum()), "x", color="#d62728", label="fatal")
    if np.isfinite(t[i]):
        ax.axvline(t[i], color="k", lw=1, label=f"threshold {format_value(float(t[i]), 4)} {units}")
    ax.set_yticks([0, 1], ["fatal", "recovered"])
    ax.set_ylim(-0.5, 1.5)
    ax.set_xlabel(f"push magnitude [{units}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center right")
    u = ds["push_direction"].values[i]
    fig.suptitle(f"{name}: the ladder of the weakest direction ({', '.join(f'{x:+.2f}' for x in u)})", fontsize=10)
    return out.save(fig, f"{stem}_push_ladder", f"{name}: recovery ladder of the weakest direction",
                    "The ladder's rungs along the direction of the smallest threshold; the bisection refines the "
                    "first fatal rung down to the threshold (line).")


def push_blocks(ds, out: FigureWriter, stem: str, name: str) -> list:
    """Facts and figures of a configuration's pushes (none without ``push_threshold``)."""
    if "push_threshold" not in ds:
        return []
    t = ds["push_threshold"].values
    units = ds["push_threshold"].attrs.get("units", "")
    monotone = ds["push_monotone"].values.astype(bool)
    finite = np.isfinite(t)
    facts = [f"smallest fatal {ds.attrs.get('push_kind')} push over {len(t)} directions: "
             f"{format_value(float(ds['push_minimum'].values), 5)} {units} "
             f"(t0 = {ds.attrs.get('push_at')} s, relative tolerance {ds.attrs.get('push_tol')}, "
             f"{ds.attrs.get('push_runs')} runs)",
             f"recovery rule: {ds.attrs.get('push_rule')}"]
    if finite.any():
        facts.append(f"median over the directions {format_value(float(np.median(t[finite])), 4)} {units}, largest "
                     f"{format_value(float(np.max(t[finite])), 4)} {units}")
    if (~monotone).any():
        facts.append(f"recovery not monotone in the magnitude along {int((~monotone).sum())} directions: their "
                     "threshold is the first fatal magnitude seen from below, at the ladder's resolution")
    return [facts, _sphere_figure(ds, out, stem, name), _ladder_figure(ds, out, stem, name)]


def stability_blocks(ds, out: FigureWriter, stem: str, name: str) -> list:
    """Facts and a figure of a configuration's basin stability (none without it)."""
    if "stability_recovered" not in ds:
        return []
    from matplotlib.figure import Figure  # heavy: matplotlib

    from ..analysis.text import rule_lines  # heavy: numba (the rbstab.analysis package)

    recovered = ds["stability_recovered"].values.astype(bool)
    keys = [str(k) for k in ds["stability_key"].values]
    units = [str(u) for u in ds["stability_units"].values]
    values = ds["stability_value"].values
    lo, hi = float(ds["stability_interval_low"].values), float(ds["stability_interval_high"].values)
    facts = [f"basin stability: {int(recovered.sum())} of {len(recovered)} draws recovered = "
             f"{float(ds['stability_fraction'].values):.1%} ({ds.attrs.get('stability_confidence', 0.95):.0%} Wilson "
             f"interval {lo:.1%} - {hi:.1%})", f"rule: {ds.attrs.get('stability_rule')}"]
    rules = _stability_rules(ds, keys)
    facts += [line.strip() for line in rule_lines([(k, r) for k, r in zip(keys, rules) if r is not None],
                                                 float(ds.attrs.get("stability_explains_bar", np.nan)))]
    accuracy = np.array([r.balanced_accuracy if r is not None else 0.5 for r in rules])
    order = np.argsort(-accuracy, kind="stable")[:2]
    fig = Figure(figsize=(6.0, 4.2), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    x = values[:, order[0]]
    y = values[:, order[1]] if len(order) > 1 else np.zeros(len(x))
    for flag, colour, marker, label in ((True, "#4daf4a", "o", "recovered"), (False, "#d62728", "x", "failed")):
        pick = recovered == flag
        ax.plot(x[pick], y[pick], marker, color=colour, ms=3, ls="none", label=f"{label} ({int(pick.sum())})")
    for line, i in ((ax.axvline, order[0]), (ax.axhline, order[1] if len(order) > 1 else None)):
        if i is not None and rules[i] is not None and rules[i].explains:  # a rule that explains, drawn
            for threshold in (rules[i].low, rules[i].high):
                if np.isfinite(threshold):
                    line(threshold, color="0.3", ls="--", lw=0.8)
    ax.set_xlabel(f"{keys[order[0]]} [{units[order[0]]}]")
    if len(order) > 1:
        ax.set_ylabel(f"{keys[order[1]]} [{units[order[1]]}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle(f"{name}: basin stability {float(ds['stability_fraction'].values):.1%} ({lo:.1%} - {hi:.1%})",
                 fontsize=10)
    figure = out.save(fig, f"{stem}_stability", f"{name}: basin stability draws",
                      "The random draws over the two keys whose rules separate recovering from failing draws "
                      "best (balanced accuracy); dashed: the thresholds of a rule that explains the outcome.")
    return [facts, figure]


def _stability_rules(ds, keys: list) -> list:
    """Per key, its rule (:class:`rbstab.analysis.thresholds.SplitRule`) as the file holds it,
    None where its draws all recovered or all failed, or the file has no rules (written before
    they were)."""
    from ..analysis.thresholds import SplitRule  # heavy: numba (the rbstab.analysis package)

    if "stability_recovered_side" not in ds:
        return [None] * len(keys)
    sides = [str(v) for v in ds["stability_recovered_side"].values]
    return [SplitRule(side, float(ds["stability_threshold_low"].values[i]),
                      float(ds["stability_threshold_high"].values[i]),
                      float(ds["stability_balanced_accuracy"].values[i]), bool(ds["stability_explains"].values[i]))
            if side else None for i, side in enumerate(sides)]


def _numeric_keys(ds) -> list[str]:
    skip = {"run_id", "axis"}
    return [k for k in ds.coords if k not in skip and ds[k].dims == ("point",) and ds[k].dtype.kind in "fiu"
            and np.unique(ds[k].values).size > 1]


def recovery_section(ds, path, out: FigureWriter) -> Section:
    """The section of a spec's curves file (``kind = "recovery"``)."""
    from matplotlib.figure import Figure  # heavy: matplotlib

    name = str(ds.attrs.get("name", path.name))
    s = Section(f"Push recovery across parameters: {name}", f"recovery-{safe_filename(name)}")
    options = json.loads(ds.attrs.get("options", "{}"))
    s.blocks.append(f"From {path}: {ds.sizes.get('point', 0)} configurations. Method: docs/push.md.")
    keys = _numeric_keys(ds) or [None]
    has_push, has_stability = "push_minimum" in ds, "stability_fraction" in ds
    rows = int(has_push) + int(has_stability)
    fig = Figure(figsize=(4.6 * len(keys), 3.4 * rows), dpi=DPI, layout="constrained")
    axes = np.atleast_2d(fig.subplots(rows, len(keys), squeeze=False))
    for j, key in enumerate(keys):
        x = ds[key].values if key else np.arange(ds.sizes["point"])
        order = np.argsort(x, kind="stable")
        label = key if key else "configuration"
        row = 0
        if has_push:
            ax = axes[row, j]
            units = ds["push_minimum"].attrs.get("units", "")
            fatal = ds["push_minimum"].values[order]
            ax.plot(x[order], fatal, "o-", label="smallest fatal push (simulated)")
            estimate = ds["push_estimate"] if "push_estimate" in ds else ds.get("push_certified")
            if estimate is not None:  # an estimate, never drawn above a simulated threshold
                below = np.fmin(estimate.values[order], fatal)
                ax.plot(x[order], below, ":", color="0.4", marker="v", ms=4,
                        label="estimate from {v <= c}: sqrt(c / dT), min")
                ax.fill_between(x[order], 0, below, color="0.6", alpha=0.15, lw=0)
            if "push_verified" in ds:  # a proven bound: drawn as it is (a proof lies below every threshold)
                ax.plot(x[order], ds["push_verified"].values[order], "-", color="k", marker="_", ms=8, lw=1.2,
                        drawstyle="steps-mid", label="verified bound from {v <= c}: sqrt(c / dT), min")
            ax.set_ylabel(f"push [{units}]")
            ax.set_xlabel(label)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncols=2)  # off the curves
            row += 1
        if has_stability:
            ax = axes[row, j]
            frac = ds["stability_fraction"].values[order]
            ax.fill_between(x[order], ds["stability_interval_low"].values[order],
                            ds["stability_interval_high"].values[order], alpha=0.3, label="Wilson interval")
            ax.plot(x[order], frac, "o-", label="basin stability")
            inside = ds["stability_inside"].values[order]
            with np.errstate(invalid="ignore", divide="ignore"):
                share = ds["stability_inside_recovered"].values[order] / inside
            ax.plot(x[order], np.where(inside > 0, share, np.nan), "s--",
                    label="recovered among draws inside {v <= c}")
            ax.set_ylim(-0.02, 1.02)
            ax.set_ylabel("fraction recovered")
            ax.set_xlabel(label)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncols=2)  # off the curves
    fig.suptitle(f"{name}: push recovery across parameters", fontsize=10)
    s.blocks.append(out.save(fig, f"recovery_{safe_filename(name)}", f"{name}: curves across parameters",
                             "Against each varied key: the smallest fatal push over the directions (simulated) and "
                             "the estimate from the sublevel set {v <= c} (dotted, shaded below: every push of "
                             "energy dT <= c; c sampled, refined by local search and checked against every run of "
                             "the point, so below each simulated threshold; an estimate, not a proof); the basin "
                             "stability with its Wilson interval as a band, and the fraction of draws inside "
                             "{v <= c} that recovered."
                             + (" Black steps: the bound from the verified set {v <= c} (interval arithmetic, "
                                "--verify): a proof, below every simulated threshold." if "push_verified" in ds
                                else "")))
    facts = []
    if has_push:
        t = ds["push_minimum"].values
        facts.append(f"smallest fatal push from {format_value(float(np.nanmin(t)), 4)} to "
                     f"{format_value(float(np.nanmax(t)), 4)} {ds['push_minimum'].attrs.get('units', '')}")
        if "push_verified" in ds:
            above = int(np.sum(ds["push_verified"].values > t))
            facts.append(f"verified bound from {format_value(float(np.nanmin(ds['push_verified'].values)), 4)} to "
                         f"{format_value(float(np.nanmax(ds['push_verified'].values)), 4)}"
                         + (f"; ABOVE the simulated threshold at {above} points: a contradiction to report"
                            if above else ", below the simulated threshold at every point"))
    if has_stability:
        f = ds["stability_fraction"].values
        facts.append(f"basin stability from {np.nanmin(f):.1%} to {np.nanmax(f):.1%}")
    if options:
        facts.append("options: " + ", ".join(f"{k} {v}" for k, v in options.items() if v not in (None, {}, [])
                                             and not isinstance(v, dict)))
    if facts:
        s.blocks.append(facts)
    if ds.sizes.get("point") and not np.isfinite(ds["sublevel"].values).any():
        s.blocks.append(["no certificate (--no-certificate): the estimate curves are empty"])
    return s
