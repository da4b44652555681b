"""Global sensitivity: Sobol' indices (Saltelli sampling) and Morris elementary effects, by SALib.

A study draws a design of the ``--vary`` factors with SALib, runs it as a sweep
(:func:`rbstab.studies.design.run_design`, resumable) and computes, per metric (a summary
figure of the runs), the indices with bootstrap confidence intervals:

- ``sobol``: Saltelli's scheme on a scrambled Sobol' sequence, ``N (D + 2)`` runs for D
  factors; first-order ``S1`` (the share of the metric's variance explained by the factor
  alone) and total ``ST`` (by the factor with all its interactions) [Saltelli et al. 2010];
- ``morris``: ``N`` trajectories of ``D + 1`` runs on a 4-level grid, ``N (D + 1)`` runs;
  ``mu_star`` (mean absolute elementary effect) and ``sigma`` (their spread: non-linearity
  and interactions) [Morris 1991; Campolongo et al. 2007].

Every factor is sampled on [0, 1] and mapped through the inverse distribution function of
its ``--vary`` distribution (:class:`rbstab.studies.design.Varied`), so indices refer to
the distributions as given; Morris effects are per unit of that quantile (the factor's
whole range is 1).

The result is an :class:`xarray.Dataset` over ``metric`` x ``factor`` written to
``<output>/<name>/sensitivity.nc`` (netCDF-4, CF attributes and rbstab's provenance),
beside the sweep ``<output>/<name>/sweep/``; :func:`read_sensitivity` reads it.

References
----------
A. Saltelli et al., "Variance based sensitivity analysis of model output. Design and
estimator for the total sensitivity index", Comput. Phys. Commun. 181 (2010) 259-270.
M. D. Morris, "Factorial sampling plans for preliminary computational experiments",
Technometrics 33 (1991) 161-174.
J. Herman, W. Usher, "SALib: An open-source Python library for sensitivity analysis",
J. Open Source Softw. 2 (2017) 97.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from ..config import dump_yaml
from ..io.metadata import provenance_attributes
from .design import (
    StudyInputError,
    Varied,
    check_metrics,
    expand_metrics,
    Members,
    members_of,
    nominal_figures,
    parse_vary,
    run_design,
    study_folder,
    vary_mapping,
)
from .files import KINDS, check_same_inputs, read_study_file, write_study_file

__all__ = ["METHODS", "DEFAULT_METRICS", "FILE", "SWEEP_FOLDER", "SensitivityDesign", "plan_sensitivity",
           "analyze_results", "sensitivity_analysis", "read_sensitivity", "metric_records", "TRANSFORMS",
           "split_transform", "RELIABLE_RANGE", "MAX_INTERVAL", "HEAVY_TAIL_DECADES"]

#: Sensitivity methods.
METHODS = ("sobol", "morris")

#: Metrics when none is given: max |E| per axis, v at t_end, the largest dv/dt, converged.
DEFAULT_METRICS = ("max_abs_constraint_error", "lyapunov_final", "max_lyapunov_rate", "converged")

#: The study's result file and its sweep folder, inside ``<output>/<name>/``.
FILE = KINDS["sensitivity"]
SWEEP_FOLDER = "sweep"

#: Levels of the Morris grid.
MORRIS_LEVELS = 4

#: Transforms of a metric before its indices (``--metric log10:lyapunov_final``): the
#: decimal logarithm (a positive metric spread over decades; a value <= 0 has none) and the
#: rank among the runs (any metric; Sobol' indices of the ranks).
TRANSFORMS = ("log10", "rank")

#: A Sobol' index whose value lies outside this range (an index lies in [0, 1]: outside it
#: by more than 0.05 the estimator has failed, not sampled), or whose confidence interval
#: is wider than :data:`MAX_INTERVAL` (half the range), is flagged unreliable.
RELIABLE_RANGE = (-0.05, 1.05)
MAX_INTERVAL = 0.5
#: A positive metric whose largest value over the runs is more than 10 ** this times its
#: smallest is heavy-tailed for Saltelli's estimators: a few runs hold its variance.
HEAVY_TAIL_DECADES = 3.0

#: Indices of each method: variable -> long name.
INDICES = {
    "sobol": {"S1": "first-order Sobol' index", "S1_conf": "half-width of the S1 confidence interval",
              "ST": "total Sobol' index", "ST_conf": "half-width of the ST confidence interval"},
    "morris": {"mu_star": "mean absolute elementary effect (Morris mu*)",
               "mu_star_conf": "half-width of the mu* confidence interval",
               "mu": "mean elementary effect (Morris mu)", "sigma": "standard deviation of the elementary effects"},
}


@dataclass(frozen=True)
class SensitivityDesign:
    """A study's factors and design, before anything runs.

    Attributes
    ----------
    base : RunConfig
    varied : list of Varied
    method : str
    n : int
        SALib's N (base samples for sobol, trajectories for morris).
    seed : int
    metrics : tuple of str
        As given (3-vector figures not yet split into components).
    unit : ndarray, shape (runs, factors)
        SALib's sample on [0, 1].
    design : pandas.DataFrame
        Absolute values, one row per run (:mod:`rbstab.studies.design`).
    """

    base: Any
    varied: list[Varied]
    method: str
    n: int
    seed: int
    metrics: tuple[str, ...]
    unit: np.ndarray
    design: Any

    @property
    def factors(self) -> list[str]:
        return [f for v in self.varied for f in v.factors]

    @property
    def problem(self) -> dict:
        """SALib's problem: every factor on [0, 1]."""
        return {"num_vars": len(self.factors), "names": self.factors, "bounds": [[0.0, 1.0]] * len(self.factors)}


