"""Run configuration: a YAML file -> a validated, frozen :class:`RunConfig`.

Validation happens here, once, at the boundary; the core (:mod:`rbstab.model`, the
variants, the integrator) trusts what it receives. Every problem in a configuration is
reported at once, one line each: the dotted key, the value found, what is allowed and,
in parentheses, what is wrong with it, e.g. (one line)::

    config key 'controller.k_t': found [1, 2]; expected 3 numbers (a diagonal) or a 3x3
    list of lists, symmetric positive definite (N/m) (2 entries, not 3)

Schema (the keys are public; units in brackets)::

    name: case3_embedded            # optional, default: the file stem; [A-Za-z0-9_.-]+
    body:
      mass: 41.0                    # m [kg] > 0, required
      inertia: [10.0, 8.0, 0.4]     # J [kg m^2]: 3 principal moments or a 3x3 list; SPD; required
      attachment_point: [0.15, 0.10, -0.42]  # R [m], body frame, required
      gravity: [0.0, 0.0, 0.0]      # g [m/s^2], inertial frame, default zeros
    controller:
      variant: embedded             # a key of rbstab.variants.VARIANTS, required
      k_t: [4100, 4100, 3280]       # gains k_t l_t k_r l_r k_c l_c k_d l_d: 3 numbers (a
      ...                           # diagonal) or a 3x3 list; SPD; required when the
                                    # variant's ``required_gains`` lists them
      k_s: 500.0                    # K_s [N] > 0 (sliding, eq 39)
      boundary_layer: 0.0           # phi [m] >= 0, default 0 (pure sign function)
    initial_state:                  # each key 3 numbers, default zeros
      theta: [0, 0, 0]              # [rad], |theta_2| < pi/2 - gimbal_margin
      omega: [16, 32, -16]          # [rad/s], body frame
      x: [0, 0, 0]                  # [m]   -> state block 'position'
      v: [0, 0, 0]                  # [m/s] -> state block 'velocity'
      d: [0, 0, 0]                  # [m]   -> state block 'controller_state' (embedded)
    simulation:
      t_end: 2.0                    # [s] > 0
      n_samples: 2001               # integer >= 2
      method: DOP853                # a scipy solve_ivp method
      rtol: 1.0e-8                  # > 0
      atol: 1.0e-10                 # > 0
      max_step: .inf                # [s] > 0 (null means inf)
      gimbal_margin: 1.0e-3         # [rad] in (0, 0.5)

Gains the variant does not use (and ``initial_state.d`` for variants without a controller
state) are validated, kept in :attr:`RunConfig.resolved`, and otherwise ignored, so one
base configuration can serve a sweep over variants.

YAML is read with a :class:`yaml.SafeLoader` subclass that differs in two ways: ``1e-8``
is a float (PyYAML follows YAML 1.1 and reads it as a string), and a key given twice in
one mapping is an error instead of silently keeping the last value.
"""

import difflib
import math
import numbers
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)
from pydantic_core import PydanticCustomError

from .layout import BLOCK_UNITS
from .model import Gains, RigidBody
from .variants import VARIANTS, Variant

__all__ = [
    "ConfigError",
    "PhysicalPlausibilityWarning",
    "RunConfig",
    "SimulationSettings",
    "load_config",
    "config_from_mapping",
    "apply_overrides",
    "set_dotted",
    "get_dotted",
    "GAIN_NAMES",
    "GAIN_UNITS",
    "INITIAL_STATE_BLOCKS",
]

#: Matrix gains of ``controller`` (:class:`rbstab.model.Gains`), with their units.
GAIN_UNITS = {
    "k_t": "N/m",
    "l_t": "N s/m",
    "k_r": "N m/rad",
    "l_r": "N m s/rad",
    "k_c": "N/m",
    "l_c": "N s/m",
    "k_d": "N/m",
    "l_d": "N s/m",
}
GAIN_NAMES = tuple(GAIN_UNITS)

