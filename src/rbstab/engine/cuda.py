"""The CUDA engine: the compiled engine's runs on an NVIDIA GPU, one thread a run.

The physics, the Runge-Kutta step and the driver's loop are the CPU engine's own
functions: numba-cuda compiles every rbstab ``@jit`` function that a CUDA kernel calls as a
device function of the same Python source. A run is :func:`rbstab.engine.integrate.drive_run`,
as on the CPU (:func:`rbstab.engine.integrate.integrate_run`): passes of
:func:`rbstab.engine.integrate.run_pass` (one step *attempt* a pass, its event, samples,
breakpoints and impulses), the step limit and the clock read between them (here the GPU's
``%globaltimer``, :func:`globaltimer`); a thread whose step is rejected tries again on the
next pass with the others of its warp, instead of stalling them. Only the kernels' frames
are written here: work arrays in thread-local memory, a persistent grid whose threads take
the next run from an atomic counter when theirs ends, the launch's one deadline, and what
becomes of a run's samples (:class:`TreeStreamSink`: its streamed summary of
:mod:`rbstab.summary` and, if asked, its samples).

Every run is a tree of 1 to :data:`MAX_TREE_BODIES` bodies (:func:`tree_kernel_function`,
:func:`integrate_chain_runs_cuda`): the driver runs on the tree's
:class:`~rbstab.engine.systems.TreeSystem` through the system's functions
(:mod:`rbstab.engine.systems`; the physics is :func:`rbstab.variants.tree.tree_rate`,
compiled as a device function with scratch arrays in thread-local memory sized for the
tree's shape: a kernel per number of bodies and of each joint kind,
:func:`tree_shape`), or, where every tree of a launch is the paper's one body, on the
body's record with one body's rate (a kernel of its own, as on the CPU). A launch takes
trees of one structure (their records passed once, read by every thread), each run with
its own tree, initial state and settings.

A run with disturbances (``disturbance_count`` > 0, read once a run) is integrated as the
CPU engine integrates it (docs/disturbances.md): its impulses at t = 0 are applied before
the first step; no step crosses a breakpoint (an edge of a disturbance's window) and no
stage of a step that ends at one evaluates at or after it; at a breakpoint its impulses
are applied and a new initial step is taken; a sample at a breakpoint shows the state
just after it, and the last sample the state after the impulses at t_end. The work W [J]
of the disturbances is one more entry of the integrated vector after the state (its rate
their power; each impulse adds its jump of kinetic energy; left out of the error norms),
sampled with the state as each sample's ``disturbance_work``.

A run gives what the CPU driver (:func:`rbstab.engine.integrate.integrate_chain_runs`)
gives, computed as it goes: its status, stop time, right-hand-side evaluations and steps,
its summary streamed (each sample evaluated on the device, :func:`tree_stream_sample` or
:func:`body_stream_sample`; :func:`rbstab.summary.tree_stream_table` makes the figures),
its state at its last sample and, if asked, its state (and W) at every ``stride``-th
sample, from which the host computes the outputs. Under numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) the same driver runs as Python over the CPU-compiled
functions and gives the CPU engine's bits.

A launch has one deadline, ``max_wall_time`` after its first thread started: no run starts
after it (such a run ends NOT_STARTED), a run under way stops at the next clock reading
(TIMEOUT), and every run's outputs are written, started or not. The grid is as many
blocks as the compiled kernel's registers let the GPU hold at once (:func:`occupancy`);
each kernel is compiled for the one argument signature every launch uses
(:func:`tree_launch_signature`), once per version, under a file lock that other
processes wait on (:func:`compiled_tree_kernel`).

Not here: the pure sign law of ``sliding`` (``boundary_layer: 0``), whose event-driven
integrator (:mod:`rbstab.engine.switching`) stays on the CPU, and the implicit methods.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import math
import sys
import time as _time
from collections import namedtuple
from dataclasses import dataclass
from types import FunctionType

import numpy as np

# numba-cuda 0.30.4 (numba_cuda/numba/cuda/np/arrayobj.py) registers an overload of
# np.row_stack whenever numpy >= 2.0, and numpy 2.5 removed np.row_stack: without this
# alias its CUDA target fails to load on numpy 2.5 (np.row_stack was np.vstack's alias).
if "row_stack" not in vars(np):
    np.row_stack = np.vstack

# numba-cuda's target where installed (rbstab[cuda]); _cuda() checks which
from numba import cuda, from_dtype, types  # noqa: E402
from numba.extending import overload  # noqa: E402

from ..convergence import DEFAULT_LYAPUNOV_RATIO
from ..jit import CACHE_DIR, cache_is_warm, jit, mark_warm
from ..kinematics import GIMBAL_LOCK_ANGLE
from ..layout import AXES, LYAPUNOV_TERMS, N_OUTPUTS, OUTPUTS, REDUCED_STATES, SATURATION_FLAGS, VELOCITIES
from ..model import PARAMETERS
from ..summary import (ACCUMULATOR_SIZE, MEMBER_SLOTS, ground_pressure, grounded, pressure_stride, short_stencils,
                       stencil_weights, stream_body_balance, stream_finish, stream_member, stream_member_start,
                       stream_pressure, stream_sample, stream_start, stream_tree_balance)
from ..variants.chain import ChainWork, _E, _saturation_flags, chain_evaluate, is_one_body
from ..variants.disturbances import edges_up_to
from ..variants.tree import TreeWork, reduced_size, tree_expand, tree_reactions
from ..variants.kernels import BALL, FREE, HINGE, PERMANENT, SLIDE, UNIVERSAL, body_pressure, output_row
from .integrate import ChunkSolution, SampleRows, clock_ns, drive_run, keep_sample
from .rk import DOP853, INTERPOLANT_ROWS, N_STAGES, STAGE_ROWS, method_number
from .settings import SETTINGS, Work, settings_records
from .systems import (CHAIN, TreeSystem, disturbed_of, expand_tree_samples, limited_of, reduce_tree_states,
                      tree_rows)
from .tableaus import METHODS
from .status import NOT_STARTED

__all__ = ["CudaUnavailable", "INSTALL_HINT", "check_available", "compute_mode", "occupancy", "THREADS_PER_BLOCK",
           "MAX_TREE_BODIES", "tree_launch_signature", "tree_shape", "tree_kernel_function", "compiled_tree_kernel",
           "integrate_chain_runs_cuda"]

#: How to get what ``--engine cuda`` needs.
INSTALL_HINT = 'pip install "rbstab[cuda]" (numba-cuda and the CUDA 12 wheels) and an NVIDIA driver'
#: Threads per block (runs of a warp step together; 128-256 within ~7 % on an H100).
THREADS_PER_BLOCK = 128
#: Share of the device's free memory the samples of one launch may take (up to four worker
#: processes may share a GPU, each taking this share of what is free when it launches).
TRACE_MEMORY_SHARE = 0.25
#: Longest launch limit [ns] (the deadline is the GPU clock plus it, in an int64).
_NO_LIMIT_NS = 2**60
#: CUDA's compute modes (``cuDeviceGetAttribute(CU_DEVICE_ATTRIBUTE_COMPUTE_MODE)``).
COMPUTE_MODES = {0: "default", 1: "exclusive-thread", 2: "prohibited", 3: "exclusive-process"}


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
    if compute_mode() == "prohibited":
        raise CudaUnavailable("--engine cuda: the GPU's compute mode is 'prohibited' (nvidia-smi -q shows it): "
                              "no process may use it; ask its administrator for the default mode")


def compute_mode() -> str:
    """The compute mode of GPU 0 (a value of :data:`COMPUTE_MODES`; ``"default"`` under the
    simulator), read from the driver without a context: ``"exclusive-process"`` lets one
    process at a time use the GPU, so a sweep then runs one GPU worker."""
    if simulated() or getattr(cuda, "implementation", "") != "NVIDIA" or not cuda.is_available():
        return "default"
    from numba.cuda.cudadrv.driver import driver  # optional: numba-cuda

    return COMPUTE_MODES.get(int(driver.get_device(0).COMPUTE_MODE), "default")


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


def _register_gpu_clock() -> None:
    """:func:`rbstab.engine.integrate.clock_ns` in a CUDA kernel: :func:`globaltimer` (none
    under the simulator, whose kernels call the CPU-compiled driver and its clock)."""
    try:
        from numba.cuda.extending import overload as cuda_overload  # optional: numba-cuda
    except ImportError:
        return
    if globaltimer is None:  # pragma: no cover - numba-cuda without its extending API
        return

    @cuda_overload(clock_ns)
    def _gpu_clock_ns():
        return lambda: globaltimer()


_register_gpu_clock()


# -- the kernel ---------------------------------------------------------------------------------------
#: Where a tree run's samples go in the tree kernel: each is evaluated
#: (:func:`tree_stream_sample`) and streamed into the summary's accumulator ``acc``
#: (:func:`rbstab.summary.stream_sample`: v, its terms, dv/dt, the disturbances' edges, with
#: the grid's ``first``, ``weights`` and the convergence ``ratio``; ``row`` the outputs'
#: scratch) and each member's slots ``members`` (n,
#: :data:`rbstab.summary.MEMBER_SLOTS`; ``flags`` (n, 3, 3) scratch); ``offset`` is the tree's
#: h [J] (v's zero: its first record's ``lyapunov_offset``); ``last`` (n_r + 1,) receives the reduced state and W of the sample;
#: ``rows`` (a :class:`rbstab.engine.integrate.SampleRows`) keeps every ``stride``-th sample
#: while it has rows, and ``rates`` its numerical dv/dt [W] (:func:`rbstab.summary.stream_sample`);
#: ``ground`` the scratch of the joints' reactions at a sample (:func:`rbstab.variants.tree.tree_reactions`:
#: dyr (n_r + 1,), the bodies' accelerations (n, 6), Lambda_j (n, 3), the ground's moments (n, 3)).
TreeStreamSink = namedtuple("TreeStreamSink", ["acc", "members", "row", "flags", "last", "first", "weights", "ratio",
                                               "offset", "rows", "rates", "ground"])
_V_AT, _RATE_AT, _EDGES_AT = (OUTPUTS[name].offset for name in ("lyapunov", "lyapunov_rate", "disturbance_edges"))
_TERMS_AT = tuple(OUTPUTS[name].offset for name in LYAPUNOV_TERMS)
_ERROR_AT = OUTPUTS["constraint_error"].offset
_FLAGS_AT = tuple(OUTPUTS[name].offset for name, _ in SATURATION_FLAGS.values())


@jit(_nrt=False)
def tree_stream_sample(sink, p, j, t, sample, work):
    """Sample j at time t [s] of a tree run (:class:`TreeStreamSink` ``sink``; the reduced
    state and W [J] ``work`` in ``sample``) on its maximal image: every joint's and body's
    quantities (:func:`rbstab.variants.chain.chain_evaluate`) and saturation flags, the
    terms of v (eq 25's grouping; h in the gravity term), v, the analytic dv/dt and the
    disturbances' edges summed over the bodies' records, as the host's
    :func:`rbstab.variants.chain.evaluate` of the sample gives them, streamed into the
    accumulators, with the balance figures' (:func:`rbstab.summary.stream_tree_balance`); a
    hinge's angle is the sample's (the host's continues it from sample to sample: the same
    turn), and at every :func:`rbstab.summary.pressure_stride`-th sample the net centre of
    pressure of its point-fixed joints to the ground (:func:`rbstab.summary.ground_pressure`;
    NaN without one or without gravity)."""
    w, n = p.work, p.codes.shape[0]
    cw = w.chain
    taken = j % pressure_stride(sink.first.shape[0]) == 0  # a sample the centre of pressure's figure reads
    px, py, pz = math.nan, math.nan, math.nan
    if taken and grounded(p.codes, p.parents, p.params):
        dyr, accelerations, reactions, moments = sink.ground
        tree_reactions(t, sample, p.params, p.codes, p.parents, p.ppoints, p.d_at, p.r_at, p.u_at, p.rd_at, dyr, w,
                       accelerations, reactions, moments)
        px, py, pz = ground_pressure(reactions, moments, p.ppoints, p.codes, p.parents, p.params)
    tree_expand(sample, p.params, p.codes, p.parents, p.ppoints, p.d_at, p.r_at, p.u_at, p.rd_at, w.y, cw.rot,
                cw.rate, True)
    for i in range(n):  # a joint's angles about axes read nearest the sample's own
        for k in range(AXES[p.codes[i]]):
            cw.angle[i, k] = sample[p.r_at[i] + k]
    chain_evaluate(t, w.y, p.params, p.codes, p.parents, p.ppoints, p.d_at, w.dy, cw.joints, cw.bodies, cw.scalars, cw)
    _saturation_flags(w.y, p.params, p.codes, cw.joints, cw.angle, sink.flags)
    row, terms = sink.row, cw.scalars
    edges = 0.0
    for i in range(n):
        stream_member(sink.members, i, cw.joints[i, _E], sink.flags[i])
        edges += edges_up_to(p.params[i], t)
    for c in range(4):
        row[_TERMS_AT[c]] = terms[c]
    row[_TERMS_AT[3]] += sink.offset
    row[_V_AT] = terms[0] + terms[1] + terms[2] + terms[3] + sink.offset
    row[_RATE_AT] = terms[4]
    row[_EDGES_AT] = edges
    stream_sample(sink.acc, j, row, sink.first, sink.weights, sink.ratio, sink.rates, sink.rows.stride)
    stream_tree_balance(sink.acc, j, w.y, cw.joints[:, _E], p.params)
    if taken:
        stream_pressure(sink.acc, j, px, py, pz)


@jit(_nrt=False)
def body_stream_sample(sink, code, p, j, t, sample, work):
    """:func:`tree_stream_sample` of a run of the paper's one body (``p`` its record,
    ``code`` its joint's law, :func:`rbstab.variants.chain.is_one_body`): one body's compiled
    outputs (:func:`rbstab.variants.kernels.output_row`, h the record's), as the host's
    :func:`rbstab.variants.chain.evaluate` gives them for such a tree, streamed into the
    accumulators and the member slots of its one joint (its centre of pressure
    :func:`rbstab.variants.kernels.body_pressure`'s)."""
    row, flags = sink.row, sink.flags
    output_row(code, t, sample, p, row, True)
    for k in range(3):
        for c in range(3):
            flags[0, k, c] = row[_FLAGS_AT[k] + c]
    stream_member(sink.members, 0, row[_ERROR_AT:_ERROR_AT + 3], flags[0])
    stream_sample(sink.acc, j, row, sink.first, sink.weights, sink.ratio, sink.rates, sink.rows.stride)
    stream_body_balance(sink.acc, j, row, p)
    if j % pressure_stride(sink.first.shape[0]) == 0:
        px, py, pz = body_pressure(code, row, p)
        stream_pressure(sink.acc, j, px, py, pz)


@overload(keep_sample, target="generic", jit_options={"forceinline": True, "error_model": "numpy", "_nrt": False})
def _keep_tree_streamed(sink, code, p, j, t, sample, work):
    if not (isinstance(sink, types.BaseNamedTuple) and sink.instance_class is TreeStreamSink):
        return None
    one_body = isinstance(p, types.Record)

    def keep(sink, code, p, j, t, sample, work):
        if one_body:
            body_stream_sample(sink, code, p, j, t, sample, work)
        else:
            tree_stream_sample(sink, p, j, t, sample, work)
        last = sink.last  # the reduced state and W of the run's last sample
        for i in range(last.shape[0] - 1):
            last[i] = sample[i]
        last[last.shape[0] - 1] = work
        rows = sink.rows
        if j % rows.stride == 0 and j // rows.stride < rows.samples.shape[0]:
            for i in range(rows.samples.shape[1]):
                rows.samples[j // rows.stride, i] = sample[i]
            rows.work[j // rows.stride] = work
    return keep


#: numba's type of a :data:`rbstab.model.PARAMETERS` record, a global of the kernels (not a
#: closure variable): numba-cuda keys its disk cache on the pickled closure, and a numba type
#: pickles with its type code, which depends on the types a process made before (a sweep's
#: worker, forked from a server that loaded the CPU kernels, numbers them otherwise than a
#: new process, so the kernel would be compiled again in every worker).
PARAMETERS_TYPE = from_dtype(PARAMETERS)


def _say_cache_miss(fn, warm: bool, what: str) -> None:
    """One line on stderr where a kernel the cache should have held (``warm``) was compiled
    again (numba-cuda's cache key did not match: minutes on the CPU, so the command says why
    it is slow)."""
    if warm and sum(fn.stats.cache_misses.values()):
        print(f"rbstab: {what} was not found in the cache ({CACHE_DIR}) and was compiled again", file=sys.stderr,
              flush=True)


@contextlib.contextmanager
def _compile_lock(group: str):
    """Hold an exclusive lock on ``CACHE_DIR/<group>.lock`` (other processes wait): one
    process at a time compiles a kernel or reads it from the cache (numba-cuda writes its
    cache files without a lock). A cache folder that cannot be written goes without."""
    try:
        CACHE_DIR.mkdir(parents=True, exist_ok=True)
        handle = open(CACHE_DIR / f"{group}.lock", "a")
    except OSError:
        yield
        return
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def kernel_resources(fn, signature: tuple) -> tuple[int, int]:
    """(registers, local memory [B]) a thread of the compiled kernel ``fn`` on the current
    device, ``signature`` the argument types it was compiled for
    (:func:`tree_launch_signature`). numba-cuda's dispatcher looks a kernel up by a
    signature object (its ``args``), not by the tuple of argument types."""
    from numba import types  # heavy: numba
    from numba.core.typing import signature as make_signature  # heavy: numba

    sig = make_signature(types.void, *signature)
    return fn.get_regs_per_thread(sig), fn.get_local_mem_per_thread(sig)


def occupancy(fn, signature: tuple) -> int:
    """Blocks of :data:`THREADS_PER_BLOCK` threads one multiprocessor holds at once for the
    compiled kernel ``fn`` of the argument types ``signature`` (CUDA's occupancy calculation
    from its registers a thread and the device's limits; the kernel uses no shared memory).
    1 under the simulator."""
    if simulated():
        return 1
    device = cuda.get_current_device()
    regs, _ = kernel_resources(fn, signature)
    warps = -(-THREADS_PER_BLOCK // device.WARP_SIZE)
    per_warp = -(-max(regs, 1) * device.WARP_SIZE // 256) * 256  # registers go to a warp in units of 256
    by_registers = device.MAX_REGISTERS_PER_MULTIPROCESSOR // (per_warp * warps)
    by_threads = device.MAX_THREADS_PER_MULTIPROCESSOR // THREADS_PER_BLOCK
    return max(1, min(by_registers, by_threads, device.MAX_BLOCKS_PER_MULTIPROCESSOR))


def _plain(value):
    """The numpy array or record behind the simulator's wrappers of a kernel's arguments
    (in a named tuple: a tuple of them, a tree's system)."""
    if isinstance(value, tuple) and hasattr(value, "_fields"):
        return type(value)(*[_plain(v) for v in value])
    while hasattr(value, "_item") or hasattr(value, "_ary"):
        value = value.__dict__["_item"] if "_item" in value.__dict__ else value._ary
    return value


def _unwrapping(function):
    def call(*args):
        return function(*[_plain(a) for a in args])

    return call


def _simulator_function(function, device_functions):
    """``function`` with the compiled functions it calls (``device_functions``, names of
    this module's globals) taking the simulator's arguments: under the simulator a kernel
    runs as Python and calls rbstab's CPU-compiled functions, which take numpy's arrays and
    records, not the simulator's wrappers of them."""
    names = dict(function.__globals__)
    names.update({name: _unwrapping(names[name]) for name in device_functions})
    names["globaltimer"] = _clock_ns_python
    return FunctionType(function.__code__, names, function.__name__, function.__defaults__,
                              function.__closure__)


# -- the tree kernel ------------------------------------------------------------------------------------
#: The most bodies of a tree the tree kernel integrates.
MAX_TREE_BODIES = 8


def tree_launch_signature() -> tuple:
    """numba's types of a tree launch's arguments, in order (every array C-contiguous):
    the signature :func:`compiled_tree_kernel` compiles for every tree shape.

    The trees, passed once and read by every thread (:class:`rbstab.engine.systems.TreeSystem`'s
    arrays for t trees of one structure, :func:`rbstab.engine.systems.tree_rows`): params
    :data:`rbstab.model.PARAMETERS` (t, n) (a tree's h [J], v's zero, its first record's
    ``lyapunov_offset``), codes, parents int64 (n,), ppoints (t, n, 3), d_at, r_at, u_at,
    rd_at int64 (n,); the k runs: tree_of
    int64 (k,) (each run's tree), y0 (k, n_r) in the reduced layout
    (:mod:`rbstab.variants.tree`), settings :data:`rbstab.engine.settings.SETTINGS` (k,);
    the grid's ``first`` int64 (n_samples,), ``weights`` (n_samples, w) and ``short`` (w, w,
    w) (:mod:`rbstab.summary`; the grid linspace(0, t_end, n_samples)); stride int64
    (every stride-th sample kept); ratio float64; control int64 (2,): the next run and the
    launch's deadline [ns] (0 until its first thread sets it); limit_ns int64; then the
    outputs: status int64 (k,), t_stop (k,), nfev,
    n_steps int64 (k,), acc (k, ACCUMULATOR_SIZE) and members (k, n, MEMBER_SLOTS) the
    streamed summary (:class:`TreeStreamSink`), last (k, n_r + 1) the reduced state and W at
    each run's last sample (NaN for a run with none), samples (k, n_kept, n_r), work (k,
    n_kept) (the disturbances' work W [J]) and rates (k, n_kept) (v's numerical dv/dt [W]) at
    the kept samples (n_kept 0: none kept).
    """
    from numba import float64, from_dtype, int64  # heavy: numba

    vector, matrix, cube = float64[::1], float64[:, ::1], float64[:, :, ::1]
    ints = int64[::1]
    return (PARAMETERS_TYPE[:, ::1], ints, ints, cube, ints, ints, ints, ints, ints, matrix,
            from_dtype(SETTINGS)[::1], ints, matrix, cube, int64, float64, ints, int64, ints, vector, ints, ints,
            matrix, cube, matrix, cube, matrix, matrix)


def tree_shape(codes, d_at) -> tuple[int, ...]:
    """(bodies, permanent joints, embedded joints, hinges, universal joints, quaternion balls,
    slides) of a tree of joint codes
    ``codes`` (n,) whose embedded joints' D sit at ``d_at`` (n,; -1: none): what sizes the
    tree kernel's thread-local arrays (:func:`tree_kernel_function`)."""
    codes, d_at = np.asarray(codes), np.asarray(d_at)
    return (int(codes.size), int(np.sum(codes == PERMANENT)), int(np.sum(d_at >= 0)), int(np.sum(codes == HINGE)),
            int(np.sum(codes == UNIVERSAL)), int(np.sum(codes == BALL)), int(np.sum(codes == SLIDE)))


#: (module, name) of the compiled functions a CUDA kernel calls as functions of their own:
#: NVVM inlines every call it may, and a tree's rate, region and impulses, called from six,
#: six and three places of the driver, were as many copies of 5,000-11,500 lines of PTX each
#: (the stance example's kernel: 174,000 lines, 69,000 with these calls). The kernel goes from
#: Python to machine code 4.7x as fast (``benchmarks/gpu.py --ptx-only``). The CPU driver
#: keeps them inlined: there the same calls made a chain's runs 10-15 % slower and its
#: cold compile 17 % shorter. A sample's evaluation (:func:`tree_stream_sample`, the
#: streamed summary's) is one more such function.
NOT_INLINED = frozenset({("rbstab.variants.tree", "tree_rate"), ("rbstab.engine.systems", "tree_margin"),
                         ("rbstab.engine.systems", "tree_impulses"), ("rbstab.engine.cuda", "tree_stream_sample")})


def _lower_not_inlined() -> None:
    """Have numba-cuda lower the functions of :data:`NOT_INLINED` with LLVM's ``noinline``
    attribute, once a process (numba-cuda has no option for it: its lowering's
    ``setup_function`` is wrapped). Under the simulator nothing is lowered; a numba-cuda
    without that method inlines them as it would (the same kernel, a longer compile)."""
    if simulated():
        return
    from numba.cuda import lowering  # heavy: numba-cuda

    setup = getattr(getattr(lowering, "CUDALower", None), "setup_function", None)
    if setup is None or getattr(setup, "not_inlined", False):
        return

    def setup_function(self, fndesc):
        setup(self, fndesc)
        if (fndesc.modname, fndesc.qualname) in NOT_INLINED and "alwaysinline" not in self.function.attributes:
            self.function.attributes.add("noinline")

    setup_function.not_inlined = True
    lowering.CUDALower.setup_function = setup_function


def tree_kernel_function(method: int, shape: tuple[int, ...], one_body: bool = False):
    """The Python function of the CUDA kernel of the runs of trees of ``shape`` (bodies n,
    permanent joints p, embedded joints e, hinges h, universal joints u, quaternion balls b, slides s (0 where left
    out); :func:`tree_shape`) with method number ``method``
    (:func:`tree_launch_signature`: one tree, k runs, one thread a run). Its name names
    them, so that each kernel has cache files of its own.

    ``one_body``: every tree of its launches is the paper's one body
    (:func:`rbstab.variants.chain.is_one_body`), integrated as the CPU driver integrates it:
    the system is the body's record (copied to thread-local memory once a run: its fields
    are read at every right-hand side), its rate one body's and its samples evaluated by one
    body's outputs (:func:`body_stream_sample`); the same states and figures as a general
    tree's to rounding, the CPU's bit for bit.

    The driver is :func:`rbstab.engine.integrate.drive_run` (with the persistent grid and
    the launch's one deadline) on a
    :class:`~rbstab.engine.systems.TreeSystem`, whose functions (:mod:`rbstab.engine.systems`)
    the passes call as the CPU driver's do; a sample is the reduced state there (and W),
    evaluated and streamed into the run's summary (:class:`TreeStreamSink`), and, while the
    launch's ``samples`` have rows, written to device memory as the CPU driver's samples are
    (the host computes the outputs from them). Its
    thread-local arrays are sized for the tree's shape (the stack a thread grows with the
    tree): the reduced state (n_r = 12 n - 6 p - 10 h + 3 e entries) and its Runge-Kutta stages, the
    maximal image (12 n + 3 e), the mass matrix (n_u)^2 of
    :func:`rbstab.variants.tree.tree_rate` (n_u = 6 n - 3 p - 5 h generalised velocities) and the
    permanent joints' reaction system (3 p)^2 of a sample's Lambda_j
    (:func:`rbstab.variants.chain.chain_evaluate`). Every run integrates its work W after the
    state (its rate 0 without disturbances), so that each vector's size is known when the
    kernel is compiled. The tree's rate, region and impulses stay functions of their own
    (:data:`NOT_INLINED`)."""
    from numba import float64, int64  # heavy: numba (this module is imported only by --engine cuda)

    _lower_not_inlined()
    n_rows, q_rows = int(STAGE_ROWS[method]), int(INTERPOLANT_ROWS[method])
    scheme = (method, int(N_STAGES[method]), method == DOP853)
    bodies, permanent, embedded, hinges, universals, balls, slides = (*(int(x) for x in shape), 0, 0, 0, 0)[:7]
    free = bodies - permanent - hinges - universals - balls - slides
    states = 12 * bodies + 3 * embedded  # the maximal image
    rates = states + 1  # its rate, and W's
    # the integrated vector: the reduced state (the joint kinds' sizes, rbstab.layout.JOINT_KINDS) and W
    size = (free * int(REDUCED_STATES[FREE]) + permanent * int(REDUCED_STATES[PERMANENT])
            + hinges * int(REDUCED_STATES[HINGE]) + universals * int(REDUCED_STATES[UNIVERSAL])
            + balls * int(REDUCED_STATES[BALL]) + slides * int(REDUCED_STATES[SLIDE]) + 3 * embedded + 1)
    n_state = size - 1
    rows = max(1, 3 * permanent)
    columns = (free * int(VELOCITIES[FREE]) + permanent * int(VELOCITIES[PERMANENT]) + hinges * int(VELOCITIES[HINGE])
               + universals * int(VELOCITIES[UNIVERSAL]) + balls * int(VELOCITIES[BALL])
               + slides * int(VELOCITIES[SLIDE]))

    def run_tree(params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, tree_of, y0s, settings, first,
                 weights, short, stride, ratio, control, limit_ns, status_o, t_stop_o, nfev_o, n_steps_o, acc_o,
                 members_o, last_o, samples_o, work_o, rates_o):
        K = cuda.local.array((n_rows, size), float64)  # sizes known when compiled: the state, then W
        Q = cuda.local.array((q_rows, size), float64)
        y = cuda.local.array(size, float64)
        f = cuda.local.array(size, float64)
        y_new = cuda.local.array(size, float64)
        scale = cuda.local.array(n_state, float64)  # the error norms take the state's entries
        work = cuda.local.array(size, float64)
        sample = cuda.local.array(size, float64)
        row = cuda.local.array(N_OUTPUTS, float64)
        saturated = cuda.local.array((bodies, 3, 3), float64)
        if one_body:
            record = cuda.local.array(1, PARAMETERS_TYPE)
        chain = ChainWork(cuda.local.array((bodies, 3, 3), float64), cuda.local.array((bodies, 3, 3), float64),
                          cuda.local.array((bodies, 3), float64), cuda.local.array((bodies, 3), float64),
                          cuda.local.array((bodies, 3, 3), float64),
                          cuda.local.array((rows, rows), float64), cuda.local.array(rows, float64),
                          cuda.local.array(bodies, int64), cuda.local.array((bodies, 7, 3), float64),
                          cuda.local.array((bodies, 3), float64), cuda.local.array(5, float64),
                          cuda.local.array((bodies, 2), float64))
        scratch = TreeWork(cuda.local.array(states, float64), cuda.local.array(rates, float64),
                           cuda.local.array((bodies, 6), float64), cuda.local.array((columns, columns), float64),
                           cuda.local.array(columns, float64), cuda.local.array(bodies, float64),
                           cuda.local.array((bodies, 3), float64), cuda.local.array((bodies, 3, 3), float64),
                           cuda.local.array((bodies, 3), float64), cuda.local.array((bodies, 3), float64),
                           cuda.local.array(bodies, int64), chain)
        ground = (cuda.local.array(size, float64), cuda.local.array((bodies, 6), float64),
                  cuda.local.array((bodies, 3), float64), cuda.local.array((bodies, 3), float64))
        w = Work(K, Q, y_new, scale, work)
        n_runs = y0s.shape[0]
        n_samples, n_kept = first.shape[0], samples_o.shape[1]
        # the launch's deadline: set once, by the first thread to start
        now = globaltimer()
        deadline = cuda.atomic.cas(control, 1, 0, now + limit_ns)
        if deadline == 0:
            deadline = now + limit_ns
        passes = 0
        k = cuda.atomic.add(control, 0, 1)
        while k < n_runs:
            tree = tree_of[k]
            if one_body:
                source, copy = params[tree, 0:1].view(np.float64), record.view(np.float64)
                for i in range(copy.shape[0]):
                    copy[i] = source[i]
                code, p = codes[0], record[0]
            else:
                code, p = CHAIN, TreeSystem(params[tree], codes, parents, ppoints[tree], d_at, r_at, u_at, rd_at,
                                            scratch)
            disturbed = disturbed_of(p)
            s = settings[k]
            limit = GIMBAL_LOCK_ANGLE - s.gimbal_margin
            flags = (limit, disturbed, limited_of(p), n_samples)
            acc, members, last = acc_o[k], members_o[k], last_o[k]
            stream_start(acc)
            stream_member_start(members)
            for i in range(N_OUTPUTS):  # what the tree's samples do not set (one body's E, flags)
                row[i] = 0.0
            for i in range(last.shape[0]):
                last[i] = math.nan
            sink = TreeStreamSink(acc, members, row, saturated, last, first, weights, ratio,
                                  params[tree, 0].lyapunov_offset,
                                  SampleRows(samples_o[k], work_o[k], stride), rates_o[k], ground)
            status, state = NOT_STARTED, (0.0, s.t_end, s.t_end, 0.0, 0.0, False, 0, 0, 0)
            if globaltimer() <= deadline:
                for i in range(n_state):
                    y[i] = y0s[k, i]
                y[n_state] = 0.0  # W [J] from 0 to t (its rate 0 without disturbances)
                status, state, passes = drive_run(code, p, s, w, (y, f, sample), sink, flags, scheme,
                                                  (deadline, passes))
            t, j, nfev, n_steps = state[0], state[6], state[7], state[8]
            # its end: every output of the run written, whether it ran or not
            stream_finish(acc, first, weights, short, rates_o[k], stride)
            status_o[k] = status
            t_stop_o[k] = t
            nfev_o[k] = nfev
            n_steps_o[k] = n_steps
            for i in range(-(-j // stride), n_kept):  # the samples after a stop: NaN, as the CPU driver's
                for c in range(n_state):
                    samples_o[k, i, c] = math.nan
                work_o[k, i] = math.nan
                rates_o[k, i] = math.nan
            k = cuda.atomic.add(control, 0, 1)

    run_tree.__name__ = run_tree.__qualname__ = (f"run_{'body' if one_body else 'tree'}{bodies}_{permanent}p"
                                                 f"{embedded}e{f'{hinges}h' if hinges else ''}"
                                                 f"{f'{universals}u' if universals else ''}"
                                                 f"{f'{balls}b' if balls else ''}{f'{slides}s' if slides else ''}"
                                                 f"_{METHODS[method]}")
    return run_tree


#: The compiled functions the tree kernel calls (the simulator hands them numpy's arrays).
TREE_DEVICE_FUNCTIONS = ("drive_run", "disturbed_of", "limited_of", "stream_start", "stream_member_start",
                         "stream_finish")


@functools.lru_cache(maxsize=None)
def compiled_tree_kernel(method: int, shape: tuple[int, ...], one_body: bool = False):
    """The CUDA kernel of the runs of trees of ``shape`` (:func:`tree_shape`; ``one_body``
    as :func:`tree_kernel_function`'s) with method number ``method``, compiled for
    :func:`tree_launch_signature` (or loaded from the disk cache beside the CPU kernels,
    :data:`rbstab.jit.CACHE_DIR`), once per process.

    Processes that need it at once take turns under a file lock in the cache folder: the
    first compiles it (and says so in one line on stderr, once for this version), the
    others load what it saved."""
    _cuda()
    function = tree_kernel_function(method, shape, one_body)
    if simulated():
        return cuda.jit(_simulator_function(function, TREE_DEVICE_FUNCTIONS))
    from numba.cuda.core import config  # optional: numba-cuda

    config.CACHE_DIR = str(CACHE_DIR)
    n, p, e, h, u, b, s = (*shape, 0, 0, 0, 0)[:7]
    group = (f"cuda-{'body' if one_body else 'tree'}{n}-{p}p{e}e{f'{h}h' if h else ''}{f'{u}u' if u else ''}"
             f"{f'{b}b' if b else ''}{f'{s}s' if s else ''}-{METHODS[method]}")
    what = (f"the CUDA kernel for one body's {('permanent', 'embedded', 'other')[0 if p else 1 if e else 2]} joint"
            if one_body else f"the CUDA kernel for trees of {n} bodies ({p} permanent joints, {e} embedded"
                             f"{f', {h} hinges' if h else ''}{f', {u} universal joints' if u else ''}"
                             f"{f', {b} balls' if b else ''}{f', {s} slides' if s else ''})")
    what += f" with {METHODS[method]}"
    with _compile_lock(group):
        warm = cache_is_warm(group)
        if not warm:
            print(f"rbstab: compiling {what} (once for this version; cached in {CACHE_DIR})", file=sys.stderr,
                  flush=True)
        fn = cuda.jit(tree_launch_signature(), cache=True)(function)  # compiles, or loads from the cache
        _say_cache_miss(fn, warm, what)
        mark_warm(group)
    return fn


# -- from Python ----------------------------------------------------------------------------------------
def _resident_blocks(fn, signature: tuple) -> int:
    """The grid of a launch: the blocks the GPU holds at once (:func:`occupancy` on every
    multiprocessor), each thread taking runs until none is left (a persistent grid)."""
    if simulated():
        return 1
    return occupancy(fn, signature) * cuda.get_current_device().MULTIPROCESSOR_COUNT


@dataclass
class CudaChainSolution(ChunkSolution):
    """:class:`rbstab.engine.integrate.ChunkSolution` of tree runs on the GPU
    (:func:`integrate_chain_runs_cuda`): ``samples`` (k, n_kept, 12 n + 3 e) the maximal
    image of the state and ``work`` (k, n_kept) at every ``stride``-th sample (none kept:
    n_kept 0); the streamed summary, ``acc`` (k, ACCUMULATOR_SIZE) and ``members`` (k, n,
    MEMBER_SLOTS) (:func:`rbstab.summary.tree_stream_table` turns them into figures);
    ``last`` (k, 12 n + 3 e) the maximal image at each run's last sample (NaN for a run with
    none); ``rates`` (k, n_kept) v's numerical dv/dt [W] at the kept samples (the whole
    grid's stencils, :func:`rbstab.summary.numerical_rate`'s); ``kernel_seconds`` the
    launches' time on the GPU (CUDA events) [s], ``seconds`` their wall time (transfers and
    the maximal image included) [s]."""

    acc: np.ndarray | None = None
    members: np.ndarray | None = None
    last: np.ndarray | None = None
    rates: np.ndarray | None = None
    kernel_seconds: float = 0.0
    seconds: float = 0.0


def integrate_chain_runs_cuda(system, y0, settings, *, method: str, n_samples: int, stride: int | None = 1,
                              max_wall_time: float = math.inf, tree_of=None,
                              ratio: float = DEFAULT_LYAPUNOV_RATIO) -> CudaChainSolution:
    """Integrate k runs of trees of one structure on the GPU, one thread a run: what
    :func:`rbstab.engine.integrate.integrate_chain_runs` does on the CPU with a
    :class:`~rbstab.engine.systems.TreeSystem` (the same arguments), the trees' records
    passed once for every run, each run's summary streamed as it goes (its samples kept only
    where asked).

    Parameters
    ----------
    system : TreeSystem
        The tree (:func:`rbstab.engine.systems.tree_system`), of at most
        :data:`MAX_TREE_BODIES` bodies, or t trees of one structure
        (:func:`rbstab.engine.systems.tree_rows`); each tree's h [J] (v's zero) its first
        record's ``lyapunov_offset`` (:func:`rbstab.engine.systems.with_offsets`).
    y0 : ndarray, shape (k, n_r) or (k, 12 n + 3 e)
        Initial states in the reduced layout (:mod:`rbstab.variants.tree`) or the maximal
        one, as :func:`rbstab.engine.integrate.integrate_chain_runs` takes them.
    settings : ndarray, shape (k, 7)
        Per run: :data:`~rbstab.engine.settings.SETTING_COLUMNS`; ``max_wall_time`` is not
        read (see below).
    method : str
        One of :data:`METHODS`.
    n_samples : int
        Samples per run, evenly spaced on [0, t_end] (>= 2); the summary is taken over them.
    stride : int or None
        Keep every ``stride``-th sample (``samples`` has ``len(range(0, n_samples,
        stride))`` rows a run); None: keep none (the summary alone).
    max_wall_time : float
        Each launch's limit [s] from its first thread's start: no run starts after it
        (NOT_STARTED, t_stop 0, NaN samples), a run under way stops (TIMEOUT).
    tree_of : ndarray of int, shape (k,), optional
        The tree of each run, for a ``system`` of t trees (default: the first).
    ratio : float
        The convergence ratio of each run's last sample not converged (the accumulator's
        ``LAST_ABOVE``: :func:`rbstab.convergence.converged` with v(0), the largest rise of v so far and its v).

    Raises
    ------
    CudaUnavailable
        No GPU, driver or numba-cuda (:func:`check_available`).
    ValueError
        For a tree of more than :data:`MAX_TREE_BODIES` bodies, ``stride`` < 1, or a
        ``tree_of`` that does not index the trees.
    """
    check_available()
    n_bodies = int(np.shape(system.codes)[0])
    if not 1 <= n_bodies <= MAX_TREE_BODIES:
        raise ValueError(f"bodies: found {n_bodies}; the CUDA engine takes 1 to {MAX_TREE_BODIES}")
    if stride is not None and stride < 1:
        raise ValueError(f"stride: found {stride}; expected an integer >= 1 or None")
    y0 = np.ascontiguousarray(np.atleast_2d(y0), dtype=float)
    params, ppoints, tree_of = tree_rows(system, y0.shape[0], tree_of)
    if y0.shape[1] != reduced_size(system.codes, system.d_at):
        y0 = reduce_tree_states(system, params, ppoints, tree_of, y0)
    k, n_state = y0.shape
    records = settings_records(np.asarray(settings, dtype=float).reshape(k, -1), method_number(method))
    ints = [np.ascontiguousarray(a, dtype=np.int64) for a in (system.codes, system.parents)]
    layout = [np.ascontiguousarray(a, dtype=np.int64) for a in (system.d_at, system.r_at, system.u_at, system.rd_at)]
    tree = (params.astype(PARAMETERS, copy=False), *ints, ppoints, *layout)
    n_kept = 0 if stride is None else len(range(0, n_samples, stride))
    one_body = is_one_body(params, system.codes, system.parents, ppoints)
    fn = compiled_tree_kernel(method_number(method), tree_shape(system.codes, system.d_at), one_body)
    limit_ns = np.int64(min(max_wall_time * 1e9, _NO_LIMIT_NS)) if math.isfinite(max_wall_time) else np.int64(
        _NO_LIMIT_NS)
    blocks = _resident_blocks(fn, tree_launch_signature())
    if simulated():
        free = 2**30
    else:
        free, _ = cuda.current_context().get_memory_info()
    per_run = 8 * (n_kept * (n_state + 2) + ACCUMULATOR_SIZE + n_bodies * MEMBER_SLOTS + n_state + 1 + 8)
    per_launch = max(1, int(free * TRACE_MEMORY_SHARE) // per_run)
    out = (np.empty(k, dtype=np.int64), np.empty(k), np.empty(k, dtype=np.int64), np.empty(k, dtype=np.int64),
           np.empty((k, ACCUMULATOR_SIZE)), np.empty((k, n_bodies, MEMBER_SLOTS)), np.empty((k, n_state + 1)),
           np.empty((k, n_kept, n_state)), np.empty((k, n_kept)), np.empty((k, n_kept)))
    kernel_seconds, start = 0.0, _time.perf_counter()
    d_tree = [cuda.to_device(a) for a in tree]
    # the numerical dv/dt's stencils are those of each run's own grid: a launch per t_end
    for t_end in dict.fromkeys(records["t_end"].tolist()):
        grid = np.linspace(0.0, t_end, n_samples)
        stencils = [cuda.to_device(np.ascontiguousarray(a)) for a in (*stencil_weights(grid), short_stencils(grid))]
        group = np.flatnonzero(records["t_end"] == t_end)
        for lo in range(0, len(group), per_launch):
            runs = group[lo: lo + per_launch]
            d_in = [cuda.to_device(a) for a in (tree_of[runs], y0[runs], records[runs])]
            d_out = [cuda.device_array(a[runs].shape, a.dtype) for a in out]
            control = cuda.to_device(np.zeros(2, dtype=np.int64))  # the next run; the deadline (set on the GPU)
            begin, end = cuda.event(), cuda.event()
            begin.record()
            fn[blocks, THREADS_PER_BLOCK](*d_tree, *d_in, *stencils, np.int64(stride or 1), float(ratio), control,
                                          limit_ns, *d_out)
            end.record()
            end.synchronize()
            kernel_seconds += begin.elapsed_time(end) / 1e3
            for a, d in zip(out, d_out):
                a[runs] = d.copy_to_host()
    status, t_stop, nfev, n_steps, acc, members, last, reduced, work, rates = out
    n_maximal = 12 * n_bodies + 3 * int(np.sum(layout[0] >= 0))
    samples, last_state = np.empty((k, n_kept, n_maximal)), np.empty((k, 1, n_maximal))
    expand_tree_samples(system, params, ppoints, tree_of, reduced, samples)
    expand_tree_samples(system, params, ppoints, tree_of, np.ascontiguousarray(last[:, None, :n_state]), last_state)
    return CudaChainSolution(samples, status, t_stop, nfev, n_steps, work, acc=acc, members=members,
                             last=last_state[:, 0], rates=rates, kernel_seconds=kernel_seconds,
                             seconds=_time.perf_counter() - start)
