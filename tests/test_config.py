"""Tests of rbstab.config: schema, error messages, overrides, round trip, shipped configs."""

import copy
import dataclasses
import math
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from rbstab.variants.paper import paper_form, paper_initial_state
from rbstab.config import (
    ConfigError,
    PhysicalPlausibilityWarning,
    RunConfig,
    SemiDefiniteGainWarning,
    SimulationSettings,
    apply_overrides,
    config_from_mapping,
    load_config,
    parse_key,
)
from rbstab.layout import is_chain
from rbstab.layout import STATE_BLOCKS
from rbstab.variants import VARIANTS

REPO = Path(__file__).resolve().parents[1]
SHIPPED = [p for p in sorted((REPO / "configs" / "paper").glob("*.yaml")) + sorted(
    (REPO / "configs" / "examples").glob("*.yaml")
) if not is_chain(yaml.safe_load(p.read_text(encoding="utf-8")))]  # one-body configs (chains: test_chain_config.py)

# A physically plausible body (3 <= 4 + 5 ...), so no warning unless a test asks for one.
BASE = {
    "name": "base",
    "body": {"mass": 41.0, "inertia": [3.0, 4.0, 5.0], "attachment_point": [0.15, 0.10, -0.42]},
    "controller": {
        "variant": "embedded",
        "k_t": [4100, 4100, 3280],
        "l_t": [200, 200, 140],
        "k_r": [400, 400, 320],
        "l_r": [60, 60, 42],
        "k_c": [12300, 12300, 9840],
        "l_c": [600, 600, 420],
        "k_d": [12300, 12300, 9840],
        "l_d": [1200, 1200, 840],
        "k_s": 2000.0,
    },
    "initial_state": {"omega": [16, 32, -16]},
}


