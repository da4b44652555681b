"""A joint's torques beyond the paper's feedback: its reference posture Theta_ref
(``joints.<name>.theta_ref``: its spring acts on Theta_j - Theta_ref, v's spring term is
1/2 (Theta_j - Theta_ref)' K_r (Theta_j - Theta_ref), the rest state is where the springs
balance gravity) and its passive torque (``joints.<name>.passive``: ligaments, never
limited, beside the feedback its actuator limits). Checked against a closed-form balance,
MuJoCo's hinge springs (``stiffness``, ``damping``, ``springref``) and position servos
(``kp``, ``kv``, ``forcerange``), and v's own bookkeeping."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from rbstab.config import ConfigError, config_from_mapping
from rbstab.simulator import simulate
from rbstab.variants import chain as C
from rbstab.variants.paper import has_paper_form

ROD_INERTIA = [0.08343, 0.08343, 0.02]  # kg m^2; a rod 1 m long, its axis z


def _rods(n, k, l, reference, theta, gravity=-9.81, t_end=2.0, n_samples=21):
    """A chain config of ``n`` rods (1 kg, 1 m, each held at its top end, the next hanging
    from its bottom end) on ball joints with K_r = k I, L_r = l I and ``reference`` (n, 3)
    [rad], released at rest from the absolute Euler angles ``theta`` (n, 3)."""
    names = [f"rod{i}" for i in range(n)]
    return {
        "name": "rods", "gravity": [0.0, 0.0, gravity],
        "bodies": [{"name": b, "mass": 1.0, "inertia": ROD_INERTIA} for b in names],
        "joints": [{"name": f"joint{i}", "parent": "ground" if i == 0 else names[i - 1],
                    "parent_point": [0.0, 0.0, 0.0] if i == 0 else [0.0, 0.0, -0.5], "child": b,
                    "child_point": [0.0, 0.0, 0.5], "variant": "permanent", "k_r": [k] * 3, "l_r": [l] * 3,
                    "theta_ref": list(map(float, reference[i]))} for i, b in enumerate(names)],
        "initial_state": {b: {"theta": list(map(float, theta[i]))} for i, b in enumerate(names)},
        "simulation": {"t_end": t_end, "n_samples": n_samples, "method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    }


def test_a_hanging_rod_rests_where_its_spring_balances_gravity():
    """One rod, its reference posture about x: the rest state is the root of the planar
    balance k (theta - theta_ref) + m g l sin(theta) = 0 (l = 0.5 m to its centre of mass),
    found by scipy's brentq alone; v is zero there (h), and a damped run released from
    Theta = 0 settles on it."""
    k, theta_ref, m, g, l = 4.0, 1.1, 1.0, 9.81, 0.5
    config = config_from_mapping(_rods(1, k, 2.0, [[theta_ref, 0, 0]], [[0, 0, 0]], t_end=30.0, n_samples=301))
    balance = brentq(lambda th: k * (th - theta_ref) + m * g * l * math.sin(th), 0.0, theta_ref)
    assert 0.2 < balance < theta_ref - 0.2  # gravity pulls the rod well back from its reference
    compiled = C.compile_chain(config.chain)
    y, _ = C.rest_state(compiled)
    np.testing.assert_allclose(y[:3], [balance, 0.0, 0.0], atol=1e-9)
    assert C.lyapunov(compiled, y)[0] == pytest.approx(0.0, abs=1e-12)
    result = simulate(config)
    assert result.status == "success"
    np.testing.assert_allclose(result.outputs["joint_theta"][-1, 0], [balance, 0.0, 0.0], atol=1e-6)
    assert result.outputs["lyapunov"][-1] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("damping", [0.0, 0.3])
def test_planar_rods_with_reference_postures_move_as_mujocos_hinge_springs(damping):
    """Two rods swinging in the y-z plane on ball joints whose springs and dampers are
    isotropic and whose references turn about x: the motion stays planar, each joint a
    hinge about x with MuJoCo's passive torque -k (q - springref) - d dq/dt. Both centres of
    mass follow MuJoCo's (RK4 at 1e-4 s) to 1e-6 m; without damping v stays constant."""
    mujoco = pytest.importorskip("mujoco")
    k, reference, q0 = 3.0, (0.3, -0.4), (0.6, 0.6)
    config = config_from_mapping(_rods(2, k, damping, [[reference[0], 0, 0], [reference[1], 0, 0]],
                                       [[q0[0], 0, 0], [q0[0] + q0[1], 0, 0]]))
    result = simulate(config)
    assert result.status == "success"
    out = result.outputs
    if damping == 0.0:
        assert np.ptp(out["lyapunov"]) < 1e-8 * np.abs(out["lyapunov_rotational"]).max()
    else:
        assert np.all(np.diff(out["lyapunov"]) <= 1e-10)
    hinge = f'type="hinge" axis="1 0 0" stiffness="{k}" damping="{damping}"'
    xml = f"""<mujoco><compiler angle="radian"/><option gravity="0 0 -9.81" timestep="1e-4" integrator="RK4"/>
      <worldbody><body name="rod0" pos="0 0 0"><joint {hinge} springref="{reference[0]}"/>
        <inertial pos="0 0 -0.5" mass="1" diaginertia="{' '.join(map(str, ROD_INERTIA))}"/>
        <body name="rod1" pos="0 0 -1"><joint {hinge} springref="{reference[1]}"/>
          <inertial pos="0 0 -0.5" mass="1" diaginertia="{' '.join(map(str, ROD_INERTIA))}"/>
        </body></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[:] = q0
    mujoco.mj_forward(model, data)
    for s, t in enumerate(result.time):
        if s:
            mujoco.mj_step(model, data, nstep=int(round((t - result.time[s - 1]) / 1e-4)))
        np.testing.assert_allclose(out["position"][s], data.xipos[1:3], atol=1e-6, err_msg=f"t = {t}")
    assert np.abs(out["joint_theta"][:, :, 1:]).max() < 1e-9  # planar


def test_without_gravity_a_damped_joint_settles_at_its_reference_and_v_never_rises():
    """No gravity: the reference posture is the rest state (h = 0); released from Theta = 0
    a damped joint turns to Theta_j = Theta_ref about all three axes, v falling to 0."""
    reference = [0.4, -0.3, 0.5]
    config = config_from_mapping(_rods(1, 5.0, 1.5, [reference], [[0, 0, 0]], gravity=0.0, t_end=40.0,
                                       n_samples=401))
    assert C.compile_chain(config.chain).offset == 0.0
    result = simulate(config)
    out = result.outputs
    np.testing.assert_allclose(out["joint_theta"][-1, 0], reference, atol=1e-6)
    assert out["lyapunov"][0] == pytest.approx(0.5 * 5.0 * np.dot(reference, reference), rel=1e-12)
    assert np.all(np.diff(out["lyapunov"]) <= 1e-12) and out["lyapunov"][-1] < 1e-10


def test_a_reference_posture_takes_a_one_body_tree_off_the_papers_form():
    """One body held at its own point is the paper's one body only with its spring relaxed
    at Theta = 0; a reference written as zeros keeps it."""
    data = _rods(1, 4.0, 1.0, [[0.2, 0.0, 0.0]], [[0, 0, 0]])
    data["joints"][0]["parent_point"] = data["joints"][0]["child_point"]
    assert not has_paper_form(config_from_mapping(data).chain)
    assert not C.compile_chain(config_from_mapping(data).chain).one_body
    data["joints"][0]["theta_ref"] = [0.0, 0.0, 0.0]
    assert has_paper_form(config_from_mapping(data).chain)


@pytest.mark.parametrize("value, expected", [
    ([0.0, 1.6, 0.0], "theta_2 in (-pi/2 + gimbal_margin"),
    ([0.0, -1.5705, 0.0], "theta_2 in (-pi/2 + gimbal_margin"),
    ([0.0, 0.2], "3 numbers"),
    ("up", "3 numbers"),
])
def test_a_reference_posture_out_of_the_euler_angles_domain_is_refused_naming_its_key(value, expected):
    data = _rods(2, 4.0, 1.0, [[0, 0, 0], [0, 0, 0]], [[0, 0, 0], [0, 0, 0]])
    data["joints"][1]["theta_ref"] = value
    with pytest.raises(ConfigError) as raised:
        config_from_mapping(data)
    message = str(raised.value)
    assert "joints.1.theta_ref" in message or "joints.joint1.theta_ref" in message
    assert expected in message


def test_the_paper_spelling_has_no_reference_posture():
    """``controller.theta_ref`` is no key: the one-body spelling is the paper's feedback."""
    from rbstab.config import load_config

    data = copy.deepcopy(load_config("configs/paper/case1_permanent.yaml").resolved)
    data["controller"]["theta_ref"] = [0.1, 0.0, 0.0]
    with pytest.raises(ConfigError, match="controller.theta_ref"):
        config_from_mapping(data)