#: ``initial_state`` config key -> state block name of :mod:`rbstab.layout`.
INITIAL_STATE_BLOCKS = {
    "theta": "theta",
    "omega": "omega",
    "x": "position",
    "v": "velocity",
    "d": "controller_state",
}

_NAME_PATTERN = re.compile(r"[A-Za-z0-9_.-]+")
_SYMMETRY_RTOL = 1e-12
# Used only if scipy moves its private registry (scipy.integrate._ivp.ivp.METHODS).
_FALLBACK_METHODS = ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA")


class ConfigError(ValueError):
    """An invalid configuration, file or override.

    Attributes
    ----------
    errors : list of str
        One line per problem, e.g.
        ``config key 'body.mass': found -1; expected a number > 0 (kg)``.
    source : str or None
        The configuration file, if known; ``str()`` then starts with ``in <source>:``.
    """

    def __init__(self, errors: Sequence[str], source: str | None = None) -> None:
        super().__init__(list(errors), source)
        self.errors = list(errors)
        self.source = source

    def __str__(self) -> str:
        header = [f"in {self.source}:"] if self.source else []
        return "\n".join(header + self.errors)


class PhysicalPlausibilityWarning(UserWarning):
    """A configuration the equations accept but no real rigid body has (e.g. the inertia)."""


# -- value checks ------------------------------------------------------------------------
# Each check takes the raw value and returns a plain-Python copy (int/float/str/lists), or
# raises _Invalid with a short detail. What is *allowed* is the field's description.


class _Invalid(Exception):
    def __init__(self, detail: str = "", expected: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.expected = expected


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, numbers.Real):
        return "a number"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    return f"a {type(value).__name__}"


def _as_number(value: Any, *, allow_inf: bool = False) -> int | float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        detail = f"{_kind(value)}, not a number"
        if isinstance(value, str):
            try:
                float(value)
                detail += "; remove the quotes"
            except ValueError:
                pass
        raise _Invalid(detail)
    number = int(value) if isinstance(value, numbers.Integral) else float(value)
    if math.isnan(number) or (math.isinf(number) and not allow_inf):
        raise _Invalid("not a finite number")
    return number


def _number(
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    allow_inf: bool = False,
    integer: bool = False,
) -> Callable[[Any], int | float]:
    def check(value: Any) -> int | float:
        if integer and (isinstance(value, bool) or not isinstance(value, numbers.Integral)):
            raise _Invalid(f"{_kind(value)}, not an integer")
        number = _as_number(value, allow_inf=allow_inf)
        if (
            (gt is not None and not number > gt)
            or (ge is not None and not number >= ge)
            or (lt is not None and not number < lt)
        ):
            raise _Invalid()  # the field's description says what is allowed
        return number

    return check


def _entry(value: Any, where: str) -> int | float:
    try:
        return _as_number(value)
    except _Invalid as exc:
        raise _Invalid(f"entry {where} is {exc.detail}") from None


def _vector(value: Any) -> list[int | float]:
    if not isinstance(value, (list, tuple)):
        raise _Invalid(f"{_kind(value)}, not a list")
    if len(value) != 3:
        raise _Invalid(f"{len(value)} entries, not 3")
    return [_entry(x, f"[{i}]") for i, x in enumerate(value)]


def _spd_matrix(value: Any) -> list:
    """3 numbers (a positive diagonal) or a symmetric positive definite 3x3 list of lists."""
    if not isinstance(value, (list, tuple)):
        raise _Invalid(f"{_kind(value)}, not a list")
    is_row = [isinstance(row, (list, tuple)) for row in value]
    if not any(is_row):
        diagonal = _vector(value)
        bad = [f"[{i}] = {x:g}" for i, x in enumerate(diagonal) if not x > 0]
        if bad:
            raise _Invalid(f"not positive definite: diagonal {', '.join(bad)}; each must be > 0")
        return diagonal
    if not all(is_row):
        raise _Invalid("it mixes numbers and lists")
    lengths = sorted({len(row) for row in value})
    if len(value) != 3 or lengths != [3]:
        raise _Invalid(f"a {len(value)}x{'/'.join(map(str, lengths))} list of lists")
    rows = [[_entry(x, f"[{i}][{j}]") for j, x in enumerate(row)] for i, row in enumerate(value)]
    matrix = np.array(rows, dtype=float)
    asymmetry = np.abs(matrix - matrix.T)
    if asymmetry.max() > _SYMMETRY_RTOL * np.abs(matrix).max():
        i, j = np.unravel_index(np.argmax(asymmetry), matrix.shape)
        raise _Invalid(
            f"not symmetric: [{i}][{j}] = {matrix[i, j]:g} but [{j}][{i}] = {matrix[j, i]:g}"
        )
    smallest = np.linalg.eigvalsh(matrix)[0]
    if not smallest > 0:
        raise _Invalid(f"not positive definite: smallest eigenvalue {smallest:g}")
    return rows


