"""The sweep spec schema: pydantic models with the checks and message format of the config schema.

:func:`validate_spec` turns a parsed spec mapping into a :class:`SweepSchema` or raises
:class:`SweepSpecError` listing every problem, one line each, in the words of
:func:`rbstab.config.schema.problem_line`: ``sweep key '<key>': found <value>; expected
<what is allowed> (<detail>)``, unknown keys with a did-you-mean. What needs files (the
``base`` configs) or the configurations themselves is checked afterwards by
:mod:`rbstab.sweep.spec` and :mod:`rbstab.sweep.plan`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic_core import PydanticCustomError

from ..config import ConfigError
from ..config.paths import parse_any_key
from ..config.paths import KeyPathError
from ..config.schema import Invalid, checked, run_name, bounded_number, optional, kind_of, problem_line, short_repr
from ..convergence import DEFAULT_LYAPUNOV_RATIO

__all__ = ["SweepSpecError", "SweepSchema", "DistributionSchema", "DISTRIBUTIONS", "DEFAULT_LYAPUNOV_RATIO",
           "validate_spec", "numeric_array"]

#: Names of the random distributions.
DISTRIBUTIONS = ("uniform", "normal", "log_uniform", "scale_uniform", "scale_log_uniform", "choice")


class SweepSpecError(ConfigError):
    """An invalid sweep spec, override or run combination.

    Same shape as :class:`rbstab.config.ConfigError`: ``errors`` (one line per problem,
    each naming the key, the value found and what is allowed) and ``source`` (the spec
    file, if known; ``str()`` then starts with ``in <source>:``).
    """


# -- value checks (raise Invalid, as the config schema's do) -----------------------------------


def numeric_array(value: Any) -> np.ndarray | None:
    """``value`` as a float array if it is a finite number or a (nested) list of them, else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)) and math.isfinite(value):
        return np.asarray(float(value))
    if not isinstance(value, (list, tuple)) or not value:
        return None
    stack = [value]
    while stack:  # every leaf a finite number (not a bool)
        item = stack.pop()
        if isinstance(item, (list, tuple)):
            stack.extend(item)
        elif isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
            return None
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):  # ragged
        return None
    return arr


def _dotted_key(key: Any) -> str:
    """A config key path of one body or of a chain (:func:`rbstab.config.loader.parse_any_key`;
    which kind the bases take is checked once they are read); its refusal is the line."""
    try:
        parse_any_key(key)
    except KeyPathError as exc:
        raise PydanticCustomError("rbstab_invalid", "invalid key", {"line": exc.problem}) from None
    return key


def _values(value: Any) -> list:
    expected = "a non-empty list of values (one run each)"
    if not isinstance(value, (list, tuple)):
        raise Invalid(f"{kind_of(value)}; write [{short_repr(value)}] for a single value", expected)
    if not value:
        raise Invalid("an empty list", expected)
    return list(value)


def _broadcast(a: np.ndarray, b: np.ndarray, names: str, expected: str) -> None:
    try:
        np.broadcast_shapes(a.shape, b.shape)
    except ValueError:
        raise Invalid(f"{names} have shapes {a.shape} and {b.shape}, which do not broadcast", expected) from None


def _bounds(*, positive: bool):
    expected = "[lo, hi] with lo <= hi, each a number or a list of numbers" + (", all > 0" if positive else "")

    def check(value: Any) -> list:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise Invalid("not a pair [lo, hi]", expected)
        lo, hi = (numeric_array(v) for v in value)
        if lo is None or hi is None:
            raise Invalid("lo and hi must be finite numbers or lists of them", expected)
        _broadcast(lo, hi, "lo and hi", expected)
        if np.any(lo > hi):
            raise Invalid("lo > hi", expected)
        if positive and np.any(lo <= 0):
            raise Invalid("lo <= 0", expected)
        return [lo.tolist(), hi.tolist()]

    return check


def _string(value: Any) -> str:
    if not isinstance(value, str):
        raise Invalid(f"{kind_of(value)}, not a string")
    return value


def _choices(value: Any) -> list:
    if not isinstance(value, (list, tuple)) or not value:
        raise Invalid(f"{kind_of(value)}, not a non-empty list", "a non-empty list of values")
    return list(value)


