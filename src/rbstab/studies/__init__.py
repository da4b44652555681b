"""Studies on the sweep engine: global sensitivity (SALib) and tuning (Optuna).

::

    import rbstab
    from rbstab.studies import sensitivity_analysis, tune

    config = rbstab.load_config("configs/paper/case3_embedded.yaml")
    ds = sensitivity_analysis(config, ["controller.k_c=scale_uniform:[0.5,2]", "body.mass=uniform:[30,50]"],
                              n=256, metrics=["max_abs_constraint_error", "lyapunov_final"])
    ds.ST.sel(metric="lyapunov_final")          # total Sobol' indices per factor
    result = tune(config, ["controller.k_c=scale_uniform:[0.25,4]", "controller.l_c=scale_uniform:[0.25,4]"],
                  minimize=["lyapunov_final"], subject_to=["max_abs_constraint_error_z<=0.1"], trials=100)
    result.best_values, result.best_params      # and results/studies/case3_embedded/best.yaml

A chain's configuration (:func:`rbstab.config.load_config`) is studied alike, with
a chain's keys (``bodies.1.mass``, ``joints.hip.k_r.0``, ``initial_state.trunk.theta.0``) and
every figure of its runs, per body or joint as its sweep's columns name them
(``max_abs_constraint_error_hip_z``, ``final_theta_trunk_x``), as metrics.

Modules: :mod:`~rbstab.studies.design` (``--vary`` factors, design tables, their run as a
sweep, metrics), :mod:`~rbstab.studies.sensitivity`, :mod:`~rbstab.studies.tuning` and
:mod:`~rbstab.studies.files` (the study files) and :mod:`~rbstab.studies.storage` (where a
tuning study is kept). SALib and Optuna are imported when a study
runs. Manual: docs/studies.md.
"""

import importlib

#: Public name -> the submodule defining it (imported on first use, PEP 562).
_SOURCES = {
    **dict.fromkeys(["StudyInputError", "parse_vary", "run_design", "check_metrics", "Varied"], "design"),
    **dict.fromkeys(["sensitivity_analysis", "plan_sensitivity", "analyze_results", "read_sensitivity",
                     "metric_records", "METHODS", "DEFAULT_METRICS"], "sensitivity"),
    **dict.fromkeys(["tune", "plan_tuning", "read_tuning", "TuningResult", "SAMPLERS"], "tuning"),
    **dict.fromkeys(["study_kind"], "files"),
    **dict.fromkeys(["optuna_storage"], "storage"),
}


def __getattr__(name: str):
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


__all__ = list(_SOURCES)
