"""Where a tuning study searches: a generation of trials at a time, asked of Optuna.

:class:`GenerationSearch` keeps the study's trials in an in-memory Optuna study (the
storage's trials and this process's) and asks it for a generation of trials at once:

- the first ``startup`` trials are space-filling: Optuna's
  :class:`~optuna.samplers.QMCSampler` (a scrambled Sobol' sequence), so the whole search
  box is seen before any sampler narrows it;
- then ``tpe``: Optuna's multivariate TPE (correlated factors modelled jointly), with the
  constant liar (the trials of a generation asked before any is told spread out instead
  of piling onto one point); or ``cmaes``: CMA-ES (the ``cmaes`` library's
  :class:`cmaes.CMA`, a generation its population) on the unit box of the factors (log
  factors on a log scale), from the best trial so far, restarted when it has converged
  (:meth:`cmaes.CMA.should_stop`) from a random point with a doubled population (IPOP),
  or alternating doubled populations with small ones of smaller steps (BIPOP).

A CMA-ES generation's trials carry their run (``chain``: the seed), restart and generation
in the user attribute ``cma``, and a restart's start in its first generation's, so a
resumed study rebuilds the strategy's state by telling it the stored generations again.

References
----------
N. Hansen, "The CMA evolution strategy: a tutorial", arXiv:1604.00772. A. Auger, N. Hansen,
"A restart CMA evolution strategy with increasing population size", CEC 2005 (IPOP). N.
Hansen, "Benchmarking a BI-population CMA-ES on the BBOB-2009 function testbed", GECCO 2009
(BIPOP). M. Nomura, M. Shibata, "cmaes: A simple yet practical Python library for CMA-ES",
arXiv:2402.01373. I. M. Sobol', "On the distribution of points in a cube and the
approximate evaluation of integrals", USSR Comput. Math. Math. Phys. 7 (1967) 86-112.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import optuna
from optuna.samplers import BaseSampler

__all__ = ["GenerationSearch", "RESTARTS", "default_population"]

#: CMA-ES restart strategies.
RESTARTS = ("ipop", "bipop", "none")
#: Initial step of CMA-ES on the unit box of the factors.
SIGMA0 = 0.25


def default_population(dimension: int) -> int:
    """CMA-ES's default population, 4 + floor(3 ln d)."""
    return 4 + int(3 * math.log(max(dimension, 1)))


class _Given(BaseSampler):
    """Optuna sampler that returns parameters chosen beforehand (a CMA-ES generation)."""

    def __init__(self) -> None:
        self.pending: list[dict] = []

    def infer_relative_search_space(self, study, trial):
        return {}

    def sample_relative(self, study, trial, search_space):
        return {}

    def sample_independent(self, study, trial, param_name, param_distribution):
        return self.pending[0][param_name]

    def after_trial(self, study, trial, state, values) -> None:  # pragma: no cover - nothing to keep
        pass


class _Box:
    """The factors' unit box: Optuna parameters <-> u in [0, 1]^d (log factors on a log scale)."""

    def __init__(self, distributions: dict) -> None:
        self.names = list(distributions)
        d = [distributions[n] for n in self.names]
        self.log = np.array([x.log for x in d])
        lo = np.array([x.low for x in d], dtype=float)
        hi = np.array([x.high for x in d], dtype=float)
        self.lo = np.where(self.log, np.log(lo), lo)
        self.span = np.where(self.log, np.log(hi), hi) - self.lo
        self.low, self.high = lo, hi

    def unit(self, params: dict) -> np.ndarray:
        x = np.array([params[n] for n in self.names], dtype=float)
        g = np.where(self.log, np.log(np.maximum(x, 1e-300)), x)
        return np.clip((g - self.lo) / np.where(self.span > 0, self.span, 1.0), 0.0, 1.0)

    def params(self, u: np.ndarray) -> dict:
        g = self.lo + np.clip(u, 0.0, 1.0) * self.span
        x = np.clip(np.where(self.log, np.exp(g), g), self.low, self.high)
        return dict(zip(self.names, x.tolist()))


