"""Tuning: search gains (or any numeric config keys) that meet a specification best, by Optuna.

The study asks Optuna for a **generation** of trials at once (Optuna's ask-and-tell
interface): the first generation space-filling (a scrambled Sobol' sequence), then
multivariate TPE (by default) or CMA-ES with restarts (:mod:`rbstab.studies.search`). Each
trial sets the ``--vary`` keys to the values suggested; with ``over``, it runs them on a
batch of uncertain bodies (one draw of the ``over`` distributions, the same for every
trial) whose worst case (or a chosen quantile) is the trial's value. The generation's runs
(trials x bodies) are one table of runs integrated as one batch on the sweep's engine
(:mod:`rbstab.studies.batch`: compiled or cuda, in this process or on an executor), and
the objectives are told to Optuna when the whole generation is done. Objectives and constraints are
summary figures of the runs (:func:`rbstab.studies.design.check_metrics`); constraints go
to the sampler as Optuna constraints (a trial is feasible when every ``metric <= limit``,
``metric >= limit`` holds).

The study lives in an Optuna storage (default: Optuna's journal storage in the SQLite file
``<output>/<name>/journal.db``, :mod:`rbstab.studies.storage`), into which a generation's
trials go once they are all finished (a generation is stored whole, values and all, or not
at all), so running the same study again resumes it at the last finished generation
(``trials`` is the number of complete trials the study should reach) and several processes
can work on one study at once. Written
into ``<output>/<name>/``: ``best.yaml`` (the base configuration with the best values:
``rbstab run best.yaml`` runs it), ``trials.csv`` and ``tuning.nc`` (every trial: number,
state, objective and constraint values, the absolute values set; :func:`read_tuning`).

References
----------
T. Akiba et al., "Optuna: A next-generation hyperparameter optimization framework",
KDD 2019. J. Bergstra et al., "Algorithms for hyper-parameter optimization" (TPE),
NeurIPS 2011. N. Hansen, "The CMA evolution strategy: a tutorial", arXiv:1604.00772.
"""

from __future__ import annotations

import contextlib
import copy
import json
import math
import os
import re
import signal
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from ..config import ConfigError, dump_yaml
from ..config.loader import config_from_mapping
from ..engine import ensure_compiled, kernel_groups
from ..results import plain
from ..engine.registry import DEFAULT_ENGINE, get_engine
from ..io.atomic import write_text_atomic
from ..io.chunk import figure_attributes
from ..io.metadata import provenance_attributes
from ..sweep.validate import key_path
from ..warning_codes import coded
from .design import (
    LOG_SCALED,
    StudyInputError,
    Varied,
    check_metrics,
    design_mappings,
    expand_metrics,
    Members,
    members_of,
    nominal_figures,
    parse_vary,
    study_folder,
    vary_mapping,
)
from .files import KINDS, check_same_inputs, read_study_file, write_study_file

__all__ = ["SAMPLERS", "Objective", "Constraint", "parse_constraint", "TuningProblem", "TuningResult",
           "plan_tuning", "tune", "read_tuning", "FILE", "BEST_FILE", "TRIALS_FILE"]

#: Samplers after the space-filling start: Optuna's multivariate TPE (default;
#: constraints, several objectives) and CMA-ES with restarts (one objective, no constraints).
SAMPLERS = ("tpe", "cmaes")
#: Trials of a generation by default: a CPU engine's batch, and a GPU's.
GENERATION = {"compiled": 32, "cuda": 2048}

#: Files of a tuning study inside ``<output>/<name>/``.
FILE = KINDS["tuning"]
BEST_FILE = "best.yaml"
TRIALS_FILE = "trials.csv"

#: Distributions a search range may have (a range needs bounds).
RANGES = ("uniform", "log_uniform", "scale_uniform", "scale_log_uniform", "choice")

_CONSTRAINT = re.compile(r"^\s*(?P<metric>[A-Za-z_][A-Za-z0-9_]*)\s*(?P<op><=|>=)\s*(?P<limit>\S+)\s*$")


@dataclass(frozen=True)
class Objective:
    """A metric to minimize or maximize (``direction``)."""

    metric: str
    direction: str = "minimize"


@dataclass(frozen=True)
class Constraint:
    """``metric <= limit`` or ``metric >= limit`` (``op``)."""

    metric: str
    op: str
    limit: float

    def excess(self, value: float) -> float:
        """How far ``value`` violates the constraint (<= 0: met), as Optuna takes it."""
        if not math.isfinite(value):
            return math.inf
        return value - self.limit if self.op == "<=" else self.limit - value

    def __str__(self) -> str:
        return f"{self.metric}{self.op}{self.limit:g}"


