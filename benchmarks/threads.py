"""Benchmark: the compiled engine's local parallel work in threads against worker processes.

The ``parameter`` sweep of benchmarks/throughput.py (Case 3 of the paper, every run a
different body and gains, random Omega) is planned as one table of N runs and integrated
in slices as the tuning generations do (:func:`rbstab.studies.batch.integrate_part`: the
compiled engine, the summary figures only), three ways:

- **one process**: every slice in this process (up to ``--serial-max`` runs);
- **threads**: :class:`rbstab.sweep.executors.ThreadExecutor` with ``--jobs`` threads (the
  kernels release the GIL);
- **processes**: :class:`rbstab.sweep.executors.LocalExecutor` with ``--jobs`` worker
  processes, their start included (a fresh executor per measurement, as a command makes);
- **warm processes**: one LocalExecutor kept for the whole benchmark (as a tuning study
  keeps its workers from one generation to the next): the slices' pickling only.

Each figure is the wall time of ``--repeat`` measurements, interleaved (threads, processes,
warm processes, threads, ...), after one warm-up of each at 200 runs; the machine is shared, so read
ranges. Both ways must give the same figures, bit for bit (checked).

Usage::

    python benchmarks/threads.py [--n 1000 10000 100000] [--jobs 2] [--repeat 2] [--serial-max 10000]
                                 [--slice ROWS]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from throughput import spec  # noqa: E402  (the same sweep specs)


def _table(n: int):
    from rbstab.sweep.spec import spec_from_mapping
    from rbstab.sweep.table import plan_table

    return plan_table(spec_from_mapping(spec("parameter", n)))


def integrate(table, executor, size: int | None) -> dict[str, np.ndarray]:
    """The figures of every run of ``table``, in slices of ``size`` rows (default: the rows
    split evenly over the executor's workers, as a tuning generation does)."""
    from rbstab.studies.batch import integrate_part

    m = table.n
    if executor is None:
        parts = [integrate_part(table.slice(np.arange(m)))]
        bounds = [(0, m)]
    else:
        step = size or max(1, math.ceil(m / (executor.parallelism() or 1)))
        bounds = [(lo, min(lo + step, m)) for lo in range(0, m, step)]
        executor.plan(len(bounds))
        done = {}
        for part, result, exc in executor.imap_unordered(integrate_part, (table.slice(np.arange(lo, hi))
                                                                           for lo, hi in bounds)):
            if exc is not None:
                raise exc
            done[int(part.index[0])] = result
        parts = [done[lo] for lo, _ in bounds]
    return {key: np.concatenate([p["figures"][key] for p in parts]) for key in parts[0]["figures"]}


def timed(way: str, table, jobs: int, size: int | None, warm=None) -> tuple[float, dict]:
    from rbstab.sweep.executors import LocalExecutor, ThreadExecutor

    t0 = time.perf_counter()
    if way == "one process":
        figures = integrate(table, None, size)
    elif way == "warm processes":
        figures = integrate(table, warm, size)
    else:
        executor = ThreadExecutor(jobs) if way == "threads" else LocalExecutor(jobs)
        with executor:
            figures = integrate(table, executor, size)
    return time.perf_counter() - t0, figures


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--serial-max", type=int, default=10000)
    parser.add_argument("--slice", type=int, default=None, help="rows a slice [default: N / jobs]")
    args = parser.parse_args(argv)

    from rbstab.engine import ensure_compiled

    ensure_compiled()
    from rbstab.sweep.executors import LocalExecutor

    pool = LocalExecutor(args.jobs)
    small = _table(200)
    for way in ("one process", "threads", "processes", "warm processes"):
        timed(way, small, args.jobs, args.slice, pool)

    print(f"| runs | one process | {args.jobs} threads | {args.jobs} processes (start included) | "
          f"{args.jobs} warm processes | threads / processes | threads / warm processes |")
    print("|---|---|---|---|---|---|---|")
    for n in args.n:
        table = _table(n)
        ways = ["threads", "processes", "warm processes"] + (["one process"] if n <= args.serial_max else [])
        times: dict[str, list[float]] = {w: [] for w in ways}
        reference = None
        for _ in range(args.repeat):
            for way in ways:
                seconds, figures = timed(way, table, args.jobs, args.slice, pool)
                times[way].append(seconds)
                if reference is None:
                    reference = figures
                else:
                    for key, values in reference.items():
                        if not np.array_equal(values, figures[key], equal_nan=True):
                            raise SystemExit(f"{way}: {key} differs from the first measurement")

        def cell(way):
            return ", ".join(f"{s:.2f} s" for s in times[way]) if way in times else "-"

        ratio = min(times["threads"]) / min(times["processes"])
        warm_ratio = min(times["threads"]) / min(times["warm processes"])
        print(f"| {n:,} | {cell('one process')} | {cell('threads')} | {cell('processes')} | "
              f"{cell('warm processes')} | {ratio:.2f} | {warm_ratio:.2f} |", flush=True)
    pool.close()


if __name__ == "__main__":
    main()
