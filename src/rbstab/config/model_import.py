"""An MJCF or URDF model -> an rbstab config (commented YAML text), through MuJoCo's compiler.

MuJoCo (the ``mujoco`` package, extra ``import``) compiles the file: MJCF as MuJoCo reads
it, URDF with its fixed joints fused and its geometry (``visual``, ``collision``) left out.
The compiled model is read in its reference pose (``qpos0``, where every hinge's q is 0):

- every body's frame is parallel to the model's world frame there and sits at its centre of
  mass; its inertia tensor [kg m^2] is written in those axes (MuJoCo's principal moments
  turned by the inertial frame's rotation); a body without a joint is welded to its
  parent: its mass and inertia join the parent's (about their common centre of mass), or
  the ground's when no joint lies between it and the world (left out);
- each ``hinge`` becomes a joint ``variant: hinge`` about its world axis (``xaxis``) at its
  world anchor (``xanchor``): ``parent_point`` and ``child_point`` are the anchor from the
  parent's and the child's centres of mass (from the world origin for the ground);
  q = qpos - qpos0 (a joint's ``ref`` is rbstab's q = 0); each ``slide`` a joint ``variant:
  slide`` along its world axis the same way (q [m], its gains [N/m], [N s/m], forces [N]); a
  body's two hinges through one point about axes that are not parallel become one joint
  ``variant: universal`` (the first hinge's q_1, then the second's q_2, their world axes in
  order), everything below per coordinate;
- its passive torque is the joint's ``stiffness``, ``damping`` and ``springref``
  (theta_ref = qpos_spring - qpos0);
- each ``ball`` becomes a joint ``variant: ball`` at its anchor (its quaternion, free of
  gimbal lock, the identity in the reference pose), its ``stiffness`` a passive spring on
  the rotation vector of its turn (MuJoCo's ball spring) and its ``damping`` a passive
  damper on Omega_j; its child starts at the keyframe's orientation and angular velocity
  (its Euler angles from the reference pose, body frame); its ``range`` (a cone of its
  turn's angle) a stop as a hinge's below (on the mean of its three dofs' inertias). A ball
  with an actuator is refused;
- its feedback is the ``position`` servo (any affine actuator on the joint: force = kp ctrl
  + b0 + b1 length + b2 velocity, length = gear qpos): k_r = -b1 gear^2, l_r = -b2 gear^2,
  theta_ref from the control (the keyframe's, else 0, within ``ctrlrange``), delivered
  between forcerange x gear (and the joint's ``actuatorfrcrange``); a ``motor`` with zero
  control gives no torque;
- its ``range`` becomes a stop (``range.k_r``, ``range.l_r``): MuJoCo's soft limit at full
  impedance as a spring and damper on the joint's effective inertia I = 1 / dof_invweight0
  (solref = (timeconst, dampratio): k = I / (timeconst dampratio)^2, l = 2 I / timeconst;
  solref < 0: k = -solref[0] I, l = -solref[1] I);
- gravity is ``option/gravity`` (zero where the model disables it); the initial state is a
  keyframe's q, u or the reference pose at rest.

What rbstab cannot represent is refused, one line each naming the model's element: a ball
with an actuator, free joints, two joints in one body that
are not a universal joint (two hinges through one point) or more,
tendons, equality constraints, muscles and actuators with activation dynamics, armature, dry
friction, gravity compensation, fluid forces, a constant actuator torque. Contacts are left
out with a note.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..kinematics import euler_angles_of
from .errors import ConfigError
from .yaml_io import read_text_limited

__all__ = ["ImportedModel", "import_model"]

#: Largest model file read [bytes] (a whole-body MJCF model is ~100 kB).
_MAX_MODEL_BYTES = 64 * 2**20
#: Column at which a written line's comment starts.
_COMMENT_COLUMN = 44


@dataclass
class ImportedModel:
    """A model's config: ``text`` (commented YAML that loads and runs as written),
    ``notes`` (one line each: a gain the model lacks written as zero, what was left out)."""

    name: str
    text: str
    notes: list[str] = field(default_factory=list)


def _number(x: float) -> str:
    x = float(x)
    if math.isinf(x):
        return ".inf" if x > 0 else "-.inf"
    return repr(float(f"{x:.15g}") + 0.0)  # 15 digits: 0.186, not 0.18599999999999994; -0.0 -> 0.0


def _vector(v, scale: float | None = None) -> str:
    """3 numbers (or a 3x3 matrix) on one line, entries below 1e-14 of ``scale`` (default:
    the largest entry) written as 0: the rounding of a rotation, not a value."""
    v = np.asarray(v, dtype=float)
    tiny = 1e-14 * (float(np.abs(v).max()) if scale is None else scale)
    v = np.where(np.abs(v) <= tiny, 0.0, v)
    if v.ndim == 2:
        return "[" + ", ".join(_vector(row, scale=0.0) for row in v) + "]"
    return "[" + ", ".join(_number(x) for x in v) + "]"


def _line(indent: int, text: str, comment: str = "") -> str:
    line = " " * indent + text
    return f"{line.ljust(_COMMENT_COLUMN - 1)} # {comment}" if comment else line


_NAME_RULE = re.compile(r"[^A-Za-z0-9_-]")


class _Names:
    """rbstab names (letters, digits, '_' and '-', starting with a letter or '_', unique)
    for the model's, which may be empty or hold other characters."""

    def __init__(self, reserved=()) -> None:
        self.used = set(reserved)

    def __call__(self, name: str, fallback: str) -> str:
        base = _NAME_RULE.sub("_", name) or fallback
        base = base if re.match(r"[A-Za-z_]", base) else "_" + base
        out, n = base[:60], 1
        while out in self.used:
            n += 1
            out = f"{base[:56]}_{n}"
        self.used.add(out)
        return out


