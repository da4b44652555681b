"""The pure sign law of ``sliding`` (eq 39, boundary_layer 0): event-driven integration.

Lambda = -K_s sgn(E) jumps wherever a component of E changes sign, and an adaptive solver
that sees the jump crawls through it with rejected steps. This engine integrates the motion
piece by piece instead (an event-driven scheme: Acary & Brogliato 2008, part II; Piiroinen
& Kuznetsov 2008; Filippov 1988). On each piece a *mode* sigma in {-1, 0, 1}^3 stands for sgn(E)
(:mod:`rbstab.variants.sliding`) and the right-hand side is smooth; the compiled engine's
Runge-Kutta step (:func:`rbstab.engine.integrate.step`, scipy's) takes it. After each step
the step's interpolant is searched for the first event (at :data:`SEARCH_POINTS` points,
with the rate of each event function to catch a dip through zero and back), located by
regula falsi (Illinois) to a few units of rounding of the step:

- **crossing**: E_i reaches 0 from the side sigma_i; sigma_i flips and a new piece starts;
- **sliding starts** (Filippov sliding on E_i = 0, F_i = 0): at a crossing whose next
  excursion, F_i^2 / (2 |dF_i/dt|), would stay within the resolution (:data:`RESOLUTION`)
  of the surface, if the equivalent force that holds C there is admissible (|Lambda_i| <=
  K_s: from both sides the one-sided vector fields push E_i back to the surface). The
  unresolved chattering is replaced by its Filippov limit: an inelastic impulse at C stops
  F_i (removing F'W^-1 F/2, about K_s times the excursion, of kinetic energy), sigma_i = 0,
  and Lambda_i is the equivalent force (Utkin's equivalent control);
- **sliding ends**: |Lambda_i| of a sliding axis reaches K_s; then sigma_i = -sgn(Lambda_i)
  (the force is continuous) and C leaves the surface on the side the force cannot hold;
- **the admissible region**: |theta_2| reaches pi/2 - gimbal_margin (gimbal lock, eq 5) or
  a component reaches its bound of ``simulation.limits``
  (:func:`rbstab.engine.systems.admissible_event`): the run stops, failed.

Methods: RK23, RK45, DOP853 (the compiled engine's); a run configured with an implicit
method is integrated with DOP853 between switchings (each piece has a constant or
equivalent force, nothing stiff comes from the law) and its message says so.
See docs/sliding.md for the physics, the resolution and measured figures.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass, field

import numpy as np

from ..jit import jit
from ..kinematics import GIMBAL_LOCK_ANGLE
from ..summary import piecewise_numerical_rate
from ..variants.kernels import SLIDING, state_rate
from ..variants.sliding import mode_code, mode_quantities, mode_rows, stop_at_c
from .integrate import CLOCK_EVERY, admissible_event, sample_time, step, wall_clock
from .rk import DOP853, N_STAGES, dense_coefficients, dense_value, initial_step, method_number
from .settings import settings_records, settings_rows, work_arrays
from .status import NOT_FINITE, STEP_LIMIT, SUCCESS, SWITCHING_LIMIT, TIMEOUT, status_message
from .tableaus import METHODS

__all__ = [
    "RESOLUTION",
    "MAX_SWITCHINGS",
    "SEARCH_POINTS",
    "CROSSING",
    "SLIDING_STARTS",
    "SLIDING_ENDS",
    "EVENT_KINDS",
    "Switchings",
    "SignLawSolution",
    "integrate_sign_law",
    "sign_law_outputs",
    "switching_summary",
    "switching_message",
]

#: Switching resolution [m]: a crossing after which E_i would stay within this distance of
#: its surface (next excursion F_i^2 / (2 |dF_i/dt|) smaller) starts sliding, when the
#: equivalent force is admissible, instead of being refined switching by switching.
RESOLUTION = 1e-9
#: Events after which a run stops as failed (switchings the resolution does not catch).
MAX_SWITCHINGS = 1_000_000
#: Points at which each step's interpolant is searched for events (besides the step's start).
SEARCH_POINTS = 8
#: Width (a fraction of the step) to which an event is located.
X_TOLERANCE = 4 * np.finfo(float).eps

#: Event kinds (``Switchings.kind``) and their names.
CROSSING, SLIDING_STARTS, SLIDING_ENDS = 0, 1, 2
EVENT_KINDS = ("crossing", "sliding starts", "sliding ends")


@dataclass
class Switchings:
    """The located events of a run, in time order.

    Attributes
    ----------
    time : ndarray, shape (k,)
        Event times [s].
    axis : ndarray of int, shape (k,)
        The component i of E (0, 1, 2: x, y, z of the inertial frame).
    kind : ndarray of int, shape (k,)
        :data:`CROSSING`, :data:`SLIDING_STARTS` or :data:`SLIDING_ENDS`.
    rate : ndarray, shape (k,)
        F_i at the event [m/s] (before the impulse of a sliding start).
    """

    time: np.ndarray
    axis: np.ndarray
    kind: np.ndarray
    rate: np.ndarray


@dataclass
class SignLawSolution:
    """Samples of a sign-law run, their modes and the run's events.

    Attributes
    ----------
    time : ndarray, shape (n_samples,)
        Sample times [s], evenly spaced on [0, t_end].
    states : ndarray, shape (n_samples, 12)
        Interpolated states; NaN after a failure.
    modes : ndarray, shape (n_samples, 3)
        sigma of the piece each sample lies on (NaN after a failure).
    switchings : Switchings
    status, message : str
        ``"success"`` or ``"failed"``, and the solver's message or why it failed.
    solver : dict
        ``nfev``, ``n_steps``, ``n_pieces`` (ints) and ``solver_status`` (0, or the
        engine's failure code).
    resolution : float
        The switching resolution used [m].
    jumps : ndarray, shape (3,)
        Summed |Delta Lambda_i| over the events [N]: 2 K_s per crossing of axis i, the jump
        at a sliding start, and the jumps a switching of another axis causes in the
        equivalent force of a sliding axis.
    t_stop : float
        Where the integration ended [s] (t_end, or the time of a failure).
    method : str
        The Runge-Kutta pair that integrated the pieces (:func:`engine_method`).
    """

    time: np.ndarray
    states: np.ndarray
    modes: np.ndarray
    switchings: Switchings
    status: str
    message: str
    solver: dict = field(default_factory=dict)
    resolution: float = RESOLUTION
    jumps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t_stop: float = 0.0
    method: str = "DOP853"


# -- events (compiled) ----------------------------------------------------------------------------
@jit
def _event_values(y, p, mode, limit, g, dg):
    """Event functions g (4,) at ``y`` and their rates dg (NaN where not used): per axis
    sigma_i E_i (rate sigma_i F_i), or K_s - |Lambda_i| when sliding; then the margin of
    the admissible region (gimbal lock at ``limit`` and ``simulation.limits``:
    :func:`rbstab.engine.systems.admissible_event`). An event is a g falling from > 0 to
    <= 0."""
    e, f, lam, _ = mode_quantities(y, p, mode)
    for i in range(3):
        if mode[i] == 0.0:
            g[i] = p.k_s - abs(lam[i])
            dg[i] = np.nan
        else:
            g[i] = mode[i] * e[i]
            dg[i] = mode[i] * f[i]
    g[3] = admissible_event(SLIDING, y, p, limit)[0]
    dg[3] = np.nan


#: A step's interpolant: size h [s], the state y_old at its start, the coefficients Q
#: (:func:`rbstab.engine.rk.dense_coefficients`) and whether the method is DOP853.
Interpolant = namedtuple("Interpolant", ["h", "y_old", "Q", "dop853"])


@jit
def _value(x, p, mode, limit, it, scratch, index, rate):
    """Event ``index`` (minus its rate when ``rate``) at the fraction x of the step of
    interpolant ``it``; ``scratch``: (a state, event values g, their rates dg), overwritten."""
    work, g, dg = scratch
    dense_value(x, it.h, it.y_old, it.Q, it.dop853, work)
    _event_values(work, p, mode, limit, g, dg)
    return -dg[index] if rate else g[index]


@jit
def _root(p, mode, limit, it, scratch, index, rate, lo, hi):
    """x in (lo, hi] (fractions of the step) where event ``index`` (minus its rate when
    ``rate``) falls to <= 0, > 0 at lo and <= 0 at hi: the Illinois variant of regula falsi
    (bisection where it stalls), to :data:`X_TOLERANCE`, keeping the bracket; returns its
    upper end, where the event function is <= 0 (the new side of a surface).
    ``scratch``: as :func:`_value`'s."""
    f_lo = _value(lo, p, mode, limit, it, scratch, index, rate)
    f_hi = _value(hi, p, mode, limit, it, scratch, index, rate)
    side = 0
    for _ in range(200):
        if hi - lo <= X_TOLERANCE or f_hi == 0.0:
            break
        x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
            if x <= lo or x >= hi:  # the spacing of floats
                break
        f_x = _value(x, p, mode, limit, it, scratch, index, rate)
        if f_x > 0:
            lo, f_lo = x, f_x
            if side < 0:
                f_hi *= 0.5
            side = -1
        else:
            hi, f_hi = x, f_x
            if side > 0:
                f_lo *= 0.5
            side = 1
    return hi


@jit
def first_event(p, mode, limit, it, work, g, dg):
    """The first event in the step of interpolant ``it``: ``(x, index)`` with x its fraction
    of the step (-1 if none) and index 0-2 an axis, 3 the admissible region's bounds. ``g``, ``dg`` (4, 4):
    rows 0 hold the event values at the step's start (:func:`_event_values`); the rest is
    scratch, as is ``work``."""
    scratch = (work, g[2], dg[2])
    for k in range(1, SEARCH_POINTS + 1):
        lo, hi = (k - 1) / SEARCH_POINTS, k / SEARCH_POINTS
        dense_value(hi, it.h, it.y_old, it.Q, it.dop853, work)
        _event_values(work, p, mode, limit, g[1], dg[1])
        first, which = 2.0, -1
        for e in range(4):
            x = 2.0
            if k == 1 and g[0, e] <= 0 and dg[0, e] <= 0 and g[1, e] < g[0, e]:
                x = 0.0  # on the surface, or past it by rounding, and moving on: a crossing now
            elif g[0, e] > 0 >= g[1, e]:
                x = _root(p, mode, limit, it, scratch, e, False, lo, hi)
            elif g[0, e] > 0 and g[1, e] > 0 and dg[0, e] < 0 < dg[1, e]:
                # a minimum inside: E_i may dip through its surface and back between two points
                x_min = _root(p, mode, limit, it, scratch, e, True, lo, hi)
                dense_value(x_min, it.h, it.y_old, it.Q, it.dop853, work)
                _event_values(work, p, mode, limit, g[3], dg[3])
                if g[3, e] <= 0:
                    x = _root(p, mode, limit, it, scratch, e, False, lo, x_min)
            if x < first:
                first, which = x, e
        if which >= 0:
            return first, which
        g[0] = g[1]
        dg[0] = dg[1]
    return -1.0, -1


# -- mode changes (compiled) ---------------------------------------------------------------------
@jit
def _with(mode, i, value):
    return (value if i == 0 else mode[0], value if i == 1 else mode[1], value if i == 2 else mode[2])


@jit
def _worst_excess(y, p, mode):
    """The sliding axis of ``mode`` whose equivalent force exceeds K_s the most at ``y``
    (-1 if none), its Lambda_i [N] and F_i [m/s]."""
    _, f, lam, _ = mode_quantities(y, p, mode)
    worst, excess = -1, 0.0
    for i in range(3):
        if mode[i] == 0.0 and abs(lam[i]) - p.k_s > excess:
            worst, excess = i, abs(lam[i]) - p.k_s
    return worst, lam[max(worst, 0)], f[max(worst, 0)]


@jit
def side_or_sliding(y, p, mode, i, side, resolution, stopped):
    """Axis i, at its surface E_i = 0 in ``y``, goes to ``side`` (sigma_i = side) unless its
    excursion there, F_i^2 / (2 |dF_i/dt|) [m] when the force pulls E_i back, is within
    ``resolution`` and the equivalent force of the sliding axes is admissible: then it
    slides (sigma_i = 0) and ``stopped`` receives the state after the impulse at C that
    stops F_i. Returns (mode, slides, F_i, longest): ``longest`` is a quarter of the
    excursion's duration, the next piece's first step at most [s] (inf if none)."""
    trial = _with(mode, i, side)
    e, f, lam, acc = mode_quantities(y, p, trial)
    pulled_back = side * acc[i] < 0
    amplitude = f[i] ** 2 / (2 * abs(acc[i])) if pulled_back else np.inf
    if amplitude <= resolution:
        slide = _with(mode, i, 0.0)
        stop_at_c(y, p, (slide[0] == 0.0, slide[1] == 0.0, slide[2] == 0.0), stopped)
        if _worst_excess(stopped, p, slide)[0] < 0:  # Filippov's condition: |Lambda_i| <= K_s
            return slide, True, f[i], np.inf
    return trial, False, f[i], abs(f[i]) / (2 * abs(acc[i])) if pulled_back else np.inf


@jit
def initial_mode(y, p, resolution, stopped):
    """sigma at t = 0: sgn(E_i); for an axis on its surface (|E_i| <= resolution), the side
    F_i moves it to, or sliding (:func:`side_or_sliding`; ``y`` is then replaced by the
    state after the impulse, via ``stopped``)."""
    e, f, _, _ = mode_quantities(y, p, (1.0, 1.0, 1.0))
    mode = (1.0 if e[0] > 0 else -1.0, 1.0 if e[1] > 0 else -1.0, 1.0 if e[2] > 0 else -1.0)
    for i in range(3):
        if abs(e[i]) <= resolution:
            side = -1.0 if f[i] < 0 else 1.0
            mode, slides, _, _ = side_or_sliding(y, p, mode, i, side, resolution, stopped)
            if slides:
                y[:] = stopped
    return mode


@jit
def _log(events, n_events, t, axis, kind, rate):
    if n_events < events.shape[0]:
        events[n_events, 0] = t
        events[n_events, 1] = axis
        events[n_events, 2] = kind
        events[n_events, 3] = rate
    return n_events + 1


@jit
def _add_jumps(jumps, p, y_before, mode_before, y_after, mode_after):
    """Add |Lambda_i(after) - Lambda_i(before)| of every axis to ``jumps`` (3,) [N]."""
    before = mode_quantities(y_before, p, mode_before)[2]
    after = mode_quantities(y_after, p, mode_after)[2]
    for i in range(3):
        jumps[i] += abs(after[i] - before[i])


@jit
def _end_inadmissible_sliding(y, p, mode, t, events, n_events):
    """End the sliding of every axis whose equivalent force exceeds K_s at ``y`` (a
    switching of another axis can make it jump there): sigma_i = -sgn(Lambda_i), one axis
    at a time, the largest excess first. Returns (mode, n_events)."""
    for _ in range(3):
        worst, lam, f = _worst_excess(y, p, mode)
        if worst < 0:
            break
        n_events = _log(events, n_events, t, worst, SLIDING_ENDS, f)
        mode = _with(mode, worst, -1.0 if lam > 0 else 1.0)
    return mode, n_events


@jit
def next_piece(p, mode, index, t, y_event, resolution, y, log, n_events):
    """The mode after event ``index`` (an axis) at ``y_event`` and time t, logged in
    ``log`` = (events, jumps) (:func:`integrate_switching`'s arrays); ``y`` receives the
    next piece's initial state. Returns (mode, longest first step [s], n_events)."""
    events, jumps = log
    longest = np.inf
    if mode[index] == 0.0:  # the equivalent force reached K_s
        _, f, lam, _ = mode_quantities(y_event, p, mode)
        n_events = _log(events, n_events, t, index, SLIDING_ENDS, f[index])
        new = _with(mode, index, -1.0 if lam[index] > 0 else 1.0)
        y[:] = y_event
    else:
        new, slides, rate, longest = side_or_sliding(y_event, p, mode, index, -mode[index], resolution, y)
        n_events = _log(events, n_events, t, index, SLIDING_STARTS if slides else CROSSING, rate)
        if not slides:
            y[:] = y_event
    new, n_events = _end_inadmissible_sliding(y, p, new, t, events, n_events)
    _add_jumps(jumps, p, y_event, mode, y, new)
    return new, longest, n_events


@jit
def _fill_samples(samples, modes, j, t, t_stop, t_end, it, mode):
    """Samples j, j+1, ... at times <= t_stop from the interpolant ``it`` of the step from
    t; the next j."""
    n_samples = samples.shape[0]
    while j < n_samples and sample_time(j, n_samples, t_end) <= t_stop:
        dense_value((sample_time(j, n_samples, t_end) - t) / it.h, it.h, it.y_old, it.Q, it.dop853, samples[j])
        for i in range(3):
            modes[j, i] = mode[i]
        j += 1
    return j


# -- the driver (compiled) -----------------------------------------------------------------------
@jit
def integrate_switching(p, y0, s, resolution, samples, modes, events, jumps):
    """Integrate one sign-law run with the settings ``s``
    (:data:`~rbstab.engine.settings.SETTINGS`) and the switching resolution [m], filling
    ``samples`` (n, 12) at linspace(0, s.t_end, n), the mode of each sample into ``modes``
    (n, 3), the events into ``events`` (rows time, axis, kind, F_i; at most its length,
    then the run stops) and the summed jumps |Delta Lambda_i| [N] at the events into
    ``jumps`` (3,). The run stops after ``s.max_steps`` accepted steps or
    ``s.max_wall_time`` seconds (inf for none), as
    :func:`rbstab.engine.integrate.integrate_run` does.

    Returns (status, t_stop, nfev, n_steps, n_pieces, n_events).
    """
    max_wall_time, t_end, method = s.max_wall_time, s.t_end, s.method
    deadline = wall_clock() + max_wall_time if max_wall_time < math.inf else math.inf
    n = y0.shape[0]
    dop853 = method == DOP853
    w = work_arrays(method, n, n)
    K, Q, y_new, work = w.K, w.Q, w.y_new, w.work
    y, f = y0.copy(), np.empty(n)
    g, dg = np.empty((4, 4)), np.empty((4, 4))
    samples[:, :] = np.nan
    modes[:, :] = np.nan
    jumps[:] = 0.0
    limit = GIMBAL_LOCK_ANGLE - s.gimbal_margin
    mode, n_events = initial_mode(y, p, resolution, work), 0
    for i in range(3):
        if mode[i] == 0.0:
            n_events = _log(events, n_events, 0.0, i, SLIDING_STARTS, 0.0)
    margin, left = admissible_event(SLIDING, y, p, limit)
    if margin < 0:  # outside the admissible region from the start
        return left, 0.0, 0, 0, 0, n_events
    state_rate(mode_code(mode), 0.0, y, p, f)  # disturbances: refused with the sign law (config)
    h_abs = initial_step(mode_code(mode), p, s, 0.0, t_end, t_end, y, f, w)
    nfev, n_steps, n_pieces, t, j = 2, 0, 1, 0.0, 0
    while t < t_end:
        if n_steps >= s.max_steps:
            return STEP_LIMIT, t, nfev, n_steps, n_pieces, n_events
        if deadline < math.inf and n_steps % CLOCK_EVERY == 0 and wall_clock() > deadline:
            return TIMEOUT, t, nfev, n_steps, n_pieces, n_events
        code = mode_code(mode)
        status, t_new, h, h_abs, attempts = step(code, p, s, (t, t_end), y, f, h_abs, w)
        nfev += attempts * N_STAGES[method]
        if status != SUCCESS:
            return status, t, nfev, n_steps, n_pieces, n_events
        n_steps += 1
        nfev += dense_coefficients(code, p, t, t_end, y, h, method, w)
        _event_values(y, p, mode, limit, g[0], dg[0])
        it = Interpolant(h, y, Q, dop853)
        x, index = first_event(p, mode, limit, it, work, g, dg)
        t_stop = t_new if index < 0 else t + x * h
        j = _fill_samples(samples, modes, j, t, t_stop, t_end, it, mode)
        if index < 0:
            t = t_new
            y[:] = y_new
            f[:] = K[N_STAGES[method]]
            continue
        dense_value(x, h, y, Q, dop853, work)  # the state at the event
        t = t_stop
        if index == 3:
            return admissible_event(SLIDING, work, p, limit)[1], t, nfev, n_steps, n_pieces, n_events
        if n_events >= events.shape[0]:
            return SWITCHING_LIMIT, t, nfev, n_steps, n_pieces, n_events
        mode, longest, n_events = next_piece(p, mode, index, t, work, resolution, y, (events, jumps), n_events)
        h_abs = min(h_abs, longest)
        n_pieces += 1
        state_rate(mode_code(mode), t, y, p, f)
        nfev += 1
        if not math.isfinite(f[0]):
            return NOT_FINITE, t, nfev, n_steps, n_pieces, n_events
    return SUCCESS, t, nfev, n_steps, n_pieces, n_events


# -- from Python -----------------------------------------------------------------------------------
def warm_up(params: np.ndarray) -> None:
    """Compile (or load from the cache) the sign-law engine and its outputs on a tiny run
    (:func:`rbstab.engine.warm_up` calls it); ``params``: a PARAMETERS array of shape (1,)."""
    y0 = np.zeros(12)
    y0[9] = 1.0
    samples, modes, events, jumps = np.empty((2, 12)), np.empty((2, 3)), np.empty((4, 4)), np.empty(3)
    for method in METHODS:
        s = settings_records(np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3, 1000, np.inf]]), method_number(method))
        integrate_switching(params[0], y0, s[0], RESOLUTION, samples, modes, events, jumps)
    mode_rows(samples, params, modes, np.empty((2, 12)))


