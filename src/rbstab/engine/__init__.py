"""The compiled engine: many runs, each with its own variant, parameters and settings.

:func:`integrate_runs` integrates runs with scipy's explicit Runge-Kutta pairs (RK23,
RK45, DOP853) compiled with the model (:mod:`rbstab.engine.rk`,
:mod:`rbstab.engine.integrate`): the same error norm, initial step, step-size control,
dense output and gimbal-lock event as ``solve_ivp``, so a run takes the steps
``solve_ivp`` would take and agrees with it to the tolerance's scale. A run's result does
not depend on the other runs of its call. Implicit methods (Radau, BDF, LSODA) are not
here: :func:`rbstab.simulator.simulate` runs them through ``solve_ivp`` with the same
compiled right-hand side.

:func:`batch_from_table` gives many runs as one :class:`RunBatch` of arrays (parameter
records, initial states, variant codes, settings), the input of an engine that depends on
no configuration object.
"""

from __future__ import annotations

from .batch import RunBatch, batch_from_table
from .integrate import ChunkSolution, integrate_runs
from .rk import method_number
from .status import DEFAULT_MAX_STEPS, status_message
from .tableaus import METHODS
from .warm import GROUPS, ensure_compiled, warm_up

__all__ = ["METHODS", "DEFAULT_MAX_STEPS", "ChunkSolution", "method_number", "integrate_runs", "status_message",
           "warm_up", "ensure_compiled", "GROUPS", "RunBatch", "batch_from_table"]
