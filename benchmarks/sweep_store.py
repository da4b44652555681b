"""Costs of a sweep outside the integration, for a 10,000-run Case 3 parameter sweep.

    python benchmarks/sweep_store.py [N]          # default N = 10000

Prints, per run and in total, with the peak resident memory of the process of each phase
(each phase runs in its own forked process):

1. planning: ``expand`` of a spec in which every run is a different config (mass, inertia,
   K_c, L_c, K_t scaled, random Omega): pydantic validation, run ids, config hashes;
2. writing the default store (``--store thinned``, store files of 512 runs) from Case 3
   results: the config column (canonical JSON: the text and its hash come from the plan,
   as in a sweep), summary columns, traces (wall and CPU time; each run's parameter coordinates
   come with its task from the parent, as in a sweep, and are timed in 1.); and the index;
3. ``rbstab.open_sweep`` of that folder, summaries loaded (``lyapunov_final``, ``status``).

The results written are a block of 32 simulated Case 3 runs (what the compiled engine
hands a worker's store file at once, :func:`rbstab.simulator.simulate_blocks`) reused for
every 32 rows (the integration is not what is measured); every row has its own run id,
parameters and config.
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
        "random": {"n": n, "seed": 1, "params": {
            "body.mass": {"scale_uniform": [0.5, 1.5]},
            "body.inertia": {"scale_uniform": [0.5, 1.5]},
            "controller.k_c": {"scale_uniform": [0.5, 2.0]},
            "controller.l_c": {"scale_uniform": [0.5, 2.0]},
            "controller.k_t": {"scale_uniform": [0.7, 1.4]},
            "initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}},
        }},
    }


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def plan(n: int) -> dict:
    from rbstab.sweep import expand, spec_from_mapping

    spec = spec_from_mapping(spec_mapping(n))
    t0 = time.perf_counter()
    runs = expand(spec)
    t1 = time.perf_counter()
    hashes = [r.config_hash for r in runs]
    t2 = time.perf_counter()
    from rbstab.sweep.folder import run_coords

    coords = [run_coords(r.params) for r in runs]
    t3 = time.perf_counter()
    assert len(set(hashes)) == n and len(coords) == n
    return {"expand (validate, ids, hashes)": t1 - t0, "config_hash (cached)": t2 - t1,
            "parameter coordinates": t3 - t2, "peak MB": _peak_mb()}


def write(n: int, folder: str) -> dict:
    from rbstab.config import load_config
    from rbstab.io.chunk import ChunkWriter, StoreRow, chunk_file_name
    from rbstab.simulator import simulate_blocks
    from rbstab.sweep import expand, spec_from_mapping
    from rbstab.sweep.folder import (RUNS_DIR, SPEC_FILE, parameter_columns, write_sweep_index,
                                     run_coords)
    from rbstab.sweep.runner import _dump_yaml, _spec_document

    spec = spec_from_mapping(spec_mapping(n))
    runs = expand(spec)
    base = load_config(CASE3)
    (_, pool), = simulate_blocks([base.with_initial_state({"omega": [16 + i, 32, -16]}) for i in range(32)],
                                 full=False)
    directory = Path(folder) / spec.name
    (directory / RUNS_DIR).mkdir(parents=True)
    parameters = parameter_columns(r.params for r in runs)
    rows = {}
    # each run's coordinates come with its task, from the parent (timed in planning)
    stored = [StoreRow(r.index, r.run_id, r.base, {k: v for k, (_, v) in run_coords(r.params).items()})
              for r in runs]
    ChunkWriter(directory / "x.h5", stored[:1])  # the provenance (git, versions), once a process
    t0 = time.perf_counter()
    c0 = time.process_time()
    for lo in range(0, n, 512):
        chunk = runs[lo : lo + 512]
        path = directory / RUNS_DIR / chunk_file_name(chunk[0].run_id)
        with ChunkWriter(path, stored[lo : lo + 512], store="thinned", parameters=parameters,
                         sweep=spec.name) as writer:
            for b in range(0, len(chunk), len(pool)):
                part = chunk[b : b + len(pool)]
                block = pool if len(part) == len(pool) else _head(pool, len(part))
                ids = [run.run_id for run in part]
                added = writer.add_block(ids, block, config_hashes=[run.config_hash for run in part],
                                         config_texts=[run.config_text for run in part])
                rows.update(zip(ids, added))
    t1 = time.perf_counter()
    cpu = time.process_time() - c0
    write_sweep_index(directory, runs, rows, {}, name=spec.name, ratio=spec.lyapunov_ratio, parameters=parameters)
    (directory / SPEC_FILE).write_text(_dump_yaml(_spec_document(spec, "benchmark")))
    t2 = time.perf_counter()
    size = sum(p.stat().st_size for p in (directory / RUNS_DIR).iterdir())
    return {"store files (thinned)": t1 - t0, "  of which CPU": cpu, "index, summary, sweep.yaml": t2 - t1,
            "MB on disk": size / 2**20, "peak MB": _peak_mb()}


def _head(block, k: int):
    """The first k runs of a RunBlock."""
    import dataclasses

    return dataclasses.replace(
        block, configs=block.configs[:k], outputs={n: v[:k] for n, v in block.outputs.items()},
        summaries={n: v[:k] for n, v in block.summaries.items()},
        **{name: getattr(block, name)[:k] for name in ("status", "message", "solver", "wall_time", "timing", "switching")})


def open_(folder: str) -> dict:
    import rbstab

    t0 = time.perf_counter()
    ds = rbstab.open_sweep(Path(folder) / "store_bench")
    t1 = time.perf_counter()
    summary = ds[["lyapunov_final", "max_abs_constraint_error_x", "status", "converged"]].load()
    t2 = time.perf_counter()
    assert summary.sizes["run"] > 0
    return {"open_sweep": t1 - t0, "load 4 summary variables": t2 - t1, "peak MB": _peak_mb()}


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


def show(title: str, figures: dict, n: int) -> None:
    print(title)
    for key, value in figures.items():
        if key in ("peak MB", "MB on disk"):
            print(f"  {key:<34} {value:10.0f}")
        else:
            print(f"  {key:<34} {value:8.2f} s  {1e3 * value / n:7.3f} ms/run")


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000
    print(f"{n} runs, Case 3 parameter sweep (every run a different config)")
    show("planning (parent)", in_process(plan, n), n)
    with tempfile.TemporaryDirectory() as folder:
        show("writing the default store", in_process(write, n, folder), n)
        show("open_sweep", in_process(open_, folder), n)


if __name__ == "__main__":
    main()
