"""Tests of chain configurations (rbstab.config.loader): the examples, every refused input
(one line through ``rbstab validate``, nothing written), the chain of a one-body config,
the placement of a child from its parent, and the names' round trip."""

from __future__ import annotations

import copy
import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from rbstab.variants.paper import paper_form
from rbstab.chain import GROUND, MAX_BODIES, Body, Joint, single
from rbstab.config import ConfigError, PhysicalPlausibilityWarning, RunConfig
from rbstab.config.loader import config_from_mapping, load_config
from rbstab.kinematics import euler_rate_matrix, rotation_matrix
from rbstab.model import Saturation
from rbstab.variants import VARIANTS
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = {name: ROOT / "configs" / "examples" / f"{name}.yaml" for name in ("double_pendulum", "stance_ankle_hip",
                                                                              "knee")}

#: Two bodies: legs on the ground by a pinned ankle, a trunk on the legs by a visco-elastic hip.
BASE = {
    "name": "stance",
    "gravity": [0, 0, -9.81],
    "bodies": [{"name": "legs", "mass": 28.0, "inertia": [2.6, 2.6, 0.1]},
               {"name": "trunk", "mass": 42.0, "inertia": [2.3, 2.3, 0.4]}],
    "joints": [
        {"name": "ankle", "parent": "ground", "parent_point": [0, 0, 0], "child": "legs",
         "child_point": [0, 0, -0.45], "variant": "permanent", "k_r": [900, 900, 300], "l_r": [200, 200, 60]},
        {"name": "hip", "parent": "legs", "parent_point": [0, 0, 0.45], "child": "trunk",
         "child_point": [0, 0, -0.30], "variant": "visco_elastic", "k_c": [4e5, 4e5, 4e5],
         "l_c": [2e3, 2e3, 2e3], "k_r": [600, 600, 200], "l_r": [120, 120, 40]},
    ],
    "initial_state": {"legs": {"theta": [0.05, 0, 0], "omega": [0.3, -0.2, 0.1]},
                      "trunk": {"theta": [-0.08, 0.02, 0], "omega": [0.1, 0.4, -0.2]}},
}


@pytest.fixture(autouse=True)
def _plausibility_warnings_are_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicalPlausibilityWarning)
        yield


def base() -> dict:
    return copy.deepcopy(BASE)


def _validate(tmp_path: Path, data: dict, *args: str):
    """``rbstab validate`` of ``data`` written to a file in an otherwise empty folder: (the
    result, the folder's files afterwards)."""
    folder = tmp_path / "work"
    folder.mkdir()
    path = folder / "chain.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    result = CliRunner().invoke(cli, [*args, str(path)] if args else ["validate", str(path)])
    return result, sorted(p.name for p in folder.iterdir())


# -- the examples --------------------------------------------------------------------------------


def test_the_examples_validate_and_show_their_tree():
    result = CliRunner().invoke(cli, ["validate", *map(str, EXAMPLES.values())])
    assert result.exit_code == 0, result.output
    assert "warning" not in result.output
    out = result.output
    assert "ok: double_pendulum (chain of 2 bodies, t_end 10 s" in out
    assert "  ground -> upper (1 kg): shoulder, permanent, [0, 0, 0] -> [0, 0, 0.5] m" in out
    assert "    upper -> lower (1 kg): elbow, permanent, [0, 0, -0.5] -> [0, 0, 0.5] m" in out
    assert "  ground -> legs (22.54 kg): ankle, permanent" in out
    assert "    legs -> trunk (47.46 kg): hip, permanent" in out
    assert "  ground -> thigh (7 kg): hip, visco_elastic" in out
    assert "    thigh -> shank (3.26 kg): knee, embedded" in out



def test_a_one_body_config_validates_as_its_one_body_tree():
    """rbstab validate shows a one-body config as the tree it is: its body held to the
    ground by its controller at its attachment point (--json: the variant and the chain)."""
    import json

    path = str(ROOT / "configs" / "examples" / "saturated_pendulum.yaml")
    result = CliRunner().invoke(cli, ["validate", path])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()  # (a first run's compile notice goes to stderr)
    assert lines[lines.index(next(line for line in lines if line.startswith("ok: "))) + 1] == \
        "  ground -> body (2 kg): controller, permanent, [0, 0, -0.5] -> [0, 0, -0.5] m"
    record = json.loads(CliRunner().invoke(cli, ["validate", "--json", path]).stdout.strip().splitlines()[-1])
    assert record["variant"] == "permanent" and record["chain"]["joints"][0]["parent"] == "ground"


