"""Plain-text summaries of an analysis and of a robustness result (what ``rbstab analyze`` prints)."""

from __future__ import annotations

import numpy as np

from ..layout import BLOCK_UNITS
from .certificate import BOUNDS
from .linearise import mode_shapes
from .thresholds import EXPLAINS_BAR

__all__ = ["certificate_lines", "describe", "describe_robustness", "format_eigenvalue", "format_state", "mode_lines",
           "mode_shape_lines", "push_lines",
           "rule_lines", "stability_lines", "time_scale"]


def _g(value, digits: int = 4) -> str:
    value = float(value)
    if not np.isfinite(value):
        return "inf" if value > 0 else "-inf" if value < 0 else "-"
    return f"{value:.{digits}g}"


def format_eigenvalue(s: complex) -> str:
    """``-3.024 + 7.556i`` (``-148.7`` when real)."""
    if s.imag == 0:
        return _g(s.real)
    return f"{_g(s.real)} {'+' if s.imag > 0 else '-'} {_g(abs(s.imag))}i"


#: Entries of a state below this [rad, m, ...] print as 0: the round-off of an equilibrium
#: found by a root finder to xtol 1e-13 (a solved 7.4e-23 is 0 to that tolerance).
ROUND_OFF_STATE = 1e-12


def format_state(layout, y: np.ndarray) -> str:
    """``theta (0, 0, 0) rad, omega (0, 0, 0) rad s-1, ...`` (entries below
    :data:`ROUND_OFF_STATE` as 0)."""
    parts = []
    y = np.asarray(y, dtype=float)
    y = np.where(np.abs(y) < ROUND_OFF_STATE, 0.0, y)
    for block, values in layout.split(y).items():
        parts.append(f"{block} ({', '.join(_g(v, 6) for v in values + 0.0)}) {BLOCK_UNITS[block]}")
    return ", ".join(parts)


def time_scale(verdict: str, slowest_time_constant: float, shortest_e_folding_time: float) -> str:
    """The time scale of a linearisation in words, from its eigenvalue with the largest real
    part (:mod:`rbstab.analysis.linearise`): ``slowest time constant 0.4296 s`` when
    asymptotically stable, ``unstable: e-folding time 2.495 s`` when unstable,
    ``marginally stable (a zero or imaginary eigenvalue)`` when marginal (no number).

    Parameters
    ----------
    verdict : str
        One of :data:`rbstab.analysis.linearise.VERDICTS`.
    slowest_time_constant, shortest_e_folding_time : float
        [s] (:attr:`rbstab.analysis.linearise.Linearisation.slowest_time_constant`,
        :attr:`~rbstab.analysis.linearise.Linearisation.shortest_e_folding_time`); the one
        the verdict does not name is not read.
    """
    if verdict == "asymptotically stable":
        return f"slowest time constant {_g(slowest_time_constant)} s"
    if verdict == "unstable":
        return f"unstable: e-folding time {_g(shortest_e_folding_time)} s"
    return "marginally stable (a zero or imaginary eigenvalue)"


def _time_scale(lin) -> str:
    return time_scale(lin.verdict, lin.slowest_time_constant, lin.shortest_e_folding_time)


def mode_lines(lin) -> list[str]:
    """The table of the eigenvalues of ``lin`` (a :class:`rbstab.analysis.linearise.Linearisation`):
    s, natural frequency, damping ratio, time constant and e-folding time, a line each."""
    lines = [f"  {'eigenvalue s [1/s]':<26}{'omega_n [rad/s]':>16}{'zeta':>11}{'tau [s]':>11}{'e-folding [s]':>15}"]
    for s, wn, zeta, tau, e_fold in zip(lin.eigenvalues, lin.natural_frequency, lin.damping_ratio, lin.time_constant,
                                        lin.e_folding_time):
        lines.append(f"  {format_eigenvalue(s):<26}{_g(wn):>16}{_g(zeta, 3):>11}{_g(tau):>11}{_g(e_fold):>15}")
    return lines


