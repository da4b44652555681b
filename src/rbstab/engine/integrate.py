"""One run from t = 0 to t_end, sampled on an even grid, as compiled code (scipy's driver).

:func:`integrate_run` is what ``solve_ivp(..., t_eval=linspace(0, t_end, n), events=[gimbal
lock])`` does with an explicit Runge-Kutta method: step (:func:`attempt_step`, an attempt
of scipy's ``_step_impl``), sample the step's interpolant at the grid times it covers, and stop where
the run leaves its admissible region (gimbal lock and the bounds of ``simulation.limits``),
located on the interpolant: :func:`begin_run`, then passes of :func:`run_pass` (one step
attempt each), the loop the CUDA kernels run too. A run's system is one body or a chain
(:mod:`rbstab.engine.systems`: its rate and admissible margin). :func:`integrate_chunk`
runs many one-body runs, each with its own variant, parameters and settings, one after the
other in one call; :func:`integrate_tree_chunk` many runs of one tree (a chain).

A run ends with a status code of :mod:`rbstab.engine.status` (the wall-time limit is
checked every :data:`CLOCK_EVERY` passes).
"""

from __future__ import annotations

import math
import sys
import time
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from llvmlite import ir
from numba import objmode, types
from numba.core import cgutils
from numba.core.extending import intrinsic
from numba.extending import overload

from ..jit import jit
from ..kinematics import GIMBAL_LOCK_ANGLE
from ..variants.chain import is_one_body
from ..variants.tree import reduced_size, tree_work
from ..variants.disturbances import before
from .rk import (DOP853, ERROR_ORDER, N_STAGES, dense_coefficients, dense_value, error_norm, initial_step,
                 method_number, rk_step)
from .settings import settings_records, work_arrays
from .status import DEFAULT_MAX_STEPS, NOT_FINITE, STEP_LIMIT, SUCCESS, TIMEOUT, TOO_SMALL_STEP
from .systems import (CHAIN, TreeSystem, admissible, admissible_event, expand_tree_samples, gimbal_event,
                      reduce_tree_states, system_breakpoint, system_disturbed, system_impulses, system_limited,
                      system_margin, system_rate, tree_rows)
from .tableaus import MAX_FACTOR, MIN_FACTOR, SAFETY

__all__ = ["integrate_run", "integrate_chunk", "sample_time", "wall_clock", "CLOCK_EVERY", "ChunkSolution",
           "integrate_runs", "integrate_chain_runs", "integrate_tree_chunk", "begin_run", "run_pass", "drive_run", "clock_ns", "NO_DEADLINE",
           "keep_sample",
           "SampleRows", "step", "attempt_step", "step_bounds", "spacing", "REJECTED", "gimbal_event", "admissible_event",
           "grazing_exit", "step_exit",
           "admissible", "locate_event"]

SAFETY, MIN_FACTOR, MAX_FACTOR = float(SAFETY), float(MIN_FACTOR), float(MAX_FACTOR)


#: Steps between two readings of the clock for the wall-time limit (a reading costs ~0.3 us,
#: a step of DOP853 on the embedded body ~6 us).
CLOCK_EVERY = 64

#: ``CLOCK_MONOTONIC`` of ``clock_gettime`` in the C library, where it is known.
_CLOCK_MONOTONIC = {"linux": 1, "darwin": 6, "freebsd": 4}.get(sys.platform.rstrip("0123456789"))


@intrinsic
def _monotonic_ns(typingctx):
    """``clock_gettime(CLOCK_MONOTONIC)`` [ns] of the C library, called from compiled code
    (no interpreter: a signal handler cannot run inside it; cacheable, libc is allowed)."""

    def codegen(context, builder, signature, args):
        i64, i32 = ir.IntType(64), ir.IntType(32)
        timespec = ir.LiteralStructType([i64, i64])  # time_t tv_sec, long tv_nsec
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(i32, [i32, timespec.as_pointer()]), "clock_gettime")
        ts = cgutils.alloca_once(builder, timespec)
        builder.call(fn, [ir.Constant(i32, _CLOCK_MONOTONIC), ts])
        sec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 0))
        nsec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 1))
        return builder.add(builder.mul(sec, ir.Constant(i64, 1_000_000_000)), nsec)

    return types.int64(), codegen


if _CLOCK_MONOTONIC is not None:

    @jit
    def wall_clock():
        """A monotonic clock [s] for the wall-time limit (the C library's, ~0.3 us a call)."""
        return _monotonic_ns() * 1e-9

else:  # pragma: no cover - other platforms: through the interpreter

    @jit
    def wall_clock():
        """A monotonic clock [s] for the wall-time limit (``time.perf_counter``)."""
        with objmode(now="float64"):
            now = time.perf_counter()
        return now


