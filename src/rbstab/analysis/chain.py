"""The analysis of a chain of rigid bodies: its rest state, the linearisation there in the
chain's independent coordinates, the eigenvalues and Lyapunov's indirect verdict
(:func:`rbstab.analysis.linearise.linearise_chain`), and v at the configured initial state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linearise import Linearisation, linearise_chain

__all__ = ["ChainAnalysis", "analyze_chain"]


@dataclass(frozen=True)
class ChainAnalysis:
    """What :func:`analyze_chain` finds.

    Attributes
    ----------
    name : str
        The run's name.
    linearisation : Linearisation
        At the rest state, in the independent coordinates (``coordinates``).
    coordinates : list of (str, str, int)
        (body name, block, index into the full state) of each 3 entries of
        ``linearisation.equilibrium`` (:func:`rbstab.variants.chain.independent_coordinates`).
    rest_state : ndarray, shape (n_states,)
        The full rest state (:func:`rbstab.variants.chain.rest_state`).
    initial_lyapunov : float
        v [J] at the configured initial state (zero at the rest state).
    """

    name: str
    linearisation: Linearisation
    coordinates: list
    rest_state: np.ndarray
    initial_lyapunov: float

    @property
    def verdict(self) -> str:
        return self.linearisation.verdict

    def as_dict(self) -> dict:
        """Plain Python (the ``--json`` form): rest state per body and block, eigenvalues as
        [re, im] [1/s], verdict, v at the initial state [J]."""
        lin = self.linearisation
        rest = {}
        for k, (body, block, _) in enumerate(self.coordinates):
            rest.setdefault(body, {})[block] = lin.equilibrium[3 * k: 3 * k + 3].tolist()
        return {"name": self.name, "verdict": lin.verdict, "rest_point": lin.is_rest_point, "rest_state": rest,
                "eigenvalues": [[float(s.real), float(s.imag)] for s in lin.eigenvalues],
                "slowest_time_constant": float(lin.slowest_time_constant),
                "initial_lyapunov": self.initial_lyapunov}

    def text(self) -> str:
        """A few lines for the terminal."""
        lin = self.linearisation
        lines = [f"{self.name}: {lin.verdict} (linearisation in {lin.equilibrium.size} independent coordinates)"]
        for k, (body, block, _) in enumerate(self.coordinates):
            if block in ("theta", "position", "controller_state"):
                block_values = lin.equilibrium[3 * k: 3 * k + 3]
                scale = max(1.0, float(np.abs(lin.equilibrium).max()))
                values = ", ".join(f"{x:.6g}" for x in np.where(np.abs(block_values) < 1e-12 * scale, 0.0, block_values))
                lines.append(f"  rest {body}.{block}: [{values}]")
        if not lin.is_rest_point:
            lines.append(f"  not a rest point to rounding: max |dz/dt| = {np.abs(lin.rest_residual).max():.3g}")
        shown = ", ".join(f"{s.real:.4g}{s.imag:+.4g}j" for s in lin.eigenvalues[:6])
        more = f" (+{lin.eigenvalues.size - 6} more)" if lin.eigenvalues.size > 6 else ""
        lines.append(f"  eigenvalues [1/s], largest real part first: {shown}{more}")
        lines.append(f"  slowest time constant {lin.slowest_time_constant:.4g} s; "
                     f"v at the initial state {self.initial_lyapunov:.6g} J")
        return "\n".join(lines)


def analyze_chain(config) -> ChainAnalysis:
    """Rest state, linearisation, eigenvalues and verdict of a chain run
    (:class:`rbstab.config.chains.ChainConfig`).

    Raises
    ------
    ValueError
        Where the chain has no rest state near its reference configuration, or a joint has
        no linearisation (:func:`rbstab.analysis.linearise.linearise_chain`).
    """
    from ..variants import chain as C  # heavy: numba (the chain's kernels compile on first use)

    compiled = C.compile_chain(config.chain)
    lin, coordinates = linearise_chain(compiled)
    rest = C.full_state(compiled, lin.equilibrium)
    v0 = C.lyapunov(compiled, C.initial_state(config))[0]
    return ChainAnalysis(config.name, lin, coordinates, rest, float(v0))
