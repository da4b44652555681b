"""Robustness from a sweep of perturbed parameters: the stable fraction with its confidence
interval, and the parameters that separate stable from unstable runs.

The sweep folder is read through :func:`rbstab.open_sweep`; a run is *stable* when it
converged (:func:`rbstab.convergence.converged`: it reached t_end and |v(t_end)| <=
lyapunov_ratio v_ref + 1e-12 J, v_ref the energy it had to lose) with the sweep's ratio, and the rest state v is zero at
is not linearly unstable: stability as seen in simulation over the sweep's t_end, not a
proof. (A run that converged beside an unstable rest state has not yet drifted away: an
*unstable rest*, counted as not stable. The rest state is linearised once per distinct
physical configuration, the values of the varied keys outside ``initial_state`` and
``simulation``, for at most :data:`MAX_REST_CHECKS` of them.) The sweep's index records its own ``converged``
column; the runs where it differs from this reading of the same figures (an index
written under another rule) are counted. Runs without a result (``error``,
``pending``) are left out and counted. Each base configuration of the sweep is a group
of its own.

Per group:

- the stable fraction k/n with the Wilson score interval at the chosen confidence
  (E. B. Wilson, J. Am. Stat. Assoc. 22 (1927) 209-212; it stays inside [0, 1] and is
  not degenerate at k = 0 or k = n, unlike the normal approximation);
- per varied parameter, how well it alone separates stable from unstable runs: the area
  under the ROC curve, AUC = P(value of a stable run > value of an unstable run), from
  the Mann-Whitney U statistic (0.5: no separation; 0 or 1: complete), and the best
  single threshold (stable below or above it) with its balanced accuracy.

Each separation also holds the rule of one or two thresholds that basin stability prints
(:func:`rbstab.analysis.thresholds.split_rule`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from ..config import config_from_mapping
from ..convergence import DEFAULT_LYAPUNOV_RATIO, converged
from ..sweep.folder import open_sweep, resolved_config, resolved_configs
from .dataset import robustness_content, robustness_dataset
from .linearise import MAX_REST_CHECKS, linearise_config, rest_verdict
from .thresholds import SplitRule, split_rule, split_rules

__all__ = ["Separation", "RobustnessGroup", "Robustness", "robustness", "wilson_interval", "separation",
           "DEFAULT_CONFIDENCE"]

#: Confidence level of the Wilson interval.
DEFAULT_CONFIDENCE = 0.95
#: Coordinates of a sweep dataset that are not parameters.
_NOT_PARAMETERS = ("run", "run_id", "base", "variant", "time", "axis")


def wilson_interval(k: int, n: int, confidence: float = DEFAULT_CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n.

    Parameters
    ----------
    k, n : int
        Successes and trials, 0 <= k <= n; n = 0 gives (0, 1).
    confidence : float
        In (0, 1).
    """
    if n == 0:
        return 0.0, 1.0
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    p = k / n
    denominator = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    low = 0.0 if k == 0 else max(0.0, float(centre - half))
    high = 1.0 if k == n else min(1.0, float(centre + half))
    return low, high


@dataclass(frozen=True)
class Separation:
    """How one parameter separates stable from unstable runs of a group.

    Attributes
    ----------
    parameter : str
        The sweep's coordinate name (``mass``, ``mass_scale``, ``k_c_0``...).
    auc : float
        P(stable value > unstable value) (ties count half).
    threshold : float
        The best single threshold (midway between two observed values).
    stable_side : str
        ``"below"`` or ``"above"``: where the stable runs lie.
    balanced_accuracy : float
        Mean of the fractions of stable and of unstable runs on their side.
    stable_range, unstable_range : (float, float)
        Smallest and largest value among the stable, the unstable runs.
    rule : SplitRule
        The best rule of one or two thresholds (:func:`rbstab.analysis.thresholds.split_rule`).
    """

    parameter: str
    auc: float
    threshold: float
    stable_side: str
    balanced_accuracy: float
    stable_range: tuple[float, float]
    unstable_range: tuple[float, float]
    rule: SplitRule

    @property
    def strength(self) -> float:
        """2 b - 1 of the rule's balanced accuracy b: 0 no separation, 1 complete (one- or
        two-sided; the AUC sees one side only)."""
        return 2.0 * self.rule.balanced_accuracy - 1.0


def _auc(s: np.ndarray, u: np.ndarray) -> float:
    """P(S > U) + P(S = U) / 2 over all pairs: the Mann-Whitney U statistic / (n_s n_u)."""
    u = np.sort(u)
    below = np.searchsorted(u, s, side="left")
    ties = np.searchsorted(u, s, side="right") - below
    return float((below.sum() + 0.5 * ties.sum()) / (len(s) * len(u)))


