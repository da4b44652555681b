"""Benchmark: tuning studies at the batch engine's speed, and a Sobol' study.

Prints one table (wall times in this process, after the compile cache is loaded and a
small untimed study has imported Optuna and SQLAlchemy, ~1 s the first study of a process pays):

- **two gains, 240 trials**: Case 2's damping gains L_t and L_r, one log-scaled factor each
  over four decades (``scale_log_uniform:[0.01,100]``), minimizing v(t_end): TPE (the
  default) and CMA-ES, with ``storage="memory"`` and with the default storage (Optuna's
  journal in the SQLite file ``journal.db``), and TPE with Optuna's relational storage on
  SQLite (``storage="sqlite:///.../study.db"``, as ``--storage`` takes it); the best value
  against the best of the 31 x 31 log grid;
- **six gains, 10,000 trials**: the six gain vectors of Case 3 scaled in [0.25, 4]
  (log-scaled), CMA-ES with IPOP restarts, in memory;
- **robust, --over 64 bodies x 2,000 trials**: Case 3's K_c and L_c over 64 bodies whose
  mass is within +-20 %, the worst case, CMA-ES, in memory (128,000 runs); in this process,
  or with ``--jobs N`` on N local worker processes (``-j N``);
- **GPU, 10^6 trial-runs** (``--gpu``): 1,000 trials x 1,000 bodies with ``engine="cuda"``,
  where a GPU can be reached; else the note says so.

Targets (two cores): 240 trials <= 2 s; 10,000 trials of six gains <= 30 s; 64 x 2,000
<= 60 s; on a GPU 10^6 trial-runs <= 10 s.

Usage::

    python benchmarks/studies.py [--only two,six,robust] [--jobs N] [--gpu]
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
CASE2 = ROOT / "configs" / "paper" / "case2_visco_elastic.yaml"
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
TWO = ["controller.l_t=scale_log_uniform:[0.01,100]", "controller.l_r=scale_log_uniform:[0.01,100]"]
SIX = [f"controller.{k}=scale_log_uniform:[0.25,4]" for k in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c")]
ROBUST = ["controller.k_c=scale_log_uniform:[0.25,4]", "controller.l_c=scale_log_uniform:[0.25,4]"]


def _grid_best(config) -> float:
    from rbstab.studies.batch import run_generation

    factors = np.geomspace(0.01, 100, 31)
    l_t, l_r = (np.asarray(config.resolved["controller"][k], dtype=float) for k in ("l_t", "l_r"))
    rows = [{**{f"controller.l_t[{i}]": l_t[i] * a for i in range(3)},
             **{f"controller.l_r[{i}]": l_r[i] * b for i in range(3)}} for a in factors for b in factors]
    return float(np.min(run_generation(config.resolved, pd.DataFrame(rows)).figures["lyapunov_final"]))


def _timed(tmp: Path, label: str, config, vary, trials: int, **kwargs) -> tuple:
    import rbstab

    start = time.perf_counter()
    result = rbstab.tune(config, vary, trials=trials, minimize=["lyapunov_final"], output=tmp, name=label.replace(" ", "_")
                         .replace(",", ""), **kwargs)
    return label, trials, time.perf_counter() - start, result.best_values[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="two,six,robust")
    parser.add_argument("--gpu", action="store_true", help="also 10^6 trial-runs with engine='cuda'")
    parser.add_argument("--jobs", type=int, default=None, help="the robust study's runs on N local processes")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    import rbstab
    from rbstab.engine import ensure_compiled

    ensure_compiled()
    only = set(args.only.split(","))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        rbstab.tune(rbstab.load_config(CASE2), TWO, trials=4, minimize=["lyapunov_final"], output=tmp,
                    name="warm_up", generation=4)  # imports Optuna and SQLAlchemy (untimed)
        if "two" in only:
            config = rbstab.load_config(CASE2)
            best = _grid_best(config)
            runs = [(sampler, storage) for sampler in ("tpe", "cmaes") for storage in ("memory", None)]
            for sampler, storage in [*runs, ("tpe", "rdb")]:
                where = {"memory": "memory", None: "SQLite journal", "rdb": "SQLite relational"}[storage]
                label = f"two gains, {sampler}, {where}"
                if storage == "rdb":
                    storage = f"sqlite:///{tmp / 'rdb.db'}"
                row = _timed(tmp, label, config, TWO, 240, sampler=sampler, storage=storage)
                rows.append((*row[:3], f"best / grid's best {row[3] / best:.3f}"))
        if "six" in only:
            config = rbstab.load_config(CASE3)
            row = _timed(tmp, "six gains, cmaes ipop, memory", config, SIX, 10_000, sampler="cmaes", storage="memory")
            rows.append((*row[:3], f"best {row[3]:.4g} J"))
        if "robust" in only:
            config = rbstab.load_config(CASE3)
            where = f", {args.jobs} processes" if args.jobs and args.jobs > 1 else ""
            row = _timed(tmp, f"robust, 64 bodies, cmaes, memory{where}", config, ROBUST, 2_000, sampler="cmaes",
                         storage="memory", over=["body.mass=scale_uniform:[0.8,1.2]"], over_n=64, generation=32,
                         jobs=args.jobs)
            rows.append((*row[:3], f"worst-case best {row[3]:.4g} J, {64 * 2000} runs"))
        if args.gpu:
            try:
                config = rbstab.load_config(CASE3)
                row = _timed(tmp, "gpu, 1000 x 1000 bodies", config, ROBUST, 1_000, sampler="tpe", storage="memory",
                             engine="cuda", over=["body.mass=scale_uniform:[0.8,1.2]"], over_n=1000, generation=500)
                rows.append((*row[:3], "10^6 trial-runs"))
            except Exception as exc:  # no GPU here
                rows.append(("gpu, 10^6 trial-runs", 0, float("nan"), f"no GPU could be reached ({exc})"))
        else:
            rows.append(("gpu, 10^6 trial-runs", 0, float("nan"), "not run (--gpu; none reachable here)"))
    print(f"{'study':<44} {'trials':>7} {'wall [s]':>9}  note")
    for label, trials, elapsed, note in rows:
        print(f"{label:<44} {trials:>7} {elapsed:9.2f}  {note}")
    print("targets (2 cores): 240 trials <= 2 s; 6 gains x 10,000 <= 30 s; 64 bodies x 2,000 <= 60 s; "
          "GPU 10^6 trial-runs <= 10 s")


if __name__ == "__main__":
    main()