def test_the_examples_mean_what_their_comments_say():
    stance = load_config(EXAMPLES["stance_ankle_hip"])
    assert isinstance(stance, RunConfig)
    ankle, hip = stance.chain.joints
    np.testing.assert_array_equal(ankle.saturation.torque_n, [120, 120, math.inf])
    np.testing.assert_array_equal(hip.saturation.torque_n, [150, 150, math.inf])
    # K_r - G positive definite in the joint angles about x (the comment's closed form)
    legs, trunk = stance.chain.bodies
    g = 9.81
    l1, big_l1, l2 = -ankle.child_point[2], hip.parent_point[2] - ankle.child_point[2], -hip.child_point[2]
    a, b = legs.mass * g * l1 + trunk.mass * g * big_l1, trunk.mass * g * l2
    gravity_stiffness = np.array([[a + b, b], [b, b]])
    np.testing.assert_allclose(gravity_stiffness, [[652, 147], [147, 147]], atol=0.5)
    assert np.all(np.linalg.eigvalsh(np.diag([ankle.k_r[0, 0], hip.k_r[0, 0]]) - gravity_stiffness) > 0)
    pendulum = load_config(EXAMPLES["double_pendulum"])
    assert all(j.variant == "permanent" and not j.k_r.any() and not j.l_r.any() for j in pendulum.chain.joints)
    knee = load_config(EXAMPLES["knee"])
    assert [j.variant for j in knee.chain.joints] == ["visco_elastic", "embedded"]


def test_one_loader_takes_both_spellings_and_refuses_a_mapping_that_mixes_them():
    """load_config and config_from_mapping (and the API's rbstab.load_config) give one type,
    a RunConfig, for a tree's file or mapping and for one body's, overrides read against the
    spelling's keys; a mapping with both body and bodies is one line."""
    import rbstab

    tree = load_config(EXAMPLES["stance_ankle_hip"], ["joints.ankle.k_r.0=400"])
    assert isinstance(tree, RunConfig) and tree.chain.joints[0].k_r[0, 0] == 400.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)  # case 1's printed inertia (W001)
        one = load_config(ROOT / "configs" / "paper" / "case1_permanent.yaml", ["controller.k_r.0=300"])
    assert isinstance(one, RunConfig) and paper_form(one).gains.k_r[0, 0] == 300.0
    again = config_from_mapping(tree.resolved, overrides=["joints.hip.l_r=[1, 2, 3]"])
    assert isinstance(again, RunConfig) and np.array_equal(np.diag(again.chain.joints[1].l_r), [1, 2, 3])
    api = rbstab.load_config(tree, {"joints.hip.k_r.0": 600})
    assert isinstance(api, RunConfig) and api.chain.joints[1].k_r[0, 0] == 600.0
    mixed = {**one.resolved, "bodies": tree.resolved["bodies"], "joints": tree.resolved["joints"]}
    with pytest.raises(ConfigError) as info:
        config_from_mapping(mixed)
    (line,) = info.value.errors
    assert line.startswith("config key 'bodies': found both 'body' and 'bodies'; expected either body and controller")


# -- refused input -------------------------------------------------------------------------------


def _later_parent(d):
    d["bodies"].append({"name": "arms", "mass": 8.0, "inertia": [0.5, 0.5, 0.1]})
    d["bodies"][1], d["bodies"][2] = d["bodies"][2], d["bodies"][1]  # legs, arms, trunk
    d["joints"].append({"name": "shoulder", "parent": "trunk", "child": "arms", "variant": "permanent"})


def _nine_bodies(d):
    d["bodies"] = [{"name": f"b{i}", "mass": 1.0, "inertia": [1, 1, 1]} for i in range(MAX_BODIES + 1)]
    d["joints"] = [{"name": f"j{i}", "parent": "ground" if i == 0 else f"b{i - 1}", "child": f"b{i}",
                    "variant": "permanent"} for i in range(MAX_BODIES + 1)]
    d["initial_state"] = {}


def _set(path, value):
    def change(d):
        node = d
        for part in path[:-1]:
            node = node[part]
        if value is _DELETE:
            del node[path[-1]]
        else:
            node[path[-1]] = value
    return change


