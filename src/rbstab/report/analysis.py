"""Report pages of analysis files (``rbstab analyze`` -> ``*.analysis.nc``).

Per configuration: the verdict and notes, the equilibrium and rest check, the eigenvalue
table and the pole plot, the time scale (the slowest time constant; the e-folding time when
unstable; none when marginal) beside the simulation's time to converge, the certificate
table and the sampled dv/dt against v, and the basin map with the sublevel-set contour,
the pushes and the basin stability (:mod:`rbstab.report.push`).
Per curves file of a sweep spec: :func:`rbstab.report.push.recovery_section`. Per robustness file: the stable fraction with its interval per
group, the separating parameters and a figure of the runs over the two strongest.

The files are read with :func:`rbstab.analysis.dataset.read_analysis` (the module that
writes them); nothing here knows their layout beyond the variable names it documents.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..analysis.thresholds import EXPLAINS_BAR
from ..convergence import RULE
from ..kinds import ANALYSIS, RUN, STORE, inputs_in, is_plain_folder
from ..layout import display_units
from .figures import DPI, FigureFile, FigureWriter
from .load import ReportInputError, safe_filename
from .push import push_blocks, recovery_section, stability_blocks
from .render import Section, Table
from .tables import format_value

__all__ = ["split_inputs", "analysis_sections"]

#: Colours of the basin outcomes (converged, not converged, failed).
_OUTCOME_COLOURS = ("#4daf4a", "#ff9f1c", "#d62728")


def split_inputs(paths: Sequence[str | os.PathLike]) -> tuple[list[Path], list]:
    """(analysis files, the other inputs) of a report.

    An analysis file given directly goes to the first list; a plain folder (not a sweep)
    gives its ``*.analysis.nc`` files, and stays an input of its own only if it also
    holds run files (``*.h5``).
    """
    analyses: list[Path] = []
    others: list = []
    for raw in paths:
        p = Path(raw)
        found = inputs_in(p, (ANALYSIS,)) if is_plain_folder(p) else []
        if ANALYSIS.can_open(p):
            analyses.append(p)
        elif found:
            analyses.extend(found)
            if inputs_in(p, (RUN, STORE)):
                others.append(raw)
        else:
            others.append(raw)
    return list(dict.fromkeys(analyses)), others


def _read(paths: Sequence[Path]) -> list:
    from ..analysis.dataset import read_analysis  # heavy: numba (the rbstab.analysis package)

    datasets, problems = [], []
    for p in paths:
        try:
            datasets.append(read_analysis(p))
        except (OSError, ValueError) as exc:
            problems.append(f"{p}: {exc}")
    if problems:
        raise ReportInputError(problems)
    return datasets


def analysis_sections(paths: Sequence[Path], out: FigureWriter) -> list[Section]:
    """The sections of every analysis file, figures written by ``out``.

    Raises
    ------
    ReportInputError
        If a file cannot be read.
    """
    sections = []
    for path, ds in zip(paths, _read(paths)):
        if ds.attrs.get("kind") == "robustness":
            sections.append(_robustness_section(ds, path, out))
        elif ds.attrs.get("kind") == "recovery":
            sections.append(recovery_section(ds, path, out))
        else:
            sections.append(_configuration_section(ds, path, out))
    return sections


# -- one configuration -------------------------------------------------------------------------------


def _f(value, digits: int = 4) -> str:
    return format_value(value, digits)


def _scalar(ds, name: str) -> float:
    return float(ds[name].values) if name in ds else float("nan")


def _eigenvalues(ds) -> np.ndarray:
    return ds["eigenvalue_real"].values + 1j * ds["eigenvalue_imag"].values


def _state_text(ds, prefix: str) -> str:
    """The blocks ``<prefix>_<block>`` of an analysis file's state in words: ``theta (0, 0, 0)
    rad; ...``, a chain's by body (``legs theta (...)``; a body without the block left out)."""
    parts = []
    for name in ds.data_vars:
        if not name.startswith(f"{prefix}_") or ds[name].dims[-1:] != ("axis",):
            continue
        block, units = name[len(prefix) + 1:], ds[name].attrs.get("units", "")
        rows = ([(f"{body} {block}", row) for body, row in zip(ds["body"].values.astype(str), ds[name].values)]
                if ds[name].dims == ("body", "axis") else [(block, ds[name].values)])
        for label, row in rows:
            if np.all(np.isfinite(row)):
                parts.append(f"{label} ({', '.join(_f(v, 6) for v in row + 0.0)}) {units}")
    return "; ".join(parts)