#: A deadline [ns] that is none: :func:`drive_run` reads no clock.
NO_DEADLINE = 2**62


def clock_ns():
    """The clock a run's deadline is read on [ns], in compiled code: ``CLOCK_MONOTONIC`` on
    the CPU (:func:`wall_clock`'s), the GPU's ``%globaltimer`` in a CUDA kernel (the
    overload :mod:`rbstab.engine.cuda` registers)."""
    raise NotImplementedError("compiled code only")


@overload(clock_ns, target="cpu", jit_options={"forceinline": True})
def _cpu_clock_ns():
    if _CLOCK_MONOTONIC is not None:
        return lambda: _monotonic_ns()
    return lambda: np.int64(wall_clock() * 1e9)  # pragma: no cover - other platforms


@jit(forceinline=True)
def sample_time(j, n, t_end):
    """The j-th of n evenly spaced times on [0, t_end], as ``numpy.linspace`` computes it."""
    if j == n - 1:
        return t_end
    return j * (t_end / (n - 1))


@jit(forceinline=True)
def spacing(t):
    """abs(nextafter(t, inf) - t) [s] for a finite t >= 0: the spacing of floats at t
    (``numpy.nextafter`` has no CUDA lowering; this is the same number)."""
    if t < 2.2250738585072014e-308:  # 0 and subnormals: the smallest subnormal
        return 5e-324
    return math.ldexp(1.0, math.frexp(t)[1] - 53)


@jit(forceinline=True)
def _limit_of(t_bound, t_end):
    """The latest time a stage of a step that ends at ``t_bound`` evaluates."""
    return before(t_bound) if t_bound < t_end else t_end


#: :func:`attempt_step`'s outcome for a rejected attempt (a step to try again, smaller).
REJECTED = 2


@jit(forceinline=True)
def step_bounds(s, t, h_abs):
    """``h_abs`` at the start of a step from t, clipped to [min_step, s.max_step], min_step
    scipy's ``10 * spacing(t)``."""
    return min(max(h_abs, 10 * spacing(t)), s.max_step)


@jit(inline="always")
def attempt_step(code, p, s, span, y, f, h_abs, rejected, w):
    """One attempt of scipy's ``_step_impl`` loop: a step of size ``h_abs`` from (t, y)
    with rate f, accepted or not by its error norm.

    ``s``: the run's :data:`~rbstab.engine.settings.SETTINGS`; ``w``: its
    :class:`~rbstab.engine.settings.Work`; ``h_abs`` before the first attempt from
    :func:`step_bounds`; ``rejected``: whether an attempt of this step was rejected before;
    ``t_bound``: where the step from t ends at the latest (t_end, or the next breakpoint of the
    disturbances), ``t_lim``: the latest time a stage evaluates (the float below a
    breakpoint, else t_bound), as ``span`` = (t, t_bound). Returns (outcome, t_new, h, next h_abs): outcome SUCCESS (``w.y_new``
    and its rate ``w.K[n_stages]`` hold the new state at t_new = t + h), :data:`REJECTED`
    (try again with the next h_abs) or TOO_SMALL_STEP / NOT_FINITE (no right-hand side
    evaluated). The CPU driver (:func:`step`) and the CUDA driver
    (:mod:`rbstab.engine.cuda`) both take their steps through it.
    """
    t, t_bound = span
    if not math.isfinite(h_abs):
        return NOT_FINITE, t, 0.0, h_abs
    if h_abs < 10 * spacing(t):
        return TOO_SMALL_STEP, t, 0.0, h_abs
    t_lim = _limit_of(t_bound, s.t_end)
    rtol, atol, method = s.rtol, s.atol, s.method
    K, y_new, scale = w.K, w.y_new, w.scale
    error_exponent = -1.0 / (ERROR_ORDER[method] + 1)
    t_new = min(t + h_abs, t_bound)
    h = t_new - t
    h_abs = abs(h)
    rk_step(code, p, t, t_lim, y, f, h, method, w)
    for i in range(scale.shape[0]):  # the state's entries (not a work W after them)
        scale[i] = atol + max(abs(y[i]), abs(y_new[i])) * rtol
    norm = error_norm(K, h, scale, method)
    if norm < 1:
        factor = MAX_FACTOR if norm == 0 else min(MAX_FACTOR, SAFETY * norm**error_exponent)
        if rejected:
            factor = min(1.0, factor)
        return SUCCESS, t_new, h, h_abs * factor
    # a NaN norm rejects the step with the smallest factor, as scipy's max() does
    factor = SAFETY * norm**error_exponent
    return REJECTED, t, 0.0, h_abs * (factor if factor > MIN_FACTOR else MIN_FACTOR)


