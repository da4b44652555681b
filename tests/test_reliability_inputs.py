"""Reliability of the input side: any input loads or is refused with rbstab's own error.

Property-based (hypothesis) tests of the YAML reader, the config loader, ``--set``
overrides and the sweep-spec loader, and tests of each documented limit
(docs/reliability.md): YAML size, depth and alias expansion, regular files only,
magnitudes, names, samples, max_step against t_end and max_steps.

Hypothesis runs derandomized (the same examples on every run, for CI); set
``HYPOTHESIS_PROFILE=explore`` to search with fresh random examples.
"""

from __future__ import annotations

import copy
import math
import os
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rbstab.config import ConfigError, RunConfig, config_from_mapping, load_config, parse_yaml
from rbstab.config.schema import MAX_MAGNITUDE, MAX_NAME_LENGTH, MAX_SAMPLES
from rbstab.config.yaml_io import MAX_YAML_BYTES, MAX_YAML_DEPTH, MAX_YAML_NODES, read_yaml_file
from rbstab.sweep import SweepSpecError, expand, spec_from_mapping

from conftest import ROOT

settings.register_profile("ci", derandomize=True, database=None, deadline=None, max_examples=150,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("explore", database=None, deadline=None, max_examples=2000,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
CASE3_DATA = yaml.safe_load(CASE3.read_text())

# -- strategies -----------------------------------------------------------------------------

SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(), st.integers(min_value=-10**400, max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20),
    st.sampled_from(["DOP853", "embedded", "free", ".inf", "1e-8", "", "0", "-1", "nan"]),
)
TREES = st.recursive(
    SCALARS,
    lambda children: st.one_of(st.lists(children, max_size=5),
                               st.dictionaries(st.text(max_size=12), children, max_size=5)),
    max_leaves=25,
)
#: Every key of the config schema, some list entries, and keys that do not exist.
KEYS = [
    "name", "body", "body.mass", "body.inertia", "body.inertia.0", "body.attachment_point", "body.gravity",
    "controller", "controller.variant", "controller.k_t", "controller.k_t.1", "controller.l_d", "controller.k_s",
    "controller.boundary_layer", "initial_state", "initial_state.theta", "initial_state.theta.1",
    "initial_state.omega", "initial_state.d", "simulation", "simulation.t_end", "simulation.n_samples",
    "simulation.method", "simulation.rtol", "simulation.atol", "simulation.max_step", "simulation.gimbal_margin",
    "simulation.max_steps", "simulation.max_wall_time", "extra", "body.extra",
]


def _set(data: dict, dotted: str, value) -> None:
    """``data[a][b][0] = value`` for ``a.b.0`` where the path exists (else nothing)."""
    node = data
    *path, last = dotted.split(".")
    for part in path:
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict):
            node = node.setdefault(part, {})
        else:
            return
    if isinstance(node, list) and last.isdigit() and int(last) < len(node):
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value


def _loads_or_refuses(call) -> None:
    """The property: ``call()`` returns or raises ConfigError, nothing else."""
    try:
        call()
    except ConfigError as exc:
        assert exc.errors and all(isinstance(line, str) and line for line in exc.errors)


# -- properties -----------------------------------------------------------------------------


@given(st.text(max_size=300))
def test_any_text_parses_or_is_a_config_error(text):
    _loads_or_refuses(lambda: parse_yaml(text))


@given(TREES)
def test_any_tree_validates_or_is_a_config_error(tree):
    _loads_or_refuses(lambda: config_from_mapping(tree, default_name="x"))


@given(st.lists(st.tuples(st.sampled_from(KEYS), TREES), min_size=1, max_size=4))
def test_a_valid_config_with_any_values_validates_or_is_a_config_error(changes):
    data = copy.deepcopy(CASE3_DATA)
    for key, value in changes:
        _set(data, key, value)
    _loads_or_refuses(lambda: config_from_mapping(data))


@given(st.lists(st.text(max_size=40), max_size=3))
def test_any_set_override_applies_or_is_a_config_error(overrides):
    _loads_or_refuses(lambda: load_config(CASE3, overrides))


SMALL = st.one_of(st.integers(-3, 12), st.floats(-1e3, 1e3), st.text(max_size=8), st.none(), st.booleans())
SMALL_TREES = st.recursive(SMALL, lambda c: st.one_of(st.lists(c, max_size=3), st.dictionaries(
    st.text(max_size=8), c, max_size=3)), max_leaves=8)
SPEC_KEYS = st.sampled_from(["body.mass", "controller.k_c", "controller.k_c.0", "controller.variant",
                             "initial_state.omega", "initial_state.theta.1", "simulation.t_end", "nothing.here", "",
                             "body.inertia.3"])
DISTRIBUTIONS = st.one_of(
    SMALL_TREES,
    st.dictionaries(st.sampled_from(["uniform", "normal", "log_uniform", "scale_uniform", "choice", "beta"]),
                    SMALL_TREES, min_size=1, max_size=2),
)


