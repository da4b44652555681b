"""The basin of attraction by simulation over a 2-D slice of initial states.

Two initial-state entries (``initial_state.omega.0`` ...) vary over even grids; every
other entry keeps the configuration's value. Each grid point is one run of the compiled
engine (:class:`rbstab.analysis.runs.Runs`, many runs per compiled call, in ``jobs``
threads), and
is classified by the rule a sweep classifies its runs with
(:func:`rbstab.convergence.converged`), applied from every sample on:

- ``converged`` (0): the run reached t_end and |v| <= ratio |v(0)| + 1e-12 J
  (:data:`rbstab.convergence.SAMPLE_RULE`) from some time on;
- ``not converged`` (1): it reached t_end with more of v left;
- ``failed`` (2): gimbal lock (|theta_2| reached pi/2 - gimbal_margin, eq 5), the
  admissible region left (``simulation.limits``; a point outside it fails at t = 0), a solver
  failure, a non-finite state, or an initial state outside the domain.

The time to converge is the first sample time from which the bound holds [s] (its
resolution: the sample spacing t_end / (n_samples - 1)).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO, converged
from ..engine.registry import DEFAULT_ENGINE, get_engine
from ..layout import BLOCK_UNITS

__all__ = ["state_entry", "BasinAxis", "BasinMap", "basin_map", "time_to_converge", "OUTCOMES", "DEFAULT_SAMPLES"]

#: Outcome codes of a grid point (the ``flag_values`` of the file's ``basin_outcome``).
OUTCOMES = ("converged", "not converged", "failed")
#: Samples per basin run (the time-to-converge resolution is t_end / (DEFAULT_SAMPLES - 1)).
DEFAULT_SAMPLES = 201
#: A hinge's child's initial-state entries (its angle q and rate u), keys without an index.
HINGE_ENTRIES = ("q", "u")
_AXIS = re.compile(r"^\s*(?P<key>[^=]+?)\s*=\s*(?P<lo>[^:]+):(?P<hi>[^:]+):(?P<n>[^:]+)\s*$")


def state_entry(key: str):
    """The :class:`~rbstab.config.paths.KeyPath` of one entry of an initial state,
    ``initial_state.<block>.<i>`` (block ``theta``, ``omega``, ``x``, ``v``, ``d``), or of
    a chain's body, ``initial_state.<body>.<block>.<i>`` (the path's ``entry`` the body's
    name).

    Raises
    ------
    ValueError
        One line: the key's problem (:func:`~rbstab.config.paths.parse_any_key`), or that it
        names no single entry of an initial state, with those allowed.
    """
    from ..config import INITIAL_STATE_BLOCKS  # heavy: yaml
    from ..config.paths import KeyPathError, parse_any_key, parse_key  # heavy: pydantic

    try:
        path = parse_any_key(key)
    except KeyPathError as exc:
        raise ValueError(exc.problem) from None
    hinge = path.section == "initial_state" and path.entry is not None and path.field in HINGE_ENTRIES
    if path.section != "initial_state" or (len(path.index) != 1 and not hinge):
        allowed = ", ".join(f"initial_state.{k}.0..{parse_key(f'initial_state.{k}').shape[0] - 1}"
                            for k in INITIAL_STATE_BLOCKS)
        raise ValueError(f"'{key}' is not one entry of an initial state; allowed: {allowed} (a tree's: "
                         "initial_state.<body>.<block>.<i>, and a hinge's child's initial_state.<body>.<q|u>)")
    return path


@dataclass(frozen=True)
class BasinAxis:
    """One axis of the slice: an initial-state entry over an even grid.

    Attributes
    ----------
    key : str
        ``initial_state.<block>.<0|1|2>`` (block ``theta``, ``omega``, ``x``, ``v``, ``d``).
    values : ndarray, shape (n,)
        The grid (units of the block, :attr:`units`).
    """

    key: str
    values: np.ndarray

    @classmethod
    def parse(cls, text: str) -> "BasinAxis":
        """From ``KEY=lo:hi:n`` (``initial_state.omega.0=-60:60:41``). Whether a
        configuration's state has that entry: :func:`rbstab.analysis.runs.check_entries`.

        Raises
        ------
        ValueError
            Naming the text, what is wrong and what is allowed.
        """
        match = _AXIS.match(text)
        if not match:
            raise ValueError(f"--basin {text!r}: expected KEY=lo:hi:n, e.g. initial_state.omega.0=-60:60:41")
        key = match["key"]
        try:
            state_entry(key)
        except ValueError as exc:
            raise ValueError(f"--basin {text!r}: {exc}") from None
        try:
            lo, hi, n = float(match["lo"]), float(match["hi"]), int(match["n"])
        except ValueError:
            raise ValueError(f"--basin {text!r}: lo and hi must be numbers and n an integer") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi) or n < 2:
            raise ValueError(f"--basin {text!r}: expected finite lo < hi and n >= 2 points, found "
                             f"lo={lo:g}, hi={hi:g}, n={n}")
        return cls(key, np.linspace(lo, hi, n))

    @property
    def block(self) -> str:
        """The state block (``theta`` ... ``controller_state``, or a hinge's ``q``, ``u``)."""
        from ..config import INITIAL_STATE_BLOCKS  # heavy: yaml

        field = state_entry(self.key).field
        return field if field in HINGE_ENTRIES else INITIAL_STATE_BLOCKS[field]

    @property
    def index(self) -> int:
        """The component (0, 1, 2; 0 for a hinge's q or u, 0 or 1 for a universal joint's)."""
        return (*state_entry(self.key).index, 0)[0]

    @property
    def body(self) -> str | None:
        """A chain's body the entry belongs to (None: a one-body config's)."""
        return state_entry(self.key).entry

    @property
    def units(self) -> str:
        return BLOCK_UNITS[self.block]

    @property
    def label(self) -> str:
        """``omega_1 [rad s-1]`` (component numbered from 1, as in the paper; a chain's
        ``legs theta_1 [rad]``)."""
        body = f"{self.body} " if self.body is not None else ""
        if self.block in HINGE_ENTRIES and not state_entry(self.key).index:  # a hinge's q, u
            return f"{body}{self.block} [{self.units}]"
        return f"{body}{self.block}_{self.index + 1} [{self.units}]"


@dataclass(frozen=True)
class BasinMap:
    """Outcome of every grid point of a slice (see the module docstring).

    Attributes
    ----------
    axes : (BasinAxis, BasinAxis)
        First axis along rows, second along columns.
    outcome : ndarray of int8, shape (n0, n1)
        Index into :data:`OUTCOMES`.
    time_to_converge : ndarray, shape (n0, n1)
        [s]; NaN where not converged.
    lyapunov_initial, lyapunov_final : ndarray, shape (n0, n1)
        v(0), v(t_end) [J] (NaN where the run did not reach t_end).
    initial_states : ndarray, shape (n0, n1, n_state)
        The initial state of each point, in the variant's layout.
    ratio : float
        The convergence ratio.
    t_end : float
        [s]
    messages : dict of str -> int
        How many points failed with each message (gimbal lock, ...).
    """

    axes: tuple[BasinAxis, BasinAxis]
    outcome: np.ndarray
    time_to_converge: np.ndarray
    lyapunov_initial: np.ndarray
    lyapunov_final: np.ndarray
    initial_states: np.ndarray
    ratio: float
    t_end: float
    messages: dict

    def counts(self, mask: np.ndarray | None = None) -> dict[str, int]:
        """Points per outcome (inside ``mask`` if given)."""
        outcome = self.outcome if mask is None else self.outcome[mask]
        return {name: int(np.sum(outcome == i)) for i, name in enumerate(OUTCOMES)}


def time_to_converge(time: np.ndarray, lyapunov: np.ndarray, ratio: float) -> float:
    """First sample time from which every sample has converged
    (:func:`rbstab.convergence.converged` with v(0), the largest rise of v up to the sample
    and the sample's v) [s]; NaN if v(t_end) has not.

    Parameters
    ----------
    time : ndarray, shape (n,)
        [s]
    lyapunov : ndarray, shape (n,)
        v [J] at ``time`` (NaN after a failure: never converged).
    ratio : float
    """
    v = np.asarray(lyapunov, dtype=float)
    with np.errstate(invalid="ignore"):
        rise = np.maximum.accumulate(v - np.minimum.accumulate(v))  # the largest rise so far
    above = ~converged(True, v[0], v, ratio, rise)
    if above[-1]:
        return float("nan")
    last = np.flatnonzero(above)
    return float(time[last[-1] + 1]) if last.size else float(time[0])


#: Why a grid point outside the domain of the Euler-angle model is not run.
OUTSIDE = ("initial state outside the domain: |theta_2| >= pi/2 - simulation.gimbal_margin, where B(theta) is "
           "singular (gimbal lock, eq 5)")


def _on_gpu(runs, states: np.ndarray, points: np.ndarray, ratio: float, n_samples: int, t_end: float) -> list[tuple]:
    """(index, outcome, time to converge, v(t_end), message) of the grid ``points`` (initial
    ``states`` (k, n_state)) as runs of ``runs`` (:class:`rbstab.analysis.runs.Runs`) on the
    GPU, each run's time to converge taken as it goes (:meth:`~rbstab.analysis.runs.Runs.streamed`)."""
    ok, last_above, v_final, messages = runs.streamed(states, n_samples, ratio)
    n = int(n_samples)
    time = np.linspace(0.0, t_end, n)
    t = np.where(ok & (last_above < n - 1), time[np.minimum(last_above + 1, n - 1)], np.nan)
    code = np.where(np.isfinite(t), 0, np.where(ok, 1, 2))
    return list(zip(points.tolist(), code.tolist(), t.tolist(), v_final.tolist(), messages))


def _on_cpu(runs, states: np.ndarray, points: np.ndarray, ratio: float, n_samples: int, t_end: float) -> list[tuple]:
    """:func:`_on_gpu`'s rows of the grid ``points`` (initial ``states``) as runs of
    ``runs`` (:class:`rbstab.analysis.runs.Runs`) on the CPU, from each run's samples of v."""
    ok, v, messages = runs.traces(states, n_samples)
    time = np.linspace(0.0, t_end, int(n_samples))
    rows = []
    for k, i in enumerate(points.tolist()):
        t = time_to_converge(time, v[k], ratio) if ok[k] else np.nan
        rows.append((i, 0 if np.isfinite(t) else (1 if ok[k] else 2), t, float(v[k, -1]), messages[k]))
    return rows


def basin_map(
    config,
    axes: Sequence[BasinAxis],
    *,
    ratio: float = DEFAULT_LYAPUNOV_RATIO,
    n_samples: int = DEFAULT_SAMPLES,
    jobs: int = 1,
    engine: str = DEFAULT_ENGINE,
) -> BasinMap:
    """Simulate every point of the slice spanned by ``axes`` (module docstring).

    Parameters
    ----------
    config : RunConfig
        The configuration whose initial state the slice passes through; its bodies, laws,
        gains and simulation settings are used for every run (``n_samples`` replaced). A
        tree's entries are ``initial_state.<body>.<block>.<i>``; a body whose ``x`` (``v``)
        the configuration leaves out is placed on its joint at every point, as the
        configuration places it (E_j = 0, dE_j/dt = 0), so a tilt moves the bodies it
        carries.
    axes : two BasinAxis
        Different keys.
    ratio : float
        Convergence ratio (0 < ratio < 1).
    n_samples : int
        Samples per run (>= 2).
    jobs : int
        Threads that integrate the runs (the compiled driver releases Python's lock).
    engine : {"compiled", "cuda"}
        A compiled engine of :data:`rbstab.engine.ENGINES`: the CPU's, or the GPU's
        (:mod:`rbstab.engine.cuda`: every point in one process, each run's time to converge
        taken as it goes; the pure sign law and implicit methods stay on the CPU). The same
        outcomes and times (on a GPU, up to its rounding).

    Raises
    ------
    ValueError
        For two equal keys, or a key that names no entry of the configuration's state
        (a body of a tree it does not have, or a D its joint does not have).
    rbstab.engine.cuda.CudaUnavailable
        For ``engine="cuda"`` where no GPU, driver or numba-cuda is found.
    """
    from ..simulator import uses_compiled_engine  # heavy: numba
    from .runs import Runs, check_axes  # heavy: numba

    check_axes(config, axes)
    shape = (len(axes[0].values), len(axes[1].values))
    first, second = np.meshgrid(axes[0].values, axes[1].values, indexing="ij")
    gpu = get_engine(engine).gpu and uses_compiled_engine(config, engine)
    runs = Runs(config, engine=engine if gpu else "compiled", jobs=jobs)
    states = runs.states(axes, np.column_stack([first.ravel(), second.ravel()]))
    # the one check an initial state of a valid configuration can fail (the grid's values are finite)
    inside = np.ones(len(states), dtype=bool)
    if runs.compiled.one_body:  # the body's theta_2, in either spelling (a tree's runs fail at t = 0 naming it)
        inside = np.abs(states[:, 1]) < np.pi / 2 - config.simulation.gimbal_margin
    points = np.flatnonzero(inside)
    outcome = np.full(len(states), 2, dtype=np.int8)
    messages: dict[str, int] = {OUTSIDE: int(len(states) - len(points))} if len(points) < len(states) else {}
    t_conv = np.full(len(states), np.nan)
    v_final = np.full(len(states), np.nan)
    rows = []
    if len(points):
        rows = (_on_gpu if gpu else _on_cpu)(runs, states[points], points, ratio, n_samples, config.simulation.t_end)
    for index, code, t, v1, message in rows:
        outcome[index], t_conv[index], v_final[index] = code, t, v1
        if message:
            messages[message] = messages.get(message, 0) + 1
    return BasinMap(
        axes=(axes[0], axes[1]),
        outcome=outcome.reshape(shape),
        time_to_converge=t_conv.reshape(shape),
        lyapunov_initial=runs.lyapunov(states).reshape(shape),
        lyapunov_final=v_final.reshape(shape),
        initial_states=states.reshape(*shape, -1),
        ratio=ratio,
        t_end=config.simulation.t_end,
        messages=messages,
    )