def _theta(value: Any) -> list[int | float]:
    """Euler angles; the margin to gimbal lock is checked with the simulation section."""
    theta = _vector(value)
    if not abs(theta[1]) < math.pi / 2:
        raise _Invalid(
            "B(theta) is singular at |theta_2| = pi/2 (gimbal lock, eq 1)",
            "3 numbers (rad) with theta_2 in (-pi/2, pi/2)",
        )
    return theta


def _optional(check: Callable[[Any], Any]) -> Callable[[Any], Any]:
    return lambda value: None if value is None else check(value)


def _did_you_mean(word: str, choices: Sequence[str], prefix: str = "") -> str:
    match = difflib.get_close_matches(word, list(choices), n=1)
    return f"did you mean '{prefix}{match[0]}'?" if match else ""


def _name(value: Any) -> str:
    if not isinstance(value, str):
        raise _Invalid(f"{_kind(value)}, not a string")
    if not _NAME_PATTERN.fullmatch(value) or set(value) == {"."}:
        raise _Invalid()
    return value


def _variant(value: Any) -> str:
    if not isinstance(value, str):
        raise _Invalid(f"{_kind(value)}, not a string")
    if value not in VARIANTS:
        raise _Invalid(_did_you_mean(value, list(VARIANTS)))
    return value


def _solver_methods() -> tuple[str, ...]:
    try:
        from scipy.integrate._ivp.ivp import METHODS  # lazy: scipy is slow to import
    except ImportError:  # pragma: no cover - scipy moved its private registry
        return _FALLBACK_METHODS
    return tuple(METHODS)


def _method(value: Any) -> str:
    methods = _solver_methods()
    expected = f"one of {', '.join(methods)} (scipy solve_ivp methods)"
    if not isinstance(value, str):
        raise _Invalid(f"{_kind(value)}, not a string", expected)
    if value not in methods:
        by_case = {m.lower(): m for m in methods}
        hint = f"did you mean '{by_case[value.lower()]}'?" if value.lower() in by_case else ""
        raise _Invalid(hint or _did_you_mean(value, methods), expected)
    return value


def _max_step(value: Any) -> float:
    """null means inf (that is how :attr:`RunConfig.resolved` writes inf)."""
    return math.inf if value is None else _number(gt=0, allow_inf=True)(value)


def _checked(check: Callable[[Any], Any]) -> BeforeValidator:
    def validate(value: Any) -> Any:
        try:
            return check(value)
        except _Invalid as exc:
            ctx = {"detail": exc.detail}
            if exc.expected:
                ctx["expected"] = exc.expected
            raise PydanticCustomError("rbstab_invalid", "invalid value {detail}", ctx) from None

    return BeforeValidator(validate)


@dataclass(frozen=True)
class SimulationSettings:
    """Integration settings of one run (``simulation`` section).

    Attributes
    ----------
    t_end : float
        Final time [s], > 0; the run starts at t = 0.
    n_samples : int
        Number of output samples on [0, t_end], >= 2.
    method : str
        scipy ``solve_ivp`` method.
    rtol, atol : float
        Relative and absolute tolerances of the solver, > 0.
    max_step : float
        Largest solver step [s], > 0; ``inf`` for no limit.
    gimbal_margin : float
        [rad] in (0, 0.5): the run stops when |theta_2| >= pi/2 - gimbal_margin.
    """

    t_end: float = 2.0
    n_samples: int = 2001
    method: str = "DOP853"
    rtol: float = 1e-8
    atol: float = 1e-10
    max_step: float = math.inf
    gimbal_margin: float = 1e-3


