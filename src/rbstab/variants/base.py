"""The controller-variant protocol, and the body of eq 1 that four of the variants share.

A variant is one way of holding the point C of the body (section 5). The integrators
and the writers talk only to :class:`Variant`, never to a variant by name:

- ``layout``: the state blocks (:mod:`rbstab.layout`); ``code``: the variant's number in
  the compiled kernels (:mod:`rbstab.variants.kernels`);
- ``initial_state``: the state vector from the configured initial blocks;
- ``rhs(t, y)``: the right-hand side, for one state (shape (n_state,)) or a stack
  (shape (..., n_state));
- ``evaluate(y)``: every output quantity along a stack of states (constraint error E and
  rate F, constraint force Lambda, controls H and N, the Lyapunov function v, its terms
  and its analytic rate dv/dt);
- ``parameters``: the run's :data:`rbstab.model.PARAMETERS` record, the runtime argument
  of the compiled kernels.

The physics is compiled code (:mod:`rbstab.jit`), written once, next to
``docs/physics.md``: this module holds eq 1 under a constraint force Lambda and the terms
of v that every variant has (eq 25); each variant's module holds its constraint law, the
energy it stores and the power it dissipates.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cached_property
from typing import ClassVar

import numpy as np

from ..layout import (  # the table of outputs lives with the layout: files and readers need no compiler
    FULL_BODY,
    LEFT_OUT,
    LIMITED,
    LYAPUNOV_TERMS,
    N_OUTPUTS,
    OUTPUTS,
    VARIANT_CODES,
    VARIANT_LAYOUTS,
    StateLayout,
)
from ..model import PARAMETERS, Gains, Limits, RigidBody, parameters
from .kernels import run_outputs, state_rates

__all__ = ["Variant", "LYAPUNOV_TERMS", "N_OUTPUTS", "split_outputs", "limited_values", "rest_equilibria"]


# -- the protocol -----------------------------------------------------------------------------
class Variant:
    """One controller variant for the point C (the protocol; see module docstring).

    Parameters
    ----------
    body : RigidBody
        The rigid body (Table 1).
    gains : Gains
        Gains; those in ``required_gains`` are not None.
    limits : Limits, optional
        The admissible region (``simulation.limits``), written into :attr:`parameters`
        for the integrators; None: unbounded.
    """

    #: Registry name (the config value of ``controller.variant``).
    name: ClassVar[str]
    #: Number of the variant in the compiled kernels (:mod:`rbstab.variants.kernels`), from
    #: :data:`rbstab.layout.VARIANT_CODES` by ``name``.
    code: ClassVar[int]
    #: Layout of the integrated state, from :data:`rbstab.layout.VARIANT_LAYOUTS` by ``name``.
    layout: ClassVar[StateLayout] = FULL_BODY
    #: Gains that must be configured for this variant.
    required_gains: ClassVar[tuple[str, ...]] = ("k_t", "l_t", "k_r", "l_r")
    #: Gains whose singularity leaves v not a strict Lyapunov function (W002): those of
    #: ``required_gains`` unless the variant says fewer.
    definite_gains: ClassVar[tuple[str, ...] | None] = None
    #: Paper equation of the constraint law, for documentation and reports.
    equation: ClassVar[str] = ""

    def __init__(self, body: RigidBody, gains: Gains, limits: Limits | None = None) -> None:
        self.body = body
        self.gains = gains
        self.limits = limits

    def __init_subclass__(cls, **kwargs) -> None:
        """A variant's ``code`` and ``layout`` are those :mod:`rbstab.layout` gives its ``name``."""
        super().__init_subclass__(**kwargs)
        cls.code = VARIANT_CODES[cls.name]
        cls.layout = VARIANT_LAYOUTS[cls.name]

    @property
    def smooth(self) -> bool:
        """Whether the right-hand side is smooth (False for the pure sign law of sliding)."""
        return True

    # -- state ---------------------------------------------------------------
    def initial_state(self, blocks: dict[str, np.ndarray]) -> np.ndarray:
        """State vector, shape (layout.size,), from initial blocks (each shape (3,)).

        Blocks the layout does not hold (e.g. ``position`` for ``permanent``) are ignored.
        """
        return self.layout.join(**{b: blocks[b] for b in self.layout.blocks})

    @cached_property
    def parameters(self) -> np.ndarray:
        """This run's :data:`~rbstab.model.PARAMETERS` record, shape (1,), with h and the
        admissible region."""
        return parameters(self.body, self.gains, self.lyapunov_offset, self.limits)[None]

    @cached_property
    def _parameters_without_offset(self) -> np.ndarray:
        return parameters(self.body, self.gains, 0.0, self.limits)[None]

    # -- dynamics and outputs (compiled kernels) -------------------------------
    def rhs(self, t: float | np.ndarray, y: np.ndarray) -> np.ndarray:
        """dy/dt at time ``t`` [s] (a number, or one a state, shape (...); it enters through
        the disturbances only), shape like ``y`` ((n_state,) or (..., n_state))."""
        y = np.asarray(y, dtype=float)
        flat = np.ascontiguousarray(y.reshape(-1, self.layout.size))
        times = np.ascontiguousarray(np.asarray(t, dtype=float).reshape(-1))  # 1 or one a state
        out = np.empty_like(flat)
        state_rates(self.code, times, flat, self._parameters_without_offset, out)
        return out.reshape(y.shape)

    @cached_property
    def _undisturbed(self) -> np.ndarray:
        """The record without h and without the disturbances (the equilibrium's)."""
        return parameters(self.body, replace(self.gains, disturbances=()), 0.0)[None]

    def _output_columns(self, y: np.ndarray, params: np.ndarray, t: np.ndarray | float = 0.0) -> np.ndarray:
        """Every output along states ``y`` (..., n_state) at times ``t`` (a number, or one
        a state): shape (N_OUTPUTS, ...)."""
        y = np.asarray(y, dtype=float)
        flat = np.ascontiguousarray(y.reshape(1, -1, self.layout.size))
        times = np.ascontiguousarray(np.broadcast_to(np.asarray(t, dtype=float), y.shape[:-1]).reshape(1, -1))
        out = np.empty((N_OUTPUTS, 1, flat.shape[1]))
        run_outputs(np.array([self.code]), params, times, flat, out, True)
        return out.reshape((N_OUTPUTS,) + y.shape[:-1])

    def evaluate(self, y: np.ndarray, t: np.ndarray | float = 0.0) -> dict[str, np.ndarray]:
        """All outputs along states ``y`` of shape (n, n_state), or (..., n_state), at times
        ``t`` [s] (a number or one a state; they enter ``disturbance_power`` and dv/dt only;
        ``disturbance_work`` is 0: it is a run's history, not a state's).

        Returns
        -------
        dict
            The state blocks of the layout plus ``position`` and ``velocity`` (reconstructed
            for ``permanent``), ``constraint_error``, ``constraint_rate``,
            ``constraint_force``, ``force_h``, ``torque_n`` (shape (..., 3)), and
            ``lyapunov``, ``lyapunov_rate`` and the terms of v (shape (...)); a state's
            outputs do not depend on the other states of ``y``.
        """
        return split_outputs(self._output_columns(y, self.parameters, t), self.layout)

    def limited_values(self, y: np.ndarray) -> np.ndarray:
        """The quantities ``simulation.limits`` bounds along states ``y`` (n, n_state):
        shape (n, 5, 3) (:func:`limited_values`)."""
        return limited_values(self.code, y, self.body.attachment_point)

    def lyapunov(self, y: np.ndarray) -> np.ndarray:
        """v [J] along states ``y`` of shape (..., n_state); shape (...)."""
        return self._output_columns(y, self.parameters)[OUTPUTS["lyapunov"].offset]

    # -- equilibrium -----------------------------------------------------------
    @property
    def _configuration_blocks(self) -> tuple[str, ...]:
        return tuple(b for b in self.layout.blocks if b in ("theta", "position", "controller_state"))

    def _potential(self, p: np.ndarray) -> float:
        """Stored energy without the constant h, at rest, for configuration vector p."""
        columns = self._output_columns(self._rest_state(p), self._undisturbed)
        return float(columns[OUTPUTS["lyapunov"].offset])

    def _rest_state(self, p: np.ndarray) -> np.ndarray:
        """State at rest (zero velocities) with configuration blocks from vector ``p``."""
        blocks = {b: np.zeros(3) for b in self.layout.blocks}
        for i, b in enumerate(self._configuration_blocks):
            blocks[b] = p[3 * i : 3 * i + 3]
        return self.layout.join(**blocks)

    def _rest_acceleration(self, p: np.ndarray) -> np.ndarray:
        """Rates of omega, velocity (and D) at rest: zero exactly at an equilibrium."""
        y = np.ascontiguousarray(self._rest_state(p)[None])
        out = np.empty_like(y)
        state_rates(self.code, np.zeros(1), y, self._undisturbed, out)
        rate = self.layout.split(out[0])
        return np.concatenate(
            [rate[b] for b in ("omega", "velocity", "controller_state") if b in self.layout.blocks]
        )

    @cached_property
    def _equilibrium(self) -> tuple[np.ndarray, float]:
        n = 3 * len(self._configuration_blocks)
        if not np.any(self.body.weight):
            return self._rest_state(np.zeros(n)), 0.0
        if self.smooth:  # Newton's method from 0 (:func:`rest_equilibria`), as a batch of records computes it
            p, h, found = rest_equilibria(type(self), self._undisturbed)
            if found[0]:
                return self._rest_state(p[0]), float(h[0])
        return self._descended_equilibrium()

    def _descended_equilibrium(self) -> tuple[np.ndarray, float]:
        """The minimum of the stored energy downhill from 0 (BFGS, polished to a rest point
        of the dynamics; Nelder-Mead for the pure sign law) and h there."""
        from scipy.optimize import minimize, root  # heavy: scipy

        n = 3 * len(self._configuration_blocks)
        if self.smooth:
            # the minimum of the stored energy, polished to a rest point of the dynamics
            p = minimize(self._potential, np.zeros(n), method="BFGS").x
            polished = root(self._rest_acceleration, p, method="hybr", options={"xtol": 1e-13})
            if np.linalg.norm(polished.fun) < np.linalg.norm(self._rest_acceleration(p)):
                p = polished.x
        else:
            p = minimize(
                self._potential,
                np.zeros(n),
                method="Nelder-Mead",
                options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 20000 * n, "maxfev": 20000 * n},
            ).x
        return self._rest_state(p), -self._potential(p)

    @property
    def equilibrium(self) -> np.ndarray:
        """Equilibrium state, shape (n_state,): the local minimum of the stored energy nearest
        the origin (zero velocities). Without gravity it is the origin."""
        return self._equilibrium[0]

    @cached_property
    def lyapunov_offset(self) -> float:
        """The constant h [J] that makes v zero at :attr:`equilibrium` (eq 30)."""
        return self._equilibrium[1]


