"""Dotted key paths (``controller.k_t``, ``initial_state.omega.0``) and ``--set`` overrides."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .errors import ConfigError
from .schema import field_at, kind_of
from .yaml_io import parse_yaml

__all__ = ["set_dotted", "get_dotted", "apply_overrides", "plain_tree"]


class _PathError(Exception):
    pass


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


def _parts(path: str) -> list[str]:
    parts = path.split(".")
    if not path or any(not p.strip() or p != p.strip() for p in parts):
        raise _PathError(
            f"malformed key path {path!r} (expected e.g. 'controller.k_t', 'initial_state.omega.0')"
        )
    return parts


def _is_index(part: str) -> bool:
    """Whether a key path component is a list index: ASCII digits only (``str.isdigit``
    also takes '²' and '١', which ``int`` refuses or reads as another number)."""
    return part.isascii() and part.isdigit()


def _index(node: list, part: str, where: str) -> int:
    if not _is_index(part):
        raise _PathError(f"'{where}' is a list; index it with 0..{len(node) - 1}, not {part!r}")
    i = int(part)
    if i >= len(node):
        raise _PathError(f"index {i} out of range for '{where}' (a list of {len(node)})")
    return i


def _schema_default(parts: Sequence[str]) -> list | None:
    """A copy of the schema default of a list-valued key (``initial_state.theta``), else None."""
    _, info = field_at(parts)
    default = info.get_default(call_default_factory=True) if info is not None else None
    return list(default) if isinstance(default, (list, tuple)) else None


def _walk(data: Any, parts: list[str], *, create: bool) -> Any:
    """The container holding ``parts[-1]``; missing mappings are created if ``create``."""
    node = data
    for depth, part in enumerate(parts[:-1]):
        where = ".".join(parts[: depth + 1])
        if isinstance(node, dict):
            if part not in node:
                if not create:
                    raise _PathError(f"'{where}' is not set")
                default = _schema_default(parts[: depth + 1])
                if default is None and _is_index(parts[depth + 1]):
                    raise _PathError(
                        f"'{where}' is not set, so it has no index {parts[depth + 1]}; "
                        "set the whole list"
                    )
                node[part] = {} if default is None else default
            node = node[part]
        elif isinstance(node, list):
            node = node[_index(node, part, ".".join(parts[:depth]))]
        else:
            raise _PathError(f"'{'.'.join(parts[:depth])}' is {kind_of(node)}; it has no '{part}'")
    if not isinstance(node, (dict, list)):
        raise _PathError(f"'{'.'.join(parts[:-1])}' is {kind_of(node)}; it has no '{parts[-1]}'")
    return node


def set_dotted(data: dict, path: str, value: Any) -> None:
    """Set ``data[a][b][0] = value`` for ``path = "a.b.0"``, in place.

    Components that are non-negative integers index into lists; missing mapping keys
    are created (whether they are allowed is for validation to judge). Indexing into an
    absent key whose schema default is a list starts from that default, so
    ``initial_state.theta.1=0.5`` works when the config leaves ``theta`` at zero.

    Raises
    ------
    ConfigError
        If the path is malformed, an index is out of range or not an integer, the path
        descends into a scalar, or it would index into a list that is not set.
    """
    try:
        _set(data, path, value)
    except _PathError as exc:
        raise ConfigError([f"cannot set {path!r}: {exc}"]) from None


def _set(data: dict, path: str, value: Any) -> None:
    parts = _parts(path)
    node = _walk(data, parts, create=True)
    if isinstance(node, list):
        node[_index(node, parts[-1], ".".join(parts[:-1]))] = value
    else:
        node[parts[-1]] = value


def get_dotted(data: Any, path: str) -> Any:
    """The value at ``path = "a.b.0"`` (``data[a][b][0]``); integer components index lists.

    Raises
    ------
    KeyError
        If the path is malformed or leads to nothing.
    """
    try:
        parts = _parts(path)
        node = _walk(data, parts, create=False)
        if isinstance(node, list):
            return node[_index(node, parts[-1], ".".join(parts[:-1]))]
        if parts[-1] not in node:
            raise _PathError(f"'{path}' is not set")
        return node[parts[-1]]
    except _PathError as exc:
        raise KeyError(str(exc)) from None


def apply_overrides(data: Mapping, overrides: Sequence[str]) -> dict:
    """A deep copy of ``data`` with each ``key.path=value`` override applied, in order.

    The value is parsed as YAML (``controller.k_t=[1,2,3]``, ``simulation.t_end=1.5``,
    ``controller.variant=free``); see :func:`set_dotted` for the path rules.

    Raises
    ------
    ConfigError
        Naming every malformed override (no '=', empty key, invalid YAML value, index out
        of range, a path through a scalar).
    """
    result = plain_tree(data)
    problems = []
    for override in overrides:
        key, sep, text = override.partition("=")
        if not sep:
            problems.append(f"override {override!r}: no '='; expected key.path=value")
            continue
        try:
            _set(result, key.strip(), parse_yaml(text))
        except _PathError as exc:
            problems.append(f"override {override!r}: {exc}")
        except ConfigError as exc:  # the value is not valid YAML
            prefix = f"override {override!r}: the value is not valid YAML"
            problems += [f"{prefix}: {line}" for line in exc.errors]
    if problems:
        raise ConfigError(problems)
    return result
