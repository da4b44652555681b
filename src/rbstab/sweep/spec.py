"""Sweep specifications: a YAML file -> a validated :class:`SweepSpec` -> a list of runs.

A sweep spec names a base configuration and the keys to vary::

    name: gains_case3
    base: ../paper/case3_embedded.yaml   # path relative to this file, an inline config,
                                         # or a list of those (each list entry is one more
                                         # grid level, labelled by its config name)
    grid:                                # Cartesian product over dotted keys
      controller.k_c: [[4100, 4100, 3280], [12300, 12300, 9840]]
      controller.variant: [visco_elastic, embedded]
    zip:                                 # keys varied together (lists of equal length)
      initial_state.omega.0: [10, 16, 22]
      initial_state.theta.2: [0.0, 0.1, 0.2]
    random:                              # n samples, reproducible from seed
      n: 10
      seed: 0
      params:
        body.mass: {scale_uniform: [0.5, 1.5]}
        initial_state.omega: {normal: {mean: [16, 32, -16], std: 5}}
    convergence:
      lyapunov_ratio: 1.0e-3             # converged: success and v(t_end) <= ratio * v(0)

Keys are the dotted paths of :func:`rbstab.config.set_dotted` (``initial_state.omega.1``
indexes into the list). The run list is the product base x grid x zip x random; its order
(and so each run's index) is: random sample (slowest), base, grid keys in the order
written (the last one fastest), zip entry (fastest). Random samples come first so that
raising ``random.n`` appends runs and keeps the ids of the earlier ones.

Random distributions (all drawn from ``numpy.random.default_rng(seed)``, sample by
sample and, within a sample, parameter by parameter in the order written, so the first
k samples do not depend on ``n`` nor on how the runs are executed):

- ``uniform: [lo, hi]`` -- lo, hi numbers or lists (one draw per component);
- ``normal: {mean: m, std: s}`` -- m, s numbers or lists (broadcast together), s >= 0;
- ``log_uniform: [lo, hi]`` -- log-uniform on [lo, hi], 0 < lo <= hi;
- ``scale_uniform: [lo, hi]`` -- the base value times a factor drawn uniformly in
  [lo, hi]; number bounds scale the whole value by one factor (an inertia keeps its
  shape), list bounds give one factor per component;
- ``choice: [a, b, ...]`` -- one of the listed values, uniformly.

The shape of a drawn value is the broadcast shape of the distribution's numbers: give
lists to draw vectors.

Run ids are ``r<index>-<h>``: ``index`` the zero-padded position in the run list (4 digits,
more for larger sweeps) and ``h`` the first 8 hex digits of the SHA-256 of the run's
resolved configuration without its name (canonical JSON). The same spec gives the same ids
on every invocation and every machine; a changed base, grid value or sample changes ``h``.
Each run's config ``name`` is its run id.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import itertools
import json
import math
import numbers
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import ConfigError
from ..config.schema import kind_of as _kind

__all__ = [
    "SweepSpec",
    "SweepSpecError",
    "Base",
    "Distribution",
    "RandomSpec",
    "PlannedRun",
    "DISTRIBUTIONS",
    "DEFAULT_LYAPUNOV_RATIO",
    "load_spec",
    "spec_from_mapping",
    "expand",
    "run_id",
    "resolved_hash",
    "warning_digest",
]

#: Default of ``convergence.lyapunov_ratio``: a successful run whose v fell to at most this
#: fraction of its initial value counts as converged.
DEFAULT_LYAPUNOV_RATIO = 1e-3

#: Names of the random distributions.
DISTRIBUTIONS = ("uniform", "normal", "log_uniform", "scale_uniform", "choice")

_TOP_KEYS = ("name", "description", "base", "grid", "zip", "random", "convergence", "generated")
_NAME_PATTERN = re.compile(r"[A-Za-z0-9_.-]+")
_MAX_LISTED = 10  # invalid runs listed in an error, the rest counted


class SweepSpecError(ConfigError):
    """An invalid sweep spec, override or run combination.

    Same shape as :class:`rbstab.config.ConfigError`: ``errors`` (one line per problem,
    each naming the key, the value found and what is allowed) and ``source`` (the spec
    file, if known; ``str()`` then starts with ``in <source>:``).
    """


# -- small helpers ---------------------------------------------------------------------------


def _short(value: Any, limit: int = 80) -> str:
    text = json.dumps(value, default=str) if not isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def _numeric_array(value: Any) -> np.ndarray | None:
    """``value`` as a float array if it is a number or a (nested) list of numbers."""
    if _is_number(value):
        return np.asarray(float(value))
    if isinstance(value, (list, tuple)) and value:
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            return None
        if arr.dtype == object or not np.all(np.isfinite(arr)):
            return None
        flat = list(_flatten(value))
        if all(_is_number(x) for x in flat):
            return arr
    return None


def _flatten(value: Any):
    if isinstance(value, (list, tuple)):
        for v in value:
            yield from _flatten(v)
    else:
        yield value


def _plain(value: Any) -> Any:
    """numpy values -> Python floats/lists (YAML and JSON friendly)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _overlapping(a: str, b: str) -> bool:
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def _parse_yaml(text: str) -> Any:
    # The project's loader: 1e-8 is a float, a duplicate key is an error.
    from ..config import parse_yaml as parse

    return parse(text)


