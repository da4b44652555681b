"""Benchmark: a 10-factor Sobol' study and a 100-trial tuning study of Case 3.

Targets: a 10-factor Sobol' study with N = 1024 on Case 3 end to end < 60 s on two cores
(< 5 s on a GPU); a 100-trial tuning study of two gains < 30 s on two cores. Prints one
table:

- **sobol**: ``rbstab sensitivity configs/paper/case3_embedded.yaml -n N`` with ten
  factors (the eight gains scaled in [0.5, 2], the mass in [30, 50] kg, Omega_x(0) in
  [10, 22] rad/s) and the default metrics, from process start to exit, in a fresh folder:
  N (D + 2) = 12 N runs (first-order and total indices; the 22,528 runs quoted for
  N = 1024 count the second-order design N (2D + 2), which the study does not draw);
- **sobol, resumed**: the same command again (every run is there: design, index, analysis);
- **tune**: ``rbstab tune configs/paper/case3_embedded.yaml --trials 100`` over K_c and
  L_c scaled in [0.25, 4], minimizing v(t_end) with max |E_z| <= 0.1 m, from process
  start to exit, with the default SQLite storage and (in process) with
  ``storage="memory"``, and the time per trial.

Usage::

    python benchmarks/studies.py [--jobs 2] [-n 1024] [--trials 100]
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
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
#: The console script beside this interpreter (the installed ``rbstab``).
RBSTAB = str(Path(sys.executable).parent / "rbstab")

FACTORS = [*(f"controller.{k}=scale_uniform:[0.5,2]" for k in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d")),
           "body.mass=uniform:[30,50]", "initial_state.omega.0=uniform:[10,22]"]
GAINS = ["controller.k_c=scale_uniform:[0.25,4]", "controller.l_c=scale_uniform:[0.25,4]"]
SPEC = ["--minimize", "lyapunov_final", "--subject-to", "max_abs_constraint_error_z<=0.1"]


def _timed(args: list[str]) -> tuple[float, str]:
    """Wall time [s] of ``rbstab ARGS`` and its stdout."""
    start = time.perf_counter()
    done = subprocess.run([RBSTAB, *args], capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"rbstab {' '.join(args)} failed:\n{done.stderr}")
    return elapsed, done.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("-n", type=int, default=1024, help="Sobol' base samples (a power of 2)")
    parser.add_argument("--trials", type=int, default=100)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        sobol = ["sensitivity", str(CASE3), "-n", str(args.n), "-j", str(args.jobs), "-o", tmp, "--json", "-q",
                 "--no-progress", "--no-warn", "all", *(f"--vary={v}" for v in FACTORS)]
        elapsed, out = _timed(sobol)
        n_runs = json.loads(out.splitlines()[0])["n_runs"]
        rows.append((f"sobol, 10 factors, N = {args.n}", f"{n_runs} runs", elapsed, f"{n_runs / elapsed:.0f} runs/s"))
        elapsed, _ = _timed(sobol)
        rows.append(("sobol, resumed (all runs there)", f"{n_runs} runs", elapsed, ""))
        tune = ["tune", str(CASE3), "--trials", str(args.trials), "-o", tmp, "--json", "-q", "--no-warn", "all",
                *(f"--vary={v}" for v in GAINS), *SPEC]
        elapsed, out = _timed(tune)
        best = json.loads(out)
        rows.append((f"tune, 2 gains, SQLite, {args.trials} trials", f"best {best['best_value']:.4g} J", elapsed,
                     f"{1e3 * elapsed / args.trials:.0f} ms/trial"))
        rows.append(_tune_in_process(args.trials, Path(tmp)))
    print(f"{'study':<44} {'size':>14} {'wall [s]':>9}  rate")
    for name, size, elapsed, rate in rows:
        print(f"{name:<44} {size:>14} {elapsed:9.2f}  {rate}")
    print("targets: sobol N = 1024 < 60 s on 2 cores; tune 100 trials < 30 s on 2 cores")


def _tune_in_process(trials: int, tmp: Path) -> tuple:
    """``rbstab.tune`` in this process with ``storage="memory"`` (after the compile cache is loaded)."""
    import rbstab
    from rbstab.engine import ensure_compiled

    ensure_compiled()
    config = rbstab.load_config(CASE3)
    start = time.perf_counter()
    result = rbstab.tune(config, GAINS, trials=trials, minimize=["lyapunov_final"],
                         subject_to=["max_abs_constraint_error_z<=0.1"], storage="memory", output=tmp, name="memory")
    elapsed = time.perf_counter() - start
    return (f"tune, in process, memory, {trials} trials", f"best {result.best_values[0]:.4g} J", elapsed,
            f"{1e3 * elapsed / trials:.0f} ms/trial")


if __name__ == "__main__":
    main()
