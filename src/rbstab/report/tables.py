"""Tables of a report: one row per run, figures read back from the result files.

Every figure in these tables is either a summary attribute of the result file
(:func:`rbstab.summary.summarize`, written by the run) or, for the settling time, a
direct function of the stored time series (:func:`settling_time`). Nothing is
recomputed from the physics but one thing: whether a run settled at a rest state that is
linearly unstable, for which the configuration of a run that would otherwise count as
settled is linearised at its rest state, once per distinct physical configuration
(:func:`rest_verdicts`, :func:`rest_outcome`).

Vector figures are split into components ``_1``, ``_2``, ``_3`` (the file's ``axis``
coordinate x, y, z; for Euler angles the rotations about x, y', z'').
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..analysis.linearise import MAX_REST_CHECKS, rest_verdict
from ..analysis.stiffness import fastest_rate
from ..config.identity import canonical_config
from ..convergence import converged
from ..diagnostics import largest_mismatch_time, simulation_rate_check_reason
from ..io.chunk import read_chunk_series, summary_columns
from ..layout import SATURATION_FLAGS, SETTLE_E, SETTLE_OMEGA, STATE_BLOCKS, SUMMARY_FIGURES
from ..summary import settling_times
from .load import RunData, SweepData

__all__ = [
    "SettleThresholds",
    "DEFAULT_SETTLE_E",
    "DEFAULT_SETTLE_OMEGA",
    "DEFAULT_METRICS",
    "SCALAR_SUMMARY_METRICS",
    "VECTOR_SUMMARY_METRICS",
    "allowed_metrics",
    "validate_metrics",
    "member_metric",
    "check_member_metrics",
    "metric_value",
    "metric_label",
    "metric_units",
    "settling_time",
    "run_settling_time",
    "run_rate_check_reason",
    "SETTLED",
    "NOT_SETTLED",
    "REST_AWAY",
    "UNSTABLE_REST",
    "MAX_REST_CHECKS",
    "NOT_CHECKED",
    "rest_outcome",
    "rest_words",
    "rest_verdicts",
    "settle_store_runs",
    "differing_parameters",
    "format_value",
    "runs_table",
    "sweep_table",
    "metric_column",
]

#: Default threshold on |E| (Euclidean norm) for the settling time [m]: the summary figure's.
DEFAULT_SETTLE_E = SETTLE_E
#: Default threshold on |Omega| (Euclidean norm) for the settling time [rad/s]: the summary figure's.
DEFAULT_SETTLE_OMEGA = SETTLE_OMEGA

#: Scalar summary figures usable as ``--metric`` (name -> (symbol, units)), from
#: :data:`rbstab.layout.SUMMARY_FIGURES` (the numbers; not the text of the rate check).
SCALAR_SUMMARY_METRICS = {
    name: (q.symbol, q.display_units) for name, q in SUMMARY_FIGURES.items() if q.size == 1 and q.units is not None
}
#: Vector summary figures usable as ``--metric`` (name -> (symbol, units)); ``NAME`` is
#: the largest |component|, ``NAME_x``, ``NAME_y``, ``NAME_z`` the components (the names of
#: the sweep's ``index.csv`` columns and dataset variables; ``NAME_1`` .. ``_3`` are accepted
#: as the old spelling).
VECTOR_SUMMARY_METRICS = {name: (q.symbol, q.display_units) for name, q in SUMMARY_FIGURES.items() if q.size == 3}
#: Figures of a run that are not summary attributes (name -> (symbol, units)).
OTHER_METRICS = {
    "wall_time": ("wall time", "s"),
    "solver_nfev": ("right-hand side evaluations", "1"),
    "converged": ("converged (1) or not (0)", "1"),
    "settled": ("settled (1) or not (0)", "1"),
}
#: Old metric names -> current ones.
METRIC_ALIASES = {"nfev": "solver_nfev", **{
    f"{key}_{i}": f"{key}_{axis}" for key in VECTOR_SUMMARY_METRICS for i, axis in zip("123", "xyz")}}
_AXES = ("x", "y", "z")
#: Metrics plotted against the varied parameters of a sweep when no ``--metric`` is given.
DEFAULT_METRICS = ("settling_time", "peak_sway", "com_excursion", "cop_excursion", "max_abs_constraint_error",
                   "lyapunov_final")


@dataclass(frozen=True)
class SettleThresholds:
    """Thresholds of the settling time.

    Attributes
    ----------
    e : float
        On |E|, the Euclidean norm of the constraint error [m] (> 0).
    omega : float
        On |Omega|, the Euclidean norm of the angular velocity [rad/s] (> 0).
    """

    e: float = DEFAULT_SETTLE_E
    omega: float = DEFAULT_SETTLE_OMEGA

    def __post_init__(self) -> None:
        if not (self.e > 0 and self.omega > 0):
            raise ValueError(f"settling thresholds must be positive, got e={self.e}, omega={self.omega}")


def allowed_metrics() -> list[str]:
    """Every name accepted by ``--metric``, sorted (besides a chain's figures per body or
    joint, :func:`member_metric`)."""
    names = set(SCALAR_SUMMARY_METRICS) | set(OTHER_METRICS)
    for key in VECTOR_SUMMARY_METRICS:
        names |= {key, *(f"{key}_{axis}" for axis in _AXES)}
    return sorted(names)


def validate_metrics(names: Sequence[str]) -> list[str]:
    """Check metric names; return them without repeats, in order.

    Raises
    ------
    ValueError
        Naming the unknown metrics and listing the allowed ones.
    """
    allowed = allowed_metrics()
    names = [METRIC_ALIASES.get(n, n) for n in names]
    unknown = [n for n in names if n not in allowed and member_metric(n) is None]
    if unknown:
        raise ValueError(f"unknown metric {', '.join(map(repr, unknown))}; allowed: {', '.join(allowed)}; and for a "
                         f"chain's sweep <figure>_<body or joint>[_<axis>] of the figures with an axis "
                         f"(max_abs_constraint_error_hip, final_theta_trunk_x)")
    return list(dict.fromkeys(names))


def member_metric(name: str) -> tuple[str, str, int | None] | None:
    """(figure, member, axis index or None) of a chain's metric of one body or joint:
    ``<figure>_<member>[_<axis>]`` of a figure with an axis (:data:`VECTOR_SUMMARY_METRICS`;
    ``max_abs_constraint_error_hip``: the largest over the hip's axes,
    ``final_theta_trunk_x``: one column of the sweep, :func:`rbstab.io.chunk.summary_columns`);
    None for any other name (one body's ``max_abs_constraint_error_x`` included)."""
    for figure in sorted(VECTOR_SUMMARY_METRICS, key=len, reverse=True):
        rest = name[len(figure) + 1:] if name.startswith(f"{figure}_") else ""
        if not rest or rest in _AXES:
            continue
        member, _, axis = rest.rpartition("_")
        if member and axis in _AXES:
            return figure, member, _AXES.index(axis)
        return figure, rest, None
    return None


def _member_metric_columns(name: str, columns) -> list[str]:
    """The sweep columns a metric of one body or joint (:func:`member_metric`) reads: the
    column of that name, or each axis's of its member; [] where the sweep has none."""
    if name in columns:
        return [name]
    found = member_metric(name)
    if found is None or found[2] is not None:
        return []
    figure, member, _ = found
    axes = [f"{figure}_{member}_{axis}" for axis in _AXES]
    return axes if all(c in columns for c in axes) else []


def check_member_metrics(names: Sequence[str], sweeps: Sequence) -> None:
    """Refuse a chain's metric of one body or joint (:func:`member_metric`) that no sweep of
    ``sweeps`` (:class:`rbstab.report.load.SweepData`) has among its index's columns.

    Raises
    ------
    ValueError
        Naming the metric and the members the sweeps have that figure of.
    """
    columns = {c for sweep in sweeps for c in sweep.index.columns}
    for name in names:
        found = member_metric(name)
        if found is None or _member_metric_columns(name, columns):
            continue
        figure = found[0]
        held = sorted({c.rpartition("_")[0] for c in _member_columns(columns, figure, None)})
        raise ValueError(f"metric {name!r}: no sweep of the report has it; the sweeps' chains have "
                         f"{', '.join(held) if held else 'no such figure (one body, or no chain sweep)'}")


def _split_metric(name: str) -> tuple[str, int | None]:
    if name in VECTOR_SUMMARY_METRICS:
        return name, None
    base, _, comp = name.rpartition("_")
    if base in VECTOR_SUMMARY_METRICS and comp in _AXES:
        return base, _AXES.index(comp)
    return name, None


def _symbol_units(name: str) -> tuple[str, str]:
    """(symbol, units as an axis writes them) of a metric (:func:`allowed_metrics`, or a
    chain's :func:`member_metric`)."""
    found = member_metric(name)
    if found is not None:
        figure, member, comp = found
        symbol, units = VECTOR_SUMMARY_METRICS[figure]
        symbol = f"{symbol}_{_AXES[comp]}" if comp is not None else f"{symbol} (largest component)"
        return f"{symbol} of {member}", units
    base, comp = _split_metric(name)
    if base in VECTOR_SUMMARY_METRICS:
        symbol, units = VECTOR_SUMMARY_METRICS[base]
        return (f"{symbol}_{_AXES[comp]}" if comp is not None else f"{symbol} (largest component)"), units
    return {**SCALAR_SUMMARY_METRICS, **OTHER_METRICS}[base]


def metric_units(name: str) -> str:
    """Units of a metric as an axis writes them (``"m"``, ``"rad/s"``; ``"1"``: none)."""
    return _symbol_units(name)[1]


def metric_label(name: str) -> str:
    """Axis label of a metric with its units, e.g. ``"max |E| [m]"``."""
    symbol, units = _symbol_units(name)
    return f"{symbol} [{units}]" if units != "1" else symbol


def settling_time(time: np.ndarray, error: np.ndarray, omega: np.ndarray, thresholds: SettleThresholds) -> float:
    """First sample time after which |E| and |Omega| stay under their thresholds: one run's
    :func:`rbstab.summary.settling_times` (the summary figure ``settling_time``'s rule) with
    ``thresholds``.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    error : ndarray, shape (n, 3), or (n, joints, 3) for a chain
        Constraint error E [m] (a chain's E_j of every joint: each must hold).
    omega : ndarray, shape (n, 3), or (n, bodies, 3) for a chain
        Angular velocity Omega [rad/s] (a chain's of every body: each must hold).
    thresholds : SettleThresholds
        Bounds on the Euclidean norms |E| [m] and |Omega| [rad/s].

    Returns
    -------
    float
        The earliest ``time[i]`` such that ``|E| <= e`` and ``|Omega| <= omega`` at every
        sample from ``i`` to the end [s]; NaN when the last sample is outside the bounds
        or not finite (a failed run never settles). Resolution: the sample spacing.
    """
    if len(time) == 0:
        return float("nan")
    return float(settling_times(time, np.asarray(error)[None], np.asarray(omega)[None], thresholds.e,
                                thresholds.omega)[0])


#: How a successful run ends (:func:`rest_outcome`), in the report's words.
SETTLED = "settled"
NOT_SETTLED = "not settled"
REST_AWAY = "rest away from equilibrium"
UNSTABLE_REST = "unstable rest"
#: :func:`rest_verdicts` for a configuration beyond :data:`MAX_REST_CHECKS`.
NOT_CHECKED = "not checked"


def rest_outcome(settling_time: float, converged: bool, verdict: str) -> str:
    """How a run ends, in the report's words.

    Parameters
    ----------
    settling_time : float
        :func:`run_settling_time` [s] (NaN: |E| or |Omega| above its threshold at t_end, or
        a failed run).
    converged : bool
        Whether v converged, |v(t_end)| <= ratio v_ref + round-off (:mod:`rbstab.convergence`).
    verdict : str
        Of the linearisation at the rest state of the run's configuration
        (:func:`rest_verdicts`; ``""`` where not known).

    Returns
    -------
    str
        :data:`NOT_SETTLED` without a finite settling time; else :data:`REST_AWAY` where v
        has not converged: at rest (or creeping) away from the rest state v is zero at, e.g.
        leaning; else :data:`UNSTABLE_REST` where that rest state is linearly ``unstable``:
        at rest beside it, the body has not yet drifted away; else :data:`SETTLED`.
    """
    if not np.isfinite(settling_time):
        return NOT_SETTLED
    if not converged:
        return REST_AWAY
    return UNSTABLE_REST if verdict == "unstable" else SETTLED


def rest_words(thresholds: SettleThresholds) -> str:
    """What :func:`rest_outcome`'s words mean, for the pages of a report."""
    return (f"Settled: |E| <= {thresholds.e:g} m and |Omega| <= {thresholds.omega:g} rad/s (Euclidean norms) from "
            "the settling time to t_end, v converged (|v(t_end)| <= ratio v_ref, v_ref the energy it had to lose: the sweep's ratio, 0.001 for a run "
            "given directly) and the rest state where v is zero is not linearly unstable. Otherwise: 'not settled' "
            "(above a threshold at t_end, or failed); 'rest away from equilibrium' (below the thresholds but v "
            "not converged: at rest, or creeping, away from the rest state v is zero at, e.g. leaning); 'unstable "
            "rest' (below the thresholds and v converged, but the linearisation at that rest state is unstable: "
            "it has not yet drifted away). The settling time is given for a settled run only.")


def physical_key(config: Mapping) -> str:
    """What sets a run's rest state and its linearisation: its resolved configuration
    without ``name``, ``initial_state`` and ``simulation``, as canonical JSON."""
    return canonical_config({k: v for k, v in config.items() if k not in ("initial_state", "simulation")})


_REST_KEY = ("rest_verdict",)  # tuples: RunData.drop_series keeps them
_PHYSICAL_KEY = ("physical_key",)


def _physical_key(run: RunData) -> str:
    """:func:`physical_key` of a run's configuration, cached on the run."""
    if _PHYSICAL_KEY not in run._cache:
        run._cache[_PHYSICAL_KEY] = physical_key(run.config)
    return run._cache[_PHYSICAL_KEY]


def rest_verdicts(runs: Sequence[RunData | None], wanted: Sequence[bool]) -> list[str]:
    """The verdict at the rest state of each run's configuration (:func:`rest_verdict`):
    the configurations of the runs where ``wanted`` (a run that would otherwise count as
    settled), each distinct physical configuration (:func:`physical_key`) once and at most
    :data:`MAX_REST_CHECKS` of them (beyond: :data:`NOT_CHECKED`); every run of a
    configuration so linearised gets its verdict, the others ``""``. Cached per run."""
    found: dict[str, str] = {}
    keys: list[str | None] = []
    for run in runs:
        key = None if run is None else _physical_key(run)
        keys.append(key)
        if key is not None and _REST_KEY in run._cache:
            found.setdefault(key, run._cache[_REST_KEY])
    checked = sum(v != NOT_CHECKED for v in found.values())
    for run, key, want in zip(runs, keys, wanted):
        if not want or key is None or key in found:
            continue
        if checked < MAX_REST_CHECKS:
            found[key] = rest_verdict(run.config, run.name)
            checked += 1
        else:
            found[key] = NOT_CHECKED
    out = []
    for run, key in zip(runs, keys):
        verdict = found.get(key, "") if key is not None else ""
        if verdict:
            run._cache[_REST_KEY] = verdict
        out.append(verdict)
    return out


_RATE_CHECK_KEY = ("rate_check_reason",)


def run_rate_check_reason(run: RunData) -> str:
    """Why a run's rate check failed, ``""`` unless it did: the mismatch against the
    tolerance and the fix (:func:`rbstab.diagnostics.simulation_rate_check_reason`, with the
    time of the largest mismatch where the file holds both rates and the fastest mode of
    the run's linearisation at rest, :func:`rbstab.analysis.stiffness.fastest_rate`).
    Cached per run."""
    if run.summary.get("lyapunov_rate_check") != "fail":
        return ""
    if _RATE_CHECK_KEY not in run._cache:
        s = run.series("lyapunov_rate", "lyapunov_rate_numerical")
        where = (largest_mismatch_time(s["time"], s["lyapunov_rate"], s["lyapunov_rate_numerical"])
                 if "lyapunov_rate_numerical" in s and "lyapunov_rate" in s else None)
        run._cache[_RATE_CHECK_KEY] = simulation_rate_check_reason(
            run.summary, run.config["simulation"], where=where, fastest=fastest_rate(run.config))
        if run.sweep is not None:
            run.drop_series()  # a sweep may hold thousands of runs: keep only the text
    return run._cache[_RATE_CHECK_KEY]


def _settling_key(thresholds: SettleThresholds) -> tuple:
    return ("settling_time", thresholds.e, thresholds.omega)


def run_settling_time(run: RunData, thresholds: SettleThresholds) -> float:
    """:func:`settling_time` of a run's stored ``constraint_error`` and ``omega`` [s].

    NaN for a failed run (its trajectory stops before ``t_end``). A run without these
    series (a summary store) has its summary figure ``settling_time`` at the default
    thresholds (:data:`DEFAULT_SETTLE_E`, :data:`DEFAULT_SETTLE_OMEGA`; computed from every
    sample as it ran), NaN at others or where the file has none. Cached per run and
    thresholds; the series of a sweep's run are not kept in memory.
    """
    if not run.ok:
        return float("nan")
    key = _settling_key(thresholds)
    if key not in run._cache:
        s = run.series("constraint_error", "omega")
        held = all(n in s for n in ("time", "constraint_error", "omega"))  # not in a summary store
        if held:
            run._cache[key] = settling_time(s["time"], s["constraint_error"], s["omega"], thresholds)
        elif thresholds == SettleThresholds():
            run._cache[key] = float(run.summary.get("settling_time", np.nan))
        else:
            run._cache[key] = float("nan")
        if run.sweep is not None:
            run.drop_series()  # a sweep may hold thousands of runs: keep only the figure
    return run._cache[key]


def settle_store_runs(runs: Sequence[RunData | None], thresholds: SettleThresholds) -> None:
    """Compute :func:`run_settling_time` of the successful runs held in sweep store files
    (``run.row`` set) a file at a time: each file's ``time``, ``constraint_error`` and
    ``omega`` are read once for all its runs (a run at a time, reopening the file, costs
    ~3 ms a run, :func:`rbstab.io.chunk.read_chunk_series` of every row); the figures
    [s] land in each run's cache, the traces are not kept. Runs of a store without traces
    are left to :func:`run_settling_time` (NaN). The files were verified when the report
    loaded them (:func:`rbstab.report.load.load_chunk_runs`); OSError if one is gone."""
    key = _settling_key(thresholds)
    by_file: dict = {}
    for run in runs:
        if run is not None and run.ok and run.row is not None and key not in run._cache:
            by_file.setdefault(run.path, []).append(run)
    for path, members in by_file.items():
        s = read_chunk_series(path, None, ("constraint_error", "omega"))
        if any(s[name] is None for name in ("time", "constraint_error", "omega")):
            continue
        for run in members:
            run._cache[key] = settling_time(s["time"], s["constraint_error"][run.row], s["omega"][run.row], thresholds)


def metric_value(run: RunData | None, name: str, thresholds: SettleThresholds | None = None) -> float:
    """Value of metric ``name`` (:func:`allowed_metrics`) for one run, NaN if unavailable.

    Summary metrics come from the file's ``summary_*`` attributes; ``settling_time``
    from :func:`run_settling_time`; ``wall_time`` and ``nfev`` from the attributes.
    """
    if run is None:
        return float("nan")
    base, comp = _split_metric(name)
    if base == "settling_time":
        return run_settling_time(run, thresholds or SettleThresholds())
    if base == "wall_time":
        return float(run.wall_time)
    if base == "solver_nfev":
        return float(run.solver.get("nfev", np.nan))
    if base in ("converged", "settled"):
        return float("nan")  # a sweep's definition, or the report's: read from its table (sweep_table)
    value = run.summary.get(base)
    if value is None:
        return float("nan")
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value, dtype=float)
        return float(arr[comp]) if comp is not None else float(np.max(np.abs(arr)))
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _canonical(value: Any) -> str:
    return repr(value)


