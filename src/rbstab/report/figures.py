"""Figures of a report (matplotlib, Agg canvas: no display needed, no pyplot state).

Per run, the figures of the paper (Figs 3-7) and more: rotational states Theta, Omega;
translational states X, V (and D for ``embedded``) with the constraint error E; the
Lyapunov function v with its terms (log scale) and its analytic and numerical rates; the
forces Lambda, H and the torque N; phase portraits (E_i against F_i, Theta_i against
Omega_i). For several runs the same quantities overlaid, one colour per run, and the
norms |E|, |Omega| against the settling thresholds. Sweep plots:
:mod:`rbstab.report.sweep_figures`.

Every figure is written by a :class:`FigureWriter` (formats PNG, PDF, SVG; resolution)
and described by a :class:`FigureFile` (files, title, caption). The words, symbols and
units on the axes come from the table of quantities (:data:`rbstab.layout.QUANTITIES`). A quantity that spans more than two
decades is drawn on a logarithmic axis (symmetric-logarithmic when it changes sign),
:func:`set_scale`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..layout import LYAPUNOV_TERMS, QUANTITIES, SATURATION_FLAGS, display_units
from .load import RunData, safe_filename
from .tables import SettleThresholds, run_rate_check_reason

__all__ = [
    "FigureFile",
    "FigureWriter",
    "FIGURE_FORMATS",
    "DPI",
    "run_figures",
    "RUN_FIGURES",
    "switching_figure",
    "lyapunov_figure",
    "control_limits",
    "has_limits",
    "disturbance_marks",
    "saturated_intervals",
    "shade_saturation",
    "comparison_figures",
    "set_scale",
    "value_scale",
    "colour_norm",
    "linear_threshold",
]

#: Default resolution of the raster (PNG) files [dots per inch].
DPI = 110
#: Figure file formats (``--figure-format``); the page shows PNG, or SVG when only it is asked.
FIGURE_FORMATS = ("png", "pdf", "svg")
#: A quantity is drawn on a logarithmic axis when its largest magnitude is more than this
#: times the magnitude a quarter of its samples stay under (it spans more than two decades).
LOG_SPAN = 100.0

_LINESTYLES = ("-", "--", ":")
#: Line styles of a chain's bodies or joints on the overlays of several runs, one a member
#: (as many as a tree has bodies at most).
_MEMBER_STYLES = ("-", "--", ":", "-.", (0, (5, 1)), (0, (3, 1, 1, 1)), (0, (1, 1)), (0, (5, 3, 1, 3, 1, 3)))
#: A constraint error below this [m] is drawn on a +-1 mm axis and labelled round-off.
ROUND_OFF_E = 1e-9


@dataclass(frozen=True)
class FigureFile:
    """One figure of the report.

    Attributes
    ----------
    path : str
        The file the page shows, relative to the report folder (``figures/<name>.png``).
    title : str
        Short title (HTML/markdown heading and alt text).
    caption : str
        What the figure shows, one or two sentences.
    files : tuple of str
        Every file of the figure, one per format asked (``figures/<name>.pdf`` ...).
    """

    path: str
    title: str
    caption: str
    files: tuple[str, ...] = ()


@dataclass(frozen=True)
class FigureWriter:
    """Where and how the figures of a report are written.

    Attributes
    ----------
    folder : Path
        Report folder; files go to ``folder/figures/`` (which must exist).
    formats : tuple of str
        Of :data:`FIGURE_FORMATS`. The page shows the PNG (or the SVG when SVG but not
        PNG is asked); with PDF alone a PNG is written for the page as well.
    dpi : int
        Resolution of the PNG files [dots per inch]; PDF and SVG are vector files.
    """

    folder: Path
    formats: tuple[str, ...] = ("png",)
    dpi: int = DPI

    @property
    def page_format(self) -> str:
        """Format of the file the page shows."""
        return "svg" if "svg" in self.formats and "png" not in self.formats else "png"

    def save(self, fig, name: str, title: str, caption: str) -> FigureFile:
        """Write ``fig`` as ``figures/<name>.<format>`` in every format; its record."""
        formats = list(dict.fromkeys([*self.formats, self.page_format]))
        files = tuple(f"figures/{name}.{fmt}" for fmt in formats)
        for rel, fmt in zip(files, formats):
            self._savefig(fig, self.folder / rel, fmt)
        return FigureFile(f"figures/{name}.{self.page_format}", title, caption,
                          tuple(f for f, fmt in zip(files, formats) if fmt in self.formats))

    def _savefig(self, fig, path: Path, fmt: str) -> None:
        meta = {"Software": f"rbstab {__version__}"} if fmt == "png" else {"Creator": f"rbstab {__version__}"}
        if fmt == "pdf":
            meta["CreationDate"] = None  # the same figure gives the same bytes
        try:
            fig.savefig(path, format=fmt, dpi=self.dpi, metadata=meta)
        except ValueError:  # a text from the data (a run's name with '$') that is not valid mathtext
            _plain_texts(fig)
            fig.savefig(path, format=fmt, dpi=self.dpi, metadata=meta)


def _plain_texts(fig) -> None:
    """Show every text of ``fig`` that mathtext cannot parse as it is written."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # heavy: matplotlib
    from matplotlib.text import Text  # heavy: matplotlib

    renderer = FigureCanvasAgg(fig).get_renderer()
    for text in fig.findobj(Text):
        try:
            text.get_window_extent(renderer)
        except ValueError:
            text.set_parse_math(False)


# -- helpers ----------------------------------------------------------------------------------------

#: CF units (``rad s-1``) as they read on an axis (``rad/s``): :func:`rbstab.layout.display_units`.
units_text = display_units


