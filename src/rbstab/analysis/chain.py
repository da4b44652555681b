"""The analysis of a chain of rigid bodies: its rest state, the linearisation there in the
chain's independent coordinates, the eigenvalues and Lyapunov's indirect verdict
(:func:`rbstab.analysis.linearise.linearise_chain`), v at the configured initial state, the
Lyapunov certificate with its sublevel estimate checked against the chain's runs
(:func:`rbstab.analysis.chain_certificate.certify_chain`), and
the basin of attraction by simulation over a 2-D slice of initial states
(:func:`chain_basin_map`), and the recovery of runs from drawn initial states
(:func:`chain_states_recover`, for :func:`rbstab.analysis.push.basin_stability`).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO, converged
from .basin import DEFAULT_SAMPLES, BasinAxis, BasinMap, time_to_converge
from .linearise import Linearisation, linearise_chain

__all__ = ["ChainAnalysis", "analyze_chain", "chain_basin_map", "check_axes", "check_entries", "chain_states",
           "chain_states_recover", "final_lyapunov"]

#: The state blocks of a body in the chain's state, in order (12 entries a body).
_BODY_BLOCKS = ("theta", "omega", "position", "velocity")


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
    certificate : Certificate or None
        The Lyapunov certificate in the independent coordinates (its states, e.g.
        ``worst_state``, are z), None where not asked for.
    notes : tuple of str
    """

    name: str
    linearisation: Linearisation
    coordinates: list
    rest_state: np.ndarray
    initial_lyapunov: float
    certificate: object = None
    notes: tuple = ()

    @property
    def verdict(self) -> str:
        return self.linearisation.verdict

    def as_dict(self) -> dict:
        """Plain Python (the ``--json`` form): rest state per body and block, eigenvalues as
        [re, im] [1/s], verdict, v at the initial state [J], the certificate (the fields of
        a one-body analysis's, :func:`rbstab.analysis.dataset.certificate_record`, with
        ``coordinates`` naming the entries of ``worst_state``) and notes."""
        lin = self.linearisation
        rest = {}
        for k, (body, block, _) in enumerate(self.coordinates):
            rest.setdefault(body, {})[block] = lin.equilibrium[3 * k: 3 * k + 3].tolist()
        return {"name": self.name, "verdict": lin.verdict, "rest_point": lin.is_rest_point, "rest_state": rest,
                "eigenvalues": [[float(s.real), float(s.imag)] for s in lin.eigenvalues],
                "slowest_time_constant": float(lin.slowest_time_constant),
                "initial_lyapunov": self.initial_lyapunov, "notes": list(self.notes),
                **({"certificate": self._certificate_dict()} if self.certificate is not None else {})}

    def _certificate_dict(self) -> dict:
        from .dataset import certificate_record

        names = [f"{body}.{block}.{i}" for body, block, _ in self.coordinates for i in range(3)]
        return {**certificate_record(self.certificate), "coordinates": names}

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
        lines += [f"  note: {n}" for n in self.notes]
        if self.certificate is not None:
            from .text import certificate_lines

            lines += certificate_lines(self.certificate, domain="|theta_2| of a body or joint")
        return "\n".join(lines)

    def checked(self, runs) -> "ChainAnalysis":
        """This analysis with its certificate's c checked against the runs of ``runs`` (an
        object with ``settling``, ``basin``, ``push`` and ``basin_stability``, those of the
        same command; :func:`rbstab.analysis.evidence.check_runs`)."""
        if self.certificate is None:
            return self
        from .evidence import check_runs

        return replace(self, certificate=check_runs(self.certificate, runs))


def analyze_chain(config, *, certificate: bool = True, samples: int | None = None, seed: int = 0,
                  falsification_runs: int | None = None, ratio: float = DEFAULT_LYAPUNOV_RATIO) -> ChainAnalysis:
    """Rest state, linearisation, eigenvalues, verdict and (``certificate``) the Lyapunov
    certificate of a chain run (:class:`rbstab.config.chains.ChainConfig`).

    ``samples`` (default :data:`rbstab.analysis.chain_certificate.DEFAULT_CHAIN_SAMPLES`),
    ``seed``, ``falsification_runs`` (default
    :data:`rbstab.analysis.evidence.FALSIFICATION_RUNS`) and ``ratio`` are those of
    :func:`rbstab.analysis.chain_certificate.certify_chain`.

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
    if certificate:
        from .chain_certificate import DEFAULT_CHAIN_SAMPLES, certify_chain
        from .evidence import FALSIFICATION_RUNS

        found, notes = certify_chain(config, compiled, lin, coordinates,
                                     n_samples=DEFAULT_CHAIN_SAMPLES if samples is None else int(samples), seed=seed,
                                     falsification_runs=FALSIFICATION_RUNS if falsification_runs is None
                                     else int(falsification_runs), ratio=ratio)
    return ChainAnalysis(config.name, lin, coordinates, rest, float(v0), found, tuple(notes))


def _state_offset(compiled, axis: BasinAxis) -> int:
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
    ``axes`` (:class:`BasinAxis`, keys ``initial_state.<body>.<block>.<i>``) set to the
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
    from ..engine.systems import chain_system  # heavy: numba
    from ..variants import chain as C  # heavy: numba

    check_entries(config, axes)
    compiled = C.compile_chain(config.chain)
    states = chain_states(config, compiled, axes, values)
    sim = config.simulation
    ok, v1 = final_lyapunov(compiled, chain_system(compiled, sim.limits), states, sim, jobs=jobs)
    v0 = C.evaluate(compiled, np.zeros(len(states)), states)["lyapunov"]
    return np.asarray(converged(ok, v0, v1, ratio), dtype=bool), v0


def final_lyapunov(compiled, system, states: np.ndarray, simulation, *, jobs: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(whether each run reached t_end inside the admissible region, v(t_end) [J], NaN for a
    run that stopped) of the runs of one chain (``compiled``, its
    :class:`~rbstab.engine.systems.ChainSystem` ``system``) from ``states`` (k, n_states)
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
    """ValueError (one line) where an axis (:class:`BasinAxis`) names no entry of the
    chain's state (keys ``initial_state.<body>.<block>.<i>``)."""
    from ..variants import chain as C  # heavy: numba

    compiled = C.compile_chain(config.chain, offset=0.0)
    for axis in axes:
        _state_offset(compiled, axis)


