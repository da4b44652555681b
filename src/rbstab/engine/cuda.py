"""The CUDA engine: the compiled engine's runs on an NVIDIA GPU, one thread a run.

The physics and the Runge-Kutta step are the CPU engine's own functions: numba-cuda
compiles every rbstab ``@jit`` function that a CUDA kernel calls as a device function of
the same Python source (:func:`rbstab.variants.kernels.state_rate`,
:func:`~rbstab.variants.kernels.output_row`, :func:`rbstab.engine.rk.initial_step`,
:func:`~rbstab.engine.rk.dense_coefficients`, :func:`~rbstab.engine.rk.dense_value`,
:func:`rbstab.engine.integrate.attempt_step`, :func:`~rbstab.engine.integrate.locate_event`
and the streaming summary of :mod:`rbstab.summary`). Only the driver loop is written here:
:func:`rbstab.engine.integrate._run`'s loop with one step *attempt* per pass (a thread
whose step is rejected tries again on the next pass with the others of its warp, instead
of stalling them), work arrays in thread-local memory, and a persistent grid whose
threads take the next run from an atomic counter when theirs ends.

A run gives what the CPU engine gives, computed as it goes: its status, stop time,
right-hand-side evaluations and steps, the outputs at its last sample, the summary
figures (:func:`rbstab.summary.stream_table`) and, if asked, every ``stride``-th sample's
outputs and numerical dv/dt (a thinned trace). Under numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) the same driver runs as Python over the CPU-compiled
functions and gives the CPU engine's bits.

Not here: the pure sign law of ``sliding`` (``boundary_layer: 0``), whose event-driven
integrator (:mod:`rbstab.engine.switching`) stays on the CPU, and the implicit methods.
"""

from __future__ import annotations

import functools
import math
import sys
import time as _time
from dataclasses import dataclass
from types import FunctionType
from typing import Iterator

import numpy as np

# numba-cuda 0.30.4 (numba_cuda/numba/cuda/np/arrayobj.py) registers an overload of
# np.row_stack whenever numpy >= 2.0, and numpy 2.5 removed np.row_stack: without this
# alias its CUDA target fails to load on numpy 2.5 (np.row_stack was np.vstack's alias).
if "row_stack" not in vars(np):
    np.row_stack = np.vstack

from numba import cuda  # noqa: E402  numba-cuda's target where installed (rbstab[cuda]); _cuda() checks which

from ..convergence import DEFAULT_LYAPUNOV_RATIO
from ..jit import CACHE_DIR, cache_is_warm, mark_warm
from ..kinematics import GIMBAL_LOCK_ANGLE
from ..layout import N_OUTPUTS
from ..model import PARAMETERS
from ..summary import (ACCUMULATOR_SIZE, NUMERICAL_RATE_AT, short_stencils, stencil_weights, stream_finish,
                       stream_sample, stream_start)
from ..variants.kernels import output_row, state_rate
from .integrate import REJECTED, attempt_step, gimbal_event, locate_event, sample_time, step_bounds
from .rk import DOP853, INTERPOLANT_ROWS, N_STAGES, STAGE_ROWS, dense_coefficients, dense_value, initial_step
from .settings import SETTINGS, Work
from .tableaus import METHODS
from .status import GIMBAL_LOCK, STEP_LIMIT, SUCCESS, TIMEOUT

__all__ = ["CudaUnavailable", "INSTALL_HINT", "check_available", "CudaChunk", "integrate_chunks_cuda",
           "TRACE_COLUMNS", "THREADS_PER_BLOCK"]

#: How to get what ``--engine cuda`` needs.
INSTALL_HINT = 'pip install "rbstab[cuda]" (numba-cuda and the CUDA 12 wheels) and an NVIDIA driver'
#: Columns of a trace's row: the outputs (N_OUTPUTS) and the numerical dv/dt.
TRACE_COLUMNS = N_OUTPUTS + 1
#: Threads per block (runs of a warp step together; 128-256 within ~7 % on an H100).
THREADS_PER_BLOCK = 128
#: Passes of a thread's loop between two readings of the GPU's clock (the launch's limit).
CLOCK_EVERY = 64
#: Device memory [bytes] the traces of one launch may take at most.
TRACE_BYTES = 2 * 2**30


class CudaUnavailable(RuntimeError):
    """``--engine cuda`` cannot run here; the message is one line: what is missing and how
    to install it."""