_DELETE = object()
_TRUNK_X = [0.006, -0.021, 1.208]  # the placed x is (0.0059996, -0.0210116, 1.197855): missed by ~1 cm

#: (id, change of BASE, the key, fragments of the line).
REFUSED = [
    ("parent_unknown", _set(["joints", 1, "parent"], "pelvis"), "joints.1.parent",
     ["found 'pelvis'", "expected 'ground' or the name of a body: 'legs', 'trunk'"]),
    ("parent_later", _later_parent, "joints.2.parent",
     ["found 'trunk'", "expected 'ground' or a body listed before 'arms' in bodies: 'legs'",
      "list 'trunk' before 'arms'"]),
    ("child_unknown", _set(["joints", 1, "child"], "trnk"), "joints.1.child",
     ["found 'trnk'", "expected the name of a body: 'legs', 'trunk'", "did you mean 'trunk'?"]),
    ("two_joints_on_one_body", lambda d: d["joints"].append(
        {"name": "knee", "parent": "ground", "child": "legs", "variant": "free"}), "joints.2.child",
     ["found 'legs'", "expected a body no other joint holds", "joint 'ankle' (joints.0) holds 'legs' already"]),
    ("body_without_joint", lambda d: d["joints"].pop(), "joints",
     ["found 1 joints ('ankle')", "expected exactly one joint per body", "body 'trunk' (bodies.1) has none"]),
    ("loop_of_two", lambda d: d["joints"][0].update(parent="trunk"), "joints.0.parent",
     ["found 'trunk'", "a loop: legs -> trunk -> legs"]),
    ("loop_on_itself", lambda d: d["joints"][1].update(parent="trunk"), "joints.1.parent",
     ["found 'trunk'", "a loop: trunk -> trunk"]),
    ("initial_state_unknown_body", lambda d: d["initial_state"].update(trnk={"theta": [0.1, 0, 0]}),
     "initial_state.trnk", ["found 'trnk'", "expected the name of a body: 'legs', 'trunk'",
                            "did you mean 'initial_state.trunk'?"]),
    ("disturbance_unknown_body", _set(["disturbances"], [
        {"kind": "impulse", "value": [0, 10, 0], "point": [0, 0, 0.2], "start": 0.1, "body": "torso"}]),
     "disturbances.0.body", ["found 'torso'", "expected the name of a body: 'legs', 'trunk'"]),
    ("disturbance_without_body", _set(["disturbances"], [
        {"kind": "impulse", "value": [0, 10, 0], "start": 0.1}]),
     "disturbances.0.body", ["found nothing", "expected the name of the body it acts on: 'legs', 'trunk'"]),
    ("permanent_x_violated", lambda d: d["joints"][1].update(variant="permanent")
     or d["initial_state"]["trunk"].update(x=_TRUNK_X), "initial_state.trunk.x",
     ["found [0.006, -0.021, 1.208]", "that holds the permanent joint 'hip' to 'legs' (E_j = 0)", "|E_j| = 0.0101",
      "leave x out and rbstab places 'trunk' from 'legs'"]),
    ("permanent_v_violated", lambda d: d["initial_state"]["legs"].update(v=[0.0, 0.0, 0.1]),
     "initial_state.legs.v", ["found [0.0, 0.0, 0.1]", "the permanent joint 'ankle' to 'ground' (dE_j/dt = 0)",
                              "|dE_j/dt| = 0.1"]),
    ("sliding_sign_law_in_a_chain", lambda d: d["joints"][1].update(variant="sliding", k_s=50.0),
     "joints.hip.boundary_layer", ["found 0", "expected a boundary layer > 0 [m] in a chain"]),
    ("more_than_8_bodies", _nine_bodies, "bodies", ["found 9 bodies", "expected a list of 1 to 8 bodies"]),
    ("duplicate_body", _set(["bodies", 1, "name"], "legs"), "bodies.1.name",
     ["found 'legs'", "expected a name no other body has", "bodies.0.name is 'legs' too"]),
    ("duplicate_joint", _set(["joints", 1, "name"], "ankle"), "joints.1.name",
     ["found 'ankle'", "expected a name no other joint has"]),
    ("body_named_ground", lambda d: d["bodies"][0].update(name="ground") or d["joints"][0].update(child="ground")
     or d["joints"][1].update(parent="ground") or d["initial_state"].pop("legs"), "bodies.0.name",
     ["found 'ground'", "expected a name other than 'ground'"]),
    ("visco_elastic_without_k_c", _set(["joints", 1, "k_c"], _DELETE), "joints.1.k_c",
     ["missing", "(required by variant 'visco_elastic')"]),
    ("embedded_without_l_d", lambda d: d["joints"][1].update(variant="embedded", k_d=[1e4, 1e4, 1e4]),
     "joints.1.l_d", ["missing", "positive definite", "(required by variant 'embedded')"]),
    ("sliding_without_k_s", _set(["joints", 1, "variant"], "sliding"), "joints.1.k_s",
     ["missing", "(required by variant 'sliding')"]),
    ("limit_on_the_pin", _set(["joints", 0, "saturation"], {"constraint_force": 100}),
     "joints.0.saturation.constraint_force", ["found 100", "no limit with variant 'permanent'"]),
    ("joint_at_gimbal_lock", lambda d: d["initial_state"]["trunk"].update(theta=[0.0, 1.0, 0.0])
     or d["initial_state"]["legs"].update(theta=[0.0, -0.5707, 0.0]), "initial_state.trunk.theta",
     ["joint 'hip' starts at its gimbal lock"]),
    ("outside_the_limits", lambda d: d.update(simulation={"limits": {"theta": 0.06}}), "simulation.limits.theta",
     ["found 0.06", "expected bounds that contain the initial state", "body 'trunk' starts outside: |theta_1| = 0.08"]),
    ("e_outside_the_limits", lambda d: d.update(simulation={"limits": {"constraint_error": 0.001}})
     or d["initial_state"]["trunk"].update(x=_TRUNK_X), "simulation.limits.constraint_error",
     ["joint 'hip' starts outside: |E_3| = 0.0101"]),
    ("bound_of_e_on_pins", lambda d: d.update(simulation={"limits": {"constraint_error": 0.01}})
     or d["joints"][1].update(variant="permanent"), "simulation.limits.constraint_error",
     ["no bound when every joint is 'permanent'"]),
    ("body_gain_on_a_joint", lambda d: d["joints"][1].update(k_t=[10, 10, 10]), "joints.1.k_t",
     ["found [10, 10, 10]", "expected no k_t on a joint", "give k_t to the child body"]),
    ("misspelt_joint_key", lambda d: d["joints"][1].update(k_rr=[10, 10, 10]), "joints.1.k_rr",
     ["unknown key; did you mean 'joints.1.k_r'?"]),
    ("one_body_initial_state", _set(["initial_state"], {"theta": [0.1, 0, 0]}), "initial_state",
     ["found keys theta", "expected body names as keys ('legs', 'trunk')"]),
    ("bad_body_name", _set(["bodies", 1, "name"], "trunk.upper"), "bodies.1.name",
     ["found 'trunk.upper'", "a name of letters, digits, '_' and '-'"]),
]