# -- schema --------------------------------------------------------------------------------

_VECTOR = Annotated[Any, _checked(_vector)]
_OPTIONAL_SPD = Annotated[Any, _checked(_optional(_spd_matrix))]
_ZERO = (0.0, 0.0, 0.0)


def _gain(name: str) -> Any:
    return Field(
        None,
        validate_default=True,
        description="3 numbers (a diagonal) or a 3x3 list of lists, "
        f"symmetric positive definite ({GAIN_UNITS[name]})",
    )


def _mapping_of(model: type[BaseModel]) -> str:
    return f"a mapping with keys {', '.join(model.model_fields)}"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class _Body(_Section):
    mass: Annotated[Any, _checked(_number(gt=0))] = Field(description="a number > 0 (kg)")
    inertia: Annotated[Any, _checked(_spd_matrix)] = Field(
        description="3 numbers (principal moments) or a 3x3 list of lists, "
        "symmetric positive definite (kg m^2)"
    )
    attachment_point: _VECTOR = Field(description="3 numbers (R, body frame, m)")
    gravity: _VECTOR = Field(_ZERO, description="3 numbers (g, inertial frame, m/s^2)")


class _Controller(_Section):
    # ``variant`` first: the gain validators read it from ``info.data``.
    variant: Annotated[Any, _checked(_variant)] = Field(description=f"one of {', '.join(VARIANTS)}")
    k_t: _OPTIONAL_SPD = _gain("k_t")
    l_t: _OPTIONAL_SPD = _gain("l_t")
    k_r: _OPTIONAL_SPD = _gain("k_r")
    l_r: _OPTIONAL_SPD = _gain("l_r")
    k_c: _OPTIONAL_SPD = _gain("k_c")
    l_c: _OPTIONAL_SPD = _gain("l_c")
    k_d: _OPTIONAL_SPD = _gain("k_d")
    l_d: _OPTIONAL_SPD = _gain("l_d")
    k_s: Annotated[Any, _checked(_optional(_number(gt=0)))] = Field(
        None, validate_default=True, description="a number > 0 (N)"
    )
    boundary_layer: Annotated[Any, _checked(_number(ge=0))] = Field(
        0.0, description="a number >= 0 (m; 0 = pure sign function)"
    )

    @field_validator(*GAIN_NAMES, "k_s", mode="after")
    @classmethod
    def _required_by_variant(cls, value: Any, info: ValidationInfo) -> Any:
        variant = info.data.get("variant")  # absent if the variant itself is invalid
        required = variant is not None and info.field_name in VARIANTS[variant].required_gains
        if value is None and required:
            raise PydanticCustomError(
                "rbstab_missing", "missing", {"detail": f"required by variant '{variant}'"}
            )
        return value


class _InitialState(_Section):
    theta: Annotated[Any, _checked(_theta)] = Field(
        _ZERO, description=f"3 numbers ({BLOCK_UNITS['theta']})"
    )
    omega: _VECTOR = Field(_ZERO, description=f"3 numbers ({BLOCK_UNITS['omega']}, body frame)")
    x: _VECTOR = Field(_ZERO, description=f"3 numbers ({BLOCK_UNITS['position']})")
    v: _VECTOR = Field(_ZERO, description=f"3 numbers ({BLOCK_UNITS['velocity']})")
    d: _VECTOR = Field(_ZERO, description=f"3 numbers ({BLOCK_UNITS['controller_state']})")


_DEFAULT_SIMULATION = SimulationSettings()


