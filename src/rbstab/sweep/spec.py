"""Sweep specifications: a YAML file -> a validated :class:`SweepSpec` (the runs: :mod:`.plan`).

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
      lyapunov_ratio: 1.0e-3             # converged: rbstab.convergence.RULE

Keys are the dotted paths of :func:`rbstab.config.paths.parse_key` (``initial_state.omega.1``
indexes into the list). A ``table:`` (a CSV or Parquet file, a DataFrame or a mapping of
columns named by dotted keys, ``initial_state.omega[1]``, ``body.inertia[0,2]``) gives runs
row by row. The run list is the product base x grid x zip x table x random; its order
(and so each run's index) is: random sample (slowest), base, grid keys in the order
written (the last one fastest), zip entry, table row (fastest). Random samples come first so that
raising ``random.n`` appends runs and keeps the ids of the earlier ones.

Random distributions (each key drawn from its own stream of ``seed``,
:func:`rbstab.sweep.table.random_stream`, all samples in one call, so the first k samples
do not depend on ``n``, on the other keys nor on how the runs are executed):

- ``uniform: [lo, hi]`` -- lo, hi numbers or lists (one draw per component);
- ``normal: {mean: m, std: s}`` -- m, s numbers or lists (broadcast together), s >= 0;
- ``log_uniform: [lo, hi]`` -- log-uniform on [lo, hi], 0 < lo <= hi;
- ``scale_uniform: [lo, hi]`` -- the base value times a factor drawn uniformly in
  [lo, hi]; number bounds scale the whole value by one factor (an inertia keeps its
  shape), list bounds give one factor per component;
- ``scale_log_uniform: [lo, hi]`` -- as ``scale_uniform``, the factor log-uniform on
  [lo, hi], 0 < lo <= hi (a gain over decades: each decade as likely);
- ``choice: [a, b, ...]`` -- one of the listed values, uniformly.

The shape of a drawn value is the broadcast shape of the distribution's numbers: give
lists to draw vectors.

Run ids are ``r<index>-<h>``: ``index`` the zero-padded position in the run list (4 digits,
more for larger sweeps) and ``h`` the first 8 hex digits of the run's ``config_hash``, a
digest of its base configuration and its values (:mod:`rbstab.sweep.table`). The same spec gives the same ids
on every invocation and every machine; a changed base, grid value or sample changes ``h``.
Each run's config ``name`` is its run id.

The spec is validated by the pydantic models of :mod:`rbstab.sweep.schema` (the checks and
message format of the config schema); this module reads the base configs, applies the
``--set`` overrides and builds the frozen :class:`SweepSpec`. :mod:`rbstab.sweep.table`
plans it as a validated table of runs.
"""

from __future__ import annotations

import copy
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config import ConfigError, apply_overrides, parse_yaml as parse
from ..config.paths import KeyPathError, parse_any_key, parse_key, schema_of
from ..config.schema import ChainSchema, SimulationSettings
from ..config.schema import kind_of as _kind
from ..config.yaml_io import copy_tree, read_yaml_file
from ..engine.registry import get_engine
from ..layout import is_chain
from ..results import plain
from .schema import DEFAULT_LYAPUNOV_RATIO, DISTRIBUTIONS, SweepSchema, SweepSpecError, validate_spec

__all__ = [
    "SweepSpec",
    "SweepSpecError",
    "Base",
    "Distribution",
    "RandomSpec",
    "DISTRIBUTIONS",
    "DEFAULT_LYAPUNOV_RATIO",
    "load_spec",
    "spec_from_mapping",
    "is_run_config",
    "MAX_RUNS",
    "DesignTable",
    "read_design_table",
    "table_columns",
    "column_key",
]


#: Most runs of one sweep: the parent holds the run table and the index's columns
#: (~:data:`BYTES_PER_RUN` a run) until the index is written.
MAX_RUNS = 1_000_000

