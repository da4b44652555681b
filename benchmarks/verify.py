"""Benchmark: the verified sublevel bound (``rbstab analyze --verify``,
:func:`rbstab.analysis.verify_sublevel`) against the falsification-checked estimate, on the
saturated pendulum, the stance body pinned at the ankle and the ankle-knee-hip stance on
hinges (the target there: within 120 s on 2 cores).

For each configuration: the checked estimate c (sampled, refined by local search, checked
against the falsification runs; :func:`rbstab.analyze` without the settling run), the
verified c at each relative tolerance, the boxes and seconds of the proof, and the ratio
verified / estimated. Run it on an idle machine: the times are wall-clock.

Usage::

    python benchmarks/verify.py [--rtol 0.01,0.003] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ("configs/examples/saturated_pendulum.yaml", "configs/examples/stance_ankle.yaml",
           "configs/examples/stance_hinges.yaml")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rtol", default="0.01,0.003", help="relative tolerances of the proof, comma-separated")
    parser.add_argument("--repeat", type=int, default=3, help="proofs per tolerance (the least time is printed)")
    args = parser.parse_args()
    from rbstab.analysis import analyze, verify_sublevel
    from rbstab.config import load_config

    print(f"{'config':20s} {'estimate c [J]':>14s} {'rtol':>6s} {'verified c [J]':>14s} {'ratio':>6s} "
          f"{'boxes':>7s} {'seconds':>8s}")
    for name in CONFIGS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            config = load_config(ROOT / name)
            estimate = analyze(config, simulate=False).certificate.sublevel
        for rtol in (float(x) for x in args.rtol.split(",")):
            best = None
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                result = verify_sublevel(config, rtol=rtol)
                seconds = time.perf_counter() - t0
                best = seconds if best is None else min(best, seconds)
            print(f"{config.name:20s} {estimate:14.5g} {rtol:6.3g} {result.level:14.5g} "
                  f"{result.level / estimate:6.3f} {result.boxes:7d} {best:8.2f}")
        print(f"  {config.name}: bounded by {result.reason}")


if __name__ == "__main__":
    main()
