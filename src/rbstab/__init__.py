"""rbstab: Lyapunov stability of constrained and embedded rigid bodies.

A batch experiment runner for the paper "On the Dynamics and Lyapunov Stability of
Constrained and Embedded Rigid Bodies": YAML configuration -> scipy integration of one
of five controller variants -> HDF5 results with Lyapunov traces.
"""

__version__ = "0.1.0"


def __getattr__(name: str):
    # rbstab.open_sweep, imported on first use (xarray, pandas): ``import rbstab`` stays light
    if name == "open_sweep":
        from .sweep.folder import open_sweep

        return open_sweep
    if name == "analyze":  # rbstab.analyze(config): the stability analysis (rbstab.analysis)
        from .analysis import analyze

        return analyze
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["open_sweep", "analyze", "__version__"]