class _CmaRestarts:
    """CMA-ES with restarts (IPOP or BIPOP) over the unit box, driven a generation at a time."""

    def __init__(self, box: _Box, *, chain: int, seed: int, population: int, restarts: str, sign: float) -> None:
        self.box, self.chain, self.seed, self.restarts, self.sign = box, chain, seed, restarts, sign
        self.population = population
        self.cma = None
        self.restart = -1
        self.generation = 0
        self.start: dict = {}
        self.used = {"large": 0, "small": 0}
        self.large = 0  # doublings of the population so far
        self.regime = "large"

    # -- the state ------------------------------------------------------------------------------

    def _new(self, mean, sigma: float, population: int) -> None:
        from cmaes import CMA  # the cmaes library (a dependency of the tuning extra)

        d = len(self.box.names)
        self.cma = CMA(mean=np.clip(np.asarray(mean, dtype=float), 0.0, 1.0), sigma=float(sigma),
                       bounds=np.array([[0.0, 1.0]] * d), seed=self.seed + max(self.restart, 0),
                       population_size=int(population))

    def begin(self, best_unit: np.ndarray | None) -> None:
        """Start the next run: the first from ``best_unit`` (else the box's centre), a restart
        from a random point, with the population and step of the strategy."""
        rng = np.random.default_rng([self.seed, self.chain, self.restart + 1])
        d = len(self.box.names)
        self.restart += 1
        self.generation = 0
        if self.restart == 0:
            mean, sigma, population, regime = (best_unit if best_unit is not None else np.full(d, 0.5)), SIGMA0, \
                self.population, "large"
        elif self.restarts == "bipop" and self.used["small"] < self.used["large"]:
            u = rng.random()
            largest = self.population * 2 ** self.large
            population = max(2, int(self.population * (largest / (2 * self.population)) ** (rng.random() ** 2)))
            mean, sigma, regime = rng.random(d), SIGMA0 * 10 ** (-2 * u), "small"
        else:
            self.large += 1
            mean, sigma, population, regime = rng.random(d), SIGMA0, self.population * 2 ** self.large, "large"
        self.regime = regime
        self.start = {"mean": [float(x) for x in mean], "sigma": float(sigma), "population": int(population),
                      "regime": regime}
        self._new(mean, sigma, population)

    def replay(self, trials) -> None:
        """Rebuild the state from the stored trials of this chain (their ``cma`` attribute):
        each restart from its start, told its complete generations in order."""
        runs: dict[int, dict] = {}
        for t in trials:
            tag = t.user_attrs.get("cma")
            if not tag or tag.get("chain") != self.chain:
                continue
            run = runs.setdefault(int(tag["restart"]), {"start": None, "generations": {}})
            if "start" in tag:
                run["start"] = tag["start"]
            run["generations"].setdefault(int(tag["generation"]), []).append(t)
        for restart in sorted(runs):
            run = runs[restart]
            if run["start"] is None:
                continue
            self.restart, start = restart, run["start"]
            self.start, self.regime = start, start.get("regime", "large")
            population = int(start["population"])
            if self.regime == "large" and restart > 0:
                self.large = max(self.large, int(round(math.log2(population / self.population))))
            self._new(start["mean"], start["sigma"], population)
            self.generation = 0
            for g in sorted(run["generations"]):
                members = run["generations"][g]
                if len(members) == population:
                    self._tell(members)
                self.generation = g + 1

    # -- a generation -------------------------------------------------------------------------

    def ask(self) -> list[tuple[dict, dict]]:
        """The next generation: (Optuna parameters, ``cma`` tag) per member; a restart first
        where the current run has converged."""
        if self.cma.should_stop():
            self.begin(None)
        tag = {"chain": self.chain, "restart": self.restart, "generation": self.generation}
        out = []
        for i in range(self.cma.population_size):
            out.append((self.box.params(self.cma.ask()), {**tag, **({"start": self.start} if self.generation == 0
                                                                   and i == 0 else {})}))
        return out

    def tell(self, trials) -> None:
        """Tell a generation's finished trials (the whole population, else nothing is told)."""
        if len(trials) == self.cma.population_size:
            self._tell(trials)
        self.generation += 1

    def _tell(self, trials) -> None:
        values = np.array([self.sign * t.values[0] if t.values else np.nan for t in trials], dtype=float)
        finite = values[np.isfinite(values)]
        worst = float(finite.max()) if len(finite) else 0.0
        values = np.where(np.isfinite(values), values, worst + abs(worst) + 1.0)  # a failed trial: worse than all
        self.cma.tell([(self.box.unit(t.params), float(v)) for t, v in zip(trials, values)])
        self.used[self.regime] += len(trials)


