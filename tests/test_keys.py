"""Key paths: one reading for every command (:func:`rbstab.config.paths.parse_key`).

A key mutated from a valid one (a word for an index, an index for a word, a float, a sign,
a digit of another script, an empty or doubled dot, a path too long) is refused by every
entry point (``--set``, a spec's grid, zip, random and table, ``--grid``, ``--zip``,
``--random``, ``--vary``, ``--over``, ``--basin``, ``--basin-stability``, the API): a non-zero
exit, no traceback, one line naming the key, nothing written. A valid key sets the same
value through every entry point, the one ``parse_key`` reads back from the configuration.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Annotated, Any

import pytest
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from rbstab_cli.main import cli

from rbstab import api
from rbstab.analysis.basin import BasinAxis
from rbstab.config.paths import KeyPathError, parse_key
from rbstab.studies import sensitivity_analysis
from rbstab.studies.tuning import plan_tuning
from rbstab.sweep import spec_from_mapping
from rbstab.sweep.table import plan_table

ROOT = Path(__file__).resolve().parents[1]
CASE3 = yaml.safe_load((ROOT / "configs" / "paper" / "case3_embedded.yaml").read_text(encoding="utf-8"))
# Case 3 with an inertia a body can have (no warning line), a limit, a bound and a disturbance,
# so that every kind of key below names something the configuration has.
BASE = copy.deepcopy(CASE3)
BASE["name"] = "keys"
BASE["body"]["inertia"] = [10.0, 8.0, 4.0]
BASE["controller"]["saturation"] = {"torque_n": 500.0}
BASE["simulation"].update(t_end=0.5, n_samples=51, limits={"theta": 1.0})
BASE["disturbances"] = [{"kind": "impulse", "value": [1.0, 0.0, 0.0], "point": [0.0, 0.0, 0.0], "start": 0.1}]

#: Valid keys of BASE, each with the range of values that keeps the configuration valid.
VALID = {
    "body.mass": (20.0, 60.0),
    "body.inertia.0.0": (9.0, 11.0),  # a diagonal entry of the matrix 3 numbers stand for
    "controller.k_c.1": (1000.0, 20000.0),  # one entry of a gain written as its diagonal
    "controller.k_r.0": (100.0, 800.0),
    "controller.saturation.torque_n.2": (100.0, 1000.0),  # one axis of a limit written as one number
    "simulation.limits.theta.0": (0.5, 1.5),
    "simulation.t_end": (0.2, 1.0),
    "initial_state.theta.1": (-0.5, 0.5),
    "initial_state.omega.2": (-5.0, 5.0),
    "disturbances.0.value.1": (-2.0, 2.0),
}
STATE_KEYS = [k for k in VALID if k.startswith("initial_state.")]

WORDS = ["x", "one", "q", "mass", "theta"]
NUMBERS = ["3", "9", "01", "-1", "+1", "1e0", "0.5", "1.0", "١", "²", "０", "0x1", " 1", "1_0"]


@st.composite
def mutated_keys(draw, keys=tuple(VALID)) -> str:
    """A valid key with one segment changed, added or emptied (and never valid)."""
    parts = draw(st.sampled_from(keys)).split(".")
    i = draw(st.integers(0, len(parts) - 1))
    how = draw(st.sampled_from(["word for index", "index for word", "number", "empty", "doubled dot", "longer",
                                "long word", "edge dot"]))
    if how == "word for index":
        parts[i] = draw(st.sampled_from(WORDS)) if parts[i].isdigit() else parts[i] + draw(st.sampled_from(WORDS))
    elif how == "index for word":
        parts[i] = draw(st.sampled_from(["0", "1", "7"])) if not parts[i].isdigit() else parts[i] + "0"
    elif how == "number":
        parts[i] = draw(st.sampled_from(NUMBERS))
    elif how == "empty":
        parts[i] = ""
    elif how == "doubled dot":
        parts.insert(i, "")
    elif how == "longer":
        parts += draw(st.lists(st.sampled_from(["0", "1", "x"]), min_size=1, max_size=4))
    elif how == "long word":
        parts[i] = "k" * draw(st.integers(40, 260))
    else:
        parts = [""] + parts if draw(st.booleans()) else parts + [""]
    key = ".".join(parts)
    try:
        parse_key(key)
    except KeyPathError:
        return key
    assume(False)  # the change gave another valid key (e.g. an index still in range)


def _entry_points(key: str, tmp: Path) -> list[tuple[str, list[str]]]:
    """(name, command line) of every command that takes the key, its output folder tmp/out."""
    config = str(tmp / "keys.yaml")
    out = ["-o", str(tmp / "out")]
    specs = {}
    for section, body in (("grid", {"grid": {key: [1.0, 2.0]}}), ("zip", {"zip": {key: [1.0, 2.0]}}),
                          ("random", {"random": {"n": 2, "params": {key: {"uniform": [1.0, 2.0]}}}})):
        path = tmp / f"{section}.yaml"
        path.write_text(yaml.safe_dump({"name": f"s_{section}", "base": config, **body}, allow_unicode=True),
                        encoding="utf-8")
        specs[section] = str(path)
    (tmp / "table.csv").write_text(f'"{key}",body.mass\n1.0,30\n', encoding="utf-8")
    (tmp / "table.yaml").write_text(yaml.safe_dump({"name": "s_table", "base": config, "table": "table.csv"}),
                                    encoding="utf-8")
    study = ["--minimize", "lyapunov_final", "--trials", "2"]
    return [
        ("run --set", ["run", config, "--set", f"{key}=1", *out]),
        ("sweep --set sweep.grid", ["sweep", config, "--set", f"sweep.grid.{key}=[1, 2]", *out]),
        ("sweep --grid", ["sweep", config, "--grid", f"{key}=1,2", *out]),
        ("sweep --grid :scale", ["sweep", config, "--grid", f"{key}:scale=0.5,2", *out]),
        ("sweep --zip", ["sweep", config, "--zip", f"{key}=1,2", *out]),
        ("sweep --random", ["sweep", config, "--random", f"{key}=uniform:[1,2]", "-n", "2", *out]),
        ("spec grid", ["sweep", specs["grid"], *out]),
        ("spec zip", ["sweep", specs["zip"], *out]),
        ("spec random", ["sweep", specs["random"], *out]),
        ("spec table", ["sweep", str(tmp / "table.yaml"), *out]),
        ("sensitivity --vary", ["sensitivity", config, "--vary", f"{key}=uniform:[1,2]", "-n", "8",
                                "--metric", "lyapunov_final", *out]),
        ("tune --vary", ["tune", config, "--vary", f"{key}=uniform:[1,2]", *study, *out]),
        ("tune --over", ["tune", config, "--vary", "body.mass=uniform:[30,50]", "--over", f"{key}=uniform:[1,2]",
                         *study, *out]),
        ("analyze --basin", ["analyze", config, "--basin", f"{key}=-1:1:3", "--basin",
                             "initial_state.omega.1=-1:1:3", *out]),
        ("analyze --basin-stability", ["analyze", config, "--push", "force", "--basin-stability", f"{key}=-1:1",
                                       *out]),
    ]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("keys")
    (tmp / "keys.yaml").write_text(yaml.safe_dump(BASE), encoding="utf-8")
    return tmp


def test_the_base_is_valid_and_every_valid_key_names_something_it_has(folder):
    config = api.load_config(folder / "keys.yaml")
    assert not config.warnings
    for key in VALID:
        assert parse_key(key).get(config.resolved) is not None


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.filter_too_much])
@given(key=mutated_keys())
def test_a_mutated_key_is_refused_in_one_line_by_every_command(folder, key):
    runner = CliRunner()
    for name, args in _entry_points(key, folder):
        result = runner.invoke(cli, args)
        assert result.exit_code != 0, (name, result.output)
        assert result.exception is None or isinstance(result.exception, SystemExit), (name, result.exception)
        assert "Traceback" not in result.output, (name, result.output)
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("Error: "), (name, result.output)
        assert key[:60] in lines[0] or repr(key)[1:61] in lines[0], (name, lines[0])
        assert not (folder / "out").exists(), name
    config = api.load_config(folder / "keys.yaml")
    out = folder / "out"
    for name, call in [  # the Python API: the same refusal, one line
        ("load_config", lambda: api.load_config(folder / "keys.yaml", [f"{key}=1"])),
        ("execute_sweep", lambda: api.execute_sweep({"name": "s", "base": str(folder / "keys.yaml"),
                                                     "grid": {key: [1.0, 2.0]}}, out)),
        ("sensitivity_analysis", lambda: sensitivity_analysis(config, [f"{key}=uniform:[1,2]"], n=8, output=out)),
        ("BasinAxis.parse", lambda: BasinAxis.parse(f"{key}=-1:1:3")),
    ]:
        with pytest.raises(ValueError) as info:  # ConfigError, SweepSpecError, StudyInputError are ValueErrors
            call()
        errors = getattr(info.value, "errors", [str(info.value)])
        assert len(errors) == 1 and "\n" not in errors[0], (name, errors)
        assert not out.exists(), name


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), key=st.sampled_from(sorted(VALID)))
def test_a_valid_key_sets_the_same_value_through_every_command(folder, data, key):
    lo, hi = VALID[key]
    value = data.draw(st.floats(lo, hi).map(lambda v: float(f"{v:.6g}")))
    path = parse_key(key)
    base = str(folder / "keys.yaml")
    one = {"name": "one", "base": base}
    resolved = {
        "--set": api.load_config(base, [f"{key}={value!r}"]).resolved,
        "grid": plan_table(spec_from_mapping({**one, "grid": {key: [value]}})).resolved(0),
        "zip": plan_table(spec_from_mapping({**one, "zip": {key: [value]}})).resolved(0),
        "table": plan_table(spec_from_mapping({**one, "table": {key: [value]}})).resolved(0),
        "random": plan_table(spec_from_mapping({**one, "random": {"n": 1, "params": {key: {"choice": [value]}}}}))
        .resolved(0),
        "sweep --set": plan_table(spec_from_mapping(one, overrides=[f"sweep.grid.{key}=[{value!r}]"])).resolved(0),
        "tune --vary": plan_tuning(api.load_config(base), [f"{key}=uniform:[{value!r},{value!r}]"],
                                   minimize=["lyapunov_final"]).configs({key: value})[0].resolved,
    }
    for name, mapping in resolved.items():
        assert math.isclose(path.get(mapping), value, rel_tol=1e-12), name
    if key in STATE_KEYS:  # a basin axis is the same entry of the same state
        axis = BasinAxis.parse(f"{key}={value!r}:{value + 1!r}:2")
        assert (axis.index, axis.values[0]) == (path.index[0], value)
        assert path.field == {"theta": "theta", "omega": "omega"}[axis.block]


@pytest.mark.parametrize("key, words", [
    ("initial_state.theta.x", "'initial_state.theta' is a list of 3; index it with 0..2, not 'x'"),
    ("controller.k_r.one", "'controller.k_r' is a 3x3 matrix; index it with 0..2, not 'one'"),
    ("body.inertia.0.x", "'body.inertia.0' is a list of 3; index it with 0..2, not 'x'"),
    ("controller.saturation.torque_n.z", "'controller.saturation.torque_n' is a list of 3; index it with 0..2"),
    ("simulation.limits.theta.q", "'simulation.limits.theta' is a list of 3; index it with 0..2, not 'q'"),
    ("disturbances.0.value.y", "'disturbances.0.value' is a list of 3; index it with 0..2, not 'y'"),
    ("controller.k_c.1e0", "index it with 0..2, not '1e0'"),
    ("body.1.mass", "'body' is a mapping, not a list; it has no '1' (allowed: mass, inertia, attachment_point"),
    ("disturbances.x.value.0", "'disturbances' is a list of at most 4 entries; index it with 0..3, not 'x'"),
    ("disturbances.0.band.2", "'disturbances.0.band' is a list of 2; index it with 0..1, not '2'"),
    ("body.mas", "'body' has no 'mas'; did you mean 'body.mass'?"),
    ("contoller.k_c", "unknown section 'contoller'; did you mean 'controller'?"),
    ("controller.t_end", "did you mean 'simulation.t_end'?"),
    ("initial_state.omega.١", "not '١'"),
    ("body..mass", "segment 2 of 3 is empty"),
    ("body.mass.0", "'body.mass' is a number > 0 (kg); it has no entry '0'"),
    ("controller.k_c.0.1.2", "'controller.k_c.0.1' is one number of 'controller.k_c' (a 3x3 matrix)"),
])
def test_the_refusal_names_the_segment_and_what_is_allowed(key, words):
    with pytest.raises(KeyPathError) as info:
        parse_key(key)
    assert words in info.value.problem
    assert str(info.value).startswith(f"key {key!r}: ") and "\n" not in str(info.value)


def test_a_list_of_named_entries_takes_an_index_or_a_name():
    """A section that is a list of entries with a ``name`` (a chain's bodies) takes either."""
    from pydantic import BaseModel, Field

    from rbstab.config.schema import checked, _vector

    class Body(BaseModel):
        name: str
        mass: float = 1.0
        attachment_point: Annotated[Any, checked(_vector)] = Field(default_factory=lambda: [0.0, 0.0, 0.0])

    class Chain(BaseModel):
        bodies: list[Body] = Field(json_schema_extra={"max_entries": 8})

    data = {"bodies": [{"name": "trunk", "mass": 30.0}, {"name": "leg", "mass": 10.0}]}
    assert parse_key("bodies.leg.mass", Chain).get(data) == parse_key("bodies.1.mass", Chain).get(data) == 10.0
    parse_key("bodies.trunk.attachment_point.2", Chain).set(data, 0.5)
    assert data["bodies"][0]["attachment_point"] == [0.0, 0.0, 0.5]
    with pytest.raises(KeyPathError, match="'bodies' is a list of at most 8 entries; index it with 0..7 or an "
                                           "entry's name, not '8'"):
        parse_key("bodies.8.mass", Chain)
    with pytest.raises(KeyPathError, match="'bodies.trunk.attachment_point' is a list of 3; index it with 0..2"):
        parse_key("bodies.trunk.attachment_point.x", Chain)
    with pytest.raises(KeyPathError, match=r"'bodies' has 2 entries \(0..1, or by name: trunk, leg\); there is no 'arm' to set"):
        parse_key("bodies.arm.mass", Chain).set(data, 1.0)


def test_a_chain_key_by_name_reaches_the_chain_and_a_one_body_key_stays_one():
    """A chain's keys by body or joint name (``initial_state.<body>``: a mapping by name)
    set what they name; a one-body key whose entry is one of the one-body section's fields
    is read as the one-body key, whatever a chain could name."""
    from rbstab.config import load_config
    from rbstab.config.paths import parse_any_key

    config = load_config(Path(__file__).parents[1] / "configs" / "examples" / "stance_ankle_hip.yaml",
                             ["bodies.trunk.mass=50", "joints.hip.k_r.0=700", "initial_state.trunk.theta.0=0.02"])
    assert config.chain.bodies[1].mass == 50.0 and config.chain.joints[1].k_r[0, 0] == 700.0
    assert config.initial_state["trunk"]["theta"][0] == 0.02
    with pytest.raises(KeyPathError, match="'initial_state.theta' is a list of 3; index it with 0..2, not 'x'"):
        parse_any_key("initial_state.theta.x")
    from rbstab.config.schema import ChainSchema

    with pytest.raises(KeyPathError, match="'initial_state' is a mapping by name"):
        parse_key("initial_state.0.theta.0", ChainSchema)
    assert parse_any_key("joints.hip.k_c.0").entry == "hip"


def test_a_typo_is_named_where_it_is_not_in_a_valid_segment_before_it(tmp_path):
    """The refusal blames the segment that is wrong: a chain's body name (``hat`` is one) is
    not taken for a one-body field, a mistyped joint name gets its did-you-mean, and a limit
    refused in a vector says which entry and why."""
    stance = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    basin = CliRunner().invoke(cli, ["analyze", str(stance), "--basin", "initial_state.trunk.thta.0=-0.1:0.1:3",
                                     "--basin", "initial_state.trunk.theta.0=-0.1:0.1:3", "-o", str(tmp_path)])
    assert basin.exit_code == 1 and "Traceback" not in basin.output
    assert "'initial_state.trunk' has no 'thta'; did you mean 'initial_state.trunk.theta'?" in basin.output, basin.output
    joint = CliRunner().invoke(cli, ["run", str(stance), "--set", "joints.ankel.k_r.0=400", "-o", str(tmp_path)])
    assert joint.exit_code == 1 and "there is no 'ankel' to set; did you mean 'joints.ankle'?" in joint.output, \
        joint.output
    one_body = CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "examples" / "stance_ankle.yaml"), "--set",
                                        "controller.saturation.torque_n=[0,180,.inf]", "-o", str(tmp_path)])
    assert one_body.exit_code == 1 and "(entry [0] is 0, not > 0)" in one_body.output, one_body.output
    assert not list(tmp_path.iterdir())
    from rbstab.config.paths import parse_any_key

    with pytest.raises(KeyPathError, match=r"'initial_state' has no 'thta'; did you mean 'initial_state.theta'\?"):
        parse_any_key("initial_state.thta.0")  # a one-body field's typo stays the one-body reading
    with pytest.raises(KeyPathError, match=r"'initial_state.hat' has no 'thta'; did you mean 'initial_state.hat.theta'"):
        parse_any_key("initial_state.hat.thta.0")