def _facts(ds) -> list[str]:
    from ..analysis.text import time_scale  # heavy: numba (the rbstab.analysis package)

    a = ds.attrs
    facts = [f"variant: {a.get('variant')}; verdict of the linearisation: {a.get('verdict')} "
             f"(modes with |Re s| <= {_f(_scalar(ds, 'eigenvalue_tolerance'), 2)} 1/s count as marginal)",
             f"equilibrium: {_state_text(ds, 'equilibrium')}",
             f"rest check: {'passed' if a.get('rest_point') else 'FAILED'} (max |dy/dt| "
             f"{_f(max(float(np.nanmax(np.abs(ds[n].values))) for n in ds.data_vars if n.startswith('rest_residual_')), 3)} "
             f"<= {_f(_scalar(ds, 'rest_tolerance'), 3)})"]
    _, _, tau, e_fold = _modes(ds)
    scale = time_scale(str(a.get("verdict")), tau[0], e_fold[0])
    if "time_to_converge" in ds:
        ttc = _scalar(ds, "time_to_converge")
        simulated = f"converged at {_f(ttc)} s" if np.isfinite(ttc) else \
            f"not converged by t_end ({a.get('simulation_status')})"
        alone = _scalar(ds, "linear_settling_time")
        facts.append(f"{scale}"
                     + (f" (alone it would take {_f(alone)} s to bring v down by the ratio "
                        f"{_f(_scalar(ds, 'convergence_ratio'))})" if np.isfinite(alone) else "")
                     + f"; simulation from the configured initial state: {simulated}")
    else:
        facts.append(scale)
    facts += [f"note: {n}" for n in str(a.get("notes", "")).splitlines() if n]
    return facts