def separation(parameter: str, values: np.ndarray, stable: np.ndarray) -> Separation | None:
    """The :class:`Separation` of one parameter; None without both stable and unstable runs."""
    values = np.asarray(values, dtype=float)
    stable = np.asarray(stable, dtype=bool)
    s, u = values[stable], values[~stable]
    if not len(s) or not len(u):
        return None
    auc = _auc(s, u)
    one, _ = split_rules(values, stable)
    threshold = one.high if one.side == "below" else one.low
    return Separation(parameter, auc, float(threshold), one.side, one.balanced_accuracy,
                      (float(s.min()), float(s.max())), (float(u.min()), float(u.max())),
                      split_rule(values, stable))


@dataclass(frozen=True)
class RobustnessGroup:
    """The runs of one base configuration.

    Attributes
    ----------
    base : str
    n_runs, n_stable : int
        Runs with a result, and those that converged.
    n_excluded : int
        Runs without a result (error, pending).
    n_disagree : int
        Runs whose stability here differs from the ``converged`` the sweep recorded (an index
        written under another rule).
    interval : (float, float)
        Wilson interval of the stable fraction.
    separations : list of Separation
        Per varied parameter, strongest first (empty when every run is stable, or none is).
    parameters : list of str
        The parameters that vary in the group.
    n_unstable_rest : int
        Runs that converged beside an unstable rest state (counted as not stable).
    n_rest_unchecked : int
        Converged runs whose configuration's rest state was not linearised
        (beyond :data:`MAX_REST_CHECKS` configurations): counted as stable.
    t_end_hint : dict or None
        When runs reached t_end without converging and the linearisation at the
        equilibrium of one of them (``run_id``) is asymptotically stable: ``t_end`` [s] of
        that run, ``tau`` [s] (its slowest mode's time constant) and ``settling_time`` [s]
        (the slowest mode alone to bring v down by the ratio): t_end may be too short.
    """

    base: str
    n_runs: int
    n_stable: int
    n_excluded: int
    n_disagree: int
    interval: tuple[float, float]
    separations: list[Separation]
    parameters: list[str]
    n_unstable_rest: int = 0
    n_rest_unchecked: int = 0
    t_end_hint: dict | None = None

    @property
    def fraction(self) -> float:
        return self.n_stable / self.n_runs if self.n_runs else float("nan")


@dataclass(frozen=True)
class Robustness:
    """Robustness of a sweep (module docstring).

    Attributes
    ----------
    sweep : str
        The sweep's name.
    folder : str
    ratio : float
        The sweep's convergence ratio (:data:`rbstab.convergence.DEFAULT_LYAPUNOV_RATIO`
        if it has none).
    confidence : float
    groups : list of RobustnessGroup
    runs : dict
        Per run with a result: ``base`` (str array), ``stable`` (bool array) and
        ``values`` (parameter -> float array), for the figures.
    """

    sweep: str
    folder: str
    ratio: float
    confidence: float
    groups: list[RobustnessGroup]
    runs: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """The ``--json`` record: the sweep, and per group the counts, the stable fraction,
        its interval and the separations (strongest first)."""
        return {
            "sweep": self.sweep,
            "folder": self.folder,
            "confidence": self.confidence,
            "groups": [
                {"base": g.base, "n_runs": g.n_runs, "n_stable": g.n_stable, "n_excluded": g.n_excluded,
                 "n_disagree": g.n_disagree, "n_unstable_rest": g.n_unstable_rest,
                 "n_rest_unchecked": g.n_rest_unchecked,
                 "stable_fraction": g.fraction if g.n_runs else None, "interval": list(g.interval),
                 "n_converged": g.n_stable, "converged_fraction": g.fraction if g.n_runs else None,
                 "t_end_hint": g.t_end_hint,
                 "separations": [{"parameter": s.parameter, "auc": s.auc, "stable_side": s.rule.side,
                                  "threshold_low": s.rule.low if math.isfinite(s.rule.low) else None,
                                  "threshold_high": s.rule.high if math.isfinite(s.rule.high) else None,
                                  "balanced_accuracy": s.rule.balanced_accuracy, "explains": s.rule.explains}
                                 for s in g.separations]}
                for g in self.groups
            ],
        }

    def to_dataset(self):
        """As an :class:`xarray.Dataset` (:func:`rbstab.analysis.dataset.robustness_dataset`)."""
        return robustness_dataset(self)

    def file_content(self, command_line: str | None = None) -> tuple[dict, dict, dict]:
        """(coordinates, variables, global attributes) of its file
        (:func:`~rbstab.analysis.dataset.robustness_content`)."""
        return robustness_content(self, command_line)


def _t_end_hint(folder, run_id: str, ratio: float) -> dict | None:
    """:attr:`RobustnessGroup.t_end_hint` from run ``run_id`` (reached t_end, not converged):
    its configuration linearised at its equilibrium; None unless asymptotically stable."""
    try:
        config = config_from_mapping(resolved_config(folder, run_id))
        lin = linearise_config(config)
    except Exception:  # noqa: BLE001 - a hint only: a run that cannot be rebuilt gives none
        return None
    if lin.verdict != "asymptotically stable":
        return None
    tau = float(lin.slowest_time_constant)
    return {"run_id": run_id, "t_end": float(config.simulation.t_end), "tau": tau,
            "settling_time": 0.5 * tau * math.log(1.0 / ratio)}