def plan_sensitivity(config, vary: Sequence[str] | Mapping[str, Any], *, n: int, method: str = "sobol",
                     metrics: Sequence[str] | None = None, seed: int = 0) -> SensitivityDesign:
    """Validate a study's options and draw its design (nothing runs).

    Parameters
    ----------
    config : RunConfig
        The base configuration (validated); a chain's takes the keys and figures of chains
        (:mod:`rbstab.studies.design`).
    vary : sequence of str or Mapping
        ``KEY=DISTRIBUTION`` (:func:`rbstab.studies.design.parse_vary`).
    n : int
        sobol: base samples N, a power of 2 (``N (D + 2)`` runs); morris: trajectories
        (``N (D + 1)`` runs).
    method : {"sobol", "morris"}
    metrics : sequence of str, optional
        Summary figures (:func:`rbstab.studies.design.check_metrics`); default
        :data:`DEFAULT_METRICS`.
    seed : int
        Seed of SALib's sampler (and of the bootstrap).

    Raises
    ------
    StudyInputError
        Listing every invalid option (naming the option, the value and what is allowed).
    """
    errors: list[str] = []
    if method not in METHODS:
        errors.append(f"--method {method!r}: expected one of {', '.join(METHODS)}")
    if not isinstance(n, (int, np.integer)) or n < 2 or (method == "sobol" and n & (n - 1)):
        errors.append(f"-n {n!r}: expected " + ("a power of 2 >= 2 (Sobol' sequences), e.g. 256 or 1024"
                                                 if method == "sobol" else "an integer >= 2 (trajectories)"))
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        errors.append(f"--seed {seed!r}: expected an integer >= 0")
    metrics = tuple(metrics or DEFAULT_METRICS)
    bare = []
    for metric in metrics:
        transform, name = split_transform(metric)
        if transform is not None and transform not in TRANSFORMS:
            errors.append(f"--metric {metric!r}: unknown transform {transform!r}; expected NAME, "
                          + " or ".join(f"{t}:NAME" for t in TRANSFORMS))
        bare.append(name)
    varied: list[Varied] = []
    for check in (lambda: check_metrics(bare, members=members_of(config)),
                  lambda: varied.extend(parse_vary(vary, config.resolved))):
        try:
            check()
        except StudyInputError as exc:
            errors += exc.errors
    if errors:
        raise StudyInputError(errors)
    factors = [f for v in varied for f in v.factors]
    problem = {"num_vars": len(factors), "names": factors, "bounds": [[0.0, 1.0]] * len(factors)}
    unit = _sample(problem, int(n), method, int(seed))
    columns: dict[str, Any] = {}
    i = 0
    for v in varied:
        values = v.from_unit(unit[:, i : i + len(v.factors)])
        i += len(v.factors)
        columns.update({c: values[:, j] for j, c in enumerate(v.columns)})
    return SensitivityDesign(config, varied, method, int(n), int(seed), metrics, unit, pd.DataFrame(columns))


