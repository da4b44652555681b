"""The Lyapunov certificate of a chain's rest state, in the chain's independent coordinates.

The certificate is that of one body (:mod:`rbstab.analysis.certificate`: H_v, H_r and the
PBH test, dv/dt <= 0 on sampled states computed twice, the sublevel estimate {v <= c} from
the samples and the local search, capped by the domain boundary), over the chain as a
:class:`~rbstab.analysis.certificate.Model` (:class:`ChainModel`):

- coordinates: the independent coordinates z of
  :func:`rbstab.variants.chain.independent_coordinates` (Theta_i, Omega_i of every body;
  X_i, V_i of bodies whose joint is not ``permanent``; D of embedded joints). A state is
  :func:`rbstab.variants.chain.full_state` of z: the children of permanent joints placed on
  their parents (E_j = F_j = 0), so every sample lies on the constraint manifold, where the
  constraint power F_j' Lambda_j of the analytic rate vanishes;
- v and the analytic dv/dt: :func:`rbstab.variants.chain.evaluate` at those states (docs/physics.md,
  "v and dv/dt"); f: :func:`rbstab.variants.chain.reduced_rate`;
- the domain: |theta_2| < pi/2 - gimbal_margin of every body and of every joint's relative
  orientation Theta_j (the chain's runs stop at either); its boundary level is the least v
  there at rest (:func:`rbstab.analysis.certificate.constrained_boundary_level`: a joint's
  angle is not a coordinate).

The level c is then checked against runs of the chain's compiled engine
(:class:`rbstab.analysis.runs.Runs`) from states on {v = c}
(:func:`rbstab.analysis.evidence.falsify_with`: a run that leaves the domain or
``simulation.limits`` or ends with v above its start lowers c below its start), and against
the run from the configured initial state as for one body
(:func:`rbstab.analysis.evidence.check_initial_run`: started inside {v <= c}, it lowers c
where v rises above c or the run fails; one still settling at t_end is run longer first).
It is an estimate, as for one body.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO, ROUND_OFF
from .certificate import DEFAULT_SAMPLES, Certificate, certify, constrained_boundary_level
from .runs import Runs
from .evidence import FALSIFICATION_RUNS, check_initial_run, falsify_with

__all__ = ["ChainModel", "certify_chain", "DEFAULT_CHAIN_SAMPLES"]

#: Sampled states of a chain's certificate (each costs a rate of the chain through Python).
DEFAULT_CHAIN_SAMPLES = DEFAULT_SAMPLES
#: Step of the central differences of a joint angle's gradient [units of z].
_ANGLE_STEP = 1e-7


class ChainModel:
    """A compiled chain (:class:`rbstab.variants.chain.CompiledChain`) as a
    :class:`~rbstab.analysis.certificate.Model` in its independent coordinates (module
    docstring).

    Attributes
    ----------
    compiled : CompiledChain
    coordinates : list of (str, str, int)
        :func:`rbstab.variants.chain.independent_coordinates`.
    angle_names : list of str
        The domain's angles, in the order of :meth:`angles`: ``"<body>.theta_2"`` of each
        body, then ``"<joint>.theta_2"`` of each joint whose parent is a body.
    angle_matrix : ndarray or None
        (bodies, n) where every angle is a coordinate (no joint has a body for parent), else None.
    """

    def __init__(self, compiled, coordinates=None) -> None:
        from ..variants import chain as C  # heavy: numba

        self.compiled = compiled
        self.coordinates = list(C.independent_coordinates(compiled) if coordinates is None else coordinates)
        self._at = [int(at) for _, _, at in self.coordinates]
        self.n = 3 * len(self.coordinates)
        names = list(compiled.chain.body_names)
        self._theta = [3 * self._at.index(12 * i) + 1 for i in range(compiled.size)]  # theta_2 of each body in z
        self._parented = [j for j in range(compiled.size) if compiled.parents[j] >= 0]
        self.angle_names = [f"{b}.theta_2" for b in names] + [f"{compiled.chain.joint_names[j]}.theta_2"
                                                               for j in self._parented]
        if self._parented:
            self.angle_matrix = None
        else:
            self.angle_matrix = np.eye(self.n)[self._theta]

    def states(self, x) -> np.ndarray:
        """The chain's full states (k, n_states) of the independent coordinates ``x`` (k, n)
        (:func:`rbstab.variants.chain.full_state`)."""
        from ..variants import chain as C  # heavy: numba

        return C.full_state(self.compiled, np.atleast_2d(np.asarray(x, dtype=float)))

    # -- v, dv/dt, f ----------------------------------------------------------------------------
    def _outputs(self, x, t=0.0) -> dict:
        from ..variants import chain as C  # heavy: numba

        y = self.states(x)
        return C.evaluate(self.compiled, np.broadcast_to(np.asarray(t, dtype=float), len(y)).copy(), y)

    def lyapunov(self, x):
        """v [J] at each row of ``x`` (a float for one state (n,))."""
        v = self._outputs(x)["lyapunov"]
        return float(v[0]) if np.ndim(x) == 1 else v

    def evaluate(self, x, t=0.0) -> dict:
        """v [J], the analytic dv/dt [W] and the angles (:meth:`angles`) at each row of ``x``
        at the times ``t`` [s]."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        out = self._outputs(x, t)
        return {"lyapunov": out["lyapunov"], "lyapunov_rate": out["lyapunov_rate"],
                "angles": self._angles_of(x, out)}

    def rhs(self, t, x) -> np.ndarray:
        """dz/dt at each row of ``x`` (:func:`rbstab.variants.chain.reduced_rate`)."""
        from ..variants import chain as C  # heavy: numba

        x = np.atleast_2d(np.asarray(x, dtype=float))
        t = np.broadcast_to(np.asarray(t, dtype=float), len(x))
        return np.array([C.reduced_rate(self.compiled, row, float(s)) for row, s in zip(x, t)]).reshape(x.shape)

    # -- the domain ----------------------------------------------------------------------------
    def angles(self, x) -> np.ndarray:
        """(k, m) theta_2 [rad] of every body, then of every joint whose parent is a body."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return self._angles_of(x, self._outputs(x) if self._parented else None)

    def _angles_of(self, x: np.ndarray, out) -> np.ndarray:
        body = x[:, self._theta]
        if not self._parented:
            return body
        return np.concatenate([body, out["joint_theta"][:, self._parented, 1]], axis=1)

    def angle_jacobian(self, x) -> np.ndarray:
        """(m, n) d angles / dx at the state ``x`` (n,) (central differences)."""
        if self.angle_matrix is not None:
            return self.angle_matrix
        x = np.asarray(x, dtype=float)
        steps = _ANGLE_STEP * np.eye(self.n)
        values = self.angles(np.concatenate([x + steps, x - steps]))
        return ((values[: self.n] - values[self.n:]) / (2 * _ANGLE_STEP)).T

    def boundary_level(self, y_e, hess, limit) -> float:
        """The least v [J] on the domain boundary (any angle at +-limit), at rest."""
        free = [3 * k + a for k, (_, block, _) in enumerate(self.coordinates)
                if block in ("theta", "position", "controller_state") for a in range(3)]
        return constrained_boundary_level(self, np.asarray(y_e, dtype=float), hess, limit, np.array(free))


def _undisturbed(compiled):
    """``compiled`` without its bodies' disturbances (the same h), or None where it has none."""
    from ..variants import chain as C  # heavy: numba

    chain = compiled.chain
    if not any(b.disturbances for b in chain.bodies):
        return None
    bodies = tuple(dataclasses.replace(b, disturbances=()) for b in chain.bodies)
    return C.compile_chain(dataclasses.replace(chain, bodies=bodies), offset=compiled.offset)