def differing_parameters(runs: Sequence[RunData], exclude: Sequence[str] = ("name",)) -> list[str]:
    """Dotted configuration keys whose values differ between ``runs``.

    Parameters
    ----------
    runs : sequence of RunData
    exclude : sequence of str
        Keys never reported (default: ``name``, which the run label already shows).

    Returns
    -------
    list of str
        Keys of :func:`rbstab.report.load.flatten_config` (a key absent from some runs
        counts as differing), in first-seen order; empty for fewer than two runs. Runs of
        one body and chains are compared among their own kind (their keys are another
        spelling): the keys that differ among either.
    """
    kinds = {run.members is None for run in runs}
    if len(kinds) > 1:
        found = [differing_parameters([r for r in runs if (r.members is None) == kind], exclude) for kind in (True, False)]
        return list(dict.fromkeys([*found[0], *found[1]]))
    if len(runs) < 2:
        return []
    keys: dict[str, None] = {}
    for run in runs:
        keys.update(dict.fromkeys(run.flat_config))
    out = []
    for key in keys:
        if key in exclude:
            continue
        values = {_canonical(run.flat_config.get(key, "<absent>")) for run in runs}
        if len(values) > 1:
            out.append(key)
    return out


def format_value(value: Any, digits: int = 4) -> str:
    """Compact text of a table cell: floats with ``digits`` significant digits, diagonal
    matrices as ``diag(a, b, c)``, vectors as ``[a, b, c]``, None/NaN as ``-``."""
    if value is None:
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "-" if not np.isfinite(value) else f"{value:.{digits}g}"
    if isinstance(value, (list, tuple, np.ndarray)):
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            return "[" + ", ".join(format_value(v, digits) for v in value) + "]"
        if arr.ndim == 2 and arr.shape[0] == arr.shape[1] and np.all(arr == np.diag(np.diag(arr))):
            return "diag(" + ", ".join(format_value(v, digits) for v in np.diag(arr)) + ")"
        if arr.ndim == 2:
            return "[" + "; ".join(", ".join(format_value(v, digits) for v in row) for row in arr) + "]"
        return "[" + ", ".join(format_value(v, digits) for v in arr) + "]"
    return str(value)