def split_transform(metric: str) -> tuple[str | None, str]:
    """``"log10:lyapunov_final"`` -> ``("log10", "lyapunov_final")``; ``(None, metric)``
    without a transform."""
    transform, sep, name = metric.partition(":")
    return (transform, name) if sep else (None, metric)


def _columns(metrics: Sequence[str], available: Sequence[str],
             members: Members | None = None) -> list[tuple[str, str, str | None]]:
    """(label, column, transform) of every metric's columns (3-vectors per component, a
    tree's figures per body or joint of ``members``):
    ``("log10:max_abs_constraint_error_x", "max_abs_constraint_error_x", "log10")``."""
    out: list[tuple[str, str, str | None]] = []
    for metric in metrics:
        transform, name = split_transform(metric)
        for column in expand_metrics([name], available, members=members):
            label = f"{transform}:{column}" if transform else column
            if label not in [o[0] for o in out]:
                out.append((label, column, transform))
    return out


def _transformed(y: np.ndarray, transform: str | None) -> np.ndarray:
    """``y`` through ``transform``: log10 (NaN where y <= 0: counted as without a value),
    rank (average ranks of ties, the non-finite values kept so)."""
    if transform == "log10":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(y > 0, np.log10(np.where(y > 0, y, 1.0)), np.nan)
    if transform == "rank":
        from scipy.stats import rankdata  # heavy: scipy

        return np.where(np.isfinite(y), rankdata(np.where(np.isfinite(y), y, 0.0)), y)
    return y


def decades(y: np.ndarray) -> float:
    """Decades a positive metric spans over the runs (log10 of largest / smallest); NaN
    for a metric with a value <= 0 or none finite."""
    y = y[np.isfinite(y)]
    if y.size == 0 or np.any(y <= 0):
        return float("nan")
    return float(np.log10(y.max() / y.min()))


def _flags(found: dict, spread: float, n: int) -> tuple[dict[str, np.ndarray], str]:
    """Per Sobol' index (``S1``, ``ST``) whether it is unreliable (its value outside
    :data:`RELIABLE_RANGE` or its interval wider than :data:`MAX_INTERVAL`, from SALib's
    values and interval half-widths), and the reason in words (empty when none is)."""
    lo, hi = RELIABLE_RANGE
    flags = {}
    for k in ("S1", "ST"):
        value = np.asarray(found[k], dtype=float)
        half = np.asarray(found[f"{k}_conf"], dtype=float)
        with np.errstate(invalid="ignore"):
            flags[k] = ~((value >= lo) & (value <= hi) & (2 * half <= MAX_INTERVAL))
    if not any(f.any() for f in flags.values()):
        return flags, ""
    what = f"value outside [{lo:g}, {hi:g}] or confidence interval wider than {MAX_INTERVAL:g}"
    if np.isfinite(spread) and spread > HEAVY_TAIL_DECADES:
        why = (f"heavy tails: the metric spans {spread:.1f} decades over the runs, a few runs hold its variance; "
               "use its log10 or rank (--metric log10:NAME or rank:NAME), or more samples")
    else:
        why = f"too few samples for this metric: more samples (-n {4 * n}) narrow the intervals"
    return flags, f"unreliable indices ({what}): {why}"