def engine_method(method: str) -> str:
    """The compiled method that integrates a sign-law run configured with ``method``."""
    return method if method in METHODS else "DOP853"


def integrate_sign_law(variant, y0: np.ndarray, settings, *, resolution: float = RESOLUTION,
                       max_switchings: int = MAX_SWITCHINGS, timeout: float | None = None) -> SignLawSolution:
    """Integrate the pure sign law of ``variant`` (``sliding``) from ``y0``, events located.

    Parameters
    ----------
    variant : Sliding
        The run's variant (``gains.k_s`` is K_s [N]; ``boundary_layer`` is not used).
    y0 : ndarray, shape (12,)
        Initial state.
    settings : SimulationSettings
        ``t_end`` [s], ``n_samples``, ``method``, ``rtol``, ``atol``, ``max_step`` [s],
        ``gimbal_margin`` [rad], ``max_steps``, ``max_wall_time`` [s].
    resolution : float
        Switching resolution [m] (:data:`RESOLUTION`).
    max_switchings : int
        Events after which the run stops, failed.
    timeout : float, optional
        Wall-time limit [s] instead of ``settings.max_wall_time``; past it the run stops,
        failed.

    Returns
    -------
    SignLawSolution
        A failure (gimbal lock, the admissible region left, solver failure, switching or
        step limit, timeout) is data.
    """
    n = int(settings.n_samples)
    samples = np.empty((n, 12))
    modes = np.empty((n, 3))
    events = np.empty((max_switchings, 4))
    jumps = np.empty(3)
    method = engine_method(settings.method)
    max_steps = int(settings.max_steps)
    max_wall_time = float(settings.max_wall_time if timeout is None else timeout)
    s = settings_records(settings_rows([settings], timeout), method_number(method))
    with np.errstate(all="ignore"):
        status, t_stop, nfev, n_steps, n_pieces, n_events = integrate_switching(
            variant._parameters_without_offset[0], np.ascontiguousarray(y0, dtype=float), s[0], float(resolution),
            samples, modes, events, jumps)
    log = events[: min(n_events, max_switchings)]
    switchings = Switchings(log[:, 0].copy(), log[:, 1].astype(np.int64), log[:, 2].astype(np.int64), log[:, 3].copy())
    message = status_message(int(status), t_stop, settings.gimbal_margin, max_steps, max_wall_time,
                             max_switchings=max_switchings, resolution=resolution,
                             limits=variant.parameters[0]["limits"])
    solver = {"nfev": int(nfev), "njev": 0, "nlu": 0, "solver_status": int(status), "n_steps": int(n_steps),
              "n_pieces": int(n_pieces)}
    time = np.linspace(0.0, float(settings.t_end), n)
    return SignLawSolution(time, samples, modes, switchings, "success" if status == SUCCESS else "failed", message,
                           solver, float(resolution), jumps, float(t_stop), method)


