"""The report's section of chain runs (``rbstab run`` of a config with ``bodies`` and
``joints``): a table of the runs and, per run, its animation, its bodies' orientations, its
joints' angles and torques, the constraints' errors and the chain's v with its terms and rate.

Each figure is drawn from the run file's variables, whose second dimension is ``body`` or
``joint`` (:func:`rbstab.io.hdf5.write_result`); the bodies and joints are named as
in the configuration.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..layout import QUANTITIES, SATURATION_FLAGS
from .figures import (FigureFile, FigureWriter, _finish_time_axes, _label, _marker, _symbol, lyapunov_figure, new_figure,
                      set_scale, shade_saturation)
from .load import RunData, safe_filename
from .render import Section, Table

__all__ = ["chain_sections", "chain_figures", "CHAIN_FIGURES"]

_STYLES = ("-", "--", ":")


def _names(run: RunData, dimension: str) -> list[str]:
    """The run's bodies or joints (``dimension``), in the file's order."""
    import h5py  # heavy: h5py

    with h5py.File(run.path, "r") as f:
        return [n.decode() if isinstance(n, bytes) else str(n) for n in f[dimension][...]]


def _component(var: str, k: int) -> str:
    """The legend of component k of ``var``: theta_1, or (Theta_j)_1 for a symbol with an index."""
    tex = QUANTITIES[var].component_tex or QUANTITIES[var].tex
    return f"$({tex})_{k + 1}$" if "_" in tex else f"${_symbol(var, k)}$"


def _suptitle(fig, run: RunData, what: str) -> None:
    failed = "" if run.ok else f" - FAILED ({run.message})"
    fig.suptitle(f"{run.label} (chain): {what}{failed}", fontsize=11)


def _per_member_figure(run: RunData, out: FigureWriter, dimension: str, names: Sequence[str], kind: str,
                       title: str, caption: str) -> FigureFile:
    """One row of panels per body or joint (``dimension``), a column per quantity of ``names``
    (each (time, member, 3)), components as solid, dashed, dotted lines."""
    members = _names(run, dimension)
    s = run.series(*names)
    fig, axes = new_figure(len(members), len(names), width=4.8 * len(names), row_height=2.2)
    for col, var in enumerate(names):
        for row, member in enumerate(members):
            ax = axes[row, col]
            values = s[var][:, row]
            for k in range(3):
                ax.plot(s["time"], values[:, k], ls=_STYLES[k], marker=_marker(values), label=_component(var, k))
            ax.set_ylabel(f"{member}\n{_label(var)}", fontsize=8)
            set_scale(ax, values)
            if var in SATURATION_FLAGS:
                shade_saturation(ax, run, var, row)
        _finish_time_axes(axes[:, col], run, ncols=3)
    _suptitle(fig, run, title)
    return out.save(fig, f"{safe_filename(run.label)}_{kind}", f"{run.label}: {title}", caption)


def _bodies_figure(run: RunData, out: FigureWriter) -> FigureFile:
    return _per_member_figure(run, out, "body", ("theta", "omega"), "bodies", "bodies",
                              "Each body's Euler angles Theta and body angular velocity Omega against time, a row a "
                              "body.")


def _joints_figure(run: RunData, out: FigureWriter) -> FigureFile:
    return _per_member_figure(run, out, "joint", ("joint_theta", "torque_n"), "joints", "joints",
                              "Each joint's relative orientation Theta_j (the Euler angles of A_parent' A_child) and "
                              "its rotational feedback N_j (eq 23 on the relative motion, child frame, as delivered) "
                              "against time, a row a joint; shaded where an axis of N_j is at its actuator's limit.")


def _constraints_figure(run: RunData, out: FigureWriter) -> FigureFile:
    joints = _names(run, "joint")
    s = run.series("constraint_error", "constraint_force")
    fig, axes = new_figure(2, row_height=2.6)
    for j, joint in enumerate(joints):
        error = np.linalg.norm(s["constraint_error"][:, j], axis=-1)
        force = np.linalg.norm(s["constraint_force"][:, j], axis=-1)
        axes[0, 0].plot(s["time"], error, color=f"C{j % 10}", label=joint)
        axes[1, 0].plot(s["time"], force, color=f"C{j % 10}", label=joint)
    set_scale(axes[0, 0], np.linalg.norm(s["constraint_error"], axis=-1))
    set_scale(axes[1, 0], np.linalg.norm(s["constraint_force"], axis=-1))
    axes[0, 0].set_ylabel(f"$|{_symbol('constraint_error')}_j|$ [{QUANTITIES['constraint_error'].display_units}]",
                          fontsize=9)
    axes[1, 0].set_ylabel(f"$|{_symbol('constraint_force')}_j|$ [{QUANTITIES['constraint_force'].display_units}]",
                          fontsize=9)
    _finish_time_axes(axes[:, 0], run, ncols=min(4, len(joints)))
    _suptitle(fig, run, "joints' constraints")
    return out.save(fig, f"{safe_filename(run.label)}_constraints", f"{run.label}: joints' constraints",
                    "Each joint's constraint error |E_j| = |X_c + A_c R_c - X_p - A_p R_p| (a permanent joint's: "
                    "rounding, since reduced coordinates hold it) and the force |Lambda_j| on the child at C, against "
                    "time; a symmetric-logarithmic axis where they span decades.")


#: The figures of a chain run, in the page's order.
CHAIN_FIGURES = (_bodies_figure, _joints_figure, _constraints_figure, lyapunov_figure)


def chain_figures(run: RunData, out: FigureWriter) -> list[FigureFile]:
    """The figures of one chain run (:data:`CHAIN_FIGURES`): ``<label>_bodies`` (Theta_i,
    Omega_i), ``<label>_joints`` (Theta_j, N_j), ``<label>_constraints`` (|E_j|,
    |Lambda_j|), ``<label>_lyapunov`` (one body's figure of v: its terms, v - W with
    disturbances, dv/dt analytic and numerical and their difference)."""
    return [make(run, out) for make in CHAIN_FIGURES]


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
        rows.append([run.label, run.status, ", ".join(_names(run, "body")), ", ".join(_names(run, "joint")),
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
        sub.blocks.extend(chain_figures(run, out))
        section.blocks.append(sub)
    return [section]
