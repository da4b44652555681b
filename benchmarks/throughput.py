"""Benchmark: the default ``rbstab sweep`` against a plain solve_ivp loop, and start-up.

Case 3 of the paper (embedded, eq 22; ``configs/paper/case3_embedded.yaml``: DOP853, t_end
2 s, 2001 samples) at rtol 1e-6, atol 1e-8. Prints one table:

- **baseline**: one ``scipy.integrate.solve_ivp`` per run with the plain numpy right-hand
  side below (:func:`baseline_rhs`, what a researcher writes by hand), one core;
  ``--baseline-n`` runs, per-run time. Also timed: the same with its cross products written
  with ``np.cross`` (:func:`baseline_rhs_cross`, ~2x slower on numpy 2.x); the
  ``np.cross`` column is the ratio to that one (docs/performance.md).
- **sweeps**, each the default command ``rbstab sweep SPEC -j JOBS --no-progress`` timed from
  process start to exit (default store, warm compile cache), for N in ``--n``:
  ``initial-state`` (Omega ~ N((16, 32, -16), 4^2)), ``parameter`` (mass and inertia x
  U(0.5, 1.5), K_c and L_c x U(0.5, 2), K_t x U(0.7, 1.4), random Omega: every run a
  different config) and ``variants`` (the five variants x random Omega); ratio = N x
  baseline per-run time / sweep wall time. The machine (a shared VM) changes speed by up
  to 1.6x within minutes: each sweep is also compared with the baseline of its moment,
  ``--local-n`` baseline runs just before and just after it (``local`` column).
- **accuracy**: the largest difference of the final states of 50 runs, the compiled engine's
  and the baseline's, from an rtol 1e-10 reference.
- **run**: ``rbstab run configs/paper/case3_embedded.yaml`` warm (best of 3) and cold (an empty
  compile cache: the one-time compilation).
- **memory**: peak resident set size of the parent and the largest worker of a
  ``--memory-n`` (100,000) run summary sweep.

Usage::

    python benchmarks/throughput.py [--n 1000 10000] [--jobs 2] [--baseline-n 30] [--local-n 5]
                                    [--memory-n 100000]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
TOLERANCES = ["simulation.rtol=1e-6", "simulation.atol=1e-8"]
OMEGA = {"normal": {"mean": [16, 32, -16], "std": 4}}

# -- the baseline: Case 3 the straightforward way ------------------------------------------
M, J = 41.0, np.diag([10.0, 8.0, 0.4])
J_INV = np.linalg.inv(J)
R = np.array([0.15, 0.10, -0.42])
G = np.zeros(3)
K_T, L_T = np.diag([4100.0, 4100, 3280]), np.diag([200.0, 200, 140])
K_R, L_R = np.diag([400.0, 400, 320]), np.diag([60.0, 60, 42])
K_C, L_C = np.diag([12300.0, 12300, 9840]), np.diag([600.0, 600, 420])
K_D, L_D_INV = K_C, np.linalg.inv(2 * L_C)


def hat(r):
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


R_HAT = hat(R)


def baseline_rhs(t, y, cross=lambda a, b: hat(a) @ b, r_cross=lambda b: R_HAT @ b):
    """d/dt (Theta, Omega, X, V, D) for one state (eqs 1, 4, 22-24); ``cross(a, b)`` is a x b,
    ``r_cross(b)`` is R x b (by default matrix products, with R's matrix computed once)."""
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
    F = v - A @ r_cross(omega)
    spring = K_C @ (E - d)
    d_dot = L_D_INV @ (spring - K_D @ d)
    lam = -spring - L_C @ F
    N = -B.T @ (K_R @ theta) - L_R @ omega
    H = -K_T @ x - L_T @ v
    omega_dot = J_INV @ (-cross(omega, J @ omega) + N + r_cross(A.T @ lam))
    v_dot = (G + H + lam) / M
    return np.concatenate([B @ omega, omega_dot, v, v_dot, d_dot])


def baseline_rhs_cross(t, y):
    """:func:`baseline_rhs` with its cross products written with ``np.cross``.

    The same values (the same steps); on numpy 2.x ``np.cross`` of two 3-vectors costs ~20 us,
    so a run takes ~2x as long as with the matrix products of :func:`baseline_rhs`.
    """
    return baseline_rhs(t, y, cross=np.cross, r_cross=lambda b: np.cross(R, b))


def baseline_run(omega, rtol=1e-6, atol=1e-8, rhs=baseline_rhs):
    from scipy.integrate import solve_ivp

    y0 = np.concatenate([np.zeros(3), omega, np.zeros(9)])
    sol = solve_ivp(rhs, (0.0, 2.0), y0, method="DOP853", rtol=rtol, atol=atol,
                    t_eval=np.linspace(0.0, 2.0, 2001))
    return sol.y[:, -1]


def omegas(n, seed=0):
    return np.random.default_rng(seed).normal([16, 32, -16], 4, size=(n, 3))


# -- sweeps through the CLI ------------------------------------------------------------------
def spec(kind: str, n: int) -> dict:
    if kind == "initial-state":
        return {"name": kind, "base": str(CASE3), "random": {"n": n, "seed": 0, "params": {"initial_state.omega": OMEGA}}}
    if kind == "parameter":
        params = {
            "body.mass": {"scale_uniform": [0.5, 1.5]},
            "body.inertia": {"scale_uniform": [0.5, 1.5]},
            "controller.k_c": {"scale_uniform": [0.5, 2.0]},
            "controller.l_c": {"scale_uniform": [0.5, 2.0]},
            "controller.k_t": {"scale_uniform": [0.7, 1.4]},
            "initial_state.omega": OMEGA,
        }
        return {"name": kind, "base": str(CASE3), "random": {"n": n, "seed": 0, "params": params}}
    variants = ["free", "permanent", "sliding", "visco_elastic", "embedded"]
    return {"name": kind, "base": str(CASE3), "grid": {"controller.variant": variants},
            "random": {"n": max(1, n // len(variants)), "seed": 0, "params": {"initial_state.omega": OMEGA}}}


def user_environment(env=None) -> dict:
    """The environment of a timed command: this one without ``PYTHONDONTWRITEBYTECODE``
    (where it is set, Python compiles every module of rbstab from source in each process,
    ~0.1-0.2 s, which a user's installation does not)."""
    return {k: v for k, v in (os.environ if env is None else env).items() if k != "PYTHONDONTWRITEBYTECODE"}


def timed(cmd, env=None) -> tuple[float, subprocess.CompletedProcess]:
    """Wall time from the command's start to its exit, as a shell sees it (in
    :func:`user_environment`).

    The output goes to files, not pipes: a pipe's reader would also wait for the sweep's
    fork server (it holds the parent's stdout) to finish its teardown after the command
    has exited.
    """
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.perf_counter()
        proc = subprocess.run(cmd, stdout=out, stderr=err, text=True, env=user_environment(env))
        wall = time.perf_counter() - start
        out.seek(0), err.seek(0)
        proc.stdout, proc.stderr = out.read(), err.read()
    return wall, proc


def sweep(kind: str, n: int, jobs: int, folder: Path, extra=()) -> tuple[float, int]:
    path = folder / f"{kind}-{n}.yaml"
    data = spec(kind, n)
    path.write_text(yaml.safe_dump(data))
    cmd = ["rbstab", "sweep", str(path), "-j", str(jobs), "--no-progress", "-o", str(folder / f"out-{kind}-{n}"),
           *[a for t in TOLERANCES for a in ("--set", t)], "--set", "controller.k_s=2000",
           "--set", "controller.boundary_layer=0.005", *extra]
    wall, proc = timed(cmd)
    if proc.returncode not in (0,) and "failed" not in proc.stdout:
        sys.exit(f"sweep failed: {' '.join(cmd)}\n{proc.stdout}\n{proc.stderr}")
    runs = n if kind != "variants" else 5 * max(1, n // 5)
    return wall, runs


def run_case3(env=None) -> float:
    with tempfile.TemporaryDirectory() as out:
        wall, proc = timed(["rbstab", "run", str(CASE3), "-o", out], env)
        if proc.returncode != 0:
            sys.exit(proc.stderr)
        return wall


def accuracy(n=50) -> tuple[float, float]:
    import warnings

    from rbstab.config import load_config
    from rbstab.simulator import simulate_many

    warnings.simplefilter("ignore")
    base = load_config(CASE3, TOLERANCES)
    configs = [base.with_initial_state({"omega": w.tolist()}, name=f"r{i}") for i, w in enumerate(omegas(n, 1))]
    compiled = {i: r for i, r in simulate_many(configs)}
    worst_c = worst_b = 0.0
    for i, w in enumerate(omegas(n, 1)):
        ref = baseline_run(w, rtol=1e-10, atol=1e-12)
        final = np.concatenate([compiled[i].outputs[b][-1] for b in ("theta", "omega", "position", "velocity",
                                                                     "controller_state")])
        worst_c = max(worst_c, np.abs(final - ref).max())
        worst_b = max(worst_b, np.abs(baseline_run(w) - ref).max())
    return worst_c, worst_b


def baseline_time(n: int, rhs=baseline_rhs) -> float:
    """Seconds a run of the baseline takes now: the mean of ``n`` runs."""
    start = time.perf_counter()
    for w in omegas(n):
        baseline_run(w, rhs=rhs)
    return (time.perf_counter() - start) / n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--baseline-n", type=int, default=30)
    parser.add_argument("--local-n", type=int, default=5)
    parser.add_argument("--memory-n", type=int, default=100_000)
    args = parser.parse_args()
    if args.baseline_n < 1 or args.local_n < 1:
        parser.error("--baseline-n and --local-n: at least 1 run each")

    rng = np.random.default_rng(1)
    for y in rng.normal(size=(20, 15)):  # the two baselines are one right-hand side
        a, b = baseline_rhs(0.0, y), baseline_rhs_cross(0.0, y)
        if not np.allclose(a, b, rtol=1e-12, atol=1e-9):
            raise SystemExit(f"baseline_rhs and baseline_rhs_cross differ at {y}: {a} != {b}")
    run_case3()  # warm the compile cache (compiles once if it is cold) and the bytecode caches
    per_run = baseline_time(args.baseline_n)
    per_run_cross = baseline_time(args.baseline_n, rhs=baseline_rhs_cross)
    print(f"baseline: solve_ivp + numpy rhs, {per_run * 1e3:.1f} ms per run ({args.baseline_n} runs, one core); "
          f"with np.cross, {per_run_cross * 1e3:.1f} ms per run")
    print(f"{'sweep':<15} {'N':>7} {'wall [s]':>9} {'runs/s':>8} {'ratio':>7} {'local baseline':>15} {'local':>6} "
          f"{'np.cross':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        before = baseline_time(args.local_n)
        for n in args.n:
            for kind in ("initial-state", "parameter", "variants"):
                wall, runs = sweep(kind, n, args.jobs, folder)
                after = baseline_time(args.local_n)
                local = (before + after) / 2
                print(f"{kind:<15} {runs:>7} {wall:>9.2f} {runs / wall:>8.0f} {runs * per_run / wall:>6.0f}x "
                      f"{local * 1e3:>12.1f} ms {runs * local / wall:>5.0f}x {runs * per_run_cross / wall:>8.0f}x",
                      flush=True)
                before = after
        warm = min(run_case3() for _ in range(3))
        with tempfile.TemporaryDirectory() as cache:
            cold = run_case3(dict(os.environ, NUMBA_CACHE_DIR=cache))
        print(f"rbstab run case3: warm {warm:.2f} s, cold (compiling once) {cold:.1f} s")
        worst_c, worst_b = accuracy()
        print(f"accuracy, max |final state - rtol 1e-10 reference| over 50 runs: compiled {worst_c:.2e}, "
              f"baseline {worst_b:.2e}")
        if args.memory_n:
            path = folder / "memory.yaml"
            path.write_text(yaml.safe_dump(spec("initial-state", args.memory_n)))
            out = folder / "out-memory"
            wall, proc = timed(["rbstab", "sweep", str(path), "-j", str(args.jobs), "--no-progress", "-o", str(out),
                                "--store", "summary", *[a for t in TOLERANCES for a in ("--set", t)]])
            parent = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
            print(f"{args.memory_n} runs, --store summary: {wall:.1f} s, peak RSS of the largest process "
                  f"{parent:.0f} MiB")


if __name__ == "__main__":
    main()