# -- what a run reports --------------------------------------------------------------------------
def _per_axis(switchings: Switchings, kind: int) -> list[np.ndarray]:
    return [switchings.time[(switchings.axis == i) & (switchings.kind == kind)] for i in range(3)]


def switching_summary(solution: SignLawSolution) -> dict:
    """The switching figures of a sign-law run, for its summary (plain floats and 3-lists,
    one value per axis of E; units and meaning in ``rbstab.layout.SUMMARY_FIGURES``):
    ``switching_count``, ``sliding_time`` [s], ``sliding_starts``,
    ``min_switching_interval`` [s] (NaN below two crossings), ``chattering`` [N/s] (the
    total variation of Lambda_i from its jumps, per second) and ``switching_resolution`` [m]."""
    s = solution.switchings
    duration = solution.t_stop
    crossings = _per_axis(s, CROSSING)
    starts, ends = _per_axis(s, SLIDING_STARTS), _per_axis(s, SLIDING_ENDS)
    sliding = []
    for i in range(3):  # every start is followed by its end, or lasts to t_stop
        stops = np.r_[ends[i], np.full(len(starts[i]) - len(ends[i]), duration)]
        sliding.append(float(np.sum(stops - starts[i])))
    return {
        "switching_count": [float(len(c)) for c in crossings],
        "sliding_time": sliding,
        "sliding_starts": [float(len(c)) for c in starts],
        "min_switching_interval": [float(np.min(np.diff(c))) if len(c) > 1 else float("nan") for c in crossings],
        "chattering": (solution.jumps / duration if duration > 0 else np.full(3, np.nan)).tolist(),
        "switching_resolution": float(solution.resolution),
    }


