"""A sweep's runs as a table: one row per run, one numpy column per varied key.

:func:`plan_table` turns a :class:`~rbstab.sweep.spec.SweepSpec` into a :class:`RunTable`
with vectorised code: grid levels by index arithmetic, zip and ``table`` entries by array
indexing, random samples by one numpy call per key. No Python object is made per run.

- **Templates.** The runs whose non-numeric values (a ``controller.variant``, a
  ``simulation.method``, a list of mixed shapes) and base are the same share a
  *template*: the resolved configuration of the first of them, validated by the config
  schema (:func:`rbstab.config.config_from_mapping`). A run is its template with its
  numeric values set (:meth:`RunTable.resolved`).
- **Validation of the columns.** Every numeric field a varied key touches is assembled as
  an array over the runs (``(n,)``, ``(n, 3)`` or ``(n, 3, 3)``) and checked at once with
  the constraint the config schema declares for it (:attr:`rbstab.config.paths.KeyPath.rule`:
  bounds, finiteness, magnitude, positive (semi-)definiteness by batched ``eigvalsh``), and
  the joint checks are made on the columns (the margin to gimbal lock, samples and steps
  that let a run end, the weight held by the stiffnesses). The runs a check flags are
  validated one by one by the schema itself, for its messages (run, key, value, what is
  allowed), so the messages are those of ``rbstab run``.
- **Identity.** A run's ``config_hash`` is the SHA-256 of its base's canonical JSON and
  of its row (the varied keys and their values, the run limits left out), ``run_id`` is
  ``r<index>-<hash[:8]>``; both are made for all runs at once.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .spec import SweepSpec, SweepSpecError
from .validate import base_value, key_path
from .validate import validate_columns
from ..config import canonical_config
from ..engine.batch import batch_from_table
from ..io.chunk import store_bytes_per_run
from .folder import parameter_name

__all__ = ["RunTable", "TableSlice", "plan_table", "estimate", "MAX_TEMPLATES",
           "RUN_SECONDS"]

#: Integration time of a run per core [s] for 2 s of simulated time (the paper's Case 3 at
#: rtol 1e-8, DOP853, the compiled engine: ~0.35-0.45 ms), for the estimate of a dry run.
RUN_SECONDS = 4e-4
#: The same for a chain's run, and the seconds a run's file costs (``benchmarks/chains.py``:
#: the 3-body chain, ~20 ms its integration, ~20 ms its file).
CHAIN_RUN_SECONDS, CHAIN_FILE_SECONDS = 2e-2, 2e-2

#: Distributions whose draws are factors of the base value.
SCALES = ("scale_uniform", "scale_log_uniform")

#: Most templates of a sweep (distinct combinations of base and non-numeric values).
MAX_TEMPLATES = 4096
_MAX_LISTED = 10  # invalid runs listed in an error, the rest counted
#: Simulation settings that are not part of a run's identity (io.hdf5.RUN_LIMIT_KEYS).
_LIMIT_KEYS = ("simulation.max_steps", "simulation.max_wall_time")
# -- columns of values ---------------------------------------------------------------------------


def _as_column(values: Sequence[Any]) -> np.ndarray:
    """Values as a numeric array (n, *shape) when they are numbers (not booleans) of one
    shape, else a 1-D object array."""
    try:
        array = np.asarray(values)
    except (ValueError, TypeError):
        array = None
    if array is not None and array.dtype.kind in "fi" and array.ndim <= 3:
        return array.astype(np.float64) if array.dtype.kind == "f" else array.astype(np.int64)
    out = np.empty(len(values), dtype=object)
    for i, v in enumerate(values):
        out[i] = v
    return out


def _draw(d, rng: np.random.Generator, n: int) -> np.ndarray:
    """n draws of a :class:`~rbstab.sweep.spec.Distribution` (the factors for scale_uniform)."""
    if d.kind in ("uniform", "scale_uniform", "log_uniform", "scale_log_uniform"):
        lo, hi = d.args
        shape = (n, *np.broadcast_shapes(lo.shape, hi.shape))
        if d.kind in ("log_uniform", "scale_log_uniform"):
            return np.exp(rng.uniform(np.log(lo), np.log(hi), size=shape))
        return rng.uniform(lo, hi, size=shape)
    if d.kind == "normal":
        mean, std = d.args
        return rng.normal(mean, std, size=(n, *np.broadcast_shapes(mean.shape, std.shape)))
    (values,) = d.args
    picks = rng.integers(len(values), size=n)
    column = _as_column(list(values))
    return column[picks]


def random_stream(seed: int, key: str) -> np.random.Generator:
    """The generator of the random key ``key``: its own stream of ``seed`` (a key's draws do
    not depend on the other keys, nor the first k samples on ``random.n``)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(zlib.crc32(key.encode()),)))