@pytest.mark.parametrize(("change", "key", "fragments"), [r[1:] for r in REFUSED], ids=[r[0] for r in REFUSED])
def test_refused_in_one_line_naming_the_key_and_nothing_written(tmp_path, change, key, fragments):
    data = base()
    change(data)
    result, files = _validate(tmp_path, data)
    assert result.exit_code != 0, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.startswith("config key")]
    assert len(lines) == 1, result.output
    assert lines[0].startswith(f"config key '{key}': "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert files == ["chain.yaml"]


def test_the_base_chain_is_valid(tmp_path):
    data = base() | {"simulation": {"limits": {"theta": 0.09, "constraint_error": 0.001}}}
    result, files = _validate(tmp_path, data)
    assert result.exit_code == 0, result.output
    assert files == ["chain.yaml"]


def test_a_config_with_both_spellings_is_refused(tmp_path):
    data = base() | {"body": {"mass": 1.0}}
    result, _ = _validate(tmp_path, data)
    assert result.exit_code != 0
    lines = [line for line in result.output.splitlines() if line.startswith("config key")]
    assert lines == ["config key 'bodies': found both 'body' and 'bodies'; expected either body and controller "
                     "(one body) or bodies and joints (a chain)"]


# -- the chain of a one-body config ------------------------------------------------------------------


ONE_BODY = ["paper/case1_permanent.yaml", "paper/case2_visco_elastic.yaml", "paper/case3_embedded.yaml",
            "examples/free_gravity.yaml", "examples/sliding.yaml", "examples/saturated_push.yaml"]


def _expected_chain(config):
    """The one-body chain written out from the one-body config's resolved sections (what
    the file says: a list of 3 numbers a diagonal matrix, a limit left out inf)."""
    r = config.resolved
    body_section, ctrl = r["body"], r["controller"]
    used = VARIANTS[ctrl["variant"]].required_gains

    def matrix(value):
        value = np.array(value, dtype=float)
        return np.diag(value) if value.ndim == 1 else value

    def gain(name):
        return matrix(ctrl[name]) if name in used else None

    written = ctrl.get("saturation")
    inf = np.full(3, math.inf)

    def limit(key):
        value = (written or {}).get(key)
        return inf.copy() if value is None else np.broadcast_to(np.array(value, dtype=float), (3,)).copy()

    shape = None if written is None else written.get("shape", "clip")
    point = np.array(body_section["attachment_point"], dtype=float)
    body = Body("body", float(body_section["mass"]), matrix(body_section["inertia"]), gain("k_t"), gain("l_t"),
                None if written is None else Saturation(inf, limit("force_h"), inf, shape),
                paper_form(config).gains.disturbances)
    joint = Joint("controller", GROUND, 0, point, point, ctrl["variant"], gain("k_r"), gain("l_r"),
                  gain("k_c"), gain("l_c"), gain("k_d"), gain("l_d"),
                  float(ctrl["k_s"]) if "k_s" in used else None,
                  float(ctrl.get("boundary_layer", 0.0)) if "k_s" in used else 0.0,
                  None if written is None else Saturation(limit("torque_n"), inf, limit("constraint_force"), shape))
    return single(body, joint, np.array(body_section["gravity"], dtype=float))


def _assert_same(a, b, where=""):
    """Field by field: arrays equal, None alike, dataclasses and tuples recursively."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    elif a is None or b is None:
        assert a is None and b is None, where
    elif isinstance(a, str):
        assert a == b, where
    else:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=where)


@pytest.mark.parametrize("path", ONE_BODY)
def test_both_spellings_of_one_body_have_one_paper_form(path):
    """The paper's one-body model (paper_form) of the same body written as a tree (bodies,
    joints) is the one-body config's, record for record, and both spellings compile to one
    tree; a tree held elsewhere than at its own point, or of two bodies, has none."""
    from conftest import tree_spelling

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        config = load_config(ROOT / "configs" / path)
        tree = tree_spelling(config)
    one, other = paper_form(config), paper_form(tree)
    assert type(one) is type(other)
    for name in one.parameters.dtype.names:
        np.testing.assert_array_equal(one.parameters[name], other.parameters[name], err_msg=name)
    from rbstab.variants.chain import compile_chain

    back, given = (compile_chain(c.chain, offset=0.0) for c in (config, tree))
    for a, b in zip(back.args, given.args):  # the same records: one model
        np.testing.assert_array_equal(a, b)
    moved = dict(tree.resolved, joints=[dict(tree.resolved["joints"][0], parent_point=[0.0, 0.0, 0.0])])
    if config.chain.joints[0].variant == "permanent":  # its initial x, v placed from the joint
        moved["initial_state"] = {"body": {k: v for k, v in tree.resolved["initial_state"]["body"].items()
                                           if k not in ("x", "v")}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert paper_form(config_from_mapping(moved)) is None
        assert paper_form(load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml")) is None


@pytest.mark.parametrize("path", ONE_BODY)
def test_chain_of_a_one_body_config_is_its_one_body_chain(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        config = load_config(ROOT / "configs" / path)
    chain = config.chain
    _assert_same(chain, _expected_chain(config))
    assert chain.size == 1 and chain.body_names == ("body",) and chain.joint_names == ("controller",)
    assert list(chain.parents) == [GROUND]


def _as_chain_mapping(config) -> dict:
    """A one-body config's resolved form written as a chain config (the other spelling)."""
    r = config.resolved
    ctrl = {k: v for k, v in r["controller"].items() if k != "saturation"}
    sat = r["controller"].get("saturation")
    body = {"name": "body", "mass": r["body"]["mass"], "inertia": r["body"]["inertia"],
            "k_t": ctrl.pop("k_t"), "l_t": ctrl.pop("l_t")}
    joint = {"name": "controller", "parent": "ground", "parent_point": r["body"]["attachment_point"],
             "child": "body", "child_point": r["body"]["attachment_point"], **ctrl}
    if sat is not None:
        body["saturation"] = {k: sat[k] for k in ("force_h", "shape") if k in sat}
        joint["saturation"] = {k: sat[k] for k in ("torque_n", "constraint_force", "shape") if k in sat}
    data = {"name": r["name"], "gravity": r["body"]["gravity"], "bodies": [body], "joints": [joint],
            "initial_state": {"body": r["initial_state"]}, "simulation": r["simulation"]}
    if "disturbances" in r:
        data["disturbances"] = r["disturbances"]
    return data


