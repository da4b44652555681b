"""Analysis files: the results of :func:`rbstab.analyze` and of :func:`rbstab.analysis.robustness`
as netCDF-4 (HDF5) files, their reader, and the ``--json`` record.

The conventions of the run results (:mod:`rbstab.io.hdf5`): every variable has
``long_name`` (and ``description`` where a formula helps) and every numeric one ``units``
(CF/UDUNITS spelling; text has none), 3-vectors are split by state block over the ``axis``
dimension (x, y, z), and the global attributes say what the file is and where it came from
(``rbstab_format``, ``name``, ``config``, ``config_hash`` and
:func:`rbstab.io.metadata.provenance_attributes`: ``Conventions``, ``rbstab_version``,
``git_commit``, ``git_dirty``, library versions, ``command_line``, ``created``). A variable
whose entries are in different units (``jacobian``, the Hessians, a value per parameter or
drawn key) has no ``units``: no CF units string gives them; its long name or description
says where they are. Open with ``xarray.open_dataset(path)`` (engine ``h5netcdf`` or
``netcdf4``) or :func:`read_analysis`.

Layout of ``<name>.analysis.nc`` (``kind = "configuration"``)::

    dims   state, state_wrt (the state variables, for matrices), mode (eigenvalues, real
           part descending), rate_mode, sample, axis, basin_x, basin_y
    equilibrium_<block>(axis), rest_residual_<block>(axis); a chain's (``variant`` chain):
    <block>(body, axis), NaN where a body has no such coordinate, the state named
    <body>.<block>_<i>, its coordinates those of rbstab analyze's linearisation (independent)
    jacobian(state, state_wrt), jacobian_error, eigenvalue_real(mode), eigenvalue_imag,
    natural_frequency, damping_ratio, time_constant, e_folding_time; eigenvalue_tolerance,
    rest_tolerance, slowest_time_constant, shortest_e_folding_time, time_to_converge,
    linear_settling_time (scalars)
    certificate: lyapunov_hessian, rate_hessian (state, state_wrt), rate_eigenvalue
    (rate_mode), sample_lyapunov, sample_rate, sample_rate_analytic, sample_outside (sample),
    worst_state_<block>(axis), sublevel, sublevel_sampled, boundary_level, ... (scalars),
    sublevel_history, sublevel_history_samples (sublevel_step)
    verification (--verify): sublevel_verified, sublevel_verified_boxes, sublevel_verified_seconds
    (scalars), sublevel_verified_box (axis, bound; a tree's: (hinge, bound), each joint coordinate's)
    basin: basin_outcome (flag_values 0 1 2: converged, not converged, failed),
    basin_time_to_converge, basin_lyapunov_initial, basin_lyapunov_final (basin_x, basin_y)
    push: push_direction(push_direction, axis), push_threshold, push_recovering,
    push_monotone (push_direction), push_ladder, push_ladder_recovered (push_direction,
    push_rung); push_refined_direction(push_refined, axis), push_refined_threshold;
    push_minimum, push_minimum_direction(axis)
    basin stability: stability_value(draw, stability_key), stability_recovered(draw),
    stability_low, stability_high, stability_auc, stability_recovered_side,
    stability_threshold_low, stability_threshold_high, stability_balanced_accuracy,
    stability_explains (stability_key); stability_fraction, stability_interval_low,
    stability_interval_high
    global attributes: verdict, notes, certificate_argument, sublevel_bound, push_kind,
    push_rule, stability_rule, ...

Layout of ``<sweep>.robustness.analysis.nc`` (``kind = "robustness"``): per ``group`` (base
configuration) the stable fraction and its Wilson interval; per (group, parameter) the
AUC, the best threshold, its side and balanced accuracy, the stable and unstable ranges;
per ``run`` its group, whether it was stable and its parameter values.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..config import canonical_config, config_hash
from ..convergence import SAMPLE_RULE
from ..io.atomic import atomic_path
from ..io.hdf5 import read_format
from ..io.metadata import provenance_attributes
from ..layout import BLOCK_UNITS
from .thresholds import EXPLAINS_BAR

__all__ = [
    "certificate_record",
    "settling_record",
    "time_scale_record",
    "FORMAT",
    "SUFFIX",
    "analysis_content",
    "analysis_dataset",
    "robustness_content",
    "robustness_dataset",
    "json_record",
    "write_analysis",
    "read_analysis",
    "is_analysis_file",
    "analysis_path",
]

#: Value of the ``rbstab_format`` attribute of an analysis file.
FORMAT = "rbstab-analysis-1"
#: File name suffix of analysis files (``<name>.analysis.nc``); not ``*.h5``, so that a
#: folder of run files and analyses reads as both.
SUFFIX = ".analysis.nc"


def _rate_units(units: str) -> str:
    """Units of d/dt of a quantity in ``units``: ``rad`` -> ``rad s-1``, ``m s-1`` -> ``m s-2``."""
    return units[: -len("s-1")] + "s-2" if units.endswith("s-1") else f"{units} s-1"


def _var(dims, data, units: str | None, long_name: str, description: str = "") -> tuple:
    """(dims, data, attrs) of one variable of a file: ``units`` (CF/UDUNITS) on numbers; none
    on text (CF 3.1), nor where ``units`` is None: entries in different units (a matrix over
    the state, a value per parameter), which no CF units string gives; the long name or
    description says where each entry's units are."""
    data = np.asarray(data)
    attrs = {"units": units} if units is not None and data.dtype.kind not in "OSU" else {}
    attrs["long_name"] = long_name
    if description:
        attrs["description"] = description
    return tuple(dims), data, attrs


