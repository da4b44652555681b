"""Integrate validated run configurations: one (:func:`simulate`) or many (:func:`simulate_many`,
or :func:`simulate_blocks`, their results as blocks of runs), or the runs of a
:class:`rbstab.engine.RunBatch` (:func:`simulate_batch`, no configuration object per run).

The engines (:data:`rbstab.engine.ENGINES`) share the compiled model
(:mod:`rbstab.variants.kernels`):

- ``compiled`` (the default): :mod:`rbstab.engine`, scipy's RK23, RK45 and DOP853
  compiled with the model, the steps ``solve_ivp`` takes; every run a tree (one body its
  one-body tree, integrated by one body's rate), every run of a call with its own
  bodies, gains and settings.
- ``scipy`` (the reference, and the path of the implicit methods Radau, BDF, LSODA):
  :func:`scipy.integrate.solve_ivp` on the compiled right-hand side.
- ``cuda``: the compiled engine's steps on an NVIDIA GPU (:mod:`rbstab.engine.cuda`).

The pure sign law of ``sliding`` (``boundary_layer: 0``), whose right-hand side jumps, is
routed by every engine to the event-driven integrator :mod:`rbstab.engine.switching`
(switchings located, Filippov sliding, see docs/sliding.md); its result also holds the
located events (``RunResult.switching``) and the switching figures in its summary.

Both sample the dense output on an even grid, evaluate every output quantity with the
compiled ``output_row`` and return a :class:`RunResult`. A failed run (solver failure,
gimbal lock, the admissible region of ``simulation.limits`` left, non-finite state, step
limit) is data: ``status == "failed"`` with a message naming the bound and the time, never
an exception.

Every run ends: on either engine a run stops as ``failed`` after
``simulation.max_steps`` accepted steps or ``simulation.max_wall_time`` seconds of
integration (the ``timeout`` argument overrides the latter), with the reason as its
message.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING

import numpy as np

from .engine import METHODS, RunBatch
from .engine.batch import batch_of
from .engine.registry import DEFAULT_ENGINE, get_engine
from .engine.status import (GIMBAL_LOCK, RANGE_LEFT, STEP_LIMIT, SUCCESS, TIMEOUT, gimbal_of, gimbal_status, limit_of,
                            limit_part, limit_status, range_of, status_message)
from .engine.switching import integrate_sign_law, sign_law_outputs, switching_message, switching_summary
from .layout import LIMITED, OUTPUTS, QUANTITIES, SUMMARY_FIGURES, VARIANT_LAYOUTS, is_chain, joint_kind, summary_stride
from .results import RunBlock, RunResult, row
from .summary import numerical_rate, pressure_samples, summarize, tree_stream_table, tree_summary_table
from .variants.paper import paper_form, paper_initial_state
from .variants.disturbances import next_breakpoint

if TYPE_CHECKING:  # pragma: no cover
    from .config import RunConfig

__all__ = [
    "RunResult",
    "RunLimits",
    "simulate",
    "simulate_many",
    "simulate_blocks",
    "simulate_batch",
    "RunBlock",
    "solve_tree",
    "uses_compiled_engine",
    "is_sign_law",
    "simulate_sign_law",
    "run_end",
]

#: What :func:`simulate_blocks` keeps of the samples of a run: every one, on the GPU every
#: ``summary_stride``-th (:func:`rbstab.layout.summary_stride`, a thinned store's; the CPU
#: keeps every one), or none (the summary figures only; on the GPU no sample comes back).
KEEP = ("all", "thinned", "none")


class RunLimits:
    """A terminal ``solve_ivp`` event (falling through zero) that ends a run before
    ``t_end`` [s] at its limits, as the compiled driver ends it: once ``max_steps`` steps
    are accepted, or once ``timeout`` [s] of wall time have passed, read after each accepted
    step. ``solve_ivp`` calls it at each integration's start and after every accepted step;
    at a limit it is ``t_stop - t`` with ``t_stop`` that step's end, where the integration
    then ends with its samples up to ``t_stop`` kept. One instance counts the steps of every
    integration of a run (its disturbances' windows, from each one's start).

    Attributes
    ----------
    status : int or None
        :data:`rbstab.engine.status.STEP_LIMIT` or ``TIMEOUT`` once a limit is reached.
    t_stop : float or None
        Where the run stopped [s].
    """

    terminal = True
    direction = -1

    def __init__(self, max_steps: int, timeout: float, t_end: float) -> None:
        self.max_steps, self.t_end = max_steps, t_end
        self.deadline = _time.perf_counter() + timeout if timeout < np.inf else np.inf
        self.steps = 0
        self.t_last: float | None = None
        self.status: int | None = None
        self.t_stop: float | None = None

    def __call__(self, t: float, y: np.ndarray) -> float:
        if self.t_stop is not None:
            return self.t_stop - t
        if self.t_last is not None and t > self.t_last:  # after an accepted step (not a start)
            self.steps += 1
            if t < self.t_end:
                if self.steps >= self.max_steps:
                    self.status = STEP_LIMIT
                elif _time.perf_counter() > self.deadline:
                    self.status = TIMEOUT
            if self.status is not None:
                self.t_stop = t
                return 0.0
        self.t_last = t
        return 1.0

    def message(self, gimbal_margin: float, timeout: float) -> str:
        """The run's message at the limit it reached (:func:`status_message`)."""
        return status_message(self.status, self.t_stop, gimbal_margin, self.max_steps, timeout)