def mode_shape_lines(lin, names, rows, shown: int = 6) -> list[str]:
    """The shapes of the slowest ``shown`` modes of ``lin`` (one of each complex pair) on the
    state entries ``rows`` named ``names`` (:func:`rbstab.analysis.linearise.mode_shapes`):
    each entry of at least 5 % of the largest as its size and, where it is not in phase
    with the largest, its phase in degrees."""
    shapes = mode_shapes(lin, rows)
    lines = [f"  mode shapes on {', '.join(names)} (the largest entry 1; phases in degrees):"]
    picked = [k for k, s in enumerate(lin.eigenvalues) if s.imag >= 0.0][:shown]
    for k in picked:
        parts = []
        for name, c in zip(names, shapes[k]):
            if abs(c) >= 0.05:
                phase = np.degrees(np.angle(c))
                parts.append(f"{name} {abs(c):.2g}" + (f" ({phase:+.0f})" if abs(phase) >= 0.5 else ""))
        lines.append(f"    s = {format_eigenvalue(lin.eigenvalues[k])}: {', '.join(parts)}")
    return lines


def _settling_line(analysis) -> str:
    s = analysis.settling
    head = f"  {_time_scale(analysis.linearisation)}"
    if s is None:
        return head
    if s["status"] != "success":
        return f"{head}; the simulation from the configured initial state failed: {s['message']}"
    if not np.isfinite(s["time_to_converge"]):
        return f"{head}; the simulation from the configured initial state did not converge (|v| <= {s['ratio']:g} |v(0)|) " \
               f"by t_end = {_g(s['t_end'])} s"
    alone = analysis.linear_settling_time
    return (f"{head}; the simulation from the configured initial state converged (|v| <= {s['ratio']:g} |v(0)| from "
            f"then on) at {_g(s['time_to_converge'])} s"
            + (f" (the slowest mode alone: {_g(alone)} s)" if np.isfinite(alone) else ""))


def certificate_lines(c, domain: str | None = None) -> list[str]:
    """The lines of a :class:`rbstab.analysis.certificate.Certificate` (none for None);
    ``domain`` names the angles of the domain boundary (a chain's)."""
    if c is None:
        return []
    head = f"  certificate: {'holds (' + c.argument + ')' if c.holds else 'does not hold'}"
    lines = [head, f"    v(y_e) = {_g(c.lyapunov_equilibrium)} J; Hessian of v "
             f"{'positive definite' if c.positive_definite else 'NOT positive definite'} (smallest eigenvalue "
             f"{_g(c.hessian_min_eigenvalue)})"]
    if not c.positive_definite:
        return lines + ["    no sublevel estimate: v has no strict minimum at the equilibrium"]
    zero = int(np.sum(np.abs(c.rate_eigenvalues) <= 1e-8 * np.abs(c.rate_eigenvalues).max()))
    lines.append(f"    Hessian of dv/dt {c.rate_definiteness} ({zero} of {len(c.rate_eigenvalues)} generalised "
                 f"eigenvalues zero); LaSalle's condition (PBH test) {'holds' if c.lasalle_observable else 'FAILS'}")
    lines.append(f"    {c.n_samples} sampled states: largest dv/dt {_g(c.worst_rate)} W at v = {_g(c.worst_lyapunov)} J; "
                 f"|numerical - analytic dv/dt| <= {_g(c.rate_mismatch, 2)} of the power scale")
    boundary = f"domain boundary{f' ({domain})' if domain else ''} at {_g(c.boundary_level)} J"
    bound = boundary if c.sublevel_bound == BOUNDS[0] else f"{c.sublevel_bound}; {boundary}"
    lines.append(f"    inner estimate of the region of attraction: {{v <= {_g(c.sublevel)} J}}, an {c.evidence}; "
                 f"bounded by: {bound}")
    lines += [f"    {note}" for note in c.notes]
    if len(c.sublevel_history):
        steps = ", ".join(f"{n} states {_g(h)} J" for n, h in zip(c.history_samples, c.sublevel_history))
        lines.append(f"    c with the local search from the first N/4, N/2, N samples: {steps} (samples alone: "
                     f"{_g(c.sublevel_sampled)} J): " + ("settled" if c.settled else
                                                          "STILL MOVING (an estimate to take with care; more --samples)"))
    return lines