def _blocks(prefix: str, layout, y: np.ndarray, long_name: str, rate: bool = False) -> dict:
    """``<prefix>_<block>(axis)`` variables of a state vector ``y`` in ``layout`` (a
    :class:`~rbstab.layout.StateLayout`), or ``<prefix>_<block>(body, axis)`` in a chain's
    (:class:`rbstab.analysis.linearise.TreeCoordinates`: NaN for a body without the block)."""
    out = {}
    for block, values in layout.split(np.asarray(y, dtype=float)).items():
        units = _rate_units(BLOCK_UNITS[block]) if rate else BLOCK_UNITS[block]
        dims = ("axis",) if values.ndim == 1 else ("body", "axis")
        out[f"{prefix}_{block}"] = _var(dims, values, units, f"{long_name}: {block}")
    return out


def _provenance(config, command_line: str | None) -> dict[str, Any]:
    return {
        "rbstab_format": FORMAT,
        "config": config.to_yaml(),
        "config_hash": config_hash(canonical_config(config.resolved)),
        **provenance_attributes(f"rbstab analyze {config.name}: stability analysis", command_line=command_line),
    }


def _linearisation_variables(analysis) -> dict:
    lin = analysis.linearisation
    layout = analysis.layout
    s = lin.eigenvalues
    omega_n, zeta, tau = lin.natural_frequency, lin.damping_ratio, lin.time_constant
    mixed = "entries in mixed units: (units of state) s-1 / (units of state_wrt), from state_units"
    return {
        **_blocks("equilibrium", layout, lin.equilibrium, "equilibrium state y_e"),
        **_blocks("rest_residual", layout, lin.rest_residual, "dy/dt at the equilibrium (zero at a rest point)",
                  rate=True),
        "rest_tolerance": _var((), lin.rest_tolerance, "1", "bound on |dy/dt| of the rest check (SI rates)"),
        "jacobian": _var(("state", "state_wrt"), lin.jacobian, None, "Jacobian A = d(dy/dt)/dy at the equilibrium",
                         f"central differences of the compiled right-hand side, extrapolated to step zero; {mixed}"),
        "jacobian_error": _var(("state", "state_wrt"), lin.jacobian_error, None,
                               "error estimate of each entry of the Jacobian (Richardson table)", mixed),
        "eigenvalue_real": _var(("mode",), s.real, "s-1", "real part of the eigenvalue s of A"),
        "eigenvalue_imag": _var(("mode",), s.imag, "rad s-1", "imaginary part of the eigenvalue s of A"),
        "natural_frequency": _var(("mode",), omega_n, "rad s-1", "natural frequency |s|"),
        "damping_ratio": _var(("mode",), zeta, "1", "damping ratio -Re(s)/|s|"),
        "time_constant": _var(("mode",), tau, "s", "time constant -1/Re(s) of a decaying mode",
                              "NaN unless Re(s) < -eigenvalue_tolerance"),
        "e_folding_time": _var(("mode",), lin.e_folding_time, "s", "e-folding time 1/Re(s) of a growing mode",
                               "NaN unless Re(s) > eigenvalue_tolerance"),
        "eigenvalue_tolerance": _var((), lin.tolerance, "s-1", "|Re(s)| at most this is marginal"),
        "slowest_time_constant": _var((), lin.slowest_time_constant, "s",
                                      "time constant of the eigenvalue with the largest real part",
                                      "NaN unless the verdict is asymptotically stable"),
        "shortest_e_folding_time": _var((), lin.shortest_e_folding_time, "s",
                                        "e-folding time of the eigenvalue with the largest real part "
                                        "(the fastest-growing mode)", "NaN unless the verdict is unstable"),
        "linear_settling_time": _var((), analysis.linear_settling_time, "s",
                                     "time the slowest mode alone takes to bring v down by the ratio",
                                     "tau ln(1/ratio) / 2, as v ~ exp(-2 t / tau); NaN unless the verdict is "
                                     "asymptotically stable"),
    }


