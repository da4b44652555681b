"""The YAML reader on libyaml's parser: the same values as PyYAML's pure-Python parser
with the project's rules (``1e-8`` a float, duplicate keys refused, bounded documents),
and the writer's fast paths giving PyYAML's text."""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import pytest
import yaml

from rbstab.config import ConfigError
from rbstab.config import yaml_io
from rbstab.config.yaml_io import MAX_YAML_DEPTH, MAX_YAML_NODES, copy_tree, dump_yaml, parse_yaml

ROOT = Path(__file__).resolve().parents[1]
LOADERS = [pytest.param(yaml_io._Loader, id="pure-python")]
if hasattr(yaml_io, "_CLoader"):
    LOADERS.append(pytest.param(yaml_io._CLoader, id="libyaml"))

#: Every kind of value a safe loader builds, with the forms PyYAML reads its own way.
EVERY_KIND = """
floats: [1e-8, 2E+3, -1.5e-3, 1.0e8, 3.25, .5, -0.0, +1.5, 1_000.5, 1:30.5, .inf, -.Inf, .nan, 6.02e23]
ints: [0, -7, +3, 012, 0o17, 0x1f, 0b101, 1_000, 1:30, 123456789012345678901234567890]
texts: ["1e-8", '2.5', plain text, 'a: b', "tab\\there", ~text, yes_no]
others: [~, null, true, False, yes, No, on, 2001-12-14, 2001-12-14t21:59:43.10-05:00, !!binary aGVsbG8=]
tagged: [!!float 1, !!str 1.5, !!int "12", !!float -nan, !!float infinity, !!float " 2.5"]
anchors:
  base: &base {mass: 41.0, inertia: [10.0, 8.0, 0.4]}
  same: *base
  merged:
    <<: *base
    mass: 50.0
  list: &vector [1.0, 2.0, 3.0]
  again: [*vector, *vector]
nested: {a: [[1.5, [2.5, {b: [3.5]}]]], '': empty key, ? complex key : value}
set: !!set {a, b}
pairs: !!pairs [a: 1, b: 2]
omap: !!omap [a: 1, b: 2]
multi: |
  line one
  line two
folded: >
  folded
  text
"""


def _load(loader, text):
    with yaml_io.gc_paused():
        return yaml.load(text, Loader=loader)  # noqa: S506 - safe loaders