# -- distributions ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Distribution:
    """One random parameter of a sweep.

    Attributes
    ----------
    key : str
        Dotted config key it sets.
    kind : str
        One of :data:`DISTRIBUTIONS`.
    args : tuple
        ``(lo, hi)`` float arrays for uniform, log_uniform and scale_uniform,
        ``(mean, std)`` for normal, ``(values,)`` for choice.
    """

    key: str
    kind: str
    args: tuple

    def draw(self, rng: np.random.Generator) -> Any:
        """One sample: a float, a list of floats, or (choice) one of the listed values.

        For ``scale_uniform`` this is the factor, not the scaled value.
        """
        if self.kind in ("uniform", "scale_uniform"):
            lo, hi = self.args
            return _plain(rng.uniform(lo, hi, size=np.broadcast_shapes(lo.shape, hi.shape)))
        if self.kind == "log_uniform":
            lo, hi = self.args
            shape = np.broadcast_shapes(lo.shape, hi.shape)
            return _plain(np.exp(rng.uniform(np.log(lo), np.log(hi), size=shape)))
        if self.kind == "normal":
            mean, std = self.args
            return _plain(rng.normal(mean, std, size=np.broadcast_shapes(mean.shape, std.shape)))
        (values,) = self.args
        return copy.deepcopy(values[int(rng.integers(len(values)))])

    def to_mapping(self) -> dict:
        """The YAML form, e.g. ``{"uniform": [lo, hi]}``."""
        if self.kind == "normal":
            return {"normal": {"mean": _plain(self.args[0]), "std": _plain(self.args[1])}}
        if self.kind == "choice":
            return {"choice": copy.deepcopy(list(self.args[0]))}
        return {self.kind: [_plain(self.args[0]), _plain(self.args[1])]}


def _bounds(where: str, kind: str, value: Any, errors: list[str], *, positive: bool = False):
    expected = (
        "[lo, hi] with lo <= hi, each a number or a list of numbers"
        + (", all > 0" if positive else "")
    )
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        errors.append(f"sweep key '{where}': found {kind}: {_short(value)}; expected {kind}: {expected}")
        return None
    lo, hi = (_numeric_array(v) for v in value)
    if lo is None or hi is None:
        errors.append(f"sweep key '{where}': found {kind}: {_short(value)}; expected {kind}: {expected}")
        return None
    try:
        np.broadcast_shapes(lo.shape, hi.shape)
    except ValueError:
        errors.append(
            f"sweep key '{where}': found {kind}: {_short(value)}; lo has shape {lo.shape} and hi "
            f"{hi.shape}, which do not broadcast; expected {expected}"
        )
        return None
    if np.any(lo > hi):
        errors.append(f"sweep key '{where}': found {kind}: {_short(value)}; lo > hi; expected {expected}")
        return None
    if positive and np.any(lo <= 0):
        errors.append(f"sweep key '{where}': found {kind}: {_short(value)}; lo <= 0; expected {expected}")
        return None
    return lo, hi


