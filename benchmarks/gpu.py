"""Benchmark: the CUDA engine (``--engine cuda``) against the CPU engine, on one NVIDIA GPU.

Case 3 of the paper (``configs/paper/case3_embedded.yaml``: embedded, 15 states), DOP853,
rtol 1e-6, atol 1e-8, t_end 2 s, 2001 samples. Two sweeps: ``initial-state`` (Omega ~
N((16, 32, -16), 4^2), one body) and ``parameter`` (mass and inertia x U(0.5, 1.5), K_c and
L_c x U(0.5, 2), K_t x U(0.7, 1.4) and a random Omega: every run another record). Prints:

- **compiled at once**: the CPU engine and the CUDA kernels the run needs, each compiled (or
  loaded from the cache) in a process of its own, at once, before anything is timed: each
  process's seconds (with an empty cache, each kernel's compile beside the others');
- **compile**: the GPU's compute mode, one body's kernel's registers and local memory a
  thread (:func:`rbstab.engine.cuda.compiled_tree_kernel` for one body on an embedded
  joint), the occupancy they allow and the resident threads; the compile (or cache load)
  time in this process and a new process's first launch, its kernel loaded from the disk
  cache;
- **deadline**: 300,000 runs, 100 samples kept, a 0.05 s limit: the kernel's time, the runs
  finished, stopped and not started, and whether every unstarted run's samples and last
  state are NaN;
- **samples** and **launch size**: kernel runs/s with 2, 201 and 2001 samples a run (none
  kept) and with 8,192 / 33,792 / 131,072 / 270,336 runs a launch;
- **kernel** and **end to end** runs/s at each N of ``--n`` (10^4, 10^5, 10^6), with no
  sample kept (the summary store's) and with a thinned trace (201 samples a run): kernel
  time by CUDA events; end to end, from the host's arrays to the results in host memory
  (:func:`rbstab.engine.cuda.integrate_chain_runs_cuda` on Case 3's one-body tree);
- **disturbed**: kernel runs/s of the parameter sweep at the smallest N of ``--n`` with
  saturating actuators and disturbances (:data:`DISTURBED`: every actuator limit, a noise, an
  impulse and a pulse), beside the same runs without them (the same kernel takes both);
- **sweep**: ``rbstab sweep SPEC --engine cuda --store summary`` from process start to
  exit at ``--sweep-n`` runs (warm kernel cache), and ``--store thinned`` at a tenth of it;
- **CPU engine**: runs/s of :func:`rbstab.engine.integrate_runs` on every core of the
  machine (one process a core), on the parameter sweep;
- **correctness** on ``--check-n`` runs of each sweep: statuses equal, step counts equal
  (and the largest difference), the final states' median and largest relative difference
  from the CPU engine's, beside the CPU engine's own difference from an rtol 1e-11 run;
- **chains** (:func:`rbstab.engine.cuda.compiled_tree_kernel`, a kernel per tree size, the
  tree in reduced coordinates): the 2-body kernel's registers and local memory a thread and
  its occupancy;
  kernel and end-to-end runs/s of an initial-state sweep of the stance example
  (``configs/examples/stance_ankle_hip.yaml``: 2 bodies on permanent joints, saturated
  torques; DOP853, rtol 1e-8, atol 1e-10, t_end 2 s, 201 samples streamed into each run's
  summary on the device, none coming back, the end-to-end figure with the summary table; each body's
  theta_1 ~ U(-0.1, 0.1) rad, omega ~ N(0, 0.2^2) rad/s) at
  each N of ``--chain-n``, beside the compiled CPU driver
  (:func:`rbstab.engine.integrate.integrate_chain_runs`) on every core at ``--chain-cpu-n``;
  the same sweep with a tree a run (the trunk's mass and inertia times U(0.8, 1.2) in each
  run's records: a sweep over the chain's parameters, one launch);
  correctness on ``--check-n`` of those runs against the CPU driver (statuses, steps, final
  states, and the summaries streamed on the GPU against the CPU's from its samples);
  Case 3's initial-state sweep at each N of ``--chain-n`` on one body's kernel and on the
  general tree kernel of its one-body tree (kernel runs/s of each, statuses, v(0) and
  v(t_end));
  ``rbstab sweep`` of the stance example over the legs' and trunk's tilt and over
  the trunk's mass, ``--store summary``, at each N of ``--chain-sweep-n`` (20,000), with
  ``--engine cuda`` and ``--engine compiled`` (the CPU's cores), process start to exit.

Usage (on a machine with an NVIDIA GPU and ``pip install -e ".[cuda]"``)::

    python benchmarks/gpu.py [--n 10000 100000 1000000] [--sweep-n 1000000] [--check-n 256]
                             [--chain-n 10000 100000] [--chain-cpu-n 2000] [--chain-sweep-n 20000]
                             [--chains-only | --one-body-only]

``--host-only`` (any machine, no GPU needed) measures what a ``--engine cuda`` sweep costs
besides the GPU: the same ``rbstab sweep`` command with every launch replaced by a stub
that returns finished runs at once (its processes load the stub through a
``sitecustomize`` module in a temporary folder), wall time from process start to exit at
each ``--sweep-n`` with the parent's seconds writing the index and summary, and one
worker's seconds a run in a process of its own
(:func:`rbstab.sweep.worker.run_table_chunk` of a 131072-run slice)::

    python benchmarks/gpu.py --host-only [--sweep-n 100000 1000000] [--jobs N]

``--ptx-only`` (any machine with numba-cuda's compilers and CUDA's ``ptxas``; no GPU
needed) compiles one body's kernel (DOP853, an embedded joint) and the tree kernel (DOP853) for
each tree shape of ``--ptx-trees``
(bodies:permanent joints:embedded joints[:hinges[:universal joints[:balls[:slides]]]];
default one body on a permanent and on an embedded joint, the stance example's 2:2:0, and
8 bodies on permanent and on embedded joints; 3:0:0:3 is the hinged stance) to optimised PTX for sm_90 and prints what ``ptxas -v``
reports for each: the registers, the stack frame (local memory) and the spill stores and
loads a thread, with each compile's seconds::

    python benchmarks/gpu.py --ptx-only [--ptx-trees 1:1:0 1:0:1 2:2:0 8:8:0 8:0:8]
"""

