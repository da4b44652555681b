"""Stability analysis of a configuration's equilibrium (``rbstab analyze``).

- :mod:`~rbstab.analysis.derivatives`: central differences of the compiled model with
  Richardson extrapolation (Jacobians, Hessians, rates along the flow);
- :mod:`~rbstab.analysis.linearise`: equilibrium, rest check, Jacobian, eigenvalues,
  modes and verdict;
- :mod:`~rbstab.analysis.certificate`: the Lyapunov certificate and the sublevel-set
  estimate of the region of attraction (sampled, refined by local search);
- :mod:`~rbstab.analysis.evidence`: that estimate checked against simulations (runs from
  {v = c}, and every run of the command);
- :mod:`~rbstab.analysis.verify`: a verified sublevel bound (interval arithmetic, branch and
  bound; the reduced 6-state model);
- :mod:`~rbstab.analysis.basin`: the basin of attraction over a 2-D slice, by simulation;
- :mod:`~rbstab.analysis.robustness`: stable fraction and separating parameters of a sweep;
- :mod:`~rbstab.analysis.thresholds`: the rule of one or two thresholds that separates two
  outcomes along one key (basin stability's rules);
- :mod:`~rbstab.analysis.push`: the smallest fatal push of each direction and basin
  stability; :mod:`~rbstab.analysis.recovery`: both across a sweep spec's configurations;
- :mod:`~rbstab.analysis.analyze`: :func:`analyze`, which ties them together, for one body
  or a tree of bodies (as its compiled tree, in its independent coordinates);
- :mod:`~rbstab.analysis.dataset`: the analysis files (netCDF-4) and the ``--json`` record.

Method and limits: ``docs/analysis.md``.
"""

from .analyze import DEFAULT_BOUNDARY_LAYER, Analysis, NoEquilibrium, OutsideLimits, analyze
from .basin import BasinAxis, BasinMap, basin_map
from .certificate import Certificate, certify
from .dataset import is_analysis_file, read_analysis, write_analysis
from .linearise import Linearisation, linearise_chain
from .robustness import Robustness, robustness, wilson_interval
from .verify import NotVerifiable, Verification, verify_analysis, verify_sublevel

__all__ = [
    "analyze",
    "Analysis",
    "DEFAULT_BOUNDARY_LAYER",
    "OutsideLimits",
    "NoEquilibrium",
    "linearise_chain",
    "Linearisation",
    "certify",
    "Certificate",
    "basin_map",
    "BasinAxis",
    "BasinMap",
    "robustness",
    "Robustness",
    "wilson_interval",
    "write_analysis",
    "read_analysis",
    "is_analysis_file",
    "verify_sublevel",
    "verify_analysis",
    "Verification",
    "NotVerifiable",
]
