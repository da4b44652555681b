"""Benchmark: ``rbstab animate`` and the report's animations, on the paper's cases.

Targets: ``rbstab animate results/case3_embedded.h5 -o case3.html`` < 15 s; the report of
the three paper cases with animations < 30 s and < 10 MB. Prints one table:

- **animate case3 html**: ``rbstab animate CASE3.h5 -o case3.html`` from process start to
  exit (defaults: 20 frames/s at a quarter of real time, 161 frames, 512 x 384 pixels;
  best of ``--repeat``), and the page's size;
- **animate case3 gif**: the same as a GIF;
- **report, 3 cases**: ``rbstab report case1 case2 case3 -o TMP`` with the animations
  (``--animation-frames``, default 100 each), drawn by one worker process per CPU (the
  default ``-j``) and in the command's process (``-j 1``), and with ``--no-animations``:
  wall time, the size of the folder (page and figures) and of ``index.html``;
- **report, case 3 alone**: what a Case 3 page weighs.

The runs are made first (``rbstab run configs/paper/*.yaml`` into a temporary folder). Each
row gives the wall time and the CPU time (user + system) of the command and of every
process it started (the report's worker processes, which its fork server starts: this
process adopts them as a child subreaper on Linux, so that their time is counted), and
the load average is printed with them: on a shared machine the wall times grow with the
load, the CPU times much less.

Usage::

    python benchmarks/animate.py [--repeat 1]
"""

from __future__ import annotations

import argparse
import ctypes
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = sorted((ROOT / "configs" / "paper").glob("*.yaml"))
#: The console script beside this interpreter (the installed ``rbstab``).
RBSTAB = str(Path(sys.executable).parent / "rbstab")


def _adopt_orphans() -> None:
    """Become the child subreaper (Linux ``prctl(PR_SET_CHILD_SUBREAPER)``): the processes
    a command leaves behind (its fork server, the workers it forked) are re-parented to
    this process, which reaps them, so that their CPU time counts in RUSAGE_CHILDREN."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):  # pragma: no cover - not Linux: the workers' time is not counted
        pass


def _reap() -> None:
    """Wait for every process this one adopted."""
    while True:
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:
            return


def _command(args: list[str], repeat: int) -> tuple[float, float]:
    """Best wall time [s] of ``rbstab ARGS`` over ``repeat`` runs, and the CPU time [s] (user +
    system) of that run."""
    best = (float("inf"), float("nan"))
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        env = {k: v for k, v in os.environ.items() if k != "RBSTAB_ANIMATION_FRAMES"}  # the defaults
        done = subprocess.run([RBSTAB, *args], capture_output=True, text=True, env=env)
        wall = time.perf_counter() - start
        _reap()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            raise SystemExit(f"rbstab {' '.join(args)} failed:\n{done.stderr}")
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        best = min(best, (wall, cpu))
    return best


def _megabytes(path: Path) -> float:
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files) / 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    _adopt_orphans()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        _command(["run", *map(str, CASES), "-o", str(tmp), "-q"], 1)
        runs = [str(tmp / f"{c.stem}.h5") for c in CASES]
        case3 = str(tmp / "case3_embedded.h5")
        rows = []
        for kind in ("html", "gif"):
            out = tmp / f"case3.{kind}"
            times = _command(["animate", case3, "-o", str(out)], args.repeat)
            rows.append((f"animate case3 {kind}", *times, _megabytes(out), "< 15 s" if kind == "html" else ""))
        for label, extra in (("report, 3 cases, animations", []), ("report, 3 cases, animations, -j 1", ["-j", "1"]),
                             ("report, 3 cases, --no-animations", ["--no-animations"])):
            out = tmp / "report"
            times = _command(["report", *runs, "-o", str(out), *extra], args.repeat)
            rows.append((label, *times, _megabytes(out), "< 30 s, < 10 MB" if not extra else ""))
            rows.append(("  of which index.html", NAN, NAN, _megabytes(out / "index.html"), ""))
        out = tmp / "report3"
        times = _command(["report", case3, "-o", str(out)], args.repeat)
        rows.append(("report, case 3 alone", *times, _megabytes(out), ""))
        rows.append(("  of which index.html", NAN, NAN, _megabytes(out / "index.html"), ""))
    print(f"load average {load:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} cores "
          f"(wall times grow with it); best of {args.repeat}")
    print(f"{'what':<36} {'wall [s]':>9} {'CPU [s]':>8} {'size [MB]':>10}  target")
    for label, wall, cpu, size, target in rows:
        print(f"{label:<36} {_number(wall):>9} {_number(cpu):>8} {size:>10.2f}  {target}")


NAN = float("nan")


def _number(value: float) -> str:
    return "" if value != value else f"{value:.2f}"


if __name__ == "__main__":
    main()
