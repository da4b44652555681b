"""Metadata of the files rbstab writes: variable attributes and provenance.

Both writers, run files (:mod:`rbstab.io.hdf5`) and sweep store files
(:mod:`rbstab.io.chunk`), take from here

- each variable's attributes (:func:`variable_attributes`): ``units`` (CF/UDUNITS
  spelling, :data:`VARIABLE_UNITS`), ``long_name`` (:data:`LONG_NAMES`) and
  ``description`` (the formula and the paper's equation, :data:`VARIABLE_DESCRIPTIONS`),
  all from the table of quantities :data:`rbstab.layout.QUANTITIES`;
- the units and long names of the summary figures (:data:`SUMMARY_FIGURES`, from
  :data:`rbstab.layout.SUMMARY_FIGURES`) and of a store file's other per-run values
  (:data:`PER_RUN`);
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
from ..layout import QUANTITIES
from ..layout import SUMMARY_FIGURES as SUMMARY_QUANTITIES

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

#: Units of every variable of a run or store file (CF/UDUNITS spelling: ``rad s-1``), from
#: :data:`rbstab.layout.QUANTITIES`.
VARIABLE_UNITS = {name: q.units for name, q in QUANTITIES.items() if q.units is not None}
#: What each variable holds, with its formula and the paper's equation.
VARIABLE_DESCRIPTIONS = {name: q.description for name, q in QUANTITIES.items()}
#: Short names of every variable (CF ``long_name``: what a plot's axis says).
LONG_NAMES = {name: q.long_name for name, q in QUANTITIES.items()}

#: Summary figures (:data:`rbstab.layout.SUMMARY_FIGURES`): name -> (units, long name),
#: units ``""`` for a text figure. A run file holds them as ``summary_<name>`` global
#: attributes (units in ``units_of_summary``), a store file as variables along ``run``
#: (3-vectors as ``<name>_x``, ``_y``, ``_z``).
SUMMARY_FIGURES = {name: (q.units or "", q.long_name) for name, q in SUMMARY_QUANTITIES.items()}

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
    "solver_status": ("1", "scipy engine: solve_ivp status (0 success, -1 failure, 1 stopped by an event or a "
                           "limit); compiled and cuda engines: the run's status code (rbstab.engine.status)"),
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
