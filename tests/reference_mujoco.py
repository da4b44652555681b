"""MuJoCo's model of ``configs/examples/double_pendulum.yaml`` and of a tree of hinges (from
its config's resolved sections alone): independent references for rbstab's chains
(tests/test_chains.py, tests/test_hinge.py) and the side-by-side timing of
benchmarks/versus_mujoco.py; and MuJoCo simulating a model file that ``rbstab import`` read
(tests/test_import.py, benchmarks/imported.py). MuJoCo is a test dependency (pip install -e ".[test]")."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

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


def _coordinates(j) -> list[dict]:
    """Each coordinate of a hinge, slide or universal joint ``j`` (its resolved section) as one
    MuJoCo hinge (a slide's: a MuJoCo slide): name, type, axis, passive stiffness, damping,
    springref, servo kp, kv, target and
    force range, and its index (a universal joint's two hinges, in order, share one body)."""
    universal = j["variant"] == "universal"
    axes = j["axis"] if universal else [j["axis"]]

    def entry(section, key, k, default):
        value = (section or {}).get(key, default)
        return float(np.broadcast_to(np.asarray(value, dtype=float), (2,))[k]) if universal else float(value)

    out = []
    kind = "slide" if j["variant"] == "slide" else "hinge"
    for k, axis in enumerate(axes):
        passive, limits = j.get("passive") or {}, j.get("saturation") or {}
        upper = entry(limits, "torque_n", k, float("inf"))
        out.append({"name": f"{j['name']}_{k + 1}" if universal else j["name"], "axis": axis, "index": k, "type": kind,
                    "stiffness": entry(passive, "k_r", k, 0.0), "damping": entry(passive, "l_r", k, 0.0),
                    "springref": entry(passive, "theta_ref", k, 0.0), "kp": entry(j, "k_r", k, 0.0),
                    "kv": entry(j, "l_r", k, 0.0), "target": entry(j, "theta_ref", k, 0.0), "upper": upper,
                    "lower": entry(limits, "torque_n_lower", k, -upper)})
    return out


def hinge_tree(config, timestep: float):
    """(model, data, qpos0, qvel0) of a chain ``config`` whose joints are all hinges, slides,
    universal joints or balls, built from its resolved sections alone: each body's frame at its
    joint's point, unrotated (q = 0 is rbstab's), its centre of mass at -child_point with
    the full inertia; each hinge's ``axis`` (a universal joint's: two hinges in its body, in
    order, as MuJoCo composes them), its passive torque as the joint's ``stiffness``,
    ``damping`` and ``springref``, its feedback as a ``position`` servo (kp = k_r, kv = l_r,
    the target theta_ref set in ``data.ctrl``) whose force is clamped to [torque_n_lower,
    torque_n] where it has limits; a ball's isotropic k_r and l_r as its ``stiffness`` and
    ``damping`` (MuJoCo's ball spring about the reference pose: a ball with a reference, a
    passive torque or limits is refused); gravity as the config's; MuJoCo's RK4 at ``timestep``
    [s]. A ``range`` is left out (MuJoCo's limit is a constraint of its own solver, not
    rbstab's stop): a run compared with it stays inside its ranges. qpos0, qvel0: the
    initial q, u of each coordinate (0 where not written; a ball at its reference pose, at
    rest)."""
    data = config.resolved
    bodies = {b["name"]: b for b in data["bodies"]}
    joints = {j["child"]: j for j in data["joints"]}
    children: dict[str, list[str]] = {}
    for j in data["joints"]:
        children.setdefault(j["parent"], []).append(j["child"])

    def vec(x):
        return " ".join(repr(float(v)) for v in np.ravel(x))

    def body(name):
        j, b = joints[name], bodies[name]
        assert j["variant"] in ("hinge", "universal", "slide", "ball"), j["variant"]
        pos = np.asarray(j["parent_point"], dtype=float)
        if j["parent"] != "ground":  # the parent's frame sits at its own joint's point
            pos = pos - np.asarray(joints[j["parent"]]["child_point"], dtype=float)
        inertia = np.asarray(b["inertia"], dtype=float)
        inertia = np.diag(inertia) if inertia.ndim == 1 else inertia
        inner = "".join(body(c) for c in children.get(name, ()))
        if j["variant"] == "ball":  # its isotropic spring (MuJoCo's ball spring about the reference pose) and damper
            k, l = (float(np.ravel(j[key])[0]) for key in ("k_r", "l_r"))
            assert np.allclose(np.diag(np.ravel(j["k_r"])) if np.size(j["k_r"]) == 3 else j["k_r"], k * np.eye(3))
            assert not np.any(j.get("theta_ref") or 0.0) and not j.get("passive") and not j.get("saturation")
            hinges = f'<joint name="{j["name"]}" type="ball" stiffness="{k}" damping="{l}"/>'
        else:
            hinges = "".join(f'<joint name="{c["name"]}" type="{c["type"]}" axis="{vec(c["axis"])}" '
                             f'stiffness="{c["stiffness"]}" '
                             f'damping="{c["damping"]}" springref="{c["springref"]}"/>' for c in _coordinates(j))
        return (f'<body name="{name}" pos="{vec(pos)}">{hinges}'
                f'<inertial pos="{vec(np.negative(j["child_point"]))}" mass="{b["mass"]}" '
                f'fullinertia="{vec([inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]])}"/>'
                f"{inner}</body>")

    coordinates = [(j, c) for j in data["joints"] if j["variant"] != "ball" for c in _coordinates(j)]
    actuators = ""
    for _, c in coordinates:
        clamp = (f' forcelimited="true" forcerange="{c["lower"]} {c["upper"]}"'
                 if np.isfinite(c["upper"]) or np.isfinite(c["lower"]) else "")
        actuators += f'<position joint="{c["name"]}" kp="{c["kp"]}" kv="{c["kv"]}"{clamp}/>'
    xml = (f'<mujoco><compiler angle="radian"/><option gravity="{vec(data["gravity"])}" timestep="{timestep}" '
           f'integrator="RK4"/><worldbody>{"".join(body(c) for c in children["ground"])}</worldbody>'
           f"<actuator>{actuators}</actuator></mujoco>")
    model = mujoco.MjModel.from_xml_string(xml)
    state = mujoco.MjData(model)
    state.ctrl[:] = [c["target"] for _, c in coordinates]
    qpos0, qvel0 = model.qpos0.copy(), np.zeros(model.nv)  # a ball at its reference pose, at rest
    for j, c in coordinates:
        written = data["initial_state"].get(j["child"]) or {}
        joint = model.joint(c["name"])
        qpos0[joint.qposadr[0]], qvel0[joint.dofadr[0]] = (
            np.ravel(written.get(key, 0.0))[c["index"] if np.size(written.get(key, 0.0)) > 1 else 0]
            for key in ("q", "u"))
    return model, state, qpos0, qvel0


def mujoco_model(path):
    """MuJoCo's model of the MJCF or URDF file at ``path`` (a URDF's visual and collision
    elements left out: its meshes need not exist; geometry plays no part)."""
    text = Path(path).read_text()
    root = ElementTree.fromstring(text)
    if root.tag == "robot":
        for link in root.iter("link"):
            for element in [*link.findall("visual"), *link.findall("collision")]:
                link.remove(element)
        return mujoco.MjModel.from_xml_string(ElementTree.tostring(root, encoding="unicode"))
    return mujoco.MjModel.from_xml_path(str(path))


def _simulated(path, result, keyframe=None, initial=None, dt=1e-4):
    """(model, data) of MuJoCo simulating the file at ``path`` from the keyframe (or qpos0
    with ``initial``'s {body: {q, u}} added) with RK4 at ``dt`` [s], yielded at each sample
    time of ``result`` (after ``mj_forward`` and ``mj_rnePostConstraint``: ``cfrc_int``)."""
    model = mujoco_model(path)
    model.opt.integrator, model.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, dt
    data = mujoco.MjData(model)
    if keyframe is not None:
        mujoco.mj_resetDataKeyframe(model, data, model.key(keyframe).id)
    for body, state in (initial or {}).items():
        joint = model.joint(model.body(body).jntadr[0])
        data.qpos[joint.qposadr[0]] += state.get("q", 0.0)
        data.qvel[joint.dofadr[0]] += state.get("u", 0.0)
    for s, t in enumerate(result.time):
        if s:
            mujoco.mj_step(model, data, nstep=int(round((t - result.time[s - 1]) / dt)))
        mujoco.mj_forward(model, data)
        mujoco.mj_rnePostConstraint(model, data)
        yield model, data


def _carriers(model, config):
    """Each of ``config``'s bodies as MuJoCo's body ids: the body and those welded to it."""
    carrier = list(range(model.nbody))
    for b in range(1, model.nbody):
        if model.body_jntnum[b] == 0:
            carrier[b] = carrier[model.body_parentid[b]]
    names = [b["name"] for b in config.resolved["bodies"]]
    return [[c for c in range(model.nbody) if carrier[c] == model.body(n).id] for n in names]


def largest_distance(path, config, result, keyframe=None, initial=None, dt=1e-4):
    """The largest distance [m] between rbstab's centres of mass and MuJoCo's (each body with
    the bodies welded to it), at the samples of ``result``: MuJoCo simulating the file at
    ``path`` from the keyframe (or qpos0 with ``initial``'s q, u added) with RK4 at ``dt``."""
    worst, groups = 0.0, None
    for s, (model, data) in enumerate(_simulated(path, result, keyframe, initial, dt)):
        groups = groups or _carriers(model, config)
        for i, group in enumerate(groups):
            m = model.body_mass[group]
            centre = (m[:, None] * data.xipos[group]).sum(axis=0) / m.sum()
            worst = max(worst, float(np.abs(result.outputs["position"][s, i] - centre).max()))
    return worst


def interaction_forces(path, config, result, keyframe=None, initial=None, dt=1e-4):
    """((samples, bodies, 3) the force [N] (world frame) that each of ``config``'s bodies
    receives from its parent, MuJoCo's ``cfrc_int`` (its linear part); (samples, 3) the
    centre of pressure [m] of the first body's joint: the point of the plane through the
    origin perpendicular to gravity about which that joint's force and moment (``cfrc_int``'s
    torque, moved from the tree's centre of mass to the joint's anchor) have no moment along
    the plane) at the samples of ``result``, MuJoCo simulating the file as
    :func:`largest_distance` does."""
    forces, pressure, groups = [], [], None
    up = -np.asarray(config.resolved["gravity"], dtype=float)
    up /= np.linalg.norm(up)
    for model, data in _simulated(path, result, keyframe, initial, dt):
        groups = groups or _carriers(model, config)
        forces.append([data.cfrc_int[group[0], 3:].copy() for group in groups])
        root = groups[0][0]
        force, anchor = data.cfrc_int[root, 3:], data.xanchor[model.body_jntadr[root]]
        moment = data.cfrc_int[root, :3] + np.cross(data.subtree_com[model.body_rootid[root]] - anchor, force)
        pressure.append(anchor - (force * (anchor @ up) - np.cross(up, moment)) / (force @ up))
    return np.array(forces), np.array(pressure)


def eigenvalues_at(path, q, keyframe=None, step=1e-6):
    """The eigenvalues [1/s] of MuJoCo's continuous-time linearisation of the hinge model at
    ``path`` at rest at the joint angles ``q`` (nv,) [rad] from its reference pose (qpos =
    qpos0 + q), the controls the keyframe's (else 0): A = [[0, I], [d qacc/d qpos, d qacc/d
    qvel]] by central differences of ``mj_forward``'s qacc (steps ``step``)."""
    model = mujoco_model(path)
    data = mujoco.MjData(model)
    if keyframe is not None:
        data.ctrl[:] = model.key_ctrl[model.key(keyframe).id]
    n = model.nv
    at = model.qpos0 + np.asarray(q, dtype=float)

    def acceleration(qpos, qvel):
        data.qpos[:], data.qvel[:] = qpos, qvel
        mujoco.mj_forward(model, data)
        return data.qacc.copy()

    jac = np.zeros((2 * n, 2 * n))
    jac[:n, n:] = np.eye(n)
    for k in range(n):
        dq = np.zeros(n)
        dq[k] = step
        jac[n:, k] = (acceleration(at + dq, 0 * dq) - acceleration(at - dq, 0 * dq)) / (2 * step)
        jac[n:, n + k] = (acceleration(at, dq) - acceleration(at, -dq)) / (2 * step)
    return np.linalg.eigvals(jac), acceleration(at, np.zeros(n))