def check_axes(config, axes) -> None:
    """ValueError (one line) where a basin axis names no entry of the chain's state
    (:func:`chain_basin_map`'s keys), or the two are the same entry."""
    if len(axes) != 2 or axes[0].key == axes[1].key:
        raise ValueError(f"--basin: expected two different keys, found {[a.key for a in axes]}")
    check_entries(config, axes)


def chain_basin_map(config, axes, *, ratio: float = DEFAULT_LYAPUNOV_RATIO,
                    n_samples: int = DEFAULT_SAMPLES) -> BasinMap:
    """The basin of attraction of a chain (:class:`rbstab.config.chains.ChainConfig`) over
    the slice of initial states spanned by two ``axes`` (:class:`BasinAxis`, keys
    ``initial_state.<body>.<block>.<i>``), every other entry the configuration's; each
    grid point one run of the compiled driver, classified as a one-body basin map's
    points are (:mod:`rbstab.analysis.basin`). A body whose ``x`` (``v``) the configuration
    leaves out is placed on its joint at every point, as the configuration places it
    (E_j = 0, dE_j/dt = 0), so a tilt moves the bodies it carries. ``initial_states``
    holds the chain's full state (n_states) of each point.

    Raises
    ------
    ValueError
        For two equal keys, or a key that names no body of the chain (or a D its joint
        does not have).
    """
    from ..engine.integrate import integrate_chain_runs  # heavy: numba
    from ..engine.settings import settings_rows  # heavy: numba
    from ..engine.status import GIMBAL_LOCK, SUCCESS, limit_of, status_message  # heavy: numba
    from ..engine.systems import chain_system  # heavy: numba
    from ..variants import chain as C  # heavy: numba

    check_axes(config, axes)
    compiled = C.compile_chain(config.chain)
    shape = (len(axes[0].values), len(axes[1].values))
    first, second = np.meshgrid(axes[0].values, axes[1].values, indexing="ij")
    states = chain_states(config, compiled, axes, np.column_stack([first.ravel(), second.ravel()]))
    sim = config.simulation
    settings = np.repeat(settings_rows([sim]), len(states), axis=0)
    sol = integrate_chain_runs(chain_system(compiled, sim.limits), states, settings, method=sim.method,
                               n_samples=int(n_samples))
    time = np.linspace(0.0, sim.t_end, int(n_samples))
    outcome = np.full(len(states), 2, dtype=np.int8)
    t_conv = np.full(len(states), np.nan)
    v_final = np.full(len(states), np.nan)
    v_initial = C.evaluate(compiled, np.zeros(len(states)), states)["lyapunov"]
    v = C.evaluate(compiled, np.tile(time, len(states)), sol.samples.reshape(-1, compiled.n_states))["lyapunov"]
    v = v.reshape(len(states), -1)
    messages: dict[str, int] = {}
    for k in range(len(states)):
        code = int(sol.status[k])
        if code == SUCCESS:
            t_conv[k], v_final[k] = time_to_converge(time, v[k], ratio), v[k, -1]
            outcome[k] = 0 if np.isfinite(t_conv[k]) else 1
            continue
        if code == GIMBAL_LOCK:
            message = "gimbal lock of a body or joint (|theta_2| = pi/2 - gimbal_margin)"
        elif limit_of(code) is not None:
            quantity, axis = limit_of(code)
            message = f"left the admissible region (simulation.limits): |{quantity}_{axis + 1}| of a body or joint"
        else:
            message = status_message(code, float(sol.t_stop[k]), sim.gimbal_margin, int(sim.max_steps),
                                     sim.max_wall_time).split(" at t =")[0]
        messages[message] = messages.get(message, 0) + 1
    return BasinMap(axes=(axes[0], axes[1]), outcome=outcome.reshape(shape), time_to_converge=t_conv.reshape(shape),
                    lyapunov_initial=v_initial.reshape(shape), lyapunov_final=v_final.reshape(shape),
                    initial_states=states.reshape(*shape, -1), ratio=ratio, t_end=sim.t_end, messages=messages)