def _settling_variables(analysis) -> dict:
    s = analysis.settling
    if s is None:
        return {}
    return {
        "time_to_converge": _var((), s["time_to_converge"], "s",
                                 "time to converge of the simulation from the configured initial state",
                                 f"first sample time from which {SAMPLE_RULE} (NaN: not converged)"),
        "simulation_lyapunov_initial": _var((), s["lyapunov_initial"], "J", "v(0) of the simulation"),
        "simulation_lyapunov_final": _var((), s["lyapunov_final"], "J", "v(t_end) of the simulation"),
        "convergence_ratio": _var((), s["ratio"], "1", f"converged: {SAMPLE_RULE} from then on"),
    }


def _certificate_variables(analysis) -> dict:
    c = analysis.certificate
    if c is None:
        return {}
    layout = analysis.layout
    per_unit = "per unit of state and of state_wrt (from state_units)"
    return {
        "lyapunov_equilibrium": _var((), c.lyapunov_equilibrium, "J", "v at the equilibrium"),
        "lyapunov_hessian": _var(("state", "state_wrt"), c.lyapunov_hessian, None,
                                 "Hessian of the Lyapunov function v at the equilibrium",
                                 f"entries in mixed units: J {per_unit}"),
        "hessian_min_eigenvalue": _var((), c.hessian_min_eigenvalue, None,
                                       "smallest eigenvalue of the Hessian of v (mixed units)"),
        "rate_hessian": _var(("state", "state_wrt"), c.rate_hessian, None, "Hessian of the analytic dv/dt at the "
                             "equilibrium", f"entries in mixed units: W {per_unit}"),
        "rate_eigenvalue": _var(("rate_mode",), c.rate_eigenvalues, "s-1",
                                "generalised eigenvalue mu of (Hessian of dv/dt, Hessian of v)",
                                "all mu < 0: negative definite; some mu = 0: semi-definite (LaSalle)"),
        "sample_lyapunov": _var(("sample",), c.sample_lyapunov, "J", "v at a sampled state"),
        "sample_rate": _var(("sample",), c.sample_rate, "W", "dv/dt at a sampled state, d/ds v(y + s f) at s = 0",
                            "from v alone along the right-hand side f; NaN outside the domain"),
        "sample_rate_analytic": _var(("sample",), c.sample_rate_analytic, "W", "analytic dv/dt at a sampled state"),
        "sample_outside": _var(("sample",), c.sample_outside.astype(np.int8), "1",
                               "sampled state outside the domain |theta_2| < pi/2 - gimbal_margin (1)"),
        **_blocks("worst_state", layout, c.worst_state, "sampled state with the largest relative dv/dt"),
        "worst_rate": _var((), c.worst_rate, "W", "dv/dt at the worst sampled state"),
        "worst_lyapunov": _var((), c.worst_lyapunov, "J", "v at the worst sampled state"),
        "rate_mismatch": _var((), c.rate_mismatch, "1",
                              "largest |numerical - analytic dv/dt| relative to the power scale"),
        "boundary_level": _var((), c.boundary_level, "J", "least v on the domain boundary |theta_2| = pi/2 - margin"),
        "sublevel": _var((), c.sublevel, "J", "c of the inner estimate {v <= c} of the region of attraction "
                         "(sampled, refined by local searches, checked against simulated runs)"),
        "sublevel_sampled": _var((), c.sublevel_sampled, "J", "c from the sampled states alone"),
        "sublevel_history": _var(("sublevel_step",), c.sublevel_history, "J",
                                 "c with the local search from the first N/4, N/2, N samples"),
        "sublevel_history_samples": _var(("sublevel_step",), np.asarray(c.history_samples, dtype=np.int64), "1",
                                         "samples of each step of the history"),
        "sublevel_runs_checked": _var((), int(c.runs_checked), "1", "simulated runs c was checked against"),
    }


def _verification_variables(analysis) -> dict:
    """The verified bound (``--verify``; none without it)."""
    w = getattr(analysis, "verification", None)
    if w is None:
        return {}
    return {
        "sublevel_verified": _var((), w.level, "J", "c of {v <= c} proven positively invariant and inside the region "
                                  "of attraction (interval arithmetic, branch and bound over Theta boxes)"),
        "sublevel_verified_boxes": _var((), int(w.boxes), "1", "boxes of the proof (of Theta, or of the hinges' q)"),
        "sublevel_verified_seconds": _var((), float(w.seconds), "s", "wall time of the proof"),
        "sublevel_verified_box": _var(("axis", "bound"), np.asarray(w.box, dtype=float), "rad",
                                      "the Theta box that stops c from being larger [low, high]")
        if w.coordinates == "theta" else
        _var(("hinge", "bound"), np.asarray(w.box, dtype=float), None if any(_slid(analysis, w)) else "rad",
             "the box of the joints' coordinates (in the joints' order: a hinge's angle [rad], a slide's "
             "displacement [m], a universal joint's two angles, a ball's rotation vector of its turn) that stops c "
             "from being larger [low, high]"),
    }