def _compile(path: Path):
    """(mujoco module, model, format name, notes) of the file at ``path``; ConfigError in one
    line for a file that is not XML, not MJCF or URDF, or that MuJoCo's compiler refuses."""
    where = str(path)
    try:
        import mujoco  # optional: the 'import' extra
    except ImportError:
        raise ConfigError([f"model file {where}: importing a model needs MuJoCo's compiler, the 'mujoco' "
                           "package (pip install 'rbstab[import]')"]) from None
    text = read_text_limited(path, "model file", limit=_MAX_MODEL_BYTES)
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise ConfigError([f"model file {where}: not an XML file ({exc}); expected an MJCF (<mujoco>) or URDF "
                           "(<robot>) model"]) from None
    notes = []
    if root.tag == "robot":
        kind = "URDF"
        for link in root.iter("link"):
            for element in [*link.findall("visual"), *link.findall("collision")]:
                link.remove(element)
        notes.append(f"{where}: the URDF's geometry (visual, collision) is left out: rbstab has no contact model")
        compile_ = lambda: mujoco.MjModel.from_xml_string(ElementTree.tostring(root, encoding="unicode"))  # noqa: E731
    elif root.tag == "mujoco":
        kind = "MJCF"
        compile_ = lambda: mujoco.MjModel.from_xml_path(str(path))  # noqa: E731
    else:
        raise ConfigError([f"model file {where}: its root element is <{root.tag}>; expected <mujoco> (MJCF) or "
                           "<robot> (URDF)"])
    try:
        model = compile_()
    except Exception as exc:  # MuJoCo's compiler reports every problem as a ValueError-like error
        message = re.sub(r"^Error:\s*", "", " ".join(str(exc).split()))
        raise ConfigError([f"model file {where}: MuJoCo's compiler refused it: {message}"]) from None
    return mujoco, model, kind, notes


def _element(tag: str, obj, more: str = "") -> str:
    """How a message names a model's element: ``<joint name="knee">``, or its index where unnamed."""
    return f'<{tag} name="{obj.name}"{more}>' if obj.name else f"<{tag}{more}> #{obj.id}"