class GenerationSearch:
    """Asks an in-memory Optuna study for a generation of trials (module docstring).

    Parameters
    ----------
    study : optuna.Study
        In memory; holds every trial of the study that this process knows.
    distributions : dict
        Optuna parameter name -> distribution (the factors).
    sampler : {"tpe", "cmaes"}
    seed : int
        Seed of the samplers (the study's; offset by the trials so far).
    chain : int
        The CMA-ES run this process continues (``--seed``).
    size : int
        Trials a TPE generation asks (a CMA-ES generation is its population).
    startup : int
        Space-filling trials first.
    population : int
        CMA-ES's first population.
    restarts : {"ipop", "bipop", "none"}
    sign : float
        1 to minimize, -1 to maximize (CMA-ES's objective).
    """

    def __init__(self, study, distributions: dict, *, sampler: str, seed: int, chain: int, size: int, startup: int,
                 population: int, restarts: str = "ipop", sign: float = 1.0) -> None:
        self.study, self.distributions, self.kind = study, distributions, sampler
        self.size, self.startup = size, startup
        with warnings.catch_warnings():  # QMCSampler is marked experimental
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            self.qmc = optuna.samplers.QMCSampler(qmc_type="sobol", scramble=True, seed=seed,
                                                  warn_independent_sampling=False, warn_asynchronous_seeding=False)
        self.tpe = optuna.samplers.TPESampler(seed=seed, multivariate=True, constant_liar=True)
        self.cma = None
        if sampler == "cmaes":
            self.given = _Given()
            self.cma = _CmaRestarts(_Box(distributions), chain=chain, seed=seed, population=population,
                                    restarts=restarts, sign=sign)
            self.cma.replay(study.get_trials(deepcopy=False))
        self.phase = "startup"

    def ask(self, limit: int) -> list[Any]:
        """A generation of at most ``limit`` trials (Optuna trials of the in-memory study)."""
        done = len(self.study.get_trials(deepcopy=False))
        if done < self.startup:
            self.phase = "startup"
            k = min(limit, self.startup - done)
            self.study.sampler = self.qmc
            with warnings.catch_warnings():  # Sobol' balance needs 2^m points: the startup is sized so
                warnings.simplefilter("ignore")
                return [self.study.ask(self.distributions) for _ in range(k)]
        if self.kind == "tpe":
            self.phase = "tpe"
            self.study.sampler = self.tpe
            return [self.study.ask(self.distributions) for _ in range(min(limit, self.size))]
        self.phase = "cmaes"
        if self.cma.cma is None:
            self.cma.begin(self._best_unit())
        members = self.cma.ask()[:limit]
        self.study.sampler = self.given
        trials = []
        for params, tag in members:
            self.given.pending = [params]
            trial = self.study.ask(self.distributions)
            trial.set_user_attr("cma", tag)
            trials.append(trial)
        return trials

    def told(self, frozen) -> None:
        """The generation's trials are told (FrozenTrials of the in-memory study)."""
        if self.phase == "cmaes":
            self.cma.tell(frozen)

    def _best_unit(self):
        complete = [t for t in self.study.get_trials(deepcopy=False) if t.state.name == "COMPLETE"]
        if not complete:
            return None
        best = min(complete, key=lambda t: self.cma.sign * t.values[0])
        return self.cma.box.unit(best.params)