def _symbol(var: str, component: int | None = None) -> str:
    """Mathtext symbol of quantity ``var`` (:data:`rbstab.layout.QUANTITIES`) or of its component."""
    q = QUANTITIES[var]
    if component is None:
        return q.tex
    tex = q.component_tex or q.tex
    return f"({tex})_{component + 1}" if "_" in tex else f"{tex}_{component + 1}"  # (\Theta_j)_1: one subscript each


def _label(var: str, component: int | None = None) -> str:
    """Axis label of quantity ``var``: words, symbol and units, e.g. ``"time $t$ [s]"``."""
    return f"{QUANTITIES[var].words} ${_symbol(var, component)}$ [{QUANTITIES[var].display_units}]"


def new_figure(rows: int, cols: int = 1, width: float = 9.0, row_height: float = 2.4, sharex: bool = True):
    """A constrained-layout figure and its (rows, cols) array of axes."""
    from matplotlib.figure import Figure  # heavy: matplotlib

    fig = Figure(figsize=(width, row_height * rows + 0.6), dpi=DPI, layout="constrained")
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    return fig, axes


def colours(n: int) -> list:
    """``n`` distinguishable colours (tab10, tab20, then viridis)."""
    from matplotlib import colormaps  # heavy: matplotlib

    if n <= 10:
        return [colormaps["tab10"](i) for i in range(n)]
    if n <= 20:
        return [colormaps["tab20"](i) for i in range(n)]
    return [colormaps["viridis"](x) for x in np.linspace(0, 0.95, n)]


def value_scale(values) -> str:
    """The scale that shows ``values``: ``"log"`` or ``"symlog"`` where they span decades,
    else ``"linear"``.

    A quantity spans decades when its largest magnitude is more than :data:`LOG_SPAN`
    times the first quartile of its non-zero magnitudes. Then ``"log"`` when no value is
    negative (zeros are not drawn), else ``"symlog"`` (signs mixed: linear near zero,
    :func:`linear_threshold`). NaN and infinite values are left out.
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    magnitude = np.abs(v)
    base = magnitude[magnitude > 0]  # a component that stays zero (an axis nothing acts on) spans nothing
    if base.size < 2 or base.max() <= LOG_SPAN * float(np.percentile(base, 25)):
        return "linear"
    return "symlog" if np.any(v < 0) else "log"


def set_scale(ax, values, axis: str = "y") -> str:
    """Put ``ax``'s ``axis`` on the scale :func:`value_scale` gives ``values``: a
    logarithmic one, a symmetric-log one (:func:`_symlog`), or as it is (``"linear"``).
    Returns the scale."""
    scale = value_scale(values)
    if scale == "log":
        (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    elif scale == "symlog":
        v = np.asarray(values, dtype=float).ravel()
        _symlog(ax, v[np.isfinite(v)], axis)
    return scale


def colour_norm(values):
    """The colour scale of a map of ``values`` (:func:`value_scale`): None (linear), a
    ``LogNorm`` from the smallest positive value to the largest, or a ``SymLogNorm``
    symmetric about zero (linear within :func:`linear_threshold`), for a diverging map."""
    from matplotlib.colors import LogNorm, SymLogNorm  # heavy: matplotlib

    scale = value_scale(values)
    if scale == "linear":
        return None
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if scale == "log":
        return LogNorm(vmin=float(v[v > 0].min()), vmax=float(v.max()))
    peak = float(np.abs(v).max())
    return SymLogNorm(linthresh=linear_threshold(v), linscale=0.5, vmin=-peak, vmax=peak)


def linear_threshold(values: np.ndarray) -> float:
    """Where a symmetric-log scale of finite ``values`` turns linear: the power of ten at or
    below the 5th percentile of their magnitudes (at least 1e-6 of the peak)."""
    magnitude = np.abs(values)
    peak = float(magnitude.max())
    return 10.0 ** math.floor(math.log10(max(float(np.percentile(magnitude, 5)), 1e-6 * peak)))


def _symlog(ax, values: np.ndarray, axis: str) -> None:
    """Symmetric-log scale: linear within :func:`linear_threshold`; labelled at 0 and at
    powers of ten inside the values' range, at most 5 decades each side."""
    magnitude = np.abs(values)
    peak = float(magnitude.max())
    low = round(math.log10(linear_threshold(values)))
    top = math.floor(math.log10(peak))
    decades = list(range(top, low, -max(1, math.ceil((top - low) / 5))))
    ticks = [-(10.0 ** k) for k in decades if -(10.0 ** k) >= values.min()] + [0.0]
    ticks += [10.0 ** k for k in reversed(decades) if 10.0 ** k <= values.max()]
    target = ax.yaxis if axis == "y" else ax.xaxis
    (ax.set_yscale if axis == "y" else ax.set_xscale)("symlog", linthresh=10.0 ** low, linscale=0.5)
    ax.autoscale_view()  # margins in the new scale, before the ticks fix the view
    target.set_ticks(ticks)
    target.set_minor_locator(_no_ticks())


def _no_ticks():
    from matplotlib.ticker import NullLocator  # heavy: matplotlib

    return NullLocator()


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


def _status(run: RunData) -> str:
    return "" if run.ok else f" - FAILED (last sample t = {run.summary.get('t_final', float('nan')):.4g} s)"


def _suptitle(fig, run: RunData, what: str) -> None:
    fig.suptitle(f"{run.label} ({run.variant}): {what}{_status(run)}", fontsize=11)


def disturbance_marks(run: RunData) -> list[tuple[str, float, float]]:
    """Where the run's disturbances (its config's ``disturbances``) act on the time axis:
    (kind, t0, t1) [s] each, t1 = t0 for an impulse, the pulse's end, t_end for the kinds
    that act from ``start`` on (step, sine, noise)."""
    t_end = float(run.config.get("simulation", {}).get("t_end", np.nan))
    marks = []
    for d in run.config.get("disturbances") or ():
        start = float(d.get("start", 0.0))
        end = {"impulse": start, "pulse": start + float(d.get("duration") or 0.0)}.get(d.get("kind"), t_end)
        marks.append((str(d.get("kind")), start, end))
    return marks