@jit(_nrt=False)
def step(code, p, s, span, y, f, h_abs, w):
    """One accepted step from (t, y) with rate f (scipy's ``_step_impl``), with the run's
    settings ``s`` (:data:`~rbstab.engine.settings.SETTINGS`) and work arrays ``w``
    (:class:`~rbstab.engine.settings.Work`): :func:`attempt_step` until one is accepted
    (``span`` = (t, t_bound): see there).

    Returns (status, t_new, h, next h_abs, attempts); ``w.y_new`` and its rate
    ``w.K[n_stages]`` hold the new state. status 0, or TOO_SMALL_STEP / NOT_FINITE (nothing
    accepted).
    """
    h_abs = step_bounds(s, span[0], h_abs)
    rejected = False
    attempts = 0
    while True:
        outcome, t_new, h, h_abs = attempt_step(code, p, s, span, y, f, h_abs, rejected, w)
        if outcome == REJECTED:
            attempts += 1
            rejected = True
            continue
        if outcome == SUCCESS:
            attempts += 1
        return outcome, t_new, h, h_abs, attempts


#: Points a step's interpolant is checked at for a bound grazed inside it
#: (:func:`grazing_exit`), and the golden-section iterations that refine a dip.
GRAZE_POINTS, GRAZE_ITERATIONS = 8, 30
_GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


@jit(forceinline=True)
def _margin_at(code, p, limit, x, interpolant, work):
    """The admissible margin at the fraction x of a step, ``interpolant`` = (h, y_old, Q,
    dop853) its dense output."""
    h, y_old, Q, dop853 = interpolant
    dense_value(x, h, y_old, Q, dop853, work)
    return system_margin(code, work, p, limit)[0]


@jit(inline="always")
def _dip(code, p, limit, lo, hi, interpolant, work):
    """(x, margin) of the smallest margin on [lo, hi] of the step's interpolant, by golden
    section (the margin has one dip there)."""
    a, b = lo, hi
    c = b - _GOLDEN * (b - a)
    d = a + _GOLDEN * (b - a)
    mc = _margin_at(code, p, limit, c, interpolant, work)
    md = _margin_at(code, p, limit, d, interpolant, work)
    for _ in range(GRAZE_ITERATIONS):
        if mc < md:
            b, d, md = d, c, mc
            c = b - _GOLDEN * (b - a)
            mc = _margin_at(code, p, limit, c, interpolant, work)
        else:
            a, c, mc = c, d, md
            d = a + _GOLDEN * (b - a)
            md = _margin_at(code, p, limit, d, interpolant, work)
    return (c, mc) if mc < md else (d, md)


@jit(inline="always")
def grazing_exit(code, p, limit, margins, interpolant, work):
    """The fraction x in (0, 1] of a step at which its interpolant is outside the
    admissible region though inside at both ends (``margins`` = (at its start, at its end),
    both >= 0; ``interpolant`` = (h, y_old, Q, dop853), its dense output): an excursion that a sign change at the ends misses, a bound grazed (the case at
    a push's threshold); -1 where there is none.

    The margin is evaluated at :data:`GRAZE_POINTS` - 1 inner points of the step's dense
    interpolant (its coefficients computed); the first point outside is returned; around
    each inner point where the margin dips (no larger than at its neighbours) a golden
    section finds the dip's bottom, returned where it is outside. ``work``: a state-sized
    scratch array.
    """
    margin_old, margin_new = margins
    step = 1.0 / GRAZE_POINTS
    before, here = margin_old, _margin_at(code, p, limit, step, interpolant, work)
    for k in range(1, GRAZE_POINTS):
        if here < 0.0:
            return k * step
        after = margin_new if k == GRAZE_POINTS - 1 else _margin_at(code, p, limit, (k + 1) * step, interpolant, work)
        if here <= before and here <= after:
            x, bottom = _dip(code, p, limit, (k - 1) * step, (k + 1) * step, interpolant, work)
            if bottom < 0.0:
                return x
        before, here = here, after
    return -1.0


@jit(inline="always")
def step_exit(code, p, limit, crossed, margins, interpolant, work):
    """Where a step leaves the admissible region, as a fraction of it: 1 where the margin
    ``crossed`` zero between its ends (``margins``), the first point outside of a bound
    grazed inside it (:func:`grazing_exit`, with ``simulation.limits`` only), or -1 where
    it stays inside. The step's dense output ``interpolant`` = (h, y_old, Q, dop853) is
    computed where the run has bounds."""
    if crossed:
        return 1.0
    if not system_limited(p):
        return -1.0
    return grazing_exit(code, p, limit, margins, interpolant, work)


