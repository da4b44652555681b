"""Benchmark: the sublevel estimate c against the sample count N, sampled alone and with the
local search (``rbstab.analysis.certificate.certify``), on the shipped configurations and a
standing body pinned at the ankle with a clipped ankle torque.

For each configuration, N and seed: c from the N samples alone, c with the local search
(its history at N/4, N/2, N and whether it settled), and the seconds ``certify`` took.
Where the states with dv/dt > 0 are a sliver at low levels (a clipped torque: a tilt just
beyond the clip, a small velocity towards it), the sampled c keeps falling with N while
the refined one stays put; where the domain boundary bounds c, both are that level.

Usage::

    python benchmarks/estimate.py [--n 250,1000,2500,10000] [--seeds 3]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: One body pinned at the ankle: 70 kg, centre of mass 0.95 m above the pin, ankle torque
#: clipped at 180 N m about the tilt axes.
STANCE = {
    "name": "stance",
    "body": {"mass": 70.0, "inertia": [12.0, 12.0, 1.0], "attachment_point": [0.0, 0.0, -0.95],
             "gravity": [0.0, 0.0, -9.81]},
    "controller": {"variant": "permanent", "k_t": [0, 0, 0], "l_t": [0, 0, 0], "k_r": [1300, 1300, 200],
                   "l_r": [350, 350, 50], "saturation": {"torque_n": [180.0, 180.0, float("inf")], "shape": "clip"}},
    "initial_state": {"theta": [0.05, 0.0, 0.0]},
    "simulation": {"t_end": 5.0},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", default="250,1000,2500,10000", help="sample counts, comma-separated")
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    from rbstab.analysis.analyze import analysed_config
    from rbstab.analysis.certificate import ChainModel, certify
    from rbstab.analysis.linearise import linearise_chain
    from rbstab.config import config_from_mapping, load_config
    from rbstab.variants import chain as C
    from rbstab.variants.paper import has_paper_form

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        configs = [load_config(p) for p in sorted((ROOT / "configs").glob("*/*.yaml"))
                   if "sweeps" not in p.parts]
        configs.append(config_from_mapping(STANCE))
    print(f"{'config':22s} {'N':>6s}  {'sampled c [J], per seed':34s} {'refined c [J], per seed':34s} "
          f"{'settled':>8s} {'s/certify':>9s}")
    for config in configs:
        config, _ = analysed_config(config)
        if not has_paper_form(config.chain) or any(b.disturbances for b in config.chain.bodies):
            continue  # one body; not the pushes' example: its dynamics change in time
        compiled = C.compile_chain(config.chain)
        lin, coordinates = linearise_chain(compiled)
        model = ChainModel(compiled, coordinates)
        for n in (int(x) for x in args.n.split(",")):
            sampled, refined, settled = [], [], []
            start = time.perf_counter()
            for seed in range(args.seeds):
                cert = certify(model, lin, gimbal_margin=config.simulation.gimbal_margin, n_samples=n, seed=seed)
                sampled.append(cert.sublevel_sampled)
                refined.append(cert.sublevel)
                settled.append(cert.settled)
            seconds = (time.perf_counter() - start) / args.seeds
            print(f"{config.name:22s} {n:6d}  {' '.join(f'{c:10.5g}' for c in sampled):34s} "
                  f"{' '.join(f'{c:10.5g}' for c in refined):34s} {sum(settled):4d}/{len(settled):<3d} "
                  f"{seconds:9.2f}", flush=True)
        print(f"{'':22s} spread of the refined c at the largest N: "
              f"{(max(refined) - min(refined)) / max(min(refined), np.finfo(float).tiny):.2%}")


if __name__ == "__main__":
    main()