#: Grey of the disturbances' marks on the time axes.
_DISTURBANCE_GREY = "0.35"


def _mark_disturbances(ax, run: RunData) -> None:
    """Each disturbance on a time axis: an impulse a dash-dotted line at its time, a pulse a
    grey span over its window, a step, sine or noise a dashed line where it starts (it acts
    from there on). The artists' gid is ``disturbance-<kind>``."""
    for kind, t0, t1 in disturbance_marks(run):
        if kind == "pulse":
            ax.axvspan(t0, t1, color=_DISTURBANCE_GREY, alpha=0.18, lw=0, gid=f"disturbance-{kind}")
        else:
            ax.axvline(t0, color=_DISTURBANCE_GREY, lw=0.9, ls="-." if kind == "impulse" else "--",
                       gid=f"disturbance-{kind}")


def _finish_time_axes(axes, run: RunData, legend: bool = True, **legend_kw) -> None:
    """Grid, legend above each panel (off its data; the figure's title names the run),
    failure and disturbance marks and the time label of a column of panels."""
    for ax in axes:
        if legend:
            ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), borderaxespad=0.1, frameon=False, fontsize=8,
                      handlelength=2.4, columnspacing=1.2, **legend_kw)
        ax.grid(alpha=0.3, which="both")
        _mark_failure(ax, run)
        _mark_disturbances(ax, run)
    axes[-1].set_xlabel(_label("time"))


