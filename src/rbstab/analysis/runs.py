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

import dataclasses
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["Runs", "batch_outcomes", "integrate_batch", "MIN_SLICE"]

#: Fewest runs of a batch slice sent to a worker.
MIN_SLICE = 64


def _take(batch, rows: np.ndarray):
    """The runs ``rows`` of a :class:`rbstab.engine.RunBatch` as a batch of their own."""
    return type(batch)(**{f.name: getattr(batch, f.name)[rows] for f in dataclasses.fields(batch)})


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
    parts = ((rows, _take(batch, rows)) for rows in slices)
    for (rows, _), result, exc in executor.imap_unordered(_integrate_slice, parts, engine):
        if exc is not None:
            raise exc
        out[:, rows] = result
    return out


def _integrate_slice(item, engine: str):
    """:func:`batch_outcomes` of an executor's item (rows, batch)."""
    return batch_outcomes(item[1], engine)


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

    Raises
    ------
    ValueError
        For one body's pure sign law (``boundary_layer`` 0), which runs one at a time.
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
        if not variant.smooth:
            raise ValueError(f"{config.name}: the pure sign law (controller.boundary_layer 0) runs one at a time; "
                             "analyse a boundary-layer law (--boundary-layer PHI)")
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
            batch = _take(self.base, np.zeros(k, dtype=np.int64))
            batch.y0[:, :states.shape[1]] = states
            if disturbance is not None:
                batch.params["disturbance_value"][:, disturbance[1], :] = disturbance[2]
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

        slices = np.array_split(np.arange(k), max(1, min(self.jobs, k)))
        with ThreadPoolExecutor(len(slices)) as pool:
            parts = list(pool.map(final, slices))
        out = np.empty((3, k))
        out[0] = np.concatenate([p[0] for p in parts])
        # v does not depend on the disturbances' values: the configuration's own chain gives it
        out[1] = C.evaluate(self.compiled, np.zeros(k), states)["lyapunov"]
        out[2] = C.evaluate(self.compiled, np.full(k, float(sim.t_end)), np.concatenate([p[1] for p in parts]))["lyapunov"]
        return out
