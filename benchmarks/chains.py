"""Chains of rigid bodies: what a run and an evaluation of the chain's rate cost.

Prints (2 cores, warm numba cache):
- ms a run of each chain example (``rbstab.variants.chain.integrate``: scipy's ``solve_ivp``
  over the compiled rate) and of the one-body Case 3 config through the same chain engine
  and through the one-body compiled engine (``rbstab.simulator.simulate``);
- us an evaluation of the rate of a serial chain of n = 1..8 bodies (alternating permanent
  and visco-elastic joints with feedback, gravity), and that per body.

Run: python benchmarks/chains.py
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from rbstab.chain import GROUND, Body, Chain, Joint
from rbstab.config import load_config
from rbstab.config.chains import chain_of, load_any_config
from rbstab.simulator import simulate
from rbstab.variants import chain as C

ROOT = Path(__file__).resolve().parents[1]
D = np.diag


def _best(f, repeat=5):
    f()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def serial(n: int) -> Chain:
    bodies = tuple(Body(f"link{i}", 2.0, D([0.2, 0.2, 0.02])) for i in range(n))
    joints = []
    for i in range(n):
        gains = {"k_c": D([5e4] * 3), "l_c": D([500.0] * 3)} if i % 2 else {}
        joints.append(Joint(f"joint{i}", GROUND if i == 0 else i - 1, i, np.zeros(3) if i == 0 else np.array([0, 0, 0.3]),
                            np.array([0, 0, -0.3]), "visco_elastic" if i % 2 else "permanent",
                            D([400.0, 400.0, 100.0]), D([40.0, 40.0, 10.0]), **gains))
    return Chain(bodies, tuple(joints), np.array([0.0, 0.0, -9.81]))


def main() -> None:
    warnings.simplefilter("ignore")
    print("runs (ms a run, best of 5):")
    for name in ("double_pendulum", "stance_ankle_hip", "knee"):
        config = load_any_config(ROOT / "configs" / "examples" / f"{name}.yaml")
        compiled = C.compile_chain(config.chain)
        seconds = _best(lambda: C.integrate(config, compiled=compiled))
        print(f"  {name:18s} {config.chain.size} bodies, t_end {config.simulation.t_end:g} s: {1e3 * seconds:8.1f} ms")
    case3 = load_config(ROOT / "configs" / "paper" / "case3_embedded.yaml")
    one = _best(lambda: simulate(case3))
    print(f"  case3_embedded one-body engine, t_end {case3.simulation.t_end:g} s: {1e3 * one:8.1f} ms")
    y0 = np.concatenate([case3.initial_state[b] for b in ("theta", "omega", "position", "velocity", "controller_state")])
    compiled = C.compile_chain(chain_of(case3), offset=0.0)
    rate = np.empty(compiled.n_states)

    def chain_run():
        from scipy.integrate import solve_ivp
        sim = case3.simulation
        return solve_ivp(lambda t, y: (C.chain_rate(t, y, *compiled.args, rate), rate.copy())[1], (0, sim.t_end), y0,
                         method=sim.method, rtol=sim.rtol, atol=sim.atol, t_eval=np.linspace(0, sim.t_end, sim.n_samples))
    print(f"  case3_embedded as a one-body chain (scipy over the chain rate): {1e3 * _best(chain_run, 3):8.1f} ms")
    print("rate evaluations (us an evaluation; per body):")
    for n in range(1, 9):
        compiled = C.compile_chain(serial(n), offset=0.0)
        y = C._place(compiled, np.random.default_rng(n).normal(scale=0.1, size=compiled.n_states))
        dy = np.empty(compiled.n_states)
        k = 2000
        args = compiled.args

        def loop():
            for _ in range(k):
                C.chain_rate(0.0, y, *args, dy)
        seconds = _best(loop, 3) / k
        print(f"  n = {n}: {1e6 * seconds:7.2f} us  ({1e6 * seconds / n:6.2f} us a body)")


if __name__ == "__main__":
    main()