def _refusals(mujoco, model, where: str) -> list[str]:
    """One line per element of the compiled ``model`` rbstab cannot represent (the module
    docstring's list; the actuators: :func:`_servos`)."""
    errors: list[str] = []
    joint_kind = {int(mujoco.mjtJoint.mjJNT_FREE): "a free joint (a floating base)"}
    ball = int(mujoco.mjtJoint.mjJNT_BALL)
    for j in range(model.njnt):
        joint = model.joint(j)
        if int(model.jnt_type[j]) in joint_kind:
            errors.append(f"model file {where}: {_element('joint', joint)} is {joint_kind[int(model.jnt_type[j])]}; "
                          "rbstab imports hinge, slide and ball joints")
            continue
        dof = int(model.jnt_dofadr[j])
        for attribute, values, why in (("armature", model.dof_armature, "rotor inertia"),
                                       ("frictionloss", model.dof_frictionloss, "dry friction")):
            if np.any(values[dof:dof + (3 if int(model.jnt_type[j]) == ball else 1)] != 0.0):
                errors.append(f"model file {where}: {_element('joint', joint)} has {attribute}="
                              f"{float(values[dof]):g}; expected 0 ({why} is not modelled)")
    for b in range(1, model.nbody):
        if model.body_jntnum[b] > 1 and not _universal(mujoco, model, b):
            errors.append(f"model file {where}: {_element('body', model.body(b))} has {int(model.body_jntnum[b])} "
                          "joints; expected one, or two hinges about axes that are not parallel through one point (a "
                          "universal joint)")
        if model.body_gravcomp[b] != 0.0:
            errors.append(f"model file {where}: {_element('body', model.body(b))} has gravcomp="
                          f"{float(model.body_gravcomp[b]):g}; expected 0 (gravity compensation is not modelled)")
    if model.ntendon:
        errors.append(f"model file {where}: it has {model.ntendon} <tendon>s ({_element('tendon', model.tendon(0))}, "
                      "...); tendons are not modelled")
    if model.neq:
        errors.append(f"model file {where}: it has {model.neq} <equality> constraints (closed loops); rbstab's models "
                      "are trees")
    if model.opt.density or model.opt.viscosity:
        errors.append(f"model file {where}: <option density={model.opt.density:g} viscosity={model.opt.viscosity:g}>;"
                      " expected 0 (fluid forces are not modelled)")
    return errors


def _universal(mujoco, model, b: int) -> bool:
    """Whether MuJoCo body ``b`` has two hinges through one point about axes that are not
    parallel: rbstab's universal joint (the first hinge's q_1, then the second's q_2)."""
    first = int(model.body_jntadr[b])
    joints = [first, first + 1]
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
    return (int(model.body_jntnum[b]) == 2 and all(int(model.jnt_type[j]) == hinge for j in joints)
            and np.allclose(model.jnt_pos[first], model.jnt_pos[first + 1], rtol=0.0, atol=1e-12)
            and np.linalg.norm(np.cross(model.jnt_axis[first], model.jnt_axis[first + 1])) > 1e-6)


def _stop_gains(model, j: int, invweight: float, units: str = "kg m^2") -> tuple[float, float, str]:
    """(k [N m/rad], l [N m s/rad]; a slide's [N/m], [N s/m], in words) of joint ``j``'s limit
    as a stop: MuJoCo's soft limit at full impedance as a spring and damper on the effective
    inertia I [kg m^2; a slide's: kg] = 1 /
    ``invweight`` (solref = (timeconst, dampratio): k = I / (timeconst dampratio)^2, l = 2 I /
    timeconst; solref < 0: k = -solref[0] I, l = -solref[1] I)."""
    inertia = 1.0 / invweight
    timeconst, ratio = (float(x) for x in model.jnt_solref[j])
    k, l = ((inertia / (timeconst * ratio) ** 2, 2.0 * inertia / timeconst) if timeconst > 0
            else (-timeconst * inertia, -ratio * inertia))
    return k, l, f"solref ({timeconst:g}, {ratio:g}) on I {inertia:.6g} {units}"