def _sample(problem: dict, n: int, method: str, seed: int) -> np.ndarray:
    # SALib (with its own imports of scipy.stats, ~0.5 s) only when a study runs
    if method == "sobol":
        from SALib.sample import sobol  # heavy: SALib

        return sobol.sample(problem, n, calc_second_order=False, seed=seed)
    from SALib.sample import morris  # heavy: SALib

    return morris.sample(problem, n, num_levels=MORRIS_LEVELS, seed=seed)


#: Why a metric that takes one value over the design has no indices.
CONSTANT = "this metric is constant over the design; no factor moves it"


def analyze_results(plan: SensitivityDesign, results, *, num_resamples: int = 200,
                    conf_level: float = 0.95):
    """The indices of every metric of ``results`` (:func:`run_design`'s Dataset, one run per
    row of ``plan.design``).

    Returns
    -------
    xarray.Dataset
        Dims ``metric`` x ``factor``: the method's indices (:data:`INDICES`) with
        ``long_name``; per metric ``mean``, ``std`` (its units), ``n_nonfinite`` (runs
        whose value is NaN or infinite, e.g. failed runs, or <= 0 under ``log10``: the
        metric's indices are NaN then) and ``decades`` (the decades a positive metric
        spans, before its transform); for sobol, ``S1_unreliable`` and ``ST_unreliable``
        (1 where the index lies outside :data:`RELIABLE_RANGE` or its confidence interval
        is wider than :data:`MAX_INTERVAL`) and per metric ``note`` (the reason, or
        empty); coords ``factor_key`` (config key of each factor) and ``units`` (of each
        metric; ``1`` for a transformed one).

    Raises
    ------
    StudyInputError
        If a metric is not a figure of these runs.
    """
    columns = _columns(plan.metrics, list(results.data_vars), members_of(plan.base))
    names = [label for label, _, _ in columns]
    indices = INDICES[plan.method]
    table = {k: np.full((len(names), len(plan.factors)), np.nan) for k in indices}
    sobol = plan.method == "sobol"
    flagged = {k: np.zeros((len(names), len(plan.factors)), dtype=np.int8) for k in (("S1", "ST") if sobol else ())}
    notes = [""] * len(names)
    moments = {k: np.full(len(names), np.nan) for k in ("mean", "std")}
    nonfinite = np.zeros(len(names), dtype=np.int64)
    spread = np.full(len(names), np.nan)
    reasons = np.full(len(names), "", dtype=object)
    for m, (name, column, transform) in enumerate(columns):
        raw = results[column].to_numpy().astype(float)
        spread[m] = decades(raw)
        y = _transformed(raw, transform)
        nonfinite[m] = int(np.sum(~np.isfinite(y)))
        moments["mean"][m], moments["std"][m] = (np.nanmean(y), np.nanstd(y)) if nonfinite[m] < len(y) else (np.nan,) * 2
        finite = y[np.isfinite(y)]
        if len(finite) and not np.ptp(finite) > 0:
            reasons[m] = CONSTANT
        elif nonfinite[m]:
            reasons[m] = f"{nonfinite[m]} of {len(y)} runs have no value of this metric; no indices"
        if reasons[m]:
            continue  # no variance to apportion, or runs without a value: no indices (NaN)
        found = _analyze(plan, y, num_resamples, conf_level)
        for k in indices:
            table[k][m] = np.asarray(found[k], dtype=float)
        if sobol:
            flags, notes[m] = _flags(found, spread[m] if transform is None else float("nan"), plan.n)
            for k, f in flags.items():
                flagged[k][m] = f
    units = ["1" if transform else str(results[column].attrs.get("units", "")) for _, column, transform in columns]
    data = {k: (("metric", "factor"), v, {"long_name": indices[k], "units": "1" if k.startswith("S") else ""})
            for k, v in table.items()}
    lo, hi = RELIABLE_RANGE
    for k, f in flagged.items():
        data[f"{k}_unreliable"] = (("metric", "factor"), f, {
            "long_name": f"1 where the {k} index is unreliable: its value outside [{lo:g}, {hi:g}] or its "
                         f"confidence interval wider than {MAX_INTERVAL:g}", "units": "1"})
    data.update(mean=("metric", moments["mean"], {"long_name": "mean of the metric over the runs"}),
                std=("metric", moments["std"], {"long_name": "standard deviation of the metric over the runs"}),
                n_nonfinite=("metric", nonfinite, {"long_name": "runs whose metric is not finite"}),
                decades=("metric", spread, {"long_name": "decades a positive metric spans over the runs "
                                                         "(before its transform; NaN for other metrics)", "units": "1"}),
                reason=("metric", reasons.astype(str), {"long_name": "why the metric has no indices (empty: it has)"}))
    if sobol:
        data["note"] = ("metric", np.array(notes, dtype=object), {"long_name": "why indices are flagged unreliable"})
    factor_keys = [v.key for v in plan.varied for _ in v.factors]
    return xr.Dataset(data, coords={"metric": names, "factor": plan.factors,
                                    "factor_key": ("factor", factor_keys), "units": ("metric", units)})


