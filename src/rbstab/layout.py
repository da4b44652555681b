"""State layouts: the one place that says where each state block lives in ``y``.

Every state block is a 3-vector. A layout is an ordered tuple of block names; the
integrators, writers and variants address the state only through a layout, in the
stacked-rows form (``split``, ``join``: blocks along the last axis) or, inside the
variants' right-hand side, the columns form of :mod:`rbstab.kinematics`
(``split_columns``, ``join_columns``: a state as the sequence of its components).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "StateLayout",
    "BLOCK_UNITS",
    "BLOCK_DESCRIPTIONS",
    "LYAPUNOV_TERMS",
    "OUTPUT_VECTORS",
    "OUTPUT_SCALARS",
    "N_OUTPUTS",
    "LEFT_OUT",
    "OUTPUT_UNITS",
    "OUTPUT_DESCRIPTIONS",
]

#: Units of each state block (also the HDF5 ``units`` attribute).
BLOCK_UNITS = {
    "theta": "rad",
    "omega": "rad s-1",
    "position": "m",
    "velocity": "m s-1",
    "controller_state": "m",
}

#: Description of each state block (also the HDF5 ``description`` attribute).
BLOCK_DESCRIPTIONS = {
    "theta": "Euler angles Theta, A = Rx(t1) Ry(t2) Rz(t3) (eq 2)",
    "omega": "angular velocity Omega in the body frame (eq 1)",
    "position": "centre-of-mass position X in the inertial frame (eq 1)",
    "velocity": "centre-of-mass velocity V in the inertial frame (eq 1)",
    "controller_state": "embedded controller state D in the inertial frame (eq 22)",
}


# -- the outputs of a run (rbstab.variants computes them; files and readers name them) --------
#: Names of the terms of v, in the order they are summed.
LYAPUNOV_TERMS = (
    "lyapunov_translational",
    "lyapunov_rotational",
    "lyapunov_constraint",
    "lyapunov_gravity",
)

#: The vector outputs of the compiled ``outputs`` kernel, 3 columns each, in order.
OUTPUT_VECTORS = (
    "theta",
    "omega",
    "position",
    "velocity",
    "controller_state",
    "constraint_error",
    "constraint_rate",
    "constraint_force",
    "force_h",
    "torque_n",
)
#: The outputs that neither the summary figures nor a ``thinned`` store read: left out of
#: the outputs of a sweep that stores no more (``full`` False in
#: :func:`rbstab.variants.kernels.run_outputs`).
LEFT_OUT = ("constraint_rate", "constraint_force", "force_h", "torque_n")
#: The scalar outputs after the vectors, one column each, in order.
OUTPUT_SCALARS = (*LYAPUNOV_TERMS, "lyapunov", "lyapunov_rate")
#: Columns of one row of outputs.
N_OUTPUTS = 3 * len(OUTPUT_VECTORS) + len(OUTPUT_SCALARS)

#: Units of every output quantity other than the state blocks.
OUTPUT_UNITS = {
    "constraint_error": "m",
    "constraint_rate": "m s-1",
    "constraint_force": "N",
    "force_h": "N",
    "torque_n": "N m",
    "lyapunov": "J",
    "lyapunov_rate": "W",
    "lyapunov_translational": "J",
    "lyapunov_rotational": "J",
    "lyapunov_constraint": "J",
    "lyapunov_gravity": "J",
}

#: Descriptions of every output quantity other than the state blocks.
OUTPUT_DESCRIPTIONS = {
    "constraint_error": "E = X + A R - R, displacement of the point C, inertial frame (eq 4)",
    "constraint_rate": "F = dE/dt = V - A hat(R) Omega, velocity of C, inertial frame (eq 4)",
    "constraint_force": "Lambda, force applied at C, inertial frame (eqs 20, 22, 39, 40)",
    "force_h": "H = -K_t X - L_t V, translational feedback, inertial frame (eq 24)",
    "torque_n": "N = -B' K_r Theta - L_r Omega, rotational feedback, body frame (eq 23)",
    "lyapunov": "Lyapunov function v, the sum of the lyapunov_* terms (eqs 28-46)",
    "lyapunov_rate": "analytic dv/dt (eqs 29, 37, 43, 46)",
    "lyapunov_translational": "v_t = V'MV/2 + X'K_t X/2 (eq 25)",
    "lyapunov_rotational": "v_r = Omega'J Omega/2 + Theta'K_r Theta/2 (eq 25)",
    "lyapunov_constraint": "energy stored in the constraint controller (eqs 41, 44; "
    "K_s |E|_1 or its boundary-layer smoothing for sliding; 0 for free and permanent)",
    "lyapunov_gravity": "-X'G plus the constant h that makes v zero at the equilibrium (eq 30)",
}


@dataclass(frozen=True)
class StateLayout:
    """Ordered 3-vector blocks of a state vector.

    Parameters
    ----------
    blocks : tuple of str
        Block names, each a key of :data:`BLOCK_UNITS`.
    """

    blocks: tuple[str, ...]

    def __post_init__(self) -> None:
        unknown = [b for b in self.blocks if b not in BLOCK_UNITS]
        if unknown:
            raise ValueError(f"unknown state blocks {unknown}")

    @property
    def size(self) -> int:
        """Number of scalar states."""
        return 3 * len(self.blocks)

    def slice(self, block: str) -> slice:
        """Slice of ``block`` in the last axis of a state array."""
        i = self.blocks.index(block)
        return slice(3 * i, 3 * i + 3)

    def split(self, y: np.ndarray) -> dict[str, np.ndarray]:
        """Views of each block: y shape (..., size) -> {name: shape (..., 3)}."""
        return {b: y[..., 3 * i : 3 * i + 3] for i, b in enumerate(self.blocks)}

    def join(self, **blocks: np.ndarray) -> np.ndarray:
        """Concatenate blocks (each shape (..., 3)) into shape (..., size), in layout order.

        Raises
        ------
        KeyError
            If a block of the layout is missing.
        """
        return np.concatenate([np.asarray(blocks[b], dtype=float) for b in self.blocks], axis=-1)

    def split_columns(self, y) -> dict:
        """Each block of a state in columns form (:mod:`rbstab.kinematics`): ``y`` a list
        of ``size`` floats (one state) -> {name: tuple of its 3 floats}; ``y`` an (size,
        m) array (a stack) -> {name: (3, m) view}."""
        if isinstance(y, np.ndarray):
            return {b: y[3 * i : 3 * i + 3] for i, b in enumerate(self.blocks)}
        return {b: tuple(y[3 * i : 3 * i + 3]) for i, b in enumerate(self.blocks)}

    def join_columns(self, **blocks):
        """A state in columns form, in layout order, from its blocks (vectors in columns
        form): an (size, m) array when every block is a (3, m) array, else the list of
        the ``size`` components; :func:`rbstab.kinematics.from_columns` makes stacked
        rows of either.

        Raises
        ------
        KeyError
            If a block of the layout is missing.
        """
        parts = [blocks[b] for b in self.blocks]
        if all(isinstance(p, np.ndarray) and p.ndim == 2 for p in parts):
            return np.concatenate(parts)
        return [c for p in parts for c in p]

    def state_names(self) -> list[str]:
        """Scalar state names such as ``theta_1`` ... in layout order."""
        return [f"{b}_{k}" for b in self.blocks for k in (1, 2, 3)]


FULL_BODY = StateLayout(("theta", "omega", "position", "velocity"))
EMBEDDED = StateLayout(("theta", "omega", "position", "velocity", "controller_state"))
REDUCED = StateLayout(("theta", "omega"))
