"""A chain's initial states with chosen entries (:func:`chain_states`: the configured
initial state with entries set, the bodies the configuration places placed on their
joints) and the check of the entries' keys (:func:`check_entries`): what the chain's basin
map and basin stability run from (:class:`rbstab.analysis.runs.Runs`)."""

from __future__ import annotations

import numpy as np

__all__ = ["chain_states", "check_entries"]

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


def check_entries(config, axes) -> None:
    """ValueError (one line) where an axis (:class:`rbstab.analysis.basin.BasinAxis`) names no entry of the
    chain's state (keys ``initial_state.<body>.<block>.<i>``)."""
    from ..variants import chain as C  # heavy: numba

    compiled = C.compile_chain(config.chain, offset=0.0)
    for axis in axes:
        _state_offset(compiled, axis)