def _vector(run: RunData, key: str) -> list[float]:
    value = run.summary.get(key)
    if value is None:
        return [float("nan")] * 3
    return [float(v) for v in np.asarray(value, dtype=float).reshape(-1)[:3]]


def _identity(run: RunData, parameters: Sequence[str]) -> dict[str, Any]:
    """The first columns of a run's row: who it is, how it ended, the ``parameters``' values."""
    row: dict[str, Any] = {"run": run.label, "file": str(run.path), "sweep": run.sweep or "", "variant": run.variant,
                           "status": run.status, "message": run.message}
    return row | {key: run.flat_config.get(key) for key in parameters}


def _solver(run: RunData) -> dict[str, Any]:
    """The last columns of a run's row: the method and the solver's statistics."""
    return {"method": run.flat_config.get("simulation.method", ""),
            **{key: run.solver.get(key) for key in ("nfev", "njev", "nlu")}, "wall_time": run.wall_time}


def runs_table(runs: Sequence[RunData], thresholds: SettleThresholds, parameters: Sequence[str] | None = None):
    """One row per run: identity, differing parameters, final state, constraint and
    Lyapunov figures, solver statistics.

    Parameters
    ----------
    runs : sequence of RunData
    thresholds : SettleThresholds
        For the ``settling_time`` column.
    parameters : sequence of str, optional
        Dotted configuration keys to show (default :func:`differing_parameters`).

    Returns
    -------
    pandas.DataFrame
        Columns (in order): ``run``, ``file``, ``sweep``, ``variant``, ``status``,
        ``message``, the ``parameters`` (raw configuration values), ``t_final`` [s],
        ``final_theta_1..3`` [rad], ``final_omega_1..3`` [rad/s],
        ``final_position_1..3`` [m], ``final_velocity_1..3`` [m/s],
        ``final_controller_state_1..3`` [m] (NaN outside ``embedded``),
        ``max_abs_constraint_error_1..3`` [m], ``settling_time`` [s] (NaN: not settled),
        ``rest`` (:func:`rest_outcome`: settled, not settled, rest away from equilibrium,
        unstable rest; v converged by the default ratio), ``rest_state`` (the verdict of
        the linearisation at the rest state, :func:`rest_verdicts`; empty where not
        needed), ``lyapunov_initial`` [J], ``lyapunov_final`` [J], ``max_lyapunov_rate`` [W],
        ``lyapunov_rate_mismatch`` [W], ``lyapunov_rate_mismatch_relative``,
        ``lyapunov_rate_check``, ``max_lyapunov_increase`` [J], ``time_lyapunov_rising`` [s],
        ``fraction_saturated_torque_n_1..3``, ``_force_h_1..3``, ``_constraint_force_1..3``
        (NaN for a file without them), ``method``, ``nfev``, ``njev``, ``nlu``,
        ``wall_time`` [s]. Values as stored in the files (full precision). A chain's run
        has its figures per body or joint in columns of their own instead of the ``_1..3``
        ones, as its sweeps' store them (:func:`rbstab.io.chunk.summary_columns`):
        ``final_theta_<body>_<axis>`` ..., ``max_abs_constraint_error_<joint>_<axis>``,
        ``fraction_saturated_torque_n_<joint>_<axis>`` ...; its settling time bounds every
        joint's |E_j| and every body's |Omega| (:func:`settling_time`).
    """
    import pandas as pd  # heavy: pandas

    if parameters is None:
        parameters = differing_parameters(runs)
    settle_store_runs(runs, thresholds)
    times = [run_settling_time(run, thresholds) for run in runs]
    v_converged = [_run_converged(run) for run in runs]
    verdicts = rest_verdicts(runs, [bool(np.isfinite(t)) and c for t, c in zip(times, v_converged)])
    rows = []
    for run, time, run_converged, verdict in zip(runs, times, v_converged, verdicts):
        row = _identity(run, parameters)
        row["t_final"] = float(run.summary.get("t_final", np.nan))
        row.update(_vector_columns(run, [f"final_{block}" for block in STATE_BLOCKS] + ["max_abs_constraint_error"]))
        row["rest"] = rest_outcome(time, run_converged, verdict)
        row["rest_state"] = verdict
        row["settling_time"] = time if row["rest"] == SETTLED else float("nan")
        for key in ("lyapunov_initial", "lyapunov_final", "max_lyapunov_rate", "lyapunov_rate_mismatch",
                    "lyapunov_rate_mismatch_relative"):
            row[key] = float(run.summary.get(key, np.nan))
        row["lyapunov_rate_check"] = run.summary.get("lyapunov_rate_check", "")
        for key in ("max_lyapunov_increase", "time_lyapunov_rising"):
            row[key] = float(run.summary.get(key, np.nan))
        row.update(_vector_columns(run, [figure for _, figure in SATURATION_FLAGS.values()]))
        rows.append(row | _solver(run))
    return pd.DataFrame(rows)


