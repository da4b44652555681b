"""Dotted key paths (``controller.k_t``, ``initial_state.omega.0``) and ``--set`` overrides.

:func:`parse_key` is the one reading of a key path, for every command that takes one
(``--set``, a sweep's grid, zip, random and table keys, ``--grid``, ``--zip``, ``--random``,
``--vary``, ``--over``, ``--basin``, ``--basin-stability``, the Python API). A key is::

    section . [entry .] field [. subfield ...] [. index ...]

- ``section`` a top-level key of the configuration (``body``, ``controller``, ...);
- ``entry`` for a section that is a list of entries (``disturbances.0``): an index in
  0..N-1, N the most entries the schema allows (an entry model with a ``name`` field also
  takes the entry's name);
- ``field`` a key of the section (``k_c``), through its subsections
  (``saturation.torque_n``, ``limits.theta``);
- ``index`` entries of a field's value, as many as its shape has dimensions (a vector of
  3: ``initial_state.omega.1``; a 3x3 matrix: ``body.inertia.0.2``, or one index for the
  diagonal entry of a matrix written as 3 numbers), each an ASCII integer in 0..n-1.

The names and the shapes are the schema's (:mod:`rbstab.config.schema`). A key that names
nothing is refused with :class:`KeyPathError`, one line naming the key, the wrong segment
and what is allowed there.
"""

from __future__ import annotations

import difflib
import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..layout import is_chain, is_index
from .errors import ConfigError
from .schema import ChainSchema, RunSchema, field_check, kind_of, list_model, mapping_model, submodel
from .yaml_io import parse_yaml

__all__ = ["KeyPath", "KeyPathError", "parse_key", "parse_any_key", "apply_overrides", "plain_tree",
           "schema_of"]

#: Longest key path taken (characters): longer is no key of the schema.
MAX_KEY_LENGTH = 200
_EXAMPLE = "e.g. 'controller.k_t', 'initial_state.omega.0', 'disturbances.0.value.2'"


class KeyPathError(ConfigError):
    """A key path that names nothing of the configuration, or that cannot be set or read.

    Attributes
    ----------
    key : str
        The key as given.
    problem : str
        One line: the wrong segment and what is allowed there (the names, the index range).
    """

    def __init__(self, key: Any, problem: str) -> None:
        self.key, self.problem = key, problem
        super().__init__([f"key {_shown(key)}: {problem}"])


def _shown(text: Any, limit: int = 80) -> str:
    """``repr`` of a key or segment (escapes included: a message stays one line), shortened."""
    shown = repr(text)
    return shown if len(shown) <= limit else shown[: limit - 4] + "...'"


_SCALARS = (float, int, str, bool, type(None))