def _analyze(plan: SensitivityDesign, y: np.ndarray, num_resamples: int, conf_level: float) -> dict:
    # SALib: imported when a study runs (see _sample)
    if plan.method == "sobol":
        from SALib.analyze import sobol  # heavy: SALib

        return sobol.analyze(plan.problem, y, calc_second_order=False, num_resamples=num_resamples,
                             conf_level=conf_level, seed=plan.seed)
    from SALib.analyze import morris  # heavy: SALib

    return morris.analyze(plan.problem, plan.unit, y, num_resamples=num_resamples, conf_level=conf_level,
                          num_levels=MORRIS_LEVELS, seed=plan.seed)


def sensitivity_analysis(config, vary: Sequence[str] | Mapping[str, Any], *, n: int, method: str = "sobol",
                         metrics: Sequence[str] | None = None, seed: int = 0,
                         output: str | os.PathLike = "results/studies", name: str | None = None,
                         num_resamples: int = 200, conf_level: float = 0.95, jobs: int | None = None,
                         executor: Any = None, scheduler: str | None = None, engine: str | None = None, log=None,
                         progress: bool | None = None,
                         command_line: str | None = None, overwrite: bool = False):
    """Run a sensitivity study end to end (``rbstab sensitivity``).

    Parameters
    ----------
    config : RunConfig
        The base configuration: one body's, or a chain's (keys and figures of chains,
        :mod:`rbstab.studies.design`).
    vary, n, method, metrics, seed
        See :func:`plan_sensitivity`.
    output : path-like
        Parent folder: the study writes ``<output>/<name>/`` (``sensitivity.nc`` and the
        sweep ``sweep/``). The same study run again resumes its sweep.
    name : str, optional
        Default: the config's name.
    num_resamples, conf_level
        Bootstrap resamples and level of the confidence intervals.
    jobs, executor, scheduler, engine, log, progress, command_line
        As for :func:`rbstab.studies.design.run_design`.
    overwrite : bool
        Replace a study of other inputs (method, n, seed, vary, base config) in the folder;
        without it that is refused (StudyInputError) before anything runs.

    Returns
    -------
    xarray.Dataset
        :func:`analyze_results`' Dataset with the study's attributes (``method``, ``n``,
        ``seed``, ``n_runs``, ``vary``, the base ``config``, provenance); ``attrs["path"]``
        is the file written.

    Raises
    ------
    StudyInputError
        For an invalid option or metric (before anything runs).
    rbstab.sweep.SweepSpecError
        If a sampled run gives an invalid configuration (e.g. a negative mass drawn from a
        normal distribution; nothing is run).
    """
    folder = study_folder(output, name, config)
    plan = plan_sensitivity(config, vary, n=n, method=method, metrics=metrics, seed=seed)
    expand_metrics([split_transform(m)[1] for m in plan.metrics],
                   list(nominal_figures(config, engine)), members=members_of(config))  # a figure these runs have
    check_same_inputs(folder / FILE, {"method": plan.method, "n": plan.n, "seed": plan.seed,
                                      "vary": json.dumps(vary_mapping(plan.varied)),
                                      "config": dump_yaml(plan.base.resolved)}, overwrite=overwrite)
    say = log or (lambda text: None)
    say(f"{plan.method}: {len(plan.factors)} factors, {len(plan.design)} runs -> {folder / SWEEP_FOLDER}")
    results = run_design(config.resolved, plan.design, folder / SWEEP_FOLDER, jobs=jobs, executor=executor,
                         scheduler=scheduler, engine=engine, log=log, progress=progress, command_line=command_line)
    ds = analyze_results(plan, results, num_resamples=num_resamples, conf_level=conf_level)
    ds.attrs.update(_attributes(plan, results, num_resamples, conf_level, command_line))
    path = write_study_file(ds, folder / FILE)
    ds.attrs["path"] = str(path)
    return ds


