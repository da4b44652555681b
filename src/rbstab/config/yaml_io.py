"""YAML reading and writing for configurations and sweep specs.

Reading uses a :class:`yaml.SafeLoader` subclass that differs in two ways: ``1e-8`` is a
float (PyYAML follows YAML 1.1 and reads it as a string), and a key given twice in one
mapping is an error instead of silently keeping the last value. Writing keeps lists
(vectors, matrices) on one line.
"""

from __future__ import annotations

import re
from collections.abc import Container, Mapping
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError

__all__ = ["parse_yaml", "read_yaml_file", "dump_yaml", "dump_yaml_sections"]


class _Loader(yaml.SafeLoader):
    """SafeLoader reading ``1e-8`` as a float and refusing duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag.endswith(":merge"):
                continue  # '<<' merge keys may repeat keys on purpose
            key = self.construct_object(key_node)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    "while reading a mapping",
                    node.start_mark,
                    f"found the key {key!r} twice (first at line {seen[key] + 1})",
                    key_node.start_mark,
                )
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


# libyaml's emitter when PyYAML was built with it (the PyPI wheels are): the same text as
# the pure-Python emitter (checked on random configurations), about 3x faster, which
# matters when a sweep hashes and writes thousands of configurations.
_SafeDumperBase = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Dumper(_SafeDumperBase):
    """SafeDumper writing lists (vectors, matrices) on one line: ``[0.15, 0.1, -0.42]``."""

    def represent_list(self, data: list) -> yaml.SequenceNode:
        return self.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


_Dumper.add_representer(list, _Dumper.represent_list)


def parse_yaml(text: str) -> Any:
    """Parse YAML text; a syntax error becomes a ConfigError line."""
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = exc.problem or exc.context or "invalid YAML"
        raise ConfigError([f"YAML syntax error{where}: {problem}"]) from None
    except yaml.YAMLError as exc:
        raise ConfigError([f"YAML syntax error: {exc}"]) from None


def read_yaml_file(path: str | Path, what: str = "config file") -> Any:
    """Read and parse a YAML file (a config or a sweep spec).

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is, for messages ("config file", "sweep spec").

    Raises
    ------
    ConfigError
        For a missing or unreadable file or a YAML syntax error; ``source`` is ``path``.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError([f"{what} not found: {path}"]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([f"cannot read the {what}: {exc}"], str(path)) from None
    try:
        return parse_yaml(text)
    except ConfigError as exc:
        raise ConfigError(exc.errors, str(path)) from None


def dump_yaml(data: Any) -> str:
    """YAML text of plain-Python ``data``: keys in insertion order, lists in flow style."""
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=True)


#: (key, repr(value)) -> YAML text of ``{key: value}``; see :func:`dump_yaml_sections`.
_SECTION_TEXT: dict[tuple[str, str], str] = {}
_SECTION_TEXT_MAX = 512


def dump_yaml_sections(data: Mapping, fresh: Container[str] = ()) -> str:
    """:func:`dump_yaml` of a mapping, top-level key by key, the text of keys not in
    ``fresh`` taken from a cache keyed by their value's ``repr``.

    The YAML of a block mapping is the concatenation of the YAML of its top-level entries,
    so the text is exactly ``dump_yaml(data)``; a sweep's runs share all sections but
    ``name`` and ``initial_state``, so writing their config is ~5x cheaper.
    """
    parts = []
    for key, value in data.items():
        if key in fresh or not isinstance(key, str):
            parts.append(dump_yaml({key: value}))
            continue
        tag = (key, repr(value))
        text = _SECTION_TEXT.get(tag)
        if text is None:
            if len(_SECTION_TEXT) >= _SECTION_TEXT_MAX:
                _SECTION_TEXT.clear()
            text = _SECTION_TEXT[tag] = dump_yaml({key: value})
        parts.append(text)
    return "".join(parts) if parts else dump_yaml(dict(data))
