"""The double pendulum and the hinged stance against MuJoCo: what a run costs each engine,
side by side.

``configs/examples/double_pendulum.yaml`` (two rods on ball joints, gravity, no feedback),
2 s from its initial state. Prints, best of 5 (one process, warm caches):

- MuJoCo: ``mj_step`` with its RK4 at dt 2e-3 (1000 steps), the model built once, each run
  starting from ``mj_resetData`` and the initial orientations (ball joints: unit quaternions);
- rbstab: the compiled driver's integration of the chain (DOP853, rtol 1e-8, atol 1e-10, the
  first and last samples kept: :func:`rbstab.engine.integrate.integrate_chain_runs`), one run a
  call and 100 runs a call;
- rbstab's whole run as ``rbstab run`` makes it (:func:`rbstab.simulator.simulate`:
  the integration, the outputs at 201 samples and the summary), alone and a run of a sweep of
  2,000 runs in one process (:func:`rbstab.simulator.simulate_many`, as a sweep's worker runs them);
- the ratio rbstab / MuJoCo a run, and each engine's largest distance [m] of a centre of mass
  at t = 2 s from an rbstab run at rtol 1e-12 (its accuracy at those settings).

The same for ``configs/examples/stance_hinges.yaml`` (three hinges, the feedback as MuJoCo's
position servos, the ankle's clamped to its forcerange, the knee's ligaments as its stiffness
and damping: :func:`reference_mujoco.hinge_tree`), 2 s from its initial state.

Run: python benchmarks/versus_mujoco.py  (MuJoCo: pip install -e ".[test]")
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import mujoco
import numpy as np

from rbstab.config.loader import load_config
from rbstab.engine.integrate import integrate_chain_runs
from rbstab.engine.settings import settings_rows
from rbstab.engine.systems import tree_system
from rbstab.variants import chain as C

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from reference_mujoco import double_pendulum, hinge_tree  # noqa: E402  (MuJoCo's models of the examples)

T_END = 2.0
DT = 2e-3
#: Runs of the sweep whose cost a run is measured over (outputs and summary included).
SWEEP = 2000


def _best(f, repeat=5) -> float:
    f()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def rbstab_run(rtol: float, k: int = 1, example: str = "double_pendulum"):
    """(a function integrating k runs, the centres of mass at t_end (n, 3), the config)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(ROOT / "configs" / "examples" / f"{example}.yaml",
                                 [f"simulation.t_end={T_END}", "simulation.n_samples=2", f"simulation.rtol={rtol}",
                                  f"simulation.atol={rtol * 1e-2}"])
    compiled = C.compile_chain(config.chain)
    system = tree_system(compiled)
    y0 = np.repeat(C.initial_state(config)[None], k, axis=0)
    rows = np.repeat(settings_rows([config.simulation]), k, axis=0)
    rows[:, 6] = np.inf

    def run():
        return integrate_chain_runs(system, y0, rows, method="DOP853", n_samples=2)

    final = run().samples[0, -1, : 12 * compiled.size].reshape(-1, 12)[:, 6:9]  # the maximal image: X of each body
    return run, final, config


def mujoco_run(config, hinges: bool = False):
    """(a function running MuJoCo's RK4 over 2 s, the centres of mass at t_end (n, 3))."""
    if hinges:
        model, data, start, rate = hinge_tree(config, DT)
        ctrl = data.ctrl.copy()
    else:
        (model, data, start), rate, ctrl = double_pendulum(config, DT), 0.0, None
    steps = int(round(T_END / DT))

    def run():
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = start, rate
        if ctrl is not None:
            data.ctrl[:] = ctrl
        mujoco.mj_forward(model, data)
        mujoco.mj_step(model, data, nstep=steps)

    run()
    return run, data.xipos[1:].copy()


def main() -> None:
    run, final, config = rbstab_run(1e-8)
    _, reference, _ = rbstab_run(1e-12)
    batch, _, _ = rbstab_run(1e-8, k=100)
    mj, mj_final = mujoco_run(config)
    ours, theirs = _best(run), _best(mj)
    per_run_batch = _best(batch) / 100
    print(f"double pendulum, 2 s: MuJoCo RK4 dt {DT:g}: {1e3 * theirs:.3f} ms a run; rbstab DOP853 rtol 1e-8: "
          f"{1e3 * ours:.3f} ms a run ({1e3 * per_run_batch:.3f} ms a run in calls of 100)")
    print(f"  ratio rbstab / MuJoCo: {ours / theirs:.2f} ({per_run_batch / theirs:.2f} in calls of 100)")
    from rbstab.simulator import simulate, simulate_many

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole_config = load_config(ROOT / "configs" / "examples" / "double_pendulum.yaml",
                                       [f"simulation.t_end={T_END}", "simulation.n_samples=201",
                                        "simulation.rtol=1e-8", "simulation.atol=1e-10"])
    whole = _best(lambda: simulate(whole_config))
    print(f"  rbstab's whole run (outputs at 201 samples, summary): {1e3 * whole:.3f} ms, {whole / theirs:.2f}x MuJoCo")
    swept = _best(lambda: sum(1 for _ in simulate_many([whole_config] * SWEEP, full=False)), repeat=2) / SWEEP
    print(f"  in a sweep of {SWEEP} runs in one process (outputs at 201 samples, summary): {1e3 * swept:.3f} ms a run, "
          f"{swept / theirs:.2f}x MuJoCo")
    print(f"  largest distance of a centre of mass at t = 2 s from rbstab at rtol 1e-12: rbstab "
          f"{np.abs(final - reference).max():.2g} m, MuJoCo {np.abs(mj_final - reference).max():.2g} m")

    run, final, config = rbstab_run(1e-8, example="stance_hinges")
    _, reference, _ = rbstab_run(1e-12, example="stance_hinges")
    batch, _, _ = rbstab_run(1e-8, k=100, example="stance_hinges")
    mj, mj_final = mujoco_run(config, hinges=True)
    ours, theirs = _best(run), _best(mj)
    per_run_batch = _best(batch) / 100
    print(f"hinged stance (3 hinges, clamped ankle servo), 2 s: MuJoCo RK4 dt {DT:g}: {1e3 * theirs:.3f} ms a run; "
          f"rbstab DOP853 rtol 1e-8: {1e3 * ours:.3f} ms a run ({1e3 * per_run_batch:.3f} ms a run in calls of 100)")
    print(f"  ratio rbstab / MuJoCo: {ours / theirs:.2f} ({per_run_batch / theirs:.2f} in calls of 100)")
    print(f"  largest distance of a centre of mass at t = 2 s from rbstab at rtol 1e-12: rbstab "
          f"{np.abs(final - reference).max():.2g} m, MuJoCo {np.abs(mj_final - reference).max():.2g} m")


if __name__ == "__main__":
    main()