def _verification_lines(analysis) -> list[str]:
    w = getattr(analysis, "verification", None)
    if w is None:
        return []
    c = analysis.certificate
    ratio = (f"; {w.level / c.sublevel:.3g} x the estimate {_g(c.sublevel)} J"
             if c is not None and c.sublevel > 0 and np.isfinite(c.sublevel) else "")
    return [f"  {w.summary}{ratio}: {{v <= c}} proven positively invariant and inside the region of attraction",
            f"    bounded by: {w.reason}"]


def _basin_lines(analysis) -> list[str]:
    b = analysis.basin
    if b is None:
        return []
    counts = b.counts()
    keys = " x ".join(f"{a.key} ({len(a.values)})" for a in b.axes)
    lines = [f"  basin over {keys}: " + ", ".join(f"{n} {k}" for k, n in counts.items())]
    for message, n in b.messages.items():
        lines.append(f"    {n} failed: {message}")
    inside = analysis.basin_inside()
    c = analysis.certificate
    if inside is not None and c.positive_definite and np.isfinite(c.sublevel) and c.sublevel > 0:
        total = sum(inside.values())
        verdict = "all converged" if inside["converged"] == total else \
            ", ".join(f"{n} {k}" for k, n in inside.items()) + " (the estimate is NOT inside the basin map)"
        lines.append(f"    inside the sublevel estimate: {total} points, {verdict}" if total else
                     "    inside the sublevel estimate: no point of the basin map (the estimate lies between its points)")
    return lines


def _direction(u) -> str:
    return "(" + ", ".join(f"{x:+.3f}" for x in u) + ")"


def push_lines(analysis) -> list[str]:
    """The lines of ``analysis.push`` (a :class:`rbstab.analysis.push.PushAnalysis`, with
    ``analysis.certificate`` or None)."""
    p = analysis.push
    if p is None:
        return []
    where = f" at ({', '.join(_g(x) for x in p.point)}) m" if p.kind == "force" else ""
    if p.body is not None:
        where += f" on {p.body}"
    frame = "inertial frame" if p.kind == "force" else f"{p.body or 'body'}'s frame"
    t = p.threshold
    finite = np.isfinite(t)
    lines = [f"  smallest fatal {p.kind} push{where}, t0 = {_g(p.at)} s, over {len(t)} directions ({frame}; "
             f"relative tolerance {_g(p.tol)}; {p.runs} runs on {p.engine}):"]
    if p.continued:
        lines.append(f"    {p.continued} runs still settling at t_end (v between 0 and dT, not yet converged) were run "
                     f"again to at most {_g(p.continued_to)} s and judged there")
    if not finite.any():
        lines.append(f"    none: every push up to the ladders' top recovered ({_g(np.max(p.thresholds.ladder))} {p.units})")
        return lines
    lines.append(f"    minimum {_g(p.minimum, 5)} {p.units} along {_direction(p.minimum_direction)}"
                 + (f" (the local search lowered it by {p.refinement_gain:.1%} from {_g(p.grid_minimum, 5)})"
                    if len(p.refined_thresholds) else ""))
    lines.append(f"    over the directions: median {_g(np.median(t[finite]), 4)}, largest {_g(np.max(t[finite]), 4)} "
                 f"{p.units}" + (f"; {int((~finite).sum())} recovered from every rung" if (~finite).any() else ""))
    c = analysis.certificate
    if c is not None and c.positive_definite:
        lines.append(f"    estimate from {{v <= {_g(c.sublevel)} J}}: pushes up to {_g(p.estimate(c.sublevel), 4)} {p.units} "
                     "recover in every direction (min over the directions of sqrt(c / dT); below every simulated "
                     "threshold)")
    flagged = int((~p.thresholds.monotone).sum())
    if flagged:
        lines.append(f"    recovery is not monotone in the magnitude along {flagged} of {len(t)} directions (a rung "
                     "above the first fatal one recovered): their threshold is the first fatal magnitude seen from "
                     "below, at the ladder's resolution")
    return lines


