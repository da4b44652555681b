"""Benchmark: sweep throughput (runs per second) with -j 1 and -j 2, and parallel efficiency.

(``benchmarks/throughput.py`` is the issue-5 benchmark against one-by-one solve_ivp; this
one compares process counts, engines and storage modes of ``rbstab sweep``.)

A sweep of ``--runs`` runs (default 200) of Case 3 of the paper (embedded, eq 22; the
settings of ``configs/paper/case3_embedded.yaml``: t_end = 2 s, 2001 samples, DOP853,
rtol = 1e-8, atol = 1e-10), the initial Omega drawn per run from N((16, 32, -16), 2^2)
rad/s, goes through :func:`rbstab.sweep.run_sweep` on the local executor, once per ``-j``
value, each time into a fresh folder (nothing is skipped). A run is the whole unit of
work: integration (``--engine``: the sweep's default, batch, or scipy), output evaluation
and the store files (``--store full|thinned|summary``).

Prints per ``-j``: the wall time of the sweep (pool start-up and index included), runs
per second, the mean wall time of one run inside its worker (integration and outputs; the
file write comes on top), and the parallel efficiency ``(rate_j / rate_1) / j``. Other
processes competing for the CPUs show up as a longer mean run time at ``-j 2`` than at
``-j 1``; the load average is printed so that such figures can be discounted.

Usage::

    python benchmarks/sweep_throughput.py [--runs 200] [--jobs 1 2] [--t-end 2.0]
                                          [--engine NAME] [--store full|thinned|summary]
                                          [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=200, help="runs in the sweep (default 200)")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2], help="process counts (default 1 2)")
    parser.add_argument("--t-end", type=float, default=None, help="override simulation.t_end [s]")
    parser.add_argument("--engine", default=None, choices=["batch", "scipy"], help="default: the sweep's (batch)")
    parser.add_argument("--store", default="thinned", choices=["full", "thinned", "summary"])
    parser.add_argument("--keep", default=None, help="write the sweeps under DIR and keep them")
    args = parser.parse_args()

    import pandas as pd

    from rbstab.sweep import expand, run_sweep, spec_from_mapping

    overrides = [] if args.t_end is None else [f"simulation.t_end={args.t_end}"]
    spec = spec_from_mapping(
        {
            "name": "throughput",
            "base": str(CASE3),
            "random": {
                "n": args.runs,
                "seed": 0,
                "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 2}}},
            },
        },
        overrides=overrides,
    )
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs = expand(spec)
    print(f"Case 3, {len(runs)} runs, t_end {runs[0].config.simulation.t_end:g} s, "
          f"{runs[0].config.simulation.n_samples} samples; planning (validation, ids) "
          f"{time.perf_counter() - t0:.2f} s; {os.cpu_count()} CPUs, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")

    parent = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="rbstab-bench-"))
    rates = {}
    try:
        for jobs in args.jobs:
            out = parent / f"j{jobs}"
            shutil.rmtree(out, ignore_errors=True)
            start = time.perf_counter()
            outcome = run_sweep(spec, out, runs=runs, jobs=jobs, engine=args.engine, store=args.store, progress=False)
            wall = time.perf_counter() - start
            index = pd.read_csv(outcome.index_path)
            rates[jobs] = len(runs) / wall
            efficiency = (rates[jobs] / rates[args.jobs[0]]) * args.jobs[0] / jobs
            print(
                f"-j {jobs} ({outcome.engine}): {wall:7.2f} s, {rates[jobs]:6.3f} runs/s, mean run "
                f"{index['wall_time'].mean():.3f} s in its worker, {outcome.counts.get('success', 0)} success / {outcome.n_failed} failed, "
                f"parallel efficiency {efficiency:.2f} (load average now "
                f"{os.getloadavg()[0]:.2f})"
            )
    finally:
        if not args.keep:
            shutil.rmtree(parent, ignore_errors=True)


if __name__ == "__main__":
    main()
