"""The compiled engine: many runs, each with its own variant, parameters and settings.

:func:`integrate_runs` integrates runs with scipy's explicit Runge-Kutta pairs (RK23,
RK45, DOP853) compiled with the model (:mod:`rbstab.engine.rk`,
:mod:`rbstab.engine.integrate`): the same error norm, initial step, step-size control,
dense output and gimbal-lock event as ``solve_ivp``, so a run takes the steps
``solve_ivp`` would take and agrees with it to the tolerance's scale. A run's result does
not depend on the other runs of its call. Implicit methods (Radau, BDF, LSODA) are not
here: :func:`rbstab.simulator.simulate` runs them through ``solve_ivp`` with the same
compiled right-hand side.

:func:`batch_from_table` gives many runs (one body's or trees') as one :class:`RunBatch`
of arrays (each run's tree, parameter records, initial states, settings), the input of an
engine that depends on no configuration object; :func:`batch_of` the same batch of
validated configurations.

:data:`ENGINES` (:mod:`rbstab.engine.registry`) names the engines (``compiled``, ``scipy``,
``cuda``) with what each integrates. The names below are imported on first use, so that
the registry can be read without numba.
"""

import importlib

#: Public name -> the submodule defining it (PEP 562: imported on first use).
_SOURCES = {
    **dict.fromkeys(["RunBatch", "batch_from_table", "batch_of"], "batch"),
    **dict.fromkeys(["ChunkSolution", "integrate_runs"], "integrate"),
    "method_number": "rk",
    **dict.fromkeys(["DEFAULT_MAX_STEPS", "status_message"], "status"),
    "METHODS": "tableaus",
    **dict.fromkeys(["GROUPS", "ensure_compiled", "kernel_groups", "warm_up"], "warm"),
    **dict.fromkeys(["ENGINES", "DEFAULT_ENGINE", "Engine", "get_engine"], "registry"),
}


def __getattr__(name: str):
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


__all__ = ["METHODS", "DEFAULT_MAX_STEPS", "ChunkSolution", "method_number", "integrate_runs", "status_message",
           "warm_up", "ensure_compiled", "kernel_groups", "GROUPS", "RunBatch", "batch_from_table", "batch_of", "ENGINES",
           "DEFAULT_ENGINE",
           "Engine", "get_engine"]