def _slid(analysis, w) -> list[bool]:
    """Whether each coordinate of a tree's verified box (``w.names``) is a slide's [m]."""
    kinds = {j.name: j.variant for j in analysis.analysed.chain.joints}
    return [kinds.get(name) == "slide" for name in w.names]


def _basin_variables(analysis) -> tuple[dict, dict]:
    b = analysis.basin
    if b is None:
        return {}, {}
    dims = ("basin_x", "basin_y")
    coords = {}
    for dim, axis in zip(dims, b.axes):
        coords[dim] = _var((dim,), axis.values, axis.units, f"initial {axis.block}_{axis.index + 1}")
        coords[dim][2]["config_key"] = axis.key
    outcome = _var(dims, b.outcome.astype(np.int8), "1", "outcome of the run from this initial state")
    outcome[2].update(flag_values=np.array([0, 1, 2], dtype=np.int8), flag_meanings="converged not_converged failed")
    return {
        "basin_outcome": outcome,
        "basin_time_to_converge": _var(dims, b.time_to_converge, "s", f"time to converge ({SAMPLE_RULE} "
                                       "from then on)"),
        "basin_lyapunov_initial": _var(dims, b.lyapunov_initial, "J", "v at the initial state"),
        "basin_lyapunov_final": _var(dims, b.lyapunov_final, "J", "v at t_end"),
    }, coords


def _push_variables(analysis) -> tuple[dict, dict, dict]:
    """(variables, coordinates, attributes) of the push analysis (none without one)."""
    p = analysis.push
    if p is None:
        return {}, {}, {}
    u, th = p.units, p.thresholds
    frame = "inertial frame" if p.kind == "force" else "body frame"
    variables = {
        "push_direction": _var(("push_direction", "axis"), p.directions, "1", f"unit direction of the push ({frame})"),
        "push_threshold": _var(("push_direction",), th.threshold, u, "smallest fatal push magnitude",
                               "the first fatal magnitude from below; inf: every rung recovered"),
        "push_recovering": _var(("push_direction",), th.recovering, u, "largest recovering magnitude below it"),
        "push_monotone": _var(("push_direction",), th.monotone.astype(np.int8), "1",
                              "recovery monotone in the magnitude along the ladder (1) or not (0)"),
        "push_ladder": _var(("push_direction", "push_rung"), th.ladder, u, "magnitudes of the ladder"),
        "push_ladder_recovered": _var(("push_direction", "push_rung"), th.ladder_recovered.astype(np.int8), "1",
                                      "the rung's push recovered (1) or was fatal (0)"),
        "push_refined_direction": _var(("push_refined", "axis"), p.refined_directions.reshape(-1, 3), "1",
                                       "directions of the local search around the weakest"),
        "push_refined_threshold": _var(("push_refined",), p.refined_thresholds, u,
                                       "smallest fatal push magnitude of the local search's directions"),
        "push_minimum": _var((), p.minimum, u, "smallest fatal push magnitude found"),
        "push_minimum_direction": _var(("axis",), p.minimum_direction, "1", "its direction"),
        "push_point": _var(("axis",), p.point, "m", "point of the force push, body frame, from the centre of mass"),
        "push_unit_energy": _var(("push_direction",), p.unit_energy, "J", "kinetic energy dT of a push of magnitude "
                                 "1 along the direction (dT grows with the magnitude's square)"),
    }
    c = analysis.certificate
    if c is not None and c.positive_definite:
        variables["push_estimate"] = _var((), p.estimate(c.sublevel), u, "smallest push the sublevel estimate "
                                          "{v <= c} holds: min over the directions of sqrt(c / dT(u)) (an estimate, "
                                          "checked against every push run)")
    attrs = {"push_kind": p.kind, "push_at": p.at, "push_tol": p.tol, "push_rungs": p.rungs, "push_ratio": p.ratio,
             "push_rule": p.rule_text, "push_engine": p.engine, "push_runs": p.runs,
             **({"push_body": p.body} if p.body is not None else {})}
    return variables, {}, attrs