@jit(_nrt=False)
def locate_event(code, p, limit, t_old, interpolant, work, x_out):
    """Where the interpolant leaves the admissible region (:func:`admissible_event` of
    variant ``code``, record ``p``, gimbal-lock angle ``limit``) in [t_old, t_old + x_out
    h] of a step whose dense output is ``interpolant`` = (h, y_old, Q, dop853): bisection
    to the spacing of floats (the margin is >= 0 at t_old, <= 0 at the fraction ``x_out``
    of the step: 1, its end, or a grazed bound's :func:`grazing_exit`). Returns (time [s],
    its fraction of the step, the status code of the bound reached there); ``work`` holds
    the state there."""
    h, y_old, Q, dop853 = interpolant
    lo, hi = 0.0, x_out
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        dense_value(mid, h, y_old, Q, dop853, work)
        if system_margin(code, work, p, limit)[0] > 0:
            lo = mid
        else:
            hi = mid
    dense_value(hi, h, y_old, Q, dop853, work)
    return t_old + hi * h, hi, system_margin(code, work, p, limit)[1]


@jit(inline="always")
def integrate_run(code, p, y0, s, samples, work_done):
    """Integrate one run with the settings ``s`` (:data:`~rbstab.engine.settings.SETTINGS`)
    and fill ``samples`` (n_samples, n_state) at linspace(0, s.t_end), and ``work_done``
    (n_samples,) with the work W [J] of the disturbances up to each sample (0 without).

    The run stops where it leaves its admissible region (GIMBAL_LOCK, or the status code of
    the bound of ``simulation.limits`` it reached: :func:`admissible_event`; at t = 0 with no
    step when it starts outside, at an impulse's time when the impulse throws it out), after
    ``s.max_steps`` accepted steps (STEP_LIMIT) or ``s.max_wall_time`` seconds (TIMEOUT;
    inf for none). Rows after the run stopped are NaN. Returns (status, t_stop, nfev,
    n_steps).
    """
    status, t_stop, nfev, n_steps, filled = _run(code, p, y0, s, samples, work_done)
    samples[filled:, :] = np.nan  # only the rows after a stop: a run that ends writes each row once
    work_done[filled:] = np.nan
    return status, t_stop, nfev, n_steps


@jit(inline="always")
def restart(code, p, s, t, y, f, w):
    """Start again from a breakpoint t of the disturbances (its impulses applied to y) as a
    new solve_ivp from there would: y's rate at t into f and a new initial step (2
    right-hand sides). Returns (the next breakpoint t_bound, the latest stage time t_lim
    before it, the initial step h_abs)."""
    t_bound = system_breakpoint(p, t, s.t_end)
    t_lim = _limit_of(t_bound, s.t_end)
    system_rate(code, t, y, p, f)
    return t_bound, t_lim, initial_step(code, p, s, t, t_bound, t_lim, y, f, w)


#: Where a run's samples go: its state (the first ``samples.shape[1]`` entries of a sample)
#: at every ``stride``-th sample j into ``samples[j // stride]`` and its work W [J] into
#: ``work[j // stride]`` (the CPU driver's samples, stride 1; the CUDA chain kernel's).
SampleRows = namedtuple("SampleRows", ["samples", "work", "stride"])


def keep_sample(sink, code, p, j, t, sample, work):
    """Hand sample j of a run (at time t [s]: the state in ``sample``, the disturbances' work
    W ``work`` [J]) of the system (``code``, ``p``) to ``sink``: a :class:`SampleRows`, or
    the CUDA kernel's streamed summary (:class:`rbstab.engine.cuda.TreeStreamSink`)."""
    raise NotImplementedError("compiled code only")


@overload(keep_sample, target="generic", jit_options={"forceinline": True, "error_model": "numpy", "_nrt": False})
def _keep_rows(sink, code, p, j, t, sample, work):
    if not (isinstance(sink, types.BaseNamedTuple) and sink.instance_class is SampleRows):
        return None

    def keep(sink, code, p, j, t, sample, work):
        row = j
        if sink.stride != 1:  # (no integer division for every sample of the CPU's runs)
            if j % sink.stride != 0:
                return
            row = j // sink.stride
        for i in range(sink.samples.shape[1]):
            sink.samples[row, i] = sample[i]
        sink.work[row] = work
    return keep


