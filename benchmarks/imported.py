"""Imported models against MuJoCo simulating the same file: how far apart, and what each costs.

For ``configs/examples/models/stance.xml`` (MJCF, three hinges with position servos, from its
keyframe ``lean``) and ``configs/examples/models/arm.urdf`` (URDF, two revolute joints and a
fixed hand, released from a raised pose), prints:

- what ``rbstab import`` takes (MuJoCo's compiler included; the CLI adds its start-up);
- the largest distance [m] of a centre of mass over 2 s (2001 samples) between rbstab
  (DOP853, rtol 1e-11) and MuJoCo's RK4 at 1e-4 s;
- rbstab's run (:func:`rbstab.simulator.simulate`: integration, outputs, summary; warm)
  and MuJoCo's RK4 at the model's own timestep over the same 2 s, best of 5.

Run: python benchmarks/imported.py  (MuJoCo: pip install -e ".[test]")
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import mujoco

from rbstab.config import config_from_mapping
from rbstab.config.model_import import import_model
from rbstab.config.yaml_io import parse_yaml
from rbstab.simulator import simulate

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from reference_mujoco import largest_distance, mujoco_model  # noqa: E402

MODELS = ROOT / "configs" / "examples" / "models"
CASES = [("stance.xml", "lean", None),
         ("arm.urdf", None, {"upper_arm": {"q": 0.5, "u": 0.0}, "forearm": {"q": -1.0, "u": 1.0}})]


def _best(f, repeat=5) -> float:
    f()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    for file, keyframe, initial in CASES:
        path = MODELS / file
        took = _best(lambda: import_model(path, keyframe=keyframe))
        data = parse_yaml(import_model(path, keyframe=keyframe).text)
        data["simulation"].update(t_end=2.0, n_samples=2001, rtol=1e-11, atol=1e-12)
        for body, state in (initial or {}).items():
            data["initial_state"][body].update(state)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            config = config_from_mapping(data)
            result = simulate(config)
            ours = _best(lambda: simulate(config))
        distance = largest_distance(path, config, result, keyframe=keyframe, initial=initial)
        model = mujoco_model(path)
        model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
        state = mujoco.MjData(model)
        steps = int(round(2.0 / model.opt.timestep))

        def theirs():
            mujoco.mj_resetData(model, state)
            mujoco.mj_step(model, state, nstep=steps)

        print(f"{file}: import {1e3 * took:.1f} ms; largest distance of a centre of mass over 2 s from MuJoCo "
              f"(RK4 at 1e-4 s): {distance:.2g} m; rbstab's run (rtol 1e-11, 2001 samples) {1e3 * ours:.1f} ms, "
              f"MuJoCo RK4 at its timestep {model.opt.timestep:g} s {1e3 * _best(theirs):.2f} ms")


if __name__ == "__main__":
    main()