# -- the table -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TableSlice:
    """Runs of a :class:`RunTable` as a worker receives them (small: numpy slices).

    Attributes
    ----------
    templates : tuple of dict
        Resolved configurations (validated) the runs start from.
    keys : tuple of str
        The varied dotted keys set on a template, in order.
    columns : dict of str to ndarray
        key -> its values, shape (k, ...) (object arrays for non-numeric values).
    template : ndarray of int, shape (k,)
    index, run_id, config_hash, base : ndarray, shape (k,)
        Position in the run list, ids, hashes, base labels.
    coords : dict of str to ndarray
        Parameter coordinate name -> values, shape (k,).
    """

    templates: tuple
    keys: tuple
    columns: dict
    template: np.ndarray
    index: np.ndarray
    run_id: np.ndarray
    config_hash: np.ndarray
    base: np.ndarray
    coords: dict

    def __len__(self) -> int:
        return len(self.index)

    def batch(self, timeout: float | None = None):
        """The slice's runs as one batch of arrays (parameter records, initial states,
        settings; ``timeout`` [s] replaces each run's ``simulation.max_wall_time``): a
        :class:`rbstab.engine.RunBatch` (:func:`rbstab.engine.batch_from_table`)."""
        return batch_from_table(self.templates, self.keys, self.columns, self.template, timeout=timeout)

    def resolved(self, j: int) -> dict:
        """The resolved configuration of run ``j`` of the slice (``name`` = its run id)."""
        return build_resolved(self.templates[int(self.template[j])], self.keys,
                              [self.columns[k][j] for k in self.keys], str(self.run_id[j]))


def build_resolved(template: Mapping, keys: Sequence[str], values: Sequence[Any], name: str) -> dict:
    """``template`` (a resolved configuration) with each dotted key of ``keys`` set to its
    value; the sections it changes are copied, the others shared."""

    out = dict(template)
    out["name"] = name
    copied: set[str] = set()
    for key, value in zip(keys, values):
        path = key_path(key, template)
        if path.section not in copied:
            out[path.section] = _deep(out[path.section])
            copied.add(path.section)
        path.set(out, value.tolist() if isinstance(value, np.ndarray | np.generic) else value)
    return out


