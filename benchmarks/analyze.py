"""Benchmark: ``rbstab analyze`` of the paper's cases, and a 41 x 41 basin map of Case 3.

Targets: ``rbstab analyze`` of a paper case (no basin) < 2 s warm; a 41 x 41 basin map of
Case 3 < 30 s on 2 cores. Prints one table:

- **analyze CASE**: ``rbstab analyze configs/paper/<case>.yaml -o TMP`` from process start to
  exit (warm compile cache; best of ``--repeat``): the linearisation, the certificate (10,000
  sampled states), the simulation from the paper's initial state and the file;
- **in process**: the same analysis through ``rbstab.analysis.analyze`` after a first call,
  split into its parts (``Analysis.timing``);
- **basin 41 x 41**: ``rbstab analyze configs/paper/case3_embedded.yaml --basin
  initial_state.omega.0=-60:60:41 --basin initial_state.omega.1=-60:60:41 -j JOBS`` from
  process start to exit, and the basin part alone in process (1,681 runs of the compiled
  engine, 201 samples each), with the outcome counts.

Usage::

    python benchmarks/analyze.py [--jobs 2] [--repeat 3] [--basin-n 41]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = sorted((ROOT / "configs" / "paper").glob("*.yaml"))
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
#: The console script beside this interpreter (the installed ``rbstab``).
RBSTAB = str(Path(sys.executable).parent / "rbstab")


def _command(args: list[str], repeat: int) -> tuple[float, str]:
    """Best wall time [s] of ``rbstab ARGS`` over ``repeat`` runs, and the last stdout."""
    best, out = float("inf"), ""
    for _ in range(repeat):
        start = time.perf_counter()
        done = subprocess.run([RBSTAB, *args], capture_output=True, text=True)
        best = min(best, time.perf_counter() - start)
        if done.returncode != 0:
            raise SystemExit(f"rbstab {' '.join(args)} failed:\n{done.stderr}")
        out = done.stdout
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--basin-n", type=int, default=41)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    from rbstab.analysis import analyze
    from rbstab.engine import ensure_compiled

    ensure_compiled(say=print)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            wall, _ = _command(["analyze", str(case), "-o", tmp], args.repeat)
            analyze(case)  # warm: kernels loaded, imports done
            start = time.perf_counter()
            result = analyze(case)
            parts = ", ".join(f"{k} {v:.3f}" for k, v in result.timing.items())
            rows.append((f"analyze {case.stem}", f"{wall:.2f}", "< 2",
                         f"in process {time.perf_counter() - start:.3f} s ({parts}); {result.verdict}"))
        n = args.basin_n
        basin = [f"initial_state.omega.0=-60:60:{n}", f"initial_state.omega.1=-60:60:{n}"]
        wall, out = _command(["analyze", str(CASE3), "-o", tmp, "--json", "-j", str(args.jobs),
                              *(a for b in basin for a in ("--basin", b))], 1)
        record = json.loads(out.splitlines()[0])
        result = analyze(CASE3, certificate=False, simulate=False, basin=basin, jobs=args.jobs)
        rows.append((f"basin {n} x {n} case3 (command)", f"{wall:.2f}", "< 30",
                     f"-j {args.jobs}; {record['basin']['counts']}; inside the estimate {record['basin']['inside_estimate']}"))
        rows.append((f"basin {n} x {n} case3 (basin part)", f"{result.timing['basin']:.2f}", "",
                     f"{n * n} runs, {n * n / result.timing['basin']:.0f} runs/s, -j {args.jobs}"))
    print(f"{'what':<36} {'wall [s]':>9} {'target':>7}  notes")
    for what, wall, target, notes in rows:
        print(f"{what:<36} {wall:>9} {target:>7}  {notes}")


if __name__ == "__main__":
    main()