def _numbers(value: Any) -> Any:
    arr = numeric_array(value)
    if arr is None:
        raise Invalid(f"{kind_of(value)}, not finite numbers", "a number or a list of numbers")
    return arr.tolist()


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


def _invalid(key: str, found: Any, expected: str, detail: str = "") -> PydanticCustomError:
    ctx = {"key": key, "found": short_repr(found), "expected": expected}
    if detail:
        ctx["detail"] = detail
    return PydanticCustomError("rbstab_invalid", "invalid value", ctx)


# -- the models ---------------------------------------------------------------------------------


class NormalSchema(_Section):
    """``normal: {mean: m, std: s}``."""

    mean: Annotated[Any, checked(_numbers)] = Field(description="a number or a list of numbers")
    std: Annotated[Any, checked(_numbers)] = Field(description="a number >= 0 or a list of them")

    @model_validator(mode="after")
    def _shapes(self) -> "NormalSchema":
        mean, std = np.asarray(self.mean, dtype=float), np.asarray(self.std, dtype=float)
        expected = "normal: {mean: m, std: s}, m and s numbers or lists of numbers that broadcast, s >= 0"
        if np.any(std < 0):
            raise PydanticCustomError("rbstab_invalid", "invalid", {"detail": "std < 0", "expected": expected})
        try:
            np.broadcast_shapes(mean.shape, std.shape)
        except ValueError:
            raise PydanticCustomError(
                "rbstab_invalid", "invalid",
                {"detail": f"mean has shape {mean.shape} and std {std.shape}, which do not broadcast",
                 "expected": expected},
            ) from None
        return self


class DistributionSchema(_Section):
    """One random parameter: a mapping with exactly one of :data:`DISTRIBUTIONS`."""

    uniform: Annotated[Any, checked(optional(_bounds(positive=False)))] = Field(
        None, description="[lo, hi] with lo <= hi, each a number or a list of numbers")
    normal: NormalSchema | None = Field(
        None, description="{mean: m, std: s}, m and s numbers or lists of numbers, s >= 0")
    log_uniform: Annotated[Any, checked(optional(_bounds(positive=True)))] = Field(
        None, description="[lo, hi] with 0 < lo <= hi, each a number or a list of numbers")
    scale_uniform: Annotated[Any, checked(optional(_bounds(positive=False)))] = Field(
        None, description="[lo, hi] factors of the base value with lo <= hi, numbers or lists of numbers")
    scale_log_uniform: Annotated[Any, checked(optional(_bounds(positive=True)))] = Field(
        None, description="[lo, hi] factors of the base value, log-uniform, 0 < lo <= hi, numbers or lists of numbers")
    choice: Annotated[Any, checked(optional(_choices))] = Field(None, description="a non-empty list of values")

    @model_validator(mode="before")
    @classmethod
    def _one_distribution(cls, value: Any) -> Any:
        if not isinstance(value, Mapping) or len(value) != 1:
            raise PydanticCustomError(
                "rbstab_invalid", "invalid",
                {"expected": f"a mapping with exactly one distribution ({', '.join(DISTRIBUTIONS)}), "
                             "e.g. {uniform: [20.5, 61.5]}"},
            )
        return value

    @property
    def kind(self) -> str:
        """The distribution's name."""
        return next(name for name in DISTRIBUTIONS if getattr(self, name) is not None)


DottedKey = Annotated[str, checked(_dotted_key)]


class RandomSchema(_Section):
    """``random``: ``n`` samples of ``params`` drawn from ``numpy.random.default_rng(seed)``."""

    n: Annotated[Any, checked(bounded_number(ge=0, integer=True))] = Field(
        0, description="an integer >= 0 (0: no random samples)")
    seed: Annotated[Any, checked(bounded_number(ge=0, integer=True))] = Field(0, description="an integer >= 0")
    params: dict[DottedKey, DistributionSchema] = Field(
        default_factory=dict, description="a mapping of dotted config key -> distribution")

    @model_validator(mode="after")
    def _params_for_samples(self) -> "RandomSchema":
        if self.n and not self.params:
            raise _invalid("random.params", {}, "at least one parameter",
                           f"random.n = {self.n} draws samples of nothing")
        return self


