"""Benchmark: batched Runge-Kutta sweep (rbstab.batch) against one solve_ivp call per run.

Case 3 of the paper (embedded, eq 22; m = 41 kg, J = diag(10, 8, 0.4) kg m^2,
R = (0.15, 0.10, -0.42) m), t_end = 2 s, rtol = 1e-6, atol = 1e-8, initial Omega =
(16, 32, -16) rad/s scaled per run by 1 + 0.1 N(0, 1) per component.

Prints the solo ``solve_ivp`` time per run (``--n-solo`` runs, plain numpy RHS on one
state, ``t_eval`` at the samples), the batch time per run (``--n-batch`` runs through
``integrate_many`` in chunks of ``--chunk``), their ratio, and the largest absolute
difference of the final states of the runs integrated both ways (next to how much a solo
solve itself moves when y0 moves by one ulp: DOP853's error estimate cancels strongly, so
at loose tolerances round-off can change its step sequence). ``--profile`` adds a
breakdown of the batch time (RHS vs. integrator bookkeeping vs. dense output).

Usage::

    python benchmarks/batch_engine.py [--method DOP853] [--n-solo 20] [--n-batch 1000]
                                      [--chunk 1024] [--n-samples 201] [--repeat 1]
                                      [--blas-threads N] [--profile]

BLAS threading matters: the batch's matrix products (and the variants' ``K @ X`` gain products) are
too small to gain from threads, and on a busy machine OpenBLAS threads waiting for a
core can make the batch several times slower; compare ``--blas-threads 1``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path


def _early_blas_threads() -> None:
    """``--blas-threads N`` must act before numpy loads OpenBLAS."""
    if "--blas-threads" in sys.argv:
        n = sys.argv[sys.argv.index("--blas-threads") + 1]
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = n


_early_blas_threads()

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from rbstab import batch  # noqa: E402
from rbstab.batch import integrate_many  # noqa: E402
from rbstab.config import PhysicalPlausibilityWarning, load_config  # noqa: E402

CASE3 = Path(__file__).resolve().parents[1] / "configs" / "paper" / "case3_embedded.yaml"


def case3():
    """The embedded variant of the shipped ``configs/paper/case3_embedded.yaml``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        return load_config(CASE3).make_variant()


def initial_states(variant, n, seed=0):
    rng = np.random.default_rng(seed)
    y0 = np.zeros((n, variant.layout.size))
    y0[:, variant.layout.slice("omega")] = np.array([16.0, 32.0, -16.0]) * (
        1 + 0.1 * rng.standard_normal((n, 3))
    )
    return y0


class _CountingRhs:
    """Wraps variant.rhs and accumulates its time and rows (for the profile)."""

    def __init__(self, variant):
        self.variant = variant
        self.layout = variant.layout
        self.name = variant.name
        self.time = 0.0
        self.calls = 0
        self.rows = 0

    def rhs(self, t, y):
        t0 = time.perf_counter()
        out = self.variant.rhs(t, y)
        self.time += time.perf_counter() - t0
        self.calls += 1
        self.rows += y.shape[0]
        return out


def run_batch(variant, y0, args):
    finals = np.empty_like(y0)
    status = np.empty(len(y0), dtype=int)
    for indices, sol in integrate_many(
        variant, y0, args.t_end, args.n_samples, chunk_size=args.chunk,
        method=args.method, rtol=args.rtol, atol=args.atol,
    ):
        finals[indices] = sol.y[:, -1]
        status[indices] = sol.status
    return finals, status