#: Newton's iterations of :func:`rest_equilibria` (each halving its step at most 30 times),
#: the residual [rad/s^2, m/s^2, m/s] at which it stops (the root polish's of one variant) and
#: the relative size of a step that round-off stops.
_NEWTON_STEPS, _NEWTON_RESIDUAL, _NEWTON_STEP = 60, 1e-13, 1e-12


def rest_equilibria(cls: type[Variant], records: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the configuration blocks p (k, n) of the equilibrium, h [J] (k,), found (k,) bool) of
    the variant class ``cls`` (smooth) with each of the :data:`~rbstab.model.PARAMETERS`
    ``records`` (k,) (read without h, disturbances and actuator limits: v's minimum, which
    no limit moves), all at once; each row's numbers are those of the record alone (no
    row's arithmetic reads another's). From the
    configuration 0, Newton's method on the rest accelerations (their Jacobian by central
    differences, the step halved until their norm falls) to 1e-13, or until Newton's step
    falls below 1e-12 (1 + |p|) (what remains is round-off); ``found`` where it
    converged to the minimum of the stored energy downhill from 0 (v no higher than at 0,
    the linearisation there stable: -dF/dp's eigenvalues real and positive), or where 0 is
    already a rest point (as a descent from it stops there); elsewhere h is NaN (and
    :attr:`Variant.equilibrium` descends from 0 by BFGS instead)."""
    layout = cls.layout
    conf = np.concatenate([np.arange(layout.slice(b).start, layout.slice(b).stop)
                           for b in layout.blocks if b in ("theta", "position", "controller_state")])
    rates = np.concatenate([np.arange(layout.slice(b).start, layout.slice(b).stop)
                            for b in ("omega", "velocity", "controller_state") if b in layout.blocks])
    records = records.copy()
    records["lyapunov_offset"], records["disturbance_count"], records["saturation"] = 0.0, 0.0, 0.0
    k, n = len(records), len(conf)

    def at_rest(p: np.ndarray) -> np.ndarray:
        y = np.zeros((len(p), layout.size))
        y[:, conf] = p
        return y

    def acceleration(p: np.ndarray, rows: np.ndarray) -> np.ndarray:
        out = np.empty((len(p), layout.size))
        state_rates(cls.code, np.zeros(1), at_rest(p), records[rows], out)
        return out[:, rates]

    def potential(p: np.ndarray) -> np.ndarray:
        out = np.empty((N_OUTPUTS, k, 1))
        run_outputs(np.full(k, cls.code), records, np.zeros((1, 1)), at_rest(p)[:, None, :], out, True)
        return out[OUTPUTS["lyapunov"].offset, :, 0]

    def jacobian(p: np.ndarray, rows: np.ndarray) -> np.ndarray:
        jac = np.empty((len(rows), n, n))
        step = 1e-7 * (1.0 + np.abs(p))
        for c in range(n):
            d = np.zeros_like(p)
            d[:, c] = step[:, c]
            jac[:, :, c] = (acceleration(p + d, rows) - acceleration(p - d, rows)) / (2.0 * step[:, c:c + 1])
        return jac

    p = np.zeros((k, n))
    f = acceleration(p, np.arange(k))
    at_zero = np.linalg.norm(f, axis=1) == 0.0
    stuck = np.zeros(k, dtype=bool)  # a singular Jacobian: left to the caller
    floor = np.zeros(k, dtype=bool)  # Newton's step below 1e-12 (1 + |p|): the residual is round-off's
    for _ in range(_NEWTON_STEPS):
        rows = np.flatnonzero((np.linalg.norm(f, axis=1) > _NEWTON_RESIDUAL) & ~stuck & ~floor)
        if not len(rows):
            break
        jac = jacobian(p[rows], rows)
        with np.errstate(all="ignore"):
            singular = ~(np.linalg.cond(jac) < 1e12)
        stuck[rows[singular]] = True
        rows, jac = rows[~singular], jac[~singular]
        if not len(rows):
            break
        step = -np.linalg.solve(jac, f[rows][..., None])[..., 0]
        size, norm = np.ones(len(rows)), np.linalg.norm(f[rows], axis=1)
        for _ in range(30):
            trial = p[rows] + size[:, None] * step
            f_trial = acceleration(trial, rows)
            worse = ~(np.linalg.norm(f_trial, axis=1) < norm)
            if not worse.any():
                break
            size = np.where(worse, 0.5 * size, size)
        floor[rows] = np.linalg.norm(step, axis=1) <= _NEWTON_STEP * (1.0 + np.linalg.norm(p[rows], axis=1))
        p[rows], f[rows] = trial, f_trial
    value = potential(p)
    found = at_zero | (((np.linalg.norm(f, axis=1) <= _NEWTON_RESIDUAL) | floor) & ~stuck)
    found &= at_zero | (value <= potential(np.zeros((k, n))) + 1e-12 * np.abs(value))
    rows = np.flatnonzero(found & ~at_zero)
    if len(rows):
        eigenvalues = np.linalg.eigvals(-jacobian(p[rows], rows))
        found[rows] = np.all((np.abs(eigenvalues.imag) <= 1e-9 * np.abs(eigenvalues)) & (eigenvalues.real > 0), axis=1)
    return p, np.where(found, -value, np.nan), found


def limited_values(code: int, y: np.ndarray, attachment_point: np.ndarray) -> np.ndarray:
    """The quantities ``simulation.limits`` bounds at states ``y`` (n, n_state) of the
    variant ``code`` whose bodies have attachment points R [m] (3,) or (n, 3): shape (n, 5, 3),
    the rows of :data:`rbstab.layout.LIMITED` (Theta [rad], Omega [rad/s] body frame, X [m],
    V [m/s], E [m] inertial frame), as the compiled outputs give them (``permanent``'s X, V
    and E those of the pinned body). They depend on the state and R only."""
    y = np.ascontiguousarray(np.atleast_2d(np.asarray(y, dtype=float)))
    n = y.shape[0]
    params = np.zeros(n, dtype=PARAMETERS)
    params["attachment_point"] = attachment_point
    out = np.empty((N_OUTPUTS, n, 1))
    with np.errstate(all="ignore"):
        run_outputs(np.full(n, code, dtype=np.int64), params, np.zeros((1, 1)), y[:, None, :], out, False)
    return np.stack([np.moveaxis(out[OUTPUTS[name].columns, :, 0], 0, -1) for name in LIMITED], axis=1)


def split_outputs(columns: np.ndarray, layout: StateLayout, full: bool = True) -> dict[str, np.ndarray]:
    """Named outputs from the ``outputs`` kernel's columns, shape (N_OUTPUTS, ...), each
    from its columns in :data:`rbstab.layout.OUTPUTS`.

    ``controller_state`` is kept only where ``layout`` integrates it; ``full`` False: the
    columns of ``run_outputs(..., full=False)``, without :data:`~rbstab.layout.LEFT_OUT`.
    Vectors are views (..., 3) and scalars views (...) of ``columns`` (not contiguous
    along the 3 axes).
    """
    out = {}
    for name, q in OUTPUTS.items():
        if (name == "controller_state" and name not in layout.blocks) or (not full and name in LEFT_OUT):
            continue
        out[name] = np.moveaxis(columns[q.columns], 0, -1) if q.size == 3 else columns[q.offset]
    return out
