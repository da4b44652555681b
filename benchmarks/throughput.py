"""Benchmark (issue 5): sweep throughput against one-by-one solve_ivp, accuracy, memory, start-up.

Case 3 of the paper (embedded, eq 22; ``configs/paper/case3_embedded.yaml``: t_end = 2 s,
2001 samples) at rtol = 1e-6, atol = 1e-8 (``--method``, default DOP853), for N runs whose
initial Omega is drawn from N((16, 32, -16), 2^2) rad/s (seed 0), measured in one
invocation on this machine:

(a) **baseline**: one ``scipy.integrate.solve_ivp`` call per run (``t_eval`` at the 2001
    samples), with a plain numpy right-hand side written below (:func:`baseline_rhs`: no
    compilation, no batching; checked against the project's model at random states);
(b) the same N runs through ``rbstab sweep SPEC -j JOBS --store STORE --layout LAYOUT
    --no-progress`` (the default engine, batch), timed from process start to exit, for each
    ``--setting STORE:LAYOUT`` (default: ``summary:chunk``, ``full:chunk``, ``summary:run``);
    and through the library call behind it, ``expand`` + ``run_sweep`` on a
    ``LocalExecutor(JOBS)`` that ran a sweep before (its workers started: a Python
    session's second sweep), with the first setting.

The time split comes from a second, identical sweep in an instrumented process that does
what the command does (workers started before planning, ``expand``, ``run_sweep``).

Prints runs per second of both, their ratio, the largest difference of the final states
of (a) and (b) from a tight-tolerance reference (DOP853, rtol 1e-10, atol 1e-12; on the
first ``--ref-n`` runs when N is larger), where the time of (b) goes (a second, identical
sweep in an instrumented process: start-up and imports, planning, the workers' config,
integration -- split into right-hand side and solver bookkeeping by an instrumented
chunk -- post-processing and file writing, and the parent's share), the peak resident
set size of the sweep's parent and of its largest worker (``getrusage`` ``ru_maxrss``),
the end-to-end time of ``rbstab run configs/paper/case3_embedded.yaml`` (best of 3 with the
bytecode cached), its cold-start time (first run with an empty bytecode cache; rbstab has no
compilation cache: the engine is numpy), and the wall time and memory of a ``--memory-n`` (10,000) run sweep.

Every timed subprocess keeps Python's bytecode in one private cache (:func:`bytecode_env`),
filled by an untimed sweep of a few runs before the first timing, as on any machine where
rbstab ran before; only the cold start begins from an empty one.

Usage::

    python benchmarks/throughput.py [--n 1000] [--jobs 2] [--setting STORE:LAYOUT ...]
                                    [--baseline-n N] [--rounds 3] [--ref-n 100] [--memory-n 10000]
                                    [--skip-single] [--keep DIR]

The host's speed drifts over minutes, so (a) is timed in ``--rounds`` slices, each followed
by one timing of every (b) setting: (a)'s rate is over all its runs, (b)'s is the median of
its rounds (each round is printed).

``--baseline-n`` times only that many baseline runs (the rate is per run, so a smaller
number is a quick look; the default is all N). ``--memory-n 0`` skips the large sweep.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
RBSTAB = Path(sys.executable).with_name("rbstab")

# -- (a) the baseline: a plain numpy right-hand side of Case 3 (eq 1 under eq 22) ----------------

M = 41.0
J = np.diag([10.0, 8.0, 0.4])
J_INV = np.linalg.inv(J)
R = np.array([0.15, 0.10, -0.42])
G = np.zeros(3)
K_T, L_T = np.diag([4100.0, 4100, 3280]), np.diag([200.0, 200, 140])
K_R, L_R = np.diag([400.0, 400, 320]), np.diag([60.0, 60, 42])
K_C, L_C = np.diag([12300.0, 12300, 9840]), np.diag([600.0, 600, 420])
K_D, L_D_INV = K_C, np.linalg.inv(np.diag([1200.0, 1200, 840]))


def hat(r):
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


R_HAT = hat(R)


def baseline_rhs(t, y):
    """d/dt (Theta, Omega, X, V, D) for one state, the straightforward way."""
    theta, omega, x, v, d = y[0:3], y[3:6], y[6:9], y[9:12], y[12:15]
    c1, c2, c3 = np.cos(theta)
    s1, s2, s3 = np.sin(theta)
    A = np.array([
        [c2 * c3, -c2 * s3, s2],
        [c1 * s3 + s1 * s2 * c3, c1 * c3 - s1 * s2 * s3, -s1 * c2],
        [s1 * s3 - c1 * s2 * c3, s1 * c3 + c1 * s2 * s3, c1 * c2],
    ])
    B = np.array([[c3 / c2, -s3 / c2, 0.0], [s3, c3, 0.0], [-s2 * c3 / c2, s2 * s3 / c2, 1.0]])
    E = x + A @ R - R
    F = v - A @ (R_HAT @ omega)
    spring = K_C @ (E - d)
    d_dot = L_D_INV @ (spring - K_D @ d)
    lam = -spring - L_C @ F
    N = -B.T @ (K_R @ theta) - L_R @ omega
    H = -K_T @ x - L_T @ v
    omega_dot = J_INV @ (-hat(omega) @ (J @ omega) + N + R_HAT @ (A.T @ lam))
    v_dot = (G + H + lam) / M
    return np.concatenate([B @ omega, omega_dot, v, v_dot, d_dot])


def solo(y0, method, rtol, atol, t_end, n_samples):
    from scipy.integrate import solve_ivp

    sol = solve_ivp(baseline_rhs, (0.0, t_end), y0, method=method, rtol=rtol, atol=atol,
                    t_eval=np.linspace(0.0, t_end, n_samples))
    return sol.y[:, -1], sol.nfev


# -- helpers ----------------------------------------------------------------------------------


def spec_mapping(n: int, method: str) -> dict:
    return {
        "name": "throughput",
        "base": str(CASE3),
        "random": {"n": n, "seed": 0,
                   "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 2}}}},
    }


def overrides(method: str) -> list[str]:
    return ["simulation.rtol=1e-6", "simulation.atol=1e-8", f"simulation.method={method}"]


def final_states(index_csv: Path) -> np.ndarray:
    """Final (Theta, Omega, X, V, D) of every run, from the index (run order)."""
    import pandas as pd

    df = pd.read_csv(index_csv)
    cols = [f"final_{b}_{a}" for b in ("theta", "omega", "position", "velocity", "controller_state") for a in "xyz"]
    return df[cols].to_numpy(float)


def mib(n_bytes) -> str:
    return "n/a" if not n_bytes else f"{n_bytes / 2**20:.0f} MiB"


def parse_setting(text: str) -> tuple[str, str]:
    """``"STORE:LAYOUT"`` -> (store, layout), e.g. ``"summary:chunk"``."""
    store, _, layout = text.partition(":")
    if store not in ("summary", "full") or layout not in ("run", "chunk"):
        raise argparse.ArgumentTypeError(f"{text!r}: expected STORE:LAYOUT, STORE summary|full, LAYOUT run|chunk")
    return store, layout


def run_cli_sweep(spec_path: Path, out: Path, args, store: str, layout: str) -> float:
    cmd = [str(RBSTAB), "sweep", str(spec_path), "-o", str(out), "-j", str(args.jobs), "--store", store,
           "--layout", layout, "--no-progress", *sum((["--set", o] for o in overrides(args.method)), [])]
    if args.chunk_size:
        cmd += ["--chunk-size", str(args.chunk_size)]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=args.env)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"rbstab sweep failed ({proc.returncode}):\n{proc.stderr}")
    return wall


def run_library_sweep(n: int, out: Path, args, store: str, layout: str, executor) -> float:
    """(b) through the library call behind ``rbstab sweep`` in this process, on ``executor``
    (started and used before: a session's second sweep): plan the N runs (``expand``),
    then ``run_sweep``; wall seconds."""
    from rbstab.sweep import expand, run_sweep, spec_from_mapping

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec = spec_from_mapping(spec_mapping(n, args.method), overrides=overrides(args.method))
        runs = expand(spec)
    run_sweep(spec, out, runs=runs, executor=executor, store=store, layout=layout, chunk_size=args.chunk_size,
              progress=False, command_line="benchmark")
    return time.perf_counter() - start


def run_child(n: int, out: Path, args, store: str, layout: str) -> dict:
    """The sweep in a fresh, instrumented process: what ``rbstab sweep`` does, with timings."""
    cmd = [sys.executable, __file__, "--child", str(n), "--child-out", str(out), "--jobs", str(args.jobs),
           "--setting", f"{store}:{layout}", "--method", args.method, "--t0", repr(time.time())]
    if args.chunk_size:
        cmd += ["--chunk-size", str(args.chunk_size)]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=args.env)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"instrumented sweep failed:\n{proc.stderr}")
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    info["wall"] = wall
    return info


def child(args) -> None:
    """Entry of the instrumented sweep process (``--child N``)."""
    started = time.time()
    from rbstab.sweep.executors import LocalExecutor

    executor = LocalExecutor(args.jobs)
    executor.start()  # as the CLI does: the workers start while the rest is imported and the runs validated
    from rbstab.sweep import expand, run_sweep, spec_from_mapping

    imported = time.time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec = spec_from_mapping(spec_mapping(args.child, args.method), overrides=overrides(args.method))
        runs = expand(spec)
    planned = time.time()
    with executor:
        outcome = run_sweep(spec, args.child_out, runs=runs, executor=executor, store=args.store,
                            layout=args.layout, chunk_size=args.chunk_size, progress=False, command_line="benchmark")
    done = time.time()
    print(json.dumps({
        "startup": started - args.t0, "imports": imported - started, "planning": planned - imported,
        "run_sweep": done - planned, "timing": outcome.timing, "n_chunks": outcome.n_chunks,
        "engine": outcome.engine, "executor": outcome.executor, "counts": outcome.counts,
        "parent_peak_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "worker_peak_rss": outcome.worker_peak_rss,
        "disk": sum(p.stat().st_size for p in (Path(args.child_out) / "throughput" / "runs").glob("*.h5")),
    }))


def rhs_share(n_runs: int, method: str) -> float:
    """Share of the batch integration spent in the right-hand side, for one chunk of
    ``n_runs`` Case 3 runs, measured in this process (the right-hand side the sweep uses:
    :func:`rbstab.traced.traced_rhs` of the variant)."""
    from rbstab.batch import integrate_batch
    from rbstab.config import load_config
    from rbstab.traced import traced_rhs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        variant = load_config(CASE3).make_variant()
    fun = traced_rhs(variant) or variant.rhs
    rng = np.random.default_rng(1)
    y0 = np.zeros((n_runs, variant.layout.size))
    y0[:, 3:6] = rng.normal([16, 32, -16], 2, (n_runs, 3))
    spent = [0.0]

    class Timed:
        layout, name = variant.layout, variant.name

        @staticmethod
        def rhs(t, y):
            t0 = time.perf_counter()
            out = fun(t, y)
            spent[0] += time.perf_counter() - t0
            return out

    start = time.perf_counter()
    integrate_batch(Timed, y0, 2.0, 2001, method=method, rtol=1e-6, atol=1e-8)
    return spent[0] / (time.perf_counter() - start)


def bytecode_env(cache: str) -> dict:
    """The environment of the timed subprocesses: Python's bytecode cache in ``cache``
    (``PYTHONPYCACHEPREFIX``), written as Python normally does even where
    ``PYTHONDONTWRITEBYTECODE`` is set (as in some CI images, where an editable install's
    modules would otherwise be compiled again by every process)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = cache
    return env


def single_run(env=None) -> float:
    out = Path(tempfile.mkdtemp(prefix="rbstab-single-"))
    try:
        start = time.perf_counter()
        proc = subprocess.run([str(RBSTAB), "run", str(CASE3), "-o", str(out)], capture_output=True, text=True,
                              env=env, cwd=ROOT)
        wall = time.perf_counter() - start
        if proc.returncode != 0 or not (out / "case3_embedded.h5").is_file():
            sys.exit(f"rbstab run failed:\n{proc.stderr}")
        return wall
    finally:
        shutil.rmtree(out, ignore_errors=True)


# -- main -------------------------------------------------------------------------------------


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000, help="runs (default 1000)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes of the sweep (default 2)")
    p.add_argument("--setting", nargs="+", type=parse_setting, metavar="STORE:LAYOUT",
                   default=[("summary", "chunk"), ("full", "chunk"), ("summary", "run")],
                   help="sweep --store and --layout pairs to time (default: summary:chunk full:chunk "
                   "summary:run); the first is also the memory sweep's")
    p.add_argument("--method", default="DOP853", choices=["DOP853", "RK45"])
    p.add_argument("--chunk-size", type=int, default=None, help="sweep --chunk-size (default: the sweep's)")
    p.add_argument("--baseline-n", type=int, default=None, help="baseline runs timed (default: all N)")
    p.add_argument("--rounds", type=int, default=3, help="slices of (a) interleaved with timings of (b) (default 3)")
    p.add_argument("--ref-n", type=int, default=100, help="runs compared with the tight reference (default 100)")
    p.add_argument("--memory-n", type=int, default=10000, help="runs of the memory sweep (0: skip)")
    p.add_argument("--skip-single", action="store_true", help="skip the single-run and cold-start timings")
    p.add_argument("--keep", default=None, help="write the sweeps under DIR and keep them")
    p.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    p.add_argument("--t0", type=float, default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child is not None:
        args.store, args.layout = args.setting[0]
        return child(args)

    import yaml

    from rbstab.config import load_config
    from rbstab.sweep import expand, spec_from_mapping
    from rbstab.sweep.executors import LocalExecutor

    n = args.n
    parent = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="rbstab-throughput-"))
    parent.mkdir(parents=True, exist_ok=True)
    args.env = bytecode_env(str(parent / "pycache"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            spec = spec_from_mapping(spec_mapping(n, args.method), overrides=overrides(args.method))
            runs = expand(spec)
            variant = load_config(CASE3).make_variant()
        spec_path = parent / "throughput.yaml"
        spec_path.write_text(yaml.safe_dump(spec_mapping(n, args.method), sort_keys=False))
        y0 = np.stack([variant.initial_state(r.config.initial_state) for r in runs])
        rng = np.random.default_rng(2)
        probe = rng.normal(0, 0.3, (20, 15))
        rhs_check = max(np.abs(baseline_rhs(0, y) - variant.rhs(0, y)).max() for y in probe)
        print(f"Case 3 (embedded), {args.method}, t_end 2 s, 2001 samples, rtol 1e-6, atol 1e-8, N = {n}; "
              f"{os.cpu_count()} CPUs, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        print(f"baseline right-hand side vs the project's model at 20 random states: max |difference| "
              f"{rhs_check:.1e}")

        # (a) and (b), interleaved: the machine's speed drifts over minutes (shared host),
        # so (a)'s runs are timed in --rounds slices with one timing of each (b) setting
        # after every slice; (a)'s rate is over all its runs, (b)'s the median of its rounds
        n_base = min(args.baseline_n or n, n)
        rounds = max(1, min(args.rounds, n_base))
        t_rhs = time.perf_counter()
        for _ in range(2000):
            baseline_rhs(0.0, y0[0])
        us_rhs = (time.perf_counter() - t_rhs) / 2000 * 1e6
        warm_spec = parent / "warm-up.yaml"  # an untimed sweep of a few runs fills the bytecode
        warm_spec.write_text(yaml.safe_dump(spec_mapping(2 * args.jobs, args.method), sort_keys=False))
        run_cli_sweep(warm_spec, parent / "warm-up", args, *args.setting[0])  # cache, as any earlier use
        shutil.rmtree(parent / "warm-up", ignore_errors=True)
        lib_store, lib_layout = args.setting[0]
        lib_key = f"library {lib_store}:{lib_layout}"
        library = LocalExecutor(args.jobs)
        library.start()
        run_library_sweep(2 * args.jobs, parent / "warm-up", args, lib_store, lib_layout, library)
        shutil.rmtree(parent / "warm-up", ignore_errors=True)
        finals_a = np.empty((n_base, 15))
        nfev = 0
        wall_a = 0.0
        walls_b: dict[str, list[float]] = {f"{s}:{l}": [] for s, l in args.setting}
        finals_b: dict[str, np.ndarray] = {}
        for r, part in enumerate(np.array_split(np.arange(n_base), rounds)):
            start = time.perf_counter()
            for i in part:
                finals_a[i], k = solo(y0[i], args.method, 1e-6, 1e-8, 2.0, 2001)
                nfev += k
            slice_a = time.perf_counter() - start
            wall_a += slice_a
            line = [f"round {r + 1}/{rounds}: (a) {len(part) / slice_a:.2f} runs/s"]
            for store, layout in args.setting:
                key = f"{store}:{layout}"
                out = parent / f"cli-{store}-{layout}"
                shutil.rmtree(out, ignore_errors=True)
                walls_b[key].append(run_cli_sweep(spec_path, out, args, store, layout))
                finals_b[key] = final_states(out / "throughput" / "index.csv")
                line.append(f"(b, {key}) {n / walls_b[key][-1]:.1f} runs/s")
            out = parent / "library"
            shutil.rmtree(out, ignore_errors=True)
            walls_b.setdefault(lib_key, []).append(run_library_sweep(n, out, args, lib_store, lib_layout, library))
            finals_b[lib_key] = final_states(out / "throughput" / "index.csv")
            line.append(f"(b, {lib_key}) {n / walls_b[lib_key][-1]:.1f} runs/s")
            print("  " + ", ".join(line))
        library.close()
        rate_a = n_base / wall_a
        print(f"(a) solve_ivp one by one: {n_base} runs in {wall_a:.1f} s = {rate_a:.2f} runs/s "
              f"({1e3 / rate_a:.0f} ms per run, {nfev / n_base:.0f} RHS evaluations per run, "
              f"{us_rhs:.0f} us per RHS evaluation, 1 core)")

        # reference
        n_ref = min(args.ref_n, n_base)
        ref = np.stack([solo(y0[i], "DOP853", 1e-10, 1e-12, 2.0, 2001)[0] for i in range(n_ref)])
        err_a = np.abs(finals_a[:n_ref] - ref).max()
        subset = "" if n_ref == n else f" (first {n_ref} of {n} runs)"

        results = {}
        for key, walls in walls_b.items():
            wall_b = float(np.median(walls))
            err_b = np.abs(finals_b[key][:n_ref] - ref).max()
            rate_b = n / wall_b
            results[key] = (rate_b, err_b)
            if key == lib_key:
                what = (f"run_sweep(executor=LocalExecutor({args.jobs}), store={lib_store!r}, layout={lib_layout!r}) "
                        f"after an earlier sweep on the same executor (workers started; planning included)")
            else:
                store, layout = key.split(":")
                what = (f"rbstab sweep -j {args.jobs} --store {store} --layout {layout} "
                        f"(process start to exit)")
            print(f"(b) {what}: {n} runs in {wall_b:.2f} s (median of {len(walls)}: "
                  f"{', '.join(f'{w:.2f}' for w in walls)} s) = {rate_b:.1f} runs/s; "
                  f"ratio (b)/(a) = {rate_b / rate_a:.1f}")
        print(f"max |final state - reference (rtol 1e-10)|{subset}: (a) {err_a:.2e}, "
              + ", ".join(f"(b, {s}) {e:.2e}" for s, (_, e) in results.items())
              + f"; max |final state| {np.abs(ref).max():.3g}")

        # where (b)'s time goes
        chunk = share = None
        for store, layout in args.setting:
            out = parent / f"child-{store}-{layout}"
            shutil.rmtree(out, ignore_errors=True)
            info = run_child(n, out, args, store, layout)
            t = info["timing"]
            chunk = chunk or max(1, -(-n // max(info["n_chunks"], 1)))
            if share is None:  # the right-hand side's share does not depend on the store
                share = rhs_share(chunk, args.method)
            busy = sum(t.values())
            other = info["run_sweep"] - busy / args.jobs
            print(f"time split of (b) --store {store} --layout {layout} (instrumented run: {info['wall']:.2f} s wall, "
                  f"{n / info['wall']:.1f} runs/s; {info['n_chunks']} chunks on {info['executor']}):")
            print(f"  process start-up + interpreter  {info['startup']:6.2f} s wall")
            print(f"  imports                         {info['imports']:6.2f} s wall")
            print(f"  planning (validate {n} configs) {info['planning']:6.2f} s wall (parent, serial)")
            per = 1e3 / n
            print(f"  workers, summed over {args.jobs} processes ({busy:.2f} CPU s = {busy / args.jobs:.2f} s wall):")
            print(f"    configs                       {t.get('config', 0):6.2f} s  ({per * t.get('config', 0):.2f} ms/run)")
            integ = t.get("integration", 0.0)
            print(f"    integration                   {integ:6.2f} s  ({per * integ:.2f} ms/run): right-hand side "
                  f"~{100 * share:.0f} %, solver bookkeeping and dense output ~{100 - 100 * share:.0f} % "
                  f"(from an instrumented chunk of {chunk})")
            print(f"    post-processing               {t.get('postprocess', 0):6.2f} s  ({per * t.get('postprocess', 0):.2f} "
                  f"ms/run: outputs, numerical dv/dt, summary)")
            print(f"    config YAML (config attribute) {t.get('config_yaml', 0):5.2f} s  ({per * t.get('config_yaml', 0):.2f} "
                  f"ms/run: RunConfig.to_yaml)")
            print(f"    HDF5 writing                  {t.get('write', 0):6.2f} s  ({per * t.get('write', 0):.2f} ms/run; "
                  f"result files {info['disk'] / 2**20:.0f} MiB)")
            print(f"  parent: waiting for the workers to start, dispatch, index ({other:5.2f} s wall beyond the "
                  f"workers' share)")
            print(f"  peak RSS: sweep parent {mib(info['parent_peak_rss'])}, largest worker "
                  f"{mib(info['worker_peak_rss'])}")

        # single runs
        if not args.skip_single:
            # cold: a second, empty bytecode cache, so every module (numpy, scipy, h5py,
            # rbstab) is compiled first; warm: the benchmark's cache, filled
            with tempfile.TemporaryDirectory(prefix="rbstab-pycache-") as cache:
                cold = single_run(bytecode_env(cache))
            warm = min(single_run(args.env) for _ in range(3))
            print(f"rbstab run configs/paper/case3_embedded.yaml (rtol 1e-8, scipy engine), process start to "
                  f"file written: {warm:.2f} s (best of 3, bytecode cached); cold start (empty bytecode cache: "
                  f"every module of numpy, scipy, h5py and rbstab compiled first): {cold:.2f} s. "
                  f"No compilation cache exists: the engine is numpy.")

        # memory of a large sweep
        if args.memory_n:
            store, layout = args.setting[0]
            out = parent / "memory"
            shutil.rmtree(out, ignore_errors=True)
            info = run_child(args.memory_n, out, args, store, layout)
            print(f"{args.memory_n}-run sweep (--store {store} --layout {layout}, 2001 samples per run): {info['wall']:.1f} s wall, "
                  f"{args.memory_n / info['wall']:.1f} runs/s, {info['n_chunks']} chunks; peak RSS: sweep parent "
                  f"{mib(info['parent_peak_rss'])}, largest worker {mib(info['worker_peak_rss'])}; result files "
                  f"{info['disk'] / 2**30:.2f} GiB")
            shutil.rmtree(out, ignore_errors=True)
    finally:
        if not args.keep:
            shutil.rmtree(parent, ignore_errors=True)


if __name__ == "__main__":
    main()
