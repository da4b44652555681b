"""The sublevel estimate {v <= c} checked against simulations: the falsification pass (runs
from states on {v = c}) and every other run of the same command.

The sampled and locally refined c of :func:`rbstab.analysis.certificate.certify` is an
estimate: a state with dv/dt > 0 that neither the samples nor the local search met would
make it too large. A run that starts inside {v <= c} and does not recover contradicts it:
:func:`rbstab.analysis.certificate.checked` lowers c below that run's starting v and names
the run. The runs are

- the falsification pass (:func:`falsify`): :data:`FALSIFICATION_RUNS` runs from states on
  {v = c} (along the directions where the local search found dv/dt largest, the worst
  sample's and random ones, :func:`rbstab.analysis.certificate.level_states`). Such a run
  contradicts {v <= c} (positively invariant, inside the region of attraction) when it
  stops early (it left the domain or ``simulation.limits``) or ends with v(t_end) above
  v(0): what LaSalle's argument rules out. (A run still on its way at t_end is no
  contradiction: t_end bounds what a run can show of convergence, not the estimate.) Where
  one contradicts it, c is lowered below its start and the pass is repeated at half that
  level (at most :data:`FALSIFICATION_ROUNDS` times);
- those of the analysis itself (:func:`check_runs`): the run from the configured initial
  state, the basin map's runs, the smallest fatal push of each direction, the basin
  stability's draws.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..convergence import ROUND_OFF
from .certificate import Certificate, checked, level_states

__all__ = ["falsify", "falsify_with", "check_runs", "FALSIFICATION_RUNS", "FALSIFICATION_ROUNDS"]

#: Runs of the falsification pass from states on {v = c}.
FALSIFICATION_RUNS = 32
#: Levels the pass tries at most (each half the start of the run that did not recover).
FALSIFICATION_ROUNDS = 6


def _state_text(y: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in y) + ")"


def falsify(config, variant, linearisation, certificate: Certificate, *, runs: int = FALSIFICATION_RUNS,
            ratio: float, engine: str = "compiled", executor=None, seed: int = 0) -> Certificate:
    """``certificate`` after the falsification pass (module docstring).

    Parameters
    ----------
    config : RunConfig
        The configuration analysed (its runs: its body, controller, limits, settings).
    variant : rbstab.variants.Variant
        Its variant without disturbances (the v of the certificate).
    linearisation : rbstab.analysis.linearise.Linearisation
    certificate : Certificate
    runs : int
        States on {v = c} per level (0: no pass).
    ratio : float
        Unused (the pass's rule is v(t_end) <= v(0) inside the domain: module docstring).
    engine, executor
        As :func:`rbstab.analysis.push.runs_from_states` takes them.
    seed : int
        Of the random directions.
    """
    from .push import runs_from_states  # heavy: numba (the batch engine)

    def run(y):
        ok, v0, v1 = runs_from_states(config, y, engine=engine, executor=executor)
        with np.errstate(invalid="ignore"):
            return (ok == 1) & np.isfinite(v1) & (v1 <= v0 + ROUND_OFF), v0

    return falsify_with(run, variant, linearisation, certificate, runs=runs, seed=seed)


def falsify_with(run, model, linearisation, certificate: Certificate, *, runs: int = FALSIFICATION_RUNS,
                 seed: int = 0) -> Certificate:
    """``certificate`` after the falsification pass (module docstring) with the runs of
    ``run``: ``run(x)`` -> (whether each run from the states ``x`` (k, n; the model's
    coordinates) recovered by the pass's rule, v [J] where each starts); ``model`` a variant
    or a :class:`rbstab.analysis.certificate.Model` (its v: the certificate's)."""
    if runs < 1 or not certificate.positive_definite:
        return certificate
    for _ in range(FALSIFICATION_ROUNDS):
        level = certificate.sublevel
        y = level_states(model, linearisation, certificate, runs, seed)
        if not len(y):
            return certificate
        recovered, v0 = run(y)
        certificate = checked(certificate, v0, recovered,
                              lambda i: f"the falsification run from {{v = {level:.4g} J}} at y = "
                              f"{_state_text(y[i])} (it left the domain or ended with v above its start)")
        if certificate.sublevel >= level:
            return certificate
        lower = 0.5 * certificate.sublevel
        certificate = replace(certificate, sublevel=lower, notes=certificate.notes[:-1] + (
            certificate.notes[-1] + f"; the pass tried again at half that, c = {lower:.4g} J",))
    y = level_states(model, linearisation, certificate, runs, seed)
    recovered, v0 = run(y)
    if not recovered.all():
        certificate = replace(certificate, sublevel=0.0, notes=certificate.notes + (
            "no level tried by the falsification pass recovered every run: no estimate",))
    return replace(certificate, runs_checked=certificate.runs_checked + len(v0))


def check_runs(certificate: Certificate, analysis) -> Certificate:
    """``certificate`` checked against the runs of ``analysis`` (an
    :class:`~rbstab.analysis.Analysis`): its settling run, basin map, pushes and basin
    stability, those it has."""
    s = analysis.settling
    if s is not None:
        ok = s["status"] == "success" and np.isfinite(s["time_to_converge"])
        certificate = checked(certificate, [s["lyapunov_initial"]], [ok],
                              lambda i: "the run from the configured initial state")
    b = analysis.basin
    if b is not None:
        x, y = (a.values for a in b.axes)
        k0, k1 = (a.key for a in b.axes)
        n1 = len(y)
        certificate = checked(certificate, b.lyapunov_initial.ravel(), (b.outcome == 0).ravel(),
                              lambda i: f"the basin map's run from {k0} = {x[i // n1]:.4g}, {k1} = {y[i % n1]:.4g}")
    p = analysis.push
    if p is not None:
        v0, name = p.fatal_starts()
        certificate = checked(certificate, v0, np.zeros(len(v0), dtype=bool), name)
    st = analysis.basin_stability
    if st is not None:
        certificate = checked(certificate, st.lyapunov_start, st.recovered,
                              lambda i: f"basin-stability draw {i} ({', '.join(f'{k} = {v:.4g}' for k, v in zip(st.keys, st.values[i]))})")
    return certificate