def solve_tree(config, timeout: float | None = None, compiled=None):
    """Integrate a run of a tree (:class:`rbstab.config.RunConfig`) in reduced
    coordinates (:func:`rbstab.variants.tree.tree_rate`) with scipy's ``solve_ivp``
    (``simulation``'s method, tolerances, steps), sampled at ``n_samples`` times on [0,
    t_end]: the reference of the compiled driver. It stops ``failed`` where any body's or
    joint's |theta_2| reaches pi/2 - ``gimbal_margin`` or the state leaves
    ``simulation.limits`` (the rows after are NaN). The edges of the disturbances' windows split the
    run: a new ``solve_ivp`` from each edge (the rate evaluated below the next one), from
    the state just after the impulses that start there (a sample at that time shows it; the
    generalised velocities jump, :func:`rbstab.variants.tree.tree_impulses`: the joints'
    impulsive reactions keep them joints). ``states`` are the maximal image (12 n + 3 e) of the samples; ``work``
    the disturbances' work W [J] there, integrated with the state where the chain has
    disturbances (its rate their power, left out of the error norm, as the compiled
    driver's; each impulse adds its energy). It stops ``failed`` after ``simulation.max_steps`` steps or ``timeout`` [s] of wall time (default
    ``simulation.max_wall_time``), keeping the samples up to its last step (:class:`RunLimits`).

    Parameters
    ----------
    config : RunConfig
        Validated (any method of ``solve_ivp``).
    timeout : float, optional
        Wall-time limit [s]; default ``simulation.max_wall_time``.
    compiled : CompiledChain, optional
        ``config``'s compiled tree (:func:`rbstab.variants.chain.compile_chain`), if at hand.

    Returns
    -------
    ChainTrajectory
        ``time`` (n_samples,) [s]; ``states`` (n_samples, 12 n + 3 e), the maximal image
        (inertial frame for X, V; body frames for Omega), NaN after a stop; ``work``
        (n_samples,) [J]; ``status``, ``message``; ``solver`` (nfev, njev, nlu,
        solver_status: scipy's, 1 at a stop before t_end; wall_time [s]). A
        physical or numerical failure is a ``"failed"`` status, never an exception."""
    from scipy.integrate import solve_ivp  # heavy: scipy

    from .engine.settings import settings_rows  # heavy: numba
    from .variants.chain import (ChainTrajectory, _gimbal_margin, compile_chain, impulse_times,  # heavy: numba
                                 initial_state, locked_part, region_margin)
    from .variants.tree import (expand_samples, reduce_state, tree_expand, tree_impulses, tree_layout,  # heavy: numba
                                tree_rate, tree_work)
    from .variants.tree import range_margin  # heavy: numba

    sim = config.simulation
    compiled = compile_chain(config.chain) if compiled is None else compiled
    layout = tree_layout(compiled)
    n = compiled.size
    args, tree = compiled.args, (*compiled.args, *layout.args)
    n_r = layout.n_r
    disturbed = bool(np.any(compiled.params["disturbance_count"] > 0.0))
    # W after the state where the chain has disturbances: its rate their power, out of the error norm
    y = np.append(reduce_state(compiled, layout, initial_state(config)), [0.0] if disturbed else [])
    # W's atol inf keeps it out of the error, but scipy's RMS norm still divides by its entry:
    # both tolerances scaled by sqrt(n_r / (n_r + 1)) give the norm over the state alone (the compiled driver's)
    shrink = math.sqrt(n_r / (n_r + 1)) if disturbed else 1.0
    atol = np.append(np.full(n_r, shrink * sim.atol), [np.inf] if disturbed else [])
    rtol = shrink * sim.rtol
    time = np.linspace(0.0, sim.t_end, sim.n_samples)
    dy = np.empty(y.size)
    work = tree_work(n, compiled.n_states)
    rot, rate = np.empty((n, 3, 3)), np.empty((n, 3, 3))
    start = _time.perf_counter()
    limit = float(timeout if timeout is not None else sim.max_wall_time)
    max_steps = int(sim.max_steps)

    def maximal(yr):
        full = np.empty(compiled.n_states)
        tree_expand(np.ascontiguousarray(yr), *tree, full, rot, rate, True)
        return full

    below = [np.inf]  # the float below the segment's end: no evaluation at or after an edge

    def reduced_rate(t, yr):
        tree_rate(min(t, below[0]), np.ascontiguousarray(yr), *tree, dy, work)
        return dy.copy()

    def jump(t, yr):
        """Apply the impulses that start at t to ``yr`` (in place; their energy added to W)."""
        energy = tree_impulses(t, yr, *tree, work)
        if energy != 0.0 and disturbed:
            yr[n_r] += energy

    def lock(t, yr):
        return _gimbal_margin(compiled, maximal(yr[:n_r]), sim.gimbal_margin)

    def region(t, yr):
        return region_margin(compiled, maximal(yr[:n_r]), sim.limits)[0]

    def ranges(yr):
        """(margin, status) of the joints' ranges that are admissible regions at ``yr``."""
        return range_margin(np.ascontiguousarray(yr[:n_r]), compiled.params, compiled.codes, layout.r_at, np.inf, 0,
                            RANGE_LEFT)

    def ranged(t, yr):
        return ranges(yr)[0]

    row = settings_rows([sim], timeout)[0]
    bounds = np.full((len(LIMITED), 3), np.inf) if sim.limits is None else sim.limits.array
    one_body = not is_chain(config)  # written as one body: one body's words

    def end(t, yr, event):
        """The message of a run stopped at t at the reduced state ``yr`` by the event
        ``event`` (gimbal lock, its bounds or a joint's range), in the compiled driver's
        words (:func:`run_end`)."""
        full = maximal(yr[:n_r])
        if event is lock:
            code = GIMBAL_LOCK if one_body else gimbal_status(*locked_part(compiled, full))
        elif event is region:
            code = limit_status(*region_margin(compiled, full, sim.limits)[1])
        else:
            code = ranges(yr)[1]
        return run_end(compiled, code, t, row, bounds, one_body)

    def left(t, yr):
        """The message where the state at t (a segment's start: after the impulses there)
        lies outside the admissible region, else None (a start on its boundary is inside)."""
        for event in events[:-1]:
            if event(t, yr) < 0:
                return end(t, yr, event)
        return None

    events = [lock] + ([] if sim.limits is None else [region]) + (
        [ranged] if np.any(compiled.params["region"] > 0.0) else [])
    for event in events:  # terminal, falling through zero (leaving the region), as one body's
        event.terminal, event.direction = True, -1
    limits = RunLimits(max_steps, limit, sim.t_end)  # shared by the segments
    events.append(limits)
    jumps = impulse_times(compiled, sim.t_end)
    edges = [0.0]  # every edge of a disturbance's window: no step crosses one
    while edges[-1] < sim.t_end:
        edges.append(min(next_breakpoint(p, edges[-1], float(sim.t_end)) for p in compiled.params))
    states = np.full((time.size, y.size), np.nan)
    counts = {"nfev": 0, "njev": 0, "nlu": 0}
    status, message = "success", "The solver successfully reached the end of the integration interval."

    def trajectory(status, message, solver_status):
        full = np.full((time.size, compiled.n_states), np.nan)
        params, codes, parents, ppoints, d_at = args
        expand_samples(np.ascontiguousarray(states[None, :, :n_r]), params[None], codes, parents, ppoints[None], d_at,
                       *layout.args, full[None], np.zeros(1, np.int64))
        done = states[:, n_r] if disturbed else np.where(np.isnan(states[:, 0]), np.nan, 0.0)
        return ChainTrajectory(time, full, status, message, {**counts, "solver_status": solver_status,
                                                             "wall_time": _time.perf_counter() - start}, compiled,
                               done)

    for a, b in zip(edges[:-1], edges[1:]):
        jump(a, y)
        outside = left(a, y)
        if outside is not None:
            status, message = "failed", outside
            break
        below[0] = np.nextafter(b, a) if b < sim.t_end else np.inf
        rows = np.flatnonzero((time >= a) & ((time < b) if b < sim.t_end else (time <= b)))
        t_eval = np.append(time[rows], b) if b < sim.t_end else time[rows]
        try:
            with np.errstate(all="ignore"):  # a run that blows up ends failed
                sol = solve_ivp(reduced_rate, (a, b), y, method=sim.method, t_eval=t_eval, rtol=rtol, atol=atol,
                                max_step=sim.max_step, events=events)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # a state scipy refuses (not finite)
            status, message = "failed", f"solver error: {exc}"
            break
        for key in counts:
            counts[key] += int(getattr(sol, key))
        solved = np.asarray(sol.y, dtype=float)  # an empty list where the first step failed
        got = min(solved.shape[1] if solved.ndim == 2 else 0, rows.size)
        if got:
            states[rows[:got]] = solved[:, :got].T
        if limits.status is not None:
            status, message = "failed", limits.message(sim.gimbal_margin, limit)
            break
        if sol.status == 1:  # the first terminal event that occurred
            k = next(k for k in range(len(events) - 1) if len(sol.t_events[k]))
            status, message = "failed", end(float(sol.t_events[k][0]), sol.y_events[k][0], events[k])
            break
        if sol.status != 0:
            status, message = "failed", str(sol.message)
            break
        y = sol.y[:, -1].copy()
    else:
        if sim.t_end in jumps:  # an impulse at t_end: the last sample shows the state after it
            y = states[-1].copy()
            jump(sim.t_end, y)
            states[-1] = y
    return trajectory(status, message, 0 if status == "success" else 1)