def _attributes(plan: SensitivityDesign, results, num_resamples: int, conf_level: float,
                command_line: str | None) -> dict:
    return {
        **provenance_attributes(f"rbstab {plan.method} sensitivity study of {plan.base.name}", command_line=command_line),
        "rbstab_study": "sensitivity",
        "method": plan.method,
        "n": plan.n,
        "seed": plan.seed,
        "n_runs": len(plan.design),
        "n_failed": int(np.sum(results["status"].to_numpy() != "success")),
        "num_resamples": num_resamples,
        "conf_level": conf_level,
        "vary": json.dumps(vary_mapping(plan.varied)),
        "config": dump_yaml(plan.base.resolved),
        "sweep": SWEEP_FOLDER,
    }


def read_sensitivity(path: str | os.PathLike):
    """Read a study's ``sensitivity.nc`` (or the study folder) into memory.

    Raises
    ------
    FileNotFoundError, ValueError
        If there is no such file or it is not a sensitivity study's.
    """
    return read_study_file(path, "sensitivity")


def metric_records(ds) -> list[dict]:
    """One plain mapping per metric (``--json``): ``metric``, ``units``, ``method``,
    ``n_runs``, ``decades``, ``reason`` (why it has no indices, else None), ``note`` (why
    indices are unreliable, or None) and per factor its indices with their interval
    half-widths (null where it has none; sobol: and ``S1_unreliable``, ``ST_unreliable``)."""
    records = []
    names = list(INDICES[ds.attrs["method"]])
    flags = [f"{k}_unreliable" for k in ("S1", "ST") if f"{k}_unreliable" in ds]
    for m, metric in enumerate(ds["metric"].values.tolist()):
        factors = {f: {**{k: _number(ds[k].values[m, i]) for k in names},
                       **{k: bool(ds[k].values[m, i]) for k in flags}}
                   for i, f in enumerate(ds["factor"].values.tolist())}
        note = str(ds["note"].values[m]) if "note" in ds else ""
        reason = str(ds["reason"].values[m]) if "reason" in ds else ""
        records.append({"metric": metric, "units": str(ds["units"].values[m]), "method": ds.attrs["method"],
                        "n_runs": int(ds.attrs["n_runs"]), "n_nonfinite": int(ds["n_nonfinite"].values[m]),
                        "decades": _number(ds["decades"].values[m]) if "decades" in ds else None,
                        "reason": reason or None, "note": note or None, "factors": factors})
    return records


def _number(value) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None