def _modes(ds) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(omega_n, zeta, tau, e-folding time) per mode, from the eigenvalues and their tolerance
    (:func:`rbstab.analysis.linearise.modes`; so for a file of any version alike)."""
    from ..analysis.linearise import modes  # heavy: numba (the rbstab.analysis package)

    return modes(_eigenvalues(ds), _scalar(ds, "eigenvalue_tolerance"))


def _eigen_table(ds) -> Table:
    rows = []
    omega_n, zeta, tau, e_fold = _modes(ds)
    for k, s in enumerate(_eigenvalues(ds)):
        rows.append([str(k + 1), _f(s.real, 6), _f(s.imag, 6), _f(omega_n[k]), _f(zeta[k], 3), _f(tau[k]),
                     _f(e_fold[k])])
    return Table("Eigenvalues of the Jacobian at the equilibrium (real part descending)",
                 ["mode", "Re s [1/s]", "Im s [rad/s]", "omega_n [rad/s]", "zeta", "tau [s]", "e-folding time [s]"],
                 rows, note="omega_n = |s|, zeta = -Re s / |s|; tau = -1 / Re s of a decaying mode (Re s < "
                            "-tolerance), the e-folding time 1 / Re s of a growing mode (Re s > tolerance); a mode "
                            "with |Re s| within the tolerance (a zero or imaginary eigenvalue) has neither ('-').")


def _certificate_table(ds) -> Table | None:
    if "lyapunov_hessian" not in ds:
        return None
    a = ds.attrs
    mu = ds["rate_eigenvalue"].values
    finite = mu[np.isfinite(mu)]
    zero = int(np.sum(np.abs(finite) <= 1e-8 * np.abs(finite).max())) if finite.size else 0
    rows = [
        ["v at the equilibrium [J]", _f(_scalar(ds, "lyapunov_equilibrium"))],
        ["Hessian of v", "positive definite" if a.get("positive_definite") else "NOT positive definite"],
        ["smallest eigenvalue of the Hessian of v (mixed units)", _f(_scalar(ds, "hessian_min_eigenvalue"))],
        ["Hessian of dv/dt", str(a.get("rate_definiteness"))],
        ["generalised eigenvalues mu of (H_dv/dt, H_v) [1/s]",
         f"{_f(finite.min())} .. {_f(finite.max())}, {zero} zero of {len(mu)}" if finite.size else "-"],
        ["LaSalle's condition (PBH test on the linearisation)", "holds" if a.get("lasalle_observable") else "fails"],
        ["sampled states", str(a.get("n_samples"))],
        ["largest relative dv/dt among them [W]", f"{_f(_scalar(ds, 'worst_rate'))} at v = "
                                                  f"{_f(_scalar(ds, 'worst_lyapunov'))} J"],
        ["|numerical - analytic dv/dt| / power scale", _f(_scalar(ds, "rate_mismatch"), 2)],
        ["least v on the domain boundary |theta_2| = pi/2 - margin [J]", _f(_scalar(ds, "boundary_level"))],
        ["sublevel estimate c of {v <= c} [J]", _f(_scalar(ds, "sublevel"))],
        ["what c is", str(a.get("sublevel_estimate", "estimate (sampled)"))],
        ["c from the samples alone [J]", _f(_scalar(ds, "sublevel_sampled")) if "sublevel_sampled" in ds else "-"],
        ["c with the local search from N/4, N/2, N samples [J]",
         ", ".join(_f(x) for x in ds["sublevel_history"].values) + ("" if a.get("sublevel_settled", 1) else
                                                                     " (STILL MOVING)")
         if "sublevel_history" in ds else "-"],
        ["c bounded by", str(a.get("sublevel_bound"))],
        *([["verified c of {v <= c} [J] (interval arithmetic, --verify)",
            f"{_f(_scalar(ds, 'sublevel_verified'))} ({int(_scalar(ds, 'sublevel_verified_boxes'))} boxes, "
            f"{_f(_scalar(ds, 'sublevel_verified_seconds'), 2)} s)"],
           ["verified c bounded by", str(a.get("sublevel_verified_reason"))]] if "sublevel_verified" in ds else []),
        ["certificate", f"holds ({a.get('certificate_argument')})" if a.get("certificate_holds") else "does not hold"],
    ]
    return Table("Lyapunov certificate", ["quantity", "value"], rows,
                 note="The sublevel set is an estimate of an inner part of the region of attraction, not a proof: "
                      "no sampled state, nor any state the local search from them found, with v < c has dv/dt > 0 "
                      "or lies outside the domain, and no simulated run of the command that started inside "
                      "{v <= c} failed to recover (docs/analysis.md)."
                      + (" The verified c is a proof: {v <= c} positively invariant and inside the region of "
                         "attraction, by interval arithmetic over boxes of Theta (docs/analysis.md, \"verified\")."
                         if "sublevel_verified" in ds else "")
                      + (("\n" + str(a.get("sublevel_notes"))) if a.get("sublevel_notes") else ""))


def _pole_figure(ds, out: FigureWriter, stem: str, name: str) -> FigureFile:
    from matplotlib.figure import Figure  # heavy: matplotlib

    s = _eigenvalues(ds)
    tol = _scalar(ds, "eigenvalue_tolerance")
    fig = Figure(figsize=(7.5, 4.2), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    ax.axvspan(-tol, tol, color="0.85", zorder=0)
    ax.axvline(0.0, color="0.4", lw=0.8)
    ax.axhline(0.0, color="0.4", lw=0.8)
    stable = s.real < -tol
    ax.plot(s.real[stable], s.imag[stable], "x", color="C0", ms=8, mew=2, label="stable")
    if (~stable).any():
        ax.plot(s.real[~stable], s.imag[~stable], "x", color="C3", ms=9, mew=2, label="marginal or unstable")
    if s.real.min() < 0 and np.abs(s).max() > 20 * np.abs(s).min():
        ax.set_xscale("symlog", linthresh=max(1.0, float(np.abs(s.real[s.real != 0]).min(initial=1.0))))
    ax.set_xlabel("Re s [1/s]")
    ax.set_ylabel("Im s [rad/s]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{name}: poles of the linearisation ({ds.attrs.get('verdict')})", fontsize=10)
    return out.save(fig, f"{stem}_poles", f"{name}: pole plot",
                    "Eigenvalues of the Jacobian at the equilibrium; grey band: |Re s| within the tolerance "
                    "(marginal). A symmetric-log real axis where the poles span decades.")


def _rate_figure(ds, out: FigureWriter, stem: str, name: str) -> FigureFile | None:
    if "sample_lyapunov" not in ds or ds.sizes.get("sample", 0) == 0:
        return None
    from matplotlib.figure import Figure  # heavy: matplotlib

    v = ds["sample_lyapunov"].values
    rate = ds["sample_rate"].values
    inside = ds["sample_outside"].values == 0
    c = _scalar(ds, "sublevel")
    fig = Figure(figsize=(7.5, 4.0), dpi=DPI, layout="constrained")
    ax = fig.subplots()
    ok = inside & np.isfinite(rate) & (v > 0)
    ax.plot(v[ok], -rate[ok], ".", ms=2, color="C0", alpha=0.5, label="-dv/dt at a sampled state")
    positive = ok & (rate > 0)
    if positive.any():
        ax.plot(v[positive], rate[positive], ".", ms=4, color="C3", label="dv/dt > 0 (as |dv/dt|)")
    if c > 0:
        ax.axvline(c, color="k", ls="--", lw=1.0, label=f"sublevel estimate c = {c:.4g} J")
    if "sublevel_verified" in ds and _scalar(ds, "sublevel_verified") > 0:
        cv = _scalar(ds, "sublevel_verified")
        ax.axvspan(v[ok].min() if ok.any() else cv * 1e-6, cv, color="C2", alpha=0.12, lw=0,
                   label=f"verified {{v <= {cv:.4g} J}} (interval arithmetic)")
    ax.set_xscale("log")
    if (-rate[ok] > 0).any():
        ax.set_yscale("log")
    ax.set_xlabel("v [J]")
    ax.set_ylabel("-dv/dt [W] (d/ds v(y + s f), from v alone)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"{name}: dv/dt on {ds.attrs.get('n_samples')} sampled states", fontsize=10)
    return out.save(fig, f"{stem}_sampled_rate", f"{name}: sampled dv/dt",
                    "The rate of v along the right-hand side at each sampled state (computed from v alone), "
                    "against v there; states with dv/dt = 0 (at rest) are off the logarithmic axis.")


def _basin_figure(ds, out: FigureWriter, stem: str, name: str) -> FigureFile:
    from matplotlib.colors import ListedColormap  # heavy: matplotlib
    from matplotlib.figure import Figure  # heavy: matplotlib
    from matplotlib.patches import Patch  # heavy: matplotlib

    x, y = ds["basin_x"], ds["basin_y"]
    outcome = ds["basin_outcome"].values.T  # rows: y
    ttc = ds["basin_time_to_converge"].values.T
    v0 = ds["basin_lyapunov_initial"].values.T
    c = _scalar(ds, "sublevel")
    fig = Figure(figsize=(11.0, 4.6), dpi=DPI, layout="constrained")
    ax1, ax2 = fig.subplots(1, 2, sharex=True, sharey=True)
    ax1.pcolormesh(x.values, y.values, outcome, cmap=ListedColormap(_OUTCOME_COLOURS), vmin=-0.5, vmax=2.5,
                   shading="nearest")
    mesh = ax2.pcolormesh(x.values, y.values, ttc, cmap="viridis", shading="nearest")
    fig.colorbar(mesh, ax=ax2, label="time to converge [s]")
    handles = [Patch(color=col, label=lab) for col, lab in zip(_OUTCOME_COLOURS, ("converged", "not converged",
                                                                                 "failed"))]
    contour = bool(c > 0 and np.nanmin(v0) < c < np.nanmax(v0))  # c NaN without a certificate: no contour
    for ax in (ax1, ax2):
        if contour:
            ax.contour(x.values, y.values, v0, levels=[c], colors="k", linewidths=1.5)
        ax.set_xlabel(f"{x.attrs.get('config_key')} [{display_units(x.attrs.get('units'))}]")
        ax.grid(alpha=0.2)
    ax1.set_ylabel(f"{y.attrs.get('config_key')} [{display_units(y.attrs.get('units'))}]")
    if contour:
        handles.append(Patch(facecolor="none", edgecolor="k", label=f"v = {c:.4g} J (sublevel estimate)"))
    ax1.legend(handles=handles, fontsize=8, loc="upper right")
    fig.suptitle(f"{name}: basin of attraction (converged: |v| <= {ds.attrs.get('basin_ratio')} |v(0)| by "
                 f"t_end = {ds.attrs.get('basin_t_end')} s)", fontsize=10)
    return out.save(fig, f"{stem}_basin", f"{name}: basin map",
                    "Outcome of the simulation from each initial state of the slice (left) and its time to "
                    "converge (right); black: the contour v = c of the certificate's sublevel estimate "
                    "(absent without a certificate, or when the slice lies wholly inside or outside it).")


def _basin_facts(ds) -> list[str]:
    outcome = ds["basin_outcome"].values
    v0 = ds["basin_lyapunov_initial"].values
    c = _scalar(ds, "sublevel")
    names = ("converged", "not converged", "failed")
    facts = [f"{outcome.size} runs over {ds['basin_x'].attrs.get('config_key')} x "
             f"{ds['basin_y'].attrs.get('config_key')}: "
             + ", ".join(f"{int(np.sum(outcome == i))} {n}" for i, n in enumerate(names))]
    facts += [f"failed: {line}" for line in str(ds.attrs.get("basin_failures", "")).splitlines() if line]
    if np.isfinite(c):
        inside = v0 <= c
        bad = int(np.sum(inside & (outcome != 0)))
        facts.append(f"{int(inside.sum())} points inside the sublevel estimate {{v <= {c:.4g} J}}: "
                     + ("all converged (the estimate lies inside the basin map)" if not bad else
                        f"{bad} did NOT converge (the estimate is not inside the basin map)"))
    return facts


def _configuration_section(ds, path: Path, out: FigureWriter) -> Section:
    name = str(ds.attrs.get("name", path.name))
    stem = f"analysis_{safe_filename(name)}"
    s = Section(f"Stability analysis: {name}", f"analysis-{safe_filename(name)}")
    s.blocks.append(f"From {path}. Method and limits: docs/analysis.md.")
    s.blocks.append(_facts(ds))
    s.blocks.append(_eigen_table(ds))
    s.blocks.append(_pole_figure(ds, out, stem, name))
    table = _certificate_table(ds)
    if table is not None:
        s.blocks.append(table)
        figure = _rate_figure(ds, out, stem, name)
        if figure is not None:
            s.blocks.append(figure)
    if "basin_outcome" in ds:
        s.blocks.append(_basin_facts(ds))
        s.blocks.append(_basin_figure(ds, out, stem, name))
    s.blocks += push_blocks(ds, out, stem, name) + stability_blocks(ds, out, stem, name)
    return s


# -- robustness ----------------------------------------------------------------------------------------


def _robustness_section(ds, path: Path, out: FigureWriter) -> Section:
    a = ds.attrs
    s = Section(f"Robustness: sweep {a.get('sweep')}", f"robustness-{safe_filename(str(a.get('sweep')))}")
    s.blocks.append(f"From {path} (sweep folder {a.get('folder')}). Stable: {a.get('stability')}; "
                    f"interval: Wilson score at {float(a.get('confidence', 0.95)):.0%}.")
    groups = [str(g) for g in ds["group"].values]
    s.blocks.append(Table("Stable fraction per base configuration",
                          ["group", "runs", "stable", "fraction", "interval", "unstable rest", "without a result",
                           "differ from the sweep's converged"],
                          [[g, str(int(ds["n_runs"].values[i])), str(int(ds["n_stable"].values[i])),
                            f"{float(ds['stable_fraction'].values[i]):.1%}",
                            f"{float(ds['stable_fraction_low'].values[i]):.1%} - "
                            f"{float(ds['stable_fraction_high'].values[i]):.1%}",
                            str(int(ds["n_unstable_rest"].values[i])) if "n_unstable_rest" in ds else "-",
                            str(int(ds["n_excluded"].values[i])), str(int(ds["n_disagree"].values[i]))]
                           for i, g in enumerate(groups)],
                          note=f"Stable, as the sweep's converged: {RULE}; they differ only for an index "
                               "written with another rule."))
    rows, order = [], []
    ruled = "rule_side" in ds  # a file written before rules of two thresholds: the one-sided threshold
    for i, g in enumerate(groups):
        for j, p in enumerate(ds["parameter"].values):
            auc = float(ds["auc"].values[i, j])
            if not np.isfinite(auc):
                continue
            if ruled:
                accuracy = float(ds["rule_balanced_accuracy"].values[i, j])
                rule = (_rule_cell(str(ds["rule_side"].values[i, j]), float(ds["rule_low"].values[i, j]),
                                   float(ds["rule_high"].values[i, j]))
                        if bool(ds["rule_explains"].values[i, j]) else "none (below the bar)")
            else:
                accuracy = float(ds["balanced_accuracy"].values[i, j])
                rule = f"{ds['stable_side'].values[i, j]} {_f(ds['threshold'].values[i, j], 6)}"
            rows.append([g, str(p), rule, f"{accuracy:.1%}",
                         f"{_f(ds['stable_min'].values[i, j])} .. {_f(ds['stable_max'].values[i, j])}",
                         f"{_f(ds['unstable_min'].values[i, j])} .. {_f(ds['unstable_max'].values[i, j])}"])
            order.append((g, -accuracy))
    rows = [r for _, r in sorted(zip(order, rows), key=lambda x: x[0])]
    if rows:
        s.blocks.append(Table("Parameters that separate stable from unstable runs (strongest first)",
                              ["group", "parameter", "converged where", "balanced accuracy",
                               "stable range", "unstable range"], rows,
                              note=f"The best rule of one or two thresholds of each parameter, given where its "
                                   f"balanced accuracy (the mean of the fractions of converged and of other runs "
                                   f"on their side; 0.5 chance) reaches {EXPLAINS_BAR:.0%} (docs/push.md)."))
    else:
        s.blocks.append("No parameter separates stable from unstable runs: every group is all stable or all unstable.")
    s.blocks.append(_robustness_figure(ds, out))
    return s


def _rule_cell(side: str, low: float, high: float) -> str:
    """``x < 0.41``, ``-0.4 < x < 0.41``... of a rule's side and thresholds."""
    if side == "below":
        return f"x < {_f(high, 6)}"
    if side == "above":
        return f"x > {_f(low, 6)}"
    if side == "inside":
        return f"{_f(low, 6)} < x < {_f(high, 6)}"
    return f"x < {_f(low, 6)} or x > {_f(high, 6)}"