def uses_compiled_engine(config, engine: str = DEFAULT_ENGINE) -> bool:
    """Whether ``engine`` integrates ``config`` (a RunConfig) in its batches
    (:meth:`rbstab.engine.Engine.takes`; ValueError for an unknown engine)."""
    return get_engine(engine).takes(config.simulation.method, is_sign_law(config))


def is_sign_law(config) -> bool:
    """Whether ``config`` has the pure sign law of ``sliding`` (``boundary_layer`` 0):
    :attr:`rbstab.chain.Chain.sign_law` of its model."""
    return config.chain.sign_law


def simulate_sign_law(config: "RunConfig", timeout: float | None = None) -> RunResult:
    """Run a pure-sign-law configuration with :mod:`rbstab.engine.switching` (see
    :func:`simulate`; ``timeout`` [s] replaces ``simulation.max_wall_time``); the result's
    ``switching`` holds the located events."""
    start = _time.perf_counter()
    variant = paper_form(config)
    solution = integrate_sign_law(variant, paper_initial_state(config, variant), config.simulation,
                                  timeout=timeout)
    solved = _time.perf_counter()
    outputs, checked = sign_law_outputs(variant, solution)
    summary = {**summarize(solution.time, outputs, checked, variant.parameters), **switching_summary(solution)}
    if is_chain(config):  # written as a tree: its results in a tree's names and shapes
        outputs, summary = _as_one_body_tree(outputs, summary)
    message = solution.message + switching_message(solution, config.simulation.method)
    result = RunResult(config=config, time=solution.time, outputs=outputs, status=solution.status, message=message,
                       solver=solution.solver, summary=summary, switching=solution.switchings)
    end = _time.perf_counter()
    result.wall_time = end - start
    result.timing = {"integration": solved - start, "postprocess": end - solved}
    return result


def _as_one_body_tree(outputs: dict, summary: dict) -> tuple[dict, dict]:
    """One body's outputs (m samples) and summary as those of its one-body tree (a config
    written as a tree): every body's or joint's quantity (:attr:`rbstab.layout.Quantity.member`)
    with an axis of one, (m, 1, 3) and (1, 3); the ground joint's Theta_j, Omega_j the body's
    own Theta, Omega (A_p = I, Omega_p = 0); D NaN where the joint has none, as in a tree's outputs."""
    tree = {key: value[:, None] if getattr(QUANTITIES.get(key), "member", None) else value
            for key, value in outputs.items()}
    tree["joint_theta"], tree["joint_omega"] = tree["theta"].copy(), tree["omega"].copy()
    tree.setdefault("controller_state", np.full_like(tree["theta"], np.nan))  # a joint without D, as a tree's
    table = {key: np.asarray(value)[None] if getattr(SUMMARY_FIGURES.get(key), "member", None) else value
             for key, value in summary.items()}
    return tree, table


def _as_one_body(outputs: dict, summary: dict, embedded: bool) -> tuple[dict, dict]:
    """The outputs (k runs, m samples) and summary columns of k runs of a one-body tree as
    those of one body (a config written as one body; the inverse of
    :func:`_as_one_body_tree`): every body's or joint's quantity
    (:attr:`rbstab.layout.Quantity.member`) without its axis of one, (k, m, 3) and (k, 3);
    without the ground joint's Theta_j, Omega_j (the body's Theta, Omega) and D where the
    joint is not ``embedded``."""
    dropped = {"joint_theta", "joint_omega", "com_position", "com_velocity", "centre_of_pressure",  # its X, V
               "net_centre_of_pressure",
               *(() if embedded else ("controller_state",))}
    order = sorted(set(outputs) - dropped, key=lambda key: _OUTPUT_ORDER.get(key, len(_OUTPUT_ORDER)))  # one body's
    body = {key: outputs[key][:, :, 0] if getattr(QUANTITIES.get(key), "member", None) else outputs[key]
            for key in order}
    table = {key: value[:, 0] if getattr(SUMMARY_FIGURES.get(key), "member", None) else value
             for key, value in summary.items()}
    return body, table