def _deep(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _deep(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_deep(v) for v in value]
    return value


@dataclass(frozen=True)
class RunTable:
    """Every run of a sweep as columns (module docstring); made by :func:`plan_table`.

    Attributes
    ----------
    spec : SweepSpec
    keys : tuple of str
        The varied dotted keys set on the templates: grid, zip, table, random (for
        ``scale_uniform`` the scaled value), in order.
    columns : dict of str to ndarray
        key -> values, shape (n, ...) float64/int64, or (n,) object.
    scales : dict of str to ndarray
        ``scale_uniform`` key -> its factors, shape (n, ...).
    templates : tuple of dict
        Validated resolved configurations the runs start from (``name`` removed).
    template : ndarray of int32, shape (n,)
    base_index : ndarray of int32, shape (n,)
    run_id, config_hash : ndarray of bytes, shape (n,)
    warnings : list of str
        Physical-plausibility warnings, one line per config key (``"200 of 200 runs: ..."``).
    """

    spec: SweepSpec
    keys: tuple
    columns: dict
    scales: dict
    templates: tuple
    template: np.ndarray
    base_index: np.ndarray
    run_id: np.ndarray
    config_hash: np.ndarray
    warnings: list = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.template)

    @functools.cached_property
    def base_labels(self) -> np.ndarray:
        """The base label of each run, shape (n,) (object)."""
        return np.asarray([b.label for b in self.spec.bases], dtype=object)[self.base_index]

    @property
    def variant(self) -> np.ndarray:
        """Each run's controller variant, shape (n,) (object)."""
        if "controller.variant" in self.columns:
            return self.columns["controller.variant"]
        return np.asarray([t["controller"]["variant"] if "controller" in t else "chain" for t in self.templates],
                          dtype=object)[self.template]

    def ids(self) -> list[str]:
        """The run ids as str."""
        return self.run_id.astype(str).tolist()

    def coords(self) -> dict[str, tuple[str, np.ndarray]]:
        """Parameter coordinate name -> (dotted key of the entry, values shape (n,)): each
        varied key split per entry (``controller.k_c`` -> ``k_c_0`` ..), then the
        ``scale_uniform`` factors (``mass_scale``), named by
        :func:`rbstab.sweep.folder.parameter_name`."""

        out: dict[str, tuple[str, np.ndarray]] = {}
        for suffix, source in (("", self.columns), (":scale", self.scales)):
            for key, values in source.items():
                if values.dtype == object or values.ndim == 1:
                    out[parameter_name(key + suffix)] = (key + suffix, values)
                    continue
                for idx in np.ndindex(values.shape[1:]):
                    entry = ".".join([key, *map(str, idx)]) + suffix
                    out[parameter_name(entry)] = (entry, values[(slice(None), *idx)])
        return out

    @functools.cached_property
    def _coords(self) -> dict[str, tuple[str, np.ndarray]]:
        return self.coords()

    def parameters(self) -> dict[str, str]:
        """Coordinate name -> dotted key of the entry (the store's ``config_key``)."""
        return {name: key for name, (key, _) in self.coords().items()}

    def resolved(self, i: int) -> dict:
        """The resolved configuration of run ``i`` (``name`` = its run id): its template
        with its values set."""
        return build_resolved(self.templates[int(self.template[i])], self.keys,
                              [self.columns[k][i] for k in self.keys], self.run_id[i].decode())

    def slice(self, rows: np.ndarray) -> TableSlice:
        """The runs ``rows`` (positions, increasing) as a worker receives them; the
        templates they use only, renumbered."""
        used, local = np.unique(self.template[rows], return_inverse=True)
        coords = {name: values[rows] for name, (_, values) in self._coords.items()}
        return TableSlice(
            templates=tuple(self.templates[t] for t in used), keys=self.keys,
            columns={k: v[rows] for k, v in self.columns.items()}, template=local.astype(np.int32),
            index=np.asarray(rows, dtype=np.int64), run_id=self.run_id[rows].astype(str),
            config_hash=self.config_hash[rows].astype(str), base=self.base_labels[rows], coords=coords)

    def time_grids(self) -> set:
        """The distinct sample grids (t_end, n_samples) of the runs."""
        return set(zip(self.setting("t_end").tolist(), self.setting("n_samples").astype(int).tolist()))

    def setting(self, name: str) -> np.ndarray:
        """A ``simulation`` setting of every run, shape (n,)."""
        key = f"simulation.{name}"
        if key in self.columns:
            return self.columns[key].astype(float)
        return np.array([t["simulation"][name] for t in self.templates], dtype=float)[self.template]

    def describe(self, head: int = 5, every: bool = False) -> list[str]:
        """Lines of a dry run: the varied keys with their ranges, then the first and last
        ``head`` runs (every run with ``every``)."""
        lines = []
        for name, (key, values) in self.coords().items():
            if values.dtype == object:
                distinct = list(dict.fromkeys(map(repr, values[:100000])))
                shown = ", ".join(distinct[:6]) + (", ..." if len(distinct) > 6 else "")
                lines.append(f"  {name} ({key}): {shown}")
            else:
                distinct = f", {len(np.unique(values))} distinct" if len(values) <= 100_000 else ""
                lines.append(f"  {name} ({key}): {values.min():.6g} .. {values.max():.6g}{distinct}")
        n = self.n
        rows = range(n) if every or n <= 2 * head else [*range(head), -1, *range(n - head, n)]
        shown = {**self.columns, **{f"{k}:scale": v for k, v in self.scales.items()}}
        labels = self.base_labels
        for i in rows:
            if i < 0:
                lines.append(f"  ... {n - 2 * head} more runs (all with -v)")
                continue
            values = "  ".join(f"{key}={_fmt(column[i])}" for key, column in shown.items())
            lines.append(f"  {self.run_id[i].decode()}  base={labels[i]}" + (f"  {values}" if values else ""))
        return lines


def _fmt(value: Any) -> str:
    value = value.tolist() if isinstance(value, np.ndarray | np.generic) else value
    return json.dumps(value) if isinstance(value, list) else str(value)


# -- planning ------------------------------------------------------------------------------------


def _axes(spec: SweepSpec) -> tuple[list[int], list[str]]:
    """(lengths, names) of the run list's axes, slowest first: sample, base, grid keys, zip, table."""
    dims, names = [], []
    if spec.random.n:
        dims.append(spec.random.n), names.append("sample")
    dims.append(len(spec.bases)), names.append("base")
    for key, values in spec.grid.items():
        dims.append(len(values)), names.append(f"grid:{key}")
    if spec.zip:
        dims.append(len(next(iter(spec.zip.values())))), names.append("zip")
    if spec.table is not None:
        dims.append(spec.table.n_rows), names.append("table")
    return dims, names