from __future__ import annotations

import argparse
import functools
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE3 = str(ROOT / "configs" / "paper" / "case3_embedded.yaml")
SETTINGS_OVERRIDES = ["simulation.rtol=1e-6", "simulation.atol=1e-8"]
RBSTAB = str(Path(sys.executable).parent / "rbstab")


#: Saturating actuators and disturbances (every actuator limit, a noise, an impulse and a pulse) added
#: to Case 3 for the ``disturbed`` line.
DISTURBED = ["controller.saturation={torque_n: 400, force_h: [300, 300, 500], constraint_force: 2000}",
             "disturbances=[{kind: noise, rms: [50, 50, 0], band: [0.5, 5], seed: 1, point: [0, 0, 0.2]},"
             " {kind: impulse, value: [0, 15, 0], point: [0, 0, 0.2], start: 0.3},"
             " {kind: pulse, quantity: torque, value: [0, 40, 0], start: 1.0, duration: 0.05}]"]


@functools.lru_cache(maxsize=4)
def runs(kind: str, n: int, seed: int = 0, rtol: float = 1e-6, extra: tuple[str, ...] = ()):
    """(codes, params, y0, settings records) of n Case 3 runs of sweep ``kind``, with the
    overrides ``extra`` (e.g. :data:`DISTURBED`); the last few kept (a parameter sweep's
    records take ~70 us a run to build). Read-only: callers slice, never write."""
    import rbstab
    from rbstab.variants.paper import paper_form, paper_initial_state
    from rbstab.engine import method_number
    from rbstab.engine.settings import settings_records
    from rbstab.model import Gains, RigidBody, parameters

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = rbstab.load_config(CASE3, [f"simulation.rtol={rtol}", "simulation.atol=1e-8" if rtol > 1e-9
                                            else "simulation.atol=1e-13", *extra])
    variant = paper_form(config)
    rng = np.random.default_rng(seed)
    y0 = np.repeat(paper_initial_state(config, variant)[None], n, axis=0)
    y0[:, 3:6] = rng.normal([16, 32, -16], 4, size=(n, 3))
    base = variant.parameters
    if kind == "initial-state":
        params = np.repeat(base, n)
    else:
        body, gains = variant.body, variant.gains
        params = np.empty(n, dtype=base.dtype)
        scale = rng.uniform(0.5, 1.5, n)
        kc, lc, kt = rng.uniform(0.5, 2, n), rng.uniform(0.5, 2, n), rng.uniform(0.7, 1.4, n)
        for i in range(n):  # the benchmark's own per-run records (the sweep builds them its way)
            b = RigidBody(body.mass * scale[i], body.inertia * scale[i], body.attachment_point, body.gravity)
            g = Gains(k_t=gains.k_t * kt[i], l_t=gains.l_t, k_r=gains.k_r, l_r=gains.l_r, k_c=gains.k_c * kc[i],
                      l_c=gains.l_c * lc[i], k_d=gains.k_d, l_d=gains.l_d, saturation=gains.saturation,
                      disturbances=gains.disturbances)
            params[i] = parameters(b, g, float(base["lyapunov_offset"][0]))
    s = config.simulation
    rows = np.tile([s.t_end, s.rtol, s.atol, s.max_step, s.gimbal_margin, s.max_steps, np.inf], (n, 1))
    return np.full(n, variant.code), params, y0, settings_records(rows, method_number(s.method)), s.n_samples


@functools.lru_cache(maxsize=4)
def one_body_trees(kind: str, n: int, rtol: float = 1e-6, extra: tuple[str, ...] = ()):
    """(system, y0 (n, 15), settings rows (n, 7), tree_of (n,), n_samples) of the n runs of
    :func:`runs` as the GPU takes them: Case 3's one-body tree
    (:attr:`rbstab.config.RunConfig.chain`) with each run's record, one tree for the
    initial-state sweep, a tree a run for the parameter sweep, each with its h."""
    import rbstab
    from rbstab.engine.systems import tree_system, with_offsets
    from rbstab.variants.chain import compile_chain

    codes, params, y0, settings, n_samples = runs(kind, n, rtol=rtol, extra=extra)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = rbstab.load_config(CASE3, list(extra))
    trees = params[:1] if kind == "initial-state" else params
    system = tree_system(compile_chain(config.chain, offset=0.0))._replace(
        params=np.ascontiguousarray(trees[:, None]), ppoints=np.ascontiguousarray(trees["attachment_point"][:, None]))
    tree_of = np.zeros(n, dtype=np.int64) if kind == "initial-state" else np.arange(n)
    rows = np.column_stack([settings[name] for name in settings.dtype.names[:-1]])
    return with_offsets(system, trees["lyapunov_offset"]), y0, rows, tree_of, n_samples