def _distribution(key: str, value: Any, errors: list[str]) -> Distribution | None:
    where = f"random.params.{key}"
    allowed = ", ".join(DISTRIBUTIONS)
    if not isinstance(value, Mapping) or len(value) != 1:
        errors.append(
            f"sweep key '{where}': found {_short(value)}; expected a mapping with exactly one "
            f"distribution ({allowed}), e.g. {{uniform: [20.5, 61.5]}}"
        )
        return None
    ((kind, args),) = value.items()
    if kind not in DISTRIBUTIONS:
        import difflib

        close = difflib.get_close_matches(str(kind), DISTRIBUTIONS, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        errors.append(f"sweep key '{where}': unknown distribution {kind!r}{hint} (allowed: {allowed})")
        return None
    if kind in ("uniform", "scale_uniform", "log_uniform"):
        b = _bounds(where, kind, args, errors, positive=kind == "log_uniform")
        return None if b is None else Distribution(key, kind, b)
    if kind == "normal":
        expected = "normal: {mean: m, std: s}, m and s numbers or lists of numbers, s >= 0"
        if not isinstance(args, Mapping) or set(args) != {"mean", "std"}:
            errors.append(f"sweep key '{where}': found normal: {_short(args)}; expected {expected}")
            return None
        mean, std = _numeric_array(args["mean"]), _numeric_array(args["std"])
        if mean is None or std is None or np.any(std < 0):
            errors.append(f"sweep key '{where}': found normal: {_short(args)}; expected {expected}")
            return None
        try:
            np.broadcast_shapes(mean.shape, std.shape)
        except ValueError:
            errors.append(
                f"sweep key '{where}': found normal: {_short(args)}; mean has shape {mean.shape} "
                f"and std {std.shape}, which do not broadcast; expected {expected}"
            )
            return None
        return Distribution(key, kind, (mean, std))
    if not isinstance(args, (list, tuple)) or not args:
        errors.append(f"sweep key '{where}': found choice: {_short(args)}; expected choice: a non-empty list of values")
        return None
    return Distribution(key, kind, (tuple(copy.deepcopy(list(args))),))


# -- the spec ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class RandomSpec:
    """``random`` section: ``n`` samples of ``params`` from ``default_rng(seed)``."""

    n: int = 0
    seed: int = 0
    params: tuple[Distribution, ...] = ()

    def samples(self) -> list[dict[str, Any]]:
        """The ``n`` samples, each ``{key: drawn value}`` (scale_uniform: the factor).

        Sample ``i`` is the same for every ``n > i``.
        """
        rng = np.random.default_rng(self.seed)
        return [{d.key: d.draw(rng) for d in self.params} for _ in range(self.n)]


@dataclass(frozen=True)
class Base:
    """One base configuration.

    Attributes
    ----------
    label : str
        Its config ``name`` or, if it has none, the file stem (``"base"`` for an inline
        config without a name); the ``base`` column of the index.
    data : dict
        The configuration mapping as written, with the ``--set`` overrides applied
        (not yet validated: the varied keys are set on top of it per run).
    source : str or None
        The file it was read from.
    """

    label: str
    data: dict
    source: str | None = None


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep spec (see the module docstring).

    Attributes
    ----------
    name : str
        Sweep name, ``[A-Za-z0-9_.-]+``; the output folder ``<output>/<name>/``.
    bases : tuple of Base
    grid : dict of str to list
        Dotted key -> its values, in the order written.
    zip : dict of str to list
        Dotted key -> its values; all lists have the same length.
    random : RandomSpec
    lyapunov_ratio : float
        Convergence threshold (see :data:`DEFAULT_LYAPUNOV_RATIO`).
    description : str
    source : str or None
        The spec file.
    overrides : tuple of str
        The ``--set`` overrides applied to the bases (recorded in ``sweep.yaml``).
    """

    name: str
    bases: tuple[Base, ...]
    grid: dict = field(default_factory=dict)
    zip: dict = field(default_factory=dict)
    random: RandomSpec = field(default_factory=RandomSpec)
    lyapunov_ratio: float = DEFAULT_LYAPUNOV_RATIO
    description: str = ""
    source: str | None = None
    overrides: tuple[str, ...] = ()

    @property
    def varied_keys(self) -> list[str]:
        """Every dotted key the sweep varies: grid, then zip, then random keys."""
        keys = list(self.grid) + list(self.zip)
        if self.random.n:
            keys += [d.key for d in self.random.params]
        return keys

    @property
    def n_runs(self) -> int:
        """Number of runs: bases x grid points x zip entries x random samples."""
        n = len(self.bases) * math.prod(len(v) for v in self.grid.values())
        if self.zip:
            n *= len(next(iter(self.zip.values())))
        return n * max(self.random.n, 1)

    def to_mapping(self) -> dict:
        """The resolved spec: re-loadable by :func:`spec_from_mapping`, bases inline.

        The ``--set`` overrides are already applied to the inline bases.
        """
        bases = []
        for b in self.bases:
            data = copy.deepcopy(b.data)
            data["name"] = b.label
            bases.append(data)
        out: dict[str, Any] = {"name": self.name}
        if self.description:
            out["description"] = self.description
        out["base"] = bases[0] if len(bases) == 1 else bases
        out["grid"] = copy.deepcopy(self.grid)
        out["zip"] = copy.deepcopy(self.zip)
        out["random"] = {
            "n": self.random.n,
            "seed": self.random.seed,
            "params": {d.key: d.to_mapping() for d in self.random.params},
        }
        out["convergence"] = {"lyapunov_ratio": self.lyapunov_ratio}
        return out


def _check_name(value: Any, errors: list[str]) -> str | None:
    if not isinstance(value, str) or not _NAME_PATTERN.fullmatch(value) or set(value) == {"."}:
        errors.append(
            f"sweep key 'name': found {_short(value)}; expected letters, digits, '_', '.' and '-' "
            "(it becomes a folder name)"
        )
        return None
    return value


def _check_key(where: str, key: Any, errors: list[str]) -> bool:
    parts = key.split(".") if isinstance(key, str) else []
    if not parts or any(not p.strip() or p != p.strip() for p in parts):
        errors.append(
            f"sweep key '{where}': found the key {_short(key)}; expected a dotted config key such as "
            "'controller.k_c' or 'initial_state.omega.0'"
        )
        return False
    return True


def _read_base(entry: Any, where: str, spec_dir: Path, errors: list[str]) -> Base | None:
    from ..config import ConfigError

    if isinstance(entry, Mapping):
        data = copy.deepcopy(dict(entry))
        label = data.get("name") if isinstance(data.get("name"), str) else "base"
        return Base(label, data, None)
    if not isinstance(entry, str) or not entry.strip():
        errors.append(
            f"sweep key '{where}': found {_short(entry)}; expected a config file path (relative to "
            "the spec file), an inline config mapping, or a list of those"
        )
        return None
    path = Path(entry).expanduser()
    if not path.is_absolute():
        path = spec_dir / path
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        errors.append(f"sweep key '{where}': found {entry!r}; config file not found: {path}")
        return None
    except (OSError, UnicodeDecodeError) as exc:
        errors.append(f"sweep key '{where}': cannot read {path}: {exc}")
        return None
    try:
        data = _parse_yaml(text)
    except ConfigError as exc:
        errors += [f"sweep key '{where}': {path}: {line}" for line in exc.errors]
        return None
    if not isinstance(data, Mapping):
        errors.append(f"sweep key '{where}': {path}: found {_kind(data)}; expected a config mapping")
        return None
    label = data.get("name") if isinstance(data.get("name"), str) else path.stem
    return Base(label, dict(data), str(path))


def _values_list(where: str, value: Any, errors: list[str], what: str) -> list | None:
    if not isinstance(value, (list, tuple)):
        errors.append(
            f"sweep key '{where}': found {_short(value)} ({_kind(value)}); expected a list of values "
            f"({what}); write [{_short(value)}] for a single value"
        )
        return None
    if not value:
        errors.append(f"sweep key '{where}': found []; expected a non-empty list of values ({what})")
        return None
    return copy.deepcopy(list(value))


def _set_spec_override(data: dict, override: str) -> None:
    """Apply ``sweep.<path>=value``; ``grid.<key>``, ``zip.<key>`` and ``random.params.<key>``
    take the rest of the path as one (dotted) key."""
    from ..config import ConfigError, set_dotted

    key, sep, text = override.partition("=")
    if not sep:
        raise ConfigError([f"override {override!r}: no '='; expected sweep.key.path=value"])
    path = key.strip()[len("sweep."):]
    try:
        value = _parse_yaml(text)
    except ConfigError as exc:
        raise ConfigError([f"override {override!r}: the value is not valid YAML: {e}" for e in exc.errors]) from None
    for section in ("grid.", "zip.", "random.params."):
        if path.startswith(section) and len(path) > len(section):
            node = data
            for part in section.rstrip(".").split("."):
                if not isinstance(node.get(part), dict):
                    node[part] = {}
                node = node[part]
            node[path[len(section):]] = value
            return
    try:
        set_dotted(data, path, value)
    except ConfigError as exc:
        raise ConfigError([f"override {override!r}: {e}" for e in exc.errors]) from None


def spec_from_mapping(
    data: Any,
    *,
    source: str | None = None,
    default_name: str | None = None,
    overrides: Sequence[str] = (),
) -> SweepSpec:
    """Validate a sweep spec mapping (the parsed YAML) into a :class:`SweepSpec`.

    Parameters
    ----------
    data : Mapping
        The spec (module docstring). Not modified.
    source : str, optional
        The spec file: relative base paths are read from its folder (else from the current
        folder), and messages name it.
    default_name : str, optional
        Sweep name when ``data`` has none (:func:`load_spec` passes the file stem).
    overrides : sequence of str
        ``key.path=value``: applied to every base configuration (as ``rbstab run --set``);
        those starting with ``sweep.`` change the spec itself (``sweep.random.n=20``,
        ``sweep.grid.body.mass=[30, 41]``).

    Raises
    ------
    SweepSpecError
        Listing every problem found (nothing is run or written for an invalid spec).
    """
    from ..config import ConfigError, apply_overrides

    errors: list[str] = []
    if not isinstance(data, Mapping):
        raise SweepSpecError(
            [f"top level: found {_kind(data)}; expected a mapping with keys {', '.join(_TOP_KEYS[:-1])}"], source
        )
    data = copy.deepcopy(dict(data))
    spec_overrides = [o for o in overrides if o.strip().startswith("sweep.")]
    base_overrides = [o for o in overrides if not o.strip().startswith("sweep.")]
    for o in spec_overrides:
        try:
            _set_spec_override(data, o)
        except ConfigError as exc:
            errors += exc.errors
    if errors:
        raise SweepSpecError(errors, source)

    for key in data:
        if key not in _TOP_KEYS:
            import difflib

            close = difflib.get_close_matches(str(key), _TOP_KEYS, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            errors.append(
                f"sweep key {str(key)!r}: unknown key{hint} (allowed: {', '.join(_TOP_KEYS[:-1])})"
            )

    name = data.get("name", default_name)
    if name is None:
        errors.append("sweep key 'name': missing; expected a name of letters, digits, '_', '.' and '-'")
    else:
        name = _check_name(name, errors)

    description = data.get("description", "") or ""
    if not isinstance(description, str):
        errors.append(f"sweep key 'description': found {_kind(description)}; expected a string")

    spec_dir = Path(source).resolve().parent if source else Path.cwd()
    bases: list[Base] = []
    raw_base = data.get("base")
    if raw_base is None:
        errors.append(
            "sweep key 'base': missing; expected a config file path (relative to the spec file), "
            "an inline config mapping, or a list of those"
        )
    else:
        entries = raw_base if isinstance(raw_base, list) else [raw_base]
        if not entries:
            errors.append("sweep key 'base': found []; expected at least one base configuration")
        for i, entry in enumerate(entries):
            where = f"base.{i}" if isinstance(raw_base, list) else "base"
            b = _read_base(entry, where, spec_dir, errors)
            if b is None:
                continue
            try:
                b = Base(b.label, apply_overrides(b.data, base_overrides), b.source)
            except ConfigError as exc:
                errors += exc.errors
                continue
            bases.append(b)
        labels = [b.label for b in bases]
        dups = sorted({x for x in labels if labels.count(x) > 1})
        if dups:
            errors.append(
                f"sweep key 'base': several bases have the label {dups} (their config name or file "
                "stem); give each a distinct 'name'"
            )

    grid: dict[str, list] = {}
    raw_grid = data.get("grid") or {}
    if not isinstance(raw_grid, Mapping):
        errors.append(f"sweep key 'grid': found {_kind(raw_grid)}; expected a mapping of dotted key -> list of values")
        raw_grid = {}
    for key, values in raw_grid.items():
        if _check_key(f"grid.{key}", key, errors):
            v = _values_list(f"grid.{key}", values, errors, "one per grid level")
            if v is not None:
                grid[key] = v

    zipped: dict[str, list] = {}
    raw_zip = data.get("zip") or {}
    if not isinstance(raw_zip, Mapping):
        errors.append(f"sweep key 'zip': found {_kind(raw_zip)}; expected a mapping of dotted key -> list of values")
        raw_zip = {}
    for key, values in raw_zip.items():
        if _check_key(f"zip.{key}", key, errors):
            v = _values_list(f"zip.{key}", values, errors, "the i-th entries of all zip keys form one run")
            if v is not None:
                zipped[key] = v
    lengths = {k: len(v) for k, v in zipped.items()}
    if len(set(lengths.values())) > 1:
        listing = ", ".join(f"{k}: {n}" for k, n in lengths.items())
        errors.append(f"sweep key 'zip': the lists have different lengths ({listing}); expected equal lengths")

    random = RandomSpec()
    raw_random = data.get("random") or {}
    if not isinstance(raw_random, Mapping):
        errors.append(f"sweep key 'random': found {_kind(raw_random)}; expected a mapping with keys n, seed, params")
        raw_random = {}
    for key in raw_random:
        if key not in ("n", "seed", "params"):
            errors.append(f"sweep key 'random.{key}': unknown key (allowed: n, seed, params)")
    n = raw_random.get("n", 0)
    seed = raw_random.get("seed", 0)
    if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 0:
        errors.append(f"sweep key 'random.n': found {_short(n)}; expected an integer >= 0 (0: no random samples)")
        n = 0
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        errors.append(f"sweep key 'random.seed': found {_short(seed)}; expected an integer >= 0")
        seed = 0
    raw_params = raw_random.get("params") or {}
    params: list[Distribution] = []
    if not isinstance(raw_params, Mapping):
        errors.append(
            f"sweep key 'random.params': found {_kind(raw_params)}; expected a mapping of dotted key -> distribution"
        )
        raw_params = {}
    for key, value in raw_params.items():
        if _check_key(f"random.params.{key}", key, errors):
            d = _distribution(key, value, errors)
            if d is not None:
                params.append(d)
    if n and not raw_params:
        errors.append(f"sweep key 'random.params': missing; random.n = {n} needs at least one parameter")
    random = RandomSpec(int(n), int(seed), tuple(params))

    ratio = DEFAULT_LYAPUNOV_RATIO
    raw_conv = data.get("convergence") or {}
    if not isinstance(raw_conv, Mapping) or set(raw_conv) - {"lyapunov_ratio"}:
        errors.append(
            f"sweep key 'convergence': found {_short(raw_conv)}; expected a mapping with the key lyapunov_ratio"
        )
    else:
        ratio = raw_conv.get("lyapunov_ratio", DEFAULT_LYAPUNOV_RATIO)
        if not _is_number(ratio) or not 0 < ratio < 1:
            errors.append(
                f"sweep key 'convergence.lyapunov_ratio': found {_short(ratio)}; expected a number in (0, 1)"
            )
            ratio = DEFAULT_LYAPUNOV_RATIO

    # one key, one section: overlapping keys would depend on the order they are applied in
    sections = [("grid", k) for k in grid] + [("zip", k) for k in zipped]
    if random.n:
        sections += [("random.params", d.key) for d in random.params]
    for (s1, k1), (s2, k2) in itertools.combinations(sections, 2):
        if _overlapping(k1, k2):
            errors.append(
                f"sweep key '{s2}.{k2}': overlaps '{s1}.{k1}'; a key (or a part of it) may be varied "
                "in one place only"
            )
    for o in base_overrides:
        okey = o.partition("=")[0].strip()
        for s, k in sections:
            if okey == k or okey.startswith(k + "."):
                errors.append(
                    f"override {o!r}: the sweep varies '{k}' ({s}), which would replace the override; "
                    "drop the override or the sweep key"
                )
    if errors:
        raise SweepSpecError(errors, source)
    return SweepSpec(
        name=name,
        bases=tuple(bases),
        grid=grid,
        zip=zipped,
        random=random,
        lyapunov_ratio=float(ratio),
        description=description,
        source=source,
        overrides=tuple(overrides),
    )


def load_spec(path: str | Path, overrides: Sequence[str] = ()) -> SweepSpec:
    """Read and validate a sweep spec YAML file (see :func:`spec_from_mapping`).

    The file stem is the default sweep name.

    Raises
    ------
    SweepSpecError
        For a missing or unreadable file, a YAML syntax error, or any invalid entry.
    """
    from ..config import ConfigError

    from ..config.yaml_io import read_yaml_file

    path = Path(path)
    try:
        data = read_yaml_file(path, "sweep spec")
    except ConfigError as exc:
        raise SweepSpecError(exc.errors, exc.source) from None
    if is_run_config(data):  # a config varied from the command line (--grid, --random, ...)
        data = {"base": path.name}
    return spec_from_mapping(data, source=str(path), default_name=path.stem, overrides=overrides)


def is_run_config(data: Any) -> bool:
    """Whether a parsed YAML file is a run config rather than a sweep spec (no ``base``,
    and a ``body`` or ``controller`` section)."""
    return isinstance(data, Mapping) and "base" not in data and ("body" in data or "controller" in data)


# -- expansion --------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PlannedRun:
    """One run of a sweep, validated.

    Attributes
    ----------
    index : int
        Position in the run list (see the module docstring for the order).
    run_id : str
        ``r<index>-<hash8>`` (module docstring); also ``config.name`` and the file stem.
    base : str
        Label of its base configuration.
    params : dict of str to Any
        The varied values: dotted key -> value set in the config, in the order of
        :attr:`SweepSpec.varied_keys`; for a ``scale_uniform`` key also ``"<key>:scale"`` ->
        the factor.
    config : RunConfig
        The validated configuration, ``config.name == run_id``.
    """

    index: int
    run_id: str
    base: str
    params: dict
    config: Any

    @functools.cached_property
    def config_hash(self) -> str:
        """SHA-256 of the resolved config without its name (:func:`resolved_hash`): the
        ``config_hash`` of its stored result."""
        return resolved_hash(self.config.resolved)


def resolved_hash(resolved: Mapping) -> str:
    """SHA-256 hex digest of a resolved configuration without its ``name`` (canonical JSON,
    :func:`rbstab.io.hdf5.canonical_config`)."""
    from ..io.hdf5 import canonical_config, config_hash

    return config_hash(canonical_config(resolved))


def run_id(index: int, n_runs: int, digest: str) -> str:
    """``r<index>-<digest[:8]>``, the index zero-padded to max(4, digits of n_runs - 1)."""
    width = max(4, len(str(max(n_runs - 1, 0))))
    return f"r{index:0{width}d}-{digest[:8]}"


def _base_value(base: Base, key: str, resolved_base: dict | None) -> Any:
    from ..config import get_dotted

    try:
        return get_dotted(base.data, key)
    except KeyError:
        if resolved_base is None:
            raise
        return get_dotted(resolved_base, key)


def _resolved_base(base: Base) -> tuple[dict | None, list[str]]:
    from ..config import ConfigError, PhysicalPlausibilityWarning, config_from_mapping

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        try:
            return config_from_mapping(base.data, default_name=base.label).resolved, []
        except ConfigError as exc:
            return None, exc.errors


def _set_varied(data: dict, key: str, value: Any, base: Base, cache: dict) -> None:
    """``set_dotted``; a list index into a list the base leaves at its default first copies
    the default list in (e.g. ``initial_state.omega.1`` with no ``omega`` in the base)."""
    from ..config import ConfigError, get_dotted, set_dotted

    try:
        set_dotted(data, key, value)
        return
    except ConfigError:
        parts = key.split(".")
        if base.label not in cache:
            cache[base.label] = _resolved_base(base)
        resolved, _ = cache[base.label]
        if resolved is None or not any(p.isdigit() for p in parts):
            raise
        for depth in range(1, len(parts)):
            prefix = ".".join(parts[:depth])
            try:
                get_dotted(data, prefix)
            except KeyError:
                try:
                    set_dotted(data, prefix, copy.deepcopy(get_dotted(resolved, prefix)))
                except (KeyError, ConfigError):
                    raise ConfigError([f"cannot set {key!r}: '{prefix}' is not set"]) from None
                break
        set_dotted(data, key, value)


def _describe(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={_short(v, 40)}" for k, v in params.items())


def _scaled(base: Base, key: str, factor: Any, cache: dict) -> tuple[Any, str | None]:
    """(base value of ``key`` times ``factor``, None) or (None, problem)."""
    if base.label not in cache:
        cache[base.label] = _resolved_base(base)
    try:
        original = _base_value(base, key, cache[base.label][0])
    except KeyError:
        return None, (
            f"random.params.{key}: scale_uniform needs a base value, but '{key}' is not set in "
            f"base '{base.label}' and has no default"
        )
    arr = _numeric_array(original)
    f = np.asarray(factor, dtype=float)
    try:
        if arr is None:
            raise ValueError
        np.broadcast_shapes(arr.shape, f.shape)
    except ValueError:
        return None, (
            f"random.params.{key}: scale_uniform factors of shape {f.shape} cannot scale the base "
            f"value {_short(original)} of base '{base.label}'"
        )
    return _plain(arr * f), None


def _own_sections(data: Mapping, keys: Iterable[str]) -> dict:
    """A copy of ``data`` in which the top-level sections ``keys`` point into are private
    (deep copies), the others shared: setting those keys leaves ``data`` intact."""
    out = dict(data)
    for top in {key.split(".", 1)[0] for key in keys}:
        if top in out:
            out[top] = copy.deepcopy(out[top])
    return out


def _plan_run(
    spec: SweepSpec, base: Base, params: dict, factors: dict, index: int, cache: dict, validated: dict
) -> tuple["PlannedRun | None", list[str]]:
    """Set the varied values on a copy of ``base``, validate, name the run by its id.

    ``validated`` maps a configuration without ``name`` and ``initial_state`` to its
    validated config: a run that differs from an earlier one only there is validated by
    :meth:`RunConfig.with_initial_state` (same result, ~10x cheaper).
    """
    from ..config import ConfigError, PhysicalPlausibilityWarning, config_from_mapping, group_key

    data = _own_sections(base.data, [*params, *factors])
    problems: list[str] = []
    try:
        for key, value in params.items():
            _set_varied(data, key, value, base, cache)
        for key, factor in factors.items():
            value, problem = _scaled(base, key, factor, cache)
            if problem:
                problems.append(problem)
                continue
            params[key] = value
            params[f"{key}:scale"] = factor
            _set_varied(data, key, value, base, cache)
    except ConfigError as exc:
        problems += exc.errors
    if problems:
        return None, problems
    data["name"] = "sweep-run"  # replaced by the run id below
    source = f"base '{base.label}'"
    group = group_key(data)
    try:
        with warnings.catch_warnings():
            # kept in config.warnings; the CLI prints a digest instead of one per run
            warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
            known = validated.get(group)
            if known is None:
                first = validated[group] = config_from_mapping(data, source=source)
            else:
                first = known.with_initial_state(data.get("initial_state"), source=source)
    except ConfigError as exc:
        return None, exc.errors
    digest = resolved_hash(first.resolved)
    rid = run_id(index, spec.n_runs, digest)
    # only the name changes: no need to validate again
    config = dataclasses.replace(first, name=rid, resolved={**first.resolved, "name": rid})
    ordered = {k: params[k] for k in spec.varied_keys if k in params}
    ordered.update({k: v for k, v in params.items() if k not in ordered})
    run = PlannedRun(index, rid, base.label, ordered, config)
    run.__dict__["config_hash"] = digest  # the name is not part of it
    return run, []


def expand(spec: SweepSpec) -> list["PlannedRun"]:
    """Every run of ``spec``, each configuration validated.

    Returns
    -------
    list of PlannedRun
        In run-list order (module docstring); ``len == spec.n_runs``.

    Raises
    ------
    SweepSpecError
        If any run's configuration is invalid: one line per problem, naming the run (index,
        base and varied values) and the config key. Nothing is run for an invalid sweep.

    Notes
    -----
    Physical-plausibility warnings are not emitted here; each run's ``config.warnings``
    holds them (:func:`warning_digest` summarises them).
    """
    samples = spec.random.samples() if spec.random.n else [{}]
    scaled = {d.key for d in spec.random.params if d.kind == "scale_uniform"}
    grid_points = list(itertools.product(*spec.grid.values())) if spec.grid else [()]
    n_zip = len(next(iter(spec.zip.values()))) if spec.zip else 1
    width = max(4, len(str(max(spec.n_runs - 1, 0))))
    runs: list[PlannedRun] = []
    bad: list[str] = []
    n_bad = 0
    cache: dict = {}
    validated: dict = {}
    combinations = itertools.product(samples, spec.bases, grid_points, range(n_zip))
    for index, (sample, base, point, z) in enumerate(combinations):
        params: dict[str, Any] = dict(zip(spec.grid, copy.deepcopy(point)))
        params.update({k: copy.deepcopy(v[z]) for k, v in spec.zip.items()})
        params.update({k: v for k, v in sample.items() if k not in scaled})
        factors = {k: v for k, v in sample.items() if k in scaled}
        run, problems = _plan_run(spec, base, params, factors, index, cache, validated)
        if run is not None:
            runs.append(run)
            continue
        n_bad += 1
        if n_bad <= _MAX_LISTED:
            head = f"run r{index:0{width}d} (base {base.label}" + (f"; {_describe(params)})" if params else ")")
            bad += [f"{head}: {line}" for line in problems]
    if n_bad:
        header = f"{n_bad} of {spec.n_runs} runs have an invalid configuration; nothing was run"
        more = [f"... and {n_bad - _MAX_LISTED} more invalid runs"] if n_bad > _MAX_LISTED else []
        raise SweepSpecError([header, *bad, *more], spec.source)
    return runs


def warning_digest(runs: Sequence[PlannedRun]) -> list[str]:
    """Physical-plausibility warnings of ``runs``, one line per config key.

    E.g. ``"200 of 200 runs: body.inertia: principal moments (10, 8, 0.4) ..."`` (the
    message of the first run with that key).
    """
    first: dict[str, str] = {}
    count: dict[str, int] = {}
    for run in runs:
        for message in run.config.warnings:
            key = message.partition(":")[0]
            first.setdefault(key, message)
            count[key] = count.get(key, 0) + 1
    return [f"{count[k]} of {len(runs)} runs: {first[k]}" for k in first]