def _stability_variables(analysis) -> tuple[dict, dict, dict]:
    """(variables, coordinates, attributes) of the basin stability (none without it)."""
    b = analysis.basin_stability
    if b is None:
        return {}, {}, {}
    n = len(b.keys)
    auc, low, high, accuracy = (np.full(n, np.nan) for _ in range(4))
    side, explains = np.full(n, "", dtype=object), np.zeros(n, dtype=np.int8)
    for s in b.separations:
        i = b.keys.index(s.parameter)
        auc[i], low[i], high[i], accuracy[i] = s.auc, s.rule.low, s.rule.high, s.rule.balanced_accuracy
        side[i], explains[i] = s.rule.side, s.rule.explains
    coords = {"stability_key": _var(("stability_key",), np.array(b.keys, dtype=object), "1", "what was drawn")}
    variables = {
        "stability_units": _var(("stability_key",), np.array(b.units, dtype=object), "1", "units of each key"),
        "stability_value": _var(("draw", "stability_key"), b.values, None,
                                "the draws (units per key: stability_units)"),
        "stability_recovered": _var(("draw",), b.recovered.astype(np.int8), "1", "the draw recovered (1) or not (0)"),
        "stability_lyapunov_start": _var(("draw",), b.lyapunov_start, "J", "v where the draw starts (of the drawn "
                                         "state, or just after the drawn push)"),
        "stability_low": _var(("stability_key",), b.low, None, "low end of the uniform box (units per key: "
                              "stability_units)"),
        "stability_high": _var(("stability_key",), b.high, None, "high end of the uniform box (units per key: "
                               "stability_units)"),
        "stability_auc": _var(("stability_key",), auc, "1", "P(recovered value > failed value) (ties half)",
                              "a one-sided measure: about 0.5 also where the recovered draws lie inside or "
                              "outside an interval (stability_recovered_side)"),
        "stability_recovered_side": _var(("stability_key",), side, "1", "where the key's rule puts the recovered "
                                         "draws: below, above, inside or outside its thresholds",
                                         "below: x < threshold_high; above: x > threshold_low; inside: threshold_low "
                                         "< x < threshold_high; outside: x < threshold_low or x > threshold_high; "
                                         "empty where the key's draws all recovered or all failed"),
        "stability_threshold_low": _var(("stability_key",), low, None, "lower threshold of the key's rule (units per "
                                        "key: stability_units; NaN where the rule has none)"),
        "stability_threshold_high": _var(("stability_key",), high, None, "upper threshold of the key's rule (units "
                                         "per key: stability_units; NaN where the rule has none)"),
        "stability_balanced_accuracy": _var(("stability_key",), accuracy, "1", "balanced accuracy of the key's rule",
                                            "mean of the fractions of the recovered and of the failed draws the rule "
                                            "puts on their side: 0.5 chance, 1 complete"),
        "stability_explains": _var(("stability_key",), explains, "1", "the key's rule explains the outcome (1) or "
                                   f"not (0): balanced accuracy >= {EXPLAINS_BAR}"),
        "stability_fraction": _var((), b.fraction, "1", "basin stability: recovered draws / draws"),
        "stability_interval_low": _var((), b.interval[0], "1", f"{b.confidence:.0%} Wilson interval, low end"),
        "stability_interval_high": _var((), b.interval[1], "1", f"{b.confidence:.0%} Wilson interval, high end"),
    }
    attrs = {"stability_perturbation": b.perturbation, "stability_rule": b.rule, "stability_seed": b.seed,
             "stability_confidence": b.confidence, "stability_engine": b.engine, "stability_explains_bar": EXPLAINS_BAR}
    if b.kind:
        attrs["stability_push_kind"] = b.kind
    return variables, coords, attrs


def _text_attributes(analysis) -> dict[str, Any]:
    lin, c, s, b = analysis.linearisation, analysis.certificate, analysis.settling, analysis.basin
    attrs: dict[str, Any] = {
        "kind": "configuration",
        "name": analysis.name,
        "variant": analysis.variant,
        "verdict": lin.verdict,
        "rest_point": int(lin.is_rest_point),
        "notes": "\n".join(analysis.notes),
    }
    if analysis.analysed is not analysis.config:
        attrs["analysed_boundary_layer"] = float(analysis.analysed.chain.joints[0].boundary_layer)
    if c is not None:
        attrs.update(certificate_holds=int(c.holds), certificate_argument=c.argument,
                     rate_definiteness=c.rate_definiteness, positive_definite=int(c.positive_definite),
                     lasalle_observable=int(c.lasalle_observable), sublevel_bound=c.sublevel_bound,
                     n_samples=int(c.n_samples), sublevel_estimate=c.evidence, sublevel_settled=int(c.settled),
                     sublevel_notes="\n".join(c.notes))
    w = getattr(analysis, "verification", None)
    if w is not None:
        attrs.update(sublevel_verified_method=w.method, sublevel_verified_reason=w.reason)
    if s is not None:
        attrs.update(simulation_status=s["status"], simulation_message=s["message"], t_end=s["t_end"])
    if b is not None:
        attrs.update(basin_ratio=b.ratio, basin_t_end=b.t_end,
                     basin_failures="\n".join(f"{n}: {m}" for m, n in b.messages.items()))
    return attrs