@jit(inline="always")
def begin_run(code, p, s, y, f, w, limit, disturbed):
    """The start of a run from the state in ``y`` (its work W after it, 0): the impulses at
    t = 0 where ``disturbed``, the admissible margin (``limit`` = pi/2 - gimbal_margin), the
    rate into ``f`` and the first step (2 right-hand sides). Returns (running, status,
    state): running False with the bound's status where the run starts outside its region
    (or an impulse at 0 throws it out); ``state`` = (t, t_bound, t_lim, h_abs, margin,
    rejected, j, nfev, n_steps) the run's loop variables, as :func:`run_pass` takes them."""
    t_end = s.t_end
    n = w.scale.shape[0]
    t_bound = t_end
    if disturbed:
        y[n] += system_impulses(code, 0.0, y, p)
        t_bound = system_breakpoint(p, 0.0, t_end)
    t_lim = _limit_of(t_bound, t_end)
    margin, left = system_margin(code, y, p, limit)
    if margin < 0:  # outside the admissible region from the start (or after an impulse at 0)
        return False, left, (0.0, t_bound, t_lim, 0.0, margin, False, 0, 0, 0)
    system_rate(code, 0.0, y, p, f)
    h_abs = step_bounds(s, 0.0, initial_step(code, p, s, 0.0, t_bound, t_lim, y, f, w))
    return True, SUCCESS, (0.0, t_bound, t_lim, h_abs, margin, False, 0, 2, 0)


@jit(inline="always")
def run_pass(code, p, s, w, vectors, state, sink, flags, scheme):
    """One pass of a run's loop: one step attempt (:func:`attempt_step`) from the loop
    variables ``state`` (:func:`begin_run`'s), and for an accepted step what follows it: the
    admissible region's event located on the interpolant, the samples the step covers handed
    to ``sink`` (:func:`keep_sample`), the impulses at a breakpoint and at t_end.
    ``vectors`` = (y, f, sample): the state and its rate at t, and a scratch vector as long;
    ``flags`` = (limit, disturbed, bounded, n_samples): the gimbal-lock angle pi/2 -
    gimbal_margin [rad], whether the run has disturbances and bounds, its samples;
    ``scheme`` = (method, n_stages, dop853). Every driver's loop is made of these passes:
    the CPU's (:func:`integrate_run`) and the CUDA kernels' (:mod:`rbstab.engine.cuda`),
    which check their clock and step limit between passes.

    With disturbances, the integration stops at each breakpoint (:func:`rbstab.variants.
    disturbances.next_breakpoint`), applies the impulses that start there and starts again
    as a new solve_ivp from there would (a new initial step); the samples at a breakpoint
    show the state just after it, the last sample the state after the impulses at t_end.
    Their work W is integrated as one more entry after the state (its rate the disturbances'
    power, :func:`~rbstab.variants.kernels.state_rate`; an impulse adds its jump of kinetic
    energy), by the same steps and interpolant, and left out of the error norms.

    Returns (running, status, state): running False where the run ended (status SUCCESS at
    t_end, the status of the region left, TOO_SMALL_STEP or NOT_FINITE; t in ``state`` the
    stop time), else the variables of the next pass, with ``y``, ``f`` at its t.
    """
    t, t_bound, t_lim, h_abs, margin, rejected, j, nfev, n_steps = state
    y, f, sample = vectors
    limit, disturbed, bounded, n_samples = flags
    method, n_stages, dop853 = scheme
    t_end = s.t_end
    n = w.scale.shape[0]
    K, Q, y_new, scratch = w.K, w.Q, w.y_new, w.work
    outcome, t_new, h, h_abs = attempt_step(code, p, s, (t, t_bound), y, f, h_abs, rejected, w)
    if outcome == REJECTED:
        return True, SUCCESS, (t, t_bound, t_lim, h_abs, margin, True, j, nfev + n_stages, n_steps)
    if outcome != SUCCESS:
        return False, outcome, (t, t_bound, t_lim, h_abs, margin, rejected, j, nfev, n_steps)
    nfev += n_stages
    n_steps += 1
    t_stop = t_new
    margin_new = system_margin(code, y_new, p, limit)[0]
    event = margin >= 0 and margin_new <= 0
    at_break = disturbed and t_new == t_bound and t_bound < t_end
    if event or bounded or (j < n_samples and sample_time(j, n_samples, t_end) <= t_new):
        nfev += dense_coefficients(code, p, t, t_lim, y, h, method, w)
    x_out = step_exit(code, p, limit, event, (margin, margin_new), (h, y, Q, dop853), scratch)
    event = x_out > 0.0
    left = SUCCESS
    if event:
        t_stop, _, left = locate_event(code, p, limit, t, (h, y, Q, dop853), scratch, x_out)
    # a sample at a breakpoint is the next step's (the state just after the breakpoint)
    while j < n_samples and (sample_time(j, n_samples, t_end) < t_stop if at_break and not event
                             else sample_time(j, n_samples, t_end) <= t_stop):
        t_j = sample_time(j, n_samples, t_end)
        dense_value((t_j - t) / h, h, y, Q, dop853, sample)
        done = 0.0
        if disturbed:
            done = sample[n]
            if j == n_samples - 1 and not event:  # at t_end: the state after its impulses
                jump = system_impulses(code, t_end, y_new, p)
                if jump != 0.0:
                    for i in range(n):
                        sample[i] = y_new[i]
                    done += jump
        keep_sample(sink, code, p, j, t_j, sample, done)
        j += 1
    if event:
        return False, left, (t_stop, t_bound, t_lim, h_abs, margin, False, j, nfev, n_steps)
    t = t_new
    margin = margin_new
    f_new = K[n_stages]
    for i in range(y.shape[0]):
        y[i] = y_new[i]
    for i in range(f.shape[0]):
        f[i] = f_new[i]
    if at_break:  # the impulses that start here; a new initial step from here
        y[n] += system_impulses(code, t, y, p)
        margin, left = system_margin(code, y, p, limit)
        if margin < 0:  # an impulse took the state out of the admissible region
            return False, left, (t, t_bound, t_lim, h_abs, margin, False, j, nfev, n_steps)
        t_bound, t_lim, h_abs = restart(code, p, s, t, y, f, w)
        nfev += 2
    h_abs = step_bounds(s, t, h_abs)
    return t < t_end, SUCCESS, (t, t_bound, t_lim, h_abs, margin, False, j, nfev, n_steps)