def _positions(spec: SweepSpec) -> dict[str, np.ndarray]:
    """Axis name -> each run's position along it, shape (n,) (int32)."""
    dims, names = _axes(spec)
    n = math.prod(dims)
    flat = np.arange(n, dtype=np.int64)
    out = {}
    for name, size, stride in zip(names, dims, np.cumprod([1, *dims[::-1]])[:-1][::-1]):
        out[name] = ((flat // int(stride)) % size).astype(np.int32)
    return out


def _scaled_columns(spec: SweepSpec, base_index: np.ndarray, sample: np.ndarray, errors: list[str]
                    ) -> tuple[dict, dict]:
    """(key -> scaled values, key -> factors) of the ``scale_uniform`` keys: each base's value
    of the key (its default if unset) times the drawn factors."""

    values, factors = {}, {}
    for d in (d for d in spec.random.params if d.kind in SCALES):
        drawn = _draw(d, random_stream(spec.random.seed, d.key), spec.random.n)
        f = drawn[sample]
        per_base = []
        for base in spec.bases:
            value, problem = base_value(base, d.key)
            if problem:
                errors.append(problem)
                continue
            per_base.append(value)
        if len(per_base) != len(spec.bases):
            continue
        shapes = {v.shape for v in per_base}
        shape = np.broadcast_shapes(*shapes) if len(shapes) > 1 else per_base[0].shape
        try:
            stacked = np.stack([np.broadcast_to(v, shape) for v in per_base])
            scaled = stacked[base_index] * f.reshape(f.shape + (1,) * (len(shape) - (f.ndim - 1)))
        except ValueError:
            errors.append(f"random.params.{d.key}: scale_uniform factors of shape {f.shape[1:]} cannot scale the "
                          f"base value of shape {shape}")
            continue
        values[d.key], factors[d.key] = scaled, f
    return values, factors


def _raw_columns(spec: SweepSpec) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """(key -> values, key -> scale factors, base index), every column of length n."""
    pos = _positions(spec)
    columns: dict[str, np.ndarray] = {}
    for key, values in spec.grid.items():
        columns[key] = _as_column(values)[pos[f"grid:{key}"]]
    for key, values in spec.zip.items():
        columns[key] = _as_column(values)[pos["zip"]]
    if spec.table is not None:
        for key, values in spec.table.columns.items():
            columns[key] = values[pos["table"]]
    errors: list[str] = []
    if spec.random.n:
        for d in spec.random.params:
            if d.kind not in SCALES:
                columns[d.key] = _draw(d, random_stream(spec.random.seed, d.key), spec.random.n)[pos["sample"]]
    scaled, factors = _scaled_columns(spec, pos["base"], pos["sample"], errors) if spec.random.n else ({}, {})
    if errors:
        raise SweepSpecError(errors, spec.source)
    ordered = {k: (scaled[k] if k in scaled else columns[k]) for k in spec.varied_keys}
    return ordered, factors, pos["base"]


def _kinds(columns: Mapping[str, np.ndarray], base_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(template of each run, first run of each template): runs share a template when their
    base and non-numeric values are the same."""
    if all(v.dtype != object for v in columns.values()) and int(base_index.max()) == 0:
        return np.zeros(len(base_index), dtype=np.int32), np.array([0])
    codes = [base_index.astype(np.int64)]
    for values in columns.values():
        if values.dtype == object:
            _, inverse = np.unique(np.array([repr(v) for v in values], dtype=object), return_inverse=True)
            codes.append(inverse.astype(np.int64))
    if len(codes) == 1:
        first_of, template = np.unique(codes[0], return_index=True)[1], None
        _, template = np.unique(codes[0], return_inverse=True)
        return template.astype(np.int32), first_of
    stacked = np.stack(codes, axis=1)
    _, first_of, template = np.unique(stacked, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first_of)  # templates numbered in run order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[template.ravel()].astype(np.int32), first_of[order]


def plan_table(spec: SweepSpec) -> RunTable:
    """Every run of ``spec`` as a validated :class:`RunTable`.

    Raises
    ------
    SweepSpecError
        If any run's configuration is invalid: one line per problem, naming the run (its
        index, base and varied values), the config key, the value and what is allowed;
        at most ten runs listed, the rest counted. Nothing is run for an invalid sweep.
    """

    columns, scales, base_index = _raw_columns(spec)
    template, first_of = _kinds(columns, base_index)
    if len(first_of) > MAX_TEMPLATES:
        raise SweepSpecError([f"the sweep's runs have {len(first_of)} distinct combinations of base and "
                              f"non-numeric values; at most {MAX_TEMPLATES}"], spec.source)
    templates, notes = validate_columns(spec, columns, base_index, template, first_of)
    config_hash, run_id = _identities(spec, columns, base_index)
    return RunTable(spec=spec, keys=tuple(columns), columns=columns, scales=scales, templates=templates,
                    template=template, base_index=base_index.astype(np.int32), run_id=run_id,
                    config_hash=config_hash, warnings=notes)


def _identities(spec: SweepSpec, columns: Mapping[str, np.ndarray], base_index: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(config_hash, run_id) of every run (module docstring), as bytes arrays."""

    n = len(base_index)
    keys = [k for k in columns if k not in _LIMIT_KEYS]
    head = json.dumps({"keys": keys, "shapes": [list(columns[k].shape[1:]) for k in keys]}, sort_keys=True)
    seeds = np.frombuffer(b"".join(hashlib.sha256((canonical_config(b.data) + head).encode()).digest()[:16]
                                   for b in spec.bases), dtype="<u8").reshape(len(spec.bases), 2)
    words = []
    for key in keys:
        values = columns[key]
        if values.dtype == object:
            texts = np.array([json.dumps(v, sort_keys=True, default=str) for v in values], dtype=object)
            distinct, inverse = np.unique(texts, return_inverse=True)
            digests = np.frombuffer(b"".join(hashlib.sha256(t.encode()).digest()[:8] for t in distinct), dtype="<u8")
            words.append(digests[inverse.ravel()][:, None])
        else:
            words.append(np.ascontiguousarray(values.reshape(n, -1).astype("<f8") + 0.0).view("<u8"))
    hashes = _row_hash(seeds[base_index], np.concatenate(words, axis=1) if words else np.zeros((n, 0), "<u8"))
    digits = max(4, len(str(max(n - 1, 0))))
    prefix = np.char.add(b"r", np.char.zfill(np.arange(n).astype(f"S{digits}"), digits))
    run_id = np.char.add(np.char.add(prefix, b"-"), hashes.astype("S8"))
    return hashes, run_id


_HEX = np.frombuffer(b"0123456789abcdef", dtype=np.uint8)


def _mix(h: np.ndarray) -> np.ndarray:
    """The splitmix64 finaliser, elementwise on uint64 (a bijection that spreads every bit)."""
    h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return h ^ (h >> np.uint64(31))


def _row_hash(seeds: np.ndarray, words: np.ndarray) -> np.ndarray:
    """A 128-bit digest of each row of ``words`` (uint64, shape (n, k)) from its ``seeds``
    (shape (n, 2), the base's SHA-256), as 32 hex digits (bytes): two lanes of splitmix64
    over the words, each word and its position mixed in. Not cryptographic: it tells apart
    the runs a sweep folder holds (a collision among 10^6 runs has a chance of ~10^-27)."""
    with np.errstate(over="ignore"):
        lanes = [seeds[:, 0].copy(), seeds[:, 1].copy()]
        for j in range(words.shape[1]):
            w = words[:, j]
            for k, salt in enumerate((0x9E3779B97F4A7C15, 0xD1B54A32D192ED03)):
                lanes[k] = _mix(lanes[k] ^ _mix(w + np.uint64((salt * (j + 1)) % 2**64)))
    raw = np.stack(lanes, axis=1).astype(">u8").view(np.uint8).reshape(len(words), 16)
    hexed = np.empty((len(words), 32), dtype=np.uint8)
    hexed[:, 0::2], hexed[:, 1::2] = _HEX[raw >> 4], _HEX[raw & 15]
    return hexed.view("S32").ravel()


def estimate(table: RunTable, store: str, workers: int) -> tuple[float, float]:
    """(bytes of the store, wall seconds) a sweep of ``table`` takes, roughly: the store
    from the bytes a run takes in it (:func:`rbstab.io.chunk.store_bytes_per_run` of each
    template's samples), the time from :data:`RUN_SECONDS` scaled by each run's ``t_end``
    over 2 s and shared by ``workers`` processes (a chain's from :data:`CHAIN_RUN_SECONDS`
    and :data:`CHAIN_FILE_SECONDS`)."""

    t_end = table.setting("t_end")
    size = float(np.sum(store_bytes_per_run(store, table.setting("n_samples"))))
    if table.spec.is_chain:
        return size, float(np.sum(t_end / 2.0 * CHAIN_RUN_SECONDS + CHAIN_FILE_SECONDS)) / max(workers, 1)
    return size, float(np.sum(t_end / 2.0)) * RUN_SECONDS / max(workers, 1)
