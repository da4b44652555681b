"""Runs of a chain of rigid bodies from chosen initial states on the compiled driver: the
states (:func:`chain_states`: the configured initial state with entries set, the bodies the
configuration places placed on their joints), whether the runs recover
(:func:`chain_states_recover`, :func:`final_lyapunov`) and the check of the entries' keys
(:func:`check_entries`). Used by the chain's basin map, certificate and pushes."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO, converged

__all__ = ["chain_states", "chain_states_recover", "check_entries", "final_lyapunov"]

#: The state blocks of a body in the chain's state, in order (12 entries a body).
_BODY_BLOCKS = ("theta", "omega", "position", "velocity")


def _state_offset(compiled, axis) -> int:
    """The index in the chain's state of the entry ``axis`` names; ValueError naming what
    is allowed where it names no body of the chain or a D its joint does not have."""
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


def chain_states(config, compiled, axes, values: np.ndarray) -> np.ndarray:
    """The chain's states (N, n_states): its configured initial state with the entries
    ``axes`` (:class:`rbstab.analysis.basin.BasinAxis`, keys
    ``initial_state.<body>.<block>.<i>``) set to the
    rows of ``values`` (N, len(axes)), the bodies whose ``x`` (``v``) the configuration
    leaves out placed on their joints (:func:`rbstab.variants.chain.place`)."""
    from ..variants import chain as C  # heavy: numba

    names = list(config.chain.body_names)
    x_placed = np.array([f"initial_state.{b}.x" in config.placed for b in names])
    v_placed = np.array([f"initial_state.{b}.v" in config.placed for b in names])
    values = np.asarray(values, dtype=float).reshape(-1, len(axes))
    states = np.repeat(C.initial_state(config)[None], len(values), axis=0)
    for j, axis in enumerate(axes):
        states[:, _state_offset(compiled, axis)] = values[:, j]
    if x_placed.any() or v_placed.any():
        states = np.array([C.place(compiled, y, x_placed, v_placed) for y in states])
    return states


def chain_states_recover(config, axes, values: np.ndarray, *, ratio: float = DEFAULT_LYAPUNOV_RATIO,
                         jobs: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(whether each run converges by the sweeps' rule, :func:`rbstab.convergence.converged`,
    without leaving the admissible region; v(0) [J]) of the chain's runs from the states
    :func:`chain_states` gives ``values`` (N, len(axes)), on the compiled driver in ``jobs``
    threads."""
    from ..engine.systems import tree_system  # heavy: numba
    from ..variants import chain as C  # heavy: numba

    check_entries(config, axes)
    compiled = C.compile_chain(config.chain)
    states = chain_states(config, compiled, axes, values)
    sim = config.simulation
    ok, v1 = final_lyapunov(compiled, tree_system(compiled, sim.limits), states, sim, jobs=jobs)
    v0 = C.evaluate(compiled, np.zeros(len(states)), states)["lyapunov"]
    return np.asarray(converged(ok, v0, v1, ratio), dtype=bool), v0


def final_lyapunov(compiled, system, states: np.ndarray, simulation, *, jobs: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(whether each run reached t_end inside the admissible region, v(t_end) [J], NaN for a
    run that stopped) of the runs of one chain (``compiled``, its
    :class:`~rbstab.engine.systems.TreeSystem` ``system``) from ``states`` (k, n_states)
    with the settings ``simulation``, on the compiled driver in ``jobs`` threads (it
    releases Python's lock); only the last sample is kept."""
    from ..engine.integrate import integrate_chain_runs  # heavy: numba
    from ..engine.settings import settings_rows  # heavy: numba
    from ..engine.status import SUCCESS  # heavy: numba
    from ..variants import chain as C  # heavy: numba

    settings = settings_rows([simulation])

    def final(rows):
        sol = integrate_chain_runs(system, states[rows], np.repeat(settings, len(rows), axis=0),
                                   method=simulation.method, n_samples=2)
        return sol.status == SUCCESS, sol.samples[:, -1]

    k = len(states)
    slices = np.array_split(np.arange(k), max(1, min(int(jobs), k)))
    with ThreadPoolExecutor(len(slices)) as pool:
        parts = list(pool.map(final, slices))
    ok = np.concatenate([p[0] for p in parts])
    v1 = C.evaluate(compiled, np.full(k, float(simulation.t_end)), np.concatenate([p[1] for p in parts]))["lyapunov"]
    return ok, v1


def check_entries(config, axes) -> None:
    """ValueError (one line) where an axis (:class:`rbstab.analysis.basin.BasinAxis`) names no entry of the
    chain's state (keys ``initial_state.<body>.<block>.<i>``)."""
    from ..variants import chain as C  # heavy: numba

    compiled = C.compile_chain(config.chain, offset=0.0)
    for axis in axes:
        _state_offset(compiled, axis)