def _vector_columns(run: RunData, figures: Sequence[str]) -> dict[str, float]:
    """The columns of the summary figures ``figures`` (3-vectors) of a run: one body's as
    ``<figure>_1..3`` (NaN where the file lacks one), a chain's per body or joint
    (:func:`rbstab.io.chunk.summary_columns`; none where the file lacks it)."""
    members = run.members
    if members is None:
        return {f"{figure}_{i}": v for figure in figures for i, v in enumerate(_vector(run, figure), start=1)}
    held = {figure: run.summary[figure] for figure in figures if run.summary.get(figure) is not None}
    return {key: float(v) for key, v in summary_columns(held, members["joint"], members["body"]).items()}


def sweep_table(sweep: SweepData, metrics: Sequence[str], thresholds: SettleThresholds):
    """The sweep's ``index.csv`` with the chosen metrics read back from each run file.

    Returns
    -------
    pandas.DataFrame
        ``index.csv`` columns first, then the grouped list parameters of
        :attr:`SweepData.axes` not already a column, then ``report:<metric>`` for each
        metric (NaN for rows without a file; ``settling_time`` NaN unless settled),
        ``report:settled`` (bool: :func:`rest_outcome` is ``settled``), ``report:rest``
        (:func:`rest_outcome`, with the sweep's ``converged``) and ``report:rest_state``
        (:func:`rest_verdicts`: the verdict of the linearisation at the rest state of the
        run's configuration, for the configurations of runs that would otherwise count as
        settled; empty for the others).
    """
    settle_store_runs(sweep.runs, thresholds)
    table = sweep.index.copy()
    for name, values in sweep.axes.items():
        if name not in table.columns:
            table[name] = list(values)
    times = [run_settling_time(run, thresholds) if run is not None else float("nan") for run in sweep.runs]
    v_converged = _converged(table, sweep)
    verdicts = rest_verdicts(sweep.runs, [bool(np.isfinite(t)) and c for t, c in zip(times, v_converged)])
    rest = [rest_outcome(t, c, v) for t, c, v in zip(times, v_converged, verdicts)]
    settled = [r == SETTLED for r in rest]
    for name in metrics:
        if name == "settling_time":
            table[metric_column(name)] = [t if ok else float("nan") for t, ok in zip(times, settled)]
        elif name == "settled":
            table[metric_column(name)] = settled  # report:settled itself
        else:
            table[metric_column(name)] = _index_metric(table, name, sweep, thresholds)
    table["report:settled"] = settled
    table["report:rest"] = rest
    table["report:rest_state"] = verdicts
    return table


