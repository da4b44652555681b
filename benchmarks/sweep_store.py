"""Costs of a sweep outside the integration, and the parent's share of a real sweep.

    python benchmarks/sweep_store.py [N_SWEEP] [N_STORE] [N_PLAN]
        # defaults 100000, 1000000, 1000000

The sweep is the Case 3 parameter sweep of docs/sweeps.md (mass, K_c, L_c and K_t scaled,
a random Omega). Each phase runs in its own forked process and prints its figures with
the peak resident memory of that process:

1. ``rbstab sweep ... --dry-run`` of N_PLAN runs: planning and validating the run table
   (:func:`rbstab.sweep.plan_table`) and the dry run's listing;
2. the sweep of N_SWEEP runs, ``--store summary -j 2``, integrated for real: wall time,
   the parent's CPU per run, the workers' time per run (integration, post-processing,
   writing, as they report it), the wall time against N x (a worker's time a run) / 2, the
   peak memory of the parent and of a worker, and the store's bytes per run;
3. a summary store of N_STORE runs written through the sweep's own path (run table,
   workers' chunk function, store files, index) with the integration replaced by a block
   of 32 simulated Case 3 runs reused for every 32 rows, then ``rbstab.open_sweep`` of it
   (in a fresh process: its first call, with the imports it makes, and a second call).
"""

from __future__ import annotations

import multiprocessing
import resource
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"


def spec_mapping(n: int) -> dict:
    return {
        "name": "store_bench",
        "base": str(CASE3),
        "overrides": [],
        "random": {"n": n, "seed": 1, "params": {
            "body.mass": {"scale_uniform": [0.5, 1.5]},
            "controller.k_c": {"scale_uniform": [0.5, 2.0]},
            "controller.l_c": {"scale_uniform": [0.5, 2.0]},
            "controller.k_t": {"scale_uniform": [0.7, 1.4]},
            "initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}},
        }},
    }


def _spec(n: int):
    from rbstab.sweep import spec_from_mapping

    data = spec_mapping(n)
    data.pop("overrides")
    return spec_from_mapping(data, overrides=["simulation.rtol=1e-6"])


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def dry_run(n: int) -> dict:
    from rbstab.sweep.table import plan_table

    spec = _spec(n)
    t0, c0 = time.perf_counter(), _cpu()
    table = plan_table(spec)
    t1 = time.perf_counter()
    lines = table.describe()
    t2, c2 = time.perf_counter(), _cpu()
    assert table.n == n and len(lines) > 10
    return {"plan and validate": (t1 - t0, "s"), "listing": (t2 - t1, "s"),
            "CPU of both": (c2 - c0, "s (target <= 10)"), "peak": (_peak_mib(), "MiB (target <= 1024)")}


def sweep(n: int, folder: str) -> dict:
    from rbstab.engine import ensure_compiled
    from rbstab.sweep import run_sweep
    from rbstab.sweep.executors import LocalExecutor

    ensure_compiled()
    spec = _spec(n)
    with LocalExecutor(2) as ex:
        ex.start()
        c0, t0 = _cpu(), time.perf_counter()
        outcome = run_sweep(spec, folder, executor=ex, store="summary", progress=False)
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
    worker = sum(outcome.timing.values()) / max(outcome.n_executed, 1)
    size = sum(p.stat().st_size for p in (Path(folder) / spec.name / "runs").iterdir())
    return {"runs executed": (outcome.n_executed, ""), "wall": (wall, "s"),
            "parent CPU a run": (1e3 * cpu / n, "ms (target <= 0.05)"),
            "worker time a run": (1e3 * worker, "ms"),
            "wall / (N x worker time / 2)": (wall / (n * worker / 2), "(target <= 1.25 + start-up)"),
            "parent peak": (_peak_mib(), "MiB"), "worker peak": ((outcome.worker_peak_rss or 0) / 2**20, "MiB"),
            "store bytes a run": (size / n, "B (target <= 600)")}


class _Serial:
    """An executor that runs each item in this process (for the replayed store)."""

    name = "serial"
    return_bytes = False

    def describe(self) -> str:
        return "this process"

    def plan(self, n_items: int) -> None:
        pass

    def parallelism(self) -> int:
        return 1

    def imap_unordered(self, fn, items, *args):
        for item in items:
            yield item, fn(item, *args), None

    def close(self) -> None:
        pass

    def abort(self) -> None:
        pass


