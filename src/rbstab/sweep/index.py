"""The sweep index: one row per run, rebuilt from the result files.

``index.csv`` (readable by ``pandas.read_csv``; ``.set_index("run_id").to_xarray()`` for
xarray) has the columns, in order:

- ``run_id``, ``run_index`` (position in the run list), ``base`` (label of the base config);
- the varied parameters, one column per scalar: a number or string as is, a list one
  column per entry with the dotted index appended (``initial_state.omega.0``,
  ``controller.k_c.2``), like the ``--set`` paths; for ``scale_uniform`` keys also
  ``<key>:scale`` (the factor drawn);
- ``status`` (``success``, ``failed``, ``error``: the worker raised, no file; ``pending``:
  not run yet, e.g. an interrupted sweep), ``converged`` (True/False, see
  :func:`is_converged`), ``message``, ``wall_time`` [s];
- the ``summary_*`` figures of the file without the prefix, 3-vectors as ``_x``, ``_y``,
  ``_z`` (``max_abs_constraint_error_x``, ``final_omega_z``, ``lyapunov_final``, ...);
- ``solver_nfev``, ``solver_njev``, ``solver_nlu``, ``solver_status``;
- ``config_hash`` and ``file`` (relative to the sweep folder); with ``--layout chunk``
  also ``file_row``, the run's row in that chunk file (:mod:`rbstab.io.chunk`).

``sweep_summary.json`` holds the counts per status, the number and fraction of converged
runs (also per base), and the convergence definition.
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..io.atomic import write_text_atomic

__all__ = ["is_converged", "index_rows", "write_index", "write_summary", "summarize_rows", "STATUSES"]

#: Values of the ``status`` column.
STATUSES = ("success", "failed", "error", "pending")

_AXES = ("x", "y", "z")
_SOLVER = ("nfev", "njev", "nlu", "status")


def is_converged(status: str, lyapunov_initial: Any, lyapunov_final: Any, ratio: float) -> bool:
    """Whether a run converged: it succeeded and ``v(t_end) <= ratio * v(0)``.

    v is the variant's Lyapunov function, zero at the equilibrium (the offset is part of
    v), so this says that the run lost all but ``ratio`` of its initial "energy" within
    ``t_end``. A run that failed (gimbal lock, solver failure, timeout) never converged.
    """
    if status != "success":
        return False
    try:
        v0, v1 = float(lyapunov_initial), float(lyapunov_final)
    except (TypeError, ValueError):
        return False
    return math.isfinite(v0) and math.isfinite(v1) and v1 <= ratio * v0


def _flat(prefix: str, value: Any, out: dict[str, Any], sep: str, names: Sequence[str] | None = None) -> None:
    if isinstance(value, (list, tuple)):
        use_names = names is not None and len(value) == len(names) and not any(
            isinstance(v, (list, tuple)) for v in value
        )
        for i, v in enumerate(value):
            suffix = names[i] if use_names else str(i)
            _flat(f"{prefix}{sep}{suffix}", v, out, sep)
    else:
        out[prefix] = value


def index_rows(
    runs: Sequence[Any],
    attrs: Mapping[str, Mapping[str, Any]],
    errors: Mapping[str, str],
    ratio: float,
) -> list[dict[str, Any]]:
    """One row (a dict in column order) per run of ``runs`` (:class:`~rbstab.sweep.spec.PlannedRun`).

    Parameters
    ----------
    attrs : mapping run_id -> global attributes of its current result file
        (:func:`rbstab.io.hdf5.read_attributes`); runs without one are absent.
    errors : mapping run_id -> message
        Runs whose worker raised (no file): status ``error``.
    ratio : float
        ``convergence.lyapunov_ratio`` (see :func:`is_converged`).
    """
    rows = []
    for run in runs:
        row: dict[str, Any] = {"run_id": run.run_id, "run_index": run.index, "base": run.base}
        for key, value in run.params.items():
            _flat(key, value, row, ".")
        a = attrs.get(run.run_id)
        if a is not None:
            row["status"] = a.get("status", "")
            row["converged"] = is_converged(
                row["status"], a.get("summary_lyapunov_initial"), a.get("summary_lyapunov_final"), ratio
            )
            row["message"] = a.get("message", "")
            row["wall_time"] = a.get("wall_time")
            for key, value in a.items():
                if key.startswith("summary_"):
                    _flat(key[len("summary_"):], value, row, "_", _AXES)
            for key in _SOLVER:
                row[f"solver_{key}"] = a.get(f"solver_{key}")
            row["config_hash"] = a.get("config_hash")
            if "row" in a:  # a row of a chunk file
                row["file"] = f"runs/{a['file']}"
                row["file_row"] = a["row"]
            else:
                row["file"] = f"runs/{run.run_id}.h5"
        elif run.run_id in errors:
            row.update(status="error", converged=False, message=errors[run.run_id])
        else:
            row.update(status="pending", converged=False, message="not run yet (rerun the sweep to finish it)")
        rows.append(row)
    return rows


def _columns(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    head = ["run_id", "run_index", "base"]
    middle = ["status", "converged", "message", "wall_time"]
    tail = [f"solver_{k}" for k in _SOLVER] + ["config_hash", "file"]
    if any("file_row" in row for row in rows):
        tail.append("file_row")
    fixed = set(head + middle + tail)
    params: list[str] = []
    summary: list[str] = []
    seen = set(fixed)
    for row in rows:
        in_params = True
        for key in row:
            if key == "status":
                in_params = False
            if key in seen:
                continue
            seen.add(key)
            (params if in_params else summary).append(key)
    return head + params + middle + summary + tail


def _cell(value: Any) -> Any:
    # csv writes None as "", a float as its repr and anything else as str()
    return json.dumps(value) if isinstance(value, (list, dict)) else value


def write_index(path: Path, rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write ``rows`` as CSV (header: the columns of the module docstring), atomically."""
    columns = _columns(rows)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    return write_text_atomic(path, buf.getvalue())


def _counts(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    status = {s: 0 for s in STATUSES}
    for row in rows:
        status[row["status"]] = status.get(row["status"], 0) + 1
    n = len(rows)
    converged = sum(1 for r in rows if r.get("converged"))
    return {
        "n_runs": n,
        "status": status,
        "n_converged": converged,
        "fraction_converged": converged / n if n else 0.0,
    }


def summarize_rows(rows: Sequence[Mapping[str, Any]], *, name: str, ratio: float) -> dict[str, Any]:
    """The content of ``sweep_summary.json``: counts, converged fraction, per base."""
    out: dict[str, Any] = {"name": name, **_counts(rows)}
    out["convergence"] = {
        "lyapunov_ratio": ratio,
        "definition": "converged = status == 'success' and lyapunov_final <= lyapunov_ratio * lyapunov_initial",
    }
    bases = list(dict.fromkeys(r["base"] for r in rows))
    if len(bases) > 1:
        out["by_base"] = {b: _counts([r for r in rows if r["base"] == b]) for b in bases}
    out["wall_time_total"] = sum(float(r["wall_time"]) for r in rows if r.get("wall_time") is not None)
    out["updated"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out["index"] = "index.csv"
    out["spec"] = "sweep.yaml"
    return out


def write_summary(path: Path, summary: Mapping[str, Any]) -> Path:
    """Write ``summary`` as indented JSON, atomically."""
    return write_text_atomic(path, json.dumps(summary, indent=2) + "\n")
