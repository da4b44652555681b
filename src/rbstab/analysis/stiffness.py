"""What the fastest mode of a configuration's linearisation asks of an explicit method (W008).

An explicit Runge-Kutta method is stable on dy/dt = s y only while h s lies in its
stability region: along the negative real axis while h |s| <= :data:`STABILITY_LIMIT`
(2.51 for RK23, 3.31 for RK45, 6.39 for DOP853: where |R(-h |s|)| = 1 for the stability
function R of scipy's tableaus). The fastest mode of the linearisation at rest
(:func:`rbstab.analysis.linearise.linearise_config`, the eigenvalue of largest |s|) so
bounds its step whatever its tolerances ask, and it takes about
``t_end |s| / STABILITY_LIMIT`` steps to t_end (:func:`explicit_steps`). Measured with
DOP853: Case 3 with L_c 1e8 N s/m, 3.9e6 estimated to t_end 2 s, 1e6 taken by t = 0.51 s;
the knee example over 0.5 s with k_c 1e10 N/m, 3.9e5 estimated, 4.2e5 taken. An implicit
method (Radau, BDF, LSODA) is held only to the accuracy its tolerances ask, which is far
fewer steps once that mode has died out; while the motion excites it, every method
follows it (the knee with k_r 1e11 N m/rad released 1.2 rad from rest: 4.4e5 steps to
0.5 s, the flexion mode, |s| 1.6e6 1/s, resolved for accuracy). A mode the motion never
excites (one out of the plane of a planar swing, which stays exactly zero) does not hold
the explicit method back: the estimate is then too high (the knee with l_r 1e4 N m s/rad:
2.4e5 estimated to 0.5 s, 2.0e4 taken).

:func:`stiffness_warning` is the one line (code W008) a run's configuration gets before
it runs where the estimate exceeds :data:`STIFF_STEPS` and the fastest mode is at least
:data:`STIFFNESS_RATIO` times faster than the slowest (else the steps are what the slow
motion over a long t_end needs, and an implicit method takes as many);
:func:`sweep_stiffness_warnings` those of a sweep's templates. The linearisation costs
4-120 ms (one body's equilibrium under gravity or a tree's rest state is most of it).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping

import numpy as np

from ..warning_codes import coded
from .linearise import linearise_config

__all__ = ["STABILITY_LIMIT", "STIFF_STEPS", "STIFFNESS_RATIO", "IMPLICIT_METHOD", "explicit_steps", "fastest_rate",
           "stiffness_warning", "sweep_stiffness_warnings"]

#: h |s| at the edge of each explicit method's stability region on the negative real axis
#: (``tests/test_stiffness.py`` checks them against the stability functions of
#: :mod:`rbstab.engine.tableaus`).
STABILITY_LIMIT = {"RK23": 2.51, "RK45": 3.31, "DOP853": 6.39}
#: Estimated explicit steps to t_end above which a stiff configuration is warned about
#: (the shipped configurations take at most ~2,500; the knee with k_r 1e11 N m/rad 4.4e6).
STIFF_STEPS = 1e5
#: Least ratio of the fastest to the slowest |s| of a stiff configuration.
STIFFNESS_RATIO = 100.0
#: The implicit method the warning names.
IMPLICIT_METHOD = "Radau"


def _linearisation(config):
    """:func:`linearise_config` of a validated configuration or of a resolved mapping, its
    warnings not shown (the configuration's own gave them); None where there is none."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            if isinstance(config, Mapping):
                from ..config.loader import config_from_mapping  # heavy: pydantic

                config = config_from_mapping(config, default_name="run")
            lin = linearise_config(config)
        except (ValueError, np.linalg.LinAlgError):  # ConfigError included: no linearisation
            return None
    return lin if lin.eigenvalues.size and np.all(np.isfinite(lin.eigenvalues)) else None


def fastest_rate(config) -> float | None:
    """|s| [1/s] of the fastest mode of the linearisation at rest of ``config`` (a validated
    one body's or tree's configuration, or its resolved mapping): the largest natural
    frequency; None where it has none (the pure sign law, no rest state, an invalid mapping)."""
    lin = _linearisation(config)
    return None if lin is None else float(lin.natural_frequency.max())


def explicit_steps(rate: float, t_end: float, method: str) -> float | None:
    """Steps the explicit ``method`` takes at least to ``t_end`` [s] where a mode of
    |s| = ``rate`` [1/s] bounds its step (module docstring); None for an implicit method."""
    limit = STABILITY_LIMIT.get(method)
    return None if limit is None else t_end * rate / limit


def stiffness_warning(config) -> str:
    """The W008 line of a validated configuration (one body's or a tree's) whose explicit
    method would take more than :data:`STIFF_STEPS` steps, held back by a stiff fastest mode
    (module docstring); ``""`` otherwise, and for an implicit method or a configuration
    without a linearisation. E.g. ``W008 simulation.method: the fastest mode at rest, |s|
    5.57e+06 1/s (time constant 1/|s| 1.8e-07 s), holds DOP853 to steps of ~1.1e-06 s:
    ~4.4e+06 steps to t_end 5 s, more than simulation.max_steps 1000000; ...``."""
    sim = config.simulation
    if sim.method not in STABILITY_LIMIT:
        return ""
    lin = _linearisation(config)
    if lin is None:
        return ""
    rates = lin.natural_frequency
    fastest = float(rates.max())
    moving = rates[rates > lin.tolerance]
    steps = explicit_steps(fastest, sim.t_end, sim.method)
    if steps <= STIFF_STEPS or not moving.size or fastest < STIFFNESS_RATIO * float(moving.min()):
        return ""
    limit = (f", more than simulation.max_steps {sim.max_steps}: it stops before t_end"
             if steps > sim.max_steps else "")
    return coded("W008", f"simulation.method: the fastest mode at rest, |s| {fastest:.3g} 1/s (time constant "
                         f"1/|s| {1.0 / fastest:.2g} s), holds {sim.method} to steps of "
                         f"~{STABILITY_LIMIT[sim.method] / fastest:.2g} s: ~{steps:.2g} steps to t_end "
                         f"{sim.t_end:g} s{limit}; an implicit method is not held to it: "
                         f"--set simulation.method={IMPLICIT_METHOD}")


def sweep_stiffness_warnings(table) -> list[str]:
    """:func:`stiffness_warning` of each template of a planned sweep
    (:class:`rbstab.sweep.table.RunTable`: checked on the template, the first run of each
    base and combination of non-numeric values), as ``"base <label>, run <id>: W008 ..."``;
    a line for each template that has one."""
    from ..config.loader import config_from_mapping  # heavy: pydantic

    lines = []
    for t, template in enumerate(table.templates):
        first = int(np.argmax(table.template == t))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the sweep gives the templates' warnings
            config = config_from_mapping({**template, "name": "template"})
        line = stiffness_warning(config)
        if line:
            lines.append(f"base {table.base_labels[first]}, run {table.run_id[first].decode()}: {line}")
    return lines