def switching_message(solution: SignLawSolution, method: str) -> str:
    """One sentence on the switchings of a run configured with ``method``, for its message."""
    s = solution.switchings
    counts = ", ".join(f"{a} {int(np.sum((s.axis == i) & (s.kind == CROSSING)))}" for i, a in enumerate("xyz"))
    instead = f", {solution.method} between switchings, not {method}" if solution.method != method else ""
    text = f" Pure sign law (eq 39{instead}): {int(np.sum(s.kind == CROSSING))} switchings located ({counts})"
    caught = [(t, "xyz"[i]) for t, i, k in zip(s.time, s.axis, s.kind) if k == SLIDING_STARTS and t > 0]
    if caught:
        when = ", ".join(f"{a} at t = {t:.4g} s" for t, a in caught[:6]) + (", ..." if len(caught) > 6 else "")
        text += (f"; sliding started where the switchings accumulated below the resolution "
                 f"{solution.resolution:g} m ({when})")
    return text + "."


def sign_law_outputs(variant, solution: SignLawSolution) -> tuple[dict, np.ndarray]:
    """Every output variable of a sign-law run, and the samples its rate check compares.

    :meth:`Variant.evaluate` along the samples, with ``constraint_force`` the force of each
    sample's mode (the equivalent force where C slides, not -K_s sgn(E) of a state that sits
    on a surface to rounding), ``sliding_mode`` (sigma of each sample, shape (n, 3)) and
    ``lyapunov_rate_numerical`` differentiated on each smooth piece between the events
    (:func:`rbstab.summary.piecewise_numerical_rate`).

    Returns
    -------
    outputs : dict of str -> ndarray
    checked : ndarray of bool, shape (n_samples,)
        Samples whose numerical rate has its full stencil on one piece.
    """
    outputs = variant.evaluate(solution.states)
    rows = np.empty((len(solution.time), 12))
    with np.errstate(all="ignore"):
        mode_rows(np.ascontiguousarray(solution.states), variant.parameters, np.ascontiguousarray(solution.modes), rows)
    outputs["constraint_force"] = rows[:, 6:9]
    outputs["sliding_mode"] = solution.modes
    events = solution.switchings.time
    rate, checked = piecewise_numerical_rate(solution.time, outputs["lyapunov"], events[events > 0])
    outputs["lyapunov_rate_numerical"] = rate
    return outputs, checked