@jit(inline="always")
def drive_run(code, p, s, w, vectors, sink, flags, scheme, clock):
    """A run from the state in ``y`` (``vectors`` = (y, f, sample), the arguments of
    :func:`run_pass`, as ``sink``, ``flags``, ``scheme``): :func:`begin_run`, then passes of
    :func:`run_pass` until it ends, reaches ``s.max_steps`` accepted steps (STEP_LIMIT) or
    the ``clock`` = (deadline [ns] of :func:`clock_ns`, passes so far) reads past its
    deadline, every :data:`CLOCK_EVERY` passes (TIMEOUT; :data:`NO_DEADLINE`: never read).
    Every driver runs its runs through it: the CPU's (:func:`integrate_run`) and the CUDA
    kernels (:mod:`rbstab.engine.cuda`, the passes counted over a thread's runs). Returns
    (status, state, passes): ``state`` the loop variables at the end (:func:`begin_run`;
    t the stop time)."""
    y, f, sample = vectors
    limit, disturbed = flags[0], flags[1]
    deadline, passes = clock
    running, status, state = begin_run(code, p, s, y, f, w, limit, disturbed)
    while running:
        if state[8] >= s.max_steps:
            status = STEP_LIMIT
            break
        if deadline < NO_DEADLINE and passes % CLOCK_EVERY == 0 and clock_ns() > deadline:
            status = TIMEOUT
            break
        passes += 1
        running, status, state = run_pass(code, p, s, w, vectors, state, sink, flags, scheme)
    return status, state, passes


@jit(inline="always")
def _run(code, p, y0, s, samples, work_done):
    """:func:`integrate_run` but the NaN rows; also returns the number of rows filled
    (:func:`drive_run`)."""
    max_wall_time, method = s.max_wall_time, s.method
    deadline = clock_ns() + np.int64(max_wall_time * 1e9) if max_wall_time < 1e9 else NO_DEADLINE  # 1e9 s: none
    n = y0.shape[0]
    disturbed = system_disturbed(p)
    m = n + 1 if disturbed else n  # the integrated vector: the state, and W at [n]
    w = work_arrays(method, m, n)
    y = np.zeros(m)
    y[:n] = y0
    f = np.empty(m)
    flags = (GIMBAL_LOCK_ANGLE - s.gimbal_margin, disturbed, system_limited(p), samples.shape[0])
    scheme = (method, N_STAGES[method], method == DOP853)
    status, state, _ = drive_run(code, p, s, w, (y, f, w.work), SampleRows(samples, work_done, 1), flags, scheme,
                                 (deadline, 0))
    return status, state[0], state[7], state[8], state[6]


@jit(nogil=True)  # no Python object inside: threads run it in parallel
def integrate_chunk(codes, params, y0, settings, samples, work_done, ends):
    """:func:`integrate_run` for every run k of a chunk.

    ``codes`` (k,) variant codes; ``params`` (k,) PARAMETERS records; ``y0`` (k, n_state);
    ``settings`` (k,) :data:`~rbstab.engine.settings.SETTINGS` records; ``samples``
    (k, n_samples, n_state); ``work_done`` (k, n_samples) the disturbances' work W [J];
    ``ends`` = (``status``, ``t_stop``, ``nfev``, ``n_steps``), each (k,), are filled.
    """
    status, t_stop, nfev, n_steps = ends
    for k in range(codes.shape[0]):
        status[k], t_stop[k], nfev[k], n_steps[k] = integrate_run(codes[k], params[k], y0[k], settings[k], samples[k],
                                                                  work_done[k])