@pytest.fixture(autouse=True)
def _plausibility_warnings_are_errors():
    """An unexpected PhysicalPlausibilityWarning fails the test (pytest.warns still works)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicalPlausibilityWarning)
        yield


def base(**sections):
    """Deep copy of BASE with sections updated: base(body={"mass": 0})."""
    data = copy.deepcopy(BASE)
    for section, values in sections.items():
        if isinstance(values, dict) and isinstance(data.get(section), dict):
            data[section].update(values)
        else:
            data[section] = values
    return data


def problems(data, **kwargs):
    with pytest.raises(ConfigError) as info:
        config_from_mapping(data, **kwargs)
    return info.value.errors


def single_problem(data, **kwargs):
    errors = problems(data, **kwargs)
    assert len(errors) == 1, errors
    return errors[0]


def write(tmp_path, text, name="cfg.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


# -- shipped configurations -------------------------------------------------------------------


def test_shipped_configs_exist():
    names = {p.relative_to(REPO / "configs").as_posix() for p in SHIPPED}
    assert {
        "paper/case1_permanent.yaml",
        "paper/case2_visco_elastic.yaml",
        "paper/case3_embedded.yaml",
        "examples/free_gravity.yaml",
        "examples/sliding.yaml",
    } <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_config_loads(path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cfg = load_config(path)
    assert cfg.name == path.stem
    assert cfg.chain.joints[0].variant in VARIANTS
    variant = paper_form(cfg)
    for gain in type(variant).required_gains:
        assert getattr(paper_form(cfg).gains, gain) is not None
    y0 = paper_initial_state(cfg, variant)
    assert y0.shape == (variant.layout.size,)
    if paper_form(cfg).body.mass == 41.0:  # the paper's body and motion (Table 1, section 6)
        # Table 1's inertia (10, 8, 0.4) violates the triangle inequality: a warning, not an error.
        assert any(isinstance(w.message, PhysicalPlausibilityWarning) and "triangle inequality" in str(w.message)
                   for w in caught)
        np.testing.assert_array_equal(cfg.initial_state["body"]["omega"], [16, 32, -16])
        assert cfg.simulation.t_end == 2.0


def test_paper_case_values():
    with pytest.warns(PhysicalPlausibilityWarning):
        case1 = load_config(REPO / "configs/paper/case1_permanent.yaml")
        case2 = load_config(REPO / "configs/paper/case2_visco_elastic.yaml")
        case3 = load_config(REPO / "configs/paper/case3_embedded.yaml")
    assert case1.chain.joints[0].variant == "permanent"
    assert paper_form(case1).body.mass == 41.0
    np.testing.assert_array_equal(paper_form(case1).body.inertia, np.diag([10, 8, 0.4]))
    np.testing.assert_array_equal(paper_form(case1).body.attachment_point, [0.15, 0.10, -0.42])
    np.testing.assert_array_equal(paper_form(case1).body.gravity, [0, 0, -10])
    np.testing.assert_array_equal(paper_form(case1).gains.l_t, np.diag([210, 210, 140]))
    np.testing.assert_array_equal(paper_form(case1).gains.l_r, np.diag([60, 60, 42]))
    assert case1.simulation == SimulationSettings(t_end=2.0, n_samples=2001, method="DOP853")

    assert case2.chain.joints[0].variant == "visco_elastic"
    np.testing.assert_array_equal(paper_form(case2).body.gravity, [0, 0, 0])
    np.testing.assert_array_equal(paper_form(case2).gains.l_t, np.diag([200, 200, 140]))
    np.testing.assert_array_equal(paper_form(case2).gains.k_c, paper_form(case2).gains.k_t)
    np.testing.assert_array_equal(paper_form(case2).gains.l_c, paper_form(case2).gains.l_t)

    assert case3.chain.joints[0].variant == "embedded"
    np.testing.assert_array_equal(paper_form(case3).gains.k_c, np.diag([12300, 12300, 9840]))
    np.testing.assert_array_equal(paper_form(case3).gains.k_d, paper_form(case3).gains.k_c)
    np.testing.assert_array_equal(paper_form(case3).gains.l_d, 2 * paper_form(case3).gains.l_c)
    for key in ("k_t", "l_t", "k_r", "l_r"):
        np.testing.assert_array_equal(getattr(paper_form(case3).gains, key), getattr(paper_form(case2).gains, key))


def test_sliding_example_has_boundary_layer():
    with pytest.warns(PhysicalPlausibilityWarning):
        cfg = load_config(REPO / "configs/examples/sliding.yaml")
    assert paper_form(cfg).gains.k_s > 0
    assert paper_form(cfg).gains.boundary_layer == 0.005


# -- the result --------------------------------------------------------------------------------


def test_valid_mapping_gives_frozen_runconfig():
    cfg = config_from_mapping(BASE)
    assert isinstance(cfg, RunConfig)
    assert (cfg.name, cfg.chain.joints[0].variant) == ("base", "embedded")
    np.testing.assert_array_equal(paper_form(cfg).gains.k_t, np.diag([4100, 4100, 3280]))
    assert paper_form(cfg).gains.k_t.shape == (3, 3)
    assert set(cfg.initial_state) == {"body"} and set(cfg.initial_state["body"]) == set(STATE_BLOCKS)
    np.testing.assert_array_equal(cfg.initial_state["body"]["theta"], [0, 0, 0])
    np.testing.assert_array_equal(cfg.initial_state["body"]["controller_state"], [0, 0, 0])
    np.testing.assert_array_equal(paper_form(cfg).body.gravity, [0, 0, 0])
    assert cfg.simulation == SimulationSettings()
    assert cfg.simulation.max_step == math.inf
    assert cfg.warnings == ()
    with pytest.raises(AttributeError):
        cfg.name = "other"
    with pytest.raises(ValueError):
        paper_form(cfg).gains.k_t[0, 0] = 1.0  # read-only arrays
    with pytest.raises(ValueError):
        cfg.initial_state["body"]["omega"][0] = 1.0


def test_input_mapping_not_modified():
    data = base()
    snapshot = copy.deepcopy(data)
    cfg = config_from_mapping(data)
    assert data == snapshot
    cfg.resolved["controller"]["k_t"][0] = -1
    assert data == snapshot


def test_initial_state_keys_map_to_layout_blocks():
    cfg = config_from_mapping(base(initial_state={"x": [1, 2, 3], "v": [4, 5, 6], "d": [7, 8, 9]}))
    np.testing.assert_array_equal(cfg.initial_state["body"]["position"], [1, 2, 3])
    np.testing.assert_array_equal(cfg.initial_state["body"]["velocity"], [4, 5, 6])
    np.testing.assert_array_equal(cfg.initial_state["body"]["controller_state"], [7, 8, 9])


def test_full_matrix_gain_and_inertia():
    k = [[4100, 10, 0], [10, 4100, 0], [0, 0, 3280]]
    j = [[3.0, 0.1, 0.0], [0.1, 4.0, 0.0], [0.0, 0.0, 5.0]]
    cfg = config_from_mapping(base(controller={"k_t": k}, body={"inertia": j}))
    np.testing.assert_array_equal(paper_form(cfg).gains.k_t, k)
    np.testing.assert_array_equal(paper_form(cfg).body.inertia, j)
    assert cfg.resolved["controller"]["k_t"] == k


def test_empty_optional_sections_mean_defaults():
    cfg = config_from_mapping(base(initial_state=None, simulation=None))
    assert cfg.simulation == SimulationSettings()
    np.testing.assert_array_equal(cfg.initial_state["body"]["omega"], [0, 0, 0])


def test_default_name(tmp_path):
    data = base()
    del data["name"]
    assert config_from_mapping(data, default_name="from_default").name == "from_default"
    assert "name" in single_problem(data)  # no name and no default
    path = write(tmp_path, yaml.safe_dump(data), name="my_case.yaml")
    assert load_config(path).name == "my_case"


def test_unused_gains_accepted_and_ignored_for_variant_sweep():
    """One base config with every gain serves all variants; each keeps only what it uses."""
    for name, cls in VARIANTS.items():
        cfg = config_from_mapping(base(controller={"variant": name}))
        assert cfg.chain.joints[0].variant == name
        for gain in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d", "k_s"):
            assert (getattr(paper_form(cfg).gains, gain) is not None) == (gain in cls.required_gains)
        # resolved keeps the config as written, so it still re-loads for another variant
        assert cfg.resolved["controller"]["k_c"] == [12300, 12300, 9840]
        assert isinstance(paper_form(cfg), cls)


# -- error messages ------------------------------------------------------------------------------


def test_unknown_key_did_you_mean():
    line = single_problem(base(controller={"k_tt": [1, 2, 3]}))
    assert line.startswith("config key 'controller.k_tt': unknown key")
    assert "did you mean 'controller.k_t'?" in line
    assert "(allowed: variant, k_t, l_t, k_r, l_r," in line


def test_unknown_key_in_wrong_section_and_top_level():
    line = single_problem(base(simulation={"mass": 3}))
    assert "config key 'simulation.mass': unknown key" in line
    assert "did you mean 'body.mass'?" in line
    line = single_problem(base(gains={}))
    assert "config key 'gains': unknown key" in line
    assert "allowed: name, body, controller, initial_state, simulation" in line


def test_missing_key():
    data = base()
    del data["body"]["mass"]
    assert single_problem(data) == "config key 'body.mass': missing; expected a number > 0 (kg)"
    data = base()
    del data["controller"]
    assert single_problem(data).startswith("config key 'controller': missing; expected a mapping")


@pytest.mark.parametrize(
    "section, key, value, found, detail",
    [
        ("body", "attachment_point", [0.1, 0.2], "[0.1, 0.2]", "2 entries, not 3"),
        ("controller", "k_t", [1, 2], "[1, 2]", "2 entries, not 3"),
        ("controller", "l_t", [[1, 0, 0], [0, 1, 0]], "[[1, 0, 0], [0, 1, 0]]", "a 2x3 list"),
        ("body", "inertia", [[1, 0], [0, 1], [0, 0]], "[[1, 0], [0, 1], [0, 0]]", "a 3x2 list"),
        ("initial_state", "omega", 16, "16", "a number, not a list"),
    ],
)
def test_wrong_shape(section, key, value, found, detail):
    line = single_problem(base(**{section: {key: value}}))
    assert f"config key '{section}.{key}': found {found}; expected " in line
    assert "3 numbers" in line
    assert detail in line


def test_wrong_shape_gain_message_lists_allowed_forms():
    line = single_problem(base(controller={"k_t": [1, 2]}))
    assert line.startswith(
        "config key 'controller.k_t': found [1, 2]; expected 3 numbers (a diagonal) "
        "or a 3x3 list of lists, symmetric positive semi-definite (N/m)"
    )
    # L_d is inverted (eq 22): it alone must be definite
    line = single_problem(base(controller={"l_d": [1, 2]}))
    assert "or a 3x3 list of lists, symmetric positive definite (N s/m)" in line


def test_wrong_type():
    line = single_problem(base(body={"mass": "heavy"}))
    assert line == (
        "config key 'body.mass': found 'heavy'; expected a number > 0 (kg) (a string, not a number)"
    )
    line = single_problem(base(simulation={"rtol": "1e-6"}))
    assert "found '1e-6'" in line and "remove the quotes" in line
    line = single_problem(base(initial_state={"theta": [0, "a", 0]}))
    assert "config key 'initial_state.theta': found [0, 'a', 0]" in line
    assert "entry [1] is a string, not a number" in line
    line = single_problem(base(body={"mass": True}))
    assert "found true" in line and "a boolean, not a number" in line
    line = single_problem(base(simulation={"n_samples": 20.5}))
    assert "config key 'simulation.n_samples': found 20.5; expected an integer in [2, 10000000]" in line


def test_non_finite_numbers_from_yaml(tmp_path):
    data = base()
    text = yaml.safe_dump(data).replace("mass: 41.0", "mass: .inf")
    text = text.replace("k_s: 2000.0", "k_s: .nan")
    text += "simulation:\n  t_end: .nan\n"
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, text))
    errors = info.value.errors
    assert errors == [
        "config key 'body.mass': found inf; expected a number > 0 (kg) (not a finite number)",
        "config key 'controller.k_s': found nan; expected a number >= 0 (N) (not a finite number)",
        "config key 'simulation.t_end': found nan; expected a number > 0 (s) (not a finite number)",
    ]
    line = single_problem(base(initial_state={"omega": [1.0, math.inf, 0.0]}))
    assert "found [1.0, inf, 0.0]" in line and "entry [1] is not a finite number" in line


@pytest.mark.parametrize("mass", [0, -41.0])
def test_mass_not_positive(mass):
    line = single_problem(base(body={"mass": mass}))
    assert line == f"config key 'body.mass': found {mass!r}; expected a number > 0 (kg)"


def test_gain_not_symmetric():
    k = [[1, 2, 0], [0, 1, 0], [0, 0, 1]]
    line = single_problem(base(controller={"k_r": k}))
    assert "config key 'controller.k_r': found [[1, 2, 0], [0, 1, 0], [0, 0, 1]]" in line
    assert "symmetric positive semi-definite (N m/rad)" in line
    assert "not symmetric: [0][1] = 2 but [1][0] = 0" in line


def test_gain_not_positive_semi_definite():
    line = single_problem(base(controller={"l_r": [60, -60, 42]}))
    assert "config key 'controller.l_r': found [60, -60, 42]" in line
    assert "symmetric positive semi-definite (N m s/rad)" in line
    assert "not positive semi-definite: diagonal [1] = -60; each must be >= 0" in line
    # symmetric, positive diagonal, but indefinite: eigenvalues 3 and -1
    line = single_problem(base(controller={"k_t": [[1, 2, 0], [2, 1, 0], [0, 0, 1]]}))
    assert "config key 'controller.k_t'" in line
    assert "not positive semi-definite: smallest eigenvalue -1" in line
    # negative definite
    line = single_problem(base(controller={"k_r": [-1, -2, -3]}))
    assert "diagonal [0] = -1, [1] = -2, [2] = -3; each must be >= 0" in line
    line = single_problem(base(controller={"k_c": [[-2, 1, 0], [1, -2, 0], [0, 0, -1]]}))
    assert "config key 'controller.k_c'" in line and "smallest eigenvalue -3" in line
    line = single_problem(base(controller={"k_s": -1.0}))
    assert line == "config key 'controller.k_s': found -1.0; expected a number >= 0 (N)"


def test_inertia_and_l_d_must_be_positive_definite():
    # the equations invert J (and J_p) and L_d (eq 22): singular ones are errors
    line = single_problem(base(body={"inertia": [3.0, 0.0, 5.0]}))
    assert "config key 'body.inertia': found [3.0, 0.0, 5.0]" in line
    assert "not positive definite: diagonal [1] = 0; each must be > 0" in line
    line = single_problem(base(controller={"l_d": [0, 0, 0]}))
    assert "config key 'controller.l_d': found [0, 0, 0]" in line
    assert "symmetric positive definite (N s/m)" in line
    assert "diagonal [0] = 0, [1] = 0, [2] = 0; each must be > 0" in line
    assert "L_d is inverted in dD/dt = L_d^-1" in line
    line = single_problem(base(controller={"l_d": [[1, 1, 0], [1, 1, 0], [0, 0, 1]]}))
    assert "not positive definite: smallest eigenvalue" in line and "L_d is inverted" in line
    # for every variant, so that one base config serves a sweep over variants
    line = single_problem(base(controller={"variant": "free", "l_d": [0, 1, 1]}))
    assert "config key 'controller.l_d'" in line


ZERO = [0, 0, 0]
ALL_ZERO = {g: ZERO for g in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d")}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_zero_gains_are_accepted_with_a_note(variant):
    # a torque-free body (free), a passive pendulum (permanent): valid physics
    data = base(controller={"variant": variant, **ALL_ZERO, "k_s": 0})
    with pytest.warns(SemiDefiniteGainWarning, match="v is then not a strict Lyapunov function"):
        cfg = config_from_mapping(data)
    used = VARIANTS[variant].required_gains
    for gain in used:
        if gain == "l_d":
            continue
        value = getattr(paper_form(cfg).gains, gain)
        assert np.all(np.asarray(value) == 0), gain
    (note,) = cfg.warnings
    code, _, keys = note.partition(":")[0].partition(" ")  # the code, then the keys sweeps' digest groups by
    assert code == "W002"
    keys = keys.split(", ")
    named = VARIANTS[variant].definite_gains or used
    assert keys == [f"controller.{g}" for g in named if g != "l_d"]
    assert "asymptotic stability is not implied" in note
    for g in named:
        if g != "l_d":
            assert f"{g} = 0" in note


def test_permanent_needs_no_translational_gains():
    # the pinned body's reduced state (Theta, Omega): v is definite with K_r alone and
    # dv/dt <= -Omega'L_r Omega (eqs 34, 37); k_t = l_t = 0 is no semi-definite v
    data = base(controller={"variant": "permanent", "k_t": [0, 0, 0], "l_t": [0, 0, 0]})
    with warnings.catch_warnings():
        warnings.simplefilter("error", SemiDefiniteGainWarning)
        cfg = config_from_mapping(data)
    assert not [w for w in cfg.warnings if w.startswith("W002")]
    # ... whose certificate agrees: v's Hessian positive definite on the reduced state
    from rbstab.analysis import analyze

    result = analyze(cfg, simulate=False, samples=200, falsification_runs=0)
    assert result.certificate.positive_definite
    # where the rotational gains are singular, the note stays
    with pytest.warns(SemiDefiniteGainWarning, match="controller.l_r"):
        config_from_mapping(base(controller={"variant": "permanent", "k_t": [0, 0, 0], "l_t": [0, 0, 0],
                                             "l_r": [0, 1, 1]}))


def test_singular_gain_note_names_the_directions():
    # eigenvalues 0, 2, 2: no damping along (1, -1, 0)/sqrt(2)
    l_r = [[1, 1, 0], [1, 1, 0], [0, 0, 2]]
    with pytest.warns(SemiDefiniteGainWarning) as caught:
        cfg = config_from_mapping(base(controller={"l_r": l_r}))
    assert len(caught) == 1
    assert cfg.warnings[0].startswith("W002 controller.l_r: positive semi-definite, not definite")
    assert "l_r has no stiffness or damping along (-0.7071, 0.7071, 0)" in cfg.warnings[0]
    np.testing.assert_array_equal(paper_form(cfg).gains.l_r, l_r)
    # a a' + b b' with a = (0.1, 0.3, 0.7), b = (0.2, -0.5, 0.3), written with decimals: exactly
    # singular (null vector a x b), but its zero eigenvalue computes as about -1e-17
    k_t = [[0.05, -0.07, 0.13], [-0.07, 0.34, 0.06], [0.13, 0.06, 0.58]]
    assert np.linalg.eigvalsh(np.array(k_t))[0] < 0
    with pytest.warns(SemiDefiniteGainWarning, match="controller.k_t"):
        config_from_mapping(base(controller={"k_t": k_t}))


def test_definite_gains_and_unused_singular_gains_give_no_note():
    # the fixture turns any PhysicalPlausibilityWarning (SemiDefiniteGainWarning included)
    # into an error: no note for positive definite gains, nor for singular unused ones
    assert issubclass(SemiDefiniteGainWarning, PhysicalPlausibilityWarning)
    cfg = config_from_mapping(base(controller={"variant": "free", "k_c": ZERO, "k_d": ZERO, "k_s": 0}))
    assert cfg.warnings == ()


@pytest.mark.parametrize(
    "variant, gains, key, detail",
    [
        # free: X_e = K_t^-1 G (eq 30) does not exist
        ("free", {"k_t": [4100, 4100, 0]}, "controller.k_t", "410 N along (0, 0, -1)"),
        ("free", {"k_t": ZERO}, "controller.k_t", "410 N along (0, 0, -1)"),
        # visco_elastic: K_t + K_c
        ("visco_elastic", {"k_t": ZERO, "k_c": [1, 1, 0]}, "controller.k_t", "K_t + K_c must resist"),
        # embedded: K_c in series with K_d, so K_d = 0 along z leaves z free
        ("embedded", {"k_t": ZERO, "k_d": [1, 1, 0]}, "controller.k_t", "in series with K_d"),
        # sliding: the force K_s sgn(E) must carry 410 N (strictly with a boundary layer)
        ("sliding", {"k_t": ZERO, "k_s": 400.0, "boundary_layer": 0.0}, "controller.k_s", "K_s >= 410 N"),
        ("sliding", {"k_t": ZERO, "k_s": 410.0, "boundary_layer": 0.01}, "controller.k_s", "K_s > 410 N"),
    ],
)
def test_gravity_needs_gains_that_hold_the_weight(variant, gains, key, detail):
    """Refused in either spelling: the same body written as a tree (``bodies``, ``joints``) is
    refused in the same line, named by its own keys, wherever its ground point lies."""
    from rbstab.config.loader import tree_resolved

    data = base(body={"gravity": [0, 0, -10]}, controller={"variant": variant, **gains})
    line = single_problem(data)
    assert line.startswith(f"config key '{key}': found ")
    assert "expected gains that hold the weight" in line
    assert "G = (0, 0, -410) N" in line and "there is no equilibrium" in line
    assert detail in line
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # singular gains: notes
        tree = tree_resolved(config_from_mapping(base(controller={"variant": variant, **gains})).resolved)
    tree["gravity"] = [0, 0, -10]
    field = key.partition(".")[2]
    tree_key = f"bodies.body.{field}" if field == "k_t" else f"joints.controller.{field}"
    for ground in (tree["joints"][0]["parent_point"], [0.3, -0.2, 1.0]):
        tree["joints"][0]["parent_point"] = ground
        assert single_problem(tree) == line.replace(f"'{key}'", f"'{tree_key}'", 1)


@pytest.mark.parametrize(
    "variant, gains",
    [
        ("free", {"k_t": [0, 0, 3280]}),  # singular, but stiff along the weight
        ("free", {"k_t": [[1, 1, 0], [1, 1, 0], [0, 0, 1]]}),
        ("visco_elastic", {"k_t": ZERO}),  # K_c holds it
        ("embedded", {"k_t": ZERO}),  # K_c in series with K_d holds it
        ("sliding", {"k_t": ZERO, "k_s": 410.0, "boundary_layer": 0.0}),
        ("sliding", {"k_t": ZERO, "k_s": 411.0, "boundary_layer": 0.01}),
        ("permanent", ALL_ZERO),  # the pivot holds it: a passive pendulum
    ],
)
def test_singular_gains_that_hold_the_weight_are_accepted(variant, gains):
    data = base(body={"gravity": [0, 0, -10]}, controller={"variant": variant, **gains})
    with pytest.warns(SemiDefiniteGainWarning):
        cfg = config_from_mapping(data)
    assert cfg.chain.joints[0].variant == variant


def _written_as_a_tree(data: dict) -> dict:
    """A one-body mapping as written (not validated) in a tree's spelling: its body ``body``
    held at R to the ground point R by its joint ``controller``; a permanent body's x, v left
    to be placed."""
    d = copy.deepcopy(data)
    body, ctrl, state = d.pop("body"), d.pop("controller"), d.pop("initial_state", {})
    point = body.pop("attachment_point")
    if "gravity" in body:
        d["gravity"] = body.pop("gravity")
    sat = ctrl.pop("saturation", None)
    tree_body = {"name": "body", **body, **{g: ctrl.pop(g) for g in ("k_t", "l_t") if g in ctrl}}
    joint = {"name": "controller", "parent": "ground", "parent_point": point, "child": "body", "child_point": point,
             **ctrl}
    if sat:
        shape = {"shape": sat["shape"]} if "shape" in sat else {}
        if "force_h" in sat:
            tree_body["saturation"] = {"force_h": sat["force_h"], **shape}
        if set(sat) & {"torque_n", "constraint_force"}:
            joint["saturation"] = {**{k: sat[k] for k in ("torque_n", "constraint_force") if k in sat}, **shape}
    if ctrl.get("variant") == "permanent":
        state = {k: v for k, v in state.items() if k not in ("x", "v")}
    d.update(bodies=[tree_body], joints=[joint], initial_state={"body": state})
    for entry in d.get("disturbances") or ():
        entry["body"] = "body"
    return d


_SIGN_LAW = {"variant": "sliding", "k_s": 100.0, "boundary_layer": 0.0}


@pytest.mark.parametrize("data", [
    base(controller={"variant": "permanent", "saturation": {"constraint_force": 10.0}}),
    base(controller={**_SIGN_LAW, "saturation": {"constraint_force": 10.0}}),
    base(controller=_SIGN_LAW, disturbances=[{"kind": "impulse", "value": [1, 0, 0], "start": 0.1}]),
    base(controller={"variant": "permanent"}, simulation={"limits": {"constraint_error": 1.0}}),
    base(initial_state={"theta": [0.0, 1.5705, 0.0]}),
    base(disturbances=[{"kind": "impulse", "value": [1, 0, 0], "start": 1e9}]),
    base(controller={"k_d": None}),
    base(controller={"variant": "sliding", "k_s": None}),
    base(simulation={"limits": {"position": 0.001}}, initial_state={"x": [1.0, 0.0, 0.0]}),
    base(body={"gravity": [0, 0, -10]}, controller={"variant": "free", "k_t": [4100, 4100, 0]}),
    base(body={"gravity": [0, 0, -10]}, controller={"k_t": ZERO, "k_d": [1, 1, 0]}),
    base(body={"mass": -1.0}),
    base(controller={"saturation": {"torque_n": 0.0}}),
], ids=["pin_force_limit", "sign_law_force_limit", "sign_law_disturbed", "pin_error_bound", "gimbal_lock",
        "late_disturbance", "missing_k_d", "missing_k_s", "start_outside_limits", "free_weight_unheld",
        "embedded_weight_unheld", "negative_mass", "zero_torque_limit"])
def test_what_one_body_refuses_its_tree_spelling_refuses_naming_the_same_key(data):
    """Refusal follows the physics, not the spelling: each one-body input refused is refused
    written as a tree too, in one line whose key is the same value's in the tree's keys
    (:func:`rbstab.config.loader.tree_keys`; a list entry by its name or its position)."""
    from rbstab.config.loader import tree_keys

    data = {section: value for section, value in data.items() if value is not None}
    data["controller"] = {k: v for k, v in data["controller"].items() if v is not None}
    line = single_problem(data)
    tree_line = single_problem(_written_as_a_tree(data))
    key = line.split("'")[1]
    tree_key = tree_line.split("'")[1].replace("bodies.0.", "bodies.body.").replace("joints.0.", "joints.controller.")
    assert tree_key in tree_keys(key), (line, tree_line)


def test_unheld_weight_names_the_override(tmp_path):
    path = write(tmp_path, yaml.safe_dump(base(controller={"variant": "free"})))
    overrides = ["controller.k_t=[1, 1, 0]", "body.gravity=[0, 0, -10]", "simulation.t_end=1"]
    with pytest.raises(ConfigError) as info:
        load_config(path, overrides)
    (line,) = info.value.errors
    assert "config key 'controller.k_t'" in line
    assert "[from override 'controller.k_t=[1, 1, 0]']" in line
    assert "[from override 'body.gravity=[0, 0, -10]']" in line
    assert "t_end" not in line


@pytest.mark.parametrize("theta_2", [1.6, -1.6, math.pi / 2])
def test_theta_2_outside_half_pi(theta_2):
    line = single_problem(base(initial_state={"theta": [0.0, theta_2, 0.0]}))
    assert f"config key 'initial_state.theta': found [0.0, {theta_2!r}, 0.0]" in line
    assert "theta_2 in (-pi/2, pi/2)" in line
    assert "gimbal lock" in line


def test_theta_2_inside_gimbal_margin():
    theta = [0.0, math.pi / 2 - 5e-4, 0.0]
    line = single_problem(base(initial_state={"theta": theta}))
    assert "config key 'initial_state.theta'" in line
    assert "theta_2 in (-pi/2 + gimbal_margin, pi/2 - gimbal_margin) = (-1.5698, 1.5698)" in line
    assert "gimbal_margin = 0.001" in line
    data = base(initial_state={"theta": theta}, simulation={"gimbal_margin": 1e-4})
    cfg = config_from_mapping(data)
    assert cfg.initial_state["body"]["theta"][1] == theta[1]


def test_gain_required_by_variant_missing():
    data = base()
    del data["controller"]["k_c"]
    line = single_problem(data)
    assert line.startswith("config key 'controller.k_c': missing; expected 3 numbers (a diagonal)")
    assert "required by variant 'embedded'" in line
    data = base(controller={"variant": "sliding"})
    del data["controller"]["k_s"]
    assert single_problem(data) == (
        "config key 'controller.k_s': missing; expected a number >= 0 (N) "
        "(required by variant 'sliding')"
    )
    # the same mapping is fine for a variant that does not use k_s
    assert config_from_mapping({**data, "controller": {**data["controller"], "variant": "free"}})


def test_t_end_not_positive():
    for t_end in (0, -1.0):
        line = single_problem(base(simulation={"t_end": t_end}))
        assert line == f"config key 'simulation.t_end': found {t_end!r}; expected a number > 0 (s)"


def test_unknown_solver_method():
    line = single_problem(base(simulation={"method": "dop853"}))
    assert "config key 'simulation.method': found 'dop853'" in line
    assert "expected one of" in line and "DOP853" in line and "Radau" in line and "LSODA" in line
    assert "did you mean 'DOP853'?" in line


def test_every_scipy_method_accepted():
    from scipy.integrate._ivp.ivp import METHODS

    from rbstab.config.schema import SOLVER_METHODS

    # validation lists scipy's methods without importing scipy.integrate: the list must be scipy's
    assert set(SOLVER_METHODS) == set(METHODS)
    for method in METHODS:
        assert config_from_mapping(base(simulation={"method": method})).simulation.method == method


def test_unknown_variant():
    line = single_problem(base(controller={"variant": "embeded"}))
    assert "config key 'controller.variant': found 'embeded'" in line
    assert "expected one of free, permanent, sliding, visco_elastic, embedded" in line
    assert "did you mean 'embedded'?" in line


@pytest.mark.parametrize("name", ["my case", "a/b", "", "..", 12])
def test_bad_name(name):
    line = single_problem(base(name=name))
    assert line.startswith(f"config key 'name': found {name!r}; expected a name of letters, digits")


def test_bad_default_name_from_file(tmp_path):
    data = base()
    del data["name"]
    path = write(tmp_path, yaml.safe_dump(data), name="my case.yaml")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert "config key 'name': found 'my case'" in str(info.value)
    assert "set 'name:' in the config" in str(info.value)


def test_other_simulation_ranges():
    for key, value in [("n_samples", 1), ("atol", 0), ("max_step", -1), ("gimbal_margin", 0.5)]:
        line = single_problem(base(simulation={key: value}))
        assert line.startswith(f"config key 'simulation.{key}': found {value!r}; expected a")
    line = single_problem(base(simulation={"gimbal_margin": 0.5}))
    assert line.endswith("expected a number in (0, 0.5) (rad)")
    line = single_problem(base(controller={"boundary_layer": -0.1}))
    assert line.startswith(
        "config key 'controller.boundary_layer': found -0.1; expected a number >= 0"
    )


def test_section_not_a_mapping():
    line = single_problem(base(body=[41.0]))
    assert line.startswith(
        "config key 'body': found [41.0]; expected a mapping with keys mass, inertia"
    )


def test_all_problems_reported_at_once():
    data = base(
        body={"mass": -1, "inertia": [1, 2]},
        controller={"k_tt": 1, "l_c": [[1, 2, 0], [0, 1, 0], [0, 0, 1]]},
        simulation={"t_end": 0, "method": "euler"},
        initial_state={"theta": [0, 2, 0]},
        name="a b",
    )
    del data["controller"]["l_d"]
    errors = problems(data)
    keys = [e.split("'")[1] for e in errors]
    assert sorted(keys) == sorted(
        [
            "name",
            "body.mass",
            "body.inertia",
            "controller.k_tt",
            "controller.l_c",
            "controller.l_d",
            "simulation.t_end",
            "simulation.method",
            "initial_state.theta",
        ]
    )


def test_config_error_format_and_pickle(tmp_path):
    path = write(tmp_path, yaml.safe_dump(base(body={"mass": 0}, simulation={"t_end": 0})))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.source == str(path)
    assert str(err).splitlines() == [f"in {path}:"] + err.errors
    assert len(err.errors) == 2
    clone = pickle.loads(pickle.dumps(err))
    assert (clone.errors, clone.source, str(clone)) == (err.errors, err.source, str(err))


def test_long_found_value_truncated():
    line = single_problem(base(initial_state={"omega": list(range(50))}))
    assert "found [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, ...]; expected" in line
    line = single_problem(base(name="x y" * 100))
    found = line.split("found ", 1)[1].split("; expected")[0]
    assert len(found) == 80 and found.startswith("'x yx y") and found.endswith("...")


# -- files -----------------------------------------------------------------------------------------


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="config file not found: .*nope.yaml"):
        load_config(tmp_path / "nope.yaml")


def test_yaml_syntax_error(tmp_path):
    path = write(tmp_path, "body:\n  mass: [41\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value).startswith(f"in {path}:\nYAML syntax error at line")


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "the configuration is empty; expected a mapping"),
        ("- 1\n- 2\n", "top level: found [1, 2]; expected a mapping"),
    ],
)
def test_top_level_not_a_mapping(tmp_path, text, message):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, text))
    assert message in str(info.value)
    assert "with keys name, body, controller, initial_state, simulation" in str(info.value)


def test_duplicate_key_is_an_error(tmp_path):
    text = yaml.safe_dump(base(), sort_keys=False).replace("  k_t:", "  k_r: [1, 1, 1]\n  k_t:", 1)
    with pytest.raises(ConfigError, match=r"found the key 'k_r' twice \(first at line \d+\)"):
        load_config(write(tmp_path, text))


def test_yaml_exponent_without_dot_is_a_float(tmp_path):
    text = yaml.safe_dump(base()) + "simulation:\n  rtol: 1e-6\n  atol: 2E-9\n  n_samples: 11\n"
    cfg = load_config(write(tmp_path, text))
    assert (cfg.simulation.rtol, cfg.simulation.atol, cfg.simulation.n_samples) == (1e-6, 2e-9, 11)


# -- warnings --------------------------------------------------------------------------------------


def test_triangle_inequality_warning():
    data = base(body={"inertia": [10.0, 8.0, 0.4]})
    match = r"body.inertia.*triangle inequality.*10 > 8 \+ 0.4"
    with pytest.warns(PhysicalPlausibilityWarning, match=match):
        cfg = config_from_mapping(data)
    assert len(cfg.warnings) == 1 and "triangle inequality" in cfg.warnings[0]


def test_triangle_inequality_warning_for_full_matrix():
    # diag(10, 8, 0.4) rotated about z: not diagonal, same principal moments
    c, s = math.cos(0.3), math.sin(0.3)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    j = (rot @ np.diag([10.0, 8.0, 0.4]) @ rot.T).tolist()
    j = [[0.5 * (j[i][k] + j[k][i]) for k in range(3)] for i in range(3)]
    with pytest.warns(PhysicalPlausibilityWarning, match="triangle inequality"):
        config_from_mapping(base(body={"inertia": j}))


def test_triangle_equality_does_not_warn():
    # a flat plate has j3 = j1 + j2 exactly: physical, no warning (the fixture makes it an error)
    cfg = config_from_mapping(base(body={"inertia": [1.0, 2.0, 3.0]}))
    assert cfg.warnings == ()


# -- round trip ------------------------------------------------------------------------------------


def assert_same_config(a: RunConfig, b: RunConfig):
    for field in ("name", "warnings"):
        assert getattr(a, field) == getattr(b, field)
    assert a.chain.joints[0].variant == b.chain.joints[0].variant
    # the admissible region's bounds are arrays: compared as such, the other settings as they are
    assert dataclasses.replace(a.simulation, limits=None) == dataclasses.replace(b.simulation, limits=None)
    assert (a.simulation.limits is None) == (b.simulation.limits is None)
    if a.simulation.limits is not None:
        for field in dataclasses.fields(a.simulation.limits):
            np.testing.assert_array_equal(getattr(a.simulation.limits, field.name),
                                          getattr(b.simulation.limits, field.name))
    assert a.resolved == b.resolved
    for field in ("mass", "inertia", "attachment_point", "gravity"):
        np.testing.assert_array_equal(getattr(paper_form(a).body, field), getattr(paper_form(b).body, field))
    for field in ("k_t", "l_t", "k_r", "l_r", "k_c", "l_c", "k_d", "l_d", "k_s", "boundary_layer"):
        x, y = getattr(paper_form(a).gains, field), getattr(paper_form(b).gains, field)
        assert (x is None) == (y is None)
        if x is not None:
            np.testing.assert_array_equal(x, y)
    assert a.initial_state.keys() == b.initial_state.keys() == {"body"}
    assert a.initial_state["body"].keys() == b.initial_state["body"].keys()
    for block in a.initial_state["body"]:
        np.testing.assert_array_equal(a.initial_state["body"][block], b.initial_state["body"][block])


@pytest.mark.parametrize("max_step", [None, 0.01])
def test_round_trip(max_step):
    data = base(controller={"k_t": [[4100, 10, 0], [10, 4100, 0], [0, 0, 3280]]})
    if max_step is not None:
        data["simulation"] = {"max_step": max_step}
    cfg = config_from_mapping(data)
    resolved = cfg.resolved
    assert list(resolved) == ["name", "body", "controller", "initial_state", "simulation"]
    assert resolved["controller"]["l_t"] == [200, 200, 140]  # 3 numbers stay 3 numbers
    assert resolved["simulation"] == {
        "t_end": 2.0,
        "n_samples": 2001,
        "method": "DOP853",
        "rtol": 1e-8,
        "atol": 1e-10,
        "max_step": max_step,  # inf is written as null
        "gimbal_margin": 1e-3,
        "max_steps": 1_000_000,
        "max_wall_time": 600.0,
    }
    assert resolved["initial_state"]["d"] == [0.0, 0.0, 0.0]
    assert_same_config(config_from_mapping(resolved), cfg)
    reread = yaml.safe_load(cfg.to_yaml())
    assert reread == resolved
    assert_same_config(config_from_mapping(reread), cfg)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_config_round_trip(path, tmp_path):
    with warnings.catch_warnings():  # some warn (the paper's inertia), some not (saturated_pendulum)
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        cfg = load_config(path)
        again = load_config(write(tmp_path, cfg.to_yaml(), name="other_stem.yaml"))
    assert_same_config(again, cfg)


def test_explicit_infinite_max_step(tmp_path):
    text = yaml.safe_dump(base()) + "simulation:\n  max_step: .inf\n"
    cfg = load_config(write(tmp_path, text))
    assert cfg.simulation.max_step == math.inf
    assert cfg.resolved["simulation"]["max_step"] is None


# -- overrides and dotted paths --------------------------------------------------------------


def test_apply_overrides():
    data = base()
    snapshot = copy.deepcopy(data)
    out = apply_overrides(
        data,
        [
            "controller.k_t=[1,2,3]",
            "simulation.t_end=1.5",
            "controller.variant=free",
            "initial_state.omega.0=5",
            "simulation.rtol = 1e-6",
            "name=other",
        ],
    )
    assert data == snapshot  # a deep copy
    assert out["controller"]["k_t"] == [1, 2, 3]
    assert out["simulation"] == {"t_end": 1.5, "rtol": 1e-6}
    assert out["controller"]["variant"] == "free"
    assert out["initial_state"]["omega"] == [5, 32, -16]
    assert out["name"] == "other"
    cfg = config_from_mapping(out)
    assert (cfg.chain.joints[0].variant, cfg.simulation.t_end, cfg.simulation.rtol) == ("free", 1.5, 1e-6)
    np.testing.assert_array_equal(paper_form(cfg).gains.k_t, np.diag([1, 2, 3]))


def test_load_config_with_overrides(tmp_path):
    path = write(tmp_path, yaml.safe_dump(base()))
    cfg = load_config(path, ["initial_state.omega.1=0.5", "controller.variant=visco_elastic"])
    assert cfg.initial_state["body"]["omega"][1] == 0.5
    assert cfg.chain.joints[0].variant == "visco_elastic"
    assert cfg.resolved["initial_state"]["omega"] == [16, 0.5, -16]


def test_override_index_into_schema_default():
    """theta is absent from BASE: indexing it starts from its default [0, 0, 0]."""
    out = apply_overrides(BASE, ["initial_state.theta.1=0.5", "body.gravity.2=-9.81"])
    assert out["initial_state"]["theta"] == [0.0, 0.5, 0.0]
    assert out["body"]["gravity"] == [0.0, 0.0, -9.81]
    cfg = config_from_mapping(out)
    np.testing.assert_array_equal(cfg.initial_state["body"]["theta"], [0.0, 0.5, 0.0])


def test_override_of_an_unknown_key_is_refused_naming_the_closest(tmp_path):
    path = write(tmp_path, yaml.safe_dump(base()))
    with pytest.raises(ConfigError) as info:
        load_config(path, ["controller.k_tt=[1,2,3]", "simulation.t_end=-1"])
    (line,) = info.value.errors
    assert line.startswith("override 'controller.k_tt=[1,2,3]': 'controller' has no 'k_tt'; did you mean "
                           "'controller.k_t'? (allowed: variant, k_t,")
    with pytest.raises(ConfigError) as info:  # a valid key with an invalid value: the schema says why
        load_config(path, ["simulation.t_end=-1"])
    (line,) = info.value.errors
    assert line.startswith("config key 'simulation.t_end': found -1;")
    assert line.endswith("[from override 'simulation.t_end=-1']")


@pytest.mark.parametrize(
    "override, message",
    [
        ("simulation.t_end", "no '='"),
        ("=3", "expected a dotted key"),
        ("controller..k_t=1", "segment 2 of 3 is empty"),
        ("initial_state.omega.3=1", "'initial_state.omega' is a list of 3; index it with 0..2, not '3'"),
        ("initial_state.omega.x=1", "'initial_state.omega' is a list of 3; index it with 0..2, not 'x'"),
        ("controller.variant.x=1", "'controller.variant' is one of free, "),
        ("body.mass.0=1", "'body.mass' is a number > 0 (kg); it has no entry '0'"),
        ("extra.list.0=1", "unknown section 'extra'"),
        ("disturbances.0.start=1", "'disturbances' is not set, so it has no entry '0'; set the whole list"),
        ("controller.k_t=[1,", "not valid YAML"),
    ],
)
def test_bad_override(override, message, tmp_path):
    with pytest.raises(ConfigError) as info:
        apply_overrides(BASE, [override])
    (line,) = info.value.errors
    assert line.startswith(f"override {override!r}: ")
    assert message in line
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, yaml.safe_dump(base())), ["simulation.t_end=1", override])
    assert info.value.source is not None and len(info.value.errors) == 1


def test_bad_overrides_all_reported():
    with pytest.raises(ConfigError) as info:
        apply_overrides(BASE, ["a", "initial_state.omega.9=1", "simulation.t_end=3"])
    assert len(info.value.errors) == 2


def test_key_path_reads_and_sets_a_config():
    data = base()
    assert parse_key("body.mass").get(data) == data["body"]["mass"]
    assert parse_key("initial_state.omega.1").get(data) == data["initial_state"]["omega"][1]
    assert parse_key("initial_state.theta.1").get(data, None) is None  # not set in the mapping
    parse_key("controller.k_t.1").set(data, 7.0)
    assert data["controller"]["k_t"][1] == 7.0
    parse_key("controller.saturation.torque_n").set(data, 5.0)  # the subsection is created
    assert data["controller"]["saturation"] == {"torque_n": 5.0}
    parse_key("controller.saturation.torque_n.2").set(data, 1.0)  # one limit: the 3 it stands for
    assert data["controller"]["saturation"]["torque_n"] == [5.0, 5.0, 1.0]
    data["body"]["inertia"] = [10.0, 8.0, 4.0]  # a diagonal
    assert parse_key("body.inertia.0.1").get(data) == 0.0 and parse_key("body.inertia.2.2").get(data) == 4.0
    parse_key("body.inertia.0.1").set(data, 0.5)  # off the diagonal: the matrix it stands for
    assert data["body"]["inertia"] == [[10.0, 0.5, 0.0], [0.0, 8.0, 0.0], [0.0, 0.0, 4.0]]
    with pytest.raises(ConfigError, match="'disturbances' is not set"):
        parse_key("disturbances.0.start").set(data, 1.0)
    with pytest.raises(ConfigError, match="'initial_state.theta' is not set"):
        parse_key("initial_state.theta.0").get(data)


def test_yaml_text_does_not_depend_on_the_emitter():
    """Config hashes (resume) must not change with PyYAML's C or Python emitter."""
    import yaml

    from rbstab.config import dump_yaml

    class PythonDumper(yaml.SafeDumper):
        def represent_list(self, data):
            return self.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)

    PythonDumper.add_representer(list, PythonDumper.represent_list)
    rng = np.random.default_rng(3)
    for path in SHIPPED:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = load_config(path).resolved
        data["body"]["mass"] = float(rng.lognormal(3, 4))
        data["name"] = "r0001-ünïcode"
        assert dump_yaml(data) == yaml.dump(data, Dumper=PythonDumper, sort_keys=False, allow_unicode=True)