class _Simulation(_Section):
    t_end: Annotated[Any, _checked(_number(gt=0))] = Field(
        _DEFAULT_SIMULATION.t_end, description="a number > 0 (s)"
    )
    n_samples: Annotated[Any, _checked(_number(ge=2, integer=True))] = Field(
        _DEFAULT_SIMULATION.n_samples, description="an integer >= 2"
    )
    method: Annotated[Any, _checked(_method)] = Field(
        _DEFAULT_SIMULATION.method, description="a scipy solve_ivp method name"
    )
    rtol: Annotated[Any, _checked(_number(gt=0))] = Field(
        _DEFAULT_SIMULATION.rtol, description="a number > 0"
    )
    atol: Annotated[Any, _checked(_number(gt=0))] = Field(
        _DEFAULT_SIMULATION.atol, description="a number > 0"
    )
    max_step: Annotated[Any, _checked(_max_step)] = Field(
        _DEFAULT_SIMULATION.max_step, description="a number > 0 (s), .inf or null for no limit"
    )
    gimbal_margin: Annotated[Any, _checked(_number(gt=0, lt=0.5))] = Field(
        _DEFAULT_SIMULATION.gimbal_margin, description="a number in (0, 0.5) (rad)"
    )


class _Run(_Section):
    name: Annotated[Any, _checked(_name)] = Field(
        description="a name of letters, digits, '_', '.' and '-' (it becomes a file name)"
    )
    body: _Body = Field(description=_mapping_of(_Body))
    controller: _Controller = Field(description=_mapping_of(_Controller))
    initial_state: _InitialState = Field(
        default_factory=_InitialState, description=_mapping_of(_InitialState)
    )
    # validate_default: the theta check below must also run when the section is absent.
    simulation: _Simulation = Field(
        default_factory=_Simulation, validate_default=True, description=_mapping_of(_Simulation)
    )

    @field_validator("initial_state", "simulation", mode="before")
    @classmethod
    def _empty_section(cls, value: Any) -> Any:
        return {} if value is None else value  # "simulation:" with every line commented out

    @field_validator("simulation", mode="after")
    @classmethod
    def _theta_clear_of_gimbal_lock(cls, value: _Simulation, info: ValidationInfo) -> _Simulation:
        state = info.data.get("initial_state")
        if state is None:
            return value
        limit = math.pi / 2 - value.gimbal_margin
        if not abs(state.theta[1]) < limit:
            raise PydanticCustomError(
                "rbstab_invalid",
                "theta_2 too close to gimbal lock",
                {
                    "key": "initial_state.theta",
                    "found": _short(state.theta),
                    "expected": "3 numbers (rad) with theta_2 in (-pi/2 + gimbal_margin, "
                    f"pi/2 - gimbal_margin) = ({-limit:.6g}, {limit:.6g})",
                    "detail": "B(theta) is singular at |theta_2| = pi/2 (gimbal lock, eq 1); "
                    f"gimbal_margin = {value.gimbal_margin:g}",
                },
            )
        return value


_SECTIONS = tuple(_Run.model_fields)
_TOP = _mapping_of(_Run)


# -- pydantic errors -> our lines ----------------------------------------------------------


def _short(value: Any, limit: int = 80) -> str:
    """Short YAML-flavoured repr of a found value, truncated to ``limit`` characters."""

    def rep(v: Any, depth: int = 0) -> str:
        if v is None:
            return "null"
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, np.ndarray):
            v = v.tolist()
        if isinstance(v, np.generic):
            v = v.item()
        if depth > 3:
            return "..."
        if isinstance(v, (list, tuple)):
            items = [rep(x, depth + 1) for x in v[:10]] + (["..."] if len(v) > 10 else [])
            return "[" + ", ".join(items) + "]"
        if isinstance(v, Mapping):
            items = [f"{rep(k, depth + 1)}: {rep(x, depth + 1)}" for k, x in list(v.items())[:10]]
            return "{" + ", ".join(items + (["..."] if len(v) > 10 else [])) + "}"
        return repr(v)

    text = rep(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _walk_models(loc: Sequence[Any]) -> tuple[type[BaseModel] | None, Any]:
    """(model holding the last key of ``loc``, FieldInfo of that key or None)."""
    model: type[BaseModel] | None = _Run
    for i, part in enumerate(loc):
        if model is None or part not in model.model_fields:
            return (model if i == len(loc) - 1 else None), None
        info = model.model_fields[part]
        if i == len(loc) - 1:
            return model, info
        ann = info.annotation
        model = ann if isinstance(ann, type) and issubclass(ann, BaseModel) else None
    return None, None


def _other_section_hint(key: str, section: str) -> str:
    for name in _SECTIONS:
        ann = _Run.model_fields[name].annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel) and name != section:
            if key in ann.model_fields:
                return f"did you mean '{name}.{key}'?"
    return ""


