"""A sweep's runs one by one, for small sweeps and for inspection: :func:`expand`.

A sweep is planned as a table (:func:`rbstab.sweep.table.plan_table`); the runner works on
its columns. :func:`expand` gives the same runs as :class:`PlannedRun` objects (a
validated :class:`~rbstab.config.RunConfig` each), the form a notebook or a test looks at.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .spec import SweepSpec
import warnings
from ..config import PhysicalPlausibilityWarning, config_from_mapping
from .table import plan_table

__all__ = ["PlannedRun", "expand"]


@dataclass(frozen=True, eq=False)
class PlannedRun:
    """One run of a sweep, validated.

    Attributes
    ----------
    index : int
        Position in the run list (:mod:`rbstab.sweep.spec` gives the order).
    run_id : str
        ``r<index>-<hash8>``; also ``config.name`` and the file stem.
    base : str
        Label of its base configuration.
    params : dict of str to Any
        The varied values: dotted key -> value set in the config, in the order of
        :attr:`SweepSpec.varied_keys`; for a ``scale_uniform`` key also ``"<key>:scale"`` ->
        the factor.
    config : RunConfig
        The configuration, ``config.name == run_id``.
    config_hash : str
        The run's identity (:mod:`rbstab.sweep.table`): the ``config_hash`` of its stored result.
    """

    index: int
    run_id: str
    base: str
    params: dict
    config: Any
    config_hash: str


def _value(column, i: int) -> Any:
    value = column[i]
    return value.tolist() if hasattr(value, "tolist") else value


def expand(spec: SweepSpec) -> list[PlannedRun]:
    """Every run of ``spec``, validated (:func:`rbstab.sweep.table.plan_table`), one object each.

    Returns
    -------
    list of PlannedRun
        In run-list order; ``len == spec.n_runs``.

    Raises
    ------
    SweepSpecError
        If any run's configuration is invalid: one line per problem, naming the run (index,
        base and varied values) and the config key. Nothing is run for an invalid sweep.
    """


    table = plan_table(spec)
    labels = table.base_labels
    runs = []
    for i in range(table.n):
        params = {k: _value(table.columns[k], i) for k in table.keys}
        params.update({f"{k}:scale": _value(v, i) for k, v in table.scales.items()})
        with warnings.catch_warnings():  # kept in config.warnings (table.warnings: their digest)
            warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
            config = config_from_mapping(table.resolved(i))
        runs.append(PlannedRun(i, table.run_id[i].decode(), str(labels[i]), params, config,
                               table.config_hash[i].decode()))
    return runs
