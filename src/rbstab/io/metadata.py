"""Metadata of the files rbstab writes: the one place for units, names and provenance.

Both writers, run files (:mod:`rbstab.io.hdf5`) and sweep store files
(:mod:`rbstab.io.chunk`), take from here

- each variable's attributes (:func:`variable_attributes`): ``units`` (CF/UDUNITS
  spelling, :data:`VARIABLE_UNITS`), ``long_name`` (:data:`LONG_NAMES`) and
  ``description`` (the formula and the paper's equation, :data:`VARIABLE_DESCRIPTIONS`);
- the units and long names of the summary figures (:data:`SUMMARY_FIGURES`) and of a
  store file's other per-run values (:data:`PER_RUN`);
- the global attributes that say what made a file (:func:`provenance_attributes`):
  ``Conventions`` (:data:`CONVENTIONS`), ``title``, ``history``, ``source``,
  ``references``, the rbstab version, the git commit with a dirty flag, and the versions
  of Python and of the libraries that computed and wrote the numbers.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from .. import __version__
from ..layout import BLOCK_DESCRIPTIONS, BLOCK_UNITS, OUTPUT_DESCRIPTIONS, OUTPUT_UNITS

__all__ = [
    "CONVENTIONS",
    "REFERENCES",
    "VARIABLE_UNITS",
    "VARIABLE_DESCRIPTIONS",
    "LONG_NAMES",
    "SUMMARY_FIGURES",
    "PER_RUN",
    "LIBRARIES",
    "variable_attributes",
    "summary_units",
    "provenance_attributes",
    "git_state",
    "git_state_of",
]

#: The ``Conventions`` global attribute of every file (CF metadata conventions).
CONVENTIONS = "CF-1.10"
#: The ``references`` global attribute: the paper whose equations rbstab integrates.
REFERENCES = "On the Dynamics and Lyapunov Stability of Constrained and Embedded Rigid Bodies"

#: Units of every variable of a run or store file (CF/UDUNITS spelling: ``rad s-1``).
VARIABLE_UNITS = {
    "time": "s",
    "run": "1",
    **BLOCK_UNITS,
    **OUTPUT_UNITS,
    "lyapunov_rate_numerical": "W",
    "sliding_mode": "1",
    "switching": "1",
    "switching_time": "s",
    "switching_axis": "1",
    "switching_kind": "1",
    "switching_constraint_rate": "m s-1",
}

#: What each variable holds, with its formula and the paper's equation.
VARIABLE_DESCRIPTIONS = {
    "time": "sample time, evenly spaced dense output of the solver",
    "axis": "vector component; frame given by each variable",
    "run": "index of the run in the sweep's run list (increasing within a store file)",
    **BLOCK_DESCRIPTIONS,
    **OUTPUT_DESCRIPTIONS,
    "lyapunov_rate_numerical": "dv/dt by differentiating v along the dense-output samples "
    "(7-point finite differences; for the pure sign law on each smooth piece between switchings); "
    "compare with lyapunov_rate",
    "sliding_mode": "pure sign law: sigma standing for sgn(E) on the sample's piece, +-1 the side of E_i = 0, "
    "0 where C slides on it (equivalent force)",
    "switching": "number of the located event of the pure sign law, in time order",
    "switching_time": "time of the event, located to the solver's resolution",
    "switching_axis": "component i of E (0, 1, 2: inertial x, y, z)",
    "switching_kind": "0 crossing of E_i = 0, 1 sliding on it starts, 2 sliding ends",
    "switching_constraint_rate": "F_i at the event (before the impulse of a sliding start)",
}

#: Short names of every variable (CF ``long_name``: what a plot's axis says).
LONG_NAMES = {
    "time": "time",
    "axis": "vector component",
    "run": "position of the run in the sweep's run list",
    "theta": "Euler angles Theta",
    "omega": "angular velocity Omega (body frame)",
    "position": "centre-of-mass position X (inertial frame)",
    "velocity": "centre-of-mass velocity V (inertial frame)",
    "controller_state": "embedded controller state D (inertial frame)",
    "constraint_error": "constraint error E (inertial frame)",
    "constraint_rate": "constraint error rate F = dE/dt (inertial frame)",
    "constraint_force": "constraint force Lambda at C (inertial frame)",
    "force_h": "translational feedback force H (inertial frame)",
    "torque_n": "rotational feedback torque N (body frame)",
    "lyapunov": "Lyapunov function v",
    "lyapunov_rate": "analytic rate dv/dt of the Lyapunov function",
    "lyapunov_rate_numerical": "numerical derivative dv/dt of the sampled Lyapunov function",
    "lyapunov_translational": "translational term v_t of the Lyapunov function",
    "lyapunov_rotational": "rotational term v_r of the Lyapunov function",
    "lyapunov_constraint": "constraint controller term of the Lyapunov function",
    "lyapunov_gravity": "gravity term of the Lyapunov function",
    "sliding_mode": "sign-law mode sigma of each component of E",
    "switching": "switching event number",
    "switching_time": "time of the switching event",
    "switching_axis": "component of E that switched",
    "switching_kind": "kind of switching event",
    "switching_constraint_rate": "constraint error rate F_i at the switching event",
}

#: Summary figures (:func:`rbstab.summary.summarize`): name -> (units, long name). A run
#: file holds them as ``summary_<name>`` global attributes (units in ``units_of_summary``),
#: a store file as variables along ``run`` (3-vectors as ``<name>_x``, ``_y``, ``_z``).
SUMMARY_FIGURES = {
    "t_final": ("s", "time of the last finite sample"),
    "final_theta": ("rad", "Euler angles Theta at t_final"),
    "final_omega": ("rad s-1", "angular velocity Omega at t_final (body frame)"),
    "final_position": ("m", "position X of C at t_final"),
    "final_velocity": ("m s-1", "velocity V of C at t_final"),
    "final_controller_state": ("m", "controller state D at t_final"),
    "max_abs_constraint_error": ("m", "max |E_i| over the samples"),
    "lyapunov_initial": ("J", "v(0)"),
    "lyapunov_final": ("J", "v(t_end)"),
    "max_lyapunov_rate": ("W", "max dv/dt"),
    "max_lyapunov_increase": ("J", "largest rise of v above its running minimum"),
    "lyapunov_rate_mismatch": ("W", "max |analytic - numerical dv/dt|"),
    "lyapunov_rate_mismatch_relative": ("1", "max |analytic - numerical dv/dt| / max |analytic dv/dt|"),
    "lyapunov_rate_check": ("", "pass, fail or n/a: analytic dv/dt agrees with the numerical derivative"),
    "lyapunov_rate_checked": ("1", "fraction of the samples the rate check compares (pure sign law: on one smooth piece)"),
    # runs of the pure sign law of sliding (rbstab.engine.switching.switching_summary)
    "switching_count": ("1", "crossings of E_i = 0 located"),
    "sliding_time": ("s", "time C slid on E_i = 0 (equivalent force)"),
    "sliding_starts": ("1", "times sliding on E_i = 0 started"),
    "min_switching_interval": ("s", "shortest time between two crossings of E_i = 0"),
    "chattering": ("N s-1", "total variation of Lambda_i from its jumps, per second"),
    "switching_resolution": ("m", "switching resolution: excursions smaller than this start sliding"),
}

#: A store file's per-run values other than summary figures: name -> (units, long name).
PER_RUN = {
    "run_id": ("", "run id r<index>-<first 8 hex of config_hash>"),
    "base": ("", "label of the run's base configuration"),
    "variant": ("", "controller variant (controller.variant)"),
    "status": ("", "success, failed (gimbal lock, solver failure, non-finite state, timeout) or error"),
    "message": ("", "the solver's message, or why the run failed"),
    "wall_time": ("s", "integration plus post-processing time"),
    "solver_nfev": ("1", "right-hand side evaluations"),
    "solver_njev": ("1", "Jacobian evaluations"),
    "solver_nlu": ("1", "LU decompositions"),
    "solver_status": ("1", "solve_ivp status (0 success, -1 failure, 1 stopped by an event)"),
    "config": ("", "resolved configuration without its name, canonical JSON"),
    "config_hash": ("", "SHA-256 of config without simulation.max_steps and max_wall_time"),
}

#: Distributions whose versions every file records (``<name>_version`` attributes; numba
#: and llvmlite compile the engine).
LIBRARIES = ("numpy", "scipy", "h5py", "h5netcdf", "numba", "llvmlite")


def variable_attributes(name: str) -> dict[str, str]:
    """``units`` (absent for text), ``long_name`` and ``description`` of variable ``name``.

    Raises
    ------
    KeyError
        If ``name`` is not a variable rbstab writes (:data:`LONG_NAMES`).
    """
    attrs = {"units": VARIABLE_UNITS[name]} if name in VARIABLE_UNITS else {}
    attrs["long_name"] = LONG_NAMES[name]
    attrs["description"] = VARIABLE_DESCRIPTIONS[name]
    return attrs


def summary_units(names) -> str:
    """The ``units_of_summary`` attribute of a run file: ``{"t_final": "s", ...}`` as JSON
    for the summary figures ``names`` (text figures, such as the rate check, have ``""``)."""
    return json.dumps({n: SUMMARY_FIGURES.get(n, ("", ""))[0] for n in names}, separators=(",", ":"))


def _git(where: Path, *args: str) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=where, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def git_state_of(places) -> tuple[str, str]:
    """(commit, dirty) of the first of ``places`` (folders) inside a git checkout:
    ``("<40 hex>", "false")``; ``dirty`` is ``"true"`` when tracked files differ from that
    commit (untracked files do not count); ``("unknown", "unknown")`` if none is."""
    for where in places:
        commit = _git(Path(where), "rev-parse", "HEAD")
        if commit:
            changes = _git(Path(where), "status", "--porcelain", "--untracked-files=no")
            return commit, "unknown" if changes is None else str(bool(changes)).lower()
    return "unknown", "unknown"


@functools.lru_cache(maxsize=1)
def git_state() -> tuple[str, str]:
    """:func:`git_state_of` the rbstab checkout in use, once per process: where the package
    is imported from (an editable install), then the working directory when it is an
    rbstab checkout (``pip install .`` run from a clone)."""
    places = [Path(__file__).resolve().parent]
    if (Path.cwd() / "src" / "rbstab").is_dir():
        places.append(Path.cwd())
    return git_state_of(places)


@functools.lru_cache(maxsize=1)
def _versions() -> dict[str, str]:
    out = {"rbstab_version": __version__, "python_version": platform.python_version()}
    for name in LIBRARIES:
        try:
            out[f"{name}_version"] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[f"{name}_version"] = "not installed"
    try:
        import h5py  # heavy: h5py

        out["hdf5_version"] = h5py.version.hdf5_version
    except ImportError:  # pragma: no cover - h5py is a dependency
        out["hdf5_version"] = "unknown"
    return out


def provenance_attributes(title: str, *, command_line: str | None = None,
                          created: str | None = None) -> dict[str, Any]:
    """The global attributes that say what made a file (the same in every file rbstab writes).

    Parameters
    ----------
    title : str
        The ``title`` attribute (what the file holds).
    command_line : str, optional
        The command that made the file (default: this process's argv).
    created : str, optional
        ISO 8601 time of creation (default: now, UTC, to the second).

    Returns
    -------
    dict
        ``Conventions`` (:data:`CONVENTIONS`), ``title``, ``history`` (``"<created>
        <command line>"``, CF), ``source``, ``references``, ``command_line``, ``created``,
        ``rbstab_version``, ``git_commit``, ``git_dirty`` (:func:`git_state`),
        ``python_version``, ``<library>_version`` for :data:`LIBRARIES` and
        ``hdf5_version``.
    """
    command_line = command_line if command_line is not None else " ".join(sys.argv)
    created = created or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    commit, dirty = git_state()
    return {
        "Conventions": CONVENTIONS,
        "title": title,
        "history": f"{created} {command_line}",
        "source": f"rbstab {__version__}",
        "references": REFERENCES,
        "command_line": command_line,
        "created": created,
        **_versions(),
        "git_commit": commit,
        "git_dirty": dirty,
    }
