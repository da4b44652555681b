"""Run result files: netCDF-4 flavoured HDF5 (h5py dimension scales), read by xarray.

Layout of ``<name>.h5``
-----------------------
- dimensions ``time`` (samples, coordinate in s) and ``axis`` (``x``, ``y``, ``z``);
- one variable per output quantity (``theta``, ``omega``, ``position``, ``velocity``,
  ``controller_state`` (embedded only), ``constraint_error``, ``constraint_rate``,
  ``constraint_force``, ``force_h``, ``torque_n``, ``lyapunov``, ``lyapunov_rate``,
  ``lyapunov_rate_numerical`` and the terms of v), each with ``units`` and
  ``description`` attributes;
- global attributes: ``rbstab_format``, ``name``, ``variant``, ``status``, ``message``,
  ``config`` (the resolved configuration as YAML text), ``config_hash``,
  ``rbstab_version``, ``git_commit``, ``command_line``, ``created``, ``wall_time``,
  ``solver_*`` statistics and ``summary_*`` figures (:func:`rbstab.summary.summarize`).

Open with ``xarray.open_dataset(path, engine="h5netcdf")``. Files are written to a
temporary name in the target folder and renamed into place, so an interrupted write
never leaves a half-written result under the final name.
"""

from __future__ import annotations

import datetime as _dt
import functools
import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import __version__
from ..layout import BLOCK_DESCRIPTIONS, BLOCK_UNITS
from ..variants import OUTPUT_DESCRIPTIONS, OUTPUT_UNITS

if TYPE_CHECKING:  # pragma: no cover
    from ..simulate import RunResult

__all__ = [
    "FORMAT",
    "VARIABLE_UNITS",
    "VARIABLE_DESCRIPTIONS",
    "write_result",
    "read_attributes",
    "read_summary",
    "config_hash",
    "NotAResultFile",
]

#: Value of the ``rbstab_format`` global attribute of every result file.
FORMAT = "rbstab-run-1"

#: Units of every variable of a result file.
VARIABLE_UNITS = {**BLOCK_UNITS, **OUTPUT_UNITS, "lyapunov_rate_numerical": "W"}
#: Description of every variable of a result file.
VARIABLE_DESCRIPTIONS = {
    **BLOCK_DESCRIPTIONS,
    **OUTPUT_DESCRIPTIONS,
    "lyapunov_rate_numerical": "dv/dt by differentiating v along the dense-output samples "
    "(quintic spline); compare with lyapunov_rate",
}


class NotAResultFile(ValueError):
    """Raised when a file is not an rbstab run result."""


