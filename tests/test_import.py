"""``rbstab import`` (rbstab.config.model_import): MJCF and URDF models through MuJoCo's
compiler become configs that run as written. Checked against MuJoCo simulating the same
file (RK4 at 1e-4 s): every body's centre of mass to 1e-6 m; the refusals in one line
naming the model's element, nothing written."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from rbstab.analysis import analyze
from rbstab.config import config_from_mapping
from rbstab.config.model_import import import_model
from rbstab.config.yaml_io import parse_yaml
from rbstab.layout import summary_stride
from rbstab.simulator import simulate
from rbstab_cli.main import cli

mujoco = pytest.importorskip("mujoco")
from reference_mujoco import eigenvalues_at, interaction_forces, largest_distance, mujoco_model  # noqa: E402

MODELS = Path(__file__).resolve().parents[1] / "configs" / "examples" / "models"

#: Welded bodies, rotated body and inertial frames, a joint's ref and springref, oblique axes,
#: a servo with a gear and a forcerange, a motor at zero control, gravity off the vertical.
OBLIQUE = """<mujoco model="oblique">
  <compiler angle="radian"/>
  <option gravity="0.3 -0.2 -9.81" timestep="0.002"/>
  <worldbody>
    <body name="base" pos="0.1 0.2 0.3" quat="0.9 0.1 0.3 -0.2">
      <geom type="box" size="0.1 0.1 0.1"/>
      <body name="a" pos="0 0 0.1" euler="0.3 -0.2 0.5">
        <joint name="ja" type="hinge" axis="1 0.3 -0.2" pos="0.02 0 0.05" ref="0.2" stiffness="3"
               springref="0.5" damping="0.1" range="-1.5 2.5" limited="true"/>
        <inertial pos="0.01 0.02 -0.3" quat="0.8 0.2 -0.1 0.4" mass="1.2" diaginertia="0.08 0.07 0.02"/>
        <body name="a_tip" pos="0 0.05 -0.6" euler="0.1 0.2 0.3">
          <inertial pos="0.03 0 0" mass="0.3" diaginertia="0.003 0.002 0.001"/>
        </body>
        <body name="b" pos="0.05 0 -0.6" euler="-0.4 0.1 0.2">
          <joint name="jb" type="hinge" axis="0.2 1 0.5" damping="0.05"/>
          <inertial pos="0 0.02 -0.25" mass="0.9" fullinertia="0.05 0.045 0.02 0.001 -0.002 0.0005"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="servo" joint="jb" kp="4" kv="0.3" gear="2" forcelimited="true" forcerange="-0.5 1.5"/>
    <motor name="drive" joint="ja"/>
  </actuator>
  <keyframe><key name="start" qpos="0.7 -0.4" qvel="0.3 -0.5" ctrl="0.3 0"/></keyframe>