@pytest.mark.parametrize("path", ONE_BODY)
def test_the_two_spellings_of_one_body_are_one_chain(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        config = load_config(ROOT / "configs" / path)
        data = _as_chain_mapping(config)
        if config.chain.joints[0].variant == "permanent":  # x and v follow from theta and omega: let rbstab place them
            for key in ("x", "v"):
                data["initial_state"]["body"].pop(key)
        chained = config_from_mapping(data)
    _assert_same(chained.chain, config.chain)  # the gains the variant does not use: None in both
    state = chained.initial_state["body"]
    for block in ("theta", "omega", "controller_state"):
        np.testing.assert_array_equal(state[block], config.initial_state["body"][block])
    if config.chain.joints[0].variant != "permanent":
        np.testing.assert_array_equal(state["position"], config.initial_state["body"]["position"])
        np.testing.assert_array_equal(state["velocity"], config.initial_state["body"]["velocity"])
    assert chained.simulation == config.simulation


# -- placement, the permanent constraint, names ------------------------------------------------------


def _point_error(config: RunConfig, states) -> list[np.ndarray]:
    """E_j = X_c + A_c R_c - X_p - A_p R_p of every joint, from the states' theta and x."""
    out = []
    for joint in config.chain.joints:
        c = states[config.chain.bodies[joint.child].name]
        here = c["position"] + rotation_matrix(c["theta"]) @ joint.child_point
        if joint.parent == GROUND:
            there = joint.parent_point
        else:
            p = states[config.chain.bodies[joint.parent].name]
            there = p["position"] + rotation_matrix(p["theta"]) @ joint.parent_point
        out.append(here - there)
    return out


def test_a_child_left_without_x_and_v_is_placed_on_its_joint():
    """E_j = 0, and E_j stays 0 to first order along the motion: advanced by +-h (theta by
    B(theta) omega, x by v), E_j changes by O(h^2) only."""
    config = config_from_mapping(base())
    assert config.placed == ("initial_state.legs.x", "initial_state.legs.v", "initial_state.trunk.x",
                             "initial_state.trunk.v")
    for e in _point_error(config, config.initial_state):
        np.testing.assert_allclose(e, 0, atol=1e-15)
    h = 1e-5
    moved = [{name: {"theta": s["theta"] + sign * h * euler_rate_matrix(s["theta"]) @ s["omega"],
                     "position": s["position"] + sign * h * s["velocity"]}
              for name, s in config.initial_state.items()} for sign in (1, -1)]
    for forward, backward in zip(_point_error(config, moved[0]), _point_error(config, moved[1])):
        assert np.abs((forward - backward) / (2 * h)).max() < 1e-8  # dE_j/dt = 0
    assert np.abs(config.initial_state["trunk"]["velocity"]).max() > 0.1  # the test is not trivial


def test_a_permanent_joint_given_its_placed_state_is_accepted():
    data = base()
    data["joints"][1]["variant"] = "permanent"
    placed = config_from_mapping(data).initial_state
    for name in ("legs", "trunk"):
        data["initial_state"][name]["x"] = placed[name]["position"].tolist()
        data["initial_state"][name]["v"] = placed[name]["velocity"].tolist()
    again = config_from_mapping(data)
    assert again.placed == ()
    for name in ("legs", "trunk"):
        np.testing.assert_array_equal(again.initial_state[name]["position"], placed[name]["position"])


def test_names_round_trip_through_the_resolved_yaml(tmp_path):
    data = base()
    data["bodies"].append({"name": "arm_L", "mass": 3.0, "inertia": [0.2, 0.2, 0.05], "k_t": [10, 10, 10]})
    data["joints"].insert(0, {"name": "shoulder-L", "parent": "trunk", "parent_point": [0.2, 0, 0.25],
                              "child": "arm_L", "child_point": [0, 0, 0.3], "variant": "embedded",
                              "k_c": [1e4] * 3, "l_c": [1e2] * 3, "k_d": [1e4] * 3, "l_d": [1e2] * 3,
                              "saturation": {"torque_n": 50, "constraint_force": [300, 300, .5e3]}})
    data["disturbances"] = [{"kind": "pulse", "value": [0, 30, 0], "point": [0, 0, 0.1], "start": 0.2,
                             "duration": 0.1, "body": "arm_L"}]
    config = config_from_mapping(data)
    assert config.chain.body_names == ("legs", "trunk", "arm_L")
    assert config.chain.joint_names == ("ankle", "hip", "shoulder-L")  # ordered by their child
    assert list(config.chain.parents) == [GROUND, 0, 1]
    assert [len(b.disturbances) for b in config.chain.bodies] == [0, 0, 1]
    path = tmp_path / "again.yaml"
    path.write_text(config.to_yaml(), encoding="utf-8")
    again = load_config(path)
    assert again.name == "stance" and again.resolved == config.resolved
    _assert_same(again.chain, config.chain)
    assert list(again.initial_state) == ["legs", "trunk", "arm_L"]
    for name, state in config.initial_state.items():
        for block, value in state.items():
            np.testing.assert_array_equal(again.initial_state[name][block], value)


def test_overrides_reach_a_chain_and_are_named_in_its_errors(tmp_path):
    path = tmp_path / "chain.yaml"
    path.write_text(yaml.safe_dump(base(), sort_keys=False), encoding="utf-8")
    config = load_config(path, ["bodies.1.mass=50", "joints.1.k_c.0=1e5"])
    assert config.chain.bodies[1].mass == 50.0 and config.chain.joints[1].k_c[0, 0] == 1e5
    with pytest.raises(ConfigError) as caught:
        load_config(path, ["bodies.0.mass=-1"])
    assert caught.value.errors == ["config key 'bodies.0.mass': found -1; expected a number > 0 (kg) "
                                   "[from override 'bodies.0.mass=-1']"]


def test_a_chain_body_warns_like_a_one_body_config():
    data = base()
    data["bodies"][1]["inertia"] = [10, 8, 0.4]
    data["initial_state"]["legs"]["theta"] = [45, 0, 0]
    with pytest.warns(PhysicalPlausibilityWarning) as caught:
        config = config_from_mapping(data)
    assert [str(w.message)[:40] for w in caught] == ["W001 bodies.1.inertia ('trunk'): princip",
                                                    "W005 initial_state.legs.theta: theta[0] "]
    assert len(config.warnings) == 2


def test_validate_json_gives_the_chain_by_names():
    import json

    result = CliRunner().invoke(cli, ["validate", "--json", str(EXAMPLES["knee"])])
    assert result.exit_code == 0, result.output
    record = json.loads(next(line for line in result.output.splitlines() if line.startswith("{")))
    assert record["valid"] and "variant" not in record
    assert [b["name"] for b in record["chain"]["bodies"]] == ["thigh", "shank"]
    assert [(j["name"], j["parent"], j["child"], j["variant"]) for j in record["chain"]["joints"]] == [
        ("hip", "ground", "thigh", "visco_elastic"), ("knee", "thigh", "shank", "embedded")]
    assert record["chain"]["joints"][1]["parent_point"] == [0.0, 0.243, 0.0]


def test_singular_gains_written_are_noted_those_left_out_are_not():
    from rbstab.config import SemiDefiniteGainWarning

    config_from_mapping(base())  # k_t, l_t left out: no note (the autouse fixture makes one an error)
    data = base()
    data["bodies"][0]["k_t"] = [0, 0, 0]
    data["joints"][1]["l_r"] = [0, 120, 40]
    with pytest.warns(SemiDefiniteGainWarning) as caught:
        config = config_from_mapping(data)
    assert [str(w.message)[:40] for w in caught] == ["W002 bodies.0.k_t: positive semi-definit",
                                                    "W002 joints.1.l_r: positive semi-definit"]
    assert len(config.warnings) == 2


def test_bodies_that_nothing_holds_under_gravity_are_warned_of_at_validation(tmp_path):
    """A ``free`` joint exerts torques only: the knee's shank on a free joint, with no k_t of
    its own, falls without bound (W007 at validation, naming it), while the same shank with a
    k_t that holds its weight, or the hip's thigh on its spring, is not warned of. A run prints
    no raw Python warning (a library's RuntimeWarning) without -v."""
    from rbstab.config.physics import unheld_bodies

    knee = EXAMPLES["knee"]
    result = CliRunner().invoke(cli, ["validate", str(knee), "--set", "joints.knee.variant=free"])
    assert result.exit_code == 0, result.output
    (line,) = [x for x in result.output.splitlines() if "W007" in x]
    assert "body 'shank' held by no joint to the ground" in line and "thigh" not in line, line
    held = CliRunner().invoke(cli, ["validate", str(knee), "--set", "joints.knee.variant=free",
                                    "--set", "bodies.shank.k_t=[0,0,400]"])
    assert held.exit_code == 0 and "W007" not in held.output, held.output
    eye, zero = np.eye(3), np.zeros((3, 3))
    g = np.array([0.0, 0.0, -9.81])
    # two bodies tied by a spring joint, free to the ground: held by the k_t of one of them
    assert unheld_bodies(["a", "b"], [1.0, 2.0], [zero, 100 * eye], [(None, 0, "free"), (0, 1, "visco_elastic")], g) == []
    (both,) = unheld_bodies(["a", "b"], [1.0, 2.0], [zero, zero], [(None, 0, "free"), (0, 1, "visco_elastic")], g)
    assert "bodies 'a', 'b'" in both and "(0, 0, -29.43) N" in both
    sideways = np.diag([100.0, 100.0, 0.0])  # springs in x and y only: the weight along z is not held
    assert unheld_bodies(["a"], [1.0], [sideways], [(None, 0, "free")], g)
    assert unheld_bodies(["a"], [1.0], [sideways], [(None, 0, "free")], np.zeros(3)) == []
    import subprocess
    import sys

    both_free = [str(knee), "--set", "joints.knee.variant=free", "--set", "joints.hip.variant=free",
                 "--set", "simulation.t_end=0.2", "--set", "simulation.n_samples=21"]
    rbstab = Path(sys.executable).parent / "rbstab"
    for flags in ((), ("-v",)):
        out = tmp_path / f"run{len(flags)}"
        done = subprocess.run([str(rbstab), "run", *both_free, "-o", str(out), *flags], capture_output=True, text=True)
        assert done.returncode == 0 and "W007" in done.stderr, done.stderr
        assert "Warning:" not in done.stderr and "warnings.warn" not in done.stderr, done.stderr  # no raw warning


def test_a_librarys_warning_is_a_note_with_v_and_silent_without(capsys):
    """A library's numerical warning (no code of rbstab's) is no finding: not shown by
    default, one ``note:`` line with ``-v``, once however often it is raised."""
    import warnings

    from rbstab_cli.console import Console

    for verbosity, shown in ((0, False), (1, True)):
        with Console(verbosity).catching_warnings():
            for _ in range(3):
                warnings.warn("overflow encountered in multiply", RuntimeWarning)
        err = capsys.readouterr().err
        assert err.count("note: RuntimeWarning from ") == (1 if shown else 0), err
        assert "Warning:" not in err, err


def test_a_runs_initial_state_placed_on_a_validated_chain_is_its_validated_one():
    """placed_initial_state (a sweep's batch of chain runs): a run's resolved initial_state
    section placed on the chain of another validated run of the same chain gives, bit for
    bit, what config_from_mapping gives that run: each block, the x and v it places."""
    from rbstab.config.loader import placed_initial_state

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        first = config_from_mapping(copy.deepcopy(BASE))
        changed = copy.deepcopy(BASE)
        changed["name"] = "tilted"
        changed["initial_state"] = {"legs": {"theta": [0.07, -0.02, 0.0], "omega": [0.3, 0.0, 0.1]},
                                    "trunk": {"theta": [-0.05, 0.0, 0.0], "d": [0.01, 0.0, 0.0]}}
        expected = config_from_mapping(changed)
    placed = placed_initial_state(expected.resolved["initial_state"], first.chain, first.simulation.gimbal_margin)
    assert placed.keys() == expected.initial_state.keys()
    for body, blocks in expected.initial_state.items():
        assert placed[body].keys() == blocks.keys()
        for block, values in blocks.items():
            assert np.array_equal(placed[body][block], values), (body, block)
    assert not np.array_equal(placed["trunk"]["position"], first.initial_state["trunk"]["position"])
