"""The report's section of chain runs (``rbstab run`` of a config with ``bodies`` and
``joints``): a table of the runs and, per run, its animation and one body's figures, a
column per body or joint (:func:`rbstab.report.figures.run_figures`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .figures import FigureWriter, member_names, run_figures
from .load import RunData, safe_filename
from .render import Section, Table

__all__ = ["chain_sections"]


def _number(value, digits: int = 4) -> str:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f"{x:.{digits}g}" if np.isfinite(x) else "—"


def chain_sections(runs: Sequence[RunData], out: FigureWriter, frames: int = 0) -> list[Section]:
    """The section of the chain runs: a table (status, bodies, joints, v(0), v(t_end), the
    rate check, the largest max |E_j| over the joints), each run's animation
    (``frames`` > 0, :func:`rbstab.report.animate.report_animation`) and figures."""
    if not runs:
        return []
    section = Section("Chains of bodies", "chains")
    rows = []
    for run in runs:
        summary = run.summary
        error = np.asarray(summary.get("max_abs_constraint_error", []), dtype=float).ravel()
        error = error[np.isfinite(error)]
        rows.append([run.label, run.status, ", ".join(member_names(run, "body")), ", ".join(member_names(run, "joint")),
                     _number(summary.get("lyapunov_initial")), _number(summary.get("lyapunov_final")),
                     str(summary.get("lyapunov_rate_check", "")), _number(error.max()) if error.size else "—"])
    section.blocks.append(Table("Chain runs", ["run", "status", "bodies", "joints", "v(0) [J]", "v(t_end) [J]",
                                               "rate check", "max |E_j| [m]"], rows))
    for run in runs:
        sub = Section(f"{run.label} (chain, {run.status})", f"chain-{safe_filename(run.label)}", level=3)
        if not run.ok:
            sub.blocks.append(f"FAILED: {run.message}")
        if frames:
            from .animate import report_animation  # heavy: numba (through rbstab.kinematics)

            sub.blocks.append(report_animation(run, frames))
        sub.blocks.extend(run_figures(run, out))
        section.blocks.append(sub)
    return [section]
