"""YAML reading and writing for configurations and sweep specs.

Reading uses a :class:`yaml.SafeLoader` subclass that differs in three ways: ``1e-8`` is a
float (PyYAML follows YAML 1.1 and reads it as a string), a key given twice in one
mapping is an error instead of silently keeping the last value, and the document is
bounded before any Python object is built from it (:data:`MAX_YAML_BYTES` of text,
:data:`MAX_YAML_DEPTH` levels of nesting, at most as many values once aliases are expanded
as the text has characters or :data:`MAX_YAML_NODES` if more, no recursive alias), so that
a small file cannot make a large object (a "billion laughs" file of nested aliases) or a
deep one, while a spec that spells out 10,000 runs is read. Files are read only when they
are regular files (not ``/dev/zero``, a FIFO or a folder), and at most
:data:`MAX_YAML_BYTES` of them. Writing keeps lists (vectors, matrices) on one line.
"""

from __future__ import annotations

import re
import stat
from collections.abc import Container, Mapping
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError

__all__ = [
    "parse_yaml",
    "read_yaml_file",
    "read_text_limited",
    "dump_yaml",
    "dump_yaml_sections",
    "MAX_YAML_BYTES",
    "MAX_YAML_DEPTH",
    "MAX_YAML_NODES",
]

#: Largest YAML text read (a config is ~1 kB; a sweep spec with long inline lists ~100 kB).
MAX_YAML_BYTES = 4 * 2**20
#: Deepest nesting of mappings and lists (a config has 3 levels, a sweep spec ~6).
MAX_YAML_DEPTH = 32
#: Most values (scalars, lists, mappings) of a document with every alias expanded, beyond
#: the values its text spells out (a value takes at least one character: a document
#: without aliases never reaches its length in characters). Aliases may add this many.
MAX_YAML_NODES = 200_000


class _LimitError(yaml.MarkedYAMLError):
    """A document past one of the limits (reported like a syntax error, with its line)."""


class _Loader(yaml.SafeLoader):
    """SafeLoader reading ``1e-8`` as a float, refusing duplicate keys and bounding the
    document (module docstring) while it is composed, before anything is constructed."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._depth = 0
        self._limit = max(MAX_YAML_NODES, len(stream) if isinstance(stream, str) else 0)
        # id(node) -> (values with aliases expanded, nesting height), filled bottom-up as
        # each node is completed; an alias to a node not in it refers to an ancestor.
        self._measure: dict[int, tuple[int, int]] = {}

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            node = super().compose_node(parent, index)
            if id(node) not in self._measure:
                raise _LimitError(None, None, f"the alias *{event.anchor} refers to a value that contains it "
                                  "(a recursive structure)", event.start_mark)
            return node
        mark = self.peek_event().start_mark
        self._depth += 1
        if self._depth > MAX_YAML_DEPTH:
            raise _LimitError(None, None, f"nested deeper than {MAX_YAML_DEPTH} levels", mark)
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        self._measure[id(node)] = self._size(node, mark)
        return node

    def _size(self, node: yaml.Node, mark) -> tuple[int, int]:
        if isinstance(node, yaml.ScalarNode):
            return 1, 1
        children = node.value if isinstance(node, yaml.SequenceNode) else [n for kv in node.value for n in kv]
        measures = [self._measure[id(child)] for child in children]
        size = 1 + sum(m[0] for m in measures)
        height = 1 + max((m[1] for m in measures), default=0)
        if size > self._limit:
            raise _LimitError(None, None, f"more than {self._limit} values once aliases are expanded", mark)
        if height > MAX_YAML_DEPTH:
            raise _LimitError(None, None, f"nested deeper than {MAX_YAML_DEPTH} levels once aliases are "
                              "expanded", mark)
        return size, height

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
    """Parse YAML text within the limits of the module docstring.

    Raises
    ------
    ConfigError
        One line for a syntax error, a document past a limit, or a value its tag cannot
        take (``!!float abc``, ``!!timestamp 2020-13-01``).
    """
    if len(text) > MAX_YAML_BYTES:
        raise ConfigError([f"YAML text of {len(text)} characters; at most {MAX_YAML_BYTES} are read"])
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except _LimitError as exc:
        mark = exc.problem_mark
        raise ConfigError([f"YAML refused at line {mark.line + 1}, column {mark.column + 1}: {exc.problem}"]) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = exc.problem or exc.context or "invalid YAML"
        raise ConfigError([f"YAML syntax error{where}: {problem}"]) from None
    except yaml.YAMLError as exc:
        raise ConfigError([f"YAML syntax error: {exc}"]) from None
    except (ValueError, TypeError, OverflowError) as exc:  # a tagged value its constructor refuses
        raise ConfigError([f"YAML value error: {exc}"]) from None


def read_text_limited(path: str | Path, what: str, limit: int = MAX_YAML_BYTES) -> str:
    """The UTF-8 text of a regular file of at most ``limit`` bytes.

    Only regular files are read: a device (``/dev/zero``), a FIFO or a folder is refused
    before it is opened for reading, and at most ``limit + 1`` bytes are read, so no
    input makes the reader block or grow.

    Raises
    ------
    ConfigError
        For a missing, unreadable, non-regular or larger file, or one that is not UTF-8
        (``source`` is ``path``).
    """
    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise ConfigError([f"{what} not found: {path}"]) from None
    except OSError as exc:
        raise ConfigError([f"cannot read the {what}: {exc.strerror or exc}"], str(path)) from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file (a device, FIFO or socket)"
        raise ConfigError([f"the {what} {path} is {kind}; expected a YAML file"], str(path))
    if info.st_size > limit:
        raise ConfigError([f"the {what} is {info.st_size} bytes; at most {limit} are read"], str(path))
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
        if len(data) > limit:  # grew since stat()
            raise ConfigError([f"the {what} is more than {limit} bytes; at most {limit} are read"], str(path))
        return data.decode("utf-8")
    except OSError as exc:
        raise ConfigError([f"cannot read the {what}: {exc.strerror or exc}"], str(path)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError([f"the {what} is not UTF-8 text ({exc.reason} at byte {exc.start})"], str(path)) from None


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
        For a missing, unreadable or non-regular file, one past the limits of the module
        docstring, or a YAML syntax error; ``source`` is ``path``.
    """
    text = read_text_limited(path, what)
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