def saturated_intervals(time: np.ndarray, flags: np.ndarray) -> list[tuple[float, float]]:
    """The intervals [t0, t1] [s] of consecutive samples whose flag is 1 (a control's axis at
    its limit, :data:`rbstab.layout.SATURATION_FLAGS`), each widened by half a sample spacing
    on either side (within the samples' span), so that a single flagged sample shows."""
    on = np.asarray(flags) == 1.0
    if not on.any():
        return []
    half = 0.5 * (time[-1] - time[0]) / max(len(time) - 1, 1)
    edges = np.diff(np.r_[0, on.astype(np.int8), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return [(max(float(time[a]) - half, float(time[0])), min(float(time[b]) + half, float(time[-1])))
            for a, b in zip(starts, ends)]


def shade_saturation(ax, run: RunData, control: str, member: int | None = None) -> None:
    """Shade, in each component's colour, where that axis of ``control`` is at its limit
    (the file's ``<control>_saturated`` flags, of body or joint ``member`` of a chain's file;
    nothing for a file without them). The spans' gid is ``saturated-<control>-<component>``."""
    flags = SATURATION_FLAGS[control][0]
    s = run.series(flags)
    if flags not in s:
        return
    values = s[flags] if member is None else s[flags][:, member]
    for k in range(3):
        for t0, t1 in saturated_intervals(s["time"], values[:, k]):
            ax.axvspan(t0, t1, color=f"C{k}", alpha=0.12, lw=0, gid=f"saturated-{control}-{k + 1}")


def _vector_figure(run: RunData, names: Sequence[str], scale: bool = False, from_start: Sequence[str] = ()):
    """A figure of each 3-vector of ``names`` in a row of panels, components as solid,
    dashed, dotted lines: one body's in one column, a chain's a column per body or joint (a
    body's quantity in its body's column, a joint's in its joint's: joint i's child is body
    i), each panel named by its member; saturated axes shaded (:func:`shade_saturation`)
    and the limits near the values dotted (:func:`_draw_limits`); the quantities of
    ``from_start`` drawn as their change since the first sample, q - q(0), q(0) written
    under the axis label. Returns (the figure, its axes (rows, columns), the series)."""
    s = run.series(*names)
    members = run.members
    n = 1 if members is None else len(members["body"])
    fig, axes = new_figure(len(names), n, width=9.0 if n == 1 else 4.2 * n)
    for row, var in enumerate(names):
        for col in range(n):
            ax = axes[row, col]
            values = s[var] if members is None else s[var][:, col]
            name = None if members is None else members[QUANTITIES[var].member][col]
            label = _label(var)
            if var in from_start and len(values):  # q - q(0), and q(0) under the label
                start = values[0].copy()
                values = values - start
                q = QUANTITIES[var]
                label = (f"{q.words} change ${q.tex} - {q.tex}(0)$ [{q.display_units}]\n"
                         f"${q.tex}(0)$ = [{', '.join(f'{v:.3g}' for v in start)}]")
            for k in range(3):
                ax.plot(s["time"], values[:, k], ls=_LINESTYLES[k], marker=_marker(values), label=f"${_symbol(var, k)}$")
            who = "" if name is None else f"{name}\n"
            ax.set_ylabel(who + label, fontsize=9 if members is None else 8)
            drawn = _draw_limits(ax, values, control_limits(run, var, name)) if var in SATURATION_FLAGS else []
            if scale:
                set_scale(ax, np.concatenate([np.ravel(values), drawn]))  # the ticks reach the limits drawn
            if var in SATURATION_FLAGS:
                shade_saturation(ax, run, var, None if members is None else col)
    for col in range(n):
        _finish_time_axes(axes[:, col], run, ncols=3)
    return fig, axes, s


def control_limits(run: RunData, control: str, name: str | None = None) -> np.ndarray | None:
    """The limit of each axis of ``control`` (``torque_n`` [N m], ``force_h`` [N],
    ``constraint_force`` [N]) that the run's configuration sets, shape (3,), inf where an
    axis has none; None without a limit. One body's ``controller.saturation``; a chain's
    joint (N_j, Lambda_j) or body (H) named ``name``."""
    config = run.config
    if run.members is not None:
        section = "bodies" if control == "force_h" else "joints"
        owner = next((m for m in config.get(section) or () if isinstance(m, dict) and m.get("name") == name), {})
        saturation = owner.get("saturation")
    else:
        saturation = (config.get("controller") or {}).get("saturation")
    value = (saturation or {}).get(control)
    if value is None:
        return None
    limits = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    return limits if np.isfinite(limits).any() else None


#: A limit is drawn on a control's panel where the control reaches this fraction of it.
LIMIT_DRAWN_FROM = 0.5


def _draw_limits(ax, values: np.ndarray, limits: np.ndarray | None) -> list[float]:
    """The actuator's limits +-L_i of a control's panel, dotted in each component's colour,
    for the axes whose values reach :data:`LIMIT_DRAWN_FROM` of theirs (a limit far beyond
    the values would only flatten them); returns the values drawn. The lines' gid is
    ``limit-<component>``."""
    drawn = []
    for k in range(3 if limits is not None else 0):
        peak = np.nanmax(np.abs(values[:, k]), initial=0.0)
        if np.isfinite(limits[k]) and peak >= LIMIT_DRAWN_FROM * limits[k]:
            for sign in (1.0, -1.0):
                ax.axhline(sign * limits[k], color=f"C{k}", ls=(0, (1, 2)), lw=1.1, gid=f"limit-{k + 1}")
                drawn.append(sign * float(limits[k]))
    return drawn


def has_limits(run: RunData) -> bool:
    """Whether the run's configuration limits a control (one body's controller, or a chain's
    joints and bodies)."""
    config = run.config
    return bool((config.get("controller") or {}).get("saturation")
                or any(m.get("saturation") for m in [*(config.get("joints") or ()), *(config.get("bodies") or ())]))


# -- per run ----------------------------------------------------------------------------------------

def run_figures(run: RunData, out: FigureWriter) -> list[FigureFile]:
    """The figures of one run.

    Returns
    -------
    list of FigureFile
        ``<label>_rotational`` (Theta [rad], Omega [rad/s] against t [s]; cf. the paper's
        Figs 3, 4, 6), ``<label>_translational`` (X [m], V [m/s], D [m] for ``embedded``,
        E [m]; Figs 5, 7), ``<label>_lyapunov`` (v [J] and its terms, log scale; analytic
        and numerical dv/dt [W]; their difference [W]), ``<label>_forces`` (Lambda [N],
        H [N], N [N m]), for a tree on the ground ``<label>_balance`` (:func:`_balance_figure`:
        the centre of mass and the centres of pressure [m], the ground's push [N]),
        ``<label>_phase`` (E_i against F_i, Theta_i against Omega_i) and,
        for a run of the pure sign law, ``<label>_switching`` (:func:`switching_figure`).
        A figure whose variables the file does not hold (a thinned store) is left out.
    """
    return [f for f in (make(run, out) for make in RUN_FIGURES) if f is not None]


def _rotational_figure(run: RunData, out: FigureWriter) -> FigureFile:
    chain = run.members is not None
    fig, _, _ = _vector_figure(run, ("theta", "omega", "joint_theta") if chain else ("theta", "omega"))
    _suptitle(fig, run, "rotational states")
    return out.save(fig, f"{safe_filename(run.label)}_rotational", f"{run.label}: rotational states",
                    "Euler angles Theta and body angular velocity Omega against time (cf. the paper's Figs 3, 4, 6)"
                    + (", a column a body, and each joint's relative orientation Theta_j (the Euler angles of "
                       "A_parent' A_child), a column a joint" if chain else "")
                    + _marks_caption(run) + ".")


def _translational_figure(run: RunData, out: FigureWriter) -> FigureFile:
    names = ["position", "velocity", "controller_state", "constraint_error"]
    held = run.series(*names)
    names = [n for n in names if n in held and (n != "controller_state" or np.isfinite(held[n]).any())]
    chain = run.members is not None
    # a chain's centre-of-mass positions as their change since t = 0: centimetres of sway, not a metre of height
    fig, axes, s = _vector_figure(run, names, from_start=("position",) if chain else ())
    e = s["constraint_error"]
    for col in range(axes.shape[1]):
        column = e if e.ndim == 2 else e[:, col]
        peak = float(np.nanmax(np.abs(column))) if np.isfinite(column).any() else np.nan
        if peak <= ROUND_OFF_E:  # E is zero up to round-off (permanent): a physical scale, said so
            axes[-1, col].set_ylim(-1e-3, 1e-3)
            axes[-1, col].text(0.02, 0.1, f"max |E| = {peak:.2g} m: zero to round-off (axis +-1 mm)",
                               transform=axes[-1, col].transAxes, fontsize=8, color="0.3")
    _suptitle(fig, run, "translational states and constraint error")
    extra = " (X, V reconstructed from Theta, Omega: C is fixed, E = 0)" if run.variant == "permanent" else ""
    if chain:
        extra = (", a column a body and its joint (E_j = X_c + A_c R_c - X_p - A_p R_p; a permanent joint's zero to "
                 "round-off, since reduced coordinates hold it)")
    return out.save(fig, f"{safe_filename(run.label)}_translational", f"{run.label}: translational states and constraint",
                    ("Each body's centre-of-mass displacement X - X(0) (X(0) under the axis label) and velocity V "
                     if chain else "Centre-of-mass position X and velocity V ") + "(inertial frame), "
                    + ("controller state D, " if "controller_state" in names else "")
                    + f"and the constraint error E = X + A R - R against time (cf. the paper's Figs 5, 7){extra}"
                    + _marks_caption(run) + ".")


def _lyapunov_terms_panel(ax, run: RunData) -> None:
    """v (black) and its non-zero terms (eq 25) on a log axis; a term that takes negative
    values (gravity) is drawn as its magnitude, labelled |v_g|."""
    s = run.series("lyapunov", *LYAPUNOV_TERMS)
    t = s["time"]
    drawn = [s["lyapunov"]]
    ax.plot(t, s["lyapunov"], color="k", lw=1.8, marker=_marker(s["lyapunov"]), label=f"${_symbol('lyapunov')}$")
    for i, name in enumerate(n for n in LYAPUNOV_TERMS if n in s):
        if not np.nanmax(np.abs(s[name]), initial=0.0) > 0:
            continue
        term, label = s[name], f"${_symbol(name)}$ {QUANTITIES[name].words}"
        if np.nanmin(term) < 0:
            term, label = np.abs(term), f"$|{_symbol(name)}|$ {QUANTITIES[name].words} (changes sign)"
        ax.plot(t, term, color=f"C{i}", lw=1.0, ls=_LINESTYLES[i % 3], label=label)
        drawn.append(term)
    values = np.concatenate(drawn)
    values = values[np.isfinite(values)]
    if values.size and values.min() >= 0 and values.max() > 0:
        ax.set_yscale("log")  # v >= 0: always on a log axis (zeros are not drawn)
    else:
        set_scale(ax, values)
    ax.set_ylabel(_label("lyapunov"), fontsize=9)


def _work_panel(ax, run: RunData) -> None:
    """v beside v - W and the disturbances' work W (linear axis): with unsaturated gains
    v - W never rises (docs/disturbances.md)."""
    s = run.series("lyapunov", "disturbance_work")
    t, v, w = s["time"], s["lyapunov"], s["disturbance_work"]
    ax.plot(t, v, color="k", lw=1.6, label=f"${_symbol('lyapunov')}$")
    ax.plot(t, v - w, color="C1", lw=1.4, ls="--", label=f"${_symbol('lyapunov')} - {_symbol('disturbance_work')}$",
            gid="lyapunov-minus-work")
    ax.plot(t, w, color="C2", lw=1.0, ls=":", label=f"${_symbol('disturbance_work')}$ {QUANTITIES['disturbance_work'].words}")
    ax.set_ylabel(f"$v$, $v - W$, $W$ [{QUANTITIES['lyapunov'].display_units}]", fontsize=9)


def _disturbed(run: RunData) -> bool:
    """Whether the run has disturbances and its file their work (not a thinned store)."""
    return bool(run.config.get("disturbances")) and "disturbance_work" in run.series("disturbance_work")


def lyapunov_figure(run: RunData, out: FigureWriter) -> FigureFile:
    """``<label>_lyapunov`` of one body's or a chain's run (:func:`run_figures`)."""
    s = run.series("lyapunov_rate", "lyapunov_rate_numerical")
    t = s["time"]
    work = _disturbed(run)
    fig, axes = new_figure(3 + work, row_height=2.6)
    _lyapunov_terms_panel(axes[0, 0], run)
    if work:
        _work_panel(axes[1, 0], run)
    rate, diff = axes[1 + work, 0], axes[2 + work, 0]
    rate.plot(t, s["lyapunov_rate"], color="C0", lw=2.2, alpha=0.6, marker=_marker(s["lyapunov_rate"]),
              label=r"$\dot v$ analytic")
    if "lyapunov_rate_numerical" in s:
        rate.plot(t, s["lyapunov_rate_numerical"], color="C3", ls="--", lw=1.0,
                  marker=_marker(s["lyapunov_rate_numerical"]), label=r"$\dot v$ numerical")
        diff.plot(t, s["lyapunov_rate"] - s["lyapunov_rate_numerical"], color="C3", lw=0.9,
                  label=r"$\dot v_{analytic} - \dot v_{numerical}$")
    set_scale(rate, s["lyapunov_rate"])
    rate.set_ylabel(_label("lyapunov_rate"), fontsize=9)
    diff.set_ylabel(rf"analytic $-$ numerical [{QUANTITIES['lyapunov_rate'].display_units}]", fontsize=9)
    _finish_time_axes(axes[:, 0], run, ncols=2)
    _suptitle(fig, run, f"Lyapunov function and its rate (check: {run.summary.get('lyapunov_rate_check', '?')})")
    terms = "translational, rotational, constraint controller, gravity" + (
        ", each summed over the bodies and joints" if run.members is not None else "")
    return out.save(fig, f"{safe_filename(run.label)}_lyapunov", f"{run.label}: Lyapunov function",
                    f"v and its non-zero terms ({terms}; "
                    "logarithmic axis, a term that changes sign as its magnitude), "
                    + ("v beside v - W, W the work of the disturbances (with unsaturated gains v - W never rises), "
                       if work else "")
                    + "its analytic rate dv/dt (solid) and the numerical derivative of v along "
                    "the samples (dashed; symmetric-logarithmic axis where it spans decades), and their difference "
                    "(cf. the paper's Figs 3, 4, 6)" + _marks_caption(run) + _rate_check_caption(run) + ".")


def _rate_check_caption(run: RunData) -> str:
    """``"; rate check fail: <why>"`` (:func:`rbstab.report.tables.run_rate_check_reason`), or ``""``."""
    reason = run_rate_check_reason(run)
    return f"; rate check fail: {reason}" if reason else ""


def _forces_figure(run: RunData, out: FigureWriter) -> FigureFile | None:
    held = run.series("constraint_force", "force_h", "torque_n")
    names = [n for n in ("constraint_force", "force_h", "torque_n") if n in held]  # a thinned chain store: Lambda, N
    unused = [n for n in names if n != "constraint_force" and not np.nanmax(np.abs(held[n]), initial=0.0) > 0.0]
    names = [n for n in names if n not in unused]  # a feedback the run does not have (a chain's H without K_t, L_t)
    if not names:
        return None
    fig, _, _ = _vector_figure(run, names, scale=True)
    _suptitle(fig, run, "constraint force and feedback")
    chain = run.members is not None
    words = {"constraint_force": "the constraint force Lambda at C (inertial frame, eqs 20-22, 39, 40)",
             "force_h": "the translational feedback H (inertial frame, eq 24)",
             "torque_n": "the rotational feedback torque N (body frame, eq 23)"}
    drawn = [words[n] for n in names]
    listed = ", ".join(drawn[:-1]) + " and " + drawn[-1] if len(drawn) > 1 else drawn[0]
    return out.save(fig, f"{safe_filename(run.label)}_forces", f"{run.label}: forces and torque",
                    listed[0].upper() + listed[1:] + " against time, as delivered"
                    + ("; a column a body and its joint (Lambda_j on the child at C, N_j on the relative motion, "
                       "child frame)" if chain else "")
                    + "; a symmetric-logarithmic axis where a quantity spans more than two decades"
                    + ("; shaded in a component's colour where that axis is commanded at or beyond its limit "
                       "(saturation; clip delivers the limit there), the limit dotted where the control reaches "
                       "half of it" if has_limits(run) else "")
                    + "".join(f"; {QUANTITIES[n].symbol} is zero throughout (no such feedback): not drawn" for n in unused)
                    + _marks_caption(run) + ".")


def _marks_caption(run: RunData) -> str:
    """The caption's words for the disturbances' marks (empty without disturbances)."""
    if not run.config.get("disturbances"):
        return ""
    return ("; disturbances in grey: an impulse dash-dotted at its time, a pulse shaded over its window, "
            "a step, sine or noise dashed where it starts")


def _phase_row(axes, run: RunData, x_var: str, y_var: str, member: int | None = None) -> None:
    """A row of portraits, ``y_var`` against ``x_var`` a component a panel: one body's, or
    a chain's body or joint ``member`` (named on the row's first panel)."""
    s = run.series(x_var, y_var)
    x_all, y_all = (s[x_var], s[y_var]) if member is None else (s[x_var][:, member], s[y_var][:, member])
    for k, ax in enumerate(axes):
        x, y = x_all[:, k], y_all[:, k]
        ok = np.isfinite(x) & np.isfinite(y)
        ax.plot(x[ok], y[ok], color=f"C{k}", lw=0.9)
        if ok.any():
            ax.plot(x[ok][0], y[ok][0], "o", color="green", ms=5, label="start")
            ax.plot(x[ok][-1], y[ok][-1], "s", color="k", ms=5, label="end")
        ax.set_xlabel(_label(x_var, k), fontsize=8)
        ax.set_ylabel(_label(y_var, k), fontsize=8)
        ax.grid(alpha=0.3)
    if member is not None:
        axes[0].set_title(run.members[QUANTITIES[x_var].member][member], fontsize=9, loc="left")
    else:
        axes[0].legend(fontsize=8, title=run.label, title_fontsize=8)


def _phase_figure(run: RunData, out: FigureWriter) -> FigureFile | None:
    """Phase portraits: one body's Theta_i against Omega_i, and E_i against F_i where E
    exceeds round-off; a chain's the same of each joint, its Theta_j against Omega_j (the
    child's orientation and angular velocity relative to its parent) and its E_j against F_j."""
    members = run.members
    pairs = [("joint_theta", "joint_omega"), ("constraint_error", "constraint_rate")] if members is not None else \
        [("theta", "omega"), ("constraint_error", "constraint_rate")]
    held = run.series(*(v for pair in pairs for v in pair))
    if not all(v in held for v in pairs[0]):
        return None  # a thinned store
    e = held.get("constraint_error")
    columns = [None] if members is None else range(len(members["joint"]))
    rows = []
    for j in columns:
        rows.append((*pairs[0], j))
        part = e if (e is None or j is None) else e[:, j]
        if "constraint_rate" in held and part is not None and np.nanmax(np.abs(part), initial=0.0) > ROUND_OFF_E:
            rows.append((*pairs[1], j))
    constraint = any(r[0] == "constraint_error" for r in rows)
    fig, axes = new_figure(len(rows), 3, width=12.0, row_height=3.4 if members is None else 3.0, sharex=False)
    for row, (x_var, y_var, j) in zip(axes, rows):
        _phase_row(row, run, x_var, y_var, j)
    if members is not None:
        axes[0, -1].legend(fontsize=8, loc="upper right")
    _suptitle(fig, run, "phase portraits")
    note = "" if constraint else " E is zero to round-off (or not stored): no E-F portraits."
    words = ("Each Euler angle Theta_i against the body angular velocity Omega_i" if members is None else
             "Each joint's relative Euler angle (Theta_j)_i against its relative angular velocity (Omega_j)_i "
             "(child frame), a row a joint")
    return out.save(fig, f"{safe_filename(run.label)}_phase", f"{run.label}: phase portraits",
                    words + (" and each component of the constraint error E_i against its rate F_i"
                             + (" where E_j exceeds round-off" if members is not None else "") if constraint else "")
                    + f", from the start (green circle) to the last sample (black square).{note}")


def _horizontal_axes(gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(e_1, e_2, n): two orthonormal directions of the ground plane (perpendicular to
    gravity g) and its upward normal n = -g/|g|; e_1 the inertial axis with the largest part
    in the plane, projected (g along -z: e_1 = x, e_2 = y)."""
    n = -gravity / np.linalg.norm(gravity)
    axes = np.eye(3) - np.outer(np.eye(3) @ n, n)
    e1 = axes[int(np.argmax(np.linalg.norm(axes, axis=1)))]
    e1 = e1 / np.linalg.norm(e1)
    return e1 + 0.0, np.cross(n, e1) + 0.0, n  # + 0.0: no -0 in the labels


def _balance_figure(run: RunData, out: FigureWriter) -> FigureFile | None:
    """A tree's balance on the ground (None for a run without a centre of pressure): the
    whole-body centre of mass and each ground joint's centre of pressure along the two
    directions of the ground plane, and the ground's push n'Lambda_j beside the total
    weight, against time (posturography's COM-COP traces)."""
    held = run.series("com_position", "centre_of_pressure", "constraint_force")
    if run.members is None or not {"com_position", "centre_of_pressure"} <= set(held):
        return None
    cop = held["centre_of_pressure"]
    ground = [j for j in range(cop.shape[1]) if np.isfinite(cop[:, j]).any()]
    gravity = np.asarray(run.config.get("gravity") or [0.0, 0.0, 0.0], dtype=float)
    if not ground or not np.any(gravity):
        return None
    e1, e2, n = _horizontal_axes(gravity)
    time, com = held["time"], held["com_position"]
    fig, axes = new_figure(3 if "constraint_force" in held else 2, 1)
    for ax, e, k in zip(axes[:2, 0], (e1, e2), (1, 2)):
        ax.plot(time, com @ e, color="k", label="COM")
        for c, j in zip(colours(len(ground)), ground):
            ax.plot(time, cop[:, j] @ e, color=c, marker=_marker(cop[:, j, 0]),
                    label=f"COP, {run.members['joint'][j]}")
        ax.set_ylabel(f"along $e_{k}$ = [{', '.join(f'{v:.3g}' for v in e)}] [m]", fontsize=8)
    if "constraint_force" in held:
        ax = axes[2, 0]
        for c, j in zip(colours(len(ground)), ground):
            ax.plot(time, held["constraint_force"][:, j] @ n, color=c,
                    label=f"$n' \\Lambda$, {run.members['joint'][j]}")
        weight = float(np.linalg.norm(gravity)) * float(sum(b["mass"] for b in run.config.get("bodies") or ()))
        ax.axhline(weight, color="0.4", ls=":", lw=0.9, label="total weight")
        ax.set_ylabel("ground's push [N]", fontsize=8)
    _finish_time_axes(axes[:, 0], run, ncols=3)
    _suptitle(fig, run, "balance: centre of mass and centre of pressure")
    return out.save(fig, f"{safe_filename(run.label)}_balance", f"{run.label}: balance",
                    "The whole-body centre of mass (black) and the centre of pressure of each joint to the ground "
                    "(its point on the ground plane, perpendicular to g, where the ground's force and moment have no "
                    "moment along the plane; docs/physics.md, 'The centre of pressure') along the plane's two "
                    "directions e_1, e_2 [m]"
                    + (", and the ground's push n' Lambda_j [N] (n = -g/|g|) beside the total weight (dotted)"
                       if "constraint_force" in held else "")
                    + " against time; the centre of pressure is undefined (not drawn) where the ground does not push"
                    + _marks_caption(run) + ".")


def switching_figure(run: RunData, out: FigureWriter) -> FigureFile | None:
    """The located events of a pure-sign-law run (None for other runs): per axis of E, the
    crossings of E_i = 0 against time with the sliding intervals shaded, and the histogram
    of the intervals between successive crossings (log scale) -- the chattering."""
    s = run.series("switching_time", "switching_axis", "switching_kind")
    if "switching_time" not in s:
        return None
    fig, axes = new_figure(1, 2, width=13.0, row_height=3.2, sharex=False)
    raster, histogram = axes[0]
    for i in range(3):
        crossings = _switching_raster(raster, run, s, i)
        gaps = np.diff(crossings)
        if gaps.size and np.all(gaps > 0):
            bins = np.logspace(np.log10(gaps.min()), np.log10(gaps.max()) + 1e-9, 40)
            histogram.hist(gaps, bins=bins, histtype="step", color=f"C{i}", label=f"$E_{i + 1}$: {crossings.size} crossings")
    raster.set_yticks([0, 1, 2], ["$E_1$", "$E_2$", "$E_3$"])
    raster.set_ylim(-0.5, 2.5)
    raster.set_xlabel(_label("time"))
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
    return out.save(fig, f"{safe_filename(run.label)}_switching", f"{run.label}: switchings",
                    "Located crossings of each surface E_i = 0 against time, the intervals where C slid on it "
                    "(equivalent force), and the histogram of the intervals between successive crossings "
                    "(the chattering; see docs/sliding.md).")


def _switching_raster(ax, run: RunData, s: dict, i: int) -> np.ndarray:
    """Axis ``i``'s crossings (lines) and sliding intervals (shaded); returns the crossing times."""
    t, axis, kind = s["switching_time"], s["switching_axis"].astype(int), s["switching_kind"].astype(int)
    crossings = t[(axis == i) & (kind == 0)]
    ax.vlines(crossings, i - 0.35, i + 0.35, color=f"C{i}", lw=0.4)
    starts, ends = t[(axis == i) & (kind == 1)], t[(axis == i) & (kind == 2)]
    t_final = float(run.summary.get("t_final", np.nan))
    for a, b in zip(starts, np.r_[ends, np.full(len(starts) - len(ends), t_final)]):
        ax.axvspan(a, b, ymin=(i + 0.1) / 3, ymax=(i + 0.9) / 3, color=f"C{i}", alpha=0.25, lw=0)
    return crossings


#: The functions that draw the figures of a run, in the page's order (:func:`run_figures`):
#: each ``make(run, out)`` writes one figure and returns its FigureFile, or None when the
#: run does not have it.
RUN_FIGURES = (_rotational_figure, _translational_figure, lyapunov_figure, _forces_figure, _balance_figure,
               _phase_figure, switching_figure)


# -- several runs -----------------------------------------------------------------------------------

def _overlay(runs: Sequence[RunData], variables: Sequence[str], out: FigureWriter, name: str, title: str,
             caption: str) -> FigureFile:
    fig, axes = new_figure(len(variables), 3, width=13.0, row_height=2.5)
    for r, var in enumerate(variables):
        for run, colour in zip(runs, colours(len(runs))):
            s = run.series(var)
            if var not in s:
                continue
            members = run.members
            names = [None] if members is None else members[QUANTITIES[var].member]
            for j, member in enumerate(names):  # a chain's bodies or joints: a line style each
                values = s[var] if member is None else s[var][:, j]
                for k in range(3):
                    axes[r, k].plot(s["time"], values[:, k], color=colour, lw=1.2, ls=_MEMBER_STYLES[j % len(_MEMBER_STYLES)],
                                    label=run.label if member is None else f"{run.label}: {member}")
        for k in range(3):
            axes[r, k].set_ylabel(_label(var, k), fontsize=9)
            axes[r, k].grid(alpha=0.3)
    for k in range(3):
        axes[-1, k].set_xlabel(_label("time"))
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), fontsize=9)
    fig.suptitle(title, fontsize=11)
    return out.save(fig, name, f"Comparison: {title[0].lower()}{title[1:]}", caption)


def _compare_lyapunov(runs: Sequence[RunData], out: FigureWriter) -> FigureFile:
    fig, axes = new_figure(2, width=11.0, row_height=2.8)
    v, rate = axes[0, 0], axes[1, 0]
    for run, colour in zip(runs, colours(len(runs))):
        s = run.series("lyapunov", "lyapunov_rate", "lyapunov_rate_numerical")
        v.plot(s["time"], s["lyapunov"], color=colour, label=run.label)
        rate.plot(s["time"], s["lyapunov_rate"], color=colour, label=f"{run.label} analytic")
        if "lyapunov_rate_numerical" in s:
            rate.plot(s["time"], s["lyapunov_rate_numerical"], color=colour, ls="--", lw=0.9, label=f"{run.label} numerical")
    v_all = np.concatenate([r.series("lyapunov")["lyapunov"] for r in runs])
    v_all = v_all[np.isfinite(v_all)]
    if v_all.size and np.all(v_all > 0):
        v.set_yscale("log")
    set_scale(rate, np.concatenate([r.series("lyapunov_rate")["lyapunov_rate"] for r in runs]))
    v.set_ylabel(_label("lyapunov"))
    rate.set_ylabel(_label("lyapunov_rate"))
    for ax in (v, rate):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, ncols=2 if len(runs) > 3 else 1, loc="upper right")
    rate.set_xlabel(_label("time"))
    fig.suptitle("Lyapunov function and its rate (analytic solid, numerical dashed)", fontsize=11)
    return out.save(fig, "compare_lyapunov", "Comparison: Lyapunov function",
                    "v (log scale where every v is positive) and dv/dt of every run (symmetric-log scale where it "
                    "spans decades); the numerical rate (dashed) should lie on the analytic one.")


def _norms_figure(runs: Sequence[RunData], out: FigureWriter, thresholds: SettleThresholds) -> FigureFile:
    fig, axes = new_figure(2, width=11.0, row_height=2.8)
    limits = {"constraint_error": thresholds.e, "omega": thresholds.omega}
    for run, colour in zip(runs, colours(len(runs))):
        s = run.series(*limits)
        for ax, (var, limit) in zip(axes[:, 0], limits.items()):
            largest = np.linalg.norm(s[var], axis=-1).reshape(len(s["time"]), -1).max(axis=1)  # a chain's: every member's
            ax.plot(s["time"], np.maximum(largest, limit * 1e-4), color=colour, label=run.label)
    for ax, (var, limit) in zip(axes[:, 0], limits.items()):
        ax.set_yscale("log")
        units = QUANTITIES[var].display_units
        ax.axhline(limit, color="k", ls="--", lw=0.9, label=f"threshold {limit:g} {units}")
        ax.set_ylabel(f"$|{_symbol(var)}|$ [{units}]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel(_label("time"))
    fig.suptitle("Norms of the constraint error and of the angular velocity (settling thresholds dashed)", fontsize=11)
    return out.save(fig, "norms", "Constraint error and angular velocity norms",
                    f"|E| and |Omega| (Euclidean norms, a chain's largest over its joints and bodies, log scale; values below {thresholds.e * 1e-4:g} m and "
                    f"{thresholds.omega * 1e-4:g} rad/s drawn at those floors). A run has settled once both stay "
                    "under the dashed thresholds.")


_MEMBER_WORDS = "; a chain's bodies (Theta, Omega, X, V) or joints (E_j) in line styles of their own, named in the legend."


def comparison_figures(runs: Sequence[RunData], out: FigureWriter, thresholds: SettleThresholds) -> list[FigureFile]:
    """Overlays of several runs (one colour per run).

    Parameters
    ----------
    runs : sequence of RunData
        At least one; the overlays of states are drawn for two or more.
    out : FigureWriter
    thresholds : SettleThresholds
        Drawn on the norms figure.

    Returns
    -------
    list of FigureFile
        ``compare_rotational`` (Theta_k [rad], Omega_k [rad/s], one column per component),
        ``compare_translational`` (X_k [m], V_k [m/s], E_k [m]), ``compare_lyapunov``
        (v [J], log scale when positive; dv/dt [W] analytic solid / numerical dashed), and
        ``norms`` (|E| [m] and |Omega| [rad/s], log scale, with the settling thresholds),
        which is also drawn for a single run. A chain's run draws each body (Theta, Omega,
        X, V) or joint (E_j) in a line style of its own; its norms are the largest over its
        joints and bodies (what :func:`rbstab.report.tables.settling_time` bounds).
    """
    if len(runs) < 2:
        return [_norms_figure(runs, out, thresholds)]
    tail = _MEMBER_WORDS if any(run.members is not None for run in runs) else "."
    return [
        _overlay(runs, ("theta", "omega"), out, "compare_rotational", "Rotational states",
                 "Theta and Omega of every run, one column per component" + tail),
        _overlay(runs, ("position", "velocity", "constraint_error"), out, "compare_translational",
                 "Translational states and constraint error",
                 "X, V and the constraint error E of every run, one column per component" + tail),
        _compare_lyapunov(runs, out),
        _norms_figure(runs, out, thresholds),
    ]
