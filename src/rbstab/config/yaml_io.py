"""YAML reading and writing for configurations and sweep specs.

Reading parses with libyaml's C parser where PyYAML has it (the PyPI wheels do; else
PyYAML's pure-Python parser, which gives the same values, ~5x slower) and builds the
values as :class:`yaml.SafeLoader` does, with three differences: ``1e-8`` is a
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

import contextlib
import copy
import gc
import io
import re
import stat
import uuid
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
    "gc_paused",
    "copy_tree",
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


def _recursive(event) -> _LimitError:
    return _LimitError(None, None, f"the alias *{event.anchor} refers to a value that contains it "
                       "(a recursive structure)", event.start_mark)


def _too_deep(mark, expanded: str = "") -> _LimitError:
    return _LimitError(None, None, f"nested deeper than {MAX_YAML_DEPTH} levels{expanded}", mark)


class _FastResolve:
    """:meth:`yaml.resolver.BaseResolver.resolve` for a resolver without path resolvers
    (the safe loaders and dumpers), its patterns looked up once per first character: the
    same tags, ~2x faster (a value of a long list is resolved once when read, twice when
    written)."""

    def resolve(self, kind, value, implicit):
        if kind is yaml.ScalarNode:
            if implicit[0]:
                for tag, regexp in self._scalar_table[value[:1]]:
                    if regexp.match(value):
                        return tag
            return self.DEFAULT_SCALAR_TAG
        return super().resolve(kind, value, implicit)


_FLOAT_TAG = "tag:yaml.org,2002:float"


class _Checks(_FastResolve):
    """What both loaders add to PyYAML's safe constructor: duplicate keys refused, and
    lists of floats built without a call a value (:meth:`construct_sequence`)."""

    def construct_sequence(self, node, deep: bool = False) -> list:
        """PyYAML's list of a sequence node, a ``!!float`` written with digits, a dot, a
        sign and an exponent only (no ``_``, ``:``, ``.inf`` or ``.nan``, which PyYAML's
        constructor reads its own way; Python's ``float`` gives the same value for the
        rest) converted in place: a spec's long lists are ~1.4x faster to build."""
        if not isinstance(node, yaml.SequenceNode):
            return super().construct_sequence(node, deep=deep)
        out = []
        for child in node.value:
            if child.tag == _FLOAT_TAG and child.__class__ is yaml.ScalarNode:
                value = child.value
                if "_" not in value and ":" not in value and "n" not in value and "N" not in value:
                    try:
                        out.append(float(value))
                        continue
                    except ValueError:
                        pass
            out.append(self.construct_object(child, deep=deep))
        return out

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


class _Loader(_Checks, yaml.SafeLoader):
    """SafeLoader reading ``1e-8`` as a float, refusing duplicate keys and bounding the
    document (module docstring) while it is composed, before anything is constructed.
    PyYAML's pure-Python parser: used where libyaml is missing (:class:`_CLoader`)."""

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
                raise _recursive(event)
            return node
        mark = self.peek_event().start_mark
        self._depth += 1
        if self._depth > MAX_YAML_DEPTH:
            raise _too_deep(mark)
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
            raise _too_deep(mark, " once aliases are expanded")
        return size, height


#: A scalar float written with an exponent and no dot (``1e-8``, ``2E+3``).
_EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")
_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _EXPONENT_FLOAT, list("-+0123456789."))


_CParser = getattr(yaml, "CSafeLoader", None)
_NO_KEY = object()