@jit(nogil=True)
def integrate_tree_chunk(system, tree_of, y0, settings, samples, work_done, ends):
    """:func:`integrate_run` for k runs of trees of one structure in reduced coordinates
    (``system``, a :class:`~rbstab.engine.systems.TreeSystem` whose ``params`` (t, n) and
    ``ppoints`` (t, n, 3) hold t trees; run i integrates tree ``tree_of[i]``,
    :func:`rbstab.engine.systems.tree_rows`) from the initial states ``y0`` (k, n_r);
    ``samples`` in the reduced layout; the other arguments as :func:`integrate_chunk`'s. The
    call evaluates the trees with scratch arrays of its own (``system.work`` is None;
    threads may integrate one system at once)."""
    status, t_stop, nfev, n_steps = ends
    n = system.codes.shape[0]
    n_states = 12 * n
    for j in range(n):
        if system.d_at[j] >= 0:
            n_states += 3
    work = tree_work(n, n_states)
    for k in range(y0.shape[0]):
        t = tree_of[k]
        own = TreeSystem(system.params[t], system.codes, system.parents, system.ppoints[t], system.d_at,
                         system.r_at, system.u_at, system.rd_at, work)
        status[k], t_stop[k], nfev[k], n_steps[k] = integrate_run(CHAIN, own, y0[k], settings[k], samples[k],
                                                                  work_done[k])


# -- from Python -----------------------------------------------------------------------------------
@dataclass
class ChunkSolution:
    """Samples of k runs and how each ended.

    Attributes
    ----------
    samples : ndarray, shape (k, n_samples, n_state)
        The state at linspace(0, t_end, n_samples) of each run; NaN after it stopped.
    status : ndarray of int, shape (k,)
        How each run ended (:mod:`rbstab.engine.status`: 0 reached t_end, 1 gimbal lock,
        2 and above the admissible region left (:func:`rbstab.engine.status.limit_of` and
        :func:`~rbstab.engine.status.limit_part` name the bound), negative a failure).
    t_stop : ndarray, shape (k,)
        Where each run stopped [s] (the event time for gimbal lock and the region).
    nfev, n_steps : ndarray of int, shape (k,)
        Right-hand-side evaluations and accepted steps.
    work : ndarray, shape (k, n_samples)
        The work W [J] of the disturbances up to each sample (0 without; NaN after a stop).
    """

    samples: np.ndarray
    status: np.ndarray
    t_stop: np.ndarray
    nfev: np.ndarray
    n_steps: np.ndarray
    work: np.ndarray | None = None


def integrate_runs(codes, params, y0, settings, *, method: str, n_samples: int,
                   max_steps: int = DEFAULT_MAX_STEPS, max_wall_time: float = np.inf,
                   out: np.ndarray | None = None) -> ChunkSolution:
    """Integrate k runs of one method and sample count.

    Parameters
    ----------
    codes : array_like of int, shape (k,)
        Variant codes (``Variant.code``); every run's state has the same size.
    params : ndarray of :data:`rbstab.model.PARAMETERS`, shape (k,)
    y0 : ndarray, shape (k, n_state)
        Initial states.
    settings : ndarray, shape (k, 5) or (k, 7)
        Per run: t_end [s], rtol, atol, max_step [s], gimbal_margin [rad], and optionally
        max_steps and max_wall_time [s] (default: the arguments of those names).
    method : str
        One of :data:`METHODS`.
    n_samples : int
        Samples per run, evenly spaced on [0, t_end] (>= 2).
    max_steps : int
        Accepted steps after which a run stops (STEP_LIMIT), for 5-column ``settings``.
    max_wall_time : float
        Seconds after which a run stops (TIMEOUT; inf: none), for 5-column ``settings``.
    out : ndarray, shape (>= k, n_samples, n_state), optional
        Where the samples go (its first k rows, returned as ``samples``): a buffer the
        caller reuses for call after call, so that a worker holds one (default: a new
        array).

    Raises
    ------
    ValueError
        If ``out`` is not a writable C-contiguous float64 array of that shape.
    """
    codes = np.ascontiguousarray(codes, dtype=np.int64)
    y0 = np.ascontiguousarray(y0, dtype=float)
    k, n = y0.shape
    settings = np.asarray(settings, dtype=float)
    if settings.shape[1] == 5:
        settings = np.column_stack([settings, np.full(k, float(max_steps)), np.full(k, float(max_wall_time))])
    samples = np.empty((k, n_samples, n)) if out is None else _sample_buffer(out, (k, n_samples, n))
    status = np.empty(k, dtype=np.int64)
    t_stop = np.empty(k)
    nfev = np.empty(k, dtype=np.int64)
    n_steps = np.empty(k, dtype=np.int64)
    work = np.empty((k, n_samples))
    with np.errstate(all="ignore"):
        integrate_chunk(codes, np.ascontiguousarray(params), y0, settings_records(settings, method_number(method)),
                        samples, work, (status, t_stop, nfev, n_steps))
    return ChunkSolution(samples, status, t_stop, nfev, n_steps, work)


