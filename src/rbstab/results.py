"""The results of runs, below the engines' callers and the files that store them:
:class:`RunResult` (one run) and :class:`RunBlock` (runs that share their sample times,
as columns), and :func:`plain`, the numpy-to-Python conversion of their values (and of
every value written to YAML, JSON or a file's attributes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .layout import is_chain

if TYPE_CHECKING:  # pragma: no cover
    from .config import RunConfig

__all__ = ["RunResult", "RunBlock", "plain", "row"]


def plain(value: Any) -> Any:
    """``value`` as plain Python: a numpy array as (nested) lists, a numpy scalar as its
    Python number, bool or str; anything else as it is."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    return value


def row(columns: dict[str, Sequence], j: int) -> dict:
    """Entry ``j`` of each column, as plain Python values (:func:`plain`)."""
    return {key: plain(values[j]) for key, values in columns.items()}


@dataclass
class RunResult:
    """Outcome of one run.

    Attributes
    ----------
    config : RunConfig
        The validated configuration that was run (a chain's: :func:`rbstab.simulator.simulate`).
    time : ndarray, shape (n_samples,)
        Sample times [s], evenly spaced on [0, t_end]. From :func:`rbstab.simulator.simulate_many`'s
        compiled engine, a read-only array that the results of a block of runs with the
        same ``t_end`` share (copy it to change it).
    outputs : dict of str -> ndarray
        Every variable of the result file, shape (n_samples, 3) or (n_samples,): state
        blocks, constraint quantities, controls, ``lyapunov``, ``lyapunov_rate``,
        ``lyapunov_rate_numerical`` and the terms of v. Rows after a failure are NaN. A
        chain's (:func:`rbstab.variants.chain.evaluate`): per body (n_samples, n_bodies, 3),
        per joint (n_samples, n_joints, 3) or (n_samples, n_joints), scalars (n_samples,).
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
    switching : Switchings or None
        The located events of a pure-sign-law run (:mod:`rbstab.engine.switching`), else None.
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
    switching: object = None

    @property
    def name(self) -> str:
        """The run's name (``config.name``), also its result file's stem."""
        return self.config.name

    @property
    def ok(self) -> bool:
        """Whether the run reached ``t_end`` (``status == "success"``)."""
        return self.status == "success"


@dataclass
class RunBlock:
    """Outcomes of k runs that share their sample times, as columns: what
    :func:`rbstab.simulator.simulate_blocks` gives and a store file takes at once
    (:meth:`rbstab.io.chunk.ChunkWriter.add_block`); :meth:`result` is one run's
    :class:`RunResult` (views of the block's arrays).

    Attributes
    ----------
    configs : list of RunConfig (or None each), length k
    time : ndarray, shape (n_samples,)
        The runs' sample times [s] (read-only when the block comes from the compiled engine).
    outputs : dict of str -> ndarray
        :attr:`RunResult.outputs` with a leading run axis: shape (k, n_samples, 3) or
        (k, n_samples).
    summaries : dict of str -> ndarray
        :func:`rbstab.summary.summary_table`: figure -> its k values, shape (k,) or (k, 3).
    status, message : list of str
    solver : dict of str -> sequence
        :attr:`RunResult.solver` as columns: key -> its k values.
    wall_time : ndarray, shape (k,)
        [s]
    timing : dict of str -> ndarray
        :attr:`RunResult.timing` as columns: key -> its k values [s].
    switching : list
        Each run's :attr:`RunResult.switching`.
    stride : int
        Samples of the runs' grid (``simulation.n_samples`` on [0, t_end]) from one entry
        of ``time`` to the next: 1, or a thinned trace of the ``cuda`` engine.
    variants : list of str
        Each run's controller variant (its one joint's law; given where ``configs`` are None;
        ``chain`` for a chain's runs).
    joints, bodies : tuple of str, optional
        The joint and body names of a block of one chain's runs: its per-joint and per-body
        summary figures have shape (k, n_joints) or (k, n_bodies[, 3]), in this order.
    """

    configs: list
    time: np.ndarray
    outputs: dict[str, np.ndarray]
    summaries: dict[str, np.ndarray]
    status: list[str]
    message: list[str]
    solver: dict[str, Sequence]
    wall_time: np.ndarray
    timing: dict[str, np.ndarray]
    switching: list
    stride: int = 1
    variants: list = None
    joints: tuple | None = None
    bodies: tuple | None = None

    def __post_init__(self) -> None:
        if self.variants is None:
            self.variants = ["chain" if self.joints is not None else c.chain.joints[0].variant for c in self.configs]

    def __len__(self) -> int:
        return len(self.status)

    def result(self, j: int) -> RunResult:
        """Run ``j`` of the block as a :class:`RunResult` (its outputs are views)."""
        return RunResult(config=self.configs[j], time=self.time,
                         outputs={key: value[j] for key, value in self.outputs.items()},
                         status=self.status[j], message=self.message[j], solver=row(self.solver, j),
                         wall_time=float(self.wall_time[j]), summary=row(self.summaries, j),
                         timing=row(self.timing, j), switching=self.switching[j])

    @classmethod
    def of(cls, result: RunResult) -> "RunBlock":
        """A block of one run (its outputs as views with a leading axis of 1)."""
        return cls([result.config], result.time, {key: np.asarray(value)[None] for key, value in result.outputs.items()},
                   {key: np.asarray([value], dtype=object if isinstance(value, str) else None)
                    for key, value in result.summary.items()},
                   [result.status], [result.message], {key: [value] for key, value in result.solver.items()},
                   np.array([result.wall_time], dtype=float), {key: np.array([value]) for key, value in result.timing.items()},
                   [result.switching], **members(result.config))


def members(config) -> dict:
    """``joints`` and ``bodies`` of a chain config (its joint and body names, as a
    :class:`RunBlock` takes them); empty for one body's."""
    if not is_chain(config):
        return {}
    return {"joints": tuple(config.chain.joint_names), "bodies": tuple(config.chain.body_names)}