def profile(variant, y0, args):
    """Split the batch time into RHS, dense output and the integrator's own bookkeeping."""
    counting = _CountingRhs(variant)
    acc = {"dense": 0.0, "dense_rhs": 0.0, "extra_rows": 0}
    patched = {
        "_Dense.__init__": (batch._Dense, "__init__"),
        "_Dense.__call__": (batch._Dense, "__call__"),
        "_DenseStep.extra_input": (batch._DenseStep, "extra_input"),
        "_DenseStep.write_samples": (batch._DenseStep, "write_samples"),
    }
    originals = {k: getattr(cls, name) for k, (cls, name) in patched.items()}

    def timed(key):
        orig = originals[key]

        def wrapper(self, *a, **k):
            t0, r0 = time.perf_counter(), counting.time
            out = orig(self, *a, **k)
            # time inside dense-output code, minus RHS calls made from inside it
            acc["dense"] += time.perf_counter() - t0 - (counting.time - r0)
            acc["dense_rhs"] += counting.time - r0
            if key == "_DenseStep.extra_input":
                acc["extra_rows"] += len(out[1])
            return out

        return wrapper

    for key, (cls, name) in patched.items():
        setattr(cls, name, timed(key))
    try:
        t0 = time.perf_counter()
        run_batch(counting, y0, args)
        total = time.perf_counter() - t0
    finally:
        for key, (cls, name) in patched.items():
            setattr(cls, name, originals[key])
    rhs = counting.time
    rest = total - rhs - acc["dense"]
    share = acc["extra_rows"] / counting.rows
    print(f"profile of the batch path ({len(y0)} runs, chunk {args.chunk}, total {total:.2f} s):")
    print(f"  variant RHS (all calls):         {rhs:6.2f} s ({100 * rhs / total:4.1f} %); "
          f"{100 * share:.0f} % of the rows evaluated are DOP853 dense-output stages")
    print(f"  dense output (coefficients, sample evaluation, gathers): {acc['dense']:6.3f} s "
          f"({100 * acc['dense'] / total:4.1f} %)")
    print(f"  integrator bookkeeping (stage sums, error norm, step control, compaction): "
          f"{rest:6.3f} s ({100 * rest / total:4.1f} %)")
    print(f"  RHS calls {counting.calls}, mean rows per call {counting.rows / counting.calls:.0f}, "
          f"{1e6 * rhs / counting.calls:.0f} us per call, {1e6 * rhs / counting.rows:.2f} us per row")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--method", default="DOP853", choices=batch.SUPPORTED_METHODS)
    p.add_argument("--n-solo", type=int, default=20)
    p.add_argument("--n-batch", type=int, default=1000)
    p.add_argument("--chunk", type=int, default=1024)
    p.add_argument("--n-samples", type=int, default=201)
    p.add_argument("--t-end", type=float, default=2.0)
    p.add_argument("--rtol", type=float, default=1e-6)
    p.add_argument("--atol", type=float, default=1e-8)
    p.add_argument("--repeat", type=int, default=1, help="interleaved timing rounds (best is kept)")
    p.add_argument("--blas-threads", type=int, default=None,
                   help="set OPENBLAS/OMP/MKL_NUM_THREADS before numpy is imported "
                        "(default: leave the environment alone)")
    p.add_argument("--n-sensitivity", type=int, default=5,
                   help="solo runs re-solved from y0 + 1 ulp, to show scipy's own round-off sensitivity")
    p.add_argument("--profile", action="store_true")
    args = p.parse_args()

    variant = case3()
    y0 = initial_states(variant, max(args.n_batch, args.n_solo))
    ts = np.linspace(0.0, args.t_end, args.n_samples)
    print(f"case 3 (embedded), {args.method}, t_end {args.t_end} s, rtol {args.rtol:g}, "
          f"atol {args.atol:g}, {args.n_samples} samples, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")

    variant.rhs(0.0, y0[0])  # warm-up

    def solo_round():
        finals, nfev = [], 0
        t0 = time.perf_counter()
        for i in range(args.n_solo):
            r = solve_ivp(variant.rhs, (0.0, args.t_end), y0[i], method=args.method,
                          rtol=args.rtol, atol=args.atol, t_eval=ts)
            finals.append(r.y[:, -1])
            nfev += r.nfev
        return (time.perf_counter() - t0) / args.n_solo, np.array(finals), nfev / args.n_solo

    def batch_round():
        t0 = time.perf_counter()
        finals, status = run_batch(variant, y0[: args.n_batch], args)
        return (time.perf_counter() - t0) / args.n_batch, finals, status

    # interleaved rounds, best of each: robust against other load on the machine
    solo_times, batch_times = [], []
    for _ in range(args.repeat):
        solo, solo_final, solo_nfev = solo_round()
        per_run, finals, status = batch_round()
        solo_times.append(solo)
        batch_times.append(per_run)
    solo, per_run = min(solo_times), min(batch_times)
    print(f"solo solve_ivp:  {1e3 * solo:8.2f} ms per run  (N = {args.n_solo}, "
          f"{solo_nfev:.0f} RHS evaluations per run, {1e6 * solo / solo_nfev:.0f} us per evaluation)")
    print(f"batch:           {1e3 * per_run:8.3f} ms per run  (N = {args.n_batch}, chunk {args.chunk}, "
          f"{np.count_nonzero(status == 0)} succeeded)")
    print(f"speed-up:        {solo / per_run:8.1f} x   (best of {args.repeat} interleaved rounds; "
          f"per round: {', '.join(f'{s / b:.0f}' for s, b in zip(solo_times, batch_times))})")
    n_cmp = min(args.n_solo, args.n_batch)
    diff = np.abs(solo_final[:n_cmp] - finals[:n_cmp]).max()
    print(f"max |final state difference| over {n_cmp} runs: {diff:.3e} "
          f"(max |final state| {np.abs(solo_final).max():.3e})")
    if args.n_sensitivity:
        # scipy's own round-off sensitivity: the same solo solves from y0 moved by one ulp
        k = min(args.n_sensitivity, n_cmp)
        sens = 0.0
        for i in range(k):
            y1 = y0[i].copy()
            y1[variant.layout.slice("omega")] = np.nextafter(y1[variant.layout.slice("omega")], np.inf)
            r = solve_ivp(variant.rhs, (0.0, args.t_end), y1, method=args.method,
                          rtol=args.rtol, atol=args.atol, t_eval=ts)
            sens = max(sens, np.abs(r.y[:, -1] - solo_final[i]).max())
        print(f"for scale: solo solve_ivp from y0 moved by 1 ulp changes the final state by up to "
              f"{sens:.3e} ({k} runs)")

    if args.profile:
        profile(variant, y0[: args.n_batch], args)


if __name__ == "__main__":
    main()
