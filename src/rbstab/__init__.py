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
    sw = rbstab.sweep("configs/sweeps/gains.yaml", grid=True)   # or rbstab.open_sweep(folder)
    rbstab.report([path])                         # results/reports/case3_embedded/
    a = rbstab.analyze(config)                    # stability analysis (rbstab.analysis)

``simulate``, ``sweep`` and ``report`` are also the names of subpackages
(:mod:`rbstab.simulate`, :mod:`rbstab.sweep`, :mod:`rbstab.report`): ``rbstab.simulate``
is that module, made callable, and calling it calls :func:`rbstab.api.simulate` (likewise
the others), so ``rbstab.simulate(config)`` and ``from rbstab.simulate import solve``
both work.
"""

import importlib
import inspect
import sys
import types

__version__ = "0.1.0"

#: Public name -> the module defining it (PEP 562: imported on first use).
_SOURCES = {
    **dict.fromkeys(["load_config", "run", "check_overwrite", "open_result", "execute_sweep", "ResultExistsError"],
                    "api"),
    "open_sweep": "sweep.folder",
    "analyze": "analysis",
    **dict.fromkeys(["ConfigError", "RunConfig", "PhysicalPlausibilityWarning"], "config"),
    "WARNING_CODES": "warning_codes",
}
#: Submodules that are also functions of :mod:`rbstab.api`: calling the module calls the function.
_CALLABLE_MODULES = ("simulate", "sweep", "report")


def _callable_module_type(name: str) -> type:
    """A module type whose instances call ``rbstab.api.<name>`` (signature and all)."""
    function = getattr(importlib.import_module(".api", __name__), name)

    def signature(self):
        return inspect.signature(function)

    return type(f"callable_module_{name}", (types.ModuleType,),
                {"__call__": staticmethod(function), "__signature__": property(signature)})


class _Package(types.ModuleType):
    """rbstab itself: a submodule of :data:`_CALLABLE_MODULES` is made callable as the import
    system sets it on the package (however it was first imported)."""

    def __setattr__(self, name: str, value) -> None:
        if name in _CALLABLE_MODULES and isinstance(value, types.ModuleType) \
                and value.__name__ == f"{__name__}.{name}" and not callable(value):
            value.__class__ = _callable_module_type(name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def __getattr__(name: str):
    if name in _CALLABLE_MODULES:
        return importlib.import_module(f".{name}", __name__)
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__} - {"importlib", "sys", "types"})


__all__ = [*_SOURCES, *_CALLABLE_MODULES, "__version__"]