if _CParser is not None:

    class _CLoader(_Checks, _CParser):
        """:class:`_Loader` on libyaml's parser: the same values and refusals, ~5x faster
        (a 2.5 MB spec of 10,000 runs: ~0.7 s instead of ~3.5 s).

        libyaml parses; the nodes are composed here from its events, one loop without
        recursion, the document's nesting and its values with aliases expanded counted as
        they come (libyaml's own composer recurses in C, and a deeply nested document
        would overflow the C stack before any limit is checked); then PyYAML's safe
        constructor builds the values from the nodes, as :class:`_Loader` does.
        """

        def __init__(self, stream) -> None:
            super().__init__(stream)
            self._limit = max(MAX_YAML_NODES, len(stream) if isinstance(stream, str) else 0)

        def get_single_data(self):
            node = self._compose()
            return None if node is None else self.construct_document(node)

        def _compose(self) -> yaml.Node | None:
            """The document's node (None for an empty stream), composed as PyYAML's
            :class:`yaml.composer.Composer` composes it, within the limits."""
            get = self.get_event
            get()  # stream start
            if self.check_event(yaml.StreamEndEvent):
                get()
                return None
            document = get()
            root = self._compose_events(get)
            get()  # document end
            if not self.check_event(yaml.StreamEndEvent):
                event = get()
                raise yaml.composer.ComposerError("expected a single document in the stream", document.start_mark,
                                                  "but found another document", event.start_mark)
            get()
            return root

        def _compose_events(self, get) -> yaml.Node:
            scalar_event, alias_event = yaml.ScalarEvent, yaml.AliasEvent
            sequence_start, mapping_start = yaml.SequenceStartEvent, yaml.MappingStartEvent
            scalar_node, sequence_node, mapping_node = yaml.ScalarNode, yaml.SequenceNode, yaml.MappingNode
            tags, limit, depth_limit = self._scalar_table, self._limit, MAX_YAML_DEPTH
            no_key = _NO_KEY
            # open collections: [node, values with aliases expanded, height of the tallest value, key node]
            stack: list[list] = []
            anchors: dict[str, yaml.Node] = {}
            measure: dict[int, tuple[int, int]] = {}  # id(anchored node) -> (values, height), once complete
            anchored: set[int] = set()
            while True:
                event = get()
                kind = event.__class__
                if kind is scalar_event:
                    tag, value = event.tag, event.value
                    if tag is None or tag == "!":
                        if event.implicit[0]:
                            for tag, regexp in tags[value[:1]]:
                                if regexp.match(value):
                                    break
                            else:
                                tag = "tag:yaml.org,2002:str"
                        else:
                            tag = "tag:yaml.org,2002:str"
                    node = scalar_node(tag, value, event.start_mark, event.end_mark, style=event.style)
                    size = height = 1
                    if event.anchor is not None:
                        self._anchor(anchors, event, node)
                        measure[id(node)] = (1, 1)
                    if len(stack) >= depth_limit:
                        raise _too_deep(event.start_mark)
                elif kind is alias_event:
                    node = anchors.get(event.anchor)
                    if node is None:
                        raise yaml.composer.ComposerError(None, None, f"found undefined alias {event.anchor!r}",
                                                          event.start_mark)
                    if id(node) not in measure:
                        raise _recursive(event)
                    size, height = measure[id(node)]
                elif kind is sequence_start or kind is mapping_start:
                    if len(stack) >= depth_limit:
                        raise _too_deep(event.start_mark)
                    collection = sequence_node if kind is sequence_start else mapping_node
                    tag = event.tag
                    if tag is None or tag == "!":
                        tag = self.resolve(collection, None, event.implicit)
                    node = collection(tag, [], event.start_mark, None, flow_style=event.flow_style)
                    if event.anchor is not None:
                        self._anchor(anchors, event, node)
                        anchored.add(id(node))
                    stack.append([node, 1, 0, no_key])
                    continue
                else:  # the end of a sequence or mapping
                    node, size, height, _ = stack.pop()
                    node.end_mark = event.end_mark
                    height += 1
                    if size > limit:
                        raise _LimitError(None, None, f"more than {limit} values once aliases are expanded",
                                          node.start_mark)
                    if height > depth_limit:
                        raise _too_deep(node.start_mark, " once aliases are expanded")
                    if id(node) in anchored:
                        measure[id(node)] = (size, height)
                if not stack:
                    return node
                frame = stack[-1]
                frame[1] += size
                if height > frame[2]:
                    frame[2] = height
                parent = frame[0]
                if parent.__class__ is sequence_node:
                    parent.value.append(node)
                elif frame[3] is no_key:
                    frame[3] = node
                else:
                    parent.value.append((frame[3], node))
                    frame[3] = no_key

        @staticmethod
        def _anchor(anchors: dict, event, node: yaml.Node) -> None:
            first = anchors.get(event.anchor)
            if first is not None:
                raise yaml.composer.ComposerError(f"found duplicate anchor {event.anchor!r}; first occurrence",
                                                  first.start_mark, "second occurrence", event.start_mark)
            anchors[event.anchor] = node

    _CLoader.add_implicit_resolver("tag:yaml.org,2002:float", _EXPONENT_FLOAT, list("-+0123456789."))


def _scalar_resolvers(cls: type) -> dict[str, tuple]:
    """First character of a plain scalar -> the (tag, pattern) its implicit tag is the first
    match of, in the order :meth:`yaml.resolver.BaseResolver.resolve` tries them (for
    :class:`_FastResolve`, which needs a class without path resolvers)."""
    if cls.yaml_path_resolvers:
        raise TypeError(f"{cls.__name__} has path resolvers")
    resolvers = cls.yaml_implicit_resolvers
    wildcard = list(resolvers.get(None, []))
    table = {char: tuple(list(found) + wildcard) for char, found in resolvers.items() if char is not None}
    table.setdefault("", tuple(wildcard))
    return _DefaultTable(table, tuple(wildcard))