def gpu_runs(kind: str, n: int, stride=None, extra: tuple[str, ...] = (), n_samples: int | None = None,
             part: slice = slice(None), max_wall_time: float = np.inf):
    """The GPU's solution (:func:`rbstab.engine.cuda.integrate_chain_runs_cuda`) of the runs
    ``part`` of :func:`one_body_trees`, every ``stride``-th sample kept (None: none)."""
    from rbstab.engine.cuda import integrate_chain_runs_cuda

    system, y0, rows, tree_of, default = one_body_trees(kind, n, extra=extra)
    return integrate_chain_runs_cuda(system, y0[part], rows[part], method="DOP853", n_samples=n_samples or default,
                                     stride=stride, tree_of=tree_of[part], max_wall_time=max_wall_time)


def gpu_rates(kind: str, n: int, stride, extra: tuple[str, ...] = ()):
    """(kernel, end-to-end) runs/s of n runs of sweep ``kind`` (overrides ``extra``)."""
    one_body_trees(kind, n, extra=extra)  # the host's arrays, built before the clock starts
    start = time.perf_counter()
    sol = gpu_runs(kind, n, stride, extra)
    return n / sol.kernel_seconds, n / (time.perf_counter() - start)


def _cpu_part(args):
    from rbstab.engine import integrate_runs

    kind, n, seed = args
    codes, params, y0, settings, n_samples = runs(kind, n, seed)
    rows = np.column_stack([settings[name] for name in settings.dtype.names[:-1]])
    start = time.process_time()
    for lo in range(0, n, 64):
        integrate_runs(codes[lo:lo + 64], params[lo:lo + 64], y0[lo:lo + 64], rows[lo:lo + 64], method="DOP853",
                       n_samples=n_samples)
    return time.process_time() - start