def plain_tree(value: Any) -> Any:
    """Deep copy with mappings as dicts, sequences as lists, numpy values as Python ones."""
    kind = type(value)
    if kind in _SCALARS:  # the common cases first, without the ABC checks
        return value
    if kind is dict:
        return {k: plain_tree(v) for k, v in value.items()}
    if kind is list:
        return [plain_tree(v) for v in value]
    if isinstance(value, Mapping):
        return {k: plain_tree(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_tree(v) for v in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    return value  # a scalar


def _shape_words(shape: tuple[int, ...]) -> str:
    return f"a list of {shape[0]}" if len(shape) == 1 else f"a {'x'.join(map(str, shape))} matrix"


_MISSING = object()


@dataclass(frozen=True)
class KeyPath:
    """A parsed key path (:func:`parse_key`).

    Attributes
    ----------
    key : str
        The key (dotted).
    section : str
        Its top-level key (``controller``).
    entry : int, str or None
        The entry of a section that is a list (``disturbances.0`` -> 0), by index or name.
    field : str
        The field inside the section or entry, dotted through subsections
        (``saturation.torque_n``); "" for the section or entry itself.
    index : tuple of int
        Indices into the field's value (``initial_state.omega.1`` -> (1,)).
    shape : tuple of int
        The shape of the field's value: () a single value, (3,) a vector, (3, 3) a matrix.
    rule : tuple or None
        The constraint of the field in the form a batched check reads (the check's
        ``rule``: ``("number", bounds)``, ``("vector",)``, ``("theta",)``, ``("matrix",
        kind)``, ``("limits", bounds)``), or None.
    description : str
        What the field takes (the schema's description).
    """

    key: str
    section: str
    entry: int | str | None
    field: str
    index: tuple[int, ...]
    shape: tuple[int, ...]
    rule: tuple | None
    description: str
    #: (position in :attr:`steps`, default) of each field on the path whose schema default is a
    #: list: what indexing into it starts from where the configuration leaves it unset.
    defaults: tuple = ()

    @property
    def name(self) -> str:
        """The dotted name inside the section, entry included (``k_c``, ``0.start``)."""
        entry = "" if self.entry is None else str(self.entry)
        return ".".join(p for p in (entry, self.field) if p)

    @functools.cached_property  # read by every get and set (a sweep sets its keys in every run)
    def steps(self) -> tuple:
        """The walk into a mapping: keys (str) and list positions (int; a str entry a name)."""
        fields = tuple(self.field.split(".")) if self.field else ()
        entry = () if self.entry is None else (self.entry,)
        return (self.section, *entry, *fields, *self.index)

    def get(self, data: Any, default: Any = _MISSING) -> Any:
        """The value at the path in ``data`` (a configuration mapping); a matrix written as
        3 numbers reads as the 3x3 it stands for, a limit written as one number as that
        number on every axis.

        Raises
        ------
        KeyPathError
            If the path leads to nothing and no ``default`` is given.
        """
        node = data
        steps = self.steps
        n_field = len(steps) - len(self.index)  # steps[n_field - 1] is the field
        for depth, step in enumerate(steps):
            if depth == n_field:  # the field's value: what stands for more numbers, read as those
                if len(self.index) == 2 and _is_vector(node, self.shape):
                    i, j = self.index
                    return node[i] if i == j else 0.0
                if self.rule is not None and self.rule[0] == "limits" and _is_number(node):
                    return node
            try:
                node = _child(node, step)
            except LookupError:
                if default is _MISSING:
                    raise KeyPathError(self.key, f"'{'.'.join(map(str, steps[:depth + 1]))}' is not set") from None
                return default
        return node

    def set(self, data: dict, value: Any) -> None:
        """Set the value at the path in ``data``, in place.

        Missing mappings are created; indexing into a field the configuration leaves at its
        default starts from the default (``initial_state.theta.1``); a matrix written as 3
        numbers becomes the 3x3 it stands for before an off-diagonal entry is set, and a
        limit written as one number the 3 it stands for before one axis is set.

        Raises
        ------
        KeyPathError
            If it indexes into a field that is not set and has no list default, an entry
            of a list section beyond its entries, or a value that is not a list.
        """
        steps = self.steps
        n_field = len(steps) - len(self.index)  # steps[n_field - 1] is the field
        defaults = dict(self.defaults)
        node = data
        for depth, step in enumerate(steps[:-1]):
            where = ".".join(map(str, steps[: depth + 1]))
            is_key = depth < n_field and not (self.entry is not None and depth == 1)
            if depth == 1 and isinstance(self.entry, str) and isinstance(node, dict):  # a named mapping's entry
                node = node.setdefault(step, {})
                continue
            if is_key and isinstance(node, dict):
                if node.get(step) is None:
                    entry_next = self.entry is not None and depth == 0
                    if depth + 1 < n_field and not entry_next:
                        node[step] = {}
                    elif isinstance(defaults.get(depth), list) and not entry_next:
                        node[step] = plain_tree(defaults[depth])
                    else:
                        raise KeyPathError(self.key, f"'{where}' is not set, so it has no entry "
                                                     f"{_shown(str(steps[depth + 1]))}; set the whole list")
                if depth == n_field - 1:  # the field: what stands for more numbers, expanded
                    node[step] = _expanded(node[step], self)
                node = node[step]
                continue
            try:
                node = _child(node, step)
            except LookupError:
                parent = ".".join(map(str, steps[:depth]))
                raise KeyPathError(self.key, f"'{parent}' {_found(node)}; there is no {_shown(str(step))} to set"
                                             f"{_close_name(node, step, parent)}") from None
        last = steps[-1]
        if isinstance(node, dict) and isinstance(last, str):
            node[last] = value
        elif isinstance(node, list) and isinstance(last, int) and last < len(node):
            node[last] = value
        else:
            where = ".".join(map(str, steps[:-1]))
            raise KeyPathError(self.key, f"'{where}' {_found(node)}; there is no {_shown(str(last))} to set"
                                         f"{_close_name(node, last, where)}")


def _found(node: Any) -> str:
    """What a value found on the path is, for a message: ``has 1 entry``, ``has 2 entries
    (names: legs, trunk)``, ``is a number``."""
    if isinstance(node, list):
        names = [e["name"] for e in node if isinstance(e, Mapping) and isinstance(e.get("name"), str)]
        named = f" (0..{len(node) - 1}, or by name: {', '.join(names)})" if names and len(names) == len(node) else ""
        return f"has {len(node)} entr{'y' if len(node) == 1 else 'ies'}{named}"
    return f"is {kind_of(node)}"


def _close_name(node: Any, step: Any, where: str) -> str:
    """The end of the message of a step that names nothing in ``node``: the closest name of
    a named list's entries (``; did you mean 'joints.ankle'?``), else what to do instead."""
    names = [e["name"] for e in node if isinstance(e, Mapping) and isinstance(e.get("name"), str)] \
        if isinstance(node, list) else []
    close = difflib.get_close_matches(str(step), names, n=1) if isinstance(step, str) else []
    return f"; did you mean '{where}.{close[0]}'?" if close else " (set the whole value)"


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.number)) and not isinstance(value, bool)