def stability_lines(analysis) -> list[str]:
    """The lines of ``analysis.basin_stability`` (a :class:`rbstab.analysis.push.BasinStability`)."""
    b = analysis.basin_stability
    if b is None:
        return []
    lo, hi = b.interval
    what = (f"random {b.kind} pushes of {_g(b.low[0])} .. {_g(b.high[0])} {b.units[0]} in uniform directions"
            if b.perturbation == "push" else
            "initial states with " + ", ".join(f"{k} in [{_g(a)}, {_g(z)}]" for k, a, z in zip(b.keys, b.low, b.high)))
    lines = [f"  basin stability over {what}: {int(b.recovered.sum())} of {b.draws} recovered = {b.fraction:.1%} "
             f"({b.confidence:.0%} Wilson interval {lo:.1%} - {hi:.1%})"]
    return lines + rule_lines([(s.parameter, s.rule) for s in b.separations], EXPLAINS_BAR)


def _rule_text(rule) -> str:
    """``x < 0.41``, ``-0.41 < x < 0.42, i.e. |x - 0.005| < 0.415`` ... of a
    :class:`rbstab.analysis.thresholds.SplitRule` (x: the key's value)."""
    if rule.side == "below":
        return f"x < {_g(rule.high, 5)}"
    if rule.side == "above":
        return f"x > {_g(rule.low, 5)}"
    centre, half = 0.5 * (rule.low + rule.high), 0.5 * (rule.high - rule.low)
    centred = f"|x {'-' if centre >= 0 else '+'} {_g(abs(centre))}|"
    if rule.side == "inside":
        return f"{_g(rule.low, 5)} < x < {_g(rule.high, 5)}, i.e. {centred} < {_g(half)}"
    return f"x < {_g(rule.low, 5)} or x > {_g(rule.high, 5)}, i.e. {centred} > {_g(half)}"


def rule_lines(rules, bar: float) -> list[str]:
    """The basin stability's lines of the rules of single keys.

    Parameters
    ----------
    rules : list of (str, SplitRule)
        Per key that has draws of both outcomes, its rule
        (:func:`rbstab.analysis.thresholds.split_rule`).
    bar : float
        The balanced accuracy from which a rule explains the outcome.

    Returns
    -------
    list of str
        ``KEY: recovered where RULE (balanced accuracy ...)`` per key whose rule explains,
        ``KEY: no threshold (...)`` per other key; where no key's rule explains, one line
        ``no single key explains the outcome (best: balanced accuracy ...)``.
    """
    if not rules:
        return []
    if not any(r.explains for _, r in rules):
        key, best = max(rules, key=lambda kr: kr[1].balanced_accuracy)
        return [f"    no single key explains the outcome (best: balanced accuracy {best.balanced_accuracy:.1%}, "
                f"{key}; a threshold is given from {bar:.0%})"]
    return [f"    {key}: recovered where {_rule_text(r)} (balanced accuracy {r.balanced_accuracy:.1%})" if r.explains
            else f"    {key}: no threshold (best: balanced accuracy {r.balanced_accuracy:.1%}, below {bar:.0%})"
            for key, r in rules]


def describe(analysis) -> list[str]:
    """Lines summarising an :class:`~rbstab.analysis.Analysis`: the verdict, the notes, the
    equilibrium (a chain's by body), the rest-point check, the table of modes (a chain's mode shapes on its
    bodies' angles), the settling, the certificate, the verification, the basin map, the
    pushes and the basin stability."""
    lin = analysis.linearisation
    tree = analysis.kind == "chain"
    size = f"; {lin.equilibrium.size} independent coordinates" if tree else ""
    lines = [f"{analysis.name} ({analysis.variant}): {lin.verdict} (tolerance |Re s| <= {_g(lin.tolerance, 2)} 1/s{size})"]
    lines += [f"  note: {n}" for n in analysis.notes]
    lines.append(f"  equilibrium: {_equilibrium(analysis)}")
    rest = "yes" if lin.is_rest_point else "NO"
    lines.append(f"  rest point: {rest} (max |dy/dt| {_g(np.abs(lin.rest_residual).max(), 3)} <= "
                 f"{_g(lin.rest_tolerance, 3)})")
    lines += mode_lines(lin)
    if tree:
        lines += mode_shape_lines(lin, *analysis.angles())
    lines.append(_settling_line(analysis))
    lines += certificate_lines(analysis.certificate, domain=analysis.domain)
    lines += _verification_lines(analysis)
    lines += _basin_lines(analysis)
    lines += push_lines(analysis)
    lines += stability_lines(analysis)
    return lines