class _DefaultTable(dict):
    """A dict whose missing keys give ``default``."""

    def __init__(self, items, default) -> None:
        super().__init__(items)
        self.default = default

    def __missing__(self, key):
        return self.default


#: The loader :func:`parse_yaml` uses: on libyaml's parser where PyYAML has it.
LOADER = _CLoader if _CParser is not None else _Loader


# libyaml's emitter when PyYAML was built with it (the PyPI wheels are): the same text as
# the pure-Python emitter (checked on random configurations), about 3x faster, which
# matters when a sweep hashes and writes thousands of configurations.
_SafeDumperBase = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Dumper(_FastResolve, _SafeDumperBase):
    """SafeDumper writing lists (vectors, matrices) on one line: ``[0.15, 0.1, -0.42]``."""

    def represent_list(self, data: list) -> yaml.SequenceNode:
        if not data or any(type(x) is not float for x in data):
            return self.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)
        # a list of floats (a spec's long lists): the nodes represent_float makes, ~2x faster
        scalar, style = yaml.ScalarNode, self.default_style
        items = []
        for x in data:
            text = repr(x)
            if "e" in text or "n" in text:  # an exponent, inf, nan: represent_float's text
                text = self.represent_float(x).value
            items.append(scalar(_FLOAT_TAG, text, style=style))
        node = yaml.SequenceNode("tag:yaml.org,2002:seq", items, flow_style=True)
        if self.alias_key is not None:
            self.represented_objects[self.alias_key] = node
        return node


_Dumper.add_representer(list, _Dumper.represent_list)
for _cls in (_Loader, LOADER, _Dumper):
    _cls._scalar_table = _scalar_resolvers(_cls)


@contextlib.contextmanager
def gc_paused():
    """Python's cyclic garbage collector off inside the block (as it was after it).

    Building many objects that all stay alive (a document's nodes, then its values) makes
    the collector walk them again and again for nothing: a 2.5 MB spec's nodes and values
    take ~2.5x the CPU with it on (3.1 s against 1.2 s). The objects of a parse hold no
    reference cycle but through aliases, and those are bounded (module docstring).
    """
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def copy_tree(value: Any) -> Any:
    """A deep copy of parsed YAML: dicts and lists copied level by level, strings and
    numbers shared (immutable), anything else through :func:`copy.deepcopy`. ~10x faster
    than ``copy.deepcopy`` on a spec's long lists (10,000 runs: ~0.1 s less); unlike it, a
    value reached twice (a YAML alias) is copied twice."""
    kind = type(value)
    if kind is list:
        return [x if type(x) in _ATOMS else copy_tree(x) for x in value]
    if kind is dict:
        return {k: x if type(x) in _ATOMS else copy_tree(x) for k, x in value.items()}
    if kind in _ATOMS:
        return value
    return copy.deepcopy(value)


_ATOMS = frozenset({float, int, str, bool, type(None)})


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
        with gc_paused():
            return yaml.load(text, Loader=LOADER)  # noqa: S506 - a SafeLoader
    except _LimitError as exc:
        mark = exc.problem_mark
        raise ConfigError([f"YAML refused at line {mark.line + 1}, column {mark.column + 1}: {exc.problem}"]) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = exc.problem or exc.context or "invalid YAML"
        if "maximum nesting depth" in problem:  # libyaml's own limit, met while it scans ahead
            raise ConfigError([f"YAML refused{where}: nested deeper than {MAX_YAML_DEPTH} levels"]) from None
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
    """YAML text of plain-Python ``data``: keys in insertion order, lists in flow style.

    Long lists of floats (:data:`FLOAT_LIST_MIN` values or more, flat or of equal-length
    lists of floats) that are values of mappings are written by :func:`_float_list_text`,
    the text libyaml's emitter writes for them (``tests/test_yaml_loader.py`` compares the two),
    ~5x faster: a spec of 10,000 runs spelled out (130,000 numbers) in ~0.1 s instead of
    ~0.5 s; everything else by libyaml's emitter.
    """
    lists: dict[str, list] = {}
    counts: dict[int, int] = {}
    _count_lists(data, counts)
    data = _set_aside_float_lists(data, lists, counts)
    with gc_paused():  # a spec's long lists: ~25 % of the time (gc_paused)
        text = yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=True)
    for mark, values in lists.items():
        at = text.index(mark)
        start = text.rfind("\n", 0, at) + 1
        keys = _LINE_START.match(text, start, at).end()  # where the line's key starts: the mapping's indentation
        if keys == at:  # no key before the mark: the value of a long key, after the ": " at the indentation
            keys -= 2
        text = text[:at] + _float_list_text(values, at - start, keys - start + _BEST_INDENT) + text[at + len(mark):]
    return text