class ConvergenceSchema(_Section):
    """``convergence``: when a run counts as converged."""

    lyapunov_ratio: Annotated[Any, checked(bounded_number(gt=0, lt=1))] = Field(
        DEFAULT_LYAPUNOV_RATIO, description="a number in (0, 1)")


_BASE_EXPECTED = "a config file path (relative to the spec file), an inline config mapping, or a list of those"


def _base(value: Any) -> list:
    entries = value if isinstance(value, list) else [value]
    if not entries:
        raise Invalid("an empty list", _BASE_EXPECTED)
    for entry in entries:
        if not (isinstance(entry, Mapping) or (isinstance(entry, str) and entry.strip())):
            raise Invalid(f"an entry is {kind_of(entry)}", _BASE_EXPECTED)
    return entries


def _overlapping(a: str, b: str) -> bool:
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


class SweepSchema(_Section):
    """A whole sweep spec (see :mod:`rbstab.sweep.spec` for the meaning of each key)."""

    name: Annotated[Any, checked(run_name)] = Field(
        description="letters, digits, '_', '.' and '-' (it becomes a folder name)")
    description: Annotated[Any, checked(optional(_string))] = Field("", description="a string")
    base: Annotated[Any, checked(_base)] = Field(description=_BASE_EXPECTED)
    grid: dict[DottedKey, Annotated[Any, checked(_values)]] = Field(
        default_factory=dict, description="a mapping of dotted config key -> list of values")
    zip: dict[DottedKey, Annotated[Any, checked(_values)]] = Field(
        default_factory=dict, description="a mapping of dotted config key -> list of values, all of one length")
    random: RandomSchema = Field(default_factory=RandomSchema, description="a mapping with keys n, seed, params")
    table: Any = Field(None, description="a CSV or Parquet file (relative to the spec file) whose columns are "
                       "dotted config keys, one run a row")
    convergence: ConvergenceSchema = Field(
        default_factory=ConvergenceSchema, description="a mapping with the key lyapunov_ratio")
    generated: Any = Field(None, description="provenance written by rbstab (ignored)")

    @field_validator("grid", "zip", "random", "convergence", mode="before")
    @classmethod
    def _empty_section(cls, value: Any) -> Any:
        return {} if value is None else value  # "grid:" with every line commented out

    @model_validator(mode="after")
    def _consistent(self) -> "SweepSchema":
        lengths = {key: len(values) for key, values in self.zip.items()}
        if len(set(lengths.values())) > 1:
            listing = ", ".join(f"{k}: {n}" for k, n in lengths.items())
            raise _invalid("zip", self.zip, "lists of equal length", f"the lists have different lengths ({listing})")
        sections = [("grid", k) for k in self.grid] + [("zip", k) for k in self.zip]
        if self.random.n:
            sections += [("random.params", k) for k in self.random.params]
        for (s1, k1), (s2, k2) in itertools.combinations(sections, 2):
            if _overlapping(k1, k2):
                raise _invalid(f"{s2}.{k2}", k2, "a key varied in one place only",
                               f"overlaps '{s1}.{k1}': the result would depend on the order they are set in")
        return self

    def varied(self) -> list[tuple[str, str]]:
        """(section, dotted key) of every varied key: grid, zip, then random (when n > 0)."""
        out = [("grid", k) for k in self.grid] + [("zip", k) for k in self.zip]
        return out + ([("random.params", k) for k in self.random.params] if self.random.n else [])


def validate_spec(data: Any, source: str | None = None) -> SweepSchema:
    """Validate a parsed sweep spec mapping.

    Raises
    ------
    SweepSpecError
        One line per problem (``sweep key '<key>': found ...; expected ...``).
    """
    if not isinstance(data, Mapping):
        allowed = ", ".join(k for k in SweepSchema.model_fields if k != "generated")
        raise SweepSpecError([f"top level: found {kind_of(data)}; expected a mapping with keys {allowed}"], source)
    try:
        return SweepSchema.model_validate(data)
    except ValidationError as exc:
        lines = [problem_line(err, False, root=SweepSchema, what="sweep key")[1]
                 for err in exc.errors(include_url=False)]
        raise SweepSpecError(lines, source) from None