def analysis_content(analysis, command_line: str | None = None) -> tuple[dict, dict, dict]:
    """(coordinates, variables, global attributes) of an :class:`rbstab.analysis.Analysis`'s
    file (module docstring); each variable a (dims, data, attrs) triple."""
    layout = analysis.layout
    names = layout.state_names()
    units = layout.state_units()
    basin, basin_coords = _basin_variables(analysis)
    push, push_coords, push_attrs = _push_variables(analysis)
    stability, stability_coords, stability_attrs = _stability_variables(analysis)
    data = {**_linearisation_variables(analysis), **_settling_variables(analysis),
            **_certificate_variables(analysis), **_verification_variables(analysis), **basin, **push, **stability}
    coords = {
        "state": _var(("state",), np.array(names, dtype=object), "1", "state variable"),
        "state_wrt": _var(("state_wrt",), np.array(names, dtype=object), "1", "state variable (derivative with "
                          "respect to)"),
        "state_units": _var(("state",), np.array(units, dtype=object), "1", "units of each state variable"),
        "mode": _var(("mode",), np.arange(len(names)), "1", "eigenvalue index, real part descending"),
        "axis": _var(("axis",), np.array(["x", "y", "z"], dtype=object), "1", "vector component"),
        **({"body": _var(("body",), np.array(layout.bodies, dtype=object), "1", "body of the chain")}
           if hasattr(layout, "bodies") else {}),
        **({"bound": _var(("bound",), np.array(["low", "high"], dtype=object), "1", "end of an interval")}
           if getattr(analysis, "verification", None) is not None else {}),
        **({"hinge": _var(("hinge",), np.array(analysis.verification.names, dtype=object), "1",
                          "the joint coordinate a row of the verified box bounds: a hinge's or a slide's joint, a "
                          "universal joint's <joint>.q_1, .q_2, a ball's <joint>.phi_1 .. .phi_3")}
           if getattr(getattr(analysis, "verification", None), "coordinates", "theta") == "q" else {}),
        **basin_coords,
        **push_coords,
        **stability_coords,
    }
    attrs = {**_provenance(analysis.analysed, command_line), **_text_attributes(analysis), **push_attrs,
             **stability_attrs}
    if analysis.analysed is not analysis.config:
        attrs["config_as_given"] = analysis.config.to_yaml()
    return coords, data, attrs


def analysis_dataset(analysis, command_line: str | None = None):
    """The :class:`xarray.Dataset` of an :class:`rbstab.analysis.Analysis` (what its file holds)."""
    return _to_xarray(*analysis_content(analysis, command_line))


def robustness_content(result, command_line: str | None = None) -> tuple[dict, dict, dict]:
    """(coordinates, variables, global attributes) of a
    :class:`rbstab.analysis.robustness.Robustness`'s file."""
    groups = result.groups
    parameters = list(dict.fromkeys(p for g in groups for p in g.parameters)) or list(result.runs["values"])
    shape = (len(groups), len(parameters))
    table = {k: np.full(shape, np.nan) for k in ("auc", "threshold", "balanced_accuracy", "stable_min",
                                                  "stable_max", "unstable_min", "unstable_max")}
    side = np.full(shape, "", dtype=object)
    rule = {k: np.full(shape, np.nan) for k in ("rule_low", "rule_high", "rule_balanced_accuracy")}
    rule_side = np.full(shape, "", dtype=object)
    explains = np.zeros(shape, dtype=bool)
    for i, g in enumerate(groups):
        for s in g.separations:
            j = parameters.index(s.parameter)
            values = (s.auc, s.threshold, s.balanced_accuracy, *s.stable_range, *s.unstable_range)
            for key, value in zip(table, values):
                table[key][i, j] = value
            side[i, j] = s.stable_side
            rule["rule_low"][i, j], rule["rule_high"][i, j] = s.rule.low, s.rule.high
            rule["rule_balanced_accuracy"][i, j] = s.rule.balanced_accuracy
            rule_side[i, j], explains[i, j] = s.rule.side, s.rule.explains
    gp = ("group", "parameter")
    data = {
        "n_runs": _var(("group",), [g.n_runs for g in groups], "1", "runs with a result"),
        "n_stable": _var(("group",), [g.n_stable for g in groups], "1", "runs that converged"),
        "n_excluded": _var(("group",), [g.n_excluded for g in groups], "1", "runs without a result"),
        "n_unstable_rest": _var(("group",), [g.n_unstable_rest for g in groups], "1",
                                "runs that converged beside an unstable rest state (counted as not stable)"),
        "n_disagree": _var(("group",), [g.n_disagree for g in groups], "1",
                           "runs whose stability differs from the sweep's converged (v(t_end) < 0)"),
        "stable_fraction": _var(("group",), [g.fraction for g in groups], "1", "stable fraction"),
        "stable_fraction_low": _var(("group",), [g.interval[0] for g in groups], "1", "Wilson interval, lower"),
        "stable_fraction_high": _var(("group",), [g.interval[1] for g in groups], "1", "Wilson interval, upper"),
        "auc": _var(gp, table["auc"], "1", "P(value of a stable run > value of an unstable run)"),
        "threshold": _var(gp, table["threshold"], None, "best single threshold (units of the parameter)"),
        "stable_side": _var(gp, side, "1", "side of the threshold where the stable runs lie"),
        "balanced_accuracy": _var(gp, table["balanced_accuracy"], "1", "balanced accuracy of the threshold"),
        "rule_side": _var(gp, rule_side, "1", "where the stable runs lie in the best rule of one or two "
                          "thresholds: below, above, inside, outside"),
        "rule_low": _var(gp, rule["rule_low"], None, "the rule's lower threshold (units of the parameter; NaN: "
                         "none)"),
        "rule_high": _var(gp, rule["rule_high"], None, "the rule's upper threshold (units of the parameter; NaN: "
                          "none)"),
        "rule_balanced_accuracy": _var(gp, rule["rule_balanced_accuracy"], "1", "balanced accuracy of the rule"),
        "rule_explains": _var(gp, explains, "1", f"the rule's balanced accuracy reaches {EXPLAINS_BAR:g}: it "
                              "explains which runs converged"),
        **{k: _var(gp, table[k], None, k.replace("_", " ") + " value (units of the parameter)")
           for k in ("stable_min", "stable_max", "unstable_min", "unstable_max")},
        "run_group": _var(("run",), np.asarray(result.runs["base"], dtype=object), "1", "group of the run"),
        "run_stable": _var(("run",), np.asarray(result.runs["stable"], dtype=np.int8), "1", "run converged (1)"),
        "run_value": _var(("run", "parameter"), np.stack([result.runs["values"][p] for p in parameters], axis=1)
                          if parameters else np.zeros((len(result.runs["base"]), 0)), None,
                          "parameter value of the run (units of the parameter)"),
    }
    coords = {"group": _var(("group",), np.array([g.base for g in groups], dtype=object), "1", "base configuration"),
              "parameter": _var(("parameter",), np.array(parameters, dtype=object), "1", "swept parameter")}

    attrs = dict(
        rbstab_format=FORMAT, kind="robustness", name=f"{result.sweep}.robustness", sweep=result.sweep,
        folder=result.folder, confidence=result.confidence, lyapunov_ratio=result.ratio,
        stability="status success and |v(t_end)| <= lyapunov_ratio v_ref (rbstab.convergence) in the sweep's simulation, and the rest "
                  "state where v is zero is not linearly unstable (an unstable rest: not stable)",
        **provenance_attributes(f"rbstab analyze --robustness {result.sweep}", command_line=command_line),
    )
    return coords, data, attrs