@functools.lru_cache(maxsize=1)
def _git_commit() -> str:
    """Commit of the rbstab checkout in use, or ``"unknown"``.

    Looks where the package is imported from (an editable install), then in the working
    directory when it is an rbstab checkout (``pip install .`` run from a clone).
    """
    candidates = [Path(__file__).resolve().parent]
    if (Path.cwd() / "src" / "rbstab").is_dir():
        candidates.append(Path.cwd())
    for where in candidates:
        try:
            out = subprocess.run(
                ["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=5
            )
        except (OSError, subprocess.SubprocessError):
            continue
        commit = out.stdout.strip()
        if out.returncode == 0 and commit:
            return commit
    return "unknown"


def config_hash(config_yaml: str) -> str:
    """SHA-256 hex digest of the resolved configuration's YAML text."""
    return hashlib.sha256(config_yaml.encode()).hexdigest()


def _attr_value(value: Any) -> Any:
    if isinstance(value, (list, tuple)):
        return np.asarray(value, dtype=float)
    return value


def write_result(result: "RunResult", path: str | os.PathLike, *, command_line: str | None = None) -> Path:
    """Write one run to ``path`` atomically (temporary file + rename).

    Parameters
    ----------
    result : RunResult
        The run (:func:`rbstab.simulate.simulate`).
    path : path-like
        Final file name; its folder is created if missing.
    command_line : str, optional
        Recorded in the ``command_line`` attribute (default: this process's argv).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OSError
        If the folder cannot be created or written; the final name is then untouched.
    """
    import h5py

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    config_yaml = result.config.to_yaml()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)  # mkstemp makes 0600; a result file follows the umask
    os.close(fd)
    try:
        # netCDF-4 conventions through HDF5 dimension scales, written with h5py directly:
        # the same file h5netcdf would write, several times faster (h5netcdf's per-variable
        # bookkeeping cost ~0.1 s per file).
        with h5py.File(tmp, "w", track_order=True) as f:
            time = f.create_dataset("time", data=np.asarray(result.time, dtype=float))
            time.make_scale("time")
            time.attrs["units"] = "s"
            time.attrs["description"] = "sample time, evenly spaced dense output of the solver"
            axis = f.create_dataset("axis", data=np.array(["x", "y", "z"], dtype=object), dtype=h5py.string_dtype())
            axis.make_scale("axis")
            axis.attrs["description"] = "vector component; frame given by each variable"
            for key, values in result.outputs.items():
                var = f.create_dataset(key, data=np.asarray(values, dtype=float))
                var.dims[0].attach_scale(time)
                if var.ndim == 2:
                    var.dims[1].attach_scale(axis)
                var.attrs["units"] = VARIABLE_UNITS[key]
                var.attrs["description"] = VARIABLE_DESCRIPTIONS[key]
            attrs = {
                "rbstab_format": FORMAT,
                "name": result.name,
                "variant": result.config.variant,
                "status": result.status,
                "message": result.message,
                "config": config_yaml,
                "config_hash": config_hash(config_yaml),
                "rbstab_version": __version__,
                "git_commit": _git_commit(),
                "command_line": command_line if command_line is not None else " ".join(sys.argv),
                "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                "wall_time": float(result.wall_time),
            }
            attrs.update({f"solver_{k}": v for k, v in result.solver.items() if not k.startswith("solver_")})
            attrs["solver_status"] = int(result.solver.get("solver_status", -1))
            attrs["solver_message"] = result.message
            attrs.update({f"summary_{k}": _attr_value(v) for k, v in result.summary.items()})
            for key, value in attrs.items():
                f.attrs[key] = value
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray):
        return value.item() if value.shape in ((), (1,)) else value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_attributes(path: str | os.PathLike) -> dict[str, Any]:
    """Global attributes of a result file as plain Python values.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotAResultFile
        If it is not an HDF5 file written by rbstab.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such result file: {path}")
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: _plain(v) for k, v in f.attrs.items()}
    except OSError as exc:
        raise NotAResultFile(f"{path}: not an HDF5 file ({exc})") from None
    if attrs.get("rbstab_format") != FORMAT:
        raise NotAResultFile(f"{path}: not an rbstab run result (no rbstab_format = {FORMAT!r} attribute)")
    return attrs


def read_summary(path: str | os.PathLike) -> dict[str, Any]:
    """Identity, status, solver statistics and summary figures of a result file.

    Returns
    -------
    dict
        ``name``, ``variant``, ``status``, ``message``, ``config_hash``, ``wall_time``,
        ``solver`` (dict) and ``summary`` (dict, keys of
        :func:`rbstab.summary.summarize`).

    Raises
    ------
    FileNotFoundError, NotAResultFile
        See :func:`read_attributes`.
    """
    attrs = read_attributes(path)
    return {
        "name": attrs["name"],
        "variant": attrs["variant"],
        "status": attrs["status"],
        "message": attrs["message"],
        "config_hash": attrs["config_hash"],
        "wall_time": attrs["wall_time"],
        "created": attrs["created"],
        "solver": {k[len("solver_"):]: v for k, v in attrs.items() if k.startswith("solver_")},
        "summary": {k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")},
    }