def _planar_mujoco(mujoco, passive, servo, ranges, dt=1e-4):
    """MuJoCo's two rods on hinges about x (radians): each joint's ``passive`` (stiffness,
    damping, springref) and a position servo ``servo`` (kp, kv, target) whose force is
    clamped to its ``ranges`` entry [lower, upper] N m."""
    joints, actuators = "", ""
    for i, ((k, d, ref), (kp, kv, _), (lower, upper)) in enumerate(zip(passive, servo, ranges)):
        joints += f'<joint name="j{i}" type="hinge" axis="1 0 0" stiffness="{k}" damping="{d}" springref="{ref}"/>|'
        actuators += (f'<position joint="j{i}" kp="{kp}" kv="{kv}" forcelimited="true" '
                      f'forcerange="{lower} {upper}"/>')
    first, second = joints.split("|")[:2]
    inertia = " ".join(map(str, ROD_INERTIA))
    xml = f"""<mujoco><compiler angle="radian"/><option gravity="0 0 -9.81" timestep="{dt}" integrator="RK4"/>
      <worldbody><body name="rod0" pos="0 0 0">{first}
        <inertial pos="0 0 -0.5" mass="1" diaginertia="{inertia}"/>
        <body name="rod1" pos="0 0 -1">{second}<inertial pos="0 0 -0.5" mass="1" diaginertia="{inertia}"/>
        </body></body></worldbody><actuator>{actuators}</actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.ctrl[:] = [target for _, _, target in servo]
    return model, data


@pytest.mark.parametrize("ranges", [[(-1.5, 1.5), (-1.5, 1.5)], [(-0.8, 2.0), (-2.5, 1.0)]])
def test_passive_torques_and_saturating_servos_move_as_mujocos(ranges):
    """Two rods in a plane, each joint a ligament (a passive spring and damper about its own
    rest angle, never limited) and a muscle (a feedback toward another reference, clipped
    to [lower, upper], which it reaches; symmetric or stronger one way): both centres of
    mass follow MuJoCo's hinges with ``stiffness``, ``damping``, ``springref`` and a
    ``position`` servo with ``kv`` and ``forcerange`` to 1e-6 m. v's analytic rate, with
    the clipped feedback's deficit power (which may be positive: v may rise), is the
    derivative of its 1 ms samples."""
    mujoco = pytest.importorskip("mujoco")
    passive, servo = [(2.0, 0.2, 0.4), (1.5, 0.1, -0.3)], [(8.0, 0.5, -0.2), (6.0, 0.4, 0.5)]
    data = _rods(2, 0.0, 0.0, [[0, 0, 0], [0, 0, 0]], [[0.9, 0, 0], [0.9 - 0.8, 0, 0]], n_samples=2001)
    for joint, (k, d, ref), (kp, kv, target), (lower, upper) in zip(data["joints"], passive, servo, ranges):
        saturation = {"torque_n": upper} if lower == -upper else {"torque_n": upper, "torque_n_lower": lower}
        joint.update(k_r=[kp] * 3, l_r=[kv] * 3, theta_ref=[target, 0.0, 0.0], saturation=saturation,
                     passive={"k_r": [k] * 3, "l_r": [d] * 3, "theta_ref": [ref, 0, 0]})
    config = config_from_mapping(data)
    result = simulate(config)
    assert result.status == "success"
    out = result.outputs
    assert out["torque_n_saturated"][:, :, 0].any()  # the muscles reach their limits
    assert result.summary["lyapunov_rate_check"] == "pass"
    model, state = _planar_mujoco(mujoco, passive, servo, ranges)
    state.qpos[:] = [0.9, -0.8]
    mujoco.mj_forward(model, state)
    for s, t in enumerate(result.time):
        if s:
            mujoco.mj_step(model, state, nstep=int(round((t - result.time[s - 1]) / 1e-4)))
        np.testing.assert_allclose(out["position"][s], state.xipos[1:3], atol=1e-6, err_msg=f"t = {t}")


def test_a_passive_torque_is_the_feedback_it_equals_where_no_limit_acts():
    """Without limits a passive spring and damper equals the same gains and reference
    written as the joint's feedback: the same motion, v and dv/dt (to rounding)."""
    base = _rods(2, 0.0, 0.0, [[0, 0, 0], [0, 0, 0]], [[0.5, 0.2, 0], [0.1, -0.3, 0.2]], n_samples=101)
    gains = [([30, 20, 10], [2, 1, 0.5], [0.1, -0.2, 0.3]), ([15, 25, 5], [1, 2, 0.3], [-0.3, 0.1, 0.0])]
    feedback, passive = copy.deepcopy(base), copy.deepcopy(base)
    for a, b, (k, l, ref) in zip(feedback["joints"], passive["joints"], gains):
        a.update(k_r=k, l_r=l, theta_ref=ref)
        b.update(passive={"k_r": k, "l_r": l, "theta_ref": ref})
    one, other = simulate(config_from_mapping(feedback)), simulate(config_from_mapping(passive))
    for key in ("position", "omega", "joint_theta", "torque_n", "lyapunov", "lyapunov_rate"):
        scale = max(1.0, float(np.abs(one.outputs[key]).max()))
        np.testing.assert_allclose(other.outputs[key], one.outputs[key], rtol=0, atol=1e-9 * scale, err_msg=key)


