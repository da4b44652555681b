"""The sublevel estimate {v <= c} checked against simulations: the falsification pass (runs
from states on {v = c}), the run from the configured initial state and every other run of
the same command.

The sampled and locally refined c of :func:`rbstab.analysis.certificate.certify` is an
estimate: a state with dv/dt > 0 that neither the samples nor the local search met would
make it too large. A run that starts inside {v <= c} and leaves it contradicts it:
:func:`rbstab.analysis.certificate.checked` lowers c below that run's starting v and names
the run and why. The runs are

- the falsification pass (:func:`falsify`): :data:`FALSIFICATION_RUNS` runs from states on
  {v = c} (along the directions where the local search found dv/dt largest, the worst
  sample's and random ones, :func:`rbstab.analysis.certificate.level_states`). Such a run
  contradicts {v <= c} (positively invariant, inside the region of attraction) when it
  stops early (it left the domain or ``simulation.limits``) or ends with v(t_end) above
  v(0): what LaSalle's argument rules out. (A run still on its way at t_end is no
  contradiction: t_end bounds what a run can show of convergence, not the estimate.) Where
  one contradicts it, c is lowered below its start and the pass is repeated at half that
  level (at most :data:`FALSIFICATION_ROUNDS` times);
- the run from the configured initial state (:func:`check_initial_run`, one body and
  chain alike): it contradicts {v <= c} only when, started inside, v rises above c at a
  sample or the run fails (gimbal lock, it left ``simulation.limits``, or the solver
  failed). A run still settling at t_end (never above c, not yet converged by the
  convergence rule) is no contradiction: it is run again to a longer t_end
  (:func:`rbstab.analysis.runs.longer_horizon`: 8 slowest time constants of the
  linearisation, at least twice t_end; then twice that, at most 3 times and to 16 times
  t_end) and counts only if the longer run contradicts c;
  one that has still not converged then is named in a note and not counted (one that has
  converged, too). An impulse disturbance is a jump of v, not a rate: the run is
  judged piece by piece between impulses, each piece from its first sample after the
  impulse (a piece an impulse starts above c is no run from inside);
- the other runs of the analysis (:func:`check_runs`): the basin map's runs, each counted
  against c when it starts inside and fails or ends with v(t_end) above its start (a point
  still settling at t_end is no contradiction); the smallest fatal push of each direction
  and the basin stability's draws, each counted when it starts inside and does not recover
  by the rule of the analysis that ran it (so that the push estimate lies below every
  simulated threshold).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..convergence import ROUND_OFF, converged
from .certificate import Certificate, checked, level_states
from .runs import SETTLING_CONTINUATIONS, Runs, continued, longer_horizon

__all__ = ["falsify", "falsify_with", "check_runs", "check_initial_run", "contradiction", "FALSIFICATION_RUNS",
           "FALSIFICATION_ROUNDS"]

#: Runs of the falsification pass from states on {v = c}.
FALSIFICATION_RUNS = 32
#: Levels the pass tries at most (each half the start of the run that did not recover).
FALSIFICATION_ROUNDS = 6


def _state_text(y: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in y) + ")"


def falsify(config, model, linearisation, certificate: Certificate, *, runs: int = FALSIFICATION_RUNS,
            seed: int = 0, jobs: int = 1) -> Certificate:
    """``certificate`` after the falsification pass (module docstring), its runs on the CPU's
    compiled engine (:class:`rbstab.analysis.runs.Runs`: 32 runs a level, where a GPU gains
    nothing).

    Parameters
    ----------
    config : RunConfig
        The configuration analysed (its runs: its bodies, laws, gains, disturbances, limits,
        settings).
    model : rbstab.analysis.certificate.Model
        The certificate's model (its v: the tree's
        :class:`~rbstab.analysis.certificate.ChainModel` in its independent coordinates),
        without disturbances.
    linearisation : rbstab.analysis.linearise.Linearisation
    certificate : Certificate
    runs : int
        States on {v = c} per level (0: no pass).
    seed : int
        Of the random directions.
    jobs : int
        Threads integrating a tree's runs (:class:`rbstab.analysis.runs.Runs`).
    """
    batch, states = Runs(config, jobs=jobs), model.states

    def run(x):
        ok, v0, v1 = batch.outcomes(states(x))
        with np.errstate(invalid="ignore"):
            return (ok == 1) & np.isfinite(v1) & (v1 <= v0 + ROUND_OFF), v0

    return falsify_with(run, model, linearisation, certificate, runs=runs, seed=seed)


def falsify_with(run, model, linearisation, certificate: Certificate, *, runs: int = FALSIFICATION_RUNS,
                 seed: int = 0) -> Certificate:
    """``certificate`` after the falsification pass (module docstring) with the runs of
    ``run``: ``run(x)`` -> (whether each run from the states ``x`` (k, n; the model's
    coordinates) recovered by the pass's rule, v [J] where each starts); ``model`` a
    :class:`rbstab.analysis.certificate.Model` (its v: the certificate's)."""
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


def _pieces(time: np.ndarray, impulses) -> list[tuple[np.ndarray, float | None]]:
    """The pieces of a run between its impulses: (the indices of its samples, the time [s] of
    the impulse it starts after, None for the first), in order; a sample at an impulse's
    time belongs to none (v jumps there)."""
    times = np.sort(np.asarray(list(impulses), dtype=float))
    before = np.searchsorted(times, time, side="left")
    at = np.searchsorted(times, time, side="right") != before
    return [(np.flatnonzero((before == k) & ~at), None if k == 0 else float(times[k - 1]))
            for k in range(len(times) + 1)]


def contradiction(time, lyapunov, ok: bool, message: str, sublevel: float, impulses=()):
    """Whether a run contradicts {v <= c} (module docstring): v rises above c after the run
    (or a piece of it between impulses) started inside, or the run fails in a piece that
    started inside.

    Parameters
    ----------
    time : array_like, shape (n,)
        The run's sample times [s].
    lyapunov : array_like, shape (n,)
        v [J] at ``time`` (NaN after a failure).
    ok : bool
        The run reached t_end (status ``success``).
    message : str
        Why it stopped (its status message).
    sublevel : float
        c [J].
    impulses : sequence of float
        Times [s] of its impulse disturbances.

    Returns
    -------
    (float, str, float or None) or None
        (v [J] where the contradicting piece started, why in words ("v rose above c = 229.9 J
        (to 230.4 J at t = 0.31 s)", "failed: <message>"), the time [s] of the impulse that
        piece starts after, None for the run's start); None where the run does not
        contradict c.
    """
    time = np.asarray(time, dtype=float)
    v = np.asarray(lyapunov, dtype=float)
    c = float(sublevel)
    last = None
    for rows, after in _pieces(time, impulses):
        rows = rows[np.isfinite(v[rows])]
        if not rows.size:
            continue
        last = (float(v[rows[0]]), after)
        if not last[0] <= c:
            continue
        above = rows[v[rows] > c + ROUND_OFF]
        if above.size:
            i = int(above[0])
            return last[0], f"v rose above c = {c:.4g} J (to {v[i]:.4g} J at t = {time[i]:.4g} s)", after
    if not ok and last is not None and last[0] <= c:
        return last[0], f"failed: {message}", last[1]
    return None


def check_initial_run(certificate: Certificate, config, simulate, linearisation, *, ratio: float, first=None,
                      impulses=(), name: str = "the run from the configured initial state") -> Certificate:
    """``certificate`` checked against the run from ``config``'s initial state (module
    docstring): c is lowered where it contradicts c (:func:`contradiction`); a run still
    settling at t_end is run again to a longer t_end first, and one that has not converged
    then is named in a note, not counted.

    Parameters
    ----------
    certificate : Certificate
    config : RunConfig
        The configuration analysed (its ``simulation``: t_end, samples, step limit).
    simulate : callable
        ``simulate(config)`` -> a :class:`rbstab.results.RunResult` (``time`` [s],
        ``outputs["lyapunov"]`` [J], ``ok``, ``message``):
        :func:`rbstab.simulator.simulate`.
    linearisation : Linearisation
        Of the certificate (its ``slowest_time_constant`` [s] sets the longer t_end).
    ratio : float
        Converged: |v(t_end)| <= ratio |v(0)| + 1e-12 J (:func:`rbstab.convergence.converged`).
    first : RunResult, optional
        ``simulate(config)`` where already run.
    impulses : sequence of float
        Times [s] of the run's impulse disturbances.
    name : str
        The run, for the notes.
    """
    run = simulate(config) if first is None else first
    t_end = horizon = float(config.simulation.t_end)
    v0 = float(np.asarray(run.outputs["lyapunov"], dtype=float)[0])
    if not certificate.positive_definite:
        return checked(certificate, [v0], [True], lambda i: name)
    c = certificate.sublevel
    tau = float(linearisation.slowest_time_constant)
    for k in range(SETTLING_CONTINUATIONS + 1):
        time, v = np.asarray(run.time, dtype=float), np.asarray(run.outputs["lyapunov"], dtype=float)
        found = contradiction(time, v, run.ok, run.message, c, impulses)
        if found is not None:
            level, why, after = found
            named = name if after is None else f"{name}, from just after its impulse at t = {after:.4g} s,"
            return checked(certificate, [level], [False], lambda i: named, reasons=[why])
        pieces = [(rows[np.isfinite(v[rows])], after) for rows, after in _pieces(time, impulses)]
        starts = [(float(v[rows[0]]), after) for rows, after in pieces if rows.size]  # where each piece started
        settling = run.ok and not converged(True, v0, v[-1], ratio) and bool(starts) and starts[-1][0] <= c
        longer = longer_horizon(t_end, horizon, k, tau)
        if not settling or k == SETTLING_CONTINUATIONS or longer <= horizon:
            break
        horizon = longer
        run = simulate(continued(config, horizon))
    out = checked(certificate, [v0], [True], lambda i: name)
    if settling:
        note = (f"{name} started inside {{v <= c}} at v = {starts[-1][0]:.4g} J"
                + (f" (after the impulse at t = {starts[-1][1]:.4g} s)" if starts[-1][1] is not None else "")
                + f", never rose above c and had not converged after {horizon:.4g} s (v = {v[-1]:.4g} J then, "
                f"converged: |v| <= {ratio:g} |v(0)|): not counted against c")
    elif not run.ok and starts and starts[-1][1] is not None and v0 <= c:
        note = (f"{name} failed ({run.message}) after the impulse at t = {starts[-1][1]:.4g} s took v to "
                f"{starts[-1][0]:.4g} J, above c: not counted against c")
    elif run.ok and horizon > t_end:
        note = (f"{name} had not converged by t_end = {t_end:.4g} s; run again to {horizon:.4g} s, it converged "
                "without rising above c")
    else:
        return out
    return replace(out, notes=out.notes + (note,))


def check_runs(certificate: Certificate, analysis) -> Certificate:
    """``certificate`` checked against the runs of ``analysis`` (an
    :class:`~rbstab.analysis.Analysis`, or an object with ``basin``, ``push`` and
    ``basin_stability``): its basin map, pushes and basin stability, those it has, each run
    counted where it starts inside {v <= c} and does not recover by its analysis's rule (the
    run from the configured initial state: :func:`check_initial_run`)."""
    b = analysis.basin
    if b is not None:
        x, y = (a.values for a in b.axes)
        k0, k1 = (a.key for a in b.axes)
        n1 = len(y)
        outcome, v0, v1 = b.outcome.ravel(), b.lyapunov_initial.ravel(), b.lyapunov_final.ravel()
        risen = v1 > v0 + ROUND_OFF * np.maximum(np.abs(v0), 1.0)
        # a point still settling at t_end (never failed, v(t_end) <= v(0)) is no contradiction
        recovered = (outcome == 0) | ((outcome == 1) & ~risen)
        reasons = [("failed (it left the domain or simulation.limits)" if o == 2 else
                    f"ended at v(t_end) = {e:.4g} J, above its start") for o, e in zip(outcome, v1)]
        certificate = checked(certificate, v0, recovered,
                              lambda i: f"the basin map's run from {k0} = {x[i // n1]:.4g}, {k1} = {y[i % n1]:.4g}",
                              reasons)
    p = analysis.push
    if p is not None:
        v0, name = p.fatal_starts()
        certificate = checked(certificate, v0, np.zeros(len(v0), dtype=bool), name)
    st = analysis.basin_stability
    if st is not None:
        certificate = checked(certificate, st.lyapunov_start, st.recovered,
                              lambda i: f"basin-stability draw {i} ({', '.join(f'{k} = {v:.4g}' for k, v in zip(st.keys, st.values[i]))})")
    return certificate