def cpu_rate(kind: str, n: int) -> float:
    """Runs/s of sweep ``kind`` on the compiled CPU engine, one process a core (the kernels
    compiled, or loaded from the cache, before the clock starts)."""
    cores = os.cpu_count() or 1
    _cpu_part((kind, 2, 0))
    with ProcessPoolExecutor(cores) as pool:
        list(pool.map(_cpu_part, [(kind, 2, seed) for seed in range(cores)]))  # each process's kernels loaded
        start = time.perf_counter()
        list(pool.map(_cpu_part, [(kind, n // cores, seed) for seed in range(cores)]))
        return (n // cores) * cores / (time.perf_counter() - start)


def correctness(kind: str, n: int) -> str:
    from rbstab.engine import integrate_runs

    codes, params, y0, settings, n_samples = runs(kind, n)
    rows = np.column_stack([settings[name] for name in settings.dtype.names[:-1]])
    cpu = integrate_runs(codes, params, y0, rows, method="DOP853", n_samples=2)
    gpu = gpu_runs(kind, n, stride=1, n_samples=2)
    fine_codes, fine_params, fine_y0, fine_settings, _ = runs(kind, n, rtol=1e-11)
    fine_rows = np.column_stack([fine_settings[name] for name in fine_settings.dtype.names[:-1]])
    fine = integrate_runs(fine_codes, fine_params, fine_y0, fine_rows, method="DOP853", n_samples=2)
    final_gpu, final_cpu, final_fine = gpu.samples[:, -1], cpu.samples[:, -1], fine.samples[:, -1]
    scale = np.max(np.abs(final_cpu), axis=1)
    rel = np.max(np.abs(final_gpu - final_cpu), axis=1) / scale
    own = np.max(np.abs(final_cpu - final_fine), axis=1) / scale
    steps = np.abs(gpu.n_steps - cpu.n_steps)
    return (f"statuses equal {int(np.sum(gpu.status == cpu.status))}/{n}; steps equal {int(np.sum(steps == 0))}/{n} "
            f"(max {int(steps.max())} apart); final states rel. diff median {np.median(rel):.2g}, max {rel.max():.2g}; "
            f"CPU engine vs rtol 1e-11: median {np.median(own):.2g}, max {own.max():.2g}")


#: What each process of :func:`compile_all` compiles (or loads from the cache).
COMPILES = {
    "cpu": "from rbstab.engine.warm import ensure_compiled; ensure_compiled(sign_law=True, chain=True)",
    "one-body": "from rbstab.engine.cuda import compiled_tree_kernel; from rbstab.engine.rk import DOP853; "
                "compiled_tree_kernel(DOP853, (1, 0, 1), True)",
    "tree": "from rbstab.engine.cuda import compiled_tree_kernel; from rbstab.engine.rk import DOP853; "
            "compiled_tree_kernel(DOP853, (2, 2, 0))",
}


def compile_all(parts) -> str:
    """The kernels of ``parts`` (keys of :data:`COMPILES`: the CPU engine, the one-body and
    the stance tree CUDA kernels) compiled at once, each in a process of its own (numba
    compiles on one core), before anything is timed: each process's wall seconds."""
    start = time.perf_counter()

    def compile_one(part: str) -> str:
        done = subprocess.run([sys.executable, "-c", COMPILES[part]], capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"compiling {part} failed:\n{done.stderr}")
        return f"{part} {time.perf_counter() - start:.1f} s"

    with ThreadPoolExecutor(len(parts)) as pool:
        return ", ".join(pool.map(compile_one, parts))


def compile_info() -> str:
    """One body's kernel's (Case 3: an embedded joint) compute mode, registers, local
    memory, occupancy and compile (or load) time."""
    from numba import cuda

    from rbstab.engine.cuda import (THREADS_PER_BLOCK, compiled_tree_kernel, compute_mode, kernel_resources,
                                    occupancy, tree_launch_signature)
    from rbstab.engine.rk import DOP853

    start = time.perf_counter()
    fn = compiled_tree_kernel(DOP853, (1, 0, 1), True)
    loaded = time.perf_counter() - start
    signature = tree_launch_signature()
    regs, local = kernel_resources(fn, signature)
    device = cuda.get_current_device()
    per_sm = occupancy(fn, signature)
    sms = device.MULTIPROCESSOR_COUNT
    share = per_sm * THREADS_PER_BLOCK / device.MAX_THREADS_PER_MULTIPROCESSOR
    gpu_runs("parameter", 128)
    script = (f"import sys, time; sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); import gpu; "
              "gpu.one_body_trees('parameter', 128); t = time.perf_counter(); gpu.gpu_runs('parameter', 128); "
              "print(time.perf_counter() - t)")
    again = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    name = device.name.decode() if isinstance(device.name, bytes) else device.name
    return (f"{name}, compute mode {compute_mode()}: {regs} registers, {local} B local memory a thread; "
            f"{per_sm} blocks of {THREADS_PER_BLOCK} a multiprocessor (occupancy {share:.0%}), "
            f"{per_sm * THREADS_PER_BLOCK * sms:,} resident threads on {sms} multiprocessors; "
            f"compiled or loaded in {loaded:.1f} s; a new process's first launch {float(again.stdout.split()[-1]):.2f} s "
            f"(the kernel from the disk cache)")


def deadline(n: int = 300_000, n_samples: int = 100, limit: float = 0.05) -> str:
    """A launch stopped by its limit: its kernel time and what its runs report."""
    from rbstab.engine.status import NOT_STARTED, SUCCESS, TIMEOUT

    sol = gpu_runs("parameter", n, stride=1, n_samples=n_samples, max_wall_time=limit)
    unstarted = sol.status == NOT_STARTED
    nan = bool(np.isnan(sol.samples[unstarted]).all() and np.isnan(sol.last[unstarted]).all())
    return (f"{n:,} runs, limit {limit} s: kernel {sol.kernel_seconds:.3f} s; "
            f"{int(np.sum(sol.status == SUCCESS)):,} finished, {int(np.sum(sol.status == TIMEOUT)):,} "
            f"stopped, {int(unstarted.sum()):,} not started (their samples and last state NaN: {nan})")


def kernel_rate(n: int, n_samples: int, launch: int | None = None) -> float:
    """Kernel runs/s of the parameter sweep, no sample kept, ``n_samples`` a run, launches
    of ``launch`` runs (one call each)."""
    launch = launch or n
    seconds = sum(gpu_runs("parameter", n, n_samples=n_samples, part=slice(lo, lo + launch)).kernel_seconds
                  for lo in range(0, n, launch))
    return n / seconds


# -- chains -----------------------------------------------------------------------------------------
STANCE = str(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml")


def stance_chain():
    """(the stance example's configuration with the **chains** settings, its compiled chain)."""
    from rbstab.config.loader import load_config
    from rbstab.variants import chain as C

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(STANCE, ["simulation.t_end=2.0", "simulation.n_samples=201",
                                      "simulation.rtol=1e-8", "simulation.atol=1e-10"])
    return config, C.compile_chain(config.chain)


def chain_runs(n: int, seed: int = 0, parameters: bool = False):
    """(system, y0 (n, n_state), settings rows (n, 7), method, n_samples, tree_of) of n runs
    of the stance example's initial-state sweep (module docstring); ``parameters``: each
    run also its own tree, the trunk's mass and inertia times U(0.8, 1.2) (``system`` holds
    n trees, ``tree_of`` arange(n); else None)."""
    from rbstab.engine.settings import settings_rows
    from rbstab.engine.systems import tree_system
    from rbstab.variants import chain as C

    config, compiled = stance_chain()
    coordinates = C.independent_coordinates(compiled)
    rng = np.random.default_rng(seed)
    z = np.zeros((n, 3 * len(coordinates)))
    for k, (_, block, _) in enumerate(coordinates):
        if block == "theta":
            z[:, 3 * k] = rng.uniform(-0.1, 0.1, n)
        elif block == "omega":
            z[:, 3 * k: 3 * k + 3] = rng.normal(0.0, 0.2, (n, 3))
    sim = config.simulation
    rows = np.repeat(settings_rows([sim]), n, axis=0)
    rows[:, 6] = np.inf
    system, tree_of = tree_system(compiled, sim.limits), None
    if parameters:
        params = np.repeat(system.params[None], n, axis=0)
        scale = rng.uniform(0.8, 1.2, n)
        params[:, 1]["mass"] *= scale
        params[:, 1]["inertia"] *= scale[:, None, None]
        system = system._replace(params=params, ppoints=np.repeat(system.ppoints[None], n, axis=0))
        tree_of = np.arange(n)
    return system, C.full_state(compiled, z), rows, sim.method, sim.n_samples, tree_of


def body_as_tree(n: int) -> str:
    """Case 3's initial-state sweep (n runs, rtol 1e-6, summaries streamed, no sample back)
    on one body's kernel (the body's record and rate) and on the general tree kernel of its
    one-body tree (1 body on an embedded joint, reduced coordinates): kernel runs/s of each,
    and the runs' agreement (statuses, v(0) and v(t_end) relative to max |v(0)|). What
    decides whether the tree kernel keeps its one-body specialisation."""
    import rbstab.engine.cuda as engine
    from rbstab.engine.status import SUCCESS
    from rbstab.summary import LAST_ABOVE, V_INITIAL, streamed_final_lyapunov

    body = gpu_runs("initial-state", n)
    one_body = engine.is_one_body
    engine.is_one_body = lambda *args: False  # the general tree's kernel for the same trees
    try:
        tree = gpu_runs("initial-state", n)
    finally:
        engine.is_one_body = one_body
    scale = np.max(np.abs(body.acc[:, V_INITIAL]))
    worst = max(np.max(np.abs(body.acc[:, V_INITIAL] - tree.acc[:, V_INITIAL])),
                np.nanmax(np.abs(streamed_final_lyapunov(body.acc) - streamed_final_lyapunov(tree.acc))))
    return (f"one body's kernel {n / body.kernel_seconds:,.0f} runs/s, the general tree kernel (1:0:1) "
            f"{n / tree.kernel_seconds:,.0f} runs/s ({body.kernel_seconds / tree.kernel_seconds:.2f}x one body's "
            f"rate); statuses equal {int(np.sum(body.status == tree.status))}/{n} "
            f"({int(np.sum(tree.status == SUCCESS))} success), last sample not converged equal "
            f"{int(np.sum(body.acc[:, LAST_ABOVE] == tree.acc[:, LAST_ABOVE]))}/{n}; v(0), v(t_end) largest difference "
            f"{worst / scale:.2g} of max |v(0)|")


def chain_compile_info() -> str:
    """The stance example's tree kernel's (2 bodies on permanent joints) registers, local
    memory, occupancy and compile (or load) time."""
    from numba import cuda

    from rbstab.engine.cuda import (THREADS_PER_BLOCK, compiled_tree_kernel, kernel_resources, occupancy,
                                    tree_launch_signature)
    from rbstab.engine.rk import DOP853

    start = time.perf_counter()
    fn = compiled_tree_kernel(DOP853, (2, 2, 0))
    loaded = time.perf_counter() - start
    regs, local = kernel_resources(fn, tree_launch_signature())
    device = cuda.get_current_device()
    per_sm = occupancy(fn, tree_launch_signature())
    share = per_sm * THREADS_PER_BLOCK / device.MAX_THREADS_PER_MULTIPROCESSOR
    return (f"{regs} registers, {local} B local memory "
            f"a thread; {per_sm} blocks of {THREADS_PER_BLOCK} a multiprocessor (occupancy {share:.0%}); compiled "
            f"or loaded in {loaded:.1f} s")


def chain_gpu_rates(n: int, parameters: bool = False) -> tuple[float, float]:
    """(kernel, end-to-end) runs/s of n runs of the chain sweep (the summaries streamed, no
    sample back; end to end with the summary table); ``parameters``: a tree a run
    (:func:`chain_runs`)."""
    from rbstab.engine.cuda import integrate_chain_runs_cuda
    from rbstab.summary import tree_stream_table

    system, y0, rows, method, n_samples, tree_of = chain_runs(n, parameters=parameters)
    start = time.perf_counter()
    sol = integrate_chain_runs_cuda(system, y0, rows, method=method, n_samples=n_samples, stride=None,
                                    tree_of=tree_of)
    tree_stream_table(np.linspace(0.0, float(rows[0, 0]), n_samples), sol.acc, sol.members, sol.last,
                      len(system.codes), np.asarray(system.d_at))
    return n / sol.kernel_seconds, n / (time.perf_counter() - start)


def _chain_cpu_part(args) -> None:
    from rbstab.engine.integrate import integrate_chain_runs

    n, seed = args
    system, y0, rows, method, n_samples, _ = chain_runs(n, seed)
    for lo in range(0, n, 64):
        integrate_chain_runs(system, y0[lo:lo + 64], rows[lo:lo + 64], method=method, n_samples=n_samples)


def chain_cpu_rate(n: int, cores: int | None = None) -> float:
    """Runs/s of the chain sweep on the compiled CPU driver, one process a core (the kernels
    compiled, or loaded from the cache, before the clock starts)."""
    cores = cores or os.cpu_count() or 1
    _chain_cpu_part((2, 0))
    with ProcessPoolExecutor(cores) as pool:
        list(pool.map(_chain_cpu_part, [(2, seed) for seed in range(cores)]))  # each process's kernels loaded
        start = time.perf_counter()
        list(pool.map(_chain_cpu_part, [(n // cores, seed) for seed in range(cores)]))
        return (n // cores) * cores / (time.perf_counter() - start)


def chain_correctness(n: int) -> str:
    """The GPU's chain runs against the CPU driver's: statuses, steps, final states, and the
    figures streamed on the GPU (no sample back) against the CPU's from its samples (the
    largest difference of v(0), v(t_end), max dv/dt and the rate check's mismatch, relative
    to max |v(0)|; of cop_excursion, relative to its largest)."""
    from rbstab.engine.cuda import integrate_chain_runs_cuda
    from rbstab.engine.integrate import integrate_chain_runs
    from rbstab.simulator import _trees_outputs
    from rbstab.summary import tree_stream_table
    from rbstab.variants import chain as C

    system, y0, rows, method, n_samples, tree_of = chain_runs(n, parameters=True)
    cpu = integrate_chain_runs(system, y0, rows, method=method, n_samples=n_samples, tree_of=tree_of)
    gpu = integrate_chain_runs_cuda(system, y0, rows, method=method, n_samples=n_samples, stride=None,
                                    tree_of=tree_of)
    final_cpu, final_gpu = cpu.samples[:, -1], gpu.last
    rel = np.max(np.abs(final_gpu - final_cpu), axis=1) / np.max(np.abs(final_cpu), axis=1)
    steps = np.abs(gpu.n_steps - cpu.n_steps)
    time_grid = np.linspace(0.0, float(rows[0, 0]), n_samples)
    structure = stance_chain()[1]  # each run's records, h 0 on both sides
    trees = [C.with_records(structure, system.params[t], system.ppoints[t]) for t in range(len(system.params))]
    _, table = _trees_outputs([trees[t] for t in tree_of], tree_of, time_grid, cpu.samples, cpu.work, False)
    streamed = tree_stream_table(time_grid, gpu.acc, gpu.members, gpu.last, len(system.codes), np.asarray(system.d_at))
    scale = np.max(np.abs(table["lyapunov_initial"]))
    worst = max(float(np.nanmax(np.abs(streamed[k] - table[k]))) for k in
                ("lyapunov_initial", "lyapunov_final", "max_lyapunov_rate", "lyapunov_rate_mismatch")) / scale
    pressure = float(np.nanmax(np.abs(streamed["cop_excursion"] - table["cop_excursion"]))
                     / np.nanmax(np.abs(table["cop_excursion"])))
    return (f"statuses equal {int(np.sum(gpu.status == cpu.status))}/{n}; steps equal {int(np.sum(steps == 0))}/{n} "
            f"(max {int(steps.max())} apart); final states rel. diff median {np.median(rel):.2g}, max {rel.max():.2g}; "
            f"streamed summaries against the CPU's: largest difference {worst:.2g} of max |v(0)|, of the centre of "
            f"pressure's excursion {pressure:.2g} of its largest")


#: The stub of ``--host-only``: every launch of the CUDA engine returns its runs finished
#: (SUCCESS at t_end, a full accumulator) at once.
STUB = """
import os
if os.environ.get("RBSTAB_BENCHMARK_STUB_GPU"):
    import numpy as np
    import rbstab.engine.cuda as cuda
    from rbstab.summary import ACCUMULATOR_SIZE, MEMBER_SLOTS, TAKEN

    def chain_launch(system, y0, settings, *, method, n_samples, stride=1, max_wall_time=np.inf, tree_of=None,
                     ratio=1e-3):
        # every run at t_end, still at its initial state (maximal), a full accumulator
        k, n_kept = len(y0), 0 if stride is None else len(range(0, n_samples, stride))
        y0 = np.asarray(y0, dtype=float)
        acc = np.ones((k, ACCUMULATOR_SIZE))
        acc[:, TAKEN] = n_samples
        return cuda.CudaChainSolution(np.repeat(y0[:, None], n_kept, axis=1), np.zeros(k, np.int64),
                                      np.asarray(settings, dtype=float)[:, 0].copy(), np.full(k, 500),
                                      np.full(k, 40), np.zeros((k, n_kept)), acc=acc,
                                      members=np.zeros((k, len(system.codes), MEMBER_SLOTS)), last=y0.copy(),
                                      rates=np.zeros((k, n_kept)))

    cuda.check_available = lambda: None
    cuda.integrate_chain_runs_cuda = chain_launch

    import sys
    import time
    import rbstab.sweep.folder as folder

    write_index = folder.write_table_index

    def timed_index(*args, **kwargs):  # the parent's index writing, said on stderr
        start = time.perf_counter()
        try:
            return write_index(*args, **kwargs)
        finally:
            print(f"benchmark: index written in {time.perf_counter() - start:.2f} s", file=sys.stderr)

    folder.write_table_index = timed_index
"""


def host_only(sizes: list[int], jobs: int | None, chain_sizes: list[int] = ()) -> None:
    """``--host-only``: a ``--engine cuda`` sweep's time with the GPU's part taken away."""
    with tempfile.TemporaryDirectory() as stub:
        Path(stub, "sitecustomize.py").write_text(STUB)
        env = dict(os.environ, RBSTAB_BENCHMARK_STUB_GPU="1",
                   PYTHONPATH=os.pathsep.join(filter(None, [stub, os.environ.get("PYTHONPATH")])))
        script = (f"import sys, time; sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); import gpu; "
                  "print(gpu.worker_seconds(131072))")
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
        print(f"one worker, {131072} runs (run_table_chunk, --store summary): "
              f"{float(done.stdout.split()[-1]) * 1e6:.1f} us a run")
        for axis in ("tilt", "mass"):  # a tree's runs: the sweep's host part
            chain_sweep_seconds(200, axis, "cuda", env=env)  # the compile cache, warm
            for n in chain_sizes:
                wall = chain_sweep_seconds(n, axis, "cuda", env=env)
                print(f"rbstab sweep of the stance example over the {axis} --engine cuda --store summary, N = {n}, "
                      f"GPU stubbed: {wall:.1f} s ({wall / n * 1e6:.1f} us a run)")
        sweep_seconds(1000, "summary", env=env, jobs=jobs)  # the compile cache, warm
        for n in sizes:
            times: dict = {}
            wall = sweep_seconds(n, "summary", env=env, jobs=jobs, times=times)
            print(f"rbstab sweep --engine cuda --store summary{f' -j {jobs}' if jobs else ''}, N = {n}, "
                  f"GPU stubbed: {wall:.1f} s ({wall / n * 1e6:.1f} us a run); the parent's index writing "
                  f"{times.get('index', float('nan')):.2f} s")


def worker_seconds(n: int) -> float:
    """Seconds a run of :func:`rbstab.sweep.worker.run_table_chunk` of an n-run slice of the
    parameter sweep (``--store summary``), after a first slice (imports, caches)."""
    from rbstab.sweep import spec_from_mapping
    from rbstab.sweep.table import plan_table
    from rbstab.sweep.worker import WorkerOptions, run_table_chunk

    spec = spec_from_mapping({"name": "host", "base": CASE3, "random": {"n": n, "seed": 1, "params": {
        "body.mass": {"scale_uniform": [0.5, 1.5]}, "controller.k_c": {"scale_uniform": [0.5, 2]},
        "controller.l_c": {"scale_uniform": [0.5, 2]}, "controller.k_t": {"scale_uniform": [0.7, 1.4]},
        "initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}}}, overrides=SETTINGS_OVERRIDES)
    table = plan_table(spec)
    options = WorkerOptions(engine="cuda", store="summary", parameters=table.parameters(), sweep="host")
    with tempfile.TemporaryDirectory() as folder:
        run_table_chunk(table.slice(np.arange(1000)), options, folder)
        start = time.perf_counter()
        run_table_chunk(table.slice(np.arange(n)), options, folder)
        return (time.perf_counter() - start) / n


def sweep_seconds(n: int, store: str, *, env: dict | None = None, jobs: int | None = None,
                  times: dict | None = None) -> float:
    """Wall seconds of the sweep's command; ``times["index"]``: the parent's seconds writing
    the index and summary, where the ``--host-only`` stub says them."""
    folder = Path(tempfile.mkdtemp())
    try:
        cmd = [RBSTAB, "sweep", CASE3, "--random", "body.mass=scale_uniform:[0.5,1.5]",
               "--random", "controller.k_c=scale_uniform:[0.5,2]", "--random", "controller.l_c=scale_uniform:[0.5,2]",
               "--random", "controller.k_t=scale_uniform:[0.7,1.4]",
               "--random", "initial_state.omega=normal:{mean: [16,32,-16], std: 4}", "-n", str(n),
               "--engine", "cuda", "--store", store, "--no-progress", "-o", str(folder),
               *[a for o in SETTINGS_OVERRIDES for a in ("--set", o)], *(["-j", str(jobs)] if jobs else [])]
        start = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - start
        if done.returncode != 0:
            raise SystemExit(done.stderr)
        said = [line.split()[-2] for line in done.stderr.splitlines() if line.startswith("benchmark: index written")]
        if times is not None and said:
            times["index"] = float(said[-1])
        return wall
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def chain_sweep_seconds(n: int, axis: str, engine: str, env: dict | None = None) -> float:
    """Wall seconds of ``rbstab sweep`` of n runs of the stance example (the **chains**
    settings: rtol 1e-8, atol 1e-10, 2 s, 201 samples; ``--store summary``, the command's
    default ``-j``) over ``axis`` (``"tilt"``: the legs' and the trunk's theta_1 ~ U(-0.1,
    0.1) rad, one chain; ``"mass"``: the trunk's mass times U(0.8, 1.2), a chain a run) on
    ``engine``, from process start to exit."""
    random = {"tilt": ["initial_state.legs.theta.0=uniform:[-0.1,0.1]", "initial_state.trunk.theta.0=uniform:[-0.1,0.1]"],
              "mass": ["bodies.trunk.mass=scale_uniform:[0.8,1.2]"]}[axis]
    settings = ["simulation.t_end=2.0", "simulation.n_samples=201", "simulation.rtol=1e-8", "simulation.atol=1e-10"]
    folder = Path(tempfile.mkdtemp())
    try:
        cmd = [RBSTAB, "sweep", STANCE, *[a for r in random for a in ("--random", r)], "-n", str(n), "--engine", engine,
               "--store", "summary", "--no-progress", "-o", str(folder), *[a for o in settings for a in ("--set", o)]]
        start = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if done.returncode != 0:
            raise SystemExit(done.stderr)
        return time.perf_counter() - start
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def ptx_only(shapes) -> None:
    """The ``ptxas -v`` lines of one body's kernel and of the tree kernel of each tree
    shape of ``shapes`` (bodies, permanent joints, embedded joints[, hinges, universal joints, balls, slides];
    module docstring,
    ``--ptx-only``)."""
    import re

    import numba.cuda.dispatcher
    from numba import cuda

    from rbstab.engine.cuda import tree_kernel_function, tree_launch_signature
    from rbstab.engine.rk import DOP853

    ptxas = shutil.which("ptxas")
    if ptxas is None:
        raise SystemExit("ptxas (CUDA's PTX assembler) is not on PATH")

    class Device:  # numba-cuda asks the current device's compute capability for called dispatchers
        compute_capability = (9, 0)

    numba.cuda.dispatcher.get_current_device = lambda: Device()
    kernels = {"one body's kernel (DOP853, an embedded joint)": (tree_kernel_function(DOP853, (1, 0, 1), True),
                                                                tree_launch_signature())}
    for shape in shapes:
        n, p, e, h, u, b, s = (*shape, 0, 0, 0, 0)[:7]
        kernels[f"tree kernel (DOP853, {n} bodies, {p} permanent, {e} embedded, {h} hinge, {u} universal, {b} "
                f"ball and {s} slide joints)"] = (tree_kernel_function(DOP853, (n, p, e, h, u, b, s)),
                                                  tree_launch_signature())
    for name, (function, signature) in kernels.items():
        start = time.perf_counter()
        ptx, _ = cuda.compile_ptx(function, signature, cc=(9, 0), opt=True)
        with tempfile.NamedTemporaryFile("w", suffix=".ptx") as handle:
            handle.write(ptx)
            handle.flush()
            report = subprocess.run([ptxas, "-v", "-arch=sm_90", handle.name, "-o", os.devnull],
                                    capture_output=True, text=True, check=True).stderr
        entry = report[report.index("Compiling entry function"):]
        regs = re.search(r"Used (\d+) registers", entry).group(1)
        frame, stores, loads = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads",
                                         entry).groups()
        print(f"{name}: {regs} registers, {int(frame):,} B stack frame (local memory), {int(stores):,} B spill stores, "
              f"{int(loads):,} B spill loads a thread ({time.perf_counter() - start:.0f} s to PTX and ptxas)")


def chains(args) -> None:
    """The lines of the tree kernel (module docstring, **chains**)."""
    print("chains, compile:", chain_compile_info())
    for n in args.chain_n:
        kernel, total = chain_gpu_rates(n)
        print(f"chains, stance sweep, {n:,} runs: kernel {kernel:,.0f} runs/s, end to end {total:,.0f} runs/s")
        kernel, total = chain_gpu_rates(n, parameters=True)
        print(f"chains, stance sweep, a tree a run, {n:,} runs: kernel {kernel:,.0f} runs/s, end to end "
              f"{total:,.0f} runs/s")
    for n in args.chain_n:
        print(f"chains, Case 3's initial-state sweep as one body and as its one-body tree, {n:,} runs: "
              f"{body_as_tree(n)}")
    print(f"chains, correctness, {args.check_n} runs: {chain_correctness(args.check_n)}")
    print(f"chains, CPU driver, {os.cpu_count()} processes, stance sweep: {chain_cpu_rate(args.chain_cpu_n):,.0f} runs/s")
    chain_sweep_seconds(1000, "tilt", "cuda")  # each process's kernels loaded from the cache once
    for n in args.chain_sweep_n:
        for axis in ("tilt", "mass"):
            cuda, compiled = (chain_sweep_seconds(n, axis, engine) for engine in ("cuda", "compiled"))
            print(f"chains, rbstab sweep of the stance example over the {axis}, {n:,} runs: --engine cuda {cuda:.1f} s, "
                  f"--engine compiled {compiled:.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--sweep-n", type=int, nargs="+", default=[1_000_000])
    parser.add_argument("--host-only", action="store_true",
                        help="no GPU: a cuda sweep's time with every launch stubbed (module docstring)")
    parser.add_argument("--jobs", type=int, default=None, help="-j of the sweeps (default: the sweep's own)")
    parser.add_argument("--check-n", type=int, default=256)
    parser.add_argument("--cpu-n", type=int, default=20_000)
    parser.add_argument("--chain-n", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--chain-cpu-n", type=int, default=2000)
    parser.add_argument("--chain-sweep-n", type=int, nargs="+", default=[20_000])
    parser.add_argument("--chains-only", action="store_true", help="only the tree kernel's lines")
    parser.add_argument("--one-body-only", action="store_true", help="all but the tree kernel's lines")
    parser.add_argument("--ptx-trees", nargs="+", default=["1:1:0", "1:0:1", "2:2:0", "8:8:0", "8:0:8"],
                        help="tree shapes of --ptx-only, "
                             "BODIES:PERMANENT:EMBEDDED[:HINGES[:UNIVERSAL[:BALLS[:SLIDES]]]]")
    parser.add_argument("--ptx-only", action="store_true",
                        help="no GPU: each kernel's registers and local memory by ptxas (module docstring)")
    args = parser.parse_args()
    if args.ptx_only:
        ptx_only([tuple(int(x) for x in shape.split(":")) for shape in args.ptx_trees])
        return
    if args.host_only:
        host_only(args.sweep_n, args.jobs, args.chain_sweep_n)
        return
    from rbstab.engine.cuda import check_available

    check_available()
    parts = ["cpu"] + ([] if args.chains_only else ["one-body"]) + ([] if args.one_body_only else ["tree"])
    print("compiled at once, each in a process of its own (empty cache: a compile; else a load):",
          compile_all(parts))
    if args.chains_only:
        chains(args)
        return
    print("compile:", compile_info())
    print("deadline:", deadline())
    for n_samples in (2, 201, 2001):
        print(f"samples {n_samples:5d}, 270,336 runs: kernel {kernel_rate(270_336, n_samples):,.0f} runs/s")
    for launch in (8192, 33_792, 131_072, 270_336):
        print(f"launches of {launch:7,d} runs (540,672 runs, 2001 samples): kernel "
              f"{kernel_rate(540_672, 2001, launch):,.0f} runs/s")
    print(f"{'sweep':14s} {'N':>9s} {'trace':>8s} {'kernel runs/s':>14s} {'end to end runs/s':>18s}")
    for kind in ("initial-state", "parameter"):
        for n in args.n:
            for stride, label in ((None, "none"), (10, "201")):
                if stride and n > 100_000:
                    continue  # 201 samples x 10^6 runs: the samples alone take 26 GB
                kernel, total = gpu_rates(kind, n, stride)
                print(f"{kind:14s} {n:9d} {label:>8s} {kernel:14,.0f} {total:18,.0f}")
    n = min(args.n)
    plain, disturbed = gpu_rates("parameter", n, None)[0], gpu_rates("parameter", n, None, tuple(DISTURBED))[0]
    print(f"disturbed: parameter sweep, {n:,} runs, every actuator limit, a noise, an impulse and a pulse: "
          f"kernel {disturbed:,.0f} runs/s, {plain / disturbed:.2f}x the time a run without them ({plain:,.0f} runs/s)")
    print(f"CPU engine, {os.cpu_count()} processes, parameter sweep: {cpu_rate('parameter', args.cpu_n):,.0f} runs/s")
    for kind in ("initial-state", "parameter"):
        print(f"correctness, {kind}, {args.check_n} runs: {correctness(kind, args.check_n)}")
    if not args.one_body_only:
        chains(args)
    sweep_seconds(1000, "summary")  # the kernel cache, warm
    for n in args.sweep_n:
        print(f"rbstab sweep --engine cuda --store summary, N = {n}: {sweep_seconds(n, 'summary', jobs=args.jobs):.1f} s")
        n = max(n // 10, 1000)
        print(f"rbstab sweep --engine cuda --store thinned, N = {n}: {sweep_seconds(n, 'thinned', jobs=args.jobs):.1f} s")


if __name__ == "__main__":
    main()
