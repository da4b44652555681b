"""The analysis of a chain of rigid bodies: its rest state, the linearisation there in the
chain's independent coordinates, the eigenvalues and Lyapunov's indirect verdict
(:func:`rbstab.analysis.linearise.linearise_chain`), v at the configured initial state, the
Lyapunov certificate with its sublevel estimate checked against the chain's runs
(:func:`rbstab.analysis.chain_certificate.certify_chain`); its basin map is
:func:`rbstab.analysis.basin.basin_map`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO
from ..layout import BLOCK_UNITS, STATE_BLOCKS
from .basin import BasinMap
from .chain_certificate import DEFAULT_CHAIN_SAMPLES, certify_chain
from .runs import check_entries
from .dataset import analysis_content, analysis_dataset, certificate_record, json_record
from .evidence import FALSIFICATION_RUNS, check_runs
from .linearise import Linearisation, linearise_chain, mode_shapes

__all__ = ["ChainAnalysis", "TreeCoordinates", "analyze_chain", "check_axes"]


@dataclass(frozen=True)
class TreeCoordinates:
    """A chain's independent coordinates (:func:`rbstab.variants.chain.independent_coordinates`)
    as the layout of its linearisation's state z: 3 entries per (body, state block), the
    blocks of :data:`rbstab.layout.STATE_BLOCKS` a body has (Theta, Omega of every body; X,
    V of one whose joint is not ``permanent``; D of an ``embedded`` joint's child), as
    :class:`rbstab.layout.StateLayout` lays out one body's state.

    Attributes
    ----------
    coordinates : tuple of (str, str, int)
        (body name, block, index into the full state) of each 3 entries of z.
    bodies : tuple of str
        The chain's bodies, in order.
    """

    coordinates: tuple
    bodies: tuple

    @property
    def blocks(self) -> tuple[str, ...]:
        """The state blocks some body has, in :data:`rbstab.layout.STATE_BLOCKS`' order."""
        present = {block for _, block, _ in self.coordinates}
        return tuple(b for b in STATE_BLOCKS if b in present)

    def state_names(self) -> list[str]:
        """Scalar coordinate names ``<body>.<block>_<i>`` (``legs.theta_1``), in z's order."""
        return [f"{body}.{block}_{i}" for body, block, _ in self.coordinates for i in (1, 2, 3)]

    def state_units(self) -> list[str]:
        """The units of each scalar coordinate (:data:`rbstab.layout.BLOCK_UNITS`), in z's order."""
        return [BLOCK_UNITS[block] for _, block, _ in self.coordinates for _ in range(3)]

    def split(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """Each block of ``z`` (n_z,) by body: {block: shape (n_bodies, 3)}, NaN for a body
        without that block."""
        z = np.asarray(z, dtype=float)
        out = {b: np.full((len(self.bodies), 3), np.nan) for b in self.blocks}
        for k, (body, block, _) in enumerate(self.coordinates):
            out[block][self.bodies.index(body)] = z[3 * k: 3 * k + 3]
        return out


@dataclass(frozen=True)
class ChainAnalysis:
    """What :func:`analyze_chain` finds, with the basin map, pushes and basin stability of
    the same command (:mod:`rbstab.analysis.dataset` writes it as one body's analysis,
    its state blocks by body).

    Attributes
    ----------
    config : ChainConfig
        The configuration analysed.
    linearisation : Linearisation
        At the rest state, in the independent coordinates (``coordinates``).
    coordinates : list of (str, str, int)
        (body name, block, index into the full state) of each 3 entries of
        ``linearisation.equilibrium`` (:func:`rbstab.variants.chain.independent_coordinates`).
    rest_state : ndarray, shape (n_states,)
        The full rest state (:func:`rbstab.variants.chain.rest_state`).
    initial_lyapunov : float
        v [J] at the configured initial state (zero at the rest state).
    certificate : Certificate or None
        The Lyapunov certificate in the independent coordinates (its states, e.g.
        ``worst_state``, are z), None where not asked for.
    settling : dict or None
        The simulation from the configured initial state, as one body's
        (:attr:`rbstab.analysis.Analysis.settling`); None where not asked for.
    notes : tuple of str
    ratio : float
        The convergence ratio of the command's runs.
    basin : BasinMap or None
        :func:`rbstab.analysis.basin.basin_map`.
    push : PushAnalysis or None
        :func:`rbstab.analysis.push.push_analysis` on one of its bodies.
    basin_stability : BasinStability or None
        :func:`rbstab.analysis.push.basin_stability`.
    """

    config: object
    linearisation: Linearisation
    coordinates: list
    rest_state: np.ndarray
    initial_lyapunov: float
    certificate: object = None
    settling: dict | None = None
    notes: tuple = ()
    ratio: float = DEFAULT_LYAPUNOV_RATIO
    basin: BasinMap | None = None
    push: object = None
    basin_stability: object = None
    #: Not verified (a tree of more than one body has more than 6 states).
    verification = None
    #: A chain's analysis file's ``variant``, as its run file's.
    variant = "chain"
    #: Its ``--json`` record's kind.
    kind = "chain"
    #: The angles that bound the certificate's domain, in its text.
    domain = "|theta_2| of a body or joint"

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def analysed(self):
        """The configuration analysed (the one given)."""
        return self.config

    @property
    def layout(self) -> TreeCoordinates:
        """The linearisation's coordinates by body and block."""
        return TreeCoordinates(tuple(self.coordinates), tuple(self.config.chain.body_names))

    @property
    def linear_settling_time(self) -> float:
        """:meth:`Linearisation.settling_time` at :attr:`ratio` [s]."""
        return self.linearisation.settling_time(self.ratio)

    def to_dataset(self):
        """The analysis as an :class:`xarray.Dataset` (its file's content, :mod:`~rbstab.analysis.dataset`)."""
        return analysis_dataset(self)

    def file_content(self, command_line: str | None = None) -> tuple[dict, dict, dict]:
        """(coordinates, variables, global attributes) of its file
        (:func:`~rbstab.analysis.dataset.analysis_content`)."""
        return analysis_content(self, command_line)

    @property
    def verdict(self) -> str:
        return self.linearisation.verdict

    @property
    def state_names(self) -> list[str]:
        """``<body>.<block>_<i>`` of each independent coordinate (:meth:`TreeCoordinates.state_names`)."""
        return self.layout.state_names()

    def as_dict(self) -> dict:
        """Plain Python (the ``--json`` form): one body's record
        (:func:`rbstab.analysis.dataset.json_record`: the verdict, the coordinates ``state``
        and the ``equilibrium`` in them, eigenvalues as [re, im] [1/s] with each one's
        natural frequency, damping ratio, time constant and e-folding time,
        ``slowest_time_constant`` [s] (null unless asymptotically stable),
        ``shortest_e_folding_time`` [s] (null unless unstable), the simulation, notes ...),
        with the rest state per body and block (``rest_state``), each eigenvalue's mode shape
        on the bodies' angles (``modes``: ``{"eigenvalue": [re, im], "shape":
        {"<body>.theta_<i>": [re, im]}}``, largest entry 1), v at the initial state [J]
        and the certificate's ``coordinates`` naming the entries of ``worst_state``."""
        lin = self.linearisation
        rest = {}
        for k, (body, block, _) in enumerate(self.coordinates):
            rest.setdefault(body, {})[block] = lin.equilibrium[3 * k: 3 * k + 3].tolist()
        return {**json_record(self), "rest_state": rest, "modes": self._modes(),
                "initial_lyapunov": self.initial_lyapunov,
                **({"certificate": self._certificate_dict()} if self.certificate is not None else {})}

    def basin_inside(self) -> dict[str, int] | None:
        """Outcome counts of the basin points inside the sublevel estimate {v <= c}."""
        if self.basin is None or self.certificate is None:
            return None
        return self.basin.counts(self.basin.lyapunov_initial <= self.certificate.sublevel)

    def to_json(self) -> dict:
        """The ``--json`` record: :meth:`as_dict` (its pushes with the push estimate from
        {v <= c}, its basin stability, as one body's), the basin map with the axes' keys and
        values, every point's outcome (rows: the first axis; 0 converged, 1 not converged,
        2 failed), the counts, those inside {v <= c} and the failures' messages."""
        record = self.as_dict()
        if self.basin is not None:
            b = self.basin
            record["basin"] = {"axes": [{"key": a.key, "values": a.values.tolist()} for a in b.axes],
                               "outcome": b.outcome.tolist(), "counts": b.counts(), "messages": b.messages,
                               "inside_estimate": self.basin_inside(), "t_end": b.t_end, "ratio": b.ratio}
        return record

    def angles(self) -> tuple[list[str], list[int]]:
        """(names ``<body>.theta_<i>``, positions in the linearisation's coordinates) of the
        bodies' Euler angles among the independent coordinates."""
        names, rows = [], []
        for k, (body, block, _) in enumerate(self.coordinates):
            if block == "theta":
                names += [f"{body}.theta_{i + 1}" for i in range(3)]
                rows += [3 * k + i for i in range(3)]
        return names, rows

    def _modes(self) -> list[dict]:
        """Each eigenvalue's mode on the bodies' angles (:func:`mode_shapes`), for ``--json``."""
        names, rows = self.angles()
        shapes = mode_shapes(self.linearisation, rows)
        return [{"eigenvalue": [float(s.real), float(s.imag)],
                 "shape": {n: [float(c.real), float(c.imag)] for n, c in zip(names, shape)}}
                for s, shape in zip(self.linearisation.eigenvalues, shapes)]

    def _certificate_dict(self) -> dict:
        names = [f"{body}.{block}.{i}" for body, block, _ in self.coordinates for i in range(3)]
        return {**certificate_record(self.certificate), "coordinates": names}

    def with_runs(self, basin=None, push=None, basin_stability=None) -> "ChainAnalysis":
        """This analysis with the basin map, pushes and basin stability of the same command,
        its certificate's c checked against their runs (:func:`rbstab.analysis.evidence.check_runs`;
        the run from the configured initial state was checked by :func:`analyze_chain`)."""
        found = replace(self, basin=basin, push=push, basin_stability=basin_stability)
        if self.certificate is None:
            return found
        return replace(found, certificate=check_runs(self.certificate, found))


def analyze_chain(config, *, certificate: bool = True, samples: int | None = None, seed: int = 0,
                  falsification_runs: int | None = None, ratio: float = DEFAULT_LYAPUNOV_RATIO,
                  settling: tuple | None = None) -> ChainAnalysis:
    """Rest state, linearisation, eigenvalues, verdict and (``certificate``) the Lyapunov
    certificate of a chain run (:class:`rbstab.config.ChainConfig`).

    ``samples`` (default :data:`rbstab.analysis.chain_certificate.DEFAULT_CHAIN_SAMPLES`),
    ``seed``, ``falsification_runs`` (default
    :data:`rbstab.analysis.evidence.FALSIFICATION_RUNS`) and ``ratio`` are those of
    :func:`rbstab.analysis.chain_certificate.certify_chain`. ``settling``: (the settling
    record, the run) of the simulation from the configured initial state where it ran
    (:attr:`ChainAnalysis.settling`; the certificate is checked against that run).

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
    found, notes = None, []
    record, first = settling if settling is not None else (None, None)
    if certificate:
        found, notes = certify_chain(config, compiled, lin, coordinates,
                                     n_samples=DEFAULT_CHAIN_SAMPLES if samples is None else int(samples), seed=seed,
                                     falsification_runs=FALSIFICATION_RUNS if falsification_runs is None
                                     else int(falsification_runs), ratio=ratio, first=first)
    return ChainAnalysis(config, lin, coordinates, rest, float(v0), found, record, tuple(notes), ratio)


def check_axes(config, axes) -> None:
    """ValueError (one line) where a basin axis names no entry of the chain's state
    (:func:`rbstab.analysis.basin.basin_map`'s keys), or the two are the same entry."""
    if len(axes) != 2 or axes[0].key == axes[1].key:
        raise ValueError(f"--basin: expected two different keys, found {[a.key for a in axes]}")
    check_entries(config, axes)
