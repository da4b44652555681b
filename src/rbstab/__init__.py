"""rbstab: Lyapunov stability of constrained and embedded rigid bodies.

A batch experiment runner for the paper "On the Dynamics and Lyapunov Stability of
Constrained and Embedded Rigid Bodies": YAML configuration -> scipy integration of one
of five controller variants -> HDF5 results with Lyapunov traces.
"""

__version__ = "0.1.0"