def _cuda():
    """numba-cuda's ``numba.cuda`` (the NVIDIA-maintained target, not numba's built-in
    one), or CudaUnavailable."""
    if getattr(cuda, "implementation", "") != "NVIDIA":
        raise CudaUnavailable(f"--engine cuda needs numba-cuda, which is not installed; install it: {INSTALL_HINT}")
    return cuda


def simulated() -> bool:
    """Whether numba's CUDA simulator stands in for a GPU (``NUMBA_ENABLE_CUDASIM=1``)."""
    from numba import config  # heavy: numba (this module is imported only by --engine cuda)

    return bool(config.ENABLE_CUDASIM)


def check_available() -> None:
    """Return if ``--engine cuda`` can run here (a GPU, its driver and numba-cuda; or the
    simulator); else raise :class:`CudaUnavailable` with one line naming what is missing."""
    cuda = _cuda()
    if simulated():
        return
    if not cuda.is_available():
        raise CudaUnavailable("--engine cuda found no usable NVIDIA GPU: no CUDA driver or device "
                              f"(numba.cuda.is_available() is False); it needs {INSTALL_HINT}")


# -- the GPU's clock -----------------------------------------------------------------------------------
def _clock_ns_python():
    """The simulator's stand-in for :func:`globaltimer` [ns]."""
    return _time.monotonic_ns()


def _globaltimer_intrinsic():
    """PTX's ``%globaltimer`` [ns] as a function device code calls (None without numba-cuda)."""
    try:
        from llvmlite import ir  # heavy: llvmlite (with numba)
        from numba.cuda import types  # optional: numba-cuda
        from numba.cuda.extending import intrinsic  # optional: numba-cuda
    except ImportError:
        return None

    @intrinsic
    def globaltimer(typingctx):
        """The GPU's global nanosecond timer (PTX ``%globaltimer``)."""

        def codegen(context, builder, signature, args):
            asm = ir.InlineAsm(ir.FunctionType(ir.IntType(64), []), "mov.u64 $0, %globaltimer;", "=l",
                               side_effect=True)
            return builder.call(asm, [])

        return types.int64(), codegen

    return globaltimer


#: The kernel's clock, a global of this module: a closure's contents key numba-cuda's disk
#: cache, and an intrinsic pickles differently in every process.
globaltimer = _globaltimer_intrinsic()