def _same(a, b) -> bool:
    """Equal, of the same types, NaN equal to NaN (and -0.0 told from 0.0)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1, a) == math.copysign(1, b))
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def test_the_loader_is_libyamls_where_pyyaml_has_it():
    if hasattr(yaml, "CSafeLoader"):
        assert yaml_io.LOADER is yaml_io._CLoader
    else:  # pragma: no cover - a PyYAML built without libyaml
        assert yaml_io.LOADER is yaml_io._Loader


@pytest.mark.skipif(not hasattr(yaml_io, "_CLoader"), reason="PyYAML without libyaml")
def test_both_loaders_give_the_same_values_of_every_kind():
    pure, fast = _load(yaml_io._Loader, EVERY_KIND), _load(yaml_io._CLoader, EVERY_KIND)
    assert _same(pure, fast)
    floats = fast["floats"]
    assert floats[:4] == [1e-8, 2e3, -1.5e-3, 1e8] and all(type(v) is float for v in floats)
    assert floats[8:10] == [1000.5, 90.5] and math.isinf(floats[10]) and floats[11] < 0 and math.isnan(floats[12])
    assert fast["ints"][3:7] == [10, "0o17", 31, 5] and fast["texts"][:2] == ["1e-8", "2.5"]
    assert fast["anchors"]["same"] is fast["anchors"]["base"]  # an alias is the same object
    assert fast["anchors"]["merged"] == {"mass": 50.0, "inertia": [10.0, 8.0, 0.4]}


@pytest.mark.skipif(not hasattr(yaml_io, "_CLoader"), reason="PyYAML without libyaml")
def test_both_loaders_read_every_yaml_file_of_the_project_alike():
    files = [(p, p.read_text(encoding="utf-8")) for folder in ("configs", "tests", "benchmarks")
             for p in sorted((ROOT / folder).rglob("*.y*ml"))]
    for doc in sorted((ROOT / "docs").glob("*.md")):  # the specs and configs the documentation shows
        files += [(doc, block) for block in re.findall(r"```yaml\n(.*?)```", doc.read_text(encoding="utf-8"), re.S)]
    assert len(files) > 5
    for path, text in files:
        try:
            pure = _load(yaml_io._Loader, text)
        except yaml.YAMLError:
            with pytest.raises(yaml.YAMLError):
                _load(yaml_io._CLoader, text)
            continue
        assert _same(pure, _load(yaml_io._CLoader, text)), path


@pytest.mark.parametrize("loader", LOADERS)
def test_exponent_without_a_dot_is_a_float(loader, monkeypatch):
    monkeypatch.setattr(yaml_io, "LOADER", loader)
    data = parse_yaml("rtol: 1e-8\natol: 2E-9\nquoted: '1e-8'\nn: 11\nlist: [1e-8, 5e+2]\n")
    assert data == {"rtol": 1e-8, "atol": 2e-9, "quoted": "1e-8", "n": 11, "list": [1e-8, 500.0]}
    assert type(data["rtol"]) is float and type(data["list"][0]) is float


@pytest.mark.parametrize("loader", LOADERS)
def test_a_key_given_twice_is_refused_with_its_name_and_lines(loader, monkeypatch):
    monkeypatch.setattr(yaml_io, "LOADER", loader)
    text = "body:\n  mass: 41.0\n  inertia: [1, 2, 3]\n  mass: 50.0\n"
    with pytest.raises(ConfigError) as info:
        parse_yaml(text)
    assert info.value.errors == ["YAML syntax error at line 4, column 3: found the key 'mass' twice (first at line 2)"]
    assert parse_yaml("a: &a {x: 1}\nb:\n  <<: *a\n  x: 2\n") == {"a": {"x": 1}, "b": {"x": 2}}  # merge keys may


@pytest.mark.parametrize("loader", LOADERS)
@pytest.mark.parametrize("text, problem", [
    ("a: " + "[" * 100_000 + "]" * 100_000, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    ("a:\n" + "- " * 100_000 + "x\n", f"nested deeper than {MAX_YAML_DEPTH} levels"),
    ("a: " + "[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH, f"nested deeper than {MAX_YAML_DEPTH} levels"),
    ("a: &a [" + "[" * 20 + "]" * 20 + "]\nb: [" + "[" * 20 + "*a" + "]" * 20 + "]",
     f"nested deeper than {MAX_YAML_DEPTH} levels once aliases are expanded"),
    ("a: &a [*a]", "the alias *a refers to a value that contains it"),
    ("a: *nowhere", "found undefined alias 'nowhere'"),
    ("a: &x 1\nb: &x 2", "line 2, column 4: second occurrence"),
    ("a: 1\n---\nb: 2", "line 2, column 1: but found another document"),
    ("x: !!float abc", "YAML value error"),
    ("x: !!python/object/apply:os.system [echo hacked]", "YAML syntax error"),
    ("body:\n  mass: [41\n", "YAML syntax error at line"),
])
def test_documents_past_the_limits_or_invalid_are_refused_in_one_line(loader, monkeypatch, text, problem):
    """The libyaml loader composes without recursion: 100,000 levels are refused, not a
    crash of the C stack (libyaml's own composer recurses)."""
    monkeypatch.setattr(yaml_io, "LOADER", loader)
    with pytest.raises(ConfigError, match=problem.replace("*", r"\*").replace("[", r"\[")) as info:
        parse_yaml(text)
    assert len(info.value.errors) == 1
    assert parse_yaml("a: " + "[" * (MAX_YAML_DEPTH - 1) + "]" * (MAX_YAML_DEPTH - 1)) is not None  # the limit itself


@pytest.mark.parametrize("loader", LOADERS)
def test_nested_aliases_are_refused_before_they_expand(loader, monkeypatch):
    monkeypatch.setattr(yaml_io, "LOADER", loader)
    lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f"{chr(97 + i)}: &{chr(97 + i)} [" + ", ".join([f"*{chr(96 + i)}"] * 9) + "]")
    with pytest.raises(ConfigError, match=f"more than {MAX_YAML_NODES} values once aliases are expanded"):
        parse_yaml("\n".join(lines))
    assert len(parse_yaml("\n".join(lines[:4]))["d"]) == 9  # 9^3 values: read