def _replay_engine(pool):
    """An engine that hands the sink ``pool`` (a RunBlock of 32 runs) for every 32 tasks."""
    import dataclasses

    def head(k: int):
        return dataclasses.replace(
            pool, configs=pool.configs[:k], outputs={n: v[:k] for n, v in pool.outputs.items()},
            summaries={n: v[:k] for n, v in pool.summaries.items()},
            **{name: getattr(pool, name)[:k] for name in ("status", "message", "solver", "wall_time", "timing",
                                                           "switching")})

    def engine(tasks, options, sink):
        records = []
        for lo in range(0, len(tasks), len(pool.configs)):
            part = tasks[lo:lo + len(pool.configs)]
            records += sink.add_block(part, pool if len(part) == len(pool.configs) else head(len(part)))
        return records

    return engine


def store(n: int, folder: str) -> dict:
    from rbstab.config import load_config
    from rbstab.simulator import simulate_blocks
    from rbstab.sweep import run_sweep
    from rbstab.sweep import worker

    base = load_config(CASE3)
    (_, pool), = simulate_blocks([base.with_initial_state({"omega": [16 + i, 32, -16]}) for i in range(32)],
                                 full=False)
    worker._compiled_engine = _replay_engine(pool)  # the compiled engine's chunks replayed, not integrated
    worker._table_batch = lambda part, options: None
    spec = _spec(n)
    t0 = time.perf_counter()
    run_sweep(spec, folder, executor=_Serial(), engine="compiled", store="summary", chunk_size=10_000,
              progress=False)
    t1 = time.perf_counter()
    size = sum(p.stat().st_size for p in (Path(folder) / spec.name / "runs").iterdir())
    return {"written (no integration)": (t1 - t0, "s"), "store bytes a run": (size / n, "B"),
            "peak": (_peak_mib(), "MiB")}


def open_(folder: str) -> dict:
    import rbstab

    t0, c0 = time.perf_counter(), _cpu()
    ds = rbstab.open_sweep(Path(folder) / "store_bench")  # its imports (xarray, pyarrow, dask) included
    t1, c1 = time.perf_counter(), _cpu()
    summary = ds[["lyapunov_final", "max_abs_constraint_error_x", "status", "converged"]].load()
    t2 = time.perf_counter()
    assert summary.sizes["run"] > 0
    del ds, summary
    t3 = time.perf_counter()
    again = rbstab.open_sweep(Path(folder) / "store_bench")
    t4 = time.perf_counter()
    assert again.sizes["run"] > 0
    return {"open_sweep": (t1 - t0, "s (target <= 2 at 10^6 runs; first call, imports included)"),
            "  its CPU": (c1 - c0, "s"), "  again (imports done)": (t4 - t3, "s"),
            "load 4 summary variables": (t2 - t1, "s"),
            "peak": (_peak_mib(), "MiB")}


def _child(queue, fn, args) -> None:
    warnings.simplefilter("ignore")
    queue.put(fn(*args))


def in_process(fn, *args) -> dict:
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(queue, fn, args))
    proc.start()
    out = queue.get()
    proc.join()
    return out


def show(title: str, figures: dict) -> None:
    print(title, flush=True)
    for key, (value, unit) in figures.items():
        print(f"  {key:<32} {value:12.4g} {unit}", flush=True)


def main() -> None:
    n_sweep, n_store, n_plan = (int(a) for a in (sys.argv[1:] + ["100000", "1000000", "1000000"][len(sys.argv) - 1:]))
    show(f"dry run, {n_plan} runs", in_process(dry_run, n_plan))
    with tempfile.TemporaryDirectory() as folder:
        show(f"sweep, {n_sweep} runs, --store summary -j 2", in_process(sweep, n_sweep, folder))
    with tempfile.TemporaryDirectory() as folder:
        show(f"summary store of {n_store} runs (integration replayed)", in_process(store, n_store, folder))
        show("open_sweep of it", in_process(open_, folder))


if __name__ == "__main__":
    main()