def _two_parameters(values: np.ndarray, order: Sequence[int]) -> list[int]:
    """The first varying parameter in ``order`` and the next one not (almost) a function of
    it (|correlation| < 0.99: a scale factor and the value it scales are one parameter)."""
    varying = [j for j in order if np.unique(values[:, j]).size > 1]
    if not varying:
        return []
    first = varying[0]
    for j in varying[1:]:
        if abs(np.corrcoef(values[:, first], values[:, j])[0, 1]) < 0.99:
            return [first, j]
    return [first]


def _robustness_figure(ds, out: FigureWriter) -> FigureFile:
    from matplotlib.figure import Figure  # heavy: matplotlib

    groups = [str(g) for g in ds["group"].values]
    parameters = [str(p) for p in ds["parameter"].values]
    fig = Figure(figsize=(5.0 * len(groups), 4.2), dpi=DPI, layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(groups), squeeze=False)[0])
    run_group = ds["run_group"].values.astype(str)
    stable = ds["run_stable"].values.astype(bool)
    values = ds["run_value"].values
    for ax, (i, g) in zip(axes, enumerate(groups)):
        if "rule_balanced_accuracy" in ds:  # strongest first, one- or two-sided
            order = list(np.argsort(-np.nan_to_num(ds["rule_balanced_accuracy"].values[i], nan=0.5)))
        else:
            order = list(np.argsort(-np.abs(2 * np.nan_to_num(ds["auc"].values[i], nan=0.5) - 1)))
        mine = run_group == g
        varying = _two_parameters(values[mine], order)
        if len(varying) == 0:
            ax.text(0.5, 0.5, "no parameter varies", ha="center", transform=ax.transAxes)
            continue
        xj = varying[0]
        yv = values[:, varying[1]] if len(varying) > 1 else np.zeros(len(values))
        for flag, colour, label in ((True, "C0", "stable"), (False, "C3", "unstable")):
            pick = mine & (stable == flag)
            ax.plot(values[pick, xj], yv[pick], "o" if flag else "x", color=colour, ms=4, label=f"{label} ({pick.sum()})")
        ax.set_xlabel(parameters[xj])
        ax.set_ylabel(parameters[varying[1]] if len(varying) > 1 else "")
        ax.set_title(g, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"sweep {ds.attrs.get('sweep')}: stable and unstable runs", fontsize=10)
    return out.save(fig, f"robustness_{safe_filename(str(ds.attrs.get('sweep')))}",
                    f"{ds.attrs.get('sweep')}: stable and unstable runs",
                    "Each run of each group over the varied parameter with the strongest separation "
                    "(|2 AUC - 1|) and the next strongest that is not a function of it (a scale factor and the "
                    "value it scales are one parameter); the first varied ones when every run is stable.")