# -- the kernel ---------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def kernel(method: int, n_state: int):
    """The CUDA kernel of the runs of method number ``method`` and ``n_state`` states (the
    shapes of its thread-local work arrays), compiled on first use and cached on disk.

    Launched as ``kernel[blocks, THREADS_PER_BLOCK](codes, params, y0, settings, first,
    weights, short, stride, full, ratio, counter, limit_ns, status, t_stop, nfev, n_steps,
    last, acc, trace)``; see :func:`integrate_chunks_cuda` for the arrays.
    """
    _cuda()
    from numba import float64, from_dtype  # heavy: numba (this module is imported only by --engine cuda)

    n_rows, q_rows, n_stages = int(STAGE_ROWS[method]), int(INTERPOLANT_ROWS[method]), int(N_STAGES[method])
    dop853 = method == DOP853
    parameters = from_dtype(PARAMETERS)

    def run_all(codes, params, y0s, settings, first, weights, short, stride, full, ratio, counter, limit_ns,
                status_o, t_stop_o, nfev_o, n_steps_o, last_o, acc_o, trace_o):
        K = cuda.local.array((n_rows, n_state), float64)
        Q = cuda.local.array((q_rows, n_state), float64)
        y = cuda.local.array(n_state, float64)
        f = cuda.local.array(n_state, float64)
        y_new = cuda.local.array(n_state, float64)
        scale = cuda.local.array(n_state, float64)
        work = cuda.local.array(n_state, float64)
        sample = cuda.local.array(n_state, float64)
        row = cuda.local.array(N_OUTPUTS, float64)
        acc = cuda.local.array(ACCUMULATOR_SIZE, float64)
        record = cuda.local.array(1, parameters)
        w = Work(K, Q, y_new, scale, work)
        n_runs = y0s.shape[0]
        n_samples = first.shape[0]
        deadline = globaltimer() + limit_ns
        passes = 0
        k = cuda.atomic.add(counter, 0, 1)
        while k < n_runs:
            # a run: its start
            code = codes[k]
            # the run's record copied to thread-local memory: its fields are read at every
            # right-hand side, and the copy reads it from device memory once, coalesced
            shared = min(k, params.shape[0] - 1)  # one record for every run, or a record a run
            source = params[shared: shared + 1].view(np.float64)
            copy = record.view(np.float64)
            for i in range(copy.shape[0]):
                copy[i] = source[i]
            p = record[0]
            s = settings[k]
            trace = trace_o[min(k, trace_o.shape[0] - 1)]
            t_end = s.t_end
            limit = GIMBAL_LOCK_ANGLE - s.gimbal_margin
            for i in range(n_state):
                y[i] = y0s[k, i]
            stream_start(acc)
            state_rate(code, y, p, f)
            h_abs = initial_step(code, p, s, y, f, w)
            nfev = 2
            t = 0.0
            j = 0
            n_steps = 0
            status = SUCCESS
            h_abs = step_bounds(s, t, h_abs)
            rejected = False
            while t < t_end:
                passes += 1
                if passes % CLOCK_EVERY == 0 and globaltimer() > deadline:
                    status = TIMEOUT
                    break
                if n_steps >= s.max_steps:
                    status = STEP_LIMIT
                    break
                outcome, t_new, h, h_abs = attempt_step(code, p, s, t, y, f, h_abs, rejected, w)
                if outcome == REJECTED:
                    nfev += n_stages
                    rejected = True
                    continue
                if outcome != SUCCESS:
                    status = outcome
                    break
                nfev += n_stages
                n_steps += 1
                t_stop = t_new
                event = gimbal_event(y, limit) >= 0 and gimbal_event(y_new, limit) <= 0
                if event or (j < n_samples and sample_time(j, n_samples, t_end) <= t_new):
                    nfev += dense_coefficients(code, p, y, y_new, K[n_stages], h, method, w)
                if event:
                    t_stop, _ = locate_event(t, h, y, Q, dop853, limit, work)
                while j < n_samples and sample_time(j, n_samples, t_end) <= t_stop:
                    dense_value((sample_time(j, n_samples, t_end) - t) / h, h, y, Q, dop853, sample)
                    output_row(code, sample, p, row, full)
                    stream_sample(acc, j, row, first, weights, trace, stride, ratio)
                    j += 1
                if event:
                    status = GIMBAL_LOCK
                    t = t_stop
                    break
                t = t_new
                for i in range(n_state):
                    y[i] = y_new[i]
                    f[i] = K[n_stages, i]
                h_abs = step_bounds(s, t, h_abs)
                rejected = False
            # its end: results, and the next run (none after the launch's limit)
            stream_finish(acc, first, weights, short, trace, stride)
            status_o[k] = status
            t_stop_o[k] = t
            nfev_o[k] = nfev
            n_steps_o[k] = n_steps
            for i in range(N_OUTPUTS):
                last_o[k, i] = row[i] if j > 0 else math.nan
            for i in range(ACCUMULATOR_SIZE):
                acc_o[k, i] = acc[i]
            # the samples after a stop: the outputs of a NaN state, as the CPU engine's
            for i in range(n_state):
                sample[i] = math.nan
            for i in range(-(-j // stride) * stride, min(n_samples, trace.shape[0] * stride), stride):
                output_row(code, sample, p, row, full)
                for c in range(N_OUTPUTS):
                    trace[i // stride, c] = row[c]
                trace[i // stride, NUMERICAL_RATE_AT] = math.nan
            if status == TIMEOUT:
                break
            k = cuda.atomic.add(counter, 0, 1)

    if simulated():
        return cuda.jit(_simulator_function(run_all))
    from numba.cuda.core import config  # optional: numba-cuda

    # beside the CPU kernels, in the folder of this version of the compiled sources (rbstab.jit)
    config.CACHE_DIR = str(CACHE_DIR)
    return cuda.jit(cache=True)(run_all)


def _say_compiling(method: int, n_state: int) -> str | None:
    """One line on stderr the first time this version compiles the kernel of ``method`` and
    ``n_state`` (numba-cuda then caches it on disk); its group for
    :func:`rbstab.jit.mark_warm` once the kernel ran, or None when it is there already."""
    group = f"cuda-{METHODS[method]}-{n_state}"
    if simulated() or cache_is_warm(group):
        return None
    print(f"rbstab: compiling the CUDA kernel for {METHODS[method]} with {n_state} states "
          f"(once for this version; cached in {CACHE_DIR})", file=sys.stderr, flush=True)
    return group


#: The compiled functions the kernel calls (the simulator hands them numpy's arrays).
DEVICE_FUNCTIONS = ("state_rate", "output_row", "initial_step", "step_bounds", "attempt_step", "gimbal_event",
                    "locate_event", "dense_coefficients", "dense_value", "sample_time", "stream_start",
                    "stream_sample", "stream_finish")


def _plain(value):
    """The numpy array or record behind the simulator's wrappers of a kernel's arguments."""
    while hasattr(value, "_item") or hasattr(value, "_ary"):
        value = value.__dict__["_item"] if "_item" in value.__dict__ else value._ary
    return value


def _unwrapping(function):
    def call(*args):
        return function(*[_plain(a) for a in args])

    return call


def _simulator_function(function):
    """``function`` with the compiled functions it calls taking the simulator's arguments:
    under the simulator a kernel runs as Python and calls rbstab's CPU-compiled functions,
    which take numpy's arrays and records, not the simulator's wrappers of them."""
    names = dict(function.__globals__)
    names.update({name: _unwrapping(names[name]) for name in DEVICE_FUNCTIONS})
    names["globaltimer"] = _clock_ns_python
    return FunctionType(function.__code__, names, function.__name__, function.__defaults__,
                              function.__closure__)


# -- from Python ----------------------------------------------------------------------------------------
@dataclass
class CudaChunk:
    """What the GPU gives for some runs of a call of :func:`integrate_chunks_cuda`.

    Attributes
    ----------
    runs : ndarray of int, shape (k,)
        The runs' positions in the call (runs of one ``t_end``, in order).
    status : ndarray of int, shape (k,)
        How each run ended (:mod:`rbstab.engine.status`); TIMEOUT with t_stop 0 for a run
        the launch's limit left unstarted.
    t_stop : ndarray, shape (k,)
        Where each run stopped [s].
    nfev, n_steps : ndarray of int, shape (k,)
    last : ndarray, shape (k, N_OUTPUTS)
        The outputs at each run's last sample (NaN for a run with none).
    acc : ndarray, shape (k, ACCUMULATOR_SIZE)
        The streamed summary (:func:`rbstab.summary.stream_table` turns it into figures).
    trace : ndarray, shape (k, n_trace, TRACE_COLUMNS) or None
        Every ``stride``-th sample's outputs and numerical dv/dt; after a run stopped, the
        outputs of a NaN state (as the CPU engine's).
    kernel_seconds : float
        The kernel's time on the GPU (CUDA events) [s].
    seconds : float
        The launch's wall time (transfers, kernel and results to the host) [s].
    """

    runs: np.ndarray
    status: np.ndarray
    t_stop: np.ndarray
    nfev: np.ndarray
    n_steps: np.ndarray
    last: np.ndarray
    acc: np.ndarray
    trace: np.ndarray | None
    kernel_seconds: float
    seconds: float


def _blocks(k: int) -> int:
    """Blocks of a launch for k runs: enough to fill the GPU (a persistent grid), no more
    than the runs need."""
    wanted = -(-k // THREADS_PER_BLOCK)
    if simulated():
        return 1
    sms = cuda.get_current_device().MULTIPROCESSOR_COUNT
    return max(1, min(wanted, 8 * sms))


def integrate_chunks_cuda(codes, params, y0, settings, *, n_samples: int, stride: int | None = None,
                          full: bool = False, max_wall_time: float = math.inf,
                          ratio: float = DEFAULT_LYAPUNOV_RATIO) -> Iterator[CudaChunk]:
    """Integrate k runs of one method and state size on the GPU; yields a
    :class:`CudaChunk` per launch (the runs of one ``t_end`` at a time, in order, as many a launch as
    :data:`TRACE_BYTES` of traces allow).

    Parameters
    ----------
    codes : array_like of int, shape (k,)
        Variant codes; no pure-sign-law mode.
    params : ndarray of :data:`rbstab.model.PARAMETERS`, shape (k,) or (1,)
        Each run's record, or one that every run shares (a basin map's).
    y0 : ndarray, shape (k, n_state)
    settings : ndarray of :data:`rbstab.engine.settings.SETTINGS`, shape (k,)
        Every run with the same ``method``; ``max_wall_time`` is not read (see below).
    n_samples : int
        Samples per run, evenly spaced on [0, t_end] (>= 2); the summary figures are
        taken over them.
    stride : int or None
        Keep every ``stride``-th sample's outputs (a trace); None: none.
    full : bool
        Every output at the kept samples, or all but :data:`rbstab.layout.LEFT_OUT`.
    max_wall_time : float
        Seconds after which a launch stops [s]: its runs not finished are TIMEOUT. A
        launch takes as many runs as :data:`TRACE_BYTES` of traces hold.
    ratio : float
        The convergence ratio of each run's last sample not converged (the accumulator's
        ``LAST_ABOVE``: :func:`rbstab.convergence.converged` with v(0) and its v).

    Raises
    ------
    CudaUnavailable
        No GPU, driver or numba-cuda (:func:`check_available`).
    ValueError
        For runs of several methods.
    """
    check_available()
    settings = np.ascontiguousarray(settings, dtype=SETTINGS)
    methods = np.unique(settings["method"])
    if len(methods) > 1:
        raise ValueError(f"settings: runs of methods {methods.tolist()} in one call; expected one")
    y0 = np.ascontiguousarray(y0, dtype=float)
    k, n_state = y0.shape
    codes = np.ascontiguousarray(codes, dtype=np.int64)
    params = np.ascontiguousarray(params, dtype=PARAMETERS)
    n_trace = 0 if stride is None else len(range(0, n_samples, stride))
    per_launch = max(1, TRACE_BYTES // max(8 * TRACE_COLUMNS * n_trace, 1))
    method = int(methods[0]) if len(methods) else 0
    compiling = _say_compiling(method, n_state)
    fn = kernel(method, n_state)
    limit_ns = np.int64(min(max_wall_time * 1e9, 2**62)) if math.isfinite(max_wall_time) else np.int64(2**62)
    pinned: dict = {}  # host buffers the launches of this call copy their results into
    # the numerical dv/dt's stencils are those of each run's own grid: a launch per t_end
    for t_end in dict.fromkeys(settings["t_end"].tolist()):
        grid = np.linspace(0.0, t_end, n_samples)
        stencils = (*stencil_weights(grid), short_stencils(grid))
        group = np.flatnonzero(settings["t_end"] == t_end)
        for lo in range(0, len(group), per_launch):
            runs = group[lo: lo + per_launch]
            start = _time.perf_counter()
            out = _launch(fn, (codes[runs], params if len(params) == 1 else params[runs], y0[runs], settings[runs]),
                          stencils, (stride or n_samples, full, ratio), n_trace, limit_ns, pinned)
            if compiling:
                mark_warm(compiling)
                compiling = None
            yield CudaChunk(runs, *out, seconds=_time.perf_counter() - start)


def _launch(fn, runs, stencils, options, n_trace, limit_ns, pinned: dict):
    """One launch over ``runs`` (codes, params, y0, settings) with the grid's ``stencils``
    (first, weights, short) and ``options`` (stride, full, ratio); the host arrays of
    :class:`CudaChunk`, copied out of the page-locked buffers of ``pinned`` (shape and
    dtype -> buffer: allocated once, the launches of a call reuse them)."""
    stride, full, ratio = options
    k = len(runs[0])
    status = np.full(k, TIMEOUT, dtype=np.int64)  # a run the launch's limit left unstarted
    t_stop = np.zeros(k)
    nfev = np.zeros(k, dtype=np.int64)
    n_steps = np.zeros(k, dtype=np.int64)
    last = np.full((k, N_OUTPUTS), np.nan)
    acc = np.zeros((k, ACCUMULATOR_SIZE))
    trace_shape = (k, n_trace, TRACE_COLUMNS) if n_trace else (1, 0, TRACE_COLUMNS)
    outputs = [status, t_stop, nfev, n_steps, last, acc]
    d_in = [cuda.to_device(a) for a in (*runs, *stencils)]
    d_out = [cuda.to_device(a) for a in outputs]
    d_trace = cuda.device_array(trace_shape)
    counter = cuda.to_device(np.zeros(1, dtype=np.int64))
    start, end = cuda.event(), cuda.event()
    start.record()
    fn[_blocks(k), THREADS_PER_BLOCK](*d_in, np.int64(stride), bool(full), float(ratio), counter, limit_ns, *d_out,
                                      d_trace)
    end.record()
    end.synchronize()
    kernel_seconds = start.elapsed_time(end) / 1e3

    def to_host(device, shape, dtype):
        key = (shape, np.dtype(dtype).str)
        if key not in pinned:
            pinned[key] = cuda.pinned_array(shape, dtype)
        return np.array(device.copy_to_host(pinned[key]))

    host = [to_host(d, a.shape, a.dtype) for d, a in zip(d_out, outputs)]
    trace = to_host(d_trace, trace_shape, np.float64) if n_trace else None
    return (*host, trace, kernel_seconds)