def _ball(model, data, keyed, b: int, jname: str, body: str) -> tuple[list[str], str]:
    """(the joint's lines after its points, the initial-state line of its child ``body``) of
    the ball joint of MuJoCo body ``b``: ``variant: ball`` (its quaternion, free of gimbal
    lock) with no servo, its ``stiffness`` k and ``damping`` a passive spring k I on the
    rotation vector of its turn from the reference pose (MuJoCo's ball spring) and a damper
    on Omega_j (``dof_damping``, child frame), its child's Euler angles and angular velocity
    (body frame) at the keyframe (``keyed``, the data at it; ``data`` at the reference pose)
    or zero (``keyed`` None)."""
    lines = [_line(4, "variant: ball", "a ball: the quaternion of A_parent' A_child, identity in the reference pose"),
             _line(4, "k_r: [0.0, 0.0, 0.0]", "[N m/rad] no servo on a ball"),
             _line(4, "l_r: [0.0, 0.0, 0.0]", "[N m s/rad]")]
    j = int(model.body_jntadr[b])
    dof = int(model.jnt_dofadr[j])
    damping = np.array(model.dof_damping[dof:dof + 3], dtype=float)
    stiffness = float(model.jnt_stiffness[j])
    if np.any(damping) or stiffness:
        lines.append(_line(4, f"passive: {{k_r: {_vector(np.full(3, stiffness))}, l_r: {_vector(damping)}}}",
                           "[N m/rad, N m s/rad] stiffness on the rotation vector, damping on Omega_j (child frame)"))
    if model.jnt_limited[j]:  # a cone of its turn's angle: a stop, MuJoCo's soft limit as for a hinge
        k, l, why = _stop_gains(model, j, float(np.mean(model.dof_invweight0[dof:dof + 3])))
        lines.append(_line(4, f"range: {{lower: 0.0, upper: {_number(model.jnt_range[j, 1])}, k_r: {_number(k)}, "
                              f"l_r: {_number(l)}}}", f"[rad] a stop on the turn's angle (a cone): {why}"))
    if keyed is None:
        theta, omega = np.zeros(3), np.zeros(3)
    else:  # the body's turn from the reference pose, and its angular velocity in its own frame
        turn = keyed.xmat[b].reshape(3, 3) @ data.xmat[b].reshape(3, 3).T
        theta, omega = euler_angles_of(turn), turn.T @ keyed.cvel[b, :3]
    start = _line(2, f"{body}: {{theta: {_vector(theta, scale=1.0)}, omega: {_vector(omega, scale=1.0)}}}",
                  f"[rad, rad/s] {jname}: Euler angles, body frame")
    return lines, start


