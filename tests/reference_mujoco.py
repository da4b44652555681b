"""MuJoCo's model of ``configs/examples/double_pendulum.yaml``: an independent reference for
rbstab's chains (tests/test_chains.py) and the side-by-side timing of
benchmarks/versus_mujoco.py. MuJoCo is a test dependency (pip install -e ".[test]")."""

from __future__ import annotations

import mujoco
import numpy as np

from rbstab.kinematics import rotation_matrix


def double_pendulum(config, timestep: float):
    """(model, data, qpos0) of the double pendulum ``config`` (a chain config: two bodies on
    ball joints, the upper pinned at the origin, each centre of mass 0.5 m below its joint,
    the lower joint 1 m below the upper) under gravity (0, 0, -9.81) m/s^2, integrated by
    MuJoCo's RK4 at ``timestep`` [s]; qpos0 (8,) the joints' unit quaternions of the
    config's initial orientations (the lower one relative to the upper), the bodies at rest."""
    upper, lower = config.chain.bodies
    xml = f"""<mujoco><option gravity="0 0 -9.81" timestep="{timestep}" integrator="RK4"/>
      <worldbody><body name="upper" pos="0 0 0"><joint type="ball" damping="0"/>
        <inertial pos="0 0 -0.5" mass="{upper.mass}" diaginertia="{' '.join(map(str, np.diag(upper.inertia)))}"/>
        <body name="lower" pos="0 0 -1"><joint type="ball" damping="0"/>
          <inertial pos="0 0 -0.5" mass="{lower.mass}" diaginertia="{' '.join(map(str, np.diag(lower.inertia)))}"/>
        </body></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    a1 = rotation_matrix(config.initial_state["upper"]["theta"])
    a2 = rotation_matrix(config.initial_state["lower"]["theta"])
    qpos0 = np.empty(8)
    for k, a in enumerate((a1, a1.T @ a2)):
        mujoco.mju_mat2Quat(qpos0[4 * k: 4 * k + 4], a.flatten())
    return model, data, qpos0