#: Fewest floats a list holds for :func:`dump_yaml` to write it itself.
FLOAT_LIST_MIN = 256
#: libyaml's emitter's defaults: the line width past which a flow sequence's next item
#: starts a new line, and the indentation step.
_BEST_WIDTH, _BEST_INDENT = 80, 2


def _float_texts(values: list) -> list[str] | None:
    """The plain scalars the dumper writes for a list of floats (``repr``, or
    ``represent_float``'s text where that has an exponent, an infinity or a NaN), or None
    when ``values`` is not a list of floats."""
    if any(type(x) is not float for x in values):
        return None
    texts = [repr(x) for x in values]
    for i, text in enumerate(texts):
        if "e" in text or "n" in text:
            texts[i] = _Dumper.represent_float(_FLOAT_DUMPER, values[i]).value
    return texts


#: The start of a block mapping's line up to its key: indentation, and the indicators
#: (``- `` of a block sequence's item, ``? `` and ``: `` of a long key and its value) the
#: emitter writes on the same line before a mapping's first key.
_LINE_START = re.compile(r"(?: *[-?:] )* *")


def _count_lists(data: Any, counts: dict[int, int]) -> None:
    """How often each list object is reached in ``data`` (id -> count): a list reached twice
    is written once and referred to (a YAML anchor and alias) by the dumper."""
    kind = type(data)
    if kind is dict:
        for value in data.values():
            if type(value) in (dict, list):
                _count_lists(value, counts)
    elif kind is list:
        counts[id(data)] = counts.get(id(data), 0) + 1
        for value in data:
            if type(value) in (dict, list):
                _count_lists(value, counts)


def _set_aside_float_lists(data: Any, lists: dict[str, list], counts: dict[int, int]) -> Any:
    """``data`` with each long list of floats (or of equal-length lists of floats) that is
    a mapping's value, reached once (``counts``, :func:`_count_lists`), replaced by a
    unique mark, the mark -> its items' texts (a list of str, or of lists of str) in
    ``lists``; the mappings on the way copied, nothing else."""
    if type(data) is not dict:
        return data
    out = {}
    for key, value in data.items():
        texts = None
        if (type(value) is list and len(value) and counts.get(id(value)) == 1
                and all(counts.get(id(v), 1) == 1 for v in value if type(v) is list)
                and sum(len(v) if type(v) is list else 1 for v in value) >= FLOAT_LIST_MIN):
            if type(value[0]) is list:
                size = len(value[0])
                if size and all(type(v) is list and len(v) == size for v in value):
                    flat = _float_texts([x for v in value for x in v])
                    texts = None if flat is None else [flat[i:i + size] for i in range(0, len(flat), size)]
            else:
                texts = _float_texts(value)
        if texts is None:
            out[key] = _set_aside_float_lists(value, lists, counts)
        else:
            mark = f"rbstab-float-list-{_MARK}-{len(lists)}"
            lists[mark] = texts
            out[key] = mark
    return out


_MARK = uuid.uuid4().hex
_FLOAT_DUMPER = _Dumper(io.StringIO())


def _float_list_text(items: list, column: int, indent: int) -> str:
    """A flow sequence of plain scalars ``items`` (str, or lists of str: nested sequences)
    as libyaml's emitter writes it from ``column`` (where its ``[`` goes) with ``indent``
    (the mapping's indentation plus one step): after each ``,`` and before an item, a new
    line indented when the line is past :data:`_BEST_WIDTH` columns; a nested sequence's
    items one step further in."""
    parts: list[str] = ["["]
    col = column + 1
    inner = indent + _BEST_INDENT
    breaks = "\n" + " " * indent
    for i, item in enumerate(items):
        if i:
            parts.append(",")
            col += 1
        if col > _BEST_WIDTH:
            parts.append(breaks)
            col = indent
        elif i:
            parts.append(" ")
            col += 1
        if type(item) is str:
            parts.append(item)
            col += len(item)
            continue
        parts.append("[")
        col += 1
        for j, text in enumerate(item):
            if j:
                parts.append(",")
                col += 1
            if col > _BEST_WIDTH:
                parts.append("\n" + " " * inner)
                col = inner
            elif j:
                parts.append(" ")
                col += 1
            parts.append(text)
            col += len(text)
        parts.append("]")
        col += 1
    parts.append("]")
    return "".join(parts)


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
