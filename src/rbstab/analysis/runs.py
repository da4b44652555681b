"""Runs of one configuration from chosen initial states, in batches: what the analyses'
simulations are (pushes, basin stability, the certificate's falsification runs).

:class:`Runs` takes a validated configuration, one body or a tree, and gives the outcome of
each run of a batch from a given initial state, optionally with its own value of one
impulse of the configuration's disturbances (a push): whether it reached t_end inside its
admissible region, v at its start and v(t_end). The runs are a
:class:`rbstab.engine.RunBatch` (:func:`rbstab.engine.batch.batch_of` of the configuration,
one row a run) integrated by :func:`rbstab.simulator.simulate_batch` on the compiled or
CUDA engine, in slices over an executor's workers or in threads. Runs no batch takes (an
implicit method, the pure sign law) are integrated one at a time, each its configuration
with its initial state, by :func:`rbstab.simulator.simulate_many` (the scipy engine or the
sign law's event-driven integrator).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO, ROUND_OFF
from ..engine.registry import get_engine
from ..layout import AXES, VARIANT_LAYOUTS, is_chain
from .linearise import linearise_config

__all__ = ["Runs", "batch_outcomes", "batch_traces", "integrate_batch", "check_entries", "check_axes", "MIN_SLICE",
           "continued", "longer_horizon", "SETTLING_TIME_CONSTANTS", "SETTLING_CONTINUATIONS", "SETTLING_LONGEST"]

#: Fewest runs of a batch slice sent to a worker.
MIN_SLICE = 64
#: Most runs of a batch slice a thread takes: an interrupt (Ctrl-C) waits for the slices
#: running, not for the whole batch.
THREAD_SLICE = 256
#: A run still settling at t_end (not yet recovered, never above its start) is run again to
#: this many slowest time constants of the linearisation (v ~ exp(-2 t / tau): e^-16 of its
#: start), at least twice t_end ...
SETTLING_TIME_CONSTANTS = 8.0
#: ... and, still settling, to twice that, at most this many times in all ...
SETTLING_CONTINUATIONS = 3
#: ... and never beyond this many times t_end.
SETTLING_LONGEST = 16.0
#: Most samples of a run continued past its t_end (the configured spacing kept up to this).
_CONTINUED_SAMPLES = 200_001


def longer_horizon(t_end: float, horizon: float, k: int, tau: float,
                   time_constants: float = SETTLING_TIME_CONSTANTS) -> float:
    """The t_end [s] of the k-th continuation (k = 0, 1, ...) of a run of ``t_end`` still
    settling at ``horizon``: ``time_constants`` x ``tau`` (the slowest time constant [s];
    NaN: unknown) and at least 2 t_end first, then twice ``horizon``, never beyond
    SETTLING_LONGEST x t_end."""
    first = max(2.0 * t_end, time_constants * tau if math.isfinite(tau) else 0.0)
    return min(SETTLING_LONGEST * t_end, 2.0 * horizon if k else first)


def continued(config, t_end: float):
    """``config`` (a RunConfig) run to ``t_end`` [s]: its sample spacing and
    its step limit per second kept (up to :data:`_CONTINUED_SAMPLES` samples and
    :data:`rbstab.config.schema.MAX_STEPS_LIMIT` steps)."""
    from ..config.schema import MAX_STEPS_LIMIT  # heavy: pydantic

    sim = config.simulation
    scale = t_end / float(sim.t_end)
    samples = min(max(int(sim.n_samples), _CONTINUED_SAMPLES), math.ceil((int(sim.n_samples) - 1) * scale) + 1)
    steps = min(MAX_STEPS_LIMIT, math.ceil(int(sim.max_steps) * scale))
    return replace(config, simulation=replace(sim, t_end=float(t_end), n_samples=samples, max_steps=steps))


def batch_outcomes(batch, engine: str) -> np.ndarray:
    """The outcomes of the k runs of ``batch`` (a :class:`rbstab.engine.RunBatch`) on
    ``engine`` as one array of shape (3, k): success (1: status ``success``, else 0), v(0)
    [J] and v(t_end) [J] (NaN for a run that stopped early). The function a worker runs."""
    from ..simulator import simulate_batch  # heavy: numba

    out = np.full((3, len(batch)), np.nan)
    for rows, block in simulate_batch(batch, full=False, engine=engine, keep="none"):
        out[0, rows] = [s == "success" for s in block.status]
        out[1, rows] = block.summaries["lyapunov_initial"]
        out[2, rows] = np.where(out[0, rows] == 1, block.summaries["lyapunov_final"], np.nan)  # not its last sample
    return out


def integrate_batch(batch, engine: str, executor=None, jobs: int = 1) -> np.ndarray:
    """:func:`batch_outcomes` of a batch, in slices of at least :data:`MIN_SLICE` runs
    over ``executor``'s workers, or where there is none over ``jobs`` threads
    (:func:`_in_threads`; the compiled driver releases Python's lock)."""
    if executor is None:
        if jobs <= 1 or len(batch) < 2:
            return batch_outcomes(batch, engine)
        out = np.full((3, len(batch)), np.nan)
        for rows, result in _in_threads(lambda rows: batch_outcomes(batch.take(rows), engine), len(batch), jobs):
            out[:, rows] = result
        return out
    workers = executor.parallelism() or 1
    if workers <= 1 or len(batch) < 2 * MIN_SLICE:
        return batch_outcomes(batch, engine)
    size = max(MIN_SLICE, -(-len(batch) // workers))
    slices = [np.arange(lo, min(lo + size, len(batch))) for lo in range(0, len(batch), size)]
    out = np.full((3, len(batch)), np.nan)
    executor.plan(len(slices))
    parts = ((rows, batch.take(rows)) for rows in slices)
    for (rows, _), result, exc in executor.imap_unordered(_integrate_slice, parts, engine):
        if exc is not None:
            raise exc
        out[:, rows] = result
    return out


def _in_threads(function, k: int, jobs: int) -> list:
    """``(rows, function(rows))`` of k runs in order: ``rows`` slices of at most
    :data:`THREAD_SLICE` runs (``jobs`` of them at least), ``function`` of them in ``jobs``
    threads. An interrupt (Ctrl-C) cancels the slices not started and waits for those
    running."""
    slices = np.array_split(np.arange(k), max(min(jobs, k), -(-k // THREAD_SLICE)))
    pool = ThreadPoolExecutor(min(jobs, len(slices)))
    try:
        return list(zip(slices, pool.map(function, slices)))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _integrate_slice(item, engine: str):
    """:func:`batch_outcomes` of an executor's item (rows, batch)."""
    return batch_outcomes(item[1], engine)


def batch_traces(batch, engine: str = "compiled") -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(whether each run of ``batch`` (a :class:`rbstab.engine.RunBatch`, one sample count)
    reached t_end (k,), its v [J] at every sample (k, n_samples; NaN after a stop), why each
    failed run stopped ('' for the others: its status message without its time)). The
    function a worker runs."""
    from ..simulator import simulate_batch  # heavy: numba

    k = len(batch)
    ok, v, messages = np.zeros(k, dtype=bool), np.full((k, int(batch.n_samples[0])), np.nan), [""] * k
    for rows, block in simulate_batch(batch, full=False, engine=engine, keep="all"):
        for j, i in enumerate(rows):
            ok[i] = block.status[j] == "success"
            messages[i] = "" if ok[i] else block.message[j].split(" at t =")[0]
        v[rows] = block.outputs["lyapunov"]
    return ok, v, messages


def _trace_slice(item, engine: str):
    """:func:`batch_traces` of an executor's item (rows, batch)."""
    return batch_traces(item[1], engine)


class Runs:
    """Batches of runs of one configuration from chosen initial states (module docstring).

    Parameters
    ----------
    config : RunConfig
        Validated: its bodies, laws, gains, disturbances, admissible region and settings.
    engine : {"compiled", "cuda"}
        The engine of the runs (:func:`rbstab.simulator.simulate_batch`).
    executor : rbstab.sweep.executors.Executor, optional
        Takes the batches in slices (None: this process).
    jobs : int
        Without an executor, the threads that integrate a batch's slices on the CPU (the
        compiled driver releases Python's lock).

    Attributes
    ----------
    initial_state : ndarray, shape (n_states,)
        The configured initial state, the tree's full state (Theta, Omega, X, V of each
        body, then each embedded joint's D; :mod:`rbstab.variants.chain`; one body's, its
        one-body tree's), the bodies permanent joints hold placed on them. Every state the
        methods take is such a full state.
    engine : str
        The engine the runs take.

    A batch needs an explicit method and no pure sign law (``boundary_layer`` 0); other
    runs are integrated one at a time (module docstring).
    """

    def __init__(self, config, *, engine: str = "compiled", executor=None, jobs: int = 1) -> None:
        from ..engine.batch import batch_of  # heavy: numba

        # one GPU takes a batch in one process, from one thread
        self.config, self.engine, self.executor = config, engine, executor
        self.jobs = 1 if get_engine(engine).gpu else max(1, int(jobs))
        self.continued_runs, self.continued_to = 0, 0.0  # runs :meth:`recoveries` continued, and how far [s]
        self._tau: float | None = None  # the slowest time constant [s], once a run needs it
        self._longer: dict[float, Runs] = {}  # the runs of each longer t_end, built once
        self.base = batch_of([config])
        from ..variants import chain as C  # heavy: numba

        size = self.base.trees[0].size  # the compiled tree (one body's: its one-body tree)
        self.compiled = C.with_records(self.base.trees[0], self.base.params[0, :size], self.base.ppoints[0, :size],
                                       self.base.offset[0])
        # a run's state in the batch: one body's in its variant's layout, the full state's first entries
        self._n_state = int(self.base.n_state[0])
        full = np.zeros(self.compiled.n_states)
        full[: self._n_state] = self.base.y0[0, : self._n_state]
        self.initial_state = C.place(self.compiled, full, self.compiled.permanent, self.compiled.permanent)

    def _rows(self, states) -> np.ndarray:
        """``states`` as a stack (k, n_states) of full states; ValueError for another width."""
        states = np.asarray(states, dtype=float)
        states = states[None] if states.ndim == 1 else states
        if states.ndim != 2 or states.shape[1] != len(self.initial_state):
            raise ValueError(f"states: found shape {states.shape}; expected (k, {len(self.initial_state)}), full "
                             "states of the configuration's tree")
        return states

    def _batch(self, states: np.ndarray, n_samples: int):
        """The base run from each of the full states ``states`` (k, n_states), sampled
        ``n_samples`` times (one body's run from the state's first entries, its variant's
        layout: Theta, Omega[, X, V][, D])."""
        batch = self.base.take(np.zeros(len(states), dtype=np.int64))
        batch.y0[:, : self._n_state] = states[:, : self._n_state]
        batch.n_samples[:] = n_samples
        return batch

    def outcomes(self, states: np.ndarray, disturbance: tuple | None = None) -> np.ndarray:
        """The outcomes of the runs from ``states`` (k, n_states), shape (3, k): success (1:
        t_end reached inside the admissible region, else 0), v at the start [J] and
        v(t_end) [J] (NaN for a run that stopped early). ``disturbance`` = (body, entry,
        values (k, 3)): each run's value of the configuration's disturbance ``entry`` (its
        index among body ``body``'s, in the order listed; one body: body 0) instead of the
        configured one. One batch, its runs sampled twice (a run's steps do not depend on
        its samples)."""
        states = self._rows(states)
        if len(states) == 0:
            return np.zeros((3, 0))
        if not self.base.compiled[0]:  # an implicit method, the pure sign law: run by run
            ok, v, _ = self._one_by_one(states, 2, disturbance)
            return np.array([ok.astype(float), v[:, 0], v[:, -1]])
        batch = self._batch(states, 2)
        if disturbance is not None:
            body, entry, values = disturbance
            batch.params["disturbance_value"][:, body, entry] = values
        return integrate_batch(batch, self.engine, self.executor, self.jobs)

    def recoveries(self, states: np.ndarray, rule, start: np.ndarray | None = None,
                   disturbance: tuple | None = None, ratio: float = DEFAULT_LYAPUNOV_RATIO
                   ) -> tuple[np.ndarray, np.ndarray]:
        """(whether each run from ``states`` (k, n_states) recovers, v at its start [J]), each
        shape (k,): ``rule(ok, v0, v1, rows)`` of its :meth:`outcomes` (``rows`` the runs'
        indices into ``states``; a bool array), a run still settling at t_end judged at a
        longer t_end. Still settling: it reached t_end, did not recover by ``rule`` and ended
        with v between 0 and ``start`` (k,) [J], its v just after the perturbation (default:
        v at its start). Such runs are run again to
        :func:`longer_horizon`, at most :data:`SETTLING_CONTINUATIONS` times: first to 1.5 times
        the time the slowest mode takes to bring v down by ``ratio`` (v ~ exp(-2 t / tau),
        tau the linearisation's slowest time constant, found when first needed): t_end bounds
        what a run can show of convergence, not whether it recovers. ``disturbance`` as
        :meth:`outcomes` takes it."""
        states = self._rows(states)
        ok, v0, v1 = self.outcomes(states, disturbance)
        first = v0
        start = v0 if start is None else np.asarray(start, dtype=float)
        rows = np.arange(len(states))
        recovered = np.asarray(rule(ok, v0, v1, rows), dtype=bool).copy()
        t_end = horizon = float(self.config.simulation.t_end)
        for k in range(SETTLING_CONTINUATIONS):
            slack = ROUND_OFF * np.maximum(np.abs(start[rows]), 1.0)
            with np.errstate(invalid="ignore"):  # on its way down to v = 0: v in [0, its start]
                settling = (ok == 1) & np.isfinite(v1) & ~recovered[rows] & (v1 >= -slack) & (v1 <= start[rows] + slack)
            rows = rows[settling]
            if not len(rows):
                break
            if self._tau is None:
                self._tau = self._slowest_time_constant()
            longer = longer_horizon(t_end, horizon, k, self._tau, 1.5 * math.log(1.0 / ratio) / 2.0)
            if longer <= horizon:
                break
            horizon = longer
            if horizon not in self._longer:
                self._longer[horizon] = Runs(continued(self.config, horizon), engine=self.engine,
                                             executor=self.executor, jobs=self.jobs)
            runs = self._longer[horizon]
            self.continued_runs += len(rows) if k == 0 else 0
            self.continued_to = max(self.continued_to, horizon)
            values = None if disturbance is None else (*disturbance[:2], np.asarray(disturbance[2])[rows])
            ok, v0, v1 = runs.outcomes(states[rows], values)
            recovered[rows] = rule(ok, v0, v1, rows)
        return recovered, first

    def _slowest_time_constant(self) -> float:
        """The slowest time constant [s] of the configuration's linearisation at rest
        (:func:`rbstab.analysis.linearise.linearise_config`), NaN where it has none."""
        try:
            return float(linearise_config(self.config).slowest_time_constant)
        except ValueError:
            return math.nan

    def states(self, axes, values: np.ndarray) -> np.ndarray:
        """The initial states (N, n_states) with the entries of ``axes``
        (:class:`rbstab.analysis.basin.BasinAxis` or what has its ``key``, ``block``,
        ``index``, ``body``) set to the rows of ``values`` (N, len(axes)), the others the
        configured ones; a tree's bodies whose ``x`` (``v``) the configuration leaves out
        placed on their joints (:func:`rbstab.variants.chain.place`).

        Raises
        ------
        ValueError
            One line, for an entry the state lacks (a tree's body or D it does not have).
        """
        from ..variants import chain as C  # heavy: numba

        values = np.asarray(values, dtype=float).reshape(-1, len(axes))
        if self.compiled.hinged:  # the hinges' q, u set in the reduced state: a hinge turns what it carries
            from ..variants.tree import expand_samples, reduce_state, tree_layout  # heavy: numba

            layout = tree_layout(self.compiled)
            reduced = np.repeat(reduce_state(self.compiled, layout, self.initial_state)[None], len(values), axis=0)
            for j, axis in enumerate(axes):
                reduced[:, _reduced_offset(self.compiled, axis)] = values[:, j]
            params, codes, parents, ppoints, d_at = self.compiled.args
            states = np.empty((1, len(values), self.compiled.n_states))
            expand_samples(reduced[None], params[None], codes, parents, ppoints[None], d_at, *layout.args, states,
                           np.zeros(1, np.int64))
            return states[0]
        names = list(self.compiled.chain.body_names)
        placed = self.compiled.permanent  # a permanent joint's child always, the bodies the configuration places
        x_placed = placed | np.array([f"initial_state.{b}.x" in self.config.placed for b in names])
        v_placed = placed | np.array([f"initial_state.{b}.v" in self.config.placed for b in names])
        states = np.repeat(self.initial_state[None], len(values), axis=0)
        for j, axis in enumerate(axes):
            states[:, _state_offset(self.compiled, axis)] = values[:, j]
        return C.place(self.compiled, states, x_placed, v_placed)

    def lyapunov(self, states: np.ndarray) -> np.ndarray:
        """v [J] at t = 0 of each of ``states`` (N, n_states)."""
        from ..variants import chain as C  # heavy: numba

        return C.evaluate(self.compiled, np.zeros(len(states)), states)["lyapunov"]

    def traces(self, states: np.ndarray, n_samples: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """The runs from ``states`` (k, n_states) sampled ``n_samples`` times on [0, t_end]:
        (whether each reached t_end inside its admissible region (k,), v [J] at its samples
        (k, n_samples; NaN after a stop), why each failed run stopped: its status in words,
        without the time ('' for the others)), in slices over the executor's workers or
        :attr:`jobs` threads."""
        states = self._rows(states)
        k, n_samples = len(states), int(n_samples)
        if not self.base.compiled[0]:  # an implicit method, the pure sign law: run by run
            return self._one_by_one(states, n_samples)
        batch = self._batch(states, n_samples)
        workers = (self.executor.parallelism() or 1) if self.executor is not None else self.jobs
        if workers <= 1 or k < (2 * MIN_SLICE if self.executor is not None else 2):
            return batch_traces(batch, self.engine)
        ok, v, messages = np.zeros(k, dtype=bool), np.full((k, n_samples), np.nan), [""] * k
        if self.executor is None:
            done = [((rows, None), result, None) for rows, result in
                    _in_threads(lambda rows: batch_traces(batch.take(rows), self.engine), k, workers)]
        else:
            size = max(MIN_SLICE, -(-k // (4 * workers)))  # 4 slices a worker: every worker busy to the end
            slices = [np.arange(lo, min(lo + size, k)) for lo in range(0, k, size)]
            self.executor.plan(len(slices))
            done = self.executor.imap_unordered(_trace_slice, ((r, batch.take(r)) for r in slices), self.engine)
        for (rows, _), result, exc in done:
            if exc is not None:  # a worker that died: its runs failed, with the reason
                result = (np.zeros(len(rows), dtype=bool), np.full((len(rows), n_samples), np.nan),
                          [f"worker error: {exc}"] * len(rows))
            ok[rows], v[rows] = result[0], result[1]
            for j, i in enumerate(rows.tolist()):
                messages[i] = result[2][j]
        return ok, v, messages

    def streamed(self, states: np.ndarray, n_samples: int, ratio: float) -> tuple:
        """The runs from ``states`` (k, n_states) sampled ``n_samples`` times on [0, t_end] on
        the GPU engine, each run's samples streamed into its summary and none brought back
        (:func:`rbstab.engine.cuda.integrate_chain_runs_cuda`; a launch's limit
        ``simulation.max_wall_time``): (whether each reached t_end inside its admissible
        region (k,), the index of its last sample not converged
        (:func:`rbstab.convergence.converged` with v(0) and ``ratio``; -1: none) (k,), v(t_end)
        [J] (k,; NaN for a run that stopped early), why each failed run stopped: its status in
        words, without the time ('' for the others))."""
        from ..engine.cuda import integrate_chain_runs_cuda  # heavy: numba-cuda
        from ..engine.status import SUCCESS  # heavy: numba
        from ..engine.systems import tree_system, with_offsets  # heavy: numba
        from ..simulator import run_end  # heavy: numba
        from ..summary import LAST_ABOVE, TAKEN, streamed_final_lyapunov  # heavy: numba

        states = self._rows(states)
        k, n, s = len(states), int(n_samples), self.config.simulation
        batch = self._batch(states, n)
        bounds, settings, size = batch.params[0, 0]["limits"], batch.settings_rows(), self.compiled.size
        system = tree_system(self.compiled)._replace(params=batch.params[0, :size], ppoints=batch.ppoints[0, :size])
        sol = integrate_chain_runs_cuda(with_offsets(system, batch.offset[0]), batch.y0[:, : self._n_state], settings,
                                        method=s.method,
                                        n_samples=n, stride=None, max_wall_time=s.max_wall_time, ratio=ratio)
        ok = sol.status == SUCCESS
        v_final = np.where(sol.acc[:, TAKEN] == n, streamed_final_lyapunov(sol.acc), np.nan)  # NaN: stopped early
        messages = [""] * k
        for i in np.flatnonzero(~ok).tolist():  # failed runs: few
            code, t = int(sol.status[i]), float(sol.t_stop[i])
            messages[i] = run_end(self.compiled, code, t, settings[i], bounds, self.base.one_body[0]).split(" at t =")[0]
        return ok, sol.acc[:, LAST_ABOVE].astype(np.int64), v_final, messages

    def _one_by_one(self, states: np.ndarray, n_samples: int,
                    disturbance: tuple | None = None) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """:meth:`traces` of runs that no batch takes (an implicit method, the pure sign
        law), each the validated configuration with its initial state (and ``disturbance``'s
        value, as :meth:`outcomes` takes it) through :func:`rbstab.simulator.simulate_many`."""
        from ..simulator import simulate_many  # heavy: numba

        k = len(states)
        values = np.broadcast_to(np.asarray(disturbance[2], dtype=float), (k, 3)) if disturbance else None
        simulation = replace(self.config.simulation, n_samples=n_samples)
        configs = [self._config_at(y, simulation, None if values is None else (*disturbance[:2], values[i]))
                   for i, y in enumerate(states)]
        ok, v, messages = np.zeros(k, dtype=bool), np.full((k, n_samples), np.nan), [""] * k
        for i, result in simulate_many(configs, engine="compiled", full=False):
            ok[i] = result.ok
            v[i] = result.outputs["lyapunov"]
            messages[i] = "" if result.ok else result.message.split(" at t =")[0]
        return ok, v, messages

    def _config_at(self, y: np.ndarray, simulation, disturbance: tuple | None):
        """The configuration of the run from the full state ``y`` (n_states,) with the
        settings ``simulation``; with ``disturbance`` = (body, entry, value (3,)), that entry
        of that body's disturbances (one body: body 0) of that value."""
        def pushed(entries):
            return tuple(replace(d, value=np.array(disturbance[2], dtype=float)) if j == disturbance[1] else d
                         for j, d in enumerate(entries))

        chain, d_at = self.config.chain, self.compiled.d_at
        initial = {}
        for i, body in enumerate(chain.bodies):
            state = {block: y[12 * i + 3 * k: 12 * i + 3 * k + 3].copy() for k, block in enumerate(_BODY_BLOCKS)}
            if d_at[i] >= 0:
                state["controller_state"] = y[d_at[i]: d_at[i] + 3].copy()
            initial[body.name] = {**self.config.initial_state[body.name], **state}
        if disturbance is not None:
            bodies = list(chain.bodies)
            bodies[disturbance[0]] = replace(bodies[disturbance[0]], disturbances=pushed(bodies[disturbance[0]].disturbances))
            chain = replace(chain, bodies=tuple(bodies))
        return replace(self.config, chain=chain, initial_state=initial, simulation=simulation)


#: The state blocks of a body in a tree's maximal state, in order (12 entries a body).
_BODY_BLOCKS = ("theta", "omega", "position", "velocity")
#: Each block's first entry in its body's 12.
_BODY_OFFSET = {block: 3 * k for k, block in enumerate(_BODY_BLOCKS)}


def _reduced_offset(compiled, axis) -> int:
    """The index in a tree's reduced state (:func:`rbstab.variants.tree.tree_layout`) of a
    hinge's or a slide's child's q or u (a universal joint's child's q_i or u_i, entry i of
    the key), or of a quaternion ball's child's Omega_j entry i (``omega.<i>``: its angular
    velocity relative to its parent, child frame), that ``axis`` names; ValueError naming
    what is allowed where the body is not such a child, or where ``axis`` names another
    entry of a tree with such joints."""
    from ..variants.tree import tree_layout  # heavy: numba

    names = list(compiled.chain.body_names)
    hinged = [b for b, code in zip(names, compiled.codes) if AXES[code] > 0]
    balls = [b for b, joint in zip(names, compiled.chain.joints) if joint.variant == "ball"]
    allowed = ", ".join(([f"initial_state.<{'|'.join(hinged)}>.<q|u>"] if hinged else [])
                        + ([f"initial_state.<{'|'.join(balls)}>.omega.<0|1|2>"] if balls else []))
    if axis.block == "omega" and axis.body in balls and axis.index is not None:
        return int(tree_layout(compiled).r_at[names.index(axis.body)]) + 4 + axis.index
    if axis.block not in ("q", "u"):
        raise ValueError(f"--basin {axis.key!r}: a tree of joints on coordinates maps its basin over its hinges', "
                         f"slides' and universal joints' q and u and its balls' Omega_j ({allowed})")
    if axis.body not in hinged:
        raise ValueError(f"--basin {axis.key!r}: '{axis.body}' is not a hinge's, a slide's or a universal joint's "
                         f"child (keys {allowed})")
    i = names.index(axis.body)
    m = int(AXES[compiled.codes[i]])
    index = axis.index or 0
    if index >= m:
        raise ValueError(f"--basin {axis.key!r}: '{axis.body}' has {m} joint angle{'s' if m > 1 else ''}; "
                         f"keys {allowed}" + (".0 or .1" if m > 1 else ""))
    return int(tree_layout(compiled).r_at[i]) + (0 if axis.block == "q" else m) + index


def _state_offset(compiled, axis) -> int:
    """The index in a tree's maximal state of the entry ``axis`` names (``key``, ``body``,
    ``block``, ``index``); ValueError naming what is allowed where it names no body of the
    tree or a D its joint does not have (a tree with a hinge: :func:`_reduced_offset`)."""
    if compiled.hinged:
        return _reduced_offset(compiled, axis)
    names = list(compiled.chain.body_names)
    if axis.body is None and len(names) == 1:  # one body's key, initial_state.<block>.<i>
        return _BODY_OFFSET[axis.block] + axis.index if axis.block != "controller_state" else \
            int(compiled.d_at[0]) + axis.index
    if axis.body not in names:
        raise ValueError(f"--basin {axis.key!r}: no body '{axis.body}' in this chain (its bodies: {', '.join(names)}; "
                         "keys initial_state.<body>.<theta|omega|x|v|d>.<0|1|2>)")
    i = names.index(axis.body)
    if axis.block == "controller_state":
        if compiled.d_at[i] < 0:
            raise ValueError(f"--basin {axis.key!r}: the joint of '{axis.body}' is not embedded (no D)")
        return int(compiled.d_at[i]) + axis.index
    return 12 * i + _BODY_OFFSET[axis.block] + axis.index


def check_entries(config, axes) -> None:
    """ValueError (one line) where an axis (:class:`rbstab.analysis.basin.BasinAxis`) names
    no entry of ``config``'s state: one body's keys ``initial_state.<block>.<i>`` of a
    block its variant has, a tree's ``initial_state.<body>.<block>.<i>`` of a body it has
    (D of an embedded joint's child)."""
    if is_chain(config):
        from ..variants import chain as C  # heavy: numba

        compiled = C.compile_chain(config.chain, offset=0.0)
        for axis in axes:
            _state_offset(compiled, axis)
        return
    from ..config import INITIAL_STATE_BLOCKS  # heavy: pydantic

    blocks = VARIANT_LAYOUTS[config.chain.joints[0].variant].blocks
    for axis in axes:
        if axis.body is not None:
            raise ValueError(f"--basin {axis.key!r}: names a body of a chain ('{axis.body}'); a one-body config's "
                             "entries are initial_state.<block>.<i>")
        if axis.block not in blocks:
            states = ", ".join(k for k, b in INITIAL_STATE_BLOCKS.items() if b in blocks)
            raise ValueError(f"--basin {axis.key!r}: '{axis.key.rsplit('.', 1)[0]}' is not a state of this variant "
                             f"(its states: {states})")


def check_axes(config, axes) -> None:
    """ValueError (one line) where the basin map's axes are not two, are the same entry or
    one names no entry of ``config``'s state (:func:`check_entries`)."""
    if len(axes) != 2 or axes[0].key == axes[1].key:
        raise ValueError(f"--basin: expected two different keys, found {[a.key for a in axes]}")
    check_entries(config, axes)
