"""Parameter sweeps: grids, zipped lists and seeded random samples of run configurations,
executed in parallel on this machine or on a Dask cluster, resumable.

Library entry points (the ``rbstab sweep`` command is a thin layer over them)::

    from rbstab.sweep import load_spec, plan_table, run_sweep

    spec = load_spec("configs/sweeps/gains.yaml", overrides=["simulation.t_end=1"])
    table = plan_table(spec)                   # every run validated; SweepSpecError if not
    outcome = run_sweep(spec, "results/sweeps", table=table, jobs=4)
    # -> results/sweeps/<name>/{sweep.yaml, runs/chunk-*.h5, index.csv, sweep_summary.json}
    ds = open_sweep("results/sweeps/gains_case3", grid=True)   # xarray, variant x k_c_0

Modules: :mod:`~rbstab.sweep.schema` (the spec's pydantic schema), :mod:`~rbstab.sweep.spec`
(spec loading, the frozen spec), :mod:`~rbstab.sweep.table` (the run table: planning,
run ids), :mod:`~rbstab.sweep.validate` (validation of its columns), :mod:`~rbstab.sweep.plan`
(the runs one by one, for small sweeps),
:mod:`~rbstab.sweep.worker` (the unit of work: a chunk of runs -> records),
:mod:`~rbstab.sweep.executors` (local process pool, Dask), :mod:`~rbstab.sweep.runner`
(resume, execution) and :mod:`~rbstab.sweep.folder` (the folder's format: file names,
parameter names, ``index.csv``, ``sweep_summary.json``, the convergence definition, and
the reader :func:`open_sweep`).
"""

import importlib

#: Public name -> the submodule defining it. Imported on first use (PEP 562), so that
#: ``rbstab sweep`` can start its worker processes (:mod:`.executors`) before it imports
#: the rest (pydantic, the config schema): they import numpy and scipy meanwhile.
_SOURCES = {
    **dict.fromkeys(["EXECUTORS", "DaskExecutor", "Executor", "ExecutorError", "LocalExecutor", "default_jobs",
                     "make_executor"], "executors"),
    **dict.fromkeys(["STATUSES", "INDEX_FILE", "RUNS_DIR", "SPEC_FILE", "SUMMARY_FILE", "LAYOUTS",
                     "open_sweep", "parameter_name", "read_index", "resolved_config"], "folder"),
    **dict.fromkeys(["DEFAULT_OUTPUT", "SweepBusyError", "SweepOutcome", "rebuild_index", "run_sweep"], "runner"),
    **dict.fromkeys(["DEFAULT_LYAPUNOV_RATIO", "DISTRIBUTIONS", "SweepSpec", "SweepSpecError", "load_spec",
                     "spec_from_mapping"], "spec"),
    **dict.fromkeys(["PlannedRun", "expand"], "plan"),
    **dict.fromkeys(["RunTable", "plan_table"], "table"),
    **dict.fromkeys(["RunTask", "WorkerOptions", "run_chunk"], "worker"),
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


__all__ = [
    "load_spec",
    "spec_from_mapping",
    "open_sweep",
    "read_index",
    "parameter_name",
    "expand",
    "plan_table",
    "RunTable",
    "resolved_config",
    "run_sweep",
    "rebuild_index",
    "SweepSpec",
    "PlannedRun",
    "SweepOutcome",
    "SweepSpecError",
    "SweepBusyError",
    "ExecutorError",
    "Executor",
    "LocalExecutor",
    "DaskExecutor",
    "make_executor",
    "default_jobs",
    "run_chunk",
    "RunTask",
    "WorkerOptions",
    "EXECUTORS",
    "STATUSES",
    "DISTRIBUTIONS",
    "DEFAULT_LYAPUNOV_RATIO",
    "DEFAULT_OUTPUT",
    "SPEC_FILE",
    "INDEX_FILE",
    "SUMMARY_FILE",
    "RUNS_DIR",
    "LAYOUTS",
]