def _is_vector(node: Any, shape: tuple[int, ...]) -> bool:
    return len(shape) == 2 and isinstance(node, (list, tuple)) and len(node) == shape[0] and not any(
        isinstance(v, (list, tuple)) for v in node)


def _expanded(value: Any, path: KeyPath) -> Any:
    """The field's value before one of its entries is set: 3 numbers of a matrix as the
    diagonal matrix (for an entry [i][j]), one limit as 3 (for an axis)."""
    if len(path.index) == 2 and _is_vector(value, path.shape):
        return np.diag(np.asarray(value, dtype=float)).tolist()
    if path.index and path.rule is not None and path.rule[0] == "limits" and _is_number(value):
        return [value] * path.shape[0]
    return value


def _child(node: Any, step: str | int) -> Any:
    """``node[step]``: a key of a mapping, a position in a list, or the entry of a list
    whose ``name`` is ``step``; LookupError where there is none."""
    if isinstance(node, Mapping) and isinstance(step, str):
        return node[step]
    if isinstance(node, (list, tuple)):
        if isinstance(step, int):
            return node[step]
        for entry in node:
            if isinstance(entry, Mapping) and entry.get("name") == step:
                return entry
    raise LookupError(step)


def _unknown(key: str, where: str, part: str, allowed: Sequence[str], model: Any, root: Any) -> KeyPathError:
    """An unknown name: the closest allowed one, else the same name in another section."""
    prefix = f"{where}." if where else ""
    close = difflib.get_close_matches(part, list(allowed), n=1)
    hint = f"; did you mean '{prefix}{close[0]}'?" if close else ""
    if not close and where and model is not root:
        other = next((s for s, info in root.model_fields.items()
                      if s != where.partition(".")[0] and (sub := submodel(info.annotation)) is not None
                      and part in sub.model_fields), None)
        hint = f"; did you mean '{other}.{part}'?" if other else ""
    what = f"'{where}' has no {_shown(part)}" if where else f"unknown section {_shown(part)}"
    if where and part.isdigit():
        what = f"'{where}' is a mapping, not a list; it has no {_shown(part)}"
    return KeyPathError(key, f"{what}{hint} (allowed: {', '.join(allowed)})")