def _servos(mujoco, model, where: str, ctrl: np.ndarray, errors: list[str]) -> tuple[dict, dict]:
    """(joint id -> its feedback: ``source``, ``k_r`` [N m/rad], ``l_r`` [N m s/rad],
    ``theta_ref`` [rad] from q = 0, torque limits ``lower``, ``upper`` [N m], ``gear``,
    ``ctrl``; joint id -> the motors at zero control on it) of the model's actuators at the
    controls ``ctrl`` (nu,); what cannot be represented appended to ``errors``, one line each."""
    feedback: dict[int, dict] = {}
    motors: dict[int, list[str]] = {}
    for a in range(model.nu):
        actuator = model.actuator(a)
        name = _element("actuator", actuator)
        if int(model.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT):
            errors.append(f"model file {where}: {name} acts on a tendon, site or body; rbstab's actuators act on a "
                          "joint")
            continue
        if int(model.actuator_dyntype[a]) != int(mujoco.mjtDyn.mjDYN_NONE):
            errors.append(f"model file {where}: {name} has activation dynamics (a muscle, a filter or an "
                          "integrator); expected none")
            continue
        if int(model.actuator_gaintype[a]) != int(mujoco.mjtGain.mjGAIN_FIXED) or int(
                model.actuator_biastype[a]) not in (int(mujoco.mjtBias.mjBIAS_NONE), int(mujoco.mjtBias.mjBIAS_AFFINE)):
            errors.append(f"model file {where}: {name} is not an affine actuator (a muscle or a user gain); expected "
                          "a position or velocity servo or a motor")
            continue
        j = int(model.actuator_trnid[a, 0])
        if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_BALL):
            errors.append(f"model file {where}: {name} acts on the ball joint {_element('joint', model.joint(j))}; "
                          "rbstab imports actuators on hinge and slide joints")
            continue
        gear = float(model.actuator_gear[a, 0])
        u = float(ctrl[a])
        if model.actuator_ctrllimited[a]:
            u = min(max(u, float(model.actuator_ctrlrange[a, 0])), float(model.actuator_ctrlrange[a, 1]))
        kp = float(model.actuator_gainprm[a, 0])
        b0, b1, b2 = (float(x) for x in model.actuator_biasprm[a, :3])
        if int(model.actuator_biastype[a]) == int(mujoco.mjtBias.mjBIAS_NONE):
            b0 = b1 = b2 = 0.0
        k, l = -b1 * gear**2, -b2 * gear**2
        # torque = gear force = gear (kp u + b0 + b1 gear qpos0) - k q - l dq/dt
        bias = gear * (kp * u + b0 + b1 * gear * float(model.qpos0[model.jnt_qposadr[j]]))
        if k == 0.0 and l == 0.0:
            if bias != 0.0:
                errors.append(f"model file {where}: {name} gives the constant torque {bias:g} N m at its control "
                              f"{u:g}; a joint's torque is its feedback (a zero control, or a servo)")
            else:
                motors.setdefault(j, []).append(name)
            continue
        if k < 0.0 or l < 0.0:
            errors.append(f"model file {where}: {name} has stiffness {k:g} N m/rad and damping {l:g} N m s/rad "
                          "(-biasprm gear^2); expected both >= 0")
            continue
        if bias != 0.0 and k == 0.0:
            errors.append(f"model file {where}: {name} adds the constant torque {bias:g} N m to its damping; "
                          "expected a position servo or a zero control")
            continue
        if j in feedback:
            errors.append(f"model file {where}: {feedback[j]['source']} and {name} both act on joint "
                          f"{model.joint(j).name!r}; expected one servo per joint")
            continue
        lower, upper = -math.inf, math.inf
        if model.actuator_forcelimited[a]:
            lower, upper = sorted(gear * float(x) for x in model.actuator_forcerange[a])
        if model.jnt_actfrclimited[j]:
            lower = max(lower, float(model.jnt_actfrcrange[j, 0]))
            upper = min(upper, float(model.jnt_actfrcrange[j, 1]))
        if not lower < 0.0 < upper:
            errors.append(f"model file {where}: {name} delivers torques in [{lower:g}, {upper:g}] N m (forcerange x "
                          "gear); expected a range that holds 0")
            continue
        feedback[j] = {"source": name, "k_r": k, "l_r": l, "theta_ref": bias / k if k else 0.0,
                       "lower": lower, "upper": upper, "gear": gear, "ctrl": u}
    return feedback, motors


