"""rbstab: Lyapunov stability of constrained and embedded rigid bodies.

A batch experiment runner for the paper "On the Dynamics and Lyapunov Stability of
Constrained and Embedded Rigid Bodies": YAML configuration -> integration of one of five
controller variants -> HDF5 results with Lyapunov traces, opened as xarray Datasets.

From Python (:mod:`rbstab.api`; each name is imported on first use, so ``import rbstab``
stays light)::

    config = rbstab.load_config("configs/paper/case3_embedded.yaml")   # validated RunConfig
    ds = rbstab.simulate(config)                  # xarray.Dataset, the result file's content
    path = rbstab.run(config, "results")          # results/case3_embedded.h5
    ds = rbstab.open_result(path)
    sw = rbstab.sweep_dataset("configs/sweeps/gains.yaml", grid=True)   # or rbstab.open_sweep(folder)
    rbstab.write_report([path])                   # results/reports/case3_embedded/
    a = rbstab.analyze(config)                    # stability analysis (rbstab.analysis)
    s = rbstab.sensitivity_analysis(config, ["body.mass=uniform:[30,50]"], n=256)  # rbstab.studies
    t = rbstab.tune(config, ["controller.k_c=scale_uniform:[0.25,4]"], minimize=["lyapunov_final"], trials=100)

The subpackages hold the parts: :mod:`rbstab.simulator` (one run, :class:`RunResult`),
:mod:`rbstab.sweep`, :mod:`rbstab.report`, :mod:`rbstab.analysis`, ...
"""

import importlib

__version__ = "0.1.0"

#: Public name -> the module defining it (PEP 562: imported on first use).
_SOURCES = {
    **dict.fromkeys(["load_config", "simulate", "run", "check_overwrite", "open_result", "execute_sweep",
                     "sweep_dataset", "write_report", "ResultExistsError"], "api"),
    "open_sweep": "sweep.folder",
    "analyze": "analysis",
    **dict.fromkeys(["sensitivity_analysis", "tune"], "studies"),
    **dict.fromkeys(["ConfigError", "RunConfig", "PhysicalPlausibilityWarning"], "config"),
    "WARNING_CODES": "warning_codes",
}
#: Subpackages and modules reachable as attributes (``rbstab.sweep.open_sweep``), imported on
#: first use like the names above.
_SUBMODULES = ("analysis", "config", "engine", "io", "report", "simulator", "studies", "sweep", "variants")


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__} - {"importlib"})


__all__ = [*_SOURCES, "__version__"]