def schema_of(data: Any):
    """The schema a configuration mapping's keys are read against: a chain's
    (:class:`~rbstab.config.schema.ChainSchema`, :func:`rbstab.layout.is_chain`), else one body's
    (:class:`~rbstab.config.schema.RunSchema`)."""
    return ChainSchema if is_chain(data) else RunSchema


@functools.lru_cache(maxsize=4096)  # the same keys for every run of a sweep
def parse_key(key: str, root: Any = None) -> KeyPath:
    """The key path ``key`` (module docstring) checked against the schema.

    Parameters
    ----------
    key : str
        A dotted key: ``body.mass``, ``controller.k_c.0.1``, ``disturbances.0.value.2``.
    root : pydantic model, optional
        The model the key starts in (default: the run configuration's schema).

    Raises
    ------
    KeyPathError
        One line naming the key, the segment that is wrong (an empty one, an unknown name,
        a word where an index belongs or an index out of range, a segment past the end)
        and what is allowed there (the names, with the closest one; the index range).
    """
    root = RunSchema if root is None else root
    if not isinstance(key, str) or not key:
        raise KeyPathError(key, f"expected a dotted key, {_EXAMPLE}")
    if len(key) > MAX_KEY_LENGTH:
        raise KeyPathError(key, f"{len(key)} characters; a key has at most {MAX_KEY_LENGTH}")
    parts = key.split(".")
    for i, part in enumerate(parts):
        if not part:
            raise KeyPathError(key, f"segment {i + 1} of {len(parts)} is empty (a doubled, leading or trailing "
                                    f"'.'); {_EXAMPLE}")
        if part != part.strip():
            raise KeyPathError(key, f"segment {_shown(part)} has white space around it")
    model, info, section, entry = root, None, "", None
    fields: list[str] = []
    index: list[int] = []
    defaults: list[tuple[int, Any]] = []
    shape: tuple[int, ...] = ()
    i = 0
    while i < len(parts):
        part, where = parts[i], ".".join(parts[:i])
        if model is not None:  # a mapping: the part names one of its fields
            if part not in model.model_fields:
                raise _unknown(key, where, part, list(model.model_fields), model, root)
            info = model.model_fields[part]
            if section:
                fields.append(part)
            else:
                section = part
            default = None if info.is_required() else info.get_default(call_default_factory=True)
            if isinstance(default, (list, tuple)):  # what indexing into the field starts from when it is unset
                defaults.append((i, plain_tree(default)))
            entries = list_model(info.annotation)
            named_values = mapping_model(info.annotation)
            if named_values is not None and not fields and i + 1 < len(parts):  # a mapping of names: a name next
                i += 1
                if is_index(parts[i]):
                    raise KeyPathError(key, f"'{'.'.join(parts[:i])}' is a mapping by name; name its entry "
                                            f"(e.g. a body's name), not {_shown(parts[i])}")
                entry, model = parts[i], named_values
            elif entries is not None and not fields and i + 1 < len(parts):  # a section that is a list: an entry next
                i += 1
                most = (info.json_schema_extra or {}).get("max_entries") if isinstance(info.json_schema_extra, dict) \
                    else None
                text = parts[i]
                named = "name" in entries.model_fields
                if is_index(text) and (most is None or int(text) < most):
                    entry = int(text)
                elif named and not is_index(text):
                    entry = text
                else:
                    size, span = (f"at most {most} entries", f"0..{most - 1}") if most else ("entries", "0, 1, ...")
                    names = " or an entry's name" if named else ""
                    raise KeyPathError(key, f"'{'.'.join(parts[:i])}' is a list of {size}; index it with {span}{names}, "
                                            f"not {_shown(text)}")
                model = entries
            else:
                model = submodel(info.annotation)
                check = field_check(info) if model is None else None
                shape = tuple(getattr(check, "shape", ())) if check is not None else ()
        else:  # past the field: the part indexes its value
            field_path = ".".join(parts[:i - len(index)])
            if len(index) >= len(shape):
                if not shape:
                    raise KeyPathError(key, f"'{field_path}' is {info.description or 'a single value'}; it has no "
                                            f"entry {_shown(part)}")
                raise KeyPathError(key, f"'{where}' is one number of '{field_path}' ({_shape_words(shape)}); it has "
                                        f"no entry {_shown(part)}")
            n = shape[len(index)]
            if not is_index(part) or int(part) >= n:
                raise KeyPathError(key, f"'{where}' is {_shape_words(shape[len(index):])}; index it with 0..{n - 1}, "
                                        f"not {_shown(part)}")
            index.append(int(part))
        i += 1
    check = field_check(info) if info is not None and model is None else None
    return KeyPath(key, section, entry, ".".join(fields), tuple(index), shape,
                   getattr(check, "rule", None) if check is not None else None,
                   (info.description or "") if info is not None else "", tuple(defaults))