def test_config_yaml_by_sections_is_the_whole_dump():
    """RunConfig.to_yaml caches the text of unchanged sections; it must be dump_yaml's text."""
    from rbstab.config import dump_yaml

    rng = np.random.default_rng(4)
    for path in SHIPPED:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            config = load_config(path)
        for i in range(3):
            if i:
                data = copy.deepcopy(config.resolved)
                data["body"]["mass"] = float(rng.lognormal(3, 4))
                data["initial_state"]["omega"] = [float(x) for x in rng.normal(0, 1e3, 3)]
                data["simulation"]["max_step"] = None if i == 1 else 0.5
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    config = config_from_mapping(data)
            assert config.to_yaml() == dump_yaml(config.resolved)
            assert config.to_yaml() == config.to_yaml()  # from the cache


def test_from_resolved_like_shares_only_equal_sections():
    """from_resolved(like=...) shares the tree and settings with a config whose body,
    controller and simulation sections are equal, and gives what a rebuild alone gives."""
    import warnings as _warnings

    from rbstab.config import RunConfig, config_from_mapping, load_config

    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore")
        base = load_config(Path(__file__).resolve().parents[1] / "configs" / "paper" / "case3_embedded.yaml")
        spun = config_from_mapping({**base.resolved, "name": "spun",
                                    "initial_state": {**base.resolved["initial_state"], "omega": [1.0, 2.0, 3.0]}})
    first = RunConfig.from_resolved(base.resolved)
    heavy = RunConfig.from_resolved({**base.resolved, "body": {**base.resolved["body"], "mass": 50.0}})
    shared = RunConfig.from_resolved(spun.resolved, like=[heavy, first])  # the first equal one
    assert shared.chain is first.chain and shared.simulation is first.simulation
    alone = RunConfig.from_resolved(spun.resolved)
    assert shared.name == alone.name == "spun" and shared.resolved is spun.resolved
    assert all(np.array_equal(shared.initial_state["body"][k], alone.initial_state["body"][k])
               for k in alone.initial_state["body"])
    assert shared.initial_state["body"]["omega"].tolist() == [1.0, 2.0, 3.0]
    for key in ("body.mass=30", "controller.l_c=[1, 2, 3]", "simulation.rtol=1e-7"):
        section, rest = key.split(".", 1)
        name, value = rest.split("=")
        data = {**spun.resolved, section: {**spun.resolved[section], name: yaml.safe_load(value)}}
        other = RunConfig.from_resolved(data, like=[first])
        assert other.chain is not first.chain, key
        assert other.simulation is not first.simulation, key
        assert other.resolved[section][name] == yaml.safe_load(value)


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[1] / "configs").glob("*/*.yaml")))
def test_from_resolved_rebuilds_the_validated_config(path):
    """RunConfig.from_resolved (the sweep workers' path) gives what validation gives, in
    either spelling: the same compiled records bit for bit, the same placed initial state."""
    import dataclasses

    import warnings as _warnings

    from rbstab.config import RunConfig, load_config
    from rbstab.variants.chain import compile_chain

    if "sweeps" in path.parts:
        pytest.skip("a sweep spec")
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore")
        config = load_config(path)
    rebuilt = RunConfig.from_resolved(config.resolved)
    a, b = (compile_chain(c.chain, offset=0.0) for c in (config, rebuilt))
    for name in ("params", "codes", "parents", "ppoints", "d_at", "n_states"):
        assert np.asarray(getattr(a, name)).tobytes() == np.asarray(getattr(b, name)).tobytes(), name
    assert len(a.args) == len(b.args)
    assert all(np.asarray(x).tobytes() == np.asarray(y).tobytes() for x, y in zip(a.args, b.args))
    assert rebuilt.name == config.name and rebuilt.resolved is config.resolved and rebuilt.placed == config.placed
    assert config.initial_state.keys() == rebuilt.initial_state.keys()
    for body, blocks in config.initial_state.items():
        assert blocks.keys() == rebuilt.initial_state[body].keys()
        assert all(blocks[k].tobytes() == rebuilt.initial_state[body][k].tobytes() for k in blocks), body
    s, r = config.simulation, rebuilt.simulation
    assert dataclasses.replace(s, limits=None) == dataclasses.replace(r, limits=None)
    assert (s.limits is None) == (r.limits is None)
    if s.limits is not None:  # configs/examples/stance_ankle.yaml
        assert s.limits.array.tobytes() == r.limits.array.tobytes()


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[1] / "configs").glob("paper/*.yaml")))
def test_resolved_is_plain_and_shares_nothing_with_the_input(path):
    """``RunConfig.resolved`` (hashed, dumped, sent to workers) holds only dicts, lists, str,
    numbers, bools and None, and no container of the mapping it was made from (changing
    that mapping afterwards changes nothing); nor does ``with_initial_state``'s."""
    import numpy as np
    import yaml

    from rbstab.config import config_from_mapping

    data = yaml.safe_load(path.read_text())
    data["initial_state"] = {"omega": np.array([1.0, 2.0, 3.0]), "theta": (0.1, 0.0, 0.0)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = config_from_mapping(data)
        moved = config.with_initial_state({"omega": [4.0, 5.0, 6.0]})

    def containers(tree):
        if isinstance(tree, dict):
            yield tree
            for v in tree.values():
                yield from containers(v)
        elif isinstance(tree, list):
            yield tree
            for v in tree:
                yield from containers(v)
        else:
            assert type(tree) in (str, int, float, bool, type(None)), repr(tree)

    resolved = {id(c) for tree in (config.resolved, moved.resolved) for c in containers(tree)}
    inputs = set()
    stack = [data]
    while stack:
        node = stack.pop()
        if isinstance(node, (dict, list)):
            inputs.add(id(node))
            stack.extend(node.values() if isinstance(node, dict) else node)
    assert resolved and not inputs & resolved
    assert config.resolved["initial_state"]["omega"] == [1.0, 2.0, 3.0]
    assert moved.resolved["initial_state"]["omega"] == [4.0, 5.0, 6.0]