def integrate_chain_runs(system, y0, settings, *, method: str, n_samples: int, tree_of=None) -> ChunkSolution:
    """Integrate k runs of trees of bodies (chains) of one structure from the initial states
    ``y0`` with the compiled driver, as :func:`integrate_runs` integrates one body's runs,
    in reduced coordinates (:mod:`rbstab.variants.tree`).

    Parameters
    ----------
    system : TreeSystem
        The tree (:func:`rbstab.engine.systems.tree_system`: its compiled description,
        admissible region and reduced layout), or t trees of one structure (the same
        codes, parents and layout): ``params`` (t, n) and ``ppoints`` (t, n, 3) stacked
        (:func:`rbstab.engine.systems.tree_rows`).
    y0 : ndarray, shape (k, n_r) or (k, 12 n + 3 e)
        Initial states in the reduced layout or the maximal one (reduced here by
        :func:`rbstab.variants.tree.reduce_states`; the two layouts are one where no joint
        is permanent).
    settings : ndarray, shape (k, 7)
        Per run: :data:`~rbstab.engine.settings.SETTING_COLUMNS` (t_end [s], rtol, atol,
        max_step [s], gimbal_margin [rad], max_steps, max_wall_time [s]).
    method : str
        One of :data:`METHODS`.
    n_samples : int
        Samples per run, evenly spaced on [0, t_end] (>= 2).
    tree_of : ndarray of int, shape (k,), optional
        The tree of each run, for a ``system`` of t trees (default: the first).

    Returns
    -------
    ChunkSolution
        ``samples`` (k, n_samples, 12 n + 3 e): the maximal image of the states (Theta,
        Omega, X, V of every body, then each embedded joint's D).

    Raises
    ------
    ValueError
        For a ``tree_of`` that does not index the trees (:func:`~rbstab.engine.systems.tree_rows`).
    """
    y0 = np.ascontiguousarray(np.atleast_2d(y0), dtype=float)
    k = y0.shape[0]
    params, ppoints, tree_of = tree_rows(system, k, tree_of)
    if y0.shape[1] != reduced_size(system.codes, system.d_at):
        y0 = reduce_tree_states(system, params, ppoints, tree_of, y0)
    n = y0.shape[1]
    samples = np.empty((k, n_samples, n))
    ends = (np.empty(k, dtype=np.int64), np.empty(k), np.empty(k, dtype=np.int64), np.empty(k, dtype=np.int64))
    work = np.empty((k, n_samples))
    records = settings_records(np.asarray(settings, dtype=float).reshape(k, -1), method_number(method))
    codes, parents = system.codes, system.parents
    with np.errstate(all="ignore"):
        if is_one_body(params, codes, parents, ppoints):
            # the paper's one-body model: one body's compiled rate, several times faster than
            # the general tree's, and its two spellings one model
            integrate_chunk(np.repeat(codes, k), np.ascontiguousarray(params[tree_of, 0]), y0, records, samples, work,
                            ends)
        else:
            integrate_tree_chunk(system._replace(params=params, ppoints=ppoints), tree_of, y0, records, samples, work,
                                 ends)
    n_states = 12 * len(codes) + 3 * int(np.sum(system.d_at >= 0))
    if n == n_states:  # no permanent joint: the reduced layout is the maximal one
        return ChunkSolution(samples, *ends, work)
    maximal = np.empty((k, n_samples, n_states))
    expand_tree_samples(system, params, ppoints, tree_of, samples, maximal)
    return ChunkSolution(maximal, *ends, work)


def _sample_buffer(out, shape: tuple[int, int, int]) -> np.ndarray:
    """The first ``shape[0]`` rows of ``out`` (see :func:`integrate_runs`); ValueError if it
    cannot hold them."""
    if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.flags.c_contiguous
            and out.flags.writeable and out.ndim == 3 and out.shape[0] >= shape[0] and out.shape[1:] == shape[1:]):
        found = f"shape {out.shape} of {out.dtype}" if isinstance(out, np.ndarray) else type(out).__name__
        raise ValueError(f"out: found {found}; expected a writable C-contiguous float64 array of shape "
                         f"(>= {shape[0]}, {shape[1]}, {shape[2]})")
    return out[: shape[0]]