def test_a_large_spec_of_floats_is_read_as_the_pure_python_loader_reads_it():
    values = [i * 0.1 + 1e-9 * i for i in range(5000)] + [1e17, -0.0, 1e-05, float("inf")]
    text = dump_yaml({"zip": {"body.mass": values, "initial_state.omega": [[v, -v, 2 * v] for v in values[:50]]}})
    assert _same(parse_yaml(text), _load(yaml_io._Loader, text))
    assert parse_yaml(text)["zip"]["body.mass"] == values


class _Stock(getattr(yaml, "CSafeDumper", yaml.SafeDumper)):
    """PyYAML's dumper with lists in flow style, without the project's fast paths."""

    def represent_list(self, data):
        return self.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


_Stock.add_representer(list, _Stock.represent_list)


def test_the_writer_gives_pyyamls_text():
    data = {"floats": [0.1, -2.5, 1e17, 1e-05, -0.0, float("inf"), -float("inf"), float("nan"), 123456789.123],
            "mixed": [1, 2.5, "text", None, True], "strings": ["1e-8", "1.5", "yes"], "empty": [],
            "nested": [[1.5, 2.5], [3.0]], "matrix": {"k_t": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}}
    stock = yaml.dump(data, Dumper=_Stock, sort_keys=False, allow_unicode=True)
    assert dump_yaml(data) == stock


def _random_floats(rng, n: int) -> list:
    special = [float("inf"), -float("inf"), float("nan"), 0.0, -0.0, 1e-05, 1e16, 1e300, 5e-324]
    return [rng.choice(special) if rng.random() < 0.05 else
            float(f"{rng.uniform(-1e5, 1e5):.{rng.randint(1, 17)}g}") if rng.random() < 0.3 else
            rng.uniform(-1, 1) * 10 ** rng.randint(-30, 30) for _ in range(n)]


def _random_document(rng, depth: int = 0) -> dict:
    """Long lists of floats (flat, or of rows of one length) at every place a mapping can
    hold them: top level, nested mappings, mappings in block sequences, after long keys
    (written ``? key`` / ``: value``) of ASCII and other characters; beside other values."""
    keys = ["body.mass", "initial_state.omega", "k", "x" * rng.randint(1, 140), "a_long_key." * rng.randint(1, 14),
            "'quoted: key'", "- dash", "ключ.ω", "日本語" * rng.randint(1, 50)]
    out = {}
    for _ in range(rng.randint(1, 5)):
        key, kind = rng.choice(keys), rng.random()
        if kind < 0.4:
            n, size = rng.randint(200, 700), rng.randint(0, 6)
            out[key] = _random_floats(rng, n) if size == 0 else [_random_floats(rng, size) for _ in range(n // size + 1)]
        elif kind < 0.6 and depth < 3:
            out[key] = _random_document(rng, depth + 1)
        elif kind < 0.7 and depth < 3:
            out[key] = [_random_document(rng, depth + 1) for _ in range(rng.randint(1, 3))]
        elif kind < 0.8:
            out[key] = [1, 2.5, "x"] * rng.randint(1, 200)
        else:
            out[key] = rng.choice(["text", 3, 2.5, None, True])
    return out


def test_the_writer_gives_pyyamls_text_for_long_lists_of_floats():
    """The writer's own text for long lists of floats is libyaml's, wherever they are."""
    import random

    rng = random.Random(0)
    for _ in range(60):
        data = _random_document(rng)
        assert dump_yaml(data) == yaml.dump(data, Dumper=_Stock, sort_keys=False, allow_unicode=True)
    shared = _random_floats(rng, 300)  # one list reached twice: an anchor and an alias
    data = {"a": shared, "b": {"c": shared}}
    assert "&id001" in dump_yaml(data)
    assert dump_yaml(data) == yaml.dump(data, Dumper=_Stock, sort_keys=False, allow_unicode=True)


def test_copy_tree_is_a_deep_copy():
    data = {"a": [1.5, [2, {"b": "c"}], None], "t": (1, [2]), "f": 1e-8}
    copied = copy_tree(data)
    assert copied == copy.deepcopy(data)
    copied["a"][1][1]["b"] = "changed"
    copied["t"][1].append(3)
    assert data == {"a": [1.5, [2, {"b": "c"}], None], "t": (1, [2]), "f": 1e-8}