def _problem(err: Mapping[str, Any], name_defaulted: bool) -> tuple[str, str]:
    """(dotted key, message line) for one pydantic error."""
    loc = tuple(err["loc"])
    ctx = err.get("ctx") or {}
    key = ctx.get("key") or ".".join(str(p) for p in loc)
    model, info = _walk_models(loc)
    expected = ctx.get("expected") or (info.description if info is not None else None) or ""
    detail = ctx.get("detail", "")
    head = f"config key '{key}'"

    if err["type"] in ("extra_forbidden", "invalid_key"):
        allowed = list(model.model_fields) if model is not None else []
        word = str(loc[-1])
        section = str(loc[-2]) if len(loc) > 1 else ""
        hint = _did_you_mean(word, allowed, f"{section}." if section else "")
        hint = hint or _other_section_hint(word, section)
        hint = f"; {hint}" if hint else ""
        return key, f"{head}: unknown key{hint} (allowed: {', '.join(allowed)})"
    if err["type"] in ("missing", "rbstab_missing"):
        text = f"{head}: missing; expected {expected}"
        return key, text + (f" ({detail})" if detail else "")
    found = ctx.get("found") or _short(err.get("input"))
    if not expected:  # a pydantic error this module does not anticipate
        expected, detail = "a valid value", err.get("msg", "")
    if err["type"] == "model_type" and not detail:
        detail = f"{_kind(err.get('input'))}, not a mapping"
    if key == "name" and name_defaulted:
        detail = "; ".join(filter(None, [detail, "the default name; set 'name:' in the config"]))
    text = f"{head}: found {found}; expected {expected}"
    return key, text + (f" ({detail})" if detail else "")


# -- YAML ----------------------------------------------------------------------------------


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


class _Dumper(yaml.SafeDumper):
    """SafeDumper writing lists (vectors, matrices) on one line: ``[0.15, 0.1, -0.42]``."""

    def represent_list(self, data: list) -> yaml.SequenceNode:
        return self.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


_Dumper.add_representer(list, _Dumper.represent_list)


def _parse_yaml(text: str) -> Any:
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


# -- dotted paths and overrides --------------------------------------------------------------


class _PathError(Exception):
    pass


