"""Benchmark: the cost of saturating actuators on the compiled engine.

Case 3 of the paper (embedded, DOP853, rtol 1e-8), a parameter sweep of ``--n`` runs (mass
and inertia x U(0.5, 1.5), K_c x U(0.5, 2), Omega(0) random), integrated by
:func:`rbstab.engine.integrate_runs` in one process: as the paper has it; with every limit
set (|N_i| <= 200 N m, |H_i| <= 2000 N, |Lambda_i| <= 5000 N) that no run reaches (the
cost of the code alone), without and with a noise disturbance (a force at the centre of
mass, RMS 20 N per axis in 0.5-5 Hz: 16 sines an axis at every right-hand side, and the
work W integrated with the state); with the limits reached (``clip`` and ``smooth``); and
with the limits reached and the noise. Prints the CPU seconds a run of each (the fastest of
two passes), their ratio to the runs without limits (the target: <= 1.3x with every limit
set and the noise), the ratio a right-hand side (saturated and pushed runs take other
steps: their dynamics differ, and ``clip``'s kinks make the step-size control reject
steps) and the share of samples at which |N_i| is at its limit (the runs'
``torque_n_saturated`` flags).

    python benchmarks/saturation.py [--runs 10000]
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE3 = str(ROOT / "configs" / "paper" / "case3_embedded.yaml")


#: The noise disturbance of the last case (a config override: validated as any config).
NOISE = "disturbances=[{kind: noise, rms: 20, band: [0.5, 5.0], seed: 1}]"


def runs(n: int, shape: str | None, seed: int = 0, scale_limits: float = 1.0, noise: bool = False):
    """(codes, params, y0, settings rows) of n Case 3 runs, with every limit under ``shape``
    (times ``scale_limits``) and, if ``noise``, the disturbance :data:`NOISE`."""
    import rbstab
    from rbstab.variants.paper import paper_form, paper_initial_state
    from rbstab.engine.settings import settings_rows
    from rbstab.model import SATURATION_SHAPES

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = rbstab.load_config(CASE3, [NOISE] if noise else [])
    variant = paper_form(config)
    rng = np.random.default_rng(seed)
    params = np.repeat(variant.parameters, n)
    scale = rng.uniform(0.5, 1.5, n)
    params["mass"] *= scale
    params["inertia"] *= scale[:, None, None]
    params["inertia_inv"] /= scale[:, None, None]
    params["k_c"] *= rng.uniform(0.5, 2.0, n)[:, None, None]
    if shape is not None:
        params["torque_limit"] = 200.0 * scale_limits
        params["force_limit"] = 2000.0 * scale_limits
        params["constraint_force_limit"] = 5000.0 * scale_limits
        params["saturation"] = SATURATION_SHAPES[shape]
    y0 = np.repeat(paper_initial_state(config, variant)[None], n, axis=0)
    y0[:, 3:6] = rng.normal([16, 32, -16], 4, size=(n, 3))
    return np.full(n, variant.code), params, y0, np.repeat(settings_rows([config.simulation]), n, axis=0)


def seconds_a_run(n: int, shape: str | None, scale_limits: float = 1.0, noise: bool = False, repeat: int = 2
                  ) -> tuple[float, float, float]:
    """(CPU seconds a run, the fastest of ``repeat`` passes; right-hand sides a run; share
    of samples where |N_i| is at its limit) of the sweep."""
    from rbstab.engine import integrate_runs
    from rbstab.variants.kernels import run_outputs
    from rbstab.layout import N_OUTPUTS, OUTPUTS

    codes, params, y0, rows = runs(n, shape, scale_limits=scale_limits, noise=noise)
    integrate_runs(codes[:8], params[:8], y0[:8], rows[:8], method="DOP853", n_samples=2001)  # compiled
    cost = math.inf
    for _ in range(repeat):  # the fastest of ``repeat`` passes: the least disturbed by other processes
        nfev = 0
        start = time.process_time()
        for lo in range(0, n, 256):
            sol = integrate_runs(codes[lo:lo + 256], params[lo:lo + 256], y0[lo:lo + 256], rows[lo:lo + 256],
                                 method="DOP853", n_samples=2001)
            nfev += int(sol.nfev.sum())
        cost = min(cost, (time.process_time() - start) / n)
    if shape is None:
        return cost, nfev / n, 0.0
    out = np.empty((N_OUTPUTS, len(sol.samples), 2001))
    run_outputs(codes[lo:lo + 256], params[lo:lo + 256], np.zeros((1, sol.samples.shape[1])), sol.samples, out, True)
    acting = out[OUTPUTS["torque_n_saturated"].columns] == 1.0
    return cost, nfev / n, float(acting.any(axis=0).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", "--n", dest="runs", type=int, default=10_000,
                        help="runs of the sweep (default 10000, the target's)")
    args = parser.parse_args()
    base, base_nfev, _ = seconds_a_run(args.runs, None)
    print(f"Case 3 parameter sweep, {args.runs} runs, one process: {base * 1e3:.3f} ms a run without limits "
          f"({base_nfev:.0f} right-hand sides a run)")
    for shape, scale, noise, what in (("clip", 1e9, False, "every limit set, none reached"),
                                      ("clip", 1e9, True, "every limit set, none reached, and a noise disturbance"),
                                      ("clip", 1.0, False, "every limit set"),
                                      ("smooth", 1.0, False, "every limit set"),
                                      ("clip", 1.0, True, "every limit set and a noise disturbance")):
        cost, nfev, share = seconds_a_run(args.runs, shape, scale, noise)
        acting = f"; |N_i| at its limit at {share:.0%} of the last batch's samples" if scale == 1.0 else ""
        print(f"  {what}, {shape}: {cost * 1e3:.3f} ms a run ({cost / base:.2f}x; {nfev:.0f} right-hand sides, "
              f"{cost / nfev / (base / base_nfev):.2f}x a right-hand side){acting}")

if __name__ == "__main__":
    main()