def certify_chain(config, compiled, linearisation, coordinates, *, n_samples: int = DEFAULT_CHAIN_SAMPLES,
                  seed: int = 0, falsification_runs: int = FALSIFICATION_RUNS,
                  ratio: float = DEFAULT_LYAPUNOV_RATIO, first=None) -> tuple[Certificate, list[str]]:
    """(the certificate of a chain's rest state, notes) (module docstring).

    Parameters
    ----------
    config : rbstab.config.ChainConfig
        Its simulation settings (gimbal margin, limits, t_end) and initial state.
    compiled : CompiledChain
        Of ``config.chain``.
    linearisation : Linearisation
        At the rest state, in the independent coordinates ``coordinates``
        (:func:`rbstab.analysis.linearise.linearise_chain`).
    n_samples, seed
        The certificate's sampled states and the seed of their draw.
    falsification_runs : int
        Runs from states on {v = c} per level tried (0: none).
    ratio : float
        Convergence of the run from the configured initial state
        (:func:`rbstab.convergence.converged`): one not converged by t_end is run longer
        (:func:`rbstab.analysis.evidence.check_initial_run`).
    first : RunResult, optional
        The run from the configured initial state where already run.
    """
    from ..simulator import simulate  # heavy: numba

    sim = config.simulation
    notes = []
    quiet = _undisturbed(compiled)
    model = ChainModel(compiled if quiet is None else quiet, coordinates)
    disturbed = None
    if quiet is not None:
        disturbed = ChainModel(compiled, coordinates)
        notes.append("disturbances: the certificate's Hessians are of the undisturbed chain; its sampled dv/dt "
                     "(each state at a time drawn in [0, t_end], impulses not seen) and the runs integrate the "
                     "disturbed one")
    certificate = certify(model, linearisation, gimbal_margin=sim.gimbal_margin, n_samples=n_samples, seed=seed,
                          disturbed=disturbed, t_end=float(sim.t_end))
    if not certificate.positive_definite:
        return certificate, notes
    runs = Runs(config)

    def run(x):
        ok, v0, v1 = runs.outcomes(model.states(x))
        with np.errstate(invalid="ignore"):
            return (ok == 1) & np.isfinite(v1) & (v1 <= v0 + ROUND_OFF), v0

    certificate = falsify_with(run, model, linearisation, certificate, runs=falsification_runs, seed=seed)
    impulses = [d.start for b in config.chain.bodies for d in b.disturbances if d.kind == "impulse"]
    certificate = check_initial_run(certificate, config, simulate, linearisation, ratio=ratio, first=first,
                                    impulses=impulses)
    return certificate, notes