</mujoco>
"""


def _reactions_are_mujocos(path, config, result, **start):
    """Every joint's reaction Lambda_j [N] at every sample is the force MuJoCo's body receives
    from its parent (``cfrc_int``'s linear part) simulating the same file, to 1e-6 of the
    largest, and the first joint's centre of pressure is the one of MuJoCo's force and moment
    there to 1e-6 m; returns the largest force."""
    theirs, pressure = interaction_forces(path, config, result, **start)
    scale = float(np.abs(theirs).max())
    np.testing.assert_allclose(result.outputs["constraint_force"], theirs, rtol=0, atol=1e-6 * scale)
    np.testing.assert_allclose(result.outputs["centre_of_pressure"][:, 0], pressure, rtol=0, atol=1e-6)
    assert np.all(np.isnan(result.outputs["centre_of_pressure"][:, 1:]))  # joints off the ground: none
    # one joint to the ground: the net centre of pressure is its own, its summary figure MuJoCo's largest
    # distance from the first, at the samples a thinned store keeps
    np.testing.assert_allclose(result.outputs["net_centre_of_pressure"], pressure, rtol=0, atol=1e-6)
    excursion = np.linalg.norm(pressure[:: summary_stride(len(result.time))] - pressure[0], axis=1).max()
    assert result.summary["cop_excursion"] == pytest.approx(excursion, abs=2e-6, nan_ok=True)
    return scale


def _imported(path, keyframe=None, t_end=2.0, n_samples=201, initial=None):
    """The config ``rbstab import`` writes for ``path``, run for ``t_end`` s with tight
    tolerances; ``initial``: {body: {q, u}} written over its initial state."""
    imported = import_model(path, keyframe=keyframe)
    data = parse_yaml(imported.text)
    data["simulation"].update(t_end=t_end, n_samples=n_samples, rtol=1e-11, atol=1e-12)
    for body, state in (initial or {}).items():
        data["initial_state"][body].update(state)
    return imported, config_from_mapping(data)


def test_the_shipped_stance_is_what_import_writes_and_moves_as_mujoco():
    """configs/examples/stance_imported.yaml is what ``rbstab import`` writes for
    configs/examples/models/stance.xml at its keyframe ``lean``; run, it follows MuJoCo's
    simulation of the XML (servos, the knee's springs) to
    1e-6 m while the knee stays inside its range (where MuJoCo's limit and rbstab's stop
    both act nowhere)."""
    path = MODELS / "stance.xml"
    shipped = (MODELS.parent / "stance_imported.yaml").read_text()
    imported, config = _imported(path, keyframe="lean", n_samples=2001)
    assert imported.text == shipped
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    knee = result.outputs["joint_theta"][:, 1, 0]
    assert -2.4 < knee.min() and knee.max() < 0.05
    assert largest_distance(path, config, result, keyframe="lean") < 1e-6
    weight = 9.81 * sum(b["mass"] for b in config.resolved["bodies"])
    assert _reactions_are_mujocos(path, config, result, keyframe="lean") > 0.9 * weight


def test_rotated_frames_welded_bodies_refs_and_gears_move_as_mujoco(tmp_path):
    """Body and inertial frames turned every way, a body welded to its parent (its mass and
    inertia joined) and one welded to the world (left out), a joint's ``ref`` and
    ``springref``, oblique axes, a servo with gear 2, a forcerange and a keyframe's control,
    a motor at zero control, oblique gravity: every centre of mass as MuJoCo's to 1e-6 m."""
    path = tmp_path / "oblique.xml"
    path.write_text(OBLIQUE)
    imported, config = _imported(path, keyframe="start")
    assert [b["name"] for b in config.resolved["bodies"]] == ["a", "b"]
    assert any("a_tip" in n and "welded to a" in n for n in imported.notes)
    assert any("base" in n and "part of the ground" in n for n in imported.notes)
    assert any("drive" in n and "zero control" in n for n in imported.notes)
    servo = config.resolved["joints"][1]
    assert servo["k_r"] == pytest.approx(16.0) and servo["l_r"] == pytest.approx(1.2)
    assert servo["theta_ref"] == pytest.approx(0.15)  # ctrl 0.3 over gear 2
    assert servo["saturation"]["torque_n"] == pytest.approx(3.0)
    assert servo["saturation"]["torque_n_lower"] == pytest.approx(-1.0)
    result = simulate(config)
    assert result.status == "success"
    assert result.outputs["torque_n_saturated"][:, 1].any()  # the servo at its forcerange
    theta = result.outputs["joint_theta"][:, 0] @ np.asarray(config.resolved["joints"][0]["axis"])
    assert -1.5 - 0.2 < theta.min() and theta.max() < 2.5 - 0.2  # inside the range: the stop idle
    assert largest_distance(path, config, result, keyframe="start") < 1e-6
    _reactions_are_mujocos(path, config, result, keyframe="start")


def test_a_urdf_arm_with_a_fixed_hand_moves_as_mujoco():
    """configs/examples/models/arm.urdf (its hand fused to the forearm by its fixed joint, a
    meshed visual left out, no springs: k_r written as 0 and named) swings from a raised
    pose under gravity and damping as MuJoCo's model of the same URDF, to 1e-6 m."""
    path = MODELS / "arm.urdf"
    start = {"upper_arm": {"q": 0.5, "u": 0.0}, "forearm": {"q": -1.0, "u": 1.0}}
    imported, config = _imported(path, initial=start)
    assert any("no servo on shoulder, elbow" in n for n in imported.notes)
    assert config.resolved["bodies"][1]["mass"] == pytest.approx(1.12 + 0.42)
    result = simulate(config)
    assert result.status == "success"
    elbow = result.outputs["joint_theta"][:, 1, 1]
    assert -2.6 < elbow.min() and elbow.max() < 0.1  # inside the range: MuJoCo's limit and the stop idle
    assert largest_distance(path, config, result, initial=start) < 1e-6
    _reactions_are_mujocos(path, config, result, initial=start)


@pytest.mark.parametrize("spring", ["", ' stiffness="3"', ' range="0 2.5" limited="true"'])
def test_the_shipped_ball_arm_is_what_import_writes_and_moves_as_mujoco(tmp_path, spring):
    """configs/examples/arm_imported.yaml is what ``rbstab import`` writes for
    configs/examples/models/arm.xml at its keyframe ``swing`` (the shoulder a ball with a
    damper, turned and turning about all three axes; the elbow a hinge with ligaments and a
    servo); run, it follows MuJoCo's simulation of the XML to 1e-6 m and its reactions to
    1e-6 of the largest, the elbow inside its range; so does the arm with a spring on its
    shoulder (MuJoCo's ball stiffness: rbstab's passive k I on the rotation vector) and with
    a cone on it (a stop, idle inside)."""
    path = MODELS / "arm.xml"
    if spring:
        path = tmp_path / "arm.xml"
        path.write_text((MODELS / "arm.xml").read_text().replace('damping="0.5"', f'damping="0.5"{spring}', 1))
    imported, config = _imported(path, keyframe="swing")
    if not spring:
        assert imported.text == (MODELS.parent / "arm_imported.yaml").read_text()
    assert not any("gimbal lock" in n for n in imported.notes)
    shoulder = config.resolved["joints"][0]
    assert shoulder["variant"] == "ball"
    assert shoulder["passive"]["k_r"] == ([3.0] * 3 if "stiffness" in spring else [0.0] * 3)
    assert ("range" in shoulder) == ("range" in spring)
    result = simulate(config)
    assert result.status == "success"
    theta = result.outputs["joint_theta"]
    assert np.ptp(theta[:, 0], axis=0).min() > 0.05  # the shoulder turns about every axis
    assert -0.05 < theta[:, 1, 0].min() and theta[:, 1, 0].max() < 2.6  # MuJoCo's limit and the stop idle
    assert largest_distance(path, config, result, keyframe="swing") < 1e-6
    _reactions_are_mujocos(path, config, result, keyframe="swing")


@pytest.mark.parametrize("model, keyframe", [("stance.xml", "lean"), ("arm.urdf", None), ("oblique", "start")])
def test_imported_models_have_mujocos_rest_state_and_eigenvalues(tmp_path, model, keyframe):
    """``rbstab analyze`` of an imported hinge tree: its rest state (springs and servos
    balancing gravity) is MuJoCo's (qacc there below 1e-8 rad/s^2) and its eigenvalues,
    linearised in the hinges' q and u, are those of MuJoCo's dynamics linearised by central
    differences at that state, to 1e-4 relative."""
    path = MODELS / model
    if model == "oblique":
        path = tmp_path / "oblique.xml"
        path.write_text(OBLIQUE)
    _, config = _imported(path, keyframe=keyframe)
    analysis = analyze(config, certificate=False, simulate=False)
    coordinates = analysis.layout.state_names()
    q = [analysis.linearisation.equilibrium[k] for k, name in enumerate(coordinates) if name.endswith(".q")]
    assert len(q) == len(coordinates) // 2 and analysis.linearisation.is_rest_point
    theirs, acceleration = eigenvalues_at(path, q, keyframe=keyframe)
    assert np.abs(acceleration).max() < 1e-8
    ours = analysis.linearisation.eigenvalues
    assert len(ours) == len(theirs)
    for s in theirs:  # each of MuJoCo's eigenvalues is one of rbstab's
        assert np.min(np.abs(ours - s)) <= 1e-4 * abs(s), (s, ours)


#: A body on two hinges through one point (a universal joint: a wrist), one with a spring,
#: a springref and a range, the other with a saturating servo, below an arm on a hinge.
WRIST = """<mujoco model="wrist">
  <compiler angle="radian"/>
  <option gravity="0 0 -9.81" timestep="0.002"/>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0" damping="0.1" stiffness="2"/>
      <inertial pos="0 0 -0.3" mass="1.5" diaginertia="0.05 0.05 0.01"/>
      <body name="hand" pos="0 0.02 -0.6" euler="0.2 0 0.1">
        <joint name="wrist_x" type="hinge" axis="1 0 0" pos="0 0 0.05" stiffness="3" springref="0.2" damping="0.05"
               range="-1.2 1.2" limited="true"/>
        <joint name="wrist_y" type="hinge" axis="0.1 1 0.3" pos="0 0 0.05" damping="0.08"/>
        <inertial pos="0.01 0 -0.15" quat="0.9 0.1 0 0.2" mass="0.5" diaginertia="0.01 0.008 0.003"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="flex" joint="wrist_y" kp="5" kv="0.4" forcelimited="true" forcerange="-0.6 1.0"/>
  </actuator>
  <keyframe><key name="start" qpos="0.4 0.3 -0.5" qvel="0.2 0.5 -0.3" ctrl="0.2"/></keyframe>
</mujoco>
"""


def test_a_body_on_two_hinges_through_one_point_imports_as_a_universal_joint(tmp_path):
    """MJCF's two hinges in one body through one point are rbstab's universal joint: its
    axes in order, its springs, range and servo per coordinate; run, every centre of mass
    follows MuJoCo's to 1e-6 m and every reaction its ``cfrc_int``, and ``rbstab analyze``'s
    rest state and eigenvalues (in q_1, q_2 of the wrist) are MuJoCo's to 1e-4 relative."""
    path = tmp_path / "wrist.xml"
    path.write_text(WRIST)
    imported, config = _imported(path, keyframe="start", n_samples=2001)
    wrist = config.resolved["joints"][1]
    assert wrist["variant"] == "universal" and wrist["name"] == "wrist_x"
    assert wrist["passive"]["k_r"] == [3.0, 0.0] and wrist["k_r"] == [0.0, pytest.approx(5.0)]
    assert wrist["range"]["upper"] == [1.2, math.inf]
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    assert result.outputs["torque_n_saturated"][:, 1, 1].any()  # the servo at its forcerange
    assert np.abs(result.outputs["joint_theta"][:, 1, 0]).max() < 1.2  # inside the range: the stop idle
    assert largest_distance(path, config, result, keyframe="start") < 1e-6
    _reactions_are_mujocos(path, config, result, keyframe="start")
    analysis = analyze(config, certificate=False, simulate=False)
    names = analysis.layout.state_names()
    assert names == ["arm.q", "arm.u", "hand.q_1", "hand.q_2", "hand.u_1", "hand.u_2"]
    q = analysis.linearisation.equilibrium[[0, 2, 3]]
    theirs, acceleration = eigenvalues_at(path, q, keyframe="start")
    assert np.abs(acceleration).max() < 1e-7  # the rest search's 1e-11 N m on the hand's ~0.005 kg m^2
    ours = analysis.linearisation.eigenvalues
    assert len(ours) == len(theirs)
    for s in theirs:
        assert np.min(np.abs(ours - s)) <= 1e-4 * abs(s), (s, ours)


def test_the_shipped_cart_pole_on_a_slide_is_what_import_writes_and_moves_as_mujoco():
    """configs/examples/cart_pole_imported.yaml is what ``rbstab import`` writes for
    configs/examples/models/cart_pole.xml at its keyframe: MJCF's slide is rbstab's slide (q
    [m] from its ref, its servo's kp, kv, target and forcerange, its spring, damper and range
    along the axis); run, every centre of mass follows MuJoCo's to 1e-6 m and every reaction
    its ``cfrc_int``; ``rbstab analyze``'s rest state and eigenvalues (in the cart's q and
    the pole's angle) are MuJoCo's to 1e-4 relative."""
    path = MODELS / "cart_pole.xml"
    imported, config = _imported(path, keyframe="start", n_samples=2001)
    assert imported.text == (MODELS.parent / "cart_pole_imported.yaml").read_text()
    rail = config.resolved["joints"][0]
    assert rail["variant"] == "slide" and rail["k_r"] == pytest.approx(20.0)
    assert rail["theta_ref"] == pytest.approx(0.2)
    assert rail["saturation"]["torque_n"] == 5.0 and rail["saturation"]["torque_n_lower"] == -3.0
    assert rail["passive"] == {"k_r": 2.0, "l_r": 0.5, "theta_ref": 0.1} and rail["range"]["upper"] == 1.0
    assert "[N/m]" in imported.text and "[m, m/s] rail" in imported.text
    result = simulate(config)
    assert result.status == "success" and result.summary["lyapunov_rate_check"] == "pass"
    assert result.outputs["constraint_force_saturated"][:, 0, 0].any()  # the push at its forcerange
    assert largest_distance(path, config, result, keyframe="start") < 1e-6
    theirs = interaction_forces(path, config, result, keyframe="start")[0]
    np.testing.assert_allclose(result.outputs["constraint_force"], theirs, rtol=0, atol=1e-6 * np.abs(theirs).max())
    analysis = analyze(config, certificate=False, simulate=False)
    assert analysis.layout.state_names() == ["cart.translation", "cart.translation_rate", "pole.q", "pole.u"]
    q = analysis.linearisation.equilibrium[[0, 2]]
    eigenvalues, acceleration = eigenvalues_at(path, q, keyframe="start")
    assert np.abs(acceleration).max() < 1e-7
    ours = analysis.linearisation.eigenvalues
    assert len(ours) == len(eigenvalues)
    for s in eigenvalues:
        assert np.min(np.abs(ours - s)) <= 1e-4 * abs(s), (s, ours)


def test_import_writes_a_config_that_runs(tmp_path):
    """The CLI writes the config (refusing to replace it without --overwrite) and notes the
    zero gains on stderr; ``rbstab run`` runs it as written."""
    out = tmp_path / "arm.yaml"
    runner = CliRunner()
    first = runner.invoke(cli, ["import", str(MODELS / "arm.urdf"), "-o", str(out)])
    assert first.exit_code == 0, first.output
    assert "no servo on shoulder, elbow" in first.stderr
    again = runner.invoke(cli, ["import", str(MODELS / "arm.urdf"), "-o", str(out)])
    assert again.exit_code == 1 and "--overwrite" in again.output
    run = runner.invoke(cli, ["run", str(out), "-o", str(tmp_path), "--set", "simulation.t_end=0.2",
                              "--set", "simulation.n_samples=21"])
    assert run.exit_code == 0, run.output
    assert (tmp_path / "arm.h5").exists()


@pytest.mark.parametrize("change, element", [
    (('type="hinge" axis="0.2 1 0.5"', 'type="ball"'), '<joint name="jb">'),
    (('quat="0.9 0.1 0.3 -0.2">', 'quat="0.9 0.1 0.3 -0.2"><freejoint name="float"/>'), '<joint name="float">'),
    (('<joint name="jb"', '<joint name="jb2" type="hinge" axis="1 0 0" pos="0 0 0.1"/><joint name="jb"'),
     '<body name="b">'),
    (('</worldbody>', '</worldbody><tendon><fixed name="t"><joint joint="ja" coef="1"/></fixed></tendon>'),
     '<tendon name="t">'),
    (('<motor name="drive" joint="ja"/>', '<muscle name="drive" joint="ja"/>'), '<actuator name="drive">'),
    (('damping="0.05"', 'damping="0.05" armature="0.01"'), '<joint name="jb">'),
])
def test_what_rbstab_cannot_represent_is_refused_in_one_line(tmp_path, change, element):
    """A ball with a servo, a free joint, a second joint in a body through another point (not a
    universal joint), a tendon, a muscle, armature:
    one line naming the element, exit 1, nothing written."""
    path, out = tmp_path / "model.xml", tmp_path / "config.yaml"
    path.write_text(OBLIQUE.replace(*change).replace('ctrl="0.3 0"', ""))
    result = CliRunner().invoke(cli, ["import", str(path), "-o", str(out)])
    assert result.exit_code == 1, result.output
    assert element in result.output and "Traceback" not in result.output
    assert not out.exists()


@pytest.mark.parametrize("change, expected", [
    (('<position name="elbow_muscles"', '<motor name="m" joint="shoulder"/><position name="elbow_muscles"'),
     "acts on the ball joint"),
])
def test_a_ball_that_rbstab_cannot_represent_is_refused_saying_why(tmp_path, change, expected):
    """The arm's ball shoulder with an actuator: refused, naming the shoulder and why."""
    from rbstab.config import ConfigError

    path = tmp_path / "arm.xml"
    path.write_text((MODELS / "arm.xml").read_text().replace(*change).replace(' ctrl="0.8"', ""))
    with pytest.raises(ConfigError) as raised:
        import_model(path)
    assert expected in str(raised.value) and "shoulder" in str(raised.value), str(raised.value)


@pytest.mark.parametrize("text, keyframe, expected", [
    (OBLIQUE, "none", "keyframe 'none' not found; its keyframes: 'start'"),
    ("<mujoco><worldbody>", None, "not an XML file"),
    ("<model/>", None, "its root element is <model>"),
    ("<mujoco><worldbody><body><joint type='hinge'/></body></worldbody></mujoco>", None,
     "MuJoCo's compiler refused it"),
])
def test_bad_model_files_and_keyframes_are_refused_in_one_line(tmp_path, text, keyframe, expected):
    path, out = tmp_path / "model.xml", tmp_path / "config.yaml"
    path.write_text(text)
    args = ["import", str(path), "-o", str(out)] + (["--keyframe", keyframe] if keyframe else [])
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and expected in result.output, result.output
    assert not out.exists()


def test_a_missing_model_file_is_refused(tmp_path):
    result = CliRunner().invoke(cli, ["import", str(tmp_path / "missing.xml")])
    assert result.exit_code == 1 and "model file not found" in result.output


def test_stop_gains_are_mujocos_soft_limit_on_the_effective_inertia():
    """The knee's range: MuJoCo's solref (0.02, 1) on the knee's inertia at the reference
    pose, I = 1 / dof_invweight0: k = I / 0.02^2, l = 2 I / 0.02."""
    _, config = _imported(MODELS / "stance.xml")
    model = mujoco_model(MODELS / "stance.xml")
    inertia = 1.0 / model.dof_invweight0[1]
    stop = config.resolved["joints"][1]["range"]
    assert (stop["lower"], stop["upper"]) == (-2.4, 0.05)
    assert stop["k_r"] == pytest.approx(inertia / 0.02**2, rel=1e-12)
    assert stop["l_r"] == pytest.approx(2 * inertia / 0.02, rel=1e-12)
    assert math.isfinite(stop["k_r"])