def _equilibrium(analysis) -> str:
    """The equilibrium's state blocks, one body's (:func:`format_state`) or a chain's by body
    (``legs: theta (0, 0, 0) rad, omega (0, 0, 0) rad s-1; trunk: ...``)."""
    y = analysis.linearisation.equilibrium
    if analysis.kind != "chain":
        return format_state(analysis.layout, y)
    y = np.where(np.abs(y) < ROUND_OFF_STATE, 0.0, y)
    bodies: dict[str, list[str]] = {}
    for (body, block, _, size), at in zip(analysis.coordinates, analysis.layout.offsets()):
        values = ", ".join(_g(v, 6) for v in y[at: at + size] + 0.0)
        bodies.setdefault(body, []).append(f"{block} ({values}) {BLOCK_UNITS[block]}")
    return "; ".join(f"{body}: {', '.join(parts)}" for body, parts in bodies.items())


def describe_robustness(result) -> list[str]:
    """Lines summarising a :class:`~rbstab.analysis.robustness.Robustness`."""
    lines = [f"robustness of sweep {result.sweep} ({result.folder}); converged by t_end: the run reached t_end "
             f"with |v(t_end)| <= {_g(result.ratio)} |v(0)| (stability as seen over t_end, not a proof)"]
    for g in result.groups:
        lo, hi = g.interval
        excluded = f", {g.n_excluded} without a result left out" if g.n_excluded else ""
        if g.n_disagree:
            excluded += (f"; {g.n_disagree} differ from the sweep's 'converged' (v(t_end) < 0: they fell below "
                         "the equilibrium's v, which is then not its minimum)")
        lines.append(f"  {g.base}: {g.n_stable} of {g.n_runs} converged by t_end = {g.fraction:.1%} "
                     f"({result.confidence:.0%} Wilson interval {lo:.1%} - {hi:.1%}){excluded}")
        if g.n_unstable_rest:
            lines.append(f"    {g.n_unstable_rest} more converged beside an unstable rest state (its linearisation "
                         "is unstable: they have not yet drifted away): counted as not stable")
        if g.n_rest_unchecked:
            lines.append(f"    {g.n_rest_unchecked} converged runs' rest states were not linearised (more than "
                         "1000 distinct configurations): counted as stable")
        h = g.t_end_hint
        if h is not None:
            lines.append(f"    runs that reached t_end without converging are not necessarily unstable: the linearisation of "
                         f"{h['run_id']} is asymptotically stable, its slowest mode (tau = {_g(h['tau'])} s) alone "
                         f"needs ~{_g(h['settling_time'], 3)} s to converge; t_end = {_g(h['t_end'])} s may be too short")
        if not g.separations:
            reason = "every run converged" if g.n_stable == g.n_runs else "no run converged" \
                if g.n_stable == 0 else "no parameter varies"
            lines.append(f"    no separating parameter: {reason}")
        for s in g.separations:
            r = s.rule
            found = (f"converged where {_rule_text(r)} (balanced accuracy {r.balanced_accuracy:.1%})" if r.explains
                     else f"no threshold (best: balanced accuracy {r.balanced_accuracy:.1%}, below {EXPLAINS_BAR:.0%})")
            lines.append(f"    {s.parameter}: {found}; converged {_g(s.stable_range[0])} .. "
                         f"{_g(s.stable_range[1])}, not converged {_g(s.unstable_range[0])} .. "
                         f"{_g(s.unstable_range[1])}")
        if g.separations and not any(s.rule.explains for s in g.separations):
            lines.append("    no single parameter explains which runs converged")
    return lines