def _coordinate_joint(mujoco, model, data, b: int, jname: str, body: str, servo: tuple[dict, dict], key,
                      keyframe: str | None, where: str, notes: list[str]) -> tuple[str, list[str], str, bool]:
    """(its source element in words, the joint's lines after its points, the initial-state line
    of its child ``body``, whether a servo holds it) of MuJoCo body ``b``'s hinge, slide or
    universal joint (two hinges through one point): its variant and axes, the servo
    (``servo``: :func:`_servos`' feedback and motors), passive spring and damper, range as a
    stop and the keyframe's (``key``, its index, or None) q and u, in the kind's units; a
    motor's note appended to ``notes``. ConfigError for a keyframe's hinge angle outside
    (-pi, pi) of its reference."""
    feedback, motors = servo
    j = int(model.body_jntadr[b])
    lines: list[str] = []
    held = True
    js = list(range(j, j + int(model.body_jntnum[b])))  # one hinge or slide, or a universal joint's two
    universal = len(js) == 2
    slide = int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_SLIDE)
    units = {"q": "m", "u": "m/s", "k": "N/m", "l": "N s/m", "force": "N"} if slide else \
        {"q": "rad", "u": "rad/s", "k": "N m/rad", "l": "N m s/rad", "force": "N m"}
    qpos0 = [float(model.qpos0[model.jnt_qposadr[k]]) for k in js]
    source = " and ".join(_element("joint", model.joint(k), f' type="{"slide" if slide else "hinge"}"') for k in js)

    def numbers(values):  # a hinge's number, a universal joint's 2
        return f"[{', '.join(_number(v) for v in values)}]" if universal else _number(values[0])

    if universal:
        source += ": a universal joint"
        lines += [
            _line(4, "variant: universal", "q_1, q_2 = qpos - qpos0 [rad] of its two hinges, in order"),
            _line(4, f"axis: [{_vector(data.xaxis[js[0]])}, {_vector(data.xaxis[js[1]])}]",
                  "the hinges' axes, world frame"),
        ]
    else:
        lines += [
            _line(4, f"variant: {'slide' if slide else 'hinge'}",
                  f"q = qpos - qpos0 [{units['q']}]" + (f" (ref {qpos0[0]:g})" if qpos0[0] else "")),
            _line(4, f"axis: {_vector(data.xaxis[j])}", "the joint's axis, world frame"),
        ]
    servos = [feedback.get(k) for k in js]
    if any(servos):
        named = [servo for servo in servos if servo is not None]
        none = {"k_r": 0.0, "l_r": 0.0, "theta_ref": 0.0, "lower": -math.inf, "upper": math.inf}
        servos = [servo or none for servo in servos]
        lines += [
            _line(4, f"k_r: {numbers([v['k_r'] for v in servos])}",
                  f"[{units['k']}] {', '.join(v['source'] for v in named)}: kp gear^2"),
            _line(4, f"l_r: {numbers([v['l_r'] for v in servos])}", f"[{units['l']}] kv gear^2"),
            _line(4, f"theta_ref: {numbers([v['theta_ref'] for v in servos])}",
                  f"[{units['q']}] its target at control "
                  + ", ".join(f"{v['ctrl']:g}, gear {v['gear']:g}" for v in named))]
        if any(math.isfinite(v["lower"]) or math.isfinite(v["upper"]) for v in servos):
            lines.append(_line(4, f"saturation: {{torque_n: {numbers([v['upper'] for v in servos])}, "
                                         f"torque_n_lower: {numbers([v['lower'] for v in servos])}}}",
                                      f"[{units['force']}] forcerange x gear, actuatorfrcrange"))
    else:
        lines += [_line(4, f"k_r: {numbers([0.0] * len(js))}", f"[{units['k']}] no servo on this joint"),
                         _line(4, f"l_r: {numbers([0.0] * len(js))}", f"[{units['l']}]")]
        held = False
    for k in js:
        if k in motors:
            notes.append(f"{where}: {', '.join(motors[k])} on joint {model.joint(k).name or jname}: a motor at zero "
                         "control, no torque" + (f" (its limits [{model.jnt_actfrcrange[k, 0]:g}, "
                                                 f"{model.jnt_actfrcrange[k, 1]:g}] N m)"
                                                 if model.jnt_actfrclimited[k] else ""))
    stiffness = [float(model.jnt_stiffness[k]) for k in js]
    damping = [float(model.dof_damping[model.jnt_dofadr[k]]) for k in js]
    if any(stiffness) or any(damping):
        spring = [float(model.qpos_spring[model.jnt_qposadr[k]]) - q0 for k, q0 in zip(js, qpos0)]
        lines.append(_line(4, f"passive: {{k_r: {numbers(stiffness)}, l_r: {numbers(damping)}, "
                                     f"theta_ref: {numbers(spring)}}}",
                                  f"[{units['k']}, {units['l']}, {units['q']}] stiffness, damping, springref"))
    if any(model.jnt_limited[k] for k in js):
        stops = []
        for k, q0 in zip(js, qpos0):
            stiff, damp, why = _stop_gains(model, k, float(model.dof_invweight0[model.jnt_dofadr[k]]),
                                           "kg" if slide else "kg m^2")
            ends = ((float(x) - q0 for x in model.jnt_range[k]) if model.jnt_limited[k]
                    else (-math.inf, math.inf))
            stops.append((*ends, stiff, damp, why))
        lower, upper, stiff, damp, why = zip(*stops)
        lines.append(_line(4, f"range: {{lower: {numbers(lower)}, upper: {numbers(upper)}, "
                                     f"k_r: {numbers(stiff)}, l_r: {numbers(damp)}}}",
                                  f"[{units['q']}] a stop: {'; '.join(why)}"))
    q = [float(model.key_qpos[key, model.jnt_qposadr[k]]) - q0 if key is not None else 0.0
         for k, q0 in zip(js, qpos0)]
    u = [float(model.key_qvel[key, model.jnt_dofadr[k]]) if key is not None else 0.0 for k in js]
    for k, value in zip(js, q):
        if not slide and not -math.pi < value < math.pi:
            element = _element("joint", model.joint(k), ' type="hinge"')
            raise ConfigError([f"model file {where}: keyframe {keyframe!r} puts {element} at q = {value:g} rad "
                               "from its reference; expected a number in (-pi, pi)"])
    start = _line(2, f"{body}: {{q: {numbers(q)}, u: {numbers(u)}}}", f"[{units['q']}, {units['u']}] {jname}")
    return source, lines, start, held