def _plain_tree(value: Any) -> Any:
    """Deep copy with mappings as dicts, sequences as lists, numpy values as Python ones."""
    if isinstance(value, Mapping):
        return {k: _plain_tree(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain_tree(v) for v in value]
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


def _index(node: list, part: str, where: str) -> int:
    if not part.isdigit():
        raise _PathError(f"'{where}' is a list; index it with 0..{len(node) - 1}, not {part!r}")
    i = int(part)
    if i >= len(node):
        raise _PathError(f"index {i} out of range for '{where}' (a list of {len(node)})")
    return i


def _schema_default(parts: Sequence[str]) -> list | None:
    """A copy of the schema default of a list-valued key (``initial_state.theta``), else None."""
    _, info = _walk_models(parts)
    default = info.default if info is not None else None
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
                if default is None and parts[depth + 1].isdigit():
                    raise _PathError(
                        f"'{where}' is not set, so it has no index {parts[depth + 1]}; "
                        "set the whole list"
                    )
                node[part] = {} if default is None else default
            node = node[part]
        elif isinstance(node, list):
            node = node[_index(node, part, ".".join(parts[:depth]))]
        else:
            raise _PathError(f"'{'.'.join(parts[:depth])}' is {_kind(node)}; it has no '{part}'")
    if not isinstance(node, (dict, list)):
        raise _PathError(f"'{'.'.join(parts[:-1])}' is {_kind(node)}; it has no '{parts[-1]}'")
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
    result = _plain_tree(data)
    problems = []
    for override in overrides:
        key, sep, text = override.partition("=")
        if not sep:
            problems.append(f"override {override!r}: no '='; expected key.path=value")
            continue
        try:
            _set(result, key.strip(), _parse_yaml(text))
        except _PathError as exc:
            problems.append(f"override {override!r}: {exc}")
        except ConfigError as exc:  # the value is not valid YAML
            prefix = f"override {override!r}: the value is not valid YAML"
            problems += [f"{prefix}: {line}" for line in exc.errors]
    if problems:
        raise ConfigError(problems)
    return result


# -- the frozen result -------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RunConfig:
    """A validated run: everything the integrator needs, read-only.

    Attributes
    ----------
    name : str
        Run name, ``[A-Za-z0-9_.-]+`` (used as a file name).
    variant : str
        Key of :data:`rbstab.variants.VARIANTS`.
    body : RigidBody
        Mass [kg], inertia [kg m^2] (3x3), attachment point R [m], gravity g [m/s^2].
    gains : Gains
        The gains the variant uses (its ``required_gains``, and ``boundary_layer`` for
        sliding), each 3x3; gains configured but unused are None here (see ``resolved``).
    initial_state : dict of str to ndarray, shape (3,)
        Keyed by the state blocks of :mod:`rbstab.layout` (``theta``, ``omega``,
        ``position``, ``velocity``, ``controller_state``), all five always present.
    simulation : SimulationSettings
    resolved : dict
        The whole configuration as plain Python with every default filled in and gains as
        written; ``config_from_mapping(resolved)`` rebuilds an identical RunConfig.
        ``max_step`` is None when infinite.
    warnings : tuple of str
        Physical-plausibility warnings (also emitted as :class:`PhysicalPlausibilityWarning`).
    """

    name: str
    variant: str
    body: RigidBody
    gains: Gains
    initial_state: dict[str, np.ndarray]
    simulation: SimulationSettings
    resolved: dict
    warnings: tuple[str, ...] = ()

    def to_yaml(self) -> str:
        """``resolved`` as YAML (keys in schema order, lists in flow style)."""
        return yaml.dump(self.resolved, Dumper=_Dumper, sort_keys=False)

    def make_variant(self) -> Variant:
        """The variant object, ``VARIANTS[variant](body, gains)``."""
        return VARIANTS[self.variant](self.body, self.gains)


def _array(value: Any) -> np.ndarray:
    """Read-only float array; a 3-list of numbers is a diagonal when ``value`` is a matrix."""
    out = np.array(value, dtype=float)
    out.setflags(write=False)
    return out


def _matrix(value: Any) -> np.ndarray:
    return _array(np.diag(value) if np.ndim(value) == 1 else value)


def _inertia_warnings(inertia: np.ndarray) -> list[str]:
    diagonal = np.diag(inertia)  # keep the user's j1, j2, j3 labels when J is diagonal
    is_diagonal = np.array_equal(inertia, np.diag(diagonal))
    moments = diagonal if is_diagonal else np.linalg.eigvalsh(inertia)
    j = [float(x) for x in moments]
    for i in range(3):
        others = [j[k] for k in range(3) if k != i]
        if j[i] > sum(others) * (1 + 1e-12):
            return [
                f"body.inertia: principal moments ({', '.join(f'{x:g}' for x in j)}) kg m^2 "
                f"violate the triangle inequality (j{i + 1} = {j[i]:g} > {others[0]:g} + "
                f"{others[1]:g}) that every real rigid body satisfies; the equations of "
                "motion still hold, but no physical body has this inertia"
            ]
    return []


def _build(
    data: Any,
    *,
    default_name: str | None,
    source: str | None,
    overrides: Sequence[str] = (),
) -> RunConfig:
    if not isinstance(data, Mapping):
        what = "the configuration is empty" if data is None else f"top level: found {_short(data)}"
        raise ConfigError([f"{what}; expected {_TOP}"], source)
    data = _plain_tree(data)
    name_defaulted = "name" not in data and default_name is not None
    if name_defaulted:
        data["name"] = default_name
    try:
        run = _Run.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors(include_url=False):
            key, text = _problem(err, name_defaulted)
            related = [o for o in overrides if _related(o.partition("=")[0].strip(), key)]
            lines.append(text + "".join(f" [from override {o!r}]" for o in related))
        raise ConfigError(lines, source) from None

    ctrl = run.controller
    used = VARIANTS[ctrl.variant].required_gains
    gains = Gains(
        **{g: _matrix(getattr(ctrl, g)) for g in GAIN_NAMES if g in used},
        k_s=float(ctrl.k_s) if "k_s" in used else None,
        boundary_layer=float(ctrl.boundary_layer) if "k_s" in used else 0.0,
    )
    body = RigidBody(
        mass=float(run.body.mass),
        inertia=_matrix(run.body.inertia),
        attachment_point=_array(run.body.attachment_point),
        gravity=_array(run.body.gravity),
    )
    sim = run.simulation
    simulation = SimulationSettings(
        t_end=float(sim.t_end),
        n_samples=sim.n_samples,
        method=sim.method,
        rtol=float(sim.rtol),
        atol=float(sim.atol),
        max_step=float(sim.max_step),
        gimbal_margin=float(sim.gimbal_margin),
    )
    dump = run.model_dump()
    dump["controller"] = {k: v for k, v in dump["controller"].items() if v is not None}
    if math.isinf(sim.max_step):
        dump["simulation"]["max_step"] = None
    found_warnings = tuple(_inertia_warnings(body.inertia))
    for message in found_warnings:
        warnings.warn(
            f"{source}: {message}" if source else message, PhysicalPlausibilityWarning, stacklevel=3
        )
    return RunConfig(
        name=run.name,
        variant=ctrl.variant,
        body=body,
        gains=gains,
        initial_state={
            block: _array(getattr(run.initial_state, key))
            for key, block in INITIAL_STATE_BLOCKS.items()
        },
        simulation=simulation,
        resolved=_plain_tree(dump),
        warnings=found_warnings,
    )


def _related(a: str, b: str) -> bool:
    """Whether one dotted key is the other or lies inside it."""
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def config_from_mapping(
    data: Mapping, *, default_name: str | None = None, source: str | None = None
) -> RunConfig:
    """Validate a configuration mapping (the parsed YAML) into a :class:`RunConfig`.

    Parameters
    ----------
    data : Mapping
        The configuration (see the module docstring for the schema). Not modified.
    default_name : str, optional
        Name used when ``data`` has no ``name``.
    source : str, optional
        Where ``data`` comes from, for messages.

    Raises
    ------
    ConfigError
        Listing every problem found.

    Warns
    -----
    PhysicalPlausibilityWarning
        For a configuration no real body has (inertia violating the triangle inequality).
    """
    return _build(data, default_name=default_name, source=source)


def load_config(path: str | Path, overrides: Sequence[str] = ()) -> RunConfig:
    """Read a YAML configuration file, apply ``key.path=value`` overrides, validate it.

    Parameters
    ----------
    path : str or Path
        The YAML file; its stem is the default ``name``.
    overrides : sequence of str
        Applied in order with :func:`apply_overrides` before validation.

    Raises
    ------
    ConfigError
        For a missing or unreadable file, a YAML syntax error, a top level that is not a
        mapping, a malformed override, or any invalid value (all listed at once; lines
        about an overridden key name the override).

    Warns
    -----
    PhysicalPlausibilityWarning
        See :func:`config_from_mapping`.
    """
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError([f"config file not found: {source}"]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([f"cannot read the config file: {exc}"], source) from None
    try:
        data = _parse_yaml(text)
        if isinstance(data, Mapping):
            data = apply_overrides(data, overrides)
    except ConfigError as exc:
        raise ConfigError(exc.errors, source) from None
    return _build(data, default_name=path.stem, source=source, overrides=overrides)