def robustness_dataset(result, command_line: str | None = None):
    """The :class:`xarray.Dataset` of a :class:`rbstab.analysis.robustness.Robustness`."""
    return _to_xarray(*robustness_content(result, command_line))


def _to_xarray(coords: dict, variables: dict, attrs: dict):
    import xarray as xr  # heavy: xarray

    return xr.Dataset({k: xr.Variable(*v) for k, v in variables.items()},
                      coords={k: xr.Variable(*v) for k, v in coords.items()}, attrs=attrs)


def _write_netcdf(path: Path, coords: dict, variables: dict, attrs: dict) -> None:
    """A netCDF-4 file through h5netcdf (without xarray, whose import costs ~0.4 s)."""
    import h5netcdf  # heavy: h5netcdf
    import h5py  # heavy: h5py

    text = h5py.string_dtype()
    with h5netcdf.File(path, "w") as f:
        for name, (dims, data, _) in {**coords, **variables}.items():
            for dim, size in zip(dims, data.shape):
                if dim not in f.dimensions:
                    f.dimensions[dim] = size
        # coordinates first: a variable created later attaches to them once
        for name, (dims, data, var_attrs) in {**coords, **variables}.items():
            if data.dtype == object or data.dtype.kind == "U":
                var = f.create_variable(name, dims, data=data.astype(object), dtype=text)
            elif data.dtype == bool:
                var = f.create_variable(name, dims, data=data.astype(np.int8))
            else:
                var = f.create_variable(name, dims, data=data)
            var.attrs.update(var_attrs)
        f.attrs.update(attrs)


def analysis_path(folder: str | os.PathLike, name: str) -> Path:
    """``<folder>/<name>.analysis.nc``."""
    return Path(folder) / f"{name}{SUFFIX}"


def write_analysis(result, path: str | os.PathLike, *, command_line: str | None = None) -> Path:
    """Write an Analysis or a Robustness to ``path`` atomically (temporary file + rename):
    the content its ``file_content`` gives (:func:`analysis_content`, :func:`robustness_content`).

    Raises
    ------
    OSError
        If the folder cannot be created or written; ``path`` is then untouched.
    """
    content = result.file_content(command_line)
    with atomic_path(path) as tmp:
        _write_netcdf(tmp, *content)
    return Path(path)


