"""The scipy core: integrate one validated run configuration (the reference path).

``simulate(config)`` calls :func:`scipy.integrate.solve_ivp` on the variant's
right-hand side, samples the dense output on an even grid, evaluates every output
quantity through the variant protocol and returns a :class:`RunResult`. A failed run
(solver failure, gimbal lock, non-finite state) is data: ``status == "failed"`` with a
message, never an exception.
"""

from __future__ import annotations

import time as _time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .kinematics import GIMBAL_LOCK_ANGLE
from .summary import numerical_rate, summarize, summarize_many
from .variants import Variant

if TYPE_CHECKING:  # pragma: no cover
    from .config import RunConfig

__all__ = [
    "RunResult",
    "RunTimeout",
    "ENGINES",
    "simulate",
    "simulate_many",
    "batch_key",
    "solve",
    "gimbal_lock_event",
    "evaluate_outputs",
]

#: Integration engines: ``scipy`` (the reference, one solve_ivp call per run, any
#: method) and ``batch`` (:mod:`rbstab.batch`, many runs per vectorised integration,
#: RK23/RK45/DOP853; other methods fall back to scipy).
ENGINES = ("scipy", "batch")


@dataclass
class RunResult:
    """Outcome of one run.

    Attributes
    ----------
    config : RunConfig
        The validated configuration that was run.
    time : ndarray, shape (n_samples,)
        Sample times [s], evenly spaced on [0, t_end].
    outputs : dict of str -> ndarray
        Every variable of the result file, shape (n_samples, 3) or (n_samples,): state
        blocks, constraint quantities, controls, ``lyapunov``, ``lyapunov_rate``,
        ``lyapunov_rate_numerical`` and the terms of v. Rows after a failure are NaN.
    status : str
        ``"success"`` or ``"failed"``.
    message : str
        The solver's message, or why the run failed.
    solver : dict
        ``nfev``, ``njev``, ``nlu`` (ints) and ``solver_status`` (scipy's int status).
    wall_time : float
        Integration plus post-processing time [s].
    summary : dict
        See :func:`rbstab.summary.summarize`.
    timing : dict
        Where ``wall_time`` went [s]: ``integration`` (for a batched run, its share of
        the batch) and ``postprocess`` (output evaluation, numerical rate, summary).
    """

    config: "RunConfig"
    time: np.ndarray
    outputs: dict[str, np.ndarray]
    status: str
    message: str
    solver: dict = field(default_factory=dict)
    wall_time: float = 0.0
    summary: dict = field(default_factory=dict)
    timing: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The run's name (``config.name``), also its result file's stem."""
        return self.config.name

    @property
    def ok(self) -> bool:
        """Whether the run reached ``t_end`` (``status == "success"``)."""
        return self.status == "success"


def gimbal_lock_event(margin: float):
    """Terminal solve_ivp event: zero when |theta_2| reaches pi/2 - ``margin`` [rad] (eq 5).

    theta is ``y[0:3]`` in every state layout.
    """

    def event(t: float, y: np.ndarray) -> float:
        return GIMBAL_LOCK_ANGLE - margin - abs(y[1])

    event.terminal = True
    event.direction = -1
    return event


def _gimbal_message(margin: float, t: float) -> str:
    return (
        f"gimbal lock: |theta_2| reached pi/2 - {margin:g} rad at t = {t:.6g} s; "
        "B(theta) is singular there (eq 5), so the Euler-angle model stops"
    )


class RunTimeout(Exception):
    """Raised inside the right-hand side when a run exceeds its wall-time budget."""


def _with_deadline(rhs, timeout: float | None):
    if timeout is None:
        return rhs
    deadline = _time.perf_counter() + timeout

    def timed_rhs(t, y):
        if _time.perf_counter() > deadline:
            raise RunTimeout(f"timeout: the run exceeded {timeout:g} s of wall time at t = {t:.6g} s")
        return rhs(t, y)

    return timed_rhs


def solve(
    variant: Variant, y0: np.ndarray, settings, timeout: float | None = None
) -> tuple[np.ndarray, np.ndarray, str, str, dict]:
    """Integrate ``variant`` from ``y0`` with :func:`scipy.integrate.solve_ivp`.

    Parameters
    ----------
    variant : Variant
        Right-hand side provider.
    y0 : ndarray, shape (n_state,)
        Initial state in ``variant.layout``.
    settings : SimulationSettings
        ``t_end`` [s], ``n_samples``, ``method``, ``rtol``, ``atol``, ``max_step`` [s],
        ``gimbal_margin`` [rad].
    timeout : float, optional
        Wall-time budget [s]; past it the run stops with status ``"failed"``.

    Returns
    -------
    time : ndarray, shape (n_samples,)
    states : ndarray, shape (n_samples, n_state)
        Dense-output samples; NaN after a failure.
    status, message : str
    solver : dict
        ``nfev``, ``njev``, ``nlu``, ``solver_status``.
    """
    from scipy.integrate import solve_ivp

    t_eval = np.linspace(0.0, settings.t_end, settings.n_samples)
    states = np.full((settings.n_samples, variant.layout.size), np.nan)
    with np.errstate(all="ignore"):
        try:
            sol = solve_ivp(
                _with_deadline(variant.rhs, timeout),
                (0.0, settings.t_end),
                y0,
                method=settings.method,
                t_eval=t_eval,
                events=[gimbal_lock_event(settings.gimbal_margin)],
                rtol=settings.rtol,
                atol=settings.atol,
                max_step=settings.max_step,
            )
        except RunTimeout as exc:
            return t_eval, states, "failed", str(exc), {"nfev": 0, "njev": 0, "nlu": 0, "solver_status": -1}
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
            return t_eval, states, "failed", f"solver error: {exc}", {"nfev": 0, "njev": 0, "nlu": 0, "solver_status": -1}
    n = sol.y.shape[1]
    states[:n] = sol.y.T
    solver = {"nfev": int(sol.nfev), "njev": int(sol.njev), "nlu": int(sol.nlu), "solver_status": int(sol.status)}
    if sol.status == 1:
        return t_eval, states, "failed", _gimbal_message(settings.gimbal_margin, float(sol.t_events[0][0])), solver
    if sol.status != 0:
        return t_eval, states, "failed", f"solver failed: {sol.message}", solver
    if not np.all(np.isfinite(states)):
        bad = int(np.argmin(np.all(np.isfinite(states), axis=1)))
        states[bad:] = np.nan
        return t_eval, states, "failed", f"non-finite state at t = {t_eval[bad]:.6g} s", solver
    return t_eval, states, "success", str(sol.message), solver


def evaluate_outputs(variant: Variant, time: np.ndarray, states: np.ndarray) -> dict[str, np.ndarray]:
    """Every output variable along sampled ``states`` (shape (n, n_state)) at ``time`` (n,).

    Adds ``lyapunov_rate_numerical`` [W], the derivative of v along the samples
    (:func:`rbstab.summary.numerical_rate`), to :meth:`Variant.evaluate`.
    """
    with np.errstate(all="ignore"):
        outputs = variant.evaluate(states)
    outputs["lyapunov_rate_numerical"] = numerical_rate(time, outputs["lyapunov"])
    return outputs


def _result(config, variant, time, states, status, message, solver, wall_time) -> RunResult:
    outputs = evaluate_outputs(variant, time, states)
    return RunResult(
        config=config,
        time=time,
        outputs=outputs,
        status=status,
        message=message,
        solver=solver,
        wall_time=wall_time,
        summary=summarize(time, outputs),
    )


def simulate(config: "RunConfig", timeout: float | None = None) -> RunResult:
    """Run one validated configuration through the scipy core.

    Parameters
    ----------
    config : RunConfig
        From :func:`rbstab.config.load_config` (already validated).
    timeout : float, optional
        Wall-time budget of the integration [s]; past it the run fails with a message.

    Returns
    -------
    RunResult
        Never raises for a physical or numerical failure: those are ``status="failed"``.
    """
    start = _time.perf_counter()
    variant = config.make_variant()
    y0 = variant.initial_state(config.initial_state)
    time, states, status, message, solver = solve(variant, y0, config.simulation, timeout)
    solved = _time.perf_counter()
    result = _result(config, variant, time, states, status, message, solver, 0.0)
    end = _time.perf_counter()
    result.wall_time = end - start
    result.timing = {"integration": solved - start, "postprocess": end - solved}
    return result


def batch_key(config: "RunConfig") -> str:
    """Configs with equal keys differ at most in name and initial state: one batch
    (:func:`rbstab.config.group_key` of ``config.resolved``)."""
    from .config import group_key

    return group_key(config.resolved)


#: Runs whose outputs :func:`simulate_many` evaluates together before yielding them (the
#: numerical rate of v is one finite-difference pass for all of them, the summaries are computed for
#: all at once); bounds the memory of outputs held at once to this many runs.
POSTPROCESS_BLOCK = 32

#: Runs per :meth:`Variant.evaluate` call inside a post-processing block: each numpy
#: operation then acts on ``EVALUATE_RUNS * n_samples`` values, enough to make numpy's
#: per-call overhead small and few enough for the temporaries to stay in the CPU caches.
EVALUATE_RUNS = 4


def _results_of_block(configs, variant, sol, block: range, chunk, share) -> list[tuple[int, RunResult]]:
    """Post-process runs ``block`` (a range of indices into the batch ``sol``) into RunResults.

    The block's samples are evaluated :data:`EVALUATE_RUNS` runs per call, the numerical
    rate of v for the whole block in one finite-difference pass, the summaries all at once; a run's
    outputs are views of the arrays of its :meth:`Variant.evaluate` call (vectors
    strided, see there). Everything is elementwise or
    per run, so a run gets the same bits whatever else is in its block or chunk.
    """
    t0 = _time.perf_counter()
    parts = []
    with np.errstate(all="ignore"):
        for lo in range(block.start, block.stop, EVALUATE_RUNS):
            parts.append(variant.evaluate(sol.y[lo : min(lo + EVALUATE_RUNS, block.stop)]))
    rates = numerical_rate(sol.t, np.concatenate([p["lyapunov"] for p in parts]))
    summaries = []
    lo = 0
    for part in parts:
        part["lyapunov_rate_numerical"] = rates[lo : lo + len(part["lyapunov"])]
        lo += len(part["lyapunov"])
        summaries.extend(summarize_many(sol.t, part))
    per_run = (_time.perf_counter() - t0) / len(block)
    results = []
    j = 0
    for part in parts:
        for b in range(len(part["lyapunov"])):
            k = block.start + j
            ok = int(sol.status[k]) == 0
            result = RunResult(
                config=configs[chunk[k]],
                time=sol.t,
                outputs={key: value[b] for key, value in part.items()},
                status="success" if ok else "failed",
                message=sol.message[k],
                solver={"nfev": int(sol.nfev[k]), "njev": 0, "nlu": 0, "solver_status": 0 if ok else -1},
                wall_time=share + per_run,
                summary=summaries[j],
                timing={"integration": share, "postprocess": per_run},
            )
            results.append((chunk[k], result))
            j += 1
    return results


def simulate_many(configs: Sequence["RunConfig"], *, engine: str = "batch", chunk_size: int = 512) -> Iterator[tuple[int, RunResult]]:
    """Run many validated configurations; yields ``(index into configs, RunResult)``.

    With ``engine="batch"``, configurations that differ only in ``name`` and
    ``initial_state`` and use RK23, RK45 or DOP853 are integrated together by
    :func:`rbstab.batch.integrate_batch` (per-run step-size control; each run takes the
    steps scipy would take alone), ``chunk_size`` runs at a time; everything else goes
    through :func:`simulate`. The batch's right-hand side is
    :func:`rbstab.traced.traced_rhs` of the group's variant (generated from the model, the
    same bits as ``variant.rhs``; traced once per group, ~8 ms) where the model can be
    traced, ``variant.rhs`` otherwise. Results are yielded as each chunk finishes, so at most one
    chunk of trajectories (``chunk_size * n_samples * n_state`` floats) and the outputs
    of :data:`POSTPROCESS_BLOCK` runs are held at once. Each result's ``wall_time`` is its
    share of the chunk's integration plus its own post-processing [s] (split in
    ``timing``).

    Raises
    ------
    ValueError
        For an unknown engine (allowed: :data:`ENGINES`) or ``chunk_size < 1``.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine: found {engine!r}; expected one of {', '.join(ENGINES)}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size: found {chunk_size}; expected an integer >= 1")
    from .batch import SUPPORTED_METHODS, integrate_batch
    from .traced import traced_rhs

    groups: dict[str, list[int]] = {}
    for i, config in enumerate(configs):
        if engine == "batch" and config.simulation.method in SUPPORTED_METHODS:
            groups.setdefault(batch_key(config), []).append(i)
        else:
            yield i, simulate(config)
    for members in groups.values():
        first = configs[members[0]]
        variant = first.make_variant()
        # the same bits as variant.rhs, about half its time per call (None: not traceable)
        fun = traced_rhs(variant) or variant.rhs
        sim = first.simulation
        for lo in range(0, len(members), chunk_size):
            chunk = members[lo : lo + chunk_size]
            start = _time.perf_counter()
            y0 = np.stack([variant.initial_state(configs[i].initial_state) for i in chunk])
            sol = integrate_batch(
                fun,
                y0,
                sim.t_end,
                sim.n_samples,
                method=sim.method,
                rtol=sim.rtol,
                atol=sim.atol,
                max_step=sim.max_step,
                gimbal_margin=sim.gimbal_margin,
            )
            share = (_time.perf_counter() - start) / len(chunk)
            for lo_b in range(0, len(chunk), POSTPROCESS_BLOCK):
                block = range(lo_b, min(lo_b + POSTPROCESS_BLOCK, len(chunk)))
                yield from _results_of_block(configs, variant, sol, block, chunk, share)
