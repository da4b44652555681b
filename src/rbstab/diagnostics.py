"""What a run's figures mean, in words: its outcome, why a rate check failed, round-off.

The words ``rbstab run``, ``rbstab show``, a sweep's line and index and the report give a
run, one vocabulary (:data:`OUTCOMES`):

- :func:`outcome` of one run and :func:`outcomes` of many: ``converged``, ``still settling``,
  ``moving away``, ``fell``, ``could not be computed`` (or ``pending``, a sweep's run not yet
  done), from the run's status and message (:func:`rbstab.engine.status.fell`) and v
  (the rule of :mod:`rbstab.convergence`).
- :func:`rate_check_reason`: why the check of the analytic dv/dt against the numerical
  derivative of v failed (the largest mismatch, when, the likely cause and its fix).
- :func:`chop`: a number at round-off level (below the tolerance that produced it) as 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .convergence import DEFAULT_LYAPUNOV_RATIO, ROUND_OFF, converged, floats
from .engine.status import fell, fell_mask
from .warning_codes import coded

__all__ = ["CONVERGED", "SETTLING", "MOVING_AWAY", "FELL", "NOT_COMPUTED", "PENDING", "OUTCOMES", "outcome",
           "outcomes", "risen_without_disturbance", "unbounded_fall_note", "rate_check_reason", "file_rate_check_reason",
           "simulation_rate_check_reason",
           "largest_mismatch_time", "samples_for_rate_check", "samples_to_resolve", "RESOLVING_SPACING",
           "chop", "NOISE_LIMIT"]

#: How a run ended, in every command's words (:func:`outcome`).
CONVERGED = "converged"
SETTLING = "still settling"
MOVING_AWAY = "moving away"
FELL = "fell"
NOT_COMPUTED = "could not be computed"
PENDING = "pending"
#: Each outcome and what it means (the README and ``sweep_summary.json`` quote them).
OUTCOMES = {
    CONVERGED: "reached t_end with v(t_end) within the convergence rule: lost all but the ratio (0.1 %) of the "
               "energy it had to lose (v(0), plus the largest rise of v: a push)",
    SETTLING: "reached t_end not converged with v(t_end) >= 0: still moving toward the equilibrium, or too short "
              "a t_end (rbstab analyze gives the slowest mode's settling time)",
    MOVING_AWAY: "reached t_end not converged with v(t_end) < 0: below the energy of the equilibrium v is zero at, "
                 "where it cannot return while dv/dt <= 0 (a slow fall, or a rest away from the equilibrium); or, "
                 "with no disturbance, with v(t_end) above v(0): the actuators did not hold the body (a fall)",
    FELL: "stopped at a gimbal lock or where it left the admissible region (simulation.limits): a result",
    NOT_COMPUTED: "stopped before t_end for a numerical reason (solver failure, non-finite state, step or "
                  "wall-time limit, an exception): no result of its physics",
    PENDING: "a sweep's run not run yet",
}

#: rtol (n_samples - 1) above which the solver's noise, differentiated over the sample
#: spacing, alone can fail the rate check of a conservative run (docs/physics.md).
NOISE_LIMIT = 3e-5


def outcome(status: str, message: str | None, lyapunov_initial: Any, lyapunov_final: Any,
            max_increase: Any = None, ratio: float = DEFAULT_LYAPUNOV_RATIO, *, disturbed: bool | None = None) -> str:
    """How a run ended: one of :data:`OUTCOMES`.

    Parameters
    ----------
    status : str
        ``"success"`` (t_end reached), ``"failed"``, ``"error"`` or ``"pending"``.
    message : str or None
        Why a failed run stopped (:func:`rbstab.engine.status.fell` reads it).
    lyapunov_initial, lyapunov_final : float
        v(0) and v(t_end) [J].
    max_increase : float, optional
        The largest rise of v above its running minimum [J] (``max_lyapunov_increase``;
        :func:`rbstab.convergence.converged`).
    ratio : float
        The convergence ratio.
    disturbed : bool, optional
        Whether the run had disturbances (None: not known). Without any, v(t_end) above
        |v(0)| is energy nothing fed the body: :data:`MOVING_AWAY`.

    Returns
    -------
    str
        :data:`PENDING`; :data:`FELL` or :data:`NOT_COMPUTED` for a run that did not reach
        t_end; else :data:`CONVERGED`, :data:`MOVING_AWAY` (v(t_end) < 0, or above |v(0)|
        without a disturbance) or :data:`SETTLING`.
    """
    if status == "pending":
        return PENDING
    if status != "success":
        return FELL if fell(status, message) else NOT_COMPUTED
    if converged(True, lyapunov_initial, lyapunov_final, ratio, max_increase):
        return CONVERGED
    away = _moving_away(floats(lyapunov_initial), floats(lyapunov_final), disturbed is False)
    return MOVING_AWAY if bool(away) else SETTLING


def _risen(v0, v1):
    """Whether v(t_end) ``v1`` lies above |v(0)| + round-off [J] (numbers or arrays)."""
    with np.errstate(invalid="ignore"):
        return v1 > np.abs(v0) + ROUND_OFF


def _moving_away(v0, v1, undisturbed):
    """Whether a run that reached t_end unconverged is :data:`MOVING_AWAY`: v(t_end) < 0, or
    without a disturbance (``undisturbed``) above |v(0)| (numbers or arrays)."""
    with np.errstate(invalid="ignore"):
        return (v1 < 0.0) | (undisturbed & _risen(v0, v1))


def outcomes(status, message, lyapunov_initial, lyapunov_final, max_increase=None,
             ratio: float = DEFAULT_LYAPUNOV_RATIO, *, disturbed=None) -> np.ndarray:
    """:func:`outcome` of n runs at once: arrays (or lists, pandas columns) of shape (n,)
    (``disturbed``: bool, or None where not known); an object array of str, shape (n,)."""
    status = np.asarray(status, dtype=object)
    v0, v1 = floats(lyapunov_initial), floats(lyapunov_final)
    success = status == "success"
    out = np.full(len(status), SETTLING, dtype=object)
    undisturbed = (np.zeros(len(status), dtype=bool) if disturbed is None else
                   np.asarray([d is False or d == 0 for d in np.asarray(disturbed, dtype=object)], dtype=bool))
    out[success & _moving_away(v0, v1, undisturbed)] = MOVING_AWAY
    out[np.asarray(converged(success, lyapunov_initial, v1, ratio, max_increase), dtype=bool) & success] = CONVERGED
    fallen = fell_mask(status, message)
    out[~success] = NOT_COMPUTED
    out[fallen] = FELL
    out[status == "pending"] = PENDING
    return out


def unbounded_fall_note(config) -> str | None:
    """The warning W009 where ``config`` (a validated configuration) is a body under gravity
    without an admissible region (``simulation.limits``): a run that falls then swings on,
    through the ground, and may come back to the equilibrium (counted as recovered) or read
    as still settling; None otherwise."""

    if config.simulation.limits is not None or not np.any(config.chain.gravity != 0):
        return None
    return coded("W009", "simulation.limits: none on a body under gravity: a run that falls swings on without end "
                         "(through the ground) and reads as still settling, or comes back and counts as recovered; "
                         "set simulation.limits (e.g. theta: [0.6, 0.6, .inf]) to end a fall where it becomes one")


def risen_without_disturbance(lyapunov_initial: Any, lyapunov_final: Any) -> str:
    """A clause for a run without disturbances whose v(t_end) ended above v(0) [J]: nothing
    fed it energy, so its actuators could not hold it (saturated) or v is not a Lyapunov
    function there (empty otherwise)."""
    try:
        v0, v1 = float(lyapunov_initial), float(lyapunov_final)
    except (TypeError, ValueError):
        return ""
    if not (math.isfinite(v0) and _risen(v0, v1)):
        return ""
    return (f"v rose from {v0:.4g} J to {v1:.4g} J without a disturbance: the actuators did not hold the body "
            "(saturated torques, or an unstable equilibrium): a fall unless simulation.limits ends it")


def samples_for_rate_check(n_samples: int, relative_mismatch: float, tolerance: float) -> int:
    """Samples for which the numerical derivative's error falls below ``tolerance``, with a
    margin of 2, rounded up to a round number. The 7-point stencil is of 6th order in the
    spacing once the samples resolve v; a failing run usually does not resolve its fastest
    transient yet, where the error falls far more slowly: taken as 2nd order (measured on
    Case 1 with t_end 20 s: 101 samples 0.5 P, 571 samples 0.061 P, 2901 samples 0.001 P,
    3201 pass)."""
    factor = 2.0 * (relative_mismatch / tolerance) ** (1.0 / 2.0)
    return _round_samples((n_samples - 1) * max(factor, 1.5) + 1)


def _round_samples(wanted: float) -> int:
    """``wanted`` samples rounded up to two significant digits, plus one (``20651`` -> 21001)."""
    step = 10 ** max(0, int(math.floor(math.log10(wanted))) - 1)
    return int(math.ceil(wanted / step) * step) + 1


#: The sample spacing times |s| of a mode at most which the rate check's numerical
#: derivative resolves it: about 7 samples per time constant 1/|s|. Measured by the fastest
#: mode of each configuration, largest spacing x |s| that failed / smallest that passed:
#: free_gravity 0.48 / 0.24, Case 2 0.56 / 0.28, Case 3 1.5 / 0.74, the stance 1.2 / 0.61,
#: the knee 3.2 / 1.6, a triple pendulum 0.41 / 0.21.
RESOLVING_SPACING = 0.15


def samples_to_resolve(rate: float, t_end: float) -> int:
    """Samples on [0, ``t_end``] [s] whose spacing resolves a mode of |s| = ``rate`` [1/s]
    (:data:`RESOLVING_SPACING`), rounded up to a round number."""
    return _round_samples(t_end * rate / RESOLVING_SPACING + 1)


def _unresolved_mode(rate: float, t_end: float, spacing: float) -> str:
    """The cause and fix of a failed rate check whose samples (``spacing`` [s]) do not
    resolve the fastest mode (|s| = ``rate`` [1/s]) of a run of ``t_end`` [s]."""
    from .config.schema import MAX_SAMPLES  # heavy: pydantic

    cause = (f"likely the samples (spacing {spacing:.3g} s) do not resolve the fastest mode at rest "
             f"(time constant 1/|s| {1.0 / rate:.2g} s)")
    wanted = samples_to_resolve(rate, t_end)
    if wanted <= MAX_SAMPLES:
        return f"{cause}: {wanted} samples resolve it, e.g. --set simulation.n_samples={wanted} (docs/physics.md)"
    longest = (MAX_SAMPLES - 1) * RESOLVING_SPACING / rate
    return (f"{cause}, which takes {wanted:.2g} samples, more than a run holds ({MAX_SAMPLES}): "
            f"set simulation.t_end <= {longest:.2g} s, or a softer gain (docs/physics.md)")


def rate_check_reason(summary: Mapping[str, Any], *, n_samples: int, t_end: float, rtol: float,
                      where: float | None = None, fastest: float | None = None) -> str:
    """Why a run's rate check failed, in one clause (empty when it did not fail).

    Parameters
    ----------
    summary : Mapping
        The run's summary figures (``lyapunov_rate_check``,
        ``lyapunov_rate_mismatch``, ``lyapunov_rate_mismatch_relative``).
    n_samples, t_end, rtol
        The run's ``simulation`` settings.
    where : float, optional
        The time of the largest mismatch [s] (:func:`largest_mismatch_time`).
    fastest : float, optional
        |s| [1/s] of the fastest mode of the run's linearisation at rest
        (:func:`rbstab.analysis.stiffness.fastest_rate`): where the sample spacing does not
        resolve it (:data:`RESOLVING_SPACING`), the reason says so and gives the samples that do.

    Returns
    -------
    str
        e.g. ``"mismatch 0.031 W = 3.2e-3 P > 1e-3 P at t = 0.41 s; likely the samples are
        too sparse for t_end 20 s (spacing 0.02 s): more samples, e.g. --set
        simulation.n_samples=4001"``.
    """
    from .summary import LYAPUNOV_RATE_TOLERANCE  # heavy: numba (a sweep's reader needs none)

    if summary.get("lyapunov_rate_check") != "fail":
        return ""
    relative = float(summary.get("lyapunov_rate_mismatch_relative", float("nan")))
    mismatch = float(summary.get("lyapunov_rate_mismatch", float("nan")))
    at = f" at t = {where:.4g} s" if where is not None and math.isfinite(where) else ""
    text = f"largest |analytic - numerical dv/dt| {mismatch:.3g} W = {relative:.2g} P > {LYAPUNOV_RATE_TOLERANCE:g} P{at}"
    spacing = t_end / max(n_samples - 1, 1)
    if rtol * (n_samples - 1) > NOISE_LIMIT:
        return (f"{text}; likely the solver's noise through the numerical derivative (rtol {rtol:g} x "
                f"{n_samples - 1} sample intervals > {NOISE_LIMIT:g}): tighten it, e.g. --set "
                f"simulation.rtol={NOISE_LIMIT / (n_samples - 1) / 3:.1g} (docs/physics.md)")
    if fastest is not None and spacing * fastest > RESOLVING_SPACING:
        return f"{text}; {_unresolved_mode(fastest, t_end, spacing)}"
    wanted = samples_for_rate_check(n_samples, relative, LYAPUNOV_RATE_TOLERANCE)
    return (f"{text}; likely the samples are too sparse for t_end {t_end:g} s (spacing {spacing:.3g} s) "
            f"to differentiate v: more samples, e.g. --set simulation.n_samples={wanted} (docs/physics.md)")


def simulation_rate_check_reason(summary: Mapping[str, Any], simulation: Mapping[str, Any], *,
                                 where: float | None = None, fastest: float | None = None) -> str:
    """:func:`rate_check_reason` of a run with its ``simulation`` settings (a mapping: the
    ``simulation`` section of its resolved configuration, ``n_samples``, ``t_end`` [s], ``rtol``)."""
    return rate_check_reason(summary, n_samples=int(simulation["n_samples"]), t_end=float(simulation["t_end"]),
                             rtol=float(simulation["rtol"]), where=where, fastest=fastest)


def largest_mismatch_time(time, rate, numerical) -> float | None:
    """The time [s] of the largest |analytic - numerical dv/dt| over the finite samples."""
    difference = np.abs(np.asarray(rate, dtype=float) - np.asarray(numerical, dtype=float))
    finite = np.isfinite(difference)
    if not finite.any():
        return None
    return float(np.asarray(time, dtype=float)[finite][np.argmax(difference[finite])])


def file_rate_check_reason(path, summary: Mapping[str, Any], fastest=None) -> str:
    """:func:`rate_check_reason` of a result file (its samples, its config's rtol, and the
    time of the largest mismatch read from it); empty unless its check failed. ``fastest``,
    given, is called with the file's resolved configuration (a mapping) for the |s| [1/s] of
    its fastest mode or None (:func:`rbstab.analysis.stiffness.fastest_rate`)."""
    if summary.get("lyapunov_rate_check") != "fail":
        return ""
    import h5py  # heavy
    import yaml  # heavy

    with h5py.File(path, "r") as f:
        time = f["time"][()]
        where = largest_mismatch_time(time, f["lyapunov_rate"][()], f["lyapunov_rate_numerical"][()])
        config = f.attrs.get("config", "")
    if isinstance(config, bytes):
        config = config.decode()
    try:
        resolved = yaml.safe_load(config) or {}
    except yaml.YAMLError:
        resolved = {}
    simulation = {"t_end": time[-1], "n_samples": len(time), "rtol": 1e-8, **resolved.get("simulation", {})}
    return simulation_rate_check_reason(summary, simulation, where=where,
                                        fastest=fastest(resolved) if fastest is not None and resolved else None)


def chop(values, tolerance: float):
    """``values`` with every entry of magnitude below ``tolerance`` set to 0 (a float or a
    list, as given): an equilibrium found to ``tolerance`` prints ``theta (0, ...)``
    instead of ``theta (7.3633e-23, ...)``."""
    if isinstance(values, (list, tuple, np.ndarray)):
        return [chop(v, tolerance) for v in values]
    value = float(values)
    return 0.0 if abs(value) < tolerance else value
