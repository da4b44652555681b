"""Reports: tables and figures comparing runs and sweeps (``rbstab report``).

- :mod:`~rbstab.report.load`: read and validate inputs (run files, sweep folders);
- :mod:`~rbstab.report.tables`: one row per run, metrics, settling time;
- :mod:`~rbstab.report.paper`: the paper's printed results and the comparison;
- :mod:`~rbstab.report.figures`: matplotlib figures (Agg canvas);
- :mod:`~rbstab.report.animate`: the 3D animation of a run (``rbstab animate``, the page's
  animations);
- :mod:`~rbstab.report.render`: the page as HTML and markdown;
- :mod:`~rbstab.report.workers`: the figures and animations drawn in worker processes
  (``rbstab report -j N``);
- :mod:`~rbstab.report.build`: :func:`build_report`, which ties them together.

Importing this package is cheap: matplotlib, pandas, h5py and xarray are imported inside
the functions that need them.
"""

from .build import ReportError, ReportOptions, build_report, default_report_name
from .load import ReportInputError, load_inputs
from .tables import DEFAULT_METRICS, DEFAULT_SETTLE_E, DEFAULT_SETTLE_OMEGA, SettleThresholds, allowed_metrics

__all__ = [
    "build_report",
    "ReportOptions",
    "ReportError",
    "ReportInputError",
    "SettleThresholds",
    "load_inputs",
    "default_report_name",
    "allowed_metrics",
    "DEFAULT_METRICS",
    "DEFAULT_SETTLE_E",
    "DEFAULT_SETTLE_OMEGA",
]