def import_model(path: str | Path, keyframe: str | None = None) -> ImportedModel:
    """The rbstab config of the MJCF or URDF model at ``path`` (see the module docstring).

    Parameters
    ----------
    path : str or Path
        An MJCF (``<mujoco>``) or URDF (``<robot>``) file.
    keyframe : str, optional
        The name of the model's keyframe whose qpos, qvel and ctrl give the initial state and
        the servos' targets; default: the reference pose at rest, zero controls.

    Returns
    -------
    ImportedModel

    Raises
    ------
    ConfigError
        One line per problem, naming the file and the model's element: an unreadable file,
        one MuJoCo's compiler refuses, a keyframe that does not exist, what rbstab cannot
        represent (module docstring).
    """
    path = Path(path)
    mujoco, model, kind, notes = _compile(path)
    where = str(path)
    errors = _refusals(mujoco, model, where)

    # Keyframe.
    key = None
    if keyframe is not None:
        names = [model.key(k).name for k in range(model.nkey)]
        if keyframe not in names:
            errors.append(f"model file {where}: keyframe {keyframe!r} not found; its keyframes: "
                          + (", ".join(repr(n) for n in names) if names else "none"))
        else:
            key = names.index(keyframe)
    elif model.nkey:
        notes.append(f"{where}: initial state: the reference pose at rest (its keyframes: "
                     + ", ".join(repr(model.key(k).name) for k in range(model.nkey)) + "; --keyframe NAME)")
    ctrl = np.array(model.key_ctrl[key]) if key is not None else np.zeros(model.nu)

    feedback, motors = _servos(mujoco, model, where, ctrl, errors)
    if errors:
        raise ConfigError(errors)

    # The reference pose.
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    owner = list(range(model.nbody))  # the body that carries each body: itself or a welded ancestor
    for b in range(1, model.nbody):
        if model.body_jntnum[b] == 0:
            owner[b] = owner[int(model.body_parentid[b])]
    body_names = _Names(reserved=("ground",))
    joint_names = _Names()
    carried = [b for b in range(1, model.nbody) if owner[b] == b]
    name_of = {b: body_names(model.body(b).name, f"body{b}") for b in carried}
    grounded = [b for b in range(1, model.nbody) if owner[b] == 0]
    if grounded:
        notes.append(f"{where}: " + ", ".join(model.body(b).name or f"#{b}" for b in grounded)
                     + " without a joint to the world: part of the ground, left out")
    welded = {b: [c for c in range(1, model.nbody) if owner[c] == b and c != b] for b in carried}
    lines_bodies, com = [], {0: np.zeros(3)}
    for b in carried:
        parts = [b, *welded[b]]
        masses = np.array([float(model.body_mass[c]) for c in parts])
        mass = float(masses.sum())
        if mass <= 0.0:
            raise ConfigError([f"model file {where}: {_element('body', model.body(b))} has no mass; expected a "
                               "mass > 0 (an <inertial> element)"])
        centre = (masses[:, None] * data.xipos[parts]).sum(axis=0) / mass
        inertia = np.zeros((3, 3))
        for c, m in zip(parts, masses):
            frame = data.ximat[c].reshape(3, 3)
            d = data.xipos[c] - centre
            inertia += frame @ np.diag(model.body_inertia[c]) @ frame.T + m * (d @ d * np.eye(3) - np.outer(d, d))
        inertia = 0.5 * (inertia + inertia.T)
        com[b] = centre
        source = _element("body", model.body(b)) + (
            " with " + ", ".join(_element("body", model.body(c)) for c in welded[b]) + " welded to it"
            if welded[b] else "")
        diagonal = np.allclose(inertia, np.diag(np.diag(inertia)), rtol=0, atol=1e-14 * np.abs(inertia).max())
        lines_bodies += [_line(2, f"- name: {name_of[b]}", source),
                         _line(4, f"mass: {_number(mass)}", "[kg]"),
                         _line(4, f"inertia: {_vector(np.diag(inertia) if diagonal else inertia)}",
                               "[kg m^2] about the centre of mass, world axes")]
        if welded[b]:
            notes.append(f"{where}: " + ", ".join(_element("body", model.body(c)) for c in welded[b])
                         + f" without a joint: welded to {name_of[b]} (mass and inertia added)")

    lines_joints, initial, unheld = [], [], []
    keyed = None  # the keyframe's state, where a ball's child starts from its orientation there
    balls = [b for b in carried if int(model.jnt_type[int(model.body_jntadr[b])]) == int(mujoco.mjtJoint.mjJNT_BALL)]
    if key is not None and balls:
        keyed = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, keyed, key)
        mujoco.mj_forward(model, keyed)
    for b in carried:
        j = int(model.body_jntadr[b])
        joint = model.joint(j)
        jname = joint_names(joint.name, f"joint{j}")
        parent = owner[int(model.body_parentid[b])]
        anchor = np.array(data.xanchor[j])
        if b in balls:
            joint_lines, start = _ball(model, data, keyed, b, jname, name_of[b])
            source, held = _element("joint", joint, ' type="ball"'), False
        else:
            source, joint_lines, start, held = _coordinate_joint(mujoco, model, data, b, jname, name_of[b],
                                                                 (feedback, motors), key, keyframe, where, notes)
        lines_joints += [
            _line(2, f"- name: {jname}", source),
            _line(4, f"parent: {name_of[parent] if parent else 'ground'}"),
            _line(4, f"parent_point: {_vector(anchor - com[parent], scale=1.0)}",
                  "[m] the anchor, " + (f"from the centre of mass of {name_of[parent]}" if parent
                                        else "inertial frame")),
            _line(4, f"child: {name_of[b]}"),
            _line(4, f"child_point: {_vector(anchor - com[b], scale=1.0)}",
                  f"[m] the anchor, from the centre of mass of {name_of[b]}"),
            *joint_lines,
        ]
        initial.append(start)
        if not held:
            unheld.append(jname)
    if unheld:
        notes.append(f"{where}: no servo on {', '.join(unheld)}: their k_r and l_r are written as 0 (passive torques "
                     "and gravity only)")
    n_contacts = int(np.count_nonzero((model.geom_contype | model.geom_conaffinity) != 0)) if model.ngeom else 0
    if n_contacts and kind == "MJCF":
        notes.append(f"{where}: {n_contacts} geoms' contacts left out: rbstab has no contact model")

    gravity = np.zeros(3) if model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_GRAVITY) else model.opt.gravity
    step = float(model.opt.timestep)
    n_samples = int(round(5.0 / step)) + 1 if 5.0 / step <= 100_000 else 100_001
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", path.stem) or "model"
    if key is not None:
        header_key = f"keyframe {keyframe!r}"
    else:
        header_key = "the reference pose at rest"
    text = "\n".join([
        f"# {path.name}: imported from {kind} by `rbstab import` (MuJoCo's compiler).",
        "# Every body's frame is parallel to the model's world frame in its reference pose (qpos0, each",
        "# hinge's q = 0 there) at its centre of mass; points [m], inertias [kg m^2] in those axes.",
        f"# Initial state: {header_key}.",
        f"name: {name}",
        _line(0, f"gravity: {_vector(gravity, scale=1.0)}", "[m/s^2] <option gravity>"),
        "bodies:", *lines_bodies,
        "joints:", *lines_joints,
        "initial_state:", *initial,
        "simulation:",
        _line(2, "t_end: 5.0", "[s] choose"),
        _line(2, f"n_samples: {n_samples}", f"one sample each <option timestep> ({step:g} s)"),
        _line(2, "method: DOP853"),
        _line(2, "rtol: 1.0e-9"),
        _line(2, "atol: 1.0e-11"),
        "",
    ])
    return ImportedModel(name=name, text=text, notes=notes)