#: Memory the parent holds per run of a sweep [bytes] (its row of the run table and of
#: the index's columns; measured ~0.5 KB for Case 3 parameter sweeps).
BYTES_PER_RUN = 600


def _parse_yaml(text: str) -> Any:
    # The project's loader: 1e-8 is a float, a duplicate key is an error.

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
        ``(lo, hi)`` float arrays for uniform, log_uniform, scale_uniform and scale_log_uniform,
        ``(mean, std)`` for normal, ``(values,)`` for choice.
    """

    key: str
    kind: str
    args: tuple

    @classmethod
    def from_schema(cls, key: str, schema) -> "Distribution":
        """From a validated :class:`~rbstab.sweep.schema.DistributionSchema`."""
        kind = schema.kind
        value = getattr(schema, kind)
        if kind == "normal":
            return cls(key, kind, (np.asarray(value.mean, dtype=float), np.asarray(value.std, dtype=float)))
        if kind == "choice":
            return cls(key, kind, (tuple(copy.deepcopy(value)),))
        return cls(key, kind, tuple(np.asarray(v, dtype=float) for v in value))

    def to_mapping(self) -> dict:
        """The YAML form, e.g. ``{"uniform": [lo, hi]}``."""
        if self.kind == "normal":
            return {"normal": {"mean": plain(self.args[0]), "std": plain(self.args[1])}}
        if self.kind == "choice":
            return {"choice": copy.deepcopy(list(self.args[0]))}
        return {self.kind: [plain(self.args[0]), plain(self.args[1])]}


# -- the spec ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class DesignTable:
    """``table``: one run per row, a column per dotted config key (entry).

    Attributes
    ----------
    columns : dict of str to ndarray
        Dotted key (``initial_state.omega.1``, ``body.inertia.0.2``) -> values, shape (rows,).
    source : str or None
        The CSV or Parquet file it was read from (None: given as a DataFrame or mapping).
    """

    columns: dict
    source: str | None = None

    @property
    def n_rows(self) -> int:
        return len(next(iter(self.columns.values())))


@dataclass(frozen=True)
class RandomSpec:
    """``random`` section: ``n`` samples of ``params`` from ``default_rng(seed)``."""

    n: int = 0
    seed: int = 0
    params: tuple[Distribution, ...] = ()


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


#: The fields of a joint of one body's tree that a sweep may vary and keep it the paper's one
#: body (:attr:`SweepSpec.may_run_tree`): its gains and limits, a lower torque limit left out.
PAPER_JOINT_FIELDS = frozenset({"k_r", "l_r", "k_c", "l_c", "k_d", "l_d", "k_s", "boundary_layer",
                                "saturation.torque_n", "saturation.constraint_force", "saturation.shape"})


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
    table : DesignTable or None
        Runs given row by row (``table:``, ``--table FILE``).
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
    table: DesignTable | None = None
    lyapunov_ratio: float = DEFAULT_LYAPUNOV_RATIO
    description: str = ""
    source: str | None = None
    overrides: tuple[str, ...] = ()

    @property
    def is_chain(self) -> bool:
        """Whether the bases are chains (:func:`rbstab.layout.is_chain`; a spec's bases
        are all chains or all one-body configurations)."""
        return bool(self.bases) and is_chain(self.bases[0].data)

    @property
    def may_run_one_body(self) -> bool:
        """Whether a run may be the paper's one body (:func:`rbstab.variants.paper.has_paper_form`):
        a one-body base, or a tree base of one body (its runs' joint points decide), so that
        the one-body kernels are compiled before the workers start
        (:func:`rbstab.engine.ensure_compiled`)."""
        return any(not is_chain(b.data) or len(b.data.get("bodies") or ()) == 1 for b in self.bases)

    @property
    def may_run_tree(self) -> bool:
        """Whether a run may be a model other than the paper's one body
        (:func:`rbstab.variants.paper.has_paper_form`), so that a tree's kernels are compiled
        before the workers start (:func:`rbstab.engine.ensure_compiled`): a tree base of
        several bodies, or of one body that is not the paper's (or that the loader refuses),
        or a varied key of a joint other than its gains and limits (:data:`PAPER_JOINT_FIELDS`:
        its points, law, reference, passive torque and lower torque limits make another model)."""
        trees = [b for b in self.bases if is_chain(b.data)]
        if not trees:
            return False
        for key in self.varied_keys:
            parts = key.split(".")
            if parts[0] == "joints" and ".".join(parts[2:4] if parts[2:3] == ["saturation"] else parts[2:3]) \
                    not in PAPER_JOINT_FIELDS:
                return True
        from ..config.loader import config_from_mapping  # heavy: numba (the loader's tree)
        from ..variants.paper import has_paper_form  # heavy: numba

        for base in trees:
            if len(base.data.get("bodies") or ()) != 1:
                return True
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # the sweep's validation reports them
                    config = config_from_mapping(base.data)
            except ConfigError:
                return True
            if not has_paper_form(config.chain):
                return True
        return False

    def may_run_scipy(self, engine: str | None = None) -> bool:
        """Whether a run may go to scipy's methods on ``engine`` (its name, default the
        compiled one; :meth:`rbstab.engine.Engine.takes`): the engine ``scipy``, a base's
        method the engine leaves out, or ``simulation.method`` varied; so that their kernels
        are compiled before the workers start (:func:`rbstab.engine.ensure_compiled`)."""
        taken = get_engine(engine)
        if "simulation.method" in self.varied_keys:
            return True
        return any(not taken.takes((b.data.get("simulation") or {}).get("method", SimulationSettings.method))
                   for b in self.bases)

    @property
    def varied_keys(self) -> list[str]:
        """Every dotted key the sweep varies: grid, zip, table, then random keys."""
        keys = list(self.grid) + list(self.zip) + (list(self.table.columns) if self.table is not None else [])
        if self.random.n:
            keys += [d.key for d in self.random.params]
        return keys

    @property
    def n_runs(self) -> int:
        """Number of runs: bases x grid points x zip entries x table rows x random samples."""
        n = len(self.bases) * math.prod(len(v) for v in self.grid.values())
        if self.zip:
            n *= len(next(iter(self.zip.values())))
        if self.table is not None:
            n *= self.table.n_rows
        return n * max(self.random.n, 1)

    def to_mapping(self) -> dict:
        """The resolved spec: re-loadable by :func:`spec_from_mapping`, bases inline.

        The ``--set`` overrides are already applied to the inline bases.
        """
        bases = []
        for b in self.bases:
            data = copy_tree(b.data)
            data["name"] = b.label
            bases.append(data)
        out: dict[str, Any] = {"name": self.name}
        if self.description:
            out["description"] = self.description
        out["base"] = bases[0] if len(bases) == 1 else bases
        out["grid"] = copy_tree(self.grid)
        out["zip"] = copy_tree(self.zip)
        if self.table is not None:
            out["table"] = self.table.source
        out["random"] = {
            "n": self.random.n,
            "seed": self.random.seed,
            "params": {d.key: d.to_mapping() for d in self.random.params},
        }
        out["convergence"] = {"lyapunov_ratio": self.lyapunov_ratio}
        return out


def _read_base(entry: Any, where: str, spec_dir: Path, errors: list[str]) -> Base | None:
    """One ``base`` entry (a path or an inline mapping, checked by the schema) as a Base."""
    if isinstance(entry, Mapping):
        data = copy.deepcopy(dict(entry))
        label = data.get("name") if isinstance(data.get("name"), str) else "base"
        return Base(label, data, None)

    path = Path(entry).expanduser()
    if not path.is_absolute():
        path = spec_dir / path
    try:  # within the YAML reader's limits (regular files, size, depth, aliases)
        data = read_yaml_file(path, "config file")
    except ConfigError as exc:
        errors += [f"sweep key '{where}': found {entry!r}; {line}" for line in exc.errors]
        return None
    if not isinstance(data, Mapping):
        errors.append(f"sweep key '{where}': {path}: found {_kind(data)}; expected a config mapping")
        return None
    label = data.get("name") if isinstance(data.get("name"), str) else path.stem
    return Base(label, dict(data), str(path))


def _set_spec_override(data: dict, override: str) -> None:
    """Apply ``sweep.<path>=value``; ``grid.<key>``, ``zip.<key>`` and ``random.params.<key>``
    take the rest of the path as one (dotted) key."""
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
        parse_key(path, SweepSchema).set(data, value)
    except KeyPathError as exc:
        raise ConfigError([f"override {override!r}: {exc.problem}"]) from None


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
        The spec (module docstring; schema: :class:`rbstab.sweep.schema.SweepSchema`).
        Not modified.
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
    if isinstance(data, Mapping):
        given_table = data.get("table")  # a DataFrame or arrays: not copied
        data = copy_tree({k: v for k, v in data.items() if k != "table"})
        if given_table is not None:
            data["table"] = given_table
        errors: list[str] = []
        for o in (o for o in overrides if o.strip().startswith("sweep.")):
            try:
                _set_spec_override(data, o)
            except ConfigError as exc:
                errors += exc.errors
        if errors:
            raise SweepSpecError(errors, source)
        if "name" not in data and default_name is not None:
            data["name"] = default_name
    schema = validate_spec(data, source)
    base_overrides = [o for o in overrides if not o.strip().startswith("sweep.")]
    bases, errors = _bases(schema, source, base_overrides)
    errors += _overridden_sweep_keys(schema, base_overrides)
    if errors:
        raise SweepSpecError(errors, source)
    table = _design_table(schema, source)
    errors = _overlapping_table_keys(schema, table, base_overrides)
    if errors:
        raise SweepSpecError(errors, source)
    n_runs = len(bases) * math.prod(len(v) for v in schema.grid.values()) * max(int(schema.random.n), 1) * (
        len(next(iter(schema.zip.values()))) if schema.zip else 1) * (table.n_rows if table is not None else 1)
    if n_runs > MAX_RUNS:
        raise SweepSpecError([
            f"the sweep has {n_runs} runs (bases x grid points x zip entries x table rows x random.n); at most "
            f"{MAX_RUNS} (its run table and index would hold ~{n_runs * BYTES_PER_RUN / 2**30:.3g} GiB in memory): "
            "split it into several sweeps"], source)
    random = RandomSpec(
        int(schema.random.n), int(schema.random.seed),
        tuple(Distribution.from_schema(key, d) for key, d in schema.random.params.items()),
    )
    return SweepSpec(
        name=schema.name,
        bases=tuple(bases),
        grid=copy_tree(dict(schema.grid)),
        zip=copy_tree(dict(schema.zip)),
        random=random,
        table=table,
        lyapunov_ratio=float(schema.convergence.lyapunov_ratio),
        description=schema.description or "",
        source=source,
        overrides=tuple(overrides),
    )


_COLUMN = re.compile(r"^\s*(.*?)\s*\[\s*([0-9]+)\s*(?:,\s*([0-9]+)\s*)?\]\s*$")


def column_key(name: str) -> str:
    """The dotted config key a design-table column name stands for: ``body.mass`` as it is,
    ``initial_state.omega[1]`` -> ``initial_state.omega.1``, ``body.inertia[0,2]`` ->
    ``body.inertia.0.2`` (whether it names anything is :func:`rbstab.config.paths.parse_key`'s
    to say)."""
    m = _COLUMN.match(str(name))
    return str(name).strip() if m is None else ".".join(p for p in m.groups() if p is not None)


def table_columns(data: Any, where: str = "table") -> dict[str, np.ndarray]:
    """A design table (pandas DataFrame, or a mapping column name -> 1-D values) as dotted
    config key -> column (float64, int64 or object for text).

    Raises
    ------
    SweepSpecError
        For a column name that is not a config key, columns of different lengths, an
        empty table or a column that is neither numbers nor text.
    """
    columns = {str(k): data[k] for k in data.columns} if hasattr(data, "columns") else dict(data)
    errors, out, lengths = [], {}, set()
    for name, values in columns.items():
        key = column_key(name)
        try:
            parse_any_key(key)  # which kind the bases take: checked run by run
        except KeyPathError as exc:
            errors.append(f"sweep key '{where}': column {name!r}: {exc.problem}")
            continue
        array = np.asarray(values)
        if array.ndim != 1:
            errors.append(f"sweep key '{where}': column {name!r} has shape {array.shape}; expected one value a run")
            continue
        if array.dtype.kind == "b" or array.dtype.kind not in "fiuOUS":
            array = array.astype(object)
        elif array.dtype.kind in "US":
            array = array.astype(object)
        elif array.dtype.kind == "u":
            array = array.astype(np.int64)
        if key in out:
            errors.append(f"sweep key '{where}': columns {name!r} and another both give '{key}'")
        out[key] = array
        lengths.add(len(array))
    if not out and not errors:
        errors.append(f"sweep key '{where}': found a table without columns; expected columns named by config keys")
    if len(lengths) > 1:
        errors.append(f"sweep key '{where}': columns of different lengths {sorted(lengths)}")
    if lengths == {0}:
        errors.append(f"sweep key '{where}': found a table without rows; expected one row a run")
    if errors:
        raise SweepSpecError(errors)
    return out


def read_design_table(path: str | Path):
    """A design table file as a pandas DataFrame: CSV (``.csv``, ``.csv.gz``, ...) or
    Parquet (``.parquet``, ``.pq``; needs pyarrow).

    Raises
    ------
    SweepSpecError
        For a missing or unreadable file, or one of another kind.
    """
    import pandas as pd  # heavy: only for a sweep with a table

    path = Path(path)
    where = "table"
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(path)
        if ".csv" in path.suffixes or path.suffix.lower() == ".csv":
            return pd.read_csv(path)
    except ImportError as exc:
        raise SweepSpecError([f"sweep key '{where}': reading {path} needs {exc.name or 'pyarrow'}: "
                              "pip install pyarrow"]) from None
    except FileNotFoundError:
        raise SweepSpecError([f"sweep key '{where}': found {str(path)!r}; no such file"]) from None
    except (OSError, ValueError) as exc:
        raise SweepSpecError([f"sweep key '{where}': cannot read {path}: {exc}"]) from None
    raise SweepSpecError([f"sweep key '{where}': found {str(path)!r}; expected a .csv or .parquet file"])


def _design_table(schema: SweepSchema, source: str | None) -> DesignTable | None:
    """The ``table`` entry (a file path relative to the spec, a DataFrame or a mapping of
    columns) as a :class:`DesignTable`."""
    given = schema.table
    if given is None:
        return None
    if isinstance(given, (str, Path)):
        path = Path(given).expanduser()
        if not path.is_absolute():
            path = (Path(source).resolve().parent if source else Path.cwd()) / path
        try:
            return DesignTable(table_columns(read_design_table(path)), str(path))
        except SweepSpecError as exc:
            raise SweepSpecError(exc.errors, source) from None
    if not (hasattr(given, "columns") or isinstance(given, Mapping)):
        raise SweepSpecError([f"sweep key 'table': found {_kind(given)}; expected a CSV or Parquet file path, "
                              "a pandas DataFrame or a mapping of column name -> values"], source)
    try:
        return DesignTable(table_columns(given), None)
    except SweepSpecError as exc:
        raise SweepSpecError(exc.errors, source) from None


def _overlapping_table_keys(schema: SweepSchema, table: DesignTable | None, overrides: Sequence[str]) -> list[str]:
    """A table column that overlaps a key varied elsewhere, or an override."""
    if table is None:
        return []
    errors = []
    for key in table.columns:
        for section, other in schema.varied():
            if key == other or key.startswith(other + ".") or other.startswith(key + "."):
                errors.append(f"sweep key 'table': column '{key}' overlaps '{section}.{other}': a key is varied "
                              "in one place only")
        for o in overrides:
            okey = o.partition("=")[0].strip()
            if okey == key or okey.startswith(key + ".") or key.startswith(okey + "."):
                errors.append(f"override {o!r}: the sweep's table varies '{key}', which would replace the "
                              "override; drop the override or the column")
    return errors


def _bases(schema: SweepSchema, source: str | None, overrides: Sequence[str]) -> tuple[list[Base], list[str]]:
    """The base configurations, read and with the overrides applied; (bases, problems)."""
    spec_dir = Path(source).resolve().parent if source else Path.cwd()
    errors: list[str] = []
    bases: list[Base] = []
    for i, entry in enumerate(schema.base):
        b = _read_base(entry, f"base.{i}" if len(schema.base) > 1 else "base", spec_dir, errors)
        if b is None:
            continue
        try:
            bases.append(Base(b.label, apply_overrides(b.data, overrides), b.source))
        except ConfigError as exc:
            errors += exc.errors
    chains = [b.label for b in bases if is_chain(b.data)]
    if chains and len(chains) < len(bases):
        bodies = next(b.label for b in bases if not is_chain(b.data))
        errors.append(f"sweep key 'base': base '{chains[0]}' is a chain (bodies, joints) and base '{bodies}' one body "
                      "(body, controller); expected the bases of a sweep all chains or all one-body configs")
    elif bases:
        errors += _keys_of_bases(schema, bases[0].data)
    labels = [b.label for b in bases]
    dups = sorted({x for x in labels if labels.count(x) > 1})
    if dups:
        errors.append(
            f"sweep key 'base': several bases have the label {dups} (their config name or file "
            "stem); give each a distinct 'name'"
        )
    return bases, errors


def _keys_of_bases(schema: SweepSchema, base: dict) -> list[str]:
    """The problems of the varied keys read as keys of the bases' kind (that of ``base``,
    one of them: chains or one-body configurations, :func:`rbstab.config.paths.schema_of`)."""
    keys = [("grid", k) for k in schema.grid] + [("zip", k) for k in schema.zip] + [
        ("random.params", k) for k in schema.random.params]
    root = schema_of(base)
    kind = "chains" if root is ChainSchema else "one-body configs"
    errors = []
    for where, key in keys:
        try:
            parse_key(key, root)
        except KeyPathError as exc:
            errors.append(f"sweep key '{where}.{key}': the bases are {kind}; {exc.errors[0]}")
    return errors


def _overridden_sweep_keys(schema: SweepSchema, overrides: Sequence[str]) -> list[str]:
    """An override of a key the sweep varies would be replaced by it: refuse the pair."""
    errors = []
    for o in overrides:
        okey = o.partition("=")[0].strip()
        for section, key in schema.varied():
            if okey == key or okey.startswith(key + "."):
                errors.append(
                    f"override {o!r}: the sweep varies '{key}' ({section}), which would replace the override; "
                    "drop the override or the sweep key"
                )
    return errors


def load_spec(path: str | Path, overrides: Sequence[str] = ()) -> SweepSpec:
    """Read and validate a sweep spec YAML file (see :func:`spec_from_mapping`).

    The file stem is the default sweep name.

    Raises
    ------
    SweepSpecError
        For a missing or unreadable file, a YAML syntax error, or any invalid entry.
    """
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
    and a ``body`` or ``controller`` section, or a chain's ``bodies`` or ``joints``)."""
    return isinstance(data, Mapping) and "base" not in data and any(
        key in data for key in ("body", "controller", "bodies", "joints"))


