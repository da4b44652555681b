"""A generation of trials as one batch of runs on the sweep's engine.

A tuning study evaluates its trials a generation at a time: the K trials' values (with
``--over``, crossed with the B uncertain bodies: K x B rows) become one design table, which
is planned as a sweep's table of runs (:func:`rbstab.sweep.table.plan_table`: every run
validated at once, by columns) and integrated as one batch of arrays
(:meth:`rbstab.sweep.table.TableSlice.batch`, :func:`rbstab.simulator.simulate_batch`), in
this process or in slices on an executor (``-j N`` local processes, Dask), as a sweep
integrates its chunks. Nothing is written: the runs' summary figures come back as columns.
The figures are those of :func:`rbstab.simulator.simulate_many` for each run's
configuration, bit for bit.

A chain's runs (a table whose base is a chain's configuration) are built from their rows and
integrated together on the engine, the runs of one chain in one call
(:func:`rbstab.simulator.simulate_blocks`: the figures of :func:`rbstab.simulator.simulate`,
per body or joint as its sweep's columns, ``<figure>_<member>[_<axis>]``).
"""

from __future__ import annotations

import copy
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..config import ConfigError, PhysicalPlausibilityWarning
from ..config.loader import config_from_mapping
from ..convergence import DEFAULT_LYAPUNOV_RATIO, converged
from ..engine.registry import get_engine
from ..io.chunk import summary_table_columns
from ..sweep.validate import key_path
from .design import METRICS_NOT_FIGURES, design_mappings, members_of

__all__ = ["GenerationRuns", "run_generation", "integrate_part", "CALLS"]

#: Batches integrated in this process (a count per call of :func:`integrate_part`; tests read it).
CALLS = {"batches": 0}


@dataclass
class GenerationRuns:
    """The runs of a generation: figure columns over the rows of its table.

    Attributes
    ----------
    figures : dict of str to ndarray
        Figure column (``lyapunov_final``, ``max_abs_constraint_error_z``, ``converged``
        ...) -> its value per row, shape (n,); NaN where a row has no such figure.
    ok : ndarray of bool, shape (n,)
        Whether the row's run succeeded.
    invalid : dict of int to str
        Row -> why its configuration is invalid (the row was not run).
    """

    figures: dict
    ok: np.ndarray
    invalid: dict


def integrate_part(part, engine: str = "compiled") -> dict:
    """Integrate the runs of a :class:`rbstab.sweep.table.TableSlice`; return their figure
    columns (``figures``: column -> values, shape (k,); a chain's per body or joint and
    axis, as its sweep's columns; ``ok``: success per run, shape (k,)). The function an
    executor runs: the runs that the compiled (or cuda) engine takes go as one batch
    (:meth:`rbstab.sweep.table.TableSlice.batch`: one body's or trees') through
    :func:`rbstab.simulator.simulate_batch` (the summary figures only, no trace kept); the
    others (implicit methods, the pure sign law) from their configurations through
    :func:`rbstab.simulator.simulate_blocks`."""
    from ..simulator import simulate_batch, simulate_blocks  # heavy: numba

    CALLS["batches"] += 1
    n = len(part)
    columns: dict[str, np.ndarray] = {}
    ok = np.zeros(n, dtype=bool)
    members = members_of(part.templates[0]) if len(part.templates) else None

    def put(rows: Sequence[int], table: Mapping[str, Any], status: Sequence[str]) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        flat = summary_table_columns(table, *((members.joints, members.bodies) if members else ()))
        for key, values in flat.items():
            values = np.asarray(values)
            if key in METRICS_NOT_FIGURES or values.dtype.kind not in "fiub":
                continue
            column = columns.get(key)
            if column is None:
                column = columns[key] = np.full(n, np.nan)
            column[rows] = values.astype(float)
        success = np.array([s == "success" for s in status])
        ok[rows] = success
        column = columns.setdefault("converged", np.full(n, np.nan))
        column[rows] = np.asarray(converged(success, np.asarray(flat["lyapunov_initial"], dtype=float),
                                            np.asarray(flat["lyapunov_final"], dtype=float),
                                            DEFAULT_LYAPUNOV_RATIO, flat.get("max_lyapunov_increase")), dtype=float)

    spec = get_engine(engine)
    engine_name = engine if spec.compiled else None
    batch = part.batch() if engine_name else None
    fast = np.flatnonzero(batch.compiled) if batch is not None else np.empty(0, dtype=np.int64)
    if len(fast):
        for rows, block in simulate_batch(batch, fast, full=False, engine=engine_name, keep="none"):
            put(rows, block.summaries, block.status)
    slow = np.setdiff1d(np.arange(n), fast)
    if len(slow):
        with warnings.catch_warnings():  # shown once, when the table was planned
            warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
            configs = [config_from_mapping(part.resolved(int(j)), source="<trial>") for j in slow]
        for rows, block in simulate_blocks(configs, engine=engine, full=False, keep="none"):
            put(slow[rows], block.summaries, block.status)
    return {"figures": columns, "ok": ok}