def _unstable_rest(folder, ds, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unstable, unchecked), bool arrays over the runs: of the runs where ``candidates``
    (converged), those whose configuration's rest state is linearly unstable, and those not
    linearised (beyond :data:`MAX_REST_CHECKS` distinct physical configurations)."""
    keys = {str(c): str(ds[c].attrs.get("config_key", "")) for c in ds.coords if ds[c].dims == ("run",)}
    columns = [ds[c].values for c, key in keys.items() if key and not key.startswith(("initial_state", "simulation"))]
    base = ds["base"].values.astype(str) if "base" in ds.coords else np.full(ds.sizes["run"], "")
    unstable = np.zeros(ds.sizes["run"], dtype=bool)
    unchecked = np.zeros(ds.sizes["run"], dtype=bool)
    runs = np.flatnonzero(candidates)
    keys = [(base[i], *(str(c[i]) for c in columns)) for i in runs]
    first: dict[tuple, str] = {}  # each physical configuration's first run, the first MAX_REST_CHECKS of them
    for i, key in zip(runs, keys):
        if key not in first and len(first) < MAX_REST_CHECKS:
            first[key] = str(ds["run_id"].values[i])
    configs = resolved_configs(folder, list(first.values()))  # each result file read once
    verdicts = {key: rest_verdict(configs[run_id]) == "unstable" for key, run_id in first.items()}
    for i, key in zip(runs, keys):
        unstable[i] = verdicts.get(key) is True
        unchecked[i] = key not in verdicts
    return unstable, unchecked


def _numeric_parameters(ds) -> list[str]:
    names = []
    for name in ds.coords:
        if name in _NOT_PARAMETERS or ds[name].dims != ("run",):
            continue
        if np.issubdtype(ds[name].dtype, np.number):
            names.append(str(name))
    return names


def robustness(path: str | os.PathLike, confidence: float = DEFAULT_CONFIDENCE) -> Robustness:
    """Robustness of the sweep folder ``path`` (module docstring).

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a sweep folder.
    ValueError
        For a confidence outside (0, 1).
    """
    if not 0 < confidence < 1:
        raise ValueError(f"--confidence: found {confidence}; expected 0 < confidence < 1")
    ds = open_sweep(path)
    status = ds["status"].values.astype(str)
    has_result = np.isin(status, ["success", "failed"])
    ratio = ds.attrs.get("lyapunov_ratio")
    ratio = float(ratio) if ratio is not None and np.isfinite(float(ratio)) else DEFAULT_LYAPUNOV_RATIO
    v0 = np.asarray(ds["lyapunov_initial"].values, dtype=float)
    v1 = np.asarray(ds["lyapunov_final"].values, dtype=float)
    rise = ds["max_lyapunov_increase"].values if "max_lyapunov_increase" in ds else None
    stable = converged(status == "success", v0, v1, ratio, rise)
    disagree = has_result & (stable != (np.asarray(ds["converged"].values, dtype=bool) & (status == "success")))
    unstable_rest, unchecked = _unstable_rest(path, ds, stable)
    stable &= ~unstable_rest
    base = ds["base"].values.astype(str) if "base" in ds.coords else np.full(ds.sizes["run"], ds.attrs["sweep"])
    parameters = _numeric_parameters(ds)
    values = {p: np.asarray(ds[p].values, dtype=float) for p in parameters}
    groups = []
    for name in dict.fromkeys(base):
        member = base == name
        ok = member & has_result
        varied = [p for p in parameters if np.unique(values[p][ok]).size > 1]
        found = [separation(p, values[p][ok], stable[ok]) for p in varied]
        n, k = int(ok.sum()), int(stable[ok].sum())
        reached = np.flatnonzero(member & (status == "success") & ~stable)
        hint = _t_end_hint(path, str(ds["run_id"].values[reached[0]]), ratio) if reached.size else None
        groups.append(RobustnessGroup(
            base=str(name), n_runs=n, n_stable=k, n_excluded=int((member & ~has_result).sum()),
            n_disagree=int((member & disagree).sum()),
            n_unstable_rest=int((member & unstable_rest).sum()), n_rest_unchecked=int((member & unchecked).sum()),
            interval=wilson_interval(k, n, confidence),
            separations=sorted((s for s in found if s is not None), key=lambda s: -s.strength),
            parameters=varied,
            t_end_hint=hint,
        ))
    runs = {"base": base[has_result], "stable": stable[has_result],
            "values": {p: v[has_result] for p, v in values.items()}}
    return Robustness(sweep=str(ds.attrs.get("sweep", "")), folder=str(path), ratio=ratio,
                      confidence=confidence, groups=groups, runs=runs)
