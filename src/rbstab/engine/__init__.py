"""The compiled engine: many runs, each with its own variant, parameters and settings.

:func:`integrate_runs` integrates runs with scipy's explicit Runge-Kutta pairs (RK23,
RK45, DOP853) compiled with the model (:mod:`rbstab.engine.rk`,
:mod:`rbstab.engine.integrate`): the same error norm, initial step, step-size control,
dense output and gimbal-lock event as ``solve_ivp``, so a run takes the steps
``solve_ivp`` would take and agrees with it to the tolerance's scale. A run's result does
not depend on the other runs of its call. Implicit methods (Radau, BDF, LSODA) are not
here: :func:`rbstab.simulate.simulate` runs them through ``solve_ivp`` with the same
compiled right-hand side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .status import DEFAULT_MAX_STEPS, status_message
from .tableaus import METHODS

__all__ = ["METHODS", "DEFAULT_MAX_STEPS", "ChunkSolution", "method_number", "integrate_runs", "status_message", "warm_up"]

def method_number(method: str) -> int:
    """The compiled engine's number of ``method`` (``"RK23"``, ``"RK45"`` or ``"DOP853"``):
    its index in :data:`METHODS` (:mod:`rbstab.engine.tableaus`), the rows of its tableau
    in :mod:`rbstab.engine.rk`'s tables.

    Raises
    ------
    ValueError
        For a method not in :data:`METHODS`.
    """
    if method not in METHODS:
        raise ValueError(f"method: found {method!r}; the compiled engine has {', '.join(METHODS)}")
    return METHODS.index(method)


@dataclass
class ChunkSolution:
    """Samples of k runs and how each ended.

    Attributes
    ----------
    samples : ndarray, shape (k, n_samples, n_state)
        The state at linspace(0, t_end, n_samples) of each run; NaN after it stopped.
    status : ndarray of int, shape (k,)
        How each run ended (:mod:`rbstab.engine.status`: 0 reached t_end, 1 gimbal lock,
        negative a failure).
    t_stop : ndarray, shape (k,)
        Where each run stopped [s] (the event time for gimbal lock).
    nfev, n_steps : ndarray of int, shape (k,)
        Right-hand-side evaluations and accepted steps.
    """

    samples: np.ndarray
    status: np.ndarray
    t_stop: np.ndarray
    nfev: np.ndarray
    n_steps: np.ndarray


def integrate_runs(codes, params, y0, settings, *, method: str, n_samples: int,
                   max_steps: int = DEFAULT_MAX_STEPS, max_wall_time: float = np.inf,
                   out: np.ndarray | None = None) -> ChunkSolution:
    """Integrate k runs of one method and sample count.

    Parameters
    ----------
    codes : array_like of int, shape (k,)
        Variant codes (``Variant.code``); every run's state has the same size.
    params : ndarray of :data:`rbstab.model.PARAMETERS`, shape (k,)
    y0 : ndarray, shape (k, n_state)
        Initial states.
    settings : ndarray, shape (k, 5) or (k, 7)
        Per run: t_end [s], rtol, atol, max_step [s], gimbal_margin [rad], and optionally
        max_steps and max_wall_time [s] (default: the arguments of those names).
    method : str
        One of :data:`METHODS`.
    n_samples : int
        Samples per run, evenly spaced on [0, t_end] (>= 2).
    max_steps : int
        Accepted steps after which a run stops (STEP_LIMIT), for 5-column ``settings``.
    max_wall_time : float
        Seconds after which a run stops (TIMEOUT; inf: none), for 5-column ``settings``.
    out : ndarray, shape (>= k, n_samples, n_state), optional
        Where the samples go (its first k rows, returned as ``samples``): a buffer the
        caller reuses for call after call, so that a worker holds one (default: a new
        array).

    Raises
    ------
    ValueError
        If ``out`` is not a writable C-contiguous float64 array of that shape.
    """
    from .integrate import integrate_chunk

    codes = np.ascontiguousarray(codes, dtype=np.int64)
    y0 = np.ascontiguousarray(y0, dtype=float)
    k, n = y0.shape
    settings = np.asarray(settings, dtype=float)
    if settings.shape[1] == 5:
        settings = np.column_stack([settings, np.full(k, float(max_steps)), np.full(k, float(max_wall_time))])
    samples = np.empty((k, n_samples, n)) if out is None else _sample_buffer(out, (k, n_samples, n))
    status = np.empty(k, dtype=np.int64)
    t_stop = np.empty(k)
    nfev = np.empty(k, dtype=np.int64)
    n_steps = np.empty(k, dtype=np.int64)
    with np.errstate(all="ignore"):
        integrate_chunk(codes, np.ascontiguousarray(params), y0, np.ascontiguousarray(settings),
                        method_number(method), samples, status, t_stop, nfev, n_steps)
    return ChunkSolution(samples, status, t_stop, nfev, n_steps)


def _sample_buffer(out, shape: tuple[int, int, int]) -> np.ndarray:
    """The first ``shape[0]`` rows of ``out`` (see :func:`integrate_runs`); ValueError if it
    cannot hold them."""
    if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.flags.c_contiguous
            and out.flags.writeable and out.ndim == 3 and out.shape[0] >= shape[0] and out.shape[1:] == shape[1:]):
        found = f"shape {out.shape} of {out.dtype}" if isinstance(out, np.ndarray) else type(out).__name__
        raise ValueError(f"out: found {found}; expected a writable C-contiguous float64 array of shape "
                         f"(>= {shape[0]}, {shape[1]}, {shape[2]})")
    return out[: shape[0]]


def warm_up(parts: str = "rates,outputs,switching") -> None:
    """Compile (or load from the cache) every kernel a run uses, on a tiny input.

    ``parts``: comma-separated, any of ``rates`` (the right-hand side and the Runge-Kutta
    integrator), ``outputs`` (every output at the samples and the numerical dv/dt,
    :func:`rbstab.summary.numerical_rate`) and ``switching`` (the sign
    law's event-driven integrator, :mod:`rbstab.engine.switching`);
    :func:`rbstab.jit.ensure_compiled` compiles some in a second process at the same time.
    """
    from ..model import PARAMETERS
    from ..variants.base import N_OUTPUTS
    from ..variants.kernels import STATE_SIZE, run_outputs, state_rates

    wanted = set(parts.split(","))
    params = np.zeros(1, dtype=PARAMETERS)
    params["mass"] = 1.0
    for name in ("inertia", "inertia_inv", "pivot_inertia", "pivot_inertia_inv"):
        params[name] = np.eye(3)
    if "switching" in wanted:
        from .switching import warm_up as warm_up_switching

        warm_up_switching(params)
    for code, n in enumerate(STATE_SIZE):
        y = np.zeros((1, n))
        if "rates" in wanted:
            state_rates(code, y, params, np.empty_like(y))
        if "outputs" in wanted:
            run_outputs(np.array([code]), params, y[None], np.empty((N_OUTPUTS, 1, 1)), True)
    if "outputs" in wanted:
        from ..summary import numerical_rate

        numerical_rate(np.linspace(0.0, 1.0, 8), np.zeros((1, 8)))
    if "rates" in wanted:
        settings = np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3]])
        for method in METHODS:
            integrate_runs([0], params, np.zeros((1, 12)), settings, method=method, n_samples=2)
