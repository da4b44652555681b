"""Benchmark: push recovery and basin stability on the batch engine (``rbstab analyze --push``).

The body of Case 1 of the paper (permanent: the point C pinned 0.46 m below the centre of
mass, gravity: an inverted pendulum) with its torque actuators limited to |N_1|, |N_2| <=
250 N m and |N_3| <= 100 N m (gravity's torque at a tilt theta is ~172 sin(theta) N m), a
fall where a tilt reaches 1 rad (``simulation.limits.theta: [1, 1, 3.2]``: the run ends
there), t_end 3 s, 301 samples, DOP853 at rtol 1e-8. Prints, each end to end (the
command's process start to its exit, the engine already compiled):

1. the smallest fatal torque push of 256 quasi-uniform directions, tolerance 1e-3, with
   the local search (target <= 10 s on two cores);
2. basin stability over 10,000 random initial tilts and rates (target <= 10 s);
3. across 32 values of the torque limit, 64 directions each, with each configuration's
   certificate (10,000 sampled states, refined and checked) for the push estimate (target <= 3 minutes);
4. with ``--gpu`` (an NVIDIA GPU and ``rbstab[cuda]``): 16,384 directions on ``--engine
   cuda`` (target <= 5 s).

    python benchmarks/push.py [--jobs 2] [--quick] [--gpu]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "configs" / "paper" / "case1_permanent.yaml"


def write_config(folder: Path) -> Path:
    """The benchmark's configuration (module docstring), beside a copy of Case 1."""
    import yaml

    data = yaml.safe_load(CASE1.read_text())
    data["name"] = "case1_torque_limited"
    data["controller"]["saturation"] = {"torque_n": [250.0, 250.0, 100.0]}
    data["initial_state"] = {"theta": [0.0, 0.0, 0.0], "omega": [0.0, 0.0, 0.0]}
    data["simulation"].update(t_end=3.0, n_samples=301, limits={"theta": [1.0, 1.0, 3.2]})
    path = folder / "case1_torque_limited.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def timed(args: list[str]) -> tuple[float, str]:
    """(wall seconds, last output lines) of ``rbstab ARGS`` in a new process."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "rbstab", *args], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"rbstab {' '.join(args)} failed:\n{done.stdout}\n{done.stderr}")
    return seconds, "\n".join(done.stdout.strip().splitlines()[-4:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", "-j", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--quick", action="store_true", help="a tenth of each size (a smoke test)")
    parser.add_argument("--gpu", action="store_true", help="also 16,384 directions on --engine cuda")
    a = parser.parse_args()
    scale = 10 if a.quick else 1
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        config = write_config(folder)
        out = str(folder / "out")
        common = ["-o", out, "--no-certificate", "--no-simulation", "-j", str(a.jobs), "--overwrite"]
        timed(["analyze", str(config), *common, "--push", "torque", "--push-direction", "1,0,0"])  # compiled, cached
        n = 256 // scale
        seconds, tail = timed(["analyze", str(config), *common, "--push", "torque", "--push-directions", str(n)])
        print(f"1. {n} directions, tolerance 1e-3, local search: {seconds:.2f} s end to end on {a.jobs} "
              f"thread(s) (target 10 s for 256)\n{tail}\n")
        n = 10_000 // scale
        seconds, tail = timed(["analyze", str(config), *common, "--basin-stability", "initial_state.theta.0=-0.95:0.95",
                               "--basin-stability", "initial_state.omega.0=-6:6", "-n", str(n)])
        print(f"2. basin stability, {n} draws: {seconds:.2f} s end to end (target 10 s for 10,000)\n{tail}\n")
        spec = folder / "limits.yaml"
        levels = ", ".join(f"[{x:.1f}, {x:.1f}, 100.0]" for x in [100 + 10 * i for i in range(32 // scale)])
        spec.write_text(f"name: limits\nbase: {config}\ngrid:\n  controller.saturation.torque_n: [{levels}]\n")
        seconds, tail = timed(["analyze", str(spec), "-o", out, "-j", str(a.jobs), "--push",
                               "torque", "--push-directions", str(64 // scale)])
        print(f"3. {32 // scale} torque limits x {64 // scale} directions: {seconds:.1f} s end to end "
              f"(target 180 s for 32 x 64)\n{tail}\n")
        if a.gpu:
            n = 16_384 // scale
            timed(["analyze", str(config), *common, "--engine", "cuda", "--push", "torque", "--push-direction", "1,0,0"])
            seconds, tail = timed(["analyze", str(config), *common, "--engine", "cuda", "--push", "torque",
                                   "--push-directions", str(n)])
            print(f"4. {n} directions on the GPU: {seconds:.2f} s end to end (target 5 s for 16,384)\n{tail}")


if __name__ == "__main__":
    main()