def parse_any_key(key: str) -> KeyPath:
    """``key`` read as a key of a one-body configuration, else of a chain's
    (:class:`rbstab.config.schema.ChainSchema`): what a command can check before it knows
    which kind its configuration is.

    Raises
    ------
    KeyPathError
        The refusal of the schema whose section the key names (the one-body one where both
        or neither name it).
    """
    try:
        return parse_key(key)
    except KeyPathError as one_body:
        section, _, rest = key.partition(".") if isinstance(key, str) else ("", "", "")
        one_body_section = RunSchema.model_fields.get(section)
        model = submodel(one_body_section.annotation) if one_body_section is not None else None
        segment = rest.partition(".")[0]
        if model is not None and segment in model.model_fields:
            raise  # a one-body key (``initial_state.theta.x``), not a body named like its field
        try:
            return parse_key(key, ChainSchema)
        except KeyPathError as chain:
            if section in ChainSchema.model_fields and (
                    one_body_section is None  # a chain's section (``joints``)
                    or (model is not None and not difflib.get_close_matches(segment, list(model.model_fields), n=1))
                    or ("did you mean" in chain.problem and "did you mean" not in one_body.problem)):
                raise chain from None  # a body's name (``initial_state.hat.thta``): the chain's reading is the one meant
            raise one_body from None


def apply_overrides(data: Mapping, overrides: Sequence[str], root: Any = None) -> dict:
    """A deep copy of ``data`` with each ``key.path=value`` override applied, in order;
    the keys read against ``root`` (a schema model; None: ``data``'s, :func:`schema_of`).

    The value is parsed as YAML (``controller.k_t=[1,2,3]``, ``simulation.t_end=1.5``,
    ``controller.variant=free``); the key is read by :func:`parse_key` and set by
    :meth:`KeyPath.set`.

    Raises
    ------
    ConfigError
        Naming every malformed override, one line each (no '=', a key that names nothing of
        the schema, an invalid YAML value, an index into a list that is not set).
    """
    result = plain_tree(data)
    root = schema_of(data) if root is None else root
    problems = []
    for override in overrides:
        key, sep, text = override.partition("=")
        if not sep:
            problems.append(f"override {override!r}: no '='; expected key.path=value")
            continue
        try:
            path = parse_key(key.strip(), root)
            value = parse_yaml(text)
            path.set(result, value)
        except KeyPathError as exc:
            problems.append(f"override {override!r}: {exc.problem}")
        except ConfigError as exc:  # the value is not valid YAML
            prefix = f"override {override!r}: the value is not valid YAML"
            problems += [f"{prefix}: {line}" for line in exc.errors]
    if problems:
        raise ConfigError(problems)
    return result