def simulate(config, timeout: float | None = None, *, engine: str = DEFAULT_ENGINE) -> RunResult:
    """Run one validated configuration: one body, or a tree of bodies.

    A tree's run with a method the engine takes is integrated by the compiled driver
    (:func:`simulate_blocks`: the same steps as ``solve_ivp``'s, the admissible region's
    events located on the step's interpolant); with scipy's engine or methods, by
    ``solve_ivp`` (:func:`solve_tree`). Its outputs and summary are per
    body and joint; a failed run's rows after the failure are NaN.

    Parameters
    ----------
    config : RunConfig
        From :func:`rbstab.config.load_config` or
        :func:`rbstab.config.load_config` (already validated).
    timeout : float, optional
        Wall-time limit of the integration [s], instead of ``simulation.max_wall_time``;
        past it the run fails with a message.
    engine : {"compiled", "scipy", "cuda"}
        See :data:`rbstab.engine.ENGINES`.

    Returns
    -------
    RunResult
        Never raises for a physical or numerical failure, nor for a run past its limits:
        those are ``status="failed"``.

    Raises
    ------
    ValueError
        For an unknown engine.
    """
    compiled = uses_compiled_engine(config, engine)  # checks the engine's name
    if is_sign_law(config):
        return simulate_sign_law(config, timeout)
    if compiled:
        return next(simulate_many([config], engine=engine, timeout=timeout))[1]
    return _simulate_tree(config, timeout)


#: One body's outputs' order in its files (:data:`rbstab.layout.OUTPUTS`; the numerical dv/dt after them).
_OUTPUT_ORDER = {key: i for i, key in enumerate(OUTPUTS)}
#: Variant code -> its name.
_VARIANT_NAMES = tuple(VARIANT_LAYOUTS)

#: Runs whose outputs :func:`simulate_many` evaluates together before yielding them; bounds
#: the memory of outputs held at once (36 columns per sample) to this many runs. Also its
#: default number of runs per compiled call (the trajectories held at once).
POSTPROCESS_BLOCK = 32
#: Bytes of samples a chain's GPU launch brings back to the host at most where its runs'
#: outputs are kept (every sample; summaries alone bring back a state a run): the runs of a
#: launch of :func:`_tree_batch_blocks` with the CUDA engine.
CUDA_CHAIN_SAMPLE_BYTES = 2 * 2**30


def _ends(trees: Sequence, tree_of: np.ndarray, status: np.ndarray, t_stop: np.ndarray, nfev: np.ndarray,
          n_steps: np.ndarray, settings: np.ndarray, limits: np.ndarray, one_body: bool) -> dict:
    """A :class:`RunBlock`'s ``status``, ``message`` and ``solver`` of k runs of the compiled
    engine (:func:`run_end`, each run's tree ``trees[tree_of[j]]``), from their status codes
    (:mod:`rbstab.engine.status`), stop times [s], right-hand-side evaluations, steps,
    settings rows (k, 7) and admissible regions (k, 5, 3; the ``limits`` of their records)."""
    status = np.asarray(status, dtype=np.int64)
    ok = status == SUCCESS
    message = np.full(len(status), status_message(SUCCESS, 0.0, 0.0), dtype=object)
    for j in np.flatnonzero(~ok).tolist():  # failed runs: few
        message[j] = run_end(trees[tree_of[j]], int(status[j]), float(t_stop[j]), settings[j], limits[j], one_body)
    return {"status": np.where(ok, "success", "failed").tolist(), "message": message.tolist(),
            "solver": _compiled_solver(nfev, n_steps, status)}


def _compiled_solver(nfev, n_steps, status) -> dict:
    """The solver counts of runs of the compiled driver (k,) each, as scipy's names them (no
    Jacobian, no LU), with their status codes (:mod:`rbstab.engine.status`)."""
    status = np.asarray(status, dtype=np.int64)
    zeros = np.zeros(len(status), dtype=np.int64)
    return {"nfev": np.asarray(nfev, dtype=np.int64), "njev": zeros, "nlu": zeros.copy(), "solver_status": status,
            "n_steps": np.asarray(n_steps, dtype=np.int64)}


def simulate_many(configs: Sequence["RunConfig"], *, engine: str = DEFAULT_ENGINE,
                  chunk_size: int = POSTPROCESS_BLOCK, timeout: float | None = None,
                  full: bool = True) -> Iterator[tuple[int, RunResult]]:
    """Run many validated configurations; yields ``(index into configs, RunResult)``.

    :func:`simulate_blocks`, a run at a time (the arguments and errors are its).
    """
    for indices, block in simulate_blocks(configs, engine=engine, chunk_size=chunk_size, timeout=timeout, full=full):
        for j, i in enumerate(indices):
            yield i, block.result(j)


