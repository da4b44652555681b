"""The settings of a run that travel together through the compiled integrators, and their
work arrays.

:data:`SETTINGS` is a numpy record (the runtime argument ``s`` of
:func:`rbstab.engine.integrate.integrate_run`, :func:`rbstab.engine.integrate.step`,
:func:`rbstab.engine.switching.integrate_switching`, ...): ``t_end`` [s], ``rtol``,
``atol``, ``max_step`` [s], ``gimbal_margin`` [rad], ``max_steps`` (accepted steps),
``max_wall_time`` [s] (inf: none) and ``method`` (the method's number,
:func:`rbstab.engine.rk.method_number`). :class:`Work` holds the arrays one run's steps
write into.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..jit import jit
from .rk import INTERPOLANT_ROWS, STAGE_ROWS

__all__ = ["SETTINGS", "SETTING_COLUMNS", "settings_rows", "settings_records", "Work", "work_arrays"]

#: A run's integration settings (module docstring); an aligned record, so that compiled code
#: reads each field with one 8-byte load.
SETTINGS = np.dtype([("t_end", np.float64), ("rtol", np.float64), ("atol", np.float64), ("max_step", np.float64),
                     ("gimbal_margin", np.float64), ("max_steps", np.int64), ("max_wall_time", np.float64),
                     ("method", np.int64)], align=True)


#: The columns of a run's settings row, :data:`SETTINGS` but the method: what
#: :func:`rbstab.engine.integrate_runs` takes as floats, shape (k, 7).
SETTING_COLUMNS = SETTINGS.names[:-1]


def settings_rows(settings, timeout: float | None = None) -> np.ndarray:
    """The settings rows, shape (k, 7) of floats (:data:`SETTING_COLUMNS`), of k runs:
    ``settings`` is a sequence of objects with those attributes
    (:class:`rbstab.config.SimulationSettings`, a configuration's ``simulation``) or an
    array of :data:`SETTINGS` records. ``timeout`` [s], if given, replaces each run's
    ``max_wall_time``."""
    if isinstance(settings, np.ndarray):
        rows = np.column_stack([settings[name].astype(float) for name in SETTING_COLUMNS]).reshape(-1, 7)
    else:
        rows = np.array([[getattr(s, name) for name in SETTING_COLUMNS] for s in settings], dtype=float).reshape(-1, 7)
    if timeout is not None:
        rows[:, 6] = timeout
    return rows


def settings_records(rows: np.ndarray, method: int) -> np.ndarray:
    """:data:`SETTINGS` records, shape (k,), of ``rows`` (k, 7, :func:`settings_rows`),
    each run with ``method``."""
    records = np.empty(len(rows), dtype=SETTINGS)
    for i, name in enumerate(SETTING_COLUMNS):
        records[name] = rows[:, i]
    records["method"] = method
    return records


#: One run's work arrays for an integrated vector of n entries (the state, and with
#: disturbances their work W after it): ``K`` (STAGE_ROWS[method], n) stage rates, ``Q``
#: (INTERPOLANT_ROWS[method], n) the step's interpolant, ``y_new`` and ``work`` (n,) the new
#: vector and scratch, and ``scale`` (n_state,) the error's scale, over the state's entries
#: only (the norms of :mod:`rbstab.engine.rk` take those).
Work = namedtuple("Work", ["K", "Q", "y_new", "scale", "work"])


@jit
def work_arrays(method, n, n_state):
    """:class:`Work` for an integrated vector of size n whose first ``n_state`` entries are
    the state, and the method number ``method``."""
    return Work(np.empty((STAGE_ROWS[method], n)), np.empty((INTERPOLANT_ROWS[method], n)), np.empty(n),
                np.empty(n_state), np.empty(n))
