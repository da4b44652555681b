"""Runs of one configuration from chosen initial states, in batches: what the analyses'
simulations are (pushes, basin stability, the certificate's falsification runs).

:class:`Runs` takes a validated configuration, one body or a tree, and gives the outcome of
each run of a batch from a given initial state, optionally with its own value of one
impulse of the configuration's disturbances (a push): whether it reached t_end inside its
admissible region, v at its start and v(t_end). One body's runs are a
:class:`rbstab.engine.RunBatch` on the compiled or CUDA engine (in slices over an
executor's workers); a tree's, a tree a run in calls of the CPU's compiled driver
(:func:`rbstab.engine.integrate.integrate_chain_runs`, in threads).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["Runs", "batch_outcomes", "batch_traces", "integrate_batch", "check_entries", "check_axes", "MIN_SLICE"]

#: Fewest runs of a batch slice sent to a worker.
MIN_SLICE = 64


def batch_outcomes(batch, engine: str) -> np.ndarray:
    """The outcomes of the k runs of ``batch`` (a :class:`rbstab.engine.RunBatch`) on
    ``engine`` as one array of shape (3, k): success (1: status ``success``, else 0), v(0)
    [J] and v(t_end) [J] (NaN for a run that stopped early). The function a worker runs."""
    from ..simulator import simulate_batch  # heavy: numba

    out = np.full((3, len(batch)), np.nan)
    for rows, block in simulate_batch(batch, full=False, engine=engine, keep="none"):
        out[0, rows] = [s == "success" for s in block.status]
        out[1, rows] = block.summaries["lyapunov_initial"]
        out[2, rows] = block.summaries["lyapunov_final"]
    return out


def integrate_batch(batch, engine: str, executor=None) -> np.ndarray:
    """:func:`batch_outcomes` of a batch, in slices of at least :data:`MIN_SLICE` runs
    over ``executor``'s workers (None: this process)."""
    workers = (executor.parallelism() or 1) if executor is not None else 1
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
    config : RunConfig or ChainConfig
        Validated: its bodies, laws, gains, disturbances, admissible region and settings.
    engine : {"compiled", "cuda"}
        One body's engine (a tree's runs: the CPU's compiled driver).
    executor : rbstab.sweep.executors.Executor, optional
        Takes one body's batches in slices (None: this process).
    jobs : int
        Threads integrating a tree's batches (the compiled driver releases Python's lock).

    Attributes
    ----------
    initial_state : ndarray, shape (n_state,)
        The configured initial state: one body's in its variant's layout
        (:data:`rbstab.layout.VARIANT_LAYOUTS`), a tree's maximal state (Theta, Omega, X, V
        of each body, then each embedded joint's D; :mod:`rbstab.variants.chain`).
    engine : str
        The engine the runs take.

    A batch of one body's runs needs an explicit method and no pure sign law
    (``boundary_layer`` 0): :meth:`outcomes` refuses them (ValueError), :meth:`traces` runs
    them one at a time.
    """

    def __init__(self, config, *, engine: str = "compiled", executor=None, jobs: int = 1) -> None:
        self.config, self.executor, self.jobs = config, executor, max(1, int(jobs))
        self.tree = getattr(config, "chain", None)
        if self.tree is not None:
            from ..engine.systems import tree_system  # heavy: numba
            from ..variants import chain as C  # heavy: numba

            self.engine = "compiled"
            self.compiled = C.compile_chain(self.tree)
            self.system = tree_system(self.compiled, config.simulation.limits)
            self.initial_state = C.initial_state(config)
            return
        from ..engine.batch import batch_from_table  # heavy: numba

        self.engine = engine
        variant = config.make_variant()
        template = {k: v for k, v in config.resolved.items() if k != "name"}
        self.base = batch_from_table([template], [], {}, np.zeros(1, dtype=np.int32))
        self.initial_state = variant.initial_state(config.initial_state)

    def outcomes(self, states: np.ndarray, disturbance: tuple | None = None) -> np.ndarray:
        """The outcomes of the runs from ``states`` (k, n_state), shape (3, k): success (1:
        t_end reached inside the admissible region, else 0), v at the start [J] and
        v(t_end) [J] (NaN for a run that stopped early). ``disturbance`` = (body, entry,
        values (k, 3)): each run's value of the configuration's disturbance ``entry`` (its
        index among body ``body``'s, in the order listed; one body: body 0) instead of the
        configured one. One batch."""
        states = np.asarray(states, dtype=float).reshape(-1, len(self.initial_state))
        k = len(states)
        if k == 0:
            return np.zeros((3, 0))
        if self.tree is None:
            if not self.base.compiled[0]:
                raise ValueError(f"{self.config.name}: the pure sign law (controller.boundary_layer 0) or an implicit "
                                 "method runs one at a time; analyse a boundary-layer law (--boundary-layer PHI) "
                                 "with an explicit method")
            batch = self.base.take(np.zeros(k, dtype=np.int64))
            batch.y0[:, :states.shape[1]] = states
            batch.n_samples[:] = 2  # v(0) and v(t_end): two samples (a run's steps do not depend on them)
            if disturbance is not None:
                batch.params["disturbance_value"][:, 0, disturbance[1], :] = disturbance[2]
            return integrate_batch(batch, self.engine, self.executor)
        return self._tree_outcomes(states, disturbance)

    def _tree_outcomes(self, states: np.ndarray, disturbance: tuple | None) -> np.ndarray:
        from ..engine.integrate import integrate_chain_runs  # heavy: numba
        from ..engine.settings import settings_rows  # heavy: numba
        from ..engine.status import SUCCESS  # heavy: numba
        from ..variants import chain as C  # heavy: numba

        k = len(states)
        system, tree_of = self.system, None
        if disturbance is not None:  # a tree a run, with its own value
            body, entry, values = disturbance
            params = np.repeat(system.params[None], k, axis=0)
            params["disturbance_value"][:, body, entry] = values
            system = system._replace(params=params, ppoints=np.repeat(system.ppoints[None], k, axis=0))
            tree_of = np.arange(k)
        sim = self.config.simulation
        settings = settings_rows([sim])

        def final(rows):
            sol = integrate_chain_runs(system, states[rows], np.repeat(settings, len(rows), axis=0),
                                       method=sim.method, n_samples=2,
                                       tree_of=None if tree_of is None else tree_of[rows])
            return sol.status == SUCCESS, sol.samples[:, -1]

        parts = self._in_threads(final, k)
        out = np.empty((3, k))
        out[0] = np.concatenate([p[0] for p in parts])
        # v does not depend on the disturbances' values: the configuration's own chain gives it
        out[1] = C.evaluate(self.compiled, np.zeros(k), states)["lyapunov"]
        out[2] = C.evaluate(self.compiled, np.full(k, float(sim.t_end)), np.concatenate([p[1] for p in parts]))["lyapunov"]
        return out

    def states(self, axes, values: np.ndarray) -> np.ndarray:
        """The initial states (N, n_state) with the entries of ``axes``
        (:class:`rbstab.analysis.basin.BasinAxis` or what has its ``key``, ``block``,
        ``index``, ``body``) set to the rows of ``values`` (N, len(axes)), the others the
        configured ones; a tree's bodies whose ``x`` (``v``) the configuration leaves out
        placed on their joints (:func:`rbstab.variants.chain.place`).

        Raises
        ------
        ValueError
            One line, for an entry the state lacks (a tree's body or D it does not have).
        """
        values = np.asarray(values, dtype=float).reshape(-1, len(axes))
        if self.tree is not None:
            return self._tree_states(axes, values)
        blocks = list(self.config.make_variant().layout.blocks)
        states = np.repeat(self.initial_state[None], len(values), axis=0)
        for j, axis in enumerate(axes):
            states[:, 3 * blocks.index(axis.block) + axis.index] = values[:, j]
        return states

    def _tree_states(self, axes, values: np.ndarray) -> np.ndarray:
        """:meth:`states` of a tree: its maximal states with the entries set, the bodies the
        configuration places placed on their joints."""
        from ..variants import chain as C  # heavy: numba

        names = list(self.tree.body_names)
        x_placed = np.array([f"initial_state.{b}.x" in self.config.placed for b in names])
        v_placed = np.array([f"initial_state.{b}.v" in self.config.placed for b in names])
        states = np.repeat(self.initial_state[None], len(values), axis=0)
        for j, axis in enumerate(axes):
            states[:, _state_offset(self.compiled, axis)] = values[:, j]
        if x_placed.any() or v_placed.any():
            states = C.place(self.compiled, states, x_placed, v_placed)
        return states

    def lyapunov(self, states: np.ndarray) -> np.ndarray:
        """v [J] at t = 0 of each of ``states`` (N, n_state)."""
        if self.tree is not None:
            from ..variants import chain as C  # heavy: numba

            return C.evaluate(self.compiled, np.zeros(len(states)), states)["lyapunov"]
        return self.config.make_variant().lyapunov(states)

    def traces(self, states: np.ndarray, n_samples: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """The runs from ``states`` (k, n_state) sampled ``n_samples`` times on [0, t_end]:
        (whether each reached t_end inside its admissible region (k,), v [J] at its samples
        (k, n_samples; NaN after a stop), why each failed run stopped: its status in words,
        without the time ('' for the others))."""
        states = np.asarray(states, dtype=float).reshape(-1, len(self.initial_state))
        k = len(states)
        if self.tree is not None:
            return self._tree_traces(states, int(n_samples))
        if not self.base.compiled[0]:  # the pure sign law, an implicit method: run by run
            return self._one_by_one(states, int(n_samples))
        batch = self.base.take(np.zeros(k, dtype=np.int64))
        batch.y0[:, :states.shape[1]] = states
        batch.n_samples[:] = int(n_samples)
        workers = (self.executor.parallelism() or 1) if self.executor is not None else 1
        if workers <= 1 or k < 2 * MIN_SLICE:
            return batch_traces(batch, self.engine)
        size = max(MIN_SLICE, -(-k // (4 * workers)))  # 4 slices a worker: every worker busy to the end
        slices = [np.arange(lo, min(lo + size, k)) for lo in range(0, k, size)]
        ok, v, messages = np.zeros(k, dtype=bool), np.full((k, int(n_samples)), np.nan), [""] * k
        self.executor.plan(len(slices))
        for (rows, _), result, exc in self.executor.imap_unordered(_trace_slice, ((r, batch.take(r)) for r in slices),
                                                                   self.engine):
            if exc is not None:  # a worker that died: its runs failed, with the reason
                result = (np.zeros(len(rows), dtype=bool), np.full((len(rows), int(n_samples)), np.nan),
                          [f"worker error: {exc}"] * len(rows))
            ok[rows], v[rows] = result[0], result[1]
            for j, i in enumerate(rows.tolist()):
                messages[i] = result[2][j]
        return ok, v, messages

    def _one_by_one(self, states: np.ndarray, n_samples: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """:meth:`traces` of one body's runs that no batch takes, each its configuration
        (rebuilt from the validated one with its initial state) through
        :func:`rbstab.simulator.simulate_many`."""
        from ..config import INITIAL_STATE_BLOCKS, RunConfig  # heavy: pydantic
        from ..simulator import simulate_many  # heavy: numba

        layout = self.config.make_variant().layout
        resolved = dict(self.config.resolved, simulation=dict(self.config.resolved["simulation"], n_samples=n_samples))
        configs = []
        for y in states:
            blocks = layout.split(y)
            section = {key: (blocks[b].tolist() if b in blocks else list(resolved["initial_state"][key]))
                       for key, b in INITIAL_STATE_BLOCKS.items()}
            configs.append(RunConfig.from_resolved({**resolved, "initial_state": section}, like=[self.config]))
        k = len(states)
        ok, v, messages = np.zeros(k, dtype=bool), np.full((k, n_samples), np.nan), [""] * k
        for i, result in simulate_many(configs, engine="compiled"):
            ok[i] = result.ok
            v[i] = result.outputs["lyapunov"]
            messages[i] = "" if result.ok else result.message.split(" at t =")[0]
        return ok, v, messages

    def _tree_traces(self, states: np.ndarray, n_samples: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
        from ..engine.integrate import integrate_chain_runs  # heavy: numba
        from ..engine.settings import settings_rows  # heavy: numba
        from ..engine.status import SUCCESS  # heavy: numba
        from ..simulator import tree_end  # heavy: numba
        from ..variants import chain as C  # heavy: numba

        sim = self.config.simulation
        settings = settings_rows([sim])

        def run(rows):
            return integrate_chain_runs(self.system, states[rows], np.repeat(settings, len(rows), axis=0),
                                        method=sim.method, n_samples=n_samples)

        parts = self._in_threads(run, len(states))
        samples = np.concatenate([p.samples for p in parts])
        status = np.concatenate([p.status for p in parts])
        t_stop = np.concatenate([p.t_stop for p in parts])
        time = np.linspace(0.0, sim.t_end, n_samples)
        v = C.evaluate(self.compiled, np.tile(time, len(states)), samples.reshape(-1, samples.shape[2]))["lyapunov"]
        messages = ["" if code == SUCCESS else
                    tree_end(self.compiled, code, float(t_stop[k]), samples[k], states[k], settings[0],
                             np.asarray(self.system.params).reshape(-1)[0]["limits"])[1].split(" at t =")[0]
                    for k, code in enumerate(status.tolist())]
        return status == SUCCESS, v.reshape(len(states), n_samples), messages

    def _in_threads(self, run, k: int) -> list:
        """``run`` of the rows of k runs in :attr:`jobs` threads' slices, the results in order."""
        slices = np.array_split(np.arange(k), max(1, min(self.jobs, k)))
        with ThreadPoolExecutor(len(slices)) as pool:
            return list(pool.map(run, slices))


#: The state blocks of a body in a tree's maximal state, in order (12 entries a body).
_BODY_BLOCKS = ("theta", "omega", "position", "velocity")


def _state_offset(compiled, axis) -> int:
    """The index in a tree's maximal state of the entry ``axis`` names (``key``, ``body``,
    ``block``, ``index``); ValueError naming what is allowed where it names no body of the
    tree or a D its joint does not have."""
    names = list(compiled.chain.body_names)
    if axis.body not in names:
        raise ValueError(f"--basin {axis.key!r}: no body '{axis.body}' in this chain (its bodies: {', '.join(names)}; "
                         "keys initial_state.<body>.<theta|omega|x|v|d>.<0|1|2>)")
    i = names.index(axis.body)
    if axis.block == "controller_state":
        if compiled.d_at[i] < 0:
            raise ValueError(f"--basin {axis.key!r}: the joint of '{axis.body}' is not embedded (no D)")
        return int(compiled.d_at[i]) + axis.index
    return 12 * i + 3 * _BODY_BLOCKS.index(axis.block) + axis.index


def check_entries(config, axes) -> None:
    """ValueError (one line) where an axis (:class:`rbstab.analysis.basin.BasinAxis`) names
    no entry of ``config``'s state: one body's keys ``initial_state.<block>.<i>`` of a
    block its variant has, a tree's ``initial_state.<body>.<block>.<i>`` of a body it has
    (D of an embedded joint's child)."""
    if getattr(config, "chain", None) is not None:
        from ..variants import chain as C  # heavy: numba

        compiled = C.compile_chain(config.chain, offset=0.0)
        for axis in axes:
            _state_offset(compiled, axis)
        return
    from ..config import INITIAL_STATE_BLOCKS  # heavy: pydantic

    blocks = config.make_variant().layout.blocks
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