def simulate_blocks(configs: Sequence["RunConfig"], *, engine: str = DEFAULT_ENGINE,
                    chunk_size: int = POSTPROCESS_BLOCK, timeout: float | None = None,
                    full: bool = True, keep: str = "all") -> Iterator[tuple[list[int], RunBlock]]:
    """Run many validated configurations (RunConfig); yields ``(indices
    into configs, RunBlock)``.

    The runs the compiled engine takes (:func:`uses_compiled_engine`) are one
    :class:`~rbstab.engine.RunBatch` (:func:`rbstab.engine.batch.batch_of`) integrated by
    :func:`simulate_batch`: every run a tree (one body its one-body tree), the runs of one
    structure (the same bodies, joints and laws; any masses, gains, points, settings and
    admissible regions) with the same method, sample count and t_end integrated together,
    ``chunk_size`` runs a call on the CPU (:func:`rbstab.engine.integrate.integrate_chain_runs`);
    a run's result does not depend on the other runs of its call. The others go through
    :func:`simulate` one by one (a block of one run each). The outputs (with ``full``
    False all but :data:`rbstab.layout.LEFT_OUT` for one body, which neither the summary
    nor a thinned store reads) are evaluated :data:`POSTPROCESS_BLOCK` runs at a time, a
    block each (one read-only ``time`` array); ``keep`` ``"none"``: the blocks carry
    summaries and no traces. Each run's ``wall_time`` is its share of its call's
    integration plus its own post-processing [s] (split in ``timing``). ``timeout`` [s],
    if given, replaces each run's ``simulation.max_wall_time``.

    With ``engine="cuda"`` the same runs go to the GPU (:mod:`rbstab.engine.cuda`), a
    call a launch (``chunk_size`` is not read): the summaries computed on the GPU as the
    runs go, the samples brought back as ``keep`` says (:data:`KEEP`; ``stride`` tells
    which), every run's
    ``wall_time`` its share of the launch. ``timeout``, if given, is each launch's limit;
    the runs' ``simulation.max_wall_time`` is not read.

    Raises
    ------
    ValueError
        For an unknown engine (allowed: :data:`rbstab.engine.ENGINES`), ``keep`` or ``chunk_size < 1``.
    rbstab.engine.cuda.CudaUnavailable
        With ``engine="cuda"`` where no GPU, driver or numba-cuda is found (before any run).
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size: found {chunk_size}; expected an integer >= 1")
    if keep not in KEEP:
        raise ValueError(f"keep: found {keep!r}; expected one of {', '.join(KEEP)}")
    get_engine(engine).check_available()  # before any run
    chosen = []
    for i, config in enumerate(configs):
        if not uses_compiled_engine(config, engine):
            yield [i], RunBlock.of(simulate(config, timeout, engine="scipy"))
        else:
            chosen.append(i)
    if chosen:
        runs = [configs[i] for i in chosen]
        for rows, block in simulate_batch(batch_of(runs, timeout), chunk_size=chunk_size, full=full, engine=engine,
                                          keep=keep, configs=runs):
            yield [chosen[r] for r in rows], block


def simulate_batch(batch: RunBatch, rows: Sequence[int] | np.ndarray | None = None, *,
                   chunk_size: int = POSTPROCESS_BLOCK, full: bool = True, engine: str = DEFAULT_ENGINE,
                   keep: str = "all", configs: Sequence | None = None) -> Iterator[tuple[list[int], RunBlock]]:
    """Integrate runs of a :class:`rbstab.engine.RunBatch` with the compiled engine; yields
    ``(rows of the batch, RunBlock)``.

    What :func:`simulate_blocks` does for the configurations of those runs, with the same
    results bit for bit, from the batch's arrays (no configuration object), as
    :func:`_tree_batch_blocks` says; a run in the one-body spelling (``batch.one_body``)
    has one body's outputs, figures and messages (:func:`_as_one_body`). The blocks'
    ``configs`` are ``configs``' entries of their rows (None where not given).

    Parameters
    ----------
    batch : RunBatch
    rows : sequence of int, optional
        The runs to integrate (default: every run with ``batch.compiled``).
    chunk_size : int
        Runs per compiled call (the trajectories held at once).
    full : bool
        Every output (else one body's all but :data:`rbstab.layout.LEFT_OUT`).
    engine : {"compiled", "cuda"}
        The CPU engine, or the GPU as :func:`simulate_blocks` runs it (``chunk_size`` not
        read).
    keep : {"all", "thinned", "none"}
        The samples kept (:data:`KEEP`).
    configs : sequence of RunConfig, optional
        The runs' configurations, one a row of the batch (what their results carry).

    Raises
    ------
    ValueError
        For a run the compiled engine does not take (``batch.compiled`` False), or
        ``chunk_size < 1``.
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size: found {chunk_size}; expected an integer >= 1")
    rows = np.flatnonzero(batch.compiled) if rows is None else np.asarray(rows, dtype=np.int64)
    if not np.all(batch.compiled[rows]):
        bad = int(rows[np.flatnonzero(~batch.compiled[rows])[0]])
        raise ValueError(f"run {bad} of the batch: the compiled engine does not take it (its method or the "
                         "pure sign law); run it with simulate()")
    yield from _tree_batch_blocks(batch, rows, engine, keep, configs, full, chunk_size)


def _configs_of(configs: Sequence | None, rows) -> list:
    """``configs``' entries at ``rows`` (None each where there are no configs)."""
    return [None] * len(rows) if configs is None else [configs[int(i)] for i in rows]


def _simulate_tree(config, timeout: float | None = None) -> RunResult:
    """A run (:class:`rbstab.config.RunConfig`: a tree, or one body as its one-body tree)
    integrated by ``solve_ivp`` (:func:`solve_tree`, any method), with its outputs and
    summary (one body's names and shapes for a config written as one body);
    ``timeout`` [s] replaces ``simulation.max_wall_time``."""
    start = _time.perf_counter()
    trajectory = solve_tree(config, timeout)
    compiled, time = trajectory.compiled, trajectory.time
    one_body = not is_chain(config)  # written as one body: one body's names and shapes
    outputs, summary = _trees_outputs([compiled], np.zeros(1, dtype=np.int64), time, trajectory.states[None],
                                      trajectory.work[None], tree=not one_body)
    if one_body:
        outputs, summary = _as_one_body(outputs, summary, bool(np.any(compiled.d_at >= 0)))
    outputs, summary = {key: value[0] for key, value in outputs.items()}, row(summary, 0)
    solver = {k: v for k, v in trajectory.solver.items() if k != "wall_time"}
    return RunResult(config, time, outputs, trajectory.status, trajectory.message, solver,
                     _time.perf_counter() - start, summary)


def _trees_outputs(compiled: Sequence, tree_of: np.ndarray, time: np.ndarray, states: np.ndarray,
                   work: np.ndarray, traces: bool = True, summary: bool = True, full: bool = True,
                   tree: bool = True) -> tuple[dict, dict]:
    """(outputs, summary columns) of k runs of chains of one structure, run i's chain
    ``compiled[i]`` (the runs of one ``tree_of`` one chain): their samples ``states`` (k, m,
    n_states) at ``time`` (m,) and their disturbances' work ``work`` (k, m) there, all at once
    (:func:`rbstab.variants.chain.evaluate`, :func:`rbstab.summary.tree_summary_table`); the
    outputs empty unless ``traces``, the summary unless ``summary`` (the GPU streams it);
    ``full`` False: one body's without :data:`rbstab.layout.LEFT_OUT`; ``tree`` False (runs
    written as one body): without the whole tree's centre of mass and centre of pressure."""
    from .variants import chain as C  # heavy: numba

    _, first, index = np.unique(tree_of, return_index=True, return_inverse=True)
    outputs = C.evaluate([compiled[i] for i in first], time, states, work, tree_of=index, full=full)
    structure = compiled[0]
    held = bool(np.any(structure.permanent & (structure.parents < 0)))  # a point-fixed joint to the ground
    grounded = held and bool(np.any(structure.chain.gravity))
    pressure = traces and full and tree  # the centres of pressure as outputs
    trees = [compiled[i] for i in first]
    # the paper's pinned body (one joint to the ground): its centre of pressure is its net one
    paper = held and pressure and all(t.one_body for t in trees)
    if (traces and full and structure.hinged) or (held and pressure and not paper):
        _reactions(structure, trees, index, time, states, outputs)
    elif held and pressure:  # the paper's pinned body: body_pressure's point (C.evaluate's), as one body's spelling
        net = outputs.setdefault("net_centre_of_pressure", np.full((*states.shape[:2], 3), np.nan))
        outputs["centre_of_pressure"] = net[:, :, None].copy()
    elif grounded and summary and "net_centre_of_pressure" not in outputs:  # at the samples its figure reads
        stride = summary_stride(len(time))
        outputs["net_centre_of_pressure"] = np.full((*states.shape[:2], 3), np.nan)
        outputs["net_centre_of_pressure"][:, ::stride] = _ground_wrenches(structure, trees, index, time, states,
                                                                           outputs, stride)[2]
    outputs["lyapunov_rate_numerical"] = numerical_rate(time, outputs["lyapunov"])
    if traces and tree:  # the whole body's centre of mass, sum m_i X_i / sum m_i
        mass = C.records_of(compiled)["mass"]  # (k, n)
        for name, block in (("com_position", "position"), ("com_velocity", "velocity")):
            outputs[name] = np.einsum("kn,kmnc->kmc", mass, outputs[block]) / mass.sum(axis=1)[:, None, None]
    table = tree_summary_table(time, outputs, embedded=bool(np.any(compiled[0].d_at >= 0)),
                               params=C.records_of(compiled)) if summary else {}
    if traces and not pressure:  # the net centre of pressure taken for the summary alone
        for name in ("centre_of_pressure", "net_centre_of_pressure"):
            outputs.pop(name, None)
    return outputs if traces else {}, table


def _ground_wrenches(structure, trees: Sequence, tree_of: np.ndarray, time: np.ndarray, states: np.ndarray,
                     outputs: dict, stride: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From the reduced motion (:func:`rbstab.variants.tree.reaction_samples`) of k runs of
    trees with a point-fixed joint (run i's tree ``trees[tree_of[i]]``, of ``structure``'s
    shape) at every ``stride``-th of their samples ``states`` (k, m, n_states) at ``time``
    (m,), with their joints' angles and rates (``outputs``' ``joint_theta``,
    ``joint_omega``): at those m' samples, Lambda_j [N] (k, m', n, 3; NaN for the joints that
    are not point-fixed), each joint to the ground's centre of pressure [m] (k, m', n, 3; NaN
    for the others) and their net centre of pressure [m] (k, m', 3;
    :func:`rbstab.summary.pressure_samples`), inertial frame."""
    from .variants import chain as C  # heavy: numba
    from .variants.tree import reaction_samples, tree_layout  # heavy: numba

    states, time = states[:, ::stride], time[::stride]
    k, m, n = states.shape[0], states.shape[1], structure.size
    reactions, moments = np.full((n, 3, k * m), np.nan), np.full((n, 3, k * m), np.nan)
    params, ppoints = C.records_of(trees), np.stack([t.ppoints for t in trees])
    angles = [np.ascontiguousarray(outputs[name][:, ::stride]).reshape(k * m, n, 3)
              for name in ("joint_theta", "joint_omega")]
    sample_tree = np.repeat(np.asarray(tree_of, dtype=np.int64), m)
    reaction_samples(np.tile(time, k), np.ascontiguousarray(states.reshape(k * m, -1)), *angles, params,
                     structure.codes, structure.parents, ppoints, structure.d_at, *tree_layout(structure).args,
                     sample_tree, reactions, moments)
    net, each = np.empty((k * m, 3)), np.empty((k * m, n, 3))
    pressure_samples(reactions, moments, ppoints, structure.codes, structure.parents, params, sample_tree, net, each)
    return reactions.transpose(2, 0, 1).reshape(k, m, n, 3), each.reshape(k, m, n, 3), net.reshape(k, m, 3)


def _reactions(structure, trees: Sequence, tree_of: np.ndarray, time: np.ndarray, states: np.ndarray,
               outputs: dict) -> None:
    """:func:`_ground_wrenches` at every sample of k runs into their outputs: Lambda_j [N]
    of the point-fixed joints where :func:`rbstab.variants.chain.evaluate` leaves them NaN
    (a tree with a hinge) into ``outputs["constraint_force"]`` (k, m, n, 3), each joint to
    the ground's centre of pressure into ``outputs["centre_of_pressure"]`` (k, m, n, 3; NaN
    for the other joints, without gravity and where the ground does not push up), their
    net centre of pressure into ``outputs["net_centre_of_pressure"]`` (k, m, 3) unless it
    holds one (the paper's one body's, :func:`rbstab.variants.kernels.body_pressure`: the GPU's)."""
    force, each, net = _ground_wrenches(structure, trees, tree_of, time, states, outputs)
    outputs.setdefault("net_centre_of_pressure", net)
    if structure.hinged:
        fixed = structure.permanent
        outputs["constraint_force"][:, :, fixed] = force[:, :, fixed]
    outputs["centre_of_pressure"] = each


def _groups(batch: RunBatch, rows: np.ndarray) -> list[np.ndarray]:
    """``rows`` of ``batch`` in groups, in order of first appearance, of what the runs
    integrated in one call share: the structure of their tree (codes, parents, embedded
    joints, names; whether one body's rate serves it), the spelling of their configurations,
    the method, sample count and t_end; their records, parent points and admissible regions
    may differ (:func:`rbstab.engine.systems.tree_rows`)."""
    from .variants.chain import one_body_mask, papers_feedback  # heavy: numba

    structures: dict[tuple, int] = {}
    shape = np.empty(len(batch.trees), dtype=np.int64)  # each tree's structure
    for t, tree in enumerate(batch.trees):
        key = (tree.codes.tobytes(), tree.parents.tobytes(), tree.d_at.tobytes(), tree.chain.body_names,
               tree.chain.joint_names)
        shape[t] = structures.setdefault(key, len(structures))
    tree = batch.tree[rows]
    one_body = np.zeros(len(rows), dtype=bool)
    points, attachment = batch.ppoints[rows, 0], batch.params["attachment_point"][rows, 0]  # the field alone copied
    papers = papers_feedback(*(batch.params[name][rows, 0] for name in ("theta_ref", "passive", "torque_floor",
                                                                         "torque_limit")))  # the fields alone
    for t in np.unique(tree).tolist():
        at = tree == t
        one_body[at] = one_body_mask(batch.trees[t].codes, batch.trees[t].parents, points[at], attachment[at],
                                     papers[at])
    keys = np.column_stack([shape[tree], one_body, batch.one_body[rows], batch.settings["method"][rows],
                            batch.n_samples[rows], batch.settings["t_end"][rows]]).astype(float)
    if np.all(keys == keys[:1]):  # one group (a sweep's usual batch)
        return [rows] if len(rows) else []
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    members = np.split(rows[order], np.cumsum(np.bincount(inverse))[:-1])
    return [members[g] for g in np.argsort(first)]


def _tree_batch_blocks(batch: RunBatch, rows: np.ndarray, engine: str, keep: str,
                       configs: Sequence | None, full: bool = True,
                       chunk_size: int = POSTPROCESS_BLOCK) -> Iterator[tuple[list[int], RunBlock]]:
    """:func:`simulate_batch` of the runs ``rows`` of a :class:`RunBatch` on the compiled
    driver (the CPU's, or the GPU's with ``engine`` ``"cuda"``): the runs of one structure
    (:func:`_groups`: the same bodies and joints and their laws; each run's masses, gains,
    points and admissible region its own) with the same method, sample count and t_end in
    calls of ``chunk_size`` runs of :func:`rbstab.engine.integrate.integrate_chain_runs`,
    each distinct tree once in a call.
    ``keep`` (:data:`KEEP`) ``"none"``: the blocks carry the summaries and no traces;
    ``full`` False: without :data:`rbstab.layout.LEFT_OUT`. On the GPU the runs of a call
    are one launch (:func:`rbstab.engine.cuda.integrate_chain_runs_cuda`; its limit the
    largest ``max_wall_time`` of its runs); their summaries are streamed on the device
    (:func:`rbstab.summary.tree_stream_table`) and the samples ``keep`` asks for come back
    (as many runs a call as :data:`CUDA_CHAIN_SAMPLE_BYTES` of samples)."""
    from .engine.integrate import integrate_chain_runs  # heavy: numba

    integrate, gpu = integrate_chain_runs, get_engine(engine).gpu
    if gpu:
        get_engine(engine).check_available()  # before any run
        from .engine.cuda import integrate_chain_runs_cuda as integrate  # heavy: numba-cuda (--engine cuda only)
    for members in _groups(batch, rows):
        per_call, n_samples = chunk_size, int(batch.n_samples[members[0]])
        stride = {"all": 1, "thinned": summary_stride(n_samples) if gpu else 1, "none": None}[keep]
        if gpu:  # a launch takes as many runs as the host may hold the samples of (none: their summaries)
            kept = 1 if stride is None else len(range(0, n_samples, stride))
            per_call = max(1, CUDA_CHAIN_SAMPLE_BYTES // (8 * kept * (int(batch.n_state[members[0]]) + 2)))
        for lo in range(0, len(members), per_call):
            yield from _tree_call(batch, members[lo: lo + per_call], integrate, gpu, stride, configs, full)


def _tree_call(batch: RunBatch, members: np.ndarray, integrate, gpu: bool, stride: int | None,
               configs: Sequence | None, full: bool = True) -> Iterator[tuple[list[int], RunBlock]]:
    """:func:`_tree_batch_blocks` for the runs ``members`` of ``batch`` (one structure,
    method, sample count and t_end): one call of ``integrate`` with each distinct tree and
    admissible region once, then their outputs at every ``stride``-th sample (None: no
    outputs) and summaries :data:`POSTPROCESS_BLOCK` runs at a time, a RunBlock each (the
    outputs held at once: those of that many runs; the GPU's summaries alone: a block). Runs
    in the one-body spelling get one body's outputs, figures and messages
    (:func:`_as_one_body`; ``full`` False: without :data:`rbstab.layout.LEFT_OUT`)."""
    from .engine.systems import tree_system, with_offsets  # heavy: numba
    from .variants import chain as C  # heavy: numba

    start = _time.perf_counter()
    one_body = bool(batch.one_body[members[0]])
    structure = batch.trees[int(batch.tree[members[0]])]
    n, n_states = structure.size, batch.n_state[members[0]]
    params, ppoints = batch.params[members, :n], batch.ppoints[members, :n]  # copies
    # h, v's zero: each tree's offset, added to v by its outputs (the records' 0: one body's outputs read theirs);
    # where the GPU streams v, in the first record of the launch's copy (rbstab.engine.systems.with_offsets)
    params[:, 0]["lyapunov_offset"] = 0.0
    limits = params[:, 0]["limits"]  # each run's admissible region
    keys = np.array([params[j].tobytes() + ppoints[j].tobytes() + batch.offset[i].tobytes()
                     for j, i in enumerate(members.tolist())], dtype=object)
    _, first, tree_of = np.unique(keys, return_index=True, return_inverse=True)  # each distinct tree once
    tree_of = tree_of.ravel().astype(np.int64)
    trees = [C.with_records(batch.trees[int(batch.tree[members[j]])], params[j], ppoints[j],
                            batch.offset[members[j]]) for j in first]
    params, ppoints = params[first], ppoints[first]
    system = tree_system(structure)._replace(params=np.ascontiguousarray(params), ppoints=np.ascontiguousarray(ppoints))
    if gpu:
        system = with_offsets(system, batch.offset[members[first]])
    y0 = batch.y0[members, :n_states]
    settings = batch.settings_rows(members)
    method, n_samples = METHODS[int(batch.settings["method"][members[0]])], int(batch.n_samples[members[0]])
    # on the GPU: a launch's limit, each tree's h, and the summaries streamed (the samples kept for the outputs only)
    gpu_options = {"max_wall_time": float(np.max(settings[:, 6])), "stride": stride} if gpu else {}
    sol = integrate(system, y0, settings, method=method, n_samples=n_samples, tree_of=tree_of, **gpu_options)
    grid = np.linspace(0.0, float(settings[0, 0]), n_samples)
    time = grid[:: stride or 1] if gpu else grid  # the samples that came back
    time.flags.writeable = False
    integration = (_time.perf_counter() - start) / len(members)
    block = len(members) if gpu and stride is None else POSTPROCESS_BLOCK
    for lo in range(0, len(members), block):
        hi = min(lo + block, len(members))
        t0 = _time.perf_counter()
        if gpu and stride is None:
            traces, summaries = {}, {}
        else:
            traces, summaries = _trees_outputs([trees[t] for t in tree_of[lo:hi]], tree_of[lo:hi], time,
                                               sol.samples[lo:hi], sol.work[lo:hi], stride is not None,
                                               summary=not gpu, full=full, tree=not one_body)
        if gpu:  # the summaries streamed on the device
            summaries = tree_stream_table(grid, sol.acc[lo:hi], sol.members[lo:hi], sol.last[lo:hi], n,
                                          structure.d_at)
            if stride is not None and stride > 1:  # a thinned trace's dv/dt: of the whole grid, on the device
                traces["lyapunov_rate_numerical"] = sol.rates[lo:hi]
        if one_body:  # one body's names and shapes
            traces, summaries = _as_one_body(traces, summaries, bool(np.any(structure.d_at >= 0)))
        ends = _ends(trees, tree_of[lo:hi], sol.status[lo:hi], sol.t_stop[lo:hi], sol.nfev[lo:hi], sol.n_steps[lo:hi],
                     settings[lo:hi], limits[lo:hi], one_body)
        post = np.full(hi - lo, (_time.perf_counter() - t0) / (hi - lo))
        yield members[lo:hi].tolist(), RunBlock(
            configs=_configs_of(configs, members[lo:hi]),
            time=time if stride is not None else time[:0],
            outputs=traces,
            summaries=summaries,
            **ends,
            wall_time=integration + post,
            timing={"integration": np.full(hi - lo, integration), "postprocess": post},
            switching=[None] * (hi - lo),
            stride=stride if gpu and stride else 1,
            **({"variants": [_VARIANT_NAMES[code] for code in batch.codes[members[lo:hi]].tolist()]} if one_body else
               {"joints": tuple(structure.chain.joint_names), "bodies": tuple(structure.chain.body_names)}),
        )


def _tree_left_region(what: str, t: float) -> str:
    """The message of a tree's run that left its admissible region at t [s] through the
    bound ``what`` (:func:`rbstab.variants.chain.bound_reached`), on every engine."""
    return f"left the admissible region: {what} at t = {t:.6g} s"


def _range_left(compiled, joint: int, coordinate: int, upper: bool, t: float) -> str:
    """The message of a tree's run whose joint ``joint``'s ``coordinate`` (a hinge's q, a
    universal joint's q_1 or q_2, a slide's q, a ball's Euler angle) reached an end of its
    range (an admissible region) at t [s], on
    every engine."""
    name = compiled.chain.joint_names[joint]
    end = float(compiled.params[joint]["range_upper" if upper else "range_lower"][coordinate])
    variant = compiled.chain.joints[joint].variant
    what = (f"the angle q of joint {name}" if variant == "hinge" else
            f"the displacement q of joint {name}" if variant == "slide" else
            f"the angle q_{coordinate + 1} of joint {name}" if variant == "universal" else
            f"the turn of joint {name} (its angle from the reference pose)" if variant == "ball" else
            f"theta_{coordinate + 1} of joint {name}'s Euler angles Theta_j")
    return (f"left the admissible region (joints.{name}.range): {what} reached its "
            f"{'upper' if upper else 'lower'} end {end:g} {joint_kind(variant).unit} at t = {t:.6g} s")


def run_end(compiled, code: int, t_stop: float, settings: np.ndarray, bounds: np.ndarray,
            one_body: bool = False) -> str:
    """The message of a run of the compiled driver that ended with ``code`` at ``t_stop``
    [s]: ``compiled`` its tree, ``settings`` its row (7,) of
    :data:`rbstab.engine.settings.SETTING_COLUMNS`, ``bounds`` (5, 3) its admissible region
    (a record's ``limits``). A gimbal lock's code names the body or joint
    (:func:`rbstab.engine.status.gimbal_of`), a bound's the quantity, its axis and the body
    or joint that reached it, a joint's range (:func:`rbstab.engine.status.range_of`) the
    joint, its coordinate and the end; with ``one_body`` (a run written as one body, whose words have
    no body or joint names) neither is named."""
    from .variants import chain as C  # heavy: numba

    margin = float(settings[4])
    # a one-body tree runs one body's compiled form: its lock, GIMBAL_LOCK, is of its one angle set
    locked = (0, bool(compiled.codes[0] == C.PERMANENT)) if code == GIMBAL_LOCK else gimbal_of(code)
    which = limit_of(code)
    ranged = range_of(code)
    if ranged is not None:
        return _range_left(compiled, *ranged, t_stop)
    if one_body or (locked is None and which is None):
        return status_message(code, t_stop, margin, int(settings[5]), float(settings[6]), limits=bounds)
    if locked is not None:
        return C.gimbal_lock_message(compiled, *locked, margin, t_stop)
    quantity, axis = which
    bound = float(np.asarray(bounds, dtype=float)[LIMITED.index(quantity), axis])
    return _tree_left_region(C.bound_reached(compiled, quantity, axis, limit_part(code), bound), t_stop)