def test_a_passive_torque_takes_a_one_body_tree_off_the_papers_form():
    data = _rods(1, 4.0, 1.0, [[0.0, 0.0, 0.0]], [[0.2, 0, 0]])
    data["joints"][0]["parent_point"] = data["joints"][0]["child_point"]
    assert has_paper_form(config_from_mapping(data).chain)
    data["joints"][0]["passive"] = {"k_r": [1.0, 1.0, 1.0]}
    config = config_from_mapping(data)
    assert not has_paper_form(config.chain) and not C.compile_chain(config.chain).one_body


def test_a_passive_torques_keys_have_the_units_of_the_feedbacks():
    from rbstab.layout import parameter_attributes

    for name in ("k_r", "l_r", "theta_ref"):
        mine = parameter_attributes(f"joints.hip.passive.{name}.0")
        theirs = parameter_attributes(f"joints.hip.{name}.0")
        assert mine["units"] == theirs["units"] and "(joint hip, passive)" in mine["long_name"]


def test_asymmetric_torque_limits_take_a_one_body_tree_off_the_papers_form_and_are_checked():
    """Lower limits of N of their own (torque_n_lower) are a tree's: one body held at its
    own point with them runs on the tree's kernels, with lower = -torque_n it is the
    paper's one body; a lower limit >= 0 is refused naming its key."""
    data = _rods(1, 4.0, 1.0, [[0.0, 0.0, 0.0]], [[0.2, 0, 0]])
    joint = data["joints"][0]
    joint["parent_point"] = joint["child_point"]
    joint["saturation"] = {"torque_n": [2.0, 2.0, 2.0], "torque_n_lower": [-2.0, -2.0, -2.0]}
    assert has_paper_form(config_from_mapping(data).chain)
    joint["saturation"]["torque_n_lower"] = [-1.0, -2.0, -2.0]
    config = config_from_mapping(data)
    assert not has_paper_form(config.chain) and not C.compile_chain(config.chain).one_body
    np.testing.assert_array_equal(C.compile_chain(config.chain).params["torque_floor"][0], [-1.0, -2.0, -2.0])
    joint["saturation"]["torque_n_lower"] = [-1.0, 0.0, -2.0]
    with pytest.raises(ConfigError, match=r"joints\.0\.saturation\.torque_n_lower|joints\.joint0\.saturation"):
        config_from_mapping(data)


def test_an_analysis_names_the_limit_each_actuated_torque_meets_at_rest():
    """At the rest state the feedback's command (the passive torque left out: no actuator
    delivers it) is compared with each limit: an axis past its upper limit and one below its
    own lower limit are named with their signs."""
    from rbstab.analysis import analyze

    data = _rods(1, 20.0, 2.0, [[0.8, -0.3, 0.2]], [[0, 0, 0]])
    data["joints"][0].update(saturation={"torque_n": [3.0, 30.0, 3.0], "torque_n_lower": [-30.0, -2.0, -30.0]},
                             passive={"k_r": [5.0, 5.0, 5.0], "l_r": [0.5, 0.5, 0.5], "theta_ref": [-0.2, 0.0, 0.0]})
    found = analyze(config_from_mapping(data), certificate=False, simulate=False)
    note = next(n for n in found.notes if "saturate" in n)
    assert "torque_n_1 of joint 'joint0' = " in note and ">= its upper limit 3 N m" in note
    assert "torque_n_2 of joint 'joint0' = -" in note and "<= its lower limit -2 N m" in note
    assert "torque_n_3" not in note
