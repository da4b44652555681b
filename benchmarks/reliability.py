"""What reliability costs: checksums on write and on resume, fsync, the wall-time clock.

Prints figures for docs/reliability.md (run it once; it takes ~30 s on 2 cores):

    python benchmarks/reliability.py
"""

from __future__ import annotations

import math
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from rbstab.config import PhysicalPlausibilityWarning, load_config
from rbstab.engine import ensure_compiled
from rbstab.io.chunk import ChunkWriter, StoreRow, read_chunk_rows
from rbstab.io.hdf5 import _file_image, result_attributes, write_result
from rbstab.io.integrity import verify_file
from rbstab.simulator import simulate_many

CASE3 = Path(__file__).resolve().parents[1] / "configs" / "paper" / "case3_embedded.yaml"
N_RUNS = 256


def _best(fn, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
    ensure_compiled()
    base = load_config(CASE3)
    configs = [base.with_initial_state({"omega": [16, 32, -16 + 0.01 * i]}, name=f"r{i}") for i in range(N_RUNS)]

    for wall in (math.inf, 600.0):  # the clock read every 64 steps
        limited = [c.__class__(**{**c.__dict__, "simulation": c.simulation.__class__(
            **{**c.simulation.__dict__, "max_wall_time": wall})}) for c in configs[:64]]
        seconds = _best(lambda: list(simulate_many(limited)), repeat=2)
        print(f"compiled engine, 64 Case 3 runs, max_wall_time={wall:g}: {seconds:.3f} s")

    results = [r for _, r in simulate_many(configs)]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        one = results[0]
        attrs = result_attributes(one)
        image = _best(lambda: _file_image(one.time, one.outputs, attrs), repeat=20)
        written = _best(lambda: write_result(one, tmp / "one.h5"), repeat=20)
        verified = _best(lambda: verify_file(tmp / "one.h5"), repeat=20)
        print(f"run file (2001 samples, {(tmp / 'one.h5').stat().st_size / 2**20:.2f} MiB): built with its "
              f"checksums {1e3 * image:.1f} ms, written with fsync {1e3 * written:.1f} ms, verified {1e3 * verified:.1f} ms")
        for store in ("thinned", "full"):
            path = tmp / f"chunk-{store}.h5"

            def write() -> None:
                with ChunkWriter(path, [StoreRow(i, f"r{i}") for i in range(N_RUNS)], store=store) as w:
                    for i, r in enumerate(results):
                        w.add(f"r{i}", r)

            seconds = _best(write, repeat=2)
            rows = _best(lambda: read_chunk_rows(path), repeat=3)
            full = _best(lambda: read_chunk_rows(path, data=True), repeat=3)
            size = path.stat().st_size / 2**20
            print(f"store '{store}' of {N_RUNS} runs ({size:.1f} MiB): written {seconds:.2f} s; read on resume "
                  f"{1e3 * rows / N_RUNS:.3f} ms/run (digest), {1e3 * full / N_RUNS:.3f} ms/run (every checksum)")
    print(f"(numpy {np.__version__})")


if __name__ == "__main__":
    main()
