"""Benchmark: the pure sign law of ``sliding`` with located switchings.

The 2 s run of ``configs/examples/sliding.yaml`` with ``boundary_layer: 0`` (Lambda =
-K_s sgn(E), eq 39). Prints:

- **run**: wall time of ``rbstab.simulator.simulate`` (warm compile cache, kernels loaded; the best
  of ``--repeat``), the located switchings and sliding of each axis, the rate check; and
  ``rbstab run`` of the same config timed from process start to exit;
- **reference**: the plain sign law (sgn(E) at every stage, no events) integrated by
  classical RK4 at fixed steps of 2 s / n, n in ``--steps``: the largest distance of the
  centre of mass X from ours up to t = 0.5 s and at t = 2 s, and the same between
  successive references; then how far our own X(2 s) moves when Omega(0) moves by 1e-12
  rad/s (the sensitivity of the chattering phase);
- **resolution**: the run at each switching resolution of ``--resolution``: wall time,
  crossings, pieces, when sliding started, and the distance of X to the finest's;
- **boundary layer**: the tanh(E/phi) law for phi in ``--phi``: its distance to the sign
  law's X up to 0.5 s and at 2 s, v(2 s), its wall time and right-hand-side calls.

Usage::

    python benchmarks/sign_law.py [--repeat 3] [--steps 1000000 2000000 4000000] [--phi 1e-2 1e-3 1e-4]
                                  [--resolution 1e-5 ... 1e-11]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
EXAMPLE = ROOT / "configs" / "examples" / "sliding.yaml"
WELL_CONDITIONED = 0.5  # [s]: before the switchings accumulate (see docs/sliding.md)

from rbstab.variants.paper import paper_form, paper_initial_state
from rbstab.config import PhysicalPlausibilityWarning  # noqa: E402

warnings.simplefilter("ignore", PhysicalPlausibilityWarning)  # Table 1's inertia (the config says so)


def config(*overrides):
    from rbstab.config import apply_overrides, config_from_mapping, parse_yaml

    return config_from_mapping(apply_overrides(parse_yaml(EXAMPLE.read_text()), list(overrides)))


def distances(x, x_ref, time):
    """max |X - X_ref| up to WELL_CONDITIONED, and at the end [m]."""
    d = np.abs(np.asarray(x) - np.asarray(x_ref)).max(axis=1)
    return d[time <= WELL_CONDITIONED + 1e-12].max(), d[-1]


def run_section(repeat: int):
    from rbstab.simulator import simulate

    simulate(config("controller.boundary_layer=0", "simulation.t_end=0.01", "simulation.n_samples=11"))  # load kernels
    runs = [simulate(config("controller.boundary_layer=0")) for _ in range(repeat)]
    best = min(runs, key=lambda r: r.wall_time)
    s = best.summary
    print(f"## run: {EXAMPLE.name}, boundary_layer 0, t_end 2 s, DOP853 rtol 1e-8 atol 1e-10")
    print(f"wall time (simulate, warm, best of {repeat}): {best.wall_time:.3f} s "
          f"(integration {best.timing['integration']:.3f} s, outputs and summary {best.timing['postprocess']:.3f} s)")
    print(f"status {best.status}; rhs calls {best.solver['nfev']}, steps {best.solver['n_steps']}, "
          f"pieces {best.solver['n_pieces']}")
    for key in ("switching_count", "sliding_starts", "sliding_time", "min_switching_interval", "chattering"):
        print(f"  {key:<24} " + "  ".join(f"{v:10.4g}" for v in s[key]))
    print(f"  v: {s['lyapunov_initial']:.4g} -> {s['lyapunov_final']:.4g} J, "
          f"max rise {s['max_lyapunov_increase']:.3g} J, "
          f"rate check {s['lyapunov_rate_check']} on {100 * s['lyapunov_rate_checked']:.0f} % of the samples "
          f"(relative mismatch {s['lyapunov_rate_mismatch_relative']:.2g})")
    print(f"  message: {best.message}")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sign.yaml"
        data = yaml.safe_load(EXAMPLE.read_text())
        data["controller"]["boundary_layer"] = 0.0
        path.write_text(yaml.safe_dump(data))
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from rbstab_cli.main import main; main()", "run", str(path), "-o", tmp],
                       check=True, capture_output=True)
        print(f"rbstab run (process start to exit, warm cache): {time.perf_counter() - start:.2f} s")
    return best


def reference_section(best, steps):
    from test_sign_law import fixed_step_sign_law

    from rbstab.engine.switching import integrate_sign_law

    c = best.config
    variant = paper_form(c)
    y0 = paper_initial_state(c, variant)
    time_ = best.time
    ours = best.outputs["position"]
    print("\n## the plain sign law by fixed-step RK4 (no events) against ours: max |X - X_ours| [m]")
    print(f"| steps of 2 s | h [s] | wall [s] | up to t = {WELL_CONDITIONED} s | at t = 2 s | "
          "to the previous reference, up to 0.5 s | at 2 s |")
    print("|---|---|---|---|---|---|---|")
    fixed_step_sign_law(variant, y0, 1e-3, 10, 10)  # compile (or load) the reference's loop
    previous = None
    for n in steps:
        start = time.perf_counter()
        ref = fixed_step_sign_law(variant, y0, 2.0, n, len(time_) - 1)[:, 6:9]
        wall = time.perf_counter() - start
        early, end = distances(ref, ours, time_)
        prev = distances(ref, previous, time_) if previous is not None else (np.nan, np.nan)
        print(f"| {n} | {2.0 / n:.1e} | {wall:.2f} | {early:.2e} | {end:.2e} | {prev[0]:.2e} | {prev[1]:.2e} |")
        previous = ref
    moved = y0.copy()
    moved[3] += 1e-12
    other = integrate_sign_law(variant, moved, c.simulation)
    early, end = distances(other.states[:, 6:9], ours, time_)
    print(f"ours with Omega_1(0) + 1e-12 rad/s: max |dX| up to {WELL_CONDITIONED} s {early:.1e} m, at 2 s {end:.1e} m")


def boundary_layer_section(best, phis):
    from rbstab.simulator import simulate

    ours = best.outputs["position"]
    simulate(config("controller.boundary_layer=0.01", "simulation.t_end=0.01", "simulation.n_samples=11"))  # load
    print("\n## the boundary layer tanh(E/phi) against the sign law: max |X_phi - X_sign| [m]")
    print(f"| phi [m] | up to t = {WELL_CONDITIONED} s | at t = 2 s | v(2 s) [J] | wall [s] | rhs calls | rate check |")
    print("|---|---|---|---|---|---|---|")
    for phi in phis:
        r = simulate(config(f"controller.boundary_layer={phi}"))
        early, end = distances(r.outputs["position"], ours, best.time)
        print(f"| {phi:g} | {early:.2e} | {end:.2e} | {r.summary['lyapunov_final']:.3g} | {r.wall_time:.3f} | "
              f"{r.solver['nfev']} | {r.summary['lyapunov_rate_check']} |")
    print(f"| 0 (sign law) | | | {best.summary['lyapunov_final']:.3g} | {best.wall_time:.3f} | {best.solver['nfev']} | "
          f"{best.summary['lyapunov_rate_check']} |")


def resolution_section(best, resolutions):
    from rbstab.engine.switching import integrate_sign_law

    c = best.config
    variant = paper_form(c)
    y0 = paper_initial_state(c, variant)
    runs = {r: integrate_sign_law(variant, y0, c.simulation, resolution=r) for r in resolutions}
    finest = runs[min(resolutions)].states[:, 6:9]
    print(f"\n## the switching resolution: max |X - X_finest| [m], the finest is {min(resolutions):g} m")
    print("| resolution [m] | wall [s] | crossings | pieces | sliding starts (t [s]) | max over the run | at t = 2 s |")
    print("|---|---|---|---|---|---|---|")
    for r in sorted(resolutions, reverse=True):
        start = time.perf_counter()
        sol = integrate_sign_law(variant, y0, c.simulation, resolution=r)
        wall = time.perf_counter() - start
        d = np.abs(sol.states[:, 6:9] - finest).max(axis=1)
        s = sol.switchings
        starts = ", ".join(f"{t:.3g}" for t in s.time[s.kind == 1])
        print(f"| {r:g} | {wall:.3f} | {np.sum(s.kind == 0)} | {sol.solver['n_pieces']} | {starts} | "
              f"{d.max():.1e} | {d[-1]:.1e} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--steps", type=int, nargs="*", default=[1_000_000, 2_000_000, 4_000_000])
    parser.add_argument("--phi", type=float, nargs="*", default=[1e-2, 1e-3, 1e-4])
    parser.add_argument("--resolution", type=float, nargs="*", default=[1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11])
    args = parser.parse_args()
    best = run_section(args.repeat)
    if args.resolution:
        resolution_section(best, args.resolution)
    if args.steps:
        reference_section(best, args.steps)
    if args.phi:
        boundary_layer_section(best, args.phi)


if __name__ == "__main__":
    main()