def parse_constraint(text: str, *, option: str = "--subject-to", members: Members | None = None) -> Constraint:
    """``"METRIC<=VALUE"`` or ``"METRIC>=VALUE"`` as a :class:`Constraint` (``members``: a
    tree's body and joint names, whose figures the metric is then, :func:`check_metrics`).

    Raises
    ------
    StudyInputError
        For another form, a limit that is not a finite number or an unknown metric.
    """
    m = _CONSTRAINT.match(str(text))
    limit = _float(m["limit"]) if m else None
    if m is None or limit is None:
        raise StudyInputError([f"{option} {text!r}: expected METRIC<=VALUE or METRIC>=VALUE with a finite number, "
                               "e.g. 'max_abs_constraint_error_z<=0.05'"])
    check_metrics([m["metric"]], option=option, members=members)
    return Constraint(m["metric"], m["op"], limit)


def _float(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class TuningProblem:
    """What a trial runs and how its value is made (validated by :func:`plan_tuning`).

    Attributes
    ----------
    base : RunConfig
    varied : list of Varied
        The searched keys (their factors are Optuna's parameters).
    objectives : tuple of Objective
    constraints : tuple of Constraint
    bodies : list of dict
        Dotted key -> value of each uncertain body of the batch (empty: one run, the base).
    quantile : float
        Of the batch's values, the one taken: 1 the worst case (largest for a minimized
        metric or a ``<=`` constraint, smallest otherwise), q < 1 the q-quantile of badness.
    engine : str
    """

    base: Any
    varied: list[Varied]
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...]
    bodies: list[dict] = field(default_factory=list)
    quantile: float = 1.0
    engine: str = DEFAULT_ENGINE
    body_columns: dict = field(default_factory=dict)

    def distributions(self) -> dict:
        """Optuna's distribution of each factor (log-scaled for ``log_uniform`` and
        ``scale_log_uniform``)."""
        from optuna.distributions import CategoricalDistribution, FloatDistribution  # heavy: optuna (~1 s)

        out = {}
        for v in self.varied:
            if v.kind == "choice":
                out[v.factors[0]] = CategoricalDistribution(list(v.args[0]))
                continue
            for name, (lo, hi) in zip(v.factors, v.bounds()):
                out[name] = FloatDistribution(lo, hi, log=v.kind in LOG_SCALED)
        return out

    def values_of(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """The absolute values (design column -> value) of Optuna's parameters (factor -> value)."""
        values: dict[str, Any] = {}
        for v in self.varied:
            if v.kind == "choice":
                values[v.columns[0]] = params[v.factors[0]]
                continue
            f = [params[name] for name in v.factors]
            values.update(zip(v.columns, v.from_factors(np.array([f]))[0].tolist()))
        return values

    def design(self, trials: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
        """The table of runs of trials' values: a row per trial and body (trial-major)."""
        n, b = len(trials), max(len(self.bodies), 1)
        data: dict[str, Any] = {}
        for column in ([*trials[0]] if trials else []):
            values = [t[column] for t in trials]
            data[column] = np.repeat(np.asarray(values, dtype=object if isinstance(values[0], str) else float), b)
        for column, values in self.body_columns.items():
            if column not in data:
                data[column] = np.tile(np.asarray(values), n)
        return pd.DataFrame(data)

    def evaluate_many(self, trials: Sequence[Mapping[str, Any]], executor=None) -> list[dict]:
        """Each trial's record: ``values``, ``figures`` (each metric of the objectives and
        constraints over the batch), ``constraints`` (their excess), ``failed`` (runs that
        failed, -1 for an invalid configuration) and ``message``; the trials' runs
        integrated as one batch (:func:`rbstab.studies.batch.run_generation`)."""
        from .batch import run_generation  # heavy: the sweep's planning (when a generation runs)

        b = max(len(self.bodies), 1)
        runs = run_generation(self.base.resolved, self.design(trials), engine=self.engine, executor=executor)
        out = []
        for i, values in enumerate(trials):
            rows = slice(i * b, (i + 1) * b)
            record: dict[str, Any] = {"values": dict(values)}
            invalid = [runs.invalid[j] for j in range(i * b, (i + 1) * b) if j in runs.invalid]
            if invalid:
                record.update(message=invalid[0], failed=-1)
                out.append(record)
                continue
            failed = int(np.sum(~runs.ok[rows]))
            figures = {}
            for metric, worst_is_max in self._badness().items():
                column = runs.figures.get(metric, np.full(len(runs.ok), np.nan))[rows]
                q = self.quantile if worst_is_max else 1.0 - self.quantile
                figures[metric] = float(np.quantile(column, q)) if np.all(np.isfinite(column)) else math.nan
            record.update(figures=figures, constraints=[c.excess(figures[c.metric]) for c in self.constraints],
                          failed=failed)
            if failed:
                record["message"] = f"{failed} run(s) failed"
            out.append(record)
        return out

    def configs(self, values: Mapping[str, Any]) -> list:
        """The run configs of a trial: the base (or each body of the batch) with ``values``.

        Raises
        ------
        rbstab.config.ConfigError
            If the values give an invalid configuration.
        """

        settings = {k: v[0] for k, v in design_mappings(pd.DataFrame({k: [x] for k, x in values.items()})).items()}
        out = []
        base = self.base.resolved
        for body in self.bodies or [{}]:
            data = copy.deepcopy(base)
            for key, value in {**body, **settings}.items():
                key_path(key, base).set(data, value)
            out.append(config_from_mapping(data, source="<trial>"))
        return out

    def evaluate(self, values: Mapping[str, Any]) -> tuple[dict[str, float], int]:
        """(one trial's figures: each metric of the objectives and constraints over the batch,
        the number of failed runs), by :meth:`evaluate_many`.

        Raises
        ------
        rbstab.config.ConfigError
            If the values give an invalid configuration.
        """
        (record,) = self.evaluate_many([values])
        if record["failed"] < 0:
            raise ConfigError([record["message"]])
        return record["figures"], record["failed"]

    def _badness(self) -> dict[str, bool]:
        """metric -> whether larger is worse."""
        out = {o.metric: o.direction == "minimize" for o in self.objectives}
        for c in self.constraints:
            out.setdefault(c.metric, c.op == "<=")
        return out

    def settings(self) -> dict:
        """What makes the study this study (stored with it; a resume must match)."""
        return {"vary": vary_mapping(self.varied), "objectives": [[o.metric, o.direction] for o in self.objectives],
                "constraints": [str(c) for c in self.constraints], "bodies": len(self.bodies),
                "quantile": self.quantile}


def plan_tuning(config, vary: Sequence[str] | Mapping[str, Any], *, minimize: Sequence[str] = (),
                maximize: Sequence[str] = (), subject_to: Sequence[str] = (),
                over: Sequence[str] | Mapping[str, Any] = (), over_n: int = 16, over_seed: int = 0,
                quantile: float = 1.0, sampler: str = "tpe", engine: str | None = None) -> TuningProblem:
    """Validate a tuning study's options (nothing runs but the checks of the configurations
    at the corners of the search box).

    Parameters
    ----------
    config : RunConfig
        The base configuration: one body's, or a chain's (keys and figures of chains,
        :mod:`rbstab.studies.design`).
    vary : sequence of str or Mapping
        ``KEY=RANGE``: ``uniform:[lo,hi]``, ``log_uniform:[lo,hi]``, ``scale_uniform:[lo,hi]``
        (a factor of the base value) or ``choice:[a,b]`` (:func:`parse_vary`).
    minimize, maximize : sequence of str
        Metrics (summary figures); one objective, or two for a Pareto front.
    subject_to : sequence of str
        ``METRIC<=VALUE`` / ``METRIC>=VALUE`` (:func:`parse_constraint`).
    over : sequence of str or Mapping
        ``KEY=DISTRIBUTION`` of the uncertain bodies (any sweep distribution); empty: one run
        per trial.
    over_n, over_seed : int
        Bodies drawn (from ``numpy.random.default_rng(over_seed)``), once for the study.
    quantile : float
        In (0, 1]; 1 = the worst case of the batch (see :class:`TuningProblem`).
    sampler : {"tpe", "cmaes"}
    engine : str, optional
        :data:`rbstab.engine.ENGINES` (default compiled).

    Raises
    ------
    StudyInputError
        Listing every invalid option, naming it, the value found and what is allowed.
    """
    errors: list[str] = []
    objectives = [Objective(m, "minimize") for m in minimize] + [Objective(m, "maximize") for m in maximize]
    constraints: list[Constraint] = []
    varied: list[Varied] = []
    over_varied: list[Varied] = []
    members = members_of(config)
    checks = [
        lambda: varied.extend(parse_vary(vary, config.resolved, allowed=RANGES)),
        lambda: check_metrics(list(minimize), option="--minimize", members=members),
        lambda: check_metrics(list(maximize), option="--maximize", members=members),
        *[(lambda t=t: constraints.append(parse_constraint(t, members=members))) for t in subject_to],
        *([lambda: over_varied.extend(parse_vary(over, config.resolved, option="--over"))] if over else []),
    ]
    for check in checks:
        try:
            check()
        except StudyInputError as exc:
            errors += exc.errors
    if not 1 <= len(objectives) <= 2:
        errors.append(f"--minimize/--maximize: found {len(objectives)} objectives; expected one, or two (a Pareto front)")
    if sampler not in SAMPLERS:
        errors.append(f"--sampler {sampler!r}: expected one of {', '.join(SAMPLERS)}")
    elif sampler == "cmaes" and (len(objectives) > 1 or subject_to or any(v.kind == "choice" for v in varied)):
        errors.append("--sampler cmaes: takes one objective, no --subject-to and no choice ranges; use --sampler tpe")
    elif sampler == "cmaes" and varied and sum(len(v.factors) for v in varied) < 2:
        errors.append("--sampler cmaes: needs two factors or more (CMA-ES searches a space of two dimensions or "
                      "more); use --sampler tpe for one")
    if not (isinstance(quantile, (int, float)) and 0 < quantile <= 1):
        errors.append(f"--quantile {quantile!r}: expected a number in (0, 1] (1: the worst case)")
    if over and not (isinstance(over_n, int) and over_n >= 1):
        errors.append(f"--over-n {over_n!r}: expected an integer >= 1")
    if errors:
        raise StudyInputError(errors)
    bodies, body_columns = _bodies(over_varied, over_n, over_seed) if over_varied else ([], {})
    problem = TuningProblem(config, varied, tuple(objectives), tuple(constraints), bodies, float(quantile),
                            engine or DEFAULT_ENGINE, body_columns)
    _check_corners(problem)
    return problem


def _bodies(varied: Sequence[Varied], n: int, seed: int) -> tuple[list[dict], dict]:
    """``n`` draws of the ``--over`` distributions: (key -> value of each body, design
    column -> the bodies' values)."""
    rng = np.random.default_rng(seed)
    columns: dict[str, Any] = {}
    for v in varied:
        values = v.from_unit(rng.random((n, len(v.factors))))
        columns.update({c: values[:, j] for j, c in enumerate(v.columns)})
    mappings = design_mappings(pd.DataFrame(columns))
    return [{k: values[i] for k, values in mappings.items()} for i in range(n)], columns


def _check_corners(problem: TuningProblem) -> None:
    """Refuse a search box whose lower or upper corner gives an invalid configuration."""
    errors = []
    for corner in (0, 1):
        values: dict[str, Any] = {}
        for v in problem.varied:
            if v.kind == "choice":
                continue
            f = np.array([[b[corner] for b in v.bounds()]])
            values.update(zip(v.columns, v.from_factors(f)[0].tolist()))
        try:
            problem.configs(values)
        except ConfigError as exc:
            where = "lower" if corner == 0 else "upper"
            errors += [f"--vary: the {where} ends of the ranges give an invalid configuration: {e}" for e in exc.errors]
    if errors:
        raise StudyInputError(errors)


@dataclass
class TuningResult:
    """The outcome of :func:`tune`.

    Attributes
    ----------
    name : str
    folder : Path
        ``best.yaml``, ``trials.csv``, ``tuning.nc`` (and ``journal.db`` by default).
    storage : str
        The Optuna storage URL, or the path of the study's SQLite journal
        (:mod:`rbstab.studies.storage`).
    n_trials : int
        Complete trials of the study (by every process, this run and earlier ones).
    n_failed : int
        Trials that failed (a failed run, an invalid configuration, an interrupt).
    best_values : list of float
        The best feasible trial's objective values (empty if no trial is feasible).
    best_params : dict
        Its absolute values, design column -> value.
    best_trial : int or None
    pareto : list of int
        Trial numbers of the Pareto front (two objectives; else the best trial).
    trials : pandas.DataFrame
        :func:`trials_table`.
    at_edge : list of str
        Warning lines (code ``W006``) for best values within 1 % of their search range's
        edge (the optimum may lie beyond it).
    """

    name: str
    folder: Path
    storage: str
    n_trials: int
    n_failed: int
    best_values: list[float]
    best_params: dict
    best_trial: int | None
    pareto: list[int]
    trials: Any
    at_edge: list = field(default_factory=list)

    def record(self) -> dict:
        """The ``--json`` object."""
        return {"study": self.name, "best_value": self.best_values[0] if len(self.best_values) == 1 else
                self.best_values or None, "best_params": self.best_params, "best_trial": self.best_trial,
                "n_trials": self.n_trials, "n_failed": self.n_failed, "pareto": self.pareto,
                "folder": str(self.folder), "storage": self.storage, "at_edge": self.at_edge}


#: A best value this close to an edge of its search range (as a fraction of the range; in
#: log10 for log_uniform) is reported (``W006``).
EDGE_FRACTION = 0.01


def edge_warnings(varied, best_params: Mapping[str, Any]) -> list[str]:
    """``W006`` lines for the factors of ``best_params`` (design column -> absolute value)
    within :data:`EDGE_FRACTION` of an edge of their range (``uniform``, ``log_uniform``,
    ``scale_uniform``; a scale factor as the value over the base value)."""
    lines = []
    for v in varied:
        if v.kind not in ("uniform", "log_uniform", "scale_uniform") or not best_params:
            continue
        values = np.array([float(best_params[c]) for c in v.columns]).reshape(v.shape or ())
        if v.kind == "scale_uniform":
            base = np.asarray(v.base, dtype=float)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(base != 0, values / np.where(base != 0, base, 1.0), np.nan)
            # one factor per entry of the bounds: the first entry it scales stands for it
            factors = ratio.reshape(*v.factor_shape, -1)[..., 0].ravel() if v.factor_shape else \
                np.array([ratio.ravel()[np.flatnonzero(np.isfinite(ratio.ravel()))[0]]
                          if np.isfinite(ratio).any() else np.nan])
        else:
            factors = values.ravel()
        for name, f, (lo, hi) in zip(v.factors, factors, v.bounds()):
            if not np.isfinite(f):
                continue
            scale = (lambda x: math.log10(x)) if v.kind == "log_uniform" else (lambda x: x)
            width = scale(hi) - scale(lo)
            where = "lower" if scale(f) - scale(lo) <= EDGE_FRACTION * width else \
                "upper" if scale(hi) - scale(f) <= EDGE_FRACTION * width else None
            if where:
                lines.append(coded("W006", f"{name}: the best value {f:.4g} lies at the {where} edge of its range "
                                           f"{v.kind}:[{lo:g}, {hi:g}]; the optimum may lie beyond it: widen the range"))
    return lines


def tune(config, vary: Sequence[str] | Mapping[str, Any], *, trials: int, minimize: Sequence[str] = (),
         maximize: Sequence[str] = (), subject_to: Sequence[str] = (), over: Sequence[str] | Mapping[str, Any] = (),
         over_n: int = 16, over_seed: int = 0, quantile: float = 1.0, sampler: str = "tpe", seed: int = 0,
         storage: str | None = None, output: str | os.PathLike = "results/studies", name: str | None = None,
         engine: str | None = None, generation: int | None = None, startup: int | None = None,
         restarts: str = "ipop", jobs: int | None = None, executor: Any = None, scheduler: str | None = None,
         log=None, command_line: str | None = None, overwrite: bool = False) -> TuningResult:
    """Run (or resume) a tuning study (``rbstab tune``) and write its files.

    Parameters
    ----------
    config : RunConfig
        The base configuration: one body's, or a chain's (keys and figures of chains,
        :mod:`rbstab.studies.design`).
    vary, minimize, maximize, subject_to, over, over_n, over_seed, quantile, sampler, engine
        See :func:`plan_tuning`.
    trials : int
        Complete trials the study should have; a resumed study runs only the missing ones.
    seed : int
        Seed of the samplers (offset by the trials already in the study, so a resumed
        study does not repeat the first suggestions); with CMA-ES also the run of the
        strategy that this process continues.
    storage : str, optional
        Optuna storage URL; by default Optuna's journal storage in the SQLite file
        ``<output>/<name>/journal.db`` (:mod:`rbstab.studies.storage`; a folder holding
        only a ``study.db`` resumes in it); ``"memory"``: the study lives in this process
        only (no resume).
    output, name
        The study writes ``<output>/<name>/``; ``name`` (default: the config's name) is
        also the study's name in the storage.
    generation : int, optional
        Trials asked and integrated at once (default :data:`GENERATION` of the engine; with
        CMA-ES, its first population, by default 4 + 3 ln d).
    startup : int, optional
        Space-filling trials (a scrambled Sobol' sequence) before the sampler (default: the
        generation's size for TPE, at least 16; 0: none).
    restarts : {"ipop", "bipop", "none"}
        CMA-ES's restarts (:mod:`rbstab.studies.search`).
    jobs, executor, scheduler
        Where a generation's runs are integrated: this process (default); with ``jobs`` > 1
        and no ``executor``, ``jobs`` threads of this process for a generation of at most
        :data:`THREADS_MAX_RUNS` runs (trials x bodies) on the compiled engine (no
        ``if __name__ == "__main__":`` guard needed), else local processes;
        ``jobs`` local processes (``executor="local"``), a Dask cluster
        (``executor="dask"`` with a ``scheduler`` address), or an Executor object (not
        closed here), as a sweep's.

    overwrite : bool
        Replace a study of other inputs (objectives, constraints, vary, base config) in
        the folder; without it that is refused (StudyInputError) before anything runs.

    Returns
    -------
    TuningResult

    Raises
    ------
    StudyInputError
        For invalid options, or a stored study of this name made with other settings.
    """
    import optuna  # optuna and SQLAlchemy: ~1 s to import, only when a study runs

    from .search import RESTARTS, GenerationSearch, default_population  # heavy: optuna, cmaes (when a study runs)
    from .storage import default_storage, storage_lock  # heavy: optuna

    folder = study_folder(output, name, config)
    problem = plan_tuning(config, vary, minimize=minimize, maximize=maximize, subject_to=subject_to, over=over,
                          over_n=over_n, over_seed=over_seed, quantile=quantile, sampler=sampler, engine=engine)
    errors = []
    if not (isinstance(trials, int) and trials >= 1):
        errors.append(f"--trials {trials!r}: expected an integer >= 1")
    if generation is not None and not (isinstance(generation, int) and generation >= 1):
        errors.append(f"--generation {generation!r}: expected an integer >= 1 (trials integrated at once)")
    if startup is not None and not (isinstance(startup, int) and startup >= 0):
        errors.append(f"--startup {startup!r}: expected an integer >= 0 (space-filling trials first)")
    if restarts not in RESTARTS:
        errors.append(f"--restarts {restarts!r}: expected one of {', '.join(RESTARTS)}")
    if jobs is not None and not (isinstance(jobs, int) and jobs >= 1):
        errors.append(f"-j/--jobs {jobs!r}: expected an integer >= 1")
    if errors:
        raise StudyInputError(errors)
    check_same_inputs(folder / FILE, {
        "objectives": json.dumps([[o.metric, o.direction] for o in problem.objectives]),
        "constraints": json.dumps([str(c) for c in problem.constraints]),
        "vary": json.dumps(vary_mapping(problem.varied)), "config": dump_yaml(problem.base.resolved)},
        overwrite=overwrite)
    groups = kernel_groups([config], engine or DEFAULT_ENGINE)
    ensure_compiled(say=log, **groups, sign_law=groups["one_body"])
    _check_scalar_metrics(problem, nominal_figures(config, engine))
    name = folder.name
    folder.mkdir(parents=True, exist_ok=True)
    storage = storage or default_storage(folder)
    optuna.logging.set_verbosity(optuna.logging.ERROR)
    study, journal = _open_study(problem, name, storage)
    say = log or (lambda _: None)
    dimension = sum(len(v.factors) for v in problem.varied)
    size = generation or GENERATION.get(problem.engine, GENERATION["compiled"])
    population = generation or default_population(dimension)
    if startup is None:
        startup = max(GENERATION.get(problem.engine, GENERATION["compiled"]) if sampler == "cmaes" else size, 16)
    known = optuna.create_study(directions=[o.direction for o in problem.objectives])  # in memory: the sampler's
    token = os.urandom(8).hex()  # this process's trials, as stored
    seen: set[int] = set()
    stored = _sync(study, known, seen, token)
    done = sum(t.state == optuna.trial.TrialState.COMPLETE for t in stored)
    search = GenerationSearch(known, problem.distributions(), sampler=sampler, seed=seed + len(stored), chain=seed,
                              size=size, startup=startup, population=population, restarts=restarts,
                              sign=1.0 if problem.objectives[0].direction == "minimize" else -1.0)
    budget = trials - done  # new trials this process may ask at most (failed ones are not replaced)
    if budget > 0:
        say(f"{name}: {done} complete trials in {storage}; running {budget} more, in generations of "
            f"{population if sampler == 'cmaes' else size} ({problem.engine} engine)")
    generation_runs = (population if sampler == "cmaes" else size) * max(len(problem.bodies), 1)
    with _executor(executor, jobs, scheduler, generation_runs <= THREADS_MAX_RUNS and _threads_take(problem)) as ex:
        while budget > 0:
            if done >= trials:
                break
            asked = search.ask(min(budget, trials - done))
            records = problem.evaluate_many([problem.values_of(t.params) for t in asked], executor=ex)
            finished = [_tell(known, problem, trial, record, token) for trial, record in zip(asked, records)]
            search.told(finished)
            with _deferred_interrupt(), (journal.transaction() if journal else contextlib.nullcontext()):
                # a generation is stored whole: in one transaction of the study's journal
                study.add_trials(finished)
            budget -= len(asked)
            stored = _sync(study, known, seen, token)
            done = sum(t.state == optuna.trial.TrialState.COMPLETE for t in stored)
    with storage_lock(storage):  # processes on one study write its files in turn, each from every stored trial
        return _write_outputs(problem, study, folder, storage, command_line)


def _tell(known, problem: TuningProblem, trial, record: dict, token: str):
    """Tell the in-memory study a trial's record; its FrozenTrial (to store)."""
    import optuna  # optuna and SQLAlchemy: ~1 s to import, only when a study runs

    failed = record.pop("failed")
    trial.set_user_attr("record", record)
    trial.set_user_attr("process", token)
    for constraint, excess in zip(problem.constraints, record.get("constraints", ())):
        trial.set_constraint(str(constraint), excess)  # feasible when every excess <= 0
    values = [record.get("figures", {}).get(o.metric, math.nan) for o in problem.objectives]
    if failed or not all(math.isfinite(v) for v in values):
        return known.tell(trial, state=optuna.trial.TrialState.FAIL)
    return known.tell(trial, values)


def _sync(study, known, seen: set, token: str) -> list:
    """The stored trials; those of other processes (or earlier runs) not yet in the in-memory
    study ``known`` are added to it."""
    stored = study.get_trials(deepcopy=False)
    new = [t for t in stored if t.number not in seen and t.state.is_finished()]
    seen.update(t.number for t in new)
    known.add_trials([t for t in new if t.user_attrs.get("process") != token])
    return stored


#: Largest generation (trials x bodies) integrated in threads with ``jobs`` > 1; a larger one
#: goes to worker processes. Up to ~2,000 runs a batch, threads are as fast as warm worker
#: processes; above, the post-processing's Python parts, which hold the GIL, make them
#: ~10 % slower (benchmarks/threads.py).
THREADS_MAX_RUNS = 1024

#: Keys whose variation can take a run off the compiled engine's batches (an implicit
#: method, the pure sign law): such a study keeps worker processes for ``jobs``.
_OFF_BATCH_KEYS = ("simulation.method", "controller.variant", "controller.boundary_layer")


def _threads_take(problem: TuningProblem) -> bool:
    """Whether every run of the study goes through the compiled engine's batches, whose
    kernels release the GIL (the runs one by one from their configurations would not)."""
    from ..simulator import uses_compiled_engine  # heavy: numba

    if members_of(problem.base) is not None:  # a chain's runs are built from their configurations
        return False
    return (not get_engine(problem.engine).gpu and uses_compiled_engine(problem.base, problem.engine)
            and not any(v.key.startswith(_OFF_BATCH_KEYS) for v in problem.varied)
            and not any(k.startswith(_OFF_BATCH_KEYS) for body in problem.bodies for k in body))


def _executor(executor: Any, jobs: int | None, scheduler: str | None, threads: bool = False):
    """The executor of a generation's runs as a context manager: None (this process) where
    neither ``executor`` nor ``jobs`` > 1 asks for one; ``jobs`` threads of this process
    where ``threads`` (:func:`_threads_take`, a generation of at most
    :data:`THREADS_MAX_RUNS` runs) and no ``executor`` is named (the compiled kernels
    release the GIL: as fast as worker processes there, with nothing started, pickled or
    imported again); one made by name is closed at the end."""
    if executor is None and (jobs is None or jobs <= 1) and scheduler is None:
        return contextlib.nullcontext(None)
    if executor is None and scheduler is None and threads:
        from ..sweep.executors import ThreadExecutor  # heavy: concurrent.futures

        return ThreadExecutor(jobs)
    if executor is None or isinstance(executor, str):
        from ..sweep.executors import ExecutorError, make_executor  # heavy: concurrent.futures, dask (with -j)

        try:
            return make_executor(executor or ("dask" if scheduler else "local"), jobs=jobs, scheduler=scheduler)
        except ExecutorError as exc:
            raise StudyInputError([str(exc)]) from None
    return contextlib.nullcontext(executor)


@contextlib.contextmanager
def _deferred_interrupt():
    """Hold Ctrl-C (SIGINT) back until the block ends (in the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            raise KeyboardInterrupt


def _check_scalar_metrics(problem: TuningProblem, available: Mapping[str, float]) -> None:
    """Refuse an objective or constraint that is no single figure of these runs (a 3-vector
    figure without its component, a figure the variant does not have)."""
    errors = []
    members = members_of(problem.base)
    for option, metric in [*((f"--{o.direction}", o.metric) for o in problem.objectives),
                           *(("--subject-to", c.metric) for c in problem.constraints)]:
        if metric not in available:
            try:
                parts = expand_metrics([metric], list(available), members=members)
            except StudyInputError:
                parts = []
            whole = "a 3-vector; give one component" if members is None else \
                "a figure of several columns (per joint or body, per axis); give one"
            errors.append(f"{option} {metric!r}: " + (f"{whole} ({', '.join(parts)})" if parts
                          else f"these runs have no such figure; they have {', '.join(available)}"))
    if errors:
        raise StudyInputError(errors)


def _open_study(problem: TuningProblem, name: str, storage: str):
    """(The study ``name`` in ``storage``: made, or loaded when its settings match; its
    SQLite journal or None)."""
    import optuna  # optuna and SQLAlchemy: ~1 s to import, only when a study runs

    from .storage import open_storage  # heavy: optuna

    directions = [o.direction for o in problem.objectives]
    opened, journal = open_storage(storage)
    try:
        study = optuna.create_study(study_name=name, storage=opened, directions=directions, load_if_exists=True)
    except ValueError as exc:  # e.g. other directions than the stored study's
        raise StudyInputError([f"study {name!r} in {storage}: {exc}; give another --name or -o"]) from None
    stored = study.user_attrs.get("settings")
    settings = json.loads(json.dumps(problem.settings()))
    if stored is None:
        study.set_user_attr("settings", settings)
    elif stored != settings or [d.name.lower() for d in study.directions] != directions:
        raise StudyInputError([f"study {name!r} in {storage} was made with other settings ({json.dumps(stored)}); "
                               "run it with those to resume, or give another --name or -o for a new study"])
    return study, journal


# -- results ---------------------------------------------------------------------------------------


def trials_table(problem: TuningProblem, study):
    """Every trial as a row: ``trial``, ``state``, one column per objective metric and
    constraint metric (the batch's value), ``feasible``, the absolute values (design
    columns) and ``message``."""
    rows = []
    metrics = list(problem._badness())
    columns = [c for v in problem.varied for c in v.columns]
    for t in study.get_trials(deepcopy=False):
        record = t.user_attrs.get("record", {})
        figures, excess = record.get("figures", {}), record.get("constraints", [])
        row = {"trial": t.number, "state": t.state.name.lower()}
        row.update({m: figures.get(m, math.nan) for m in metrics})
        row["feasible"] = bool(t.state.name == "COMPLETE" and all(e <= 0 for e in excess))
        row.update({c: record.get("values", {}).get(c) for c in columns})
        row["message"] = record.get("message", "")
        rows.append(row)
    return pd.DataFrame(rows, columns=["trial", "state", *metrics, "feasible", *columns, "message"])


def best_trials(problem: TuningProblem, table) -> list[int]:
    """Row positions of the best feasible trials: the best one (one objective) or the
    Pareto front (two), sorted by the first objective."""
    ok = table[table["feasible"]]
    if ok.empty:
        return []
    signs = np.array([1.0 if o.direction == "minimize" else -1.0 for o in problem.objectives])
    values = ok[[o.metric for o in problem.objectives]].to_numpy(dtype=float) * signs
    if len(signs) == 1:
        return [int(ok.index[int(np.argmin(values[:, 0]))])]
    front = [i for i in range(len(values)) if not np.any(np.all(values <= values[i], axis=1)
                                                         & np.any(values < values[i], axis=1))]
    front.sort(key=lambda i: values[i, 0])
    return [int(ok.index[i]) for i in front]


def _write_outputs(problem: TuningProblem, study, folder: Path, storage: str, command_line: str | None) -> TuningResult:
    table = trials_table(problem, study)
    best = best_trials(problem, table)
    write_text_atomic(folder / TRIALS_FILE, table.to_csv(index=False))
    best_params: dict = {}
    if not best:  # no feasible trial (yet): no best configuration, nor one of an earlier run
        (folder / BEST_FILE).unlink(missing_ok=True)
    else:
        row = table.loc[best[0]]
        best_params = {c: plain(row[c]) for v in problem.varied for c in v.columns}
        config = problem.configs(best_params)[0] if not problem.bodies else _nominal(problem, best_params)
        data = dict(config.resolved)
        data["name"] = f"{study.study_name}_best"
        write_text_atomic(folder / BEST_FILE, f"# best trial {int(row['trial'])} of tuning study "
                                              f"{study.study_name} ({storage})\n" + dump_yaml(data))
    _write_dataset(problem, study, table, best, folder / FILE, command_line)
    states = table["state"]
    return TuningResult(study.study_name, folder, storage, int((states == "complete").sum()),
                        int((states == "fail").sum()),
                        [float(table.loc[best[0], o.metric]) for o in problem.objectives] if best else [],
                        best_params, int(table.loc[best[0], "trial"]) if best else None,
                        [int(table.loc[i, "trial"]) for i in best], table, edge_warnings(problem.varied, best_params))


def _nominal(problem: TuningProblem, values: Mapping[str, Any]):
    """The base configuration (the nominal body) with ``values``."""
    return TuningProblem(problem.base, problem.varied, problem.objectives, problem.constraints).configs(values)[0]


def _write_dataset(problem: TuningProblem, study, table, best: Sequence[int], path: Path,
                   command_line: str | None) -> None:

    data = {}
    for column in table.columns:
        if column == "trial":
            continue
        values = table[column].to_numpy()
        if values.dtype == object:
            values = table[column].astype(str).to_numpy()
        units, long_name = figure_attributes(column)
        data[column] = xr.Variable(("trial",), values, {"long_name": long_name, **({"units": units} if units else {})})
    ds = xr.Dataset(data, coords={"trial": table["trial"].to_numpy()})
    ds.attrs.update(provenance_attributes(f"rbstab tuning study {study.study_name}", command_line=command_line))
    ds.attrs.update(rbstab_study="tuning", study=study.study_name,
                    objectives=json.dumps([[o.metric, o.direction] for o in problem.objectives]),
                    constraints=json.dumps([str(c) for c in problem.constraints]),
                    parameters=json.dumps([c for v in problem.varied for c in v.columns]),
                    vary=json.dumps(vary_mapping(problem.varied)), bodies=len(problem.bodies),
                    quantile=problem.quantile, best=json.dumps([int(table.loc[i, "trial"]) for i in best]),
                    config=dump_yaml(problem.base.resolved))
    write_study_file(ds, path)


def read_tuning(path: str | os.PathLike):
    """Read a tuning study's ``tuning.nc`` (or its folder) into memory: an
    :class:`xarray.Dataset` over ``trial`` (:func:`trials_table`'s columns) with the
    study's attributes (``objectives``, ``constraints``, ``parameters``, ``best``: JSON).

    Raises
    ------
    FileNotFoundError, ValueError
        If there is no such file or it is not a tuning study's.
    """
    return read_study_file(path, "tuning")