def run_generation(base: Mapping, design: pd.DataFrame, *, engine: str = "compiled", executor=None,
                   size: int | None = None) -> GenerationRuns:
    """Plan the rows of ``design`` (absolute values, columns as in :mod:`rbstab.studies.design`)
    on ``base`` (a resolved configuration, one body's or a chain's) as a table of runs and
    integrate it as one batch (:func:`integrate_part`).

    ``executor`` (an :class:`rbstab.sweep.executors.Executor`, or None: this process) takes
    the table in ``size``-row slices (default: the rows split evenly over its workers). A
    row whose configuration is invalid is not run (``invalid`` says why).
    """
    from ..sweep.spec import SweepSpecError, spec_from_mapping  # heavy: pydantic, numba
    from ..sweep.table import plan_table  # heavy: numba, h5py (imported with the first generation)

    n = len(design)
    invalid: dict[int, str] = {}
    keep = np.arange(n)
    try:
        table = plan_table(spec_from_mapping({"name": "generation", "base": dict(base), "table": design}))
    except SweepSpecError:  # rare: a row the search box's corners did not rule out; find it row by row
        invalid = _invalid_rows(base, design)
        keep = np.array([i for i in range(n) if i not in invalid], dtype=np.int64)
        if not len(keep):
            return GenerationRuns({}, np.zeros(n, dtype=bool), invalid)
        table = plan_table(spec_from_mapping({"name": "generation", "base": dict(base),
                                              "table": design.iloc[keep].reset_index(drop=True)}))
    m = table.n
    if executor is None:
        parts = [integrate_part(table.slice(np.arange(m)), engine)]
        bounds = [(0, m)]
    else:
        workers = max(executor.parallelism() or 1, 1)
        step = size or max(1, math.ceil(m / workers))
        bounds = [(lo, min(lo + step, m)) for lo in range(0, m, step)]
        slices = (table.slice(np.arange(lo, hi)) for lo, hi in bounds)
        executor.plan(len(bounds))
        done: dict[int, dict] = {}
        for part, result, exc in executor.imap_unordered(integrate_part, slices, engine):
            if exc is not None:
                raise exc
            done[int(part.index[0])] = result
        parts = [done[lo] for lo, _ in bounds]
    figures: dict[str, np.ndarray] = {}
    ok = np.zeros(n, dtype=bool)
    for (lo, hi), result in zip(bounds, parts):
        rows = keep[lo:hi]
        ok[rows] = result["ok"]
        for key, values in result["figures"].items():
            figures.setdefault(key, np.full(n, np.nan))[rows] = values
    return GenerationRuns(figures, ok, invalid)


def _invalid_rows(base: Mapping, design: pd.DataFrame) -> dict[int, str]:
    """Row -> why its configuration is invalid (the schema's messages), of the rows of ``design``."""
    mappings = design_mappings(design)
    out = {}
    for i in range(len(design)):
        data = copy.deepcopy(dict(base))
        for key, values in mappings.items():
            key_path(key, base).set(data, values[i])
        try:
            config_from_mapping(data, source="<trial>")
        except ConfigError as exc:
            out[i] = "; ".join(exc.errors)
    return out