@given(
    grid=st.one_of(SMALL_TREES, st.dictionaries(SPEC_KEYS, st.lists(SMALL_TREES, max_size=3), max_size=2)),
    zipped=st.one_of(st.none(), st.dictionaries(SPEC_KEYS, st.lists(SMALL_TREES, max_size=3), max_size=2)),
    random=st.one_of(st.none(), SMALL_TREES, st.fixed_dictionaries({
        "n": SMALL, "seed": SMALL, "params": st.dictionaries(SPEC_KEYS, DISTRIBUTIONS, max_size=2)})),
    extra=st.dictionaries(st.sampled_from(["name", "convergence", "bases", "base"]), SMALL_TREES, max_size=1),
)
def test_any_sweep_spec_plans_or_is_a_sweep_spec_error(grid, zipped, random, extra):
    """Sizes stay small here (a random.n of 1e9 is planned in memory: the planner's limit
    on sweep sizes is the next step, not this test's)."""
    data = {"name": "prop", "base": copy.deepcopy(CASE3_DATA), "grid": grid, "zip": zipped, "random": random}
    data.update(extra)
    try:
        expand(spec_from_mapping(data))
    except SweepSpecError as exc:
        assert exc.errors


# -- the YAML limits ------------------------------------------------------------------------


def test_nested_aliases_are_refused_before_they_expand():
    lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):  # 9^10 values once expanded, from 400 bytes
        lines.append(f"{chr(97 + i)}: &{chr(97 + i)} [" + ", ".join([f"*{chr(96 + i)}"] * 9) + "]")
    with pytest.raises(ConfigError, match=f"more than {MAX_YAML_NODES} values once aliases are expanded"):
        parse_yaml("\n".join(lines))


@pytest.mark.parametrize("text, problem", [
    ("a: " + "[" * 5000 + "]" * 5000, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    ("a: &a [*a]", "refers to a value that contains it"),
    ("x: !!float abc", "YAML value error"),
    ("x: !!python/object/apply:os.system [echo hacked]", "YAML syntax error"),
])
def test_dangerous_yaml_is_refused_in_one_line(text, problem):
    with pytest.raises(ConfigError, match=problem) as info:
        parse_yaml(text)
    assert len(info.value.errors) == 1


def test_only_regular_files_of_bounded_size_are_read(tmp_path):
    with pytest.raises(ConfigError, match="not a regular file"):
        read_yaml_file("/dev/zero")
    with pytest.raises(ConfigError, match="is a folder"):
        read_yaml_file(tmp_path)
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * (MAX_YAML_BYTES + 1))
    with pytest.raises(ConfigError, match=f"at most {MAX_YAML_BYTES} are read"):
        read_yaml_file(big)
    if hasattr(os, "mkfifo"):  # a FIFO nobody writes would block a reader forever
        fifo = tmp_path / "fifo.yaml"
        os.mkfifo(fifo)
        with pytest.raises(ConfigError, match="not a regular file"):
            load_config(fifo)


# -- the documented bounds on values ------------------------------------------------------------


def _problem(**changes) -> str:
    data = copy.deepcopy(CASE3_DATA)
    for key, value in changes.items():
        _set(data, key.replace("__", "."), value)
    with pytest.raises(ConfigError) as info:
        config_from_mapping(data)
    assert len(info.value.errors) == 1, info.value.errors
    return info.value.errors[0]


def test_magnitudes_that_overflow_the_dynamics_are_refused():
    assert "beyond 1e+12 in magnitude" in _problem(body__mass=1e13)
    assert "beyond 1e+12 in magnitude" in _problem(initial_state__omega=[1e200, 0, 0])
    assert "an integer of 401 digits" in _problem(body__mass=10**400)  # no OverflowError
    assert "below 1e-12" in _problem(body__inertia=[1e-300, 1, 1])
    assert "below 1e-12" in _problem(controller__l_d=[1e-13, 1, 1])  # l_d is inverted (eq 22)
    config_from_mapping({**CASE3_DATA, "body": {**CASE3_DATA["body"], "mass": MAX_MAGNITUDE}})  # the limit itself


def test_names_samples_and_steps_are_bounded_with_the_reason():
    assert f"at most {MAX_NAME_LENGTH}" in _problem(name="a" * (MAX_NAME_LENGTH + 1))
    line = _problem(simulation__n_samples=10**9)
    assert f"[2, {MAX_SAMPLES}]" in line and "GiB" in line  # the memory estimate
    line = _problem(simulation__max_step=1e-300)
    assert "config key 'simulation.max_step'" in line and "more than simulation.max_steps" in line
    line = _problem(simulation__t_end=1e-300)
    assert "config key 'simulation.t_end'" in line and "apart" in line
    assert "an integer in [1, " in _problem(simulation__max_steps=0)


def test_limits_are_not_part_of_a_runs_identity():
    from rbstab.config import canonical_config

    a = config_from_mapping(CASE3_DATA)
    b = config_from_mapping({**CASE3_DATA, "simulation": {**CASE3_DATA.get("simulation", {}), "max_steps": 10,
                                                          "max_wall_time": None}})
    assert b.simulation.max_steps == 10 and math.isinf(b.simulation.max_wall_time)
    assert canonical_config(a.resolved) == canonical_config(b.resolved)
    assert RunConfig.from_resolved(b.resolved).simulation == b.simulation


@pytest.mark.parametrize("index", ["²", "١", "٣", "+1", " 1"])
def test_list_indices_in_set_are_ascii_digits(index):
    with pytest.raises(ConfigError, match="override|malformed"):
        load_config(CASE3, [f"initial_state.omega.{index}=3"])