def _converged(table, sweep: SweepData) -> list[bool]:
    """Whether each run's v converged: the sweep's own ``converged`` column (its ratio), or
    for an index without it :func:`rbstab.convergence.converged` of the run's summary."""
    if "converged" in table.columns:
        return list(table["converged"].astype(str).eq("True") & table["status"].astype(str).eq("success"))
    return [run is not None and _run_converged(run) for run in sweep.runs]


def _run_converged(run: RunData) -> bool:
    """:func:`rbstab.convergence.converged` of a run's summary (the default ratio)."""
    s = run.summary
    return bool(converged(run.ok, s.get("lyapunov_initial"), s.get("lyapunov_final"),
                          max_increase=s.get("max_lyapunov_increase")))


def _index_metric(table, name: str, sweep: SweepData, thresholds: SettleThresholds):
    """A metric of every run of a sweep: the index column of that name (the same names),
    the largest |component| of a vector's columns, or read from the runs (settling time)."""
    if name == "converged":
        return table["converged"].astype(str).eq("True").astype(float).where(table["status"] == "success")
    if name in table.columns:
        return table[name].astype(float).where(table["status"] == "success")
    member = _member_metric_columns(name, table.columns)
    if member:  # one body's or joint's axes: the largest |component|
        return table[member].astype(float).abs().max(axis=1, skipna=False).where(table["status"] == "success")
    base, comp = _split_metric(name)
    columns = [f"{base}_{axis}" for axis in _AXES]
    if base in VECTOR_SUMMARY_METRICS and comp is None and all(c in table.columns for c in columns):
        return table[columns].astype(float).abs().max(axis=1, skipna=False).where(table["status"] == "success")
    members = _member_columns(table.columns, base, comp) if base in VECTOR_SUMMARY_METRICS else []
    if members:  # a chain's sweep: the largest over its bodies or joints
        return table[members].astype(float).abs().max(axis=1).where(table["status"] == "success")
    return [metric_value(run, name, thresholds) for run in sweep.runs]


def _member_columns(columns, base: str, comp: int | None) -> list[str]:
    """A chain sweep's columns ``<base>_<member>_<axis>`` of the vector figure ``base``
    (:func:`rbstab.io.chunk.summary_columns`), of component ``comp`` only unless None."""
    axes = _AXES if comp is None else (_AXES[comp],)
    return [c for c in columns if c.startswith(f"{base}_") and c.rpartition("_")[2] in axes
            and c.rpartition("_")[0] != base]


def metric_column(name: str) -> str:
    """Column of :func:`sweep_table` holding metric ``name``: ``report:<name>``."""
    return f"report:{name}"