def is_analysis_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a file written by :func:`write_analysis`."""
    try:
        return read_format(path) == FORMAT
    except (OSError, ValueError):
        return False


def read_analysis(path: str | os.PathLike):
    """An analysis file as an :class:`xarray.Dataset` (loaded into memory).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is not an analysis file.
    """
    import xarray as xr  # heavy: xarray

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such analysis file: {path}")
    if not is_analysis_file(path):
        raise ValueError(f"{path}: not an rbstab analysis file (no rbstab_format = {FORMAT!r} attribute)")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()


def _finite(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _floats(values) -> list:
    return [_finite(v) for v in np.asarray(values, dtype=float).ravel()]


def certificate_record(c) -> dict:
    """A :class:`rbstab.analysis.certificate.Certificate` as plain Python (the ``--json``
    record's ``certificate``; non-finite numbers are null)."""
    return {
        "holds": c.holds, "argument": c.argument, "lyapunov_equilibrium": c.lyapunov_equilibrium,
        "positive_definite": c.positive_definite, "hessian_min_eigenvalue": c.hessian_min_eigenvalue,
        "rate_definiteness": c.rate_definiteness, "lasalle_observable": c.lasalle_observable,
        "n_samples": c.n_samples, "worst_rate": _finite(c.worst_rate), "worst_lyapunov": _finite(c.worst_lyapunov),
        "worst_state": _floats(c.worst_state), "rate_mismatch": _finite(c.rate_mismatch),
        "boundary_level": _finite(c.boundary_level), "sublevel": c.sublevel, "sublevel_bound": c.sublevel_bound,
        "sublevel_estimate": c.evidence, "sublevel_sampled": _finite(c.sublevel_sampled),
        "sublevel_history": _floats(c.sublevel_history),
        "sublevel_history_samples": [int(n) for n in c.history_samples], "sublevel_settled": c.settled,
        "runs_checked": c.runs_checked, "sublevel_notes": list(c.notes),
    }


def time_scale_record(lin) -> dict[str, float | None]:
    """The time scale of a :class:`rbstab.analysis.linearise.Linearisation` as plain
    Python (the ``--json`` records of one body and of a chain): ``slowest_time_constant``
    [s] (null unless asymptotically stable), ``shortest_e_folding_time`` [s] (null unless
    unstable); both null when marginal."""
    return {"slowest_time_constant": _finite(lin.slowest_time_constant),
            "shortest_e_folding_time": _finite(lin.shortest_e_folding_time)}


def settling_record(settling: dict) -> dict[str, Any]:
    """The ``--json`` record of an analysis's simulation from the configured initial state
    (:attr:`rbstab.analysis.Analysis.settling`): ``status``, ``time_to_converge`` [s] (null:
    not converged), ``ratio``, ``t_end`` [s]."""
    return {"status": settling["status"], "time_to_converge": _finite(settling["time_to_converge"]),
            "ratio": settling["ratio"], "t_end": settling["t_end"]}


def json_record(analysis) -> dict[str, Any]:
    """The ``--json`` record of an analysis: plain JSON (non-finite numbers are null)."""
    lin = analysis.linearisation
    record: dict[str, Any] = {
        "name": analysis.name,
        "variant": analysis.variant,
        "verdict": lin.verdict,
        "state": analysis.state_names,
        "equilibrium": _floats(lin.equilibrium),
        "eigenvalues": [[float(s.real), float(s.imag)] for s in lin.eigenvalues],
        "tolerance": lin.tolerance,
        "rest_point": lin.is_rest_point,
        "rest_residual": float(np.abs(lin.rest_residual).max()),
        "natural_frequency": _floats(lin.natural_frequency),
        "damping_ratio": _floats(lin.damping_ratio),
        "time_constant": _floats(lin.time_constant),
        "e_folding_time": _floats(lin.e_folding_time),
        **time_scale_record(lin),
        "linear_settling_time": _finite(analysis.linear_settling_time),
        "notes": list(analysis.notes),
    }
    if analysis.analysed is not analysis.config:
        record["analysed_boundary_layer"] = float(analysis.analysed.chain.joints[0].boundary_layer)
    if analysis.settling is not None:
        record["simulation"] = settling_record(analysis.settling)
    c = analysis.certificate
    if c is not None:
        record["certificate"] = certificate_record(c)
    w = getattr(analysis, "verification", None)
    if w is not None:
        record["verification"] = {"sublevel": w.level, "method": w.method, "boxes": w.boxes, "seconds": w.seconds,
                                  "reason": w.reason, "box": [_floats(row) for row in w.box]}
    if analysis.basin is not None:
        b = analysis.basin
        record["basin"] = {"axes": [a.key for a in b.axes], "shape": list(b.outcome.shape), "counts": b.counts(),
                           "inside_estimate": analysis.basin_inside(), "ratio": b.ratio}
    if analysis.push is not None:
        record["push"] = analysis.push.to_json()
        if c is not None and c.positive_definite:
            record["push"]["estimate"] = _finite(analysis.push.estimate(c.sublevel))
    if analysis.basin_stability is not None:
        record["basin_stability"] = analysis.basin_stability.to_json()
    return record
