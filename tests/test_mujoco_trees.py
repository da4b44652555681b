"""Random trees of every joint kind of a skeleton (hinges, universal joints, slides and
quaternion balls) with springs, dampers, reference postures, passive torques and servos
(some saturating) against MuJoCo's own simulation of the same bodies and joints, built
from the configuration's resolved sections alone (tests/reference_mujoco.py)."""

from __future__ import annotations

import numpy as np
import pytest

from rbstab.config import config_from_mapping
from rbstab.simulator import simulate

mujoco = pytest.importorskip("mujoco")

KINDS = ("hinge", "universal", "slide", "ball")


def _unit(rng) -> list[float]:
    axis = rng.normal(size=3)
    return (axis / np.linalg.norm(axis)).tolist()


def _joint(rng, kind: str) -> dict:
    """A joint of ``kind`` with random gains: a hinge's, a universal joint's (per coordinate)
    and a slide's servo about a reference, a passive spring about its own, a clip on some;
    a ball's isotropic spring and damper (MuJoCo's ball spring about the reference pose)."""
    if kind == "ball":
        k = float(rng.uniform(2.0, 6.0))
        return {"variant": "ball", "k_r": [k] * 3, "l_r": [float(rng.uniform(0.05, 0.3))] * 3}
    size = 2 if kind == "universal" else 1
    scale = 30.0 if kind == "slide" else 1.0  # a slide's spring [N/m] holds a weight

    def numbers(low, high):
        values = rng.uniform(low, high, size).tolist()
        return values if size == 2 else values[0]

    joint = {"variant": kind, "k_r": numbers(2.0 * scale, 6.0 * scale), "l_r": numbers(0.05 * scale, 0.3 * scale),
             "theta_ref": numbers(-0.05, 0.05),
             "passive": {"k_r": numbers(0.0, scale), "l_r": numbers(0.0, 0.1 * scale),
                         "theta_ref": numbers(-0.05, 0.05)}}
    if kind == "universal":
        first = np.asarray(_unit(rng))
        second = np.cross(first, _unit(rng))
        joint["axis"] = [first.tolist(), (second / np.linalg.norm(second)).tolist()]
    else:
        joint["axis"] = _unit(rng)
    if rng.uniform() < 0.6:  # a servo that clips, harder one way
        upper = numbers(0.3 * scale, 0.8 * scale)
        joint["saturation"] = {"torque_n": upper,
                               "torque_n_lower": np.negative(np.multiply(upper, rng.uniform(0.5, 2.0))).tolist()}
    return joint


def random_tree(seed: int, n: int = 4) -> dict:
    """n bodies, each held by a random kind of joint to the ground or to an earlier body, at
    random points, with full inertia tensors, under a tilted gravity; the coordinates of the
    hinges, universal joints and slides start off their references, moving."""
    rng = np.random.default_rng(seed)
    kinds = [KINDS[i % 4] for i in rng.permutation(n)]
    bodies, joints, start = [], [], {}
    for i, kind in enumerate(kinds):
        name = f"b{i}"
        root = rng.normal(scale=0.3, size=(3, 3))
        inertia = 0.02 * np.eye(3) + 0.01 * root @ root.T
        bodies.append({"name": name, "mass": float(rng.uniform(0.5, 2.0)), "inertia": inertia.tolist()})
        parent = "ground" if i == 0 else f"b{int(rng.integers(0, i))}"
        joints.append({"name": f"j{i}", "parent": parent, "child": name,
                       "parent_point": rng.normal(scale=0.1, size=3).tolist(),
                       "child_point": rng.normal(scale=0.2, size=3).tolist(), **_joint(rng, kind)})
        if kind in ("hinge", "slide"):
            start[name] = {"q": float(rng.uniform(-0.3, 0.3)), "u": float(rng.uniform(-0.5, 0.5))}
        elif kind == "universal":
            start[name] = {"q": rng.uniform(-0.3, 0.3, 2).tolist(), "u": rng.uniform(-0.5, 0.5, 2).tolist()}
    gravity = (np.array([0.0, 0.0, -9.81]) + rng.normal(scale=1.0, size=3)).tolist()
    return {"name": f"random{seed}", "gravity": gravity, "bodies": bodies, "joints": joints, "initial_state": start,
            "simulation": {"t_end": 2.0, "n_samples": 101, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12}}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_trees_of_every_kind_move_as_mujocos(seed):
    """Every body's centre of mass follows MuJoCo's (RK4 at 1e-4 s, its hinges, two-hinge
    bodies, slides and balls with their springs, dampers and position servos clamped to
    their force ranges) to 1e-6 m over 2 s; a ball's child, which rbstab starts unturned in
    the inertial frame, starts in MuJoCo at its turn from its parent then."""
    from scipy.spatial.transform import Rotation

    from reference_mujoco import hinge_tree

    config = config_from_mapping(random_tree(seed))
    assert {j.variant for j in config.chain.joints} == set(KINDS)
    result = simulate(config)
    assert result.status == "success", result.message
    clipped = [np.max(result.summary[f"fraction_saturated_{name}"]) for name in ("torque_n", "constraint_force")]
    assert max(clipped) > 0.0  # a servo (a slide's: its force) clips for a while
    dt = 1e-4
    model, state, qpos0, qvel0 = hinge_tree(config, dt)
    for b, joint in enumerate(config.chain.joints):  # a ball's child starts unturned in the inertial frame:
        if joint.variant == "ball":  # its turn from its parent, A_rel (a rotation vector), and Omega_j at t = 0
            at = model.joint(joint.name)
            turn = Rotation.from_rotvec(result.outputs["joint_theta"][0, b]).as_quat()  # (x, y, z, w)
            qpos0[at.qposadr[0]: at.qposadr[0] + 4] = np.roll(turn, 1)
            qvel0[at.dofadr[0]: at.dofadr[0] + 3] = result.outputs["joint_omega"][0, b]
    state.qpos[:], state.qvel[:] = qpos0, qvel0
    ids = [model.body(name).id for name in config.chain.body_names]  # MuJoCo's bodies in rbstab's order
    worst = 0.0
    for s, t in enumerate(result.time):
        if s:
            mujoco.mj_step(model, state, nstep=int(round((t - result.time[s - 1]) / dt)))
        mujoco.mj_forward(model, state)
        worst = max(worst, float(np.abs(result.outputs["position"][s] - state.xipos[ids]).max()))
    moved = float(np.abs(result.outputs["position"] - result.outputs["position"][0]).max())
    assert moved > 0.01  # the bodies move
    assert worst < 1e-6, worst
