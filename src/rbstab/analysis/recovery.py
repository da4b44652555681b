"""Push recovery and basin stability across parameters: the questions of
:mod:`rbstab.analysis.push` at every configuration of a sweep spec (``rbstab analyze
SPEC.yaml --push ...``), with the Lyapunov certificate's inner estimate beside them.

At each configuration (a run of the spec's table: grid, zip, random or table), as asked:

- the smallest fatal push over the directions (:func:`~rbstab.analysis.push.push_analysis`),
  and the *estimate* from the sublevel set {v <= c} (:mod:`rbstab.analysis.certificate`,
  checked against every run of the point, :mod:`rbstab.analysis.evidence`): it holds every
  push whose energy dT = v just after it is at most c, so along u the pushes up to
  sqrt(c / dT(u)) recover by the estimate (``push_estimate``: its minimum over the
  directions; below every simulated threshold, since each fatal push lowers c below its dT);
- the basin stability (:func:`~rbstab.analysis.push.basin_stability`), and among the draws
  inside {v <= c} (v of the drawn state, or dT of the drawn push) the fraction that
  recovered: 1 where the certificate's estimate is right.

A folder ``<output>/<spec name>.recovery/`` keeps one JSON record a configuration
(``points/<run_id>.json``, written when it is done): a command stopped and started again
computes only the configurations without one, and refuses records made with other options
(``--overwrite`` replaces them). The curves over the configurations go to
``<output>/<spec name>.recovery.analysis.nc`` (``kind = "recovery"``): a ``point``
dimension, the varied keys as its coordinates.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time as _time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..convergence import DEFAULT_LYAPUNOV_RATIO
from ..layout import parameter_attributes, slide_parts

__all__ = ["Recovery", "recovery_across", "recovery_content", "RECOVERY_SUFFIX"]

#: Suffix of the folder of records and of the curves file.
RECOVERY_SUFFIX = ".recovery"
#: How each configuration's sublevel estimate is made (in the records' options: records of
#: an older method are not read back).
ESTIMATE_METHOD = "sampled, refined by local search, falsified and checked against the runs"


@dataclass
class Recovery:
    """The records of every configuration of a spec (:func:`recovery_across`).

    Attributes
    ----------
    name : str
        The spec's name.
    keys : list of str
        Its varied keys (columns), in order; a vector key as one key an entry.
    values : dict of str to ndarray
        Key -> its value at each configuration, shape (n,).
    records : list of dict
        Per configuration: ``run_id``, ``warnings`` (its configuration's lines), ``push``
        (``minimum``, ``direction``, ``median``, ``estimate``, ``non_monotone``, ``units``),
        ``stability`` (``fraction``, ``low``, ``high``, ``draws``, ``inside``,
        ``inside_recovered``), ``sublevel`` c [J], ``sublevel_bound``, ``sublevel_sampled``,
        ``sublevel_history``, ``sublevel_settled``, ``runs_checked``, ``sublevel_notes``,
        ``seconds``; an entry not asked for is absent.
    options : dict
        What was asked (the push and basin-stability options, ratio, engine excluded).
    folder : Path
    computed : int
        Configurations computed by this call (the others were read back).
    seconds : float
    slides : frozenset of str
        The configurations' slides and their children (:func:`rbstab.layout.slide_parts`),
        whose keys carry a slide's units.
    """

    name: str
    keys: list
    values: dict
    records: list
    options: dict
    folder: Path
    computed: int = 0
    seconds: float = 0.0
    slides: frozenset = frozenset()

    def file_content(self, command_line: str | None = None) -> tuple[dict, dict, dict]:
        """(coordinates, variables, global attributes) of its curves file (:func:`recovery_content`)."""
        return recovery_content(self, command_line)


def _options_hash(options: Mapping[str, Any]) -> str:
    text = json.dumps(options, sort_keys=True, default=lambda x: np.asarray(x).tolist())
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _certificate(config, options: dict):
    """The Lyapunov certificate of one configuration, a body's or a tree's (:func:`rbstab.analysis.analyze`:
    sampled, falsified against the compiled engine's runs and checked against the run from
    the configured initial state), None for a law without one (the pure sign law) or a
    configuration without an equilibrium inside its admissible region."""
    from .analyze import NoEquilibrium, OutsideLimits, analyze  # heavy: numba
    from .certificate import DEFAULT_SAMPLES  # heavy: numba

    if any(j.variant == "sliding" and not j.boundary_layer for j in config.chain.joints):
        return None
    try:
        return analyze(config, samples=int(options.get("certificate_samples", DEFAULT_SAMPLES)), seed=options["seed"],
                       ratio=options["ratio"]).certificate
    except (NoEquilibrium, OutsideLimits):
        return None


def _point(item: tuple[str, dict], options: dict, engine: str) -> dict:
    """The record of one configuration (the function a worker runs): ``item`` its
    (run_id, resolved configuration)."""
    from ..config.loader import config_from_mapping  # heavy: pydantic
    from .push import basin_stability, push_analysis  # heavy: numba (its engine)

    start = _time.perf_counter()
    run_id, resolved = item
    with warnings.catch_warnings(record=True):  # its lines are kept in the record, shown once by the caller
        warnings.simplefilter("always")
        config = config_from_mapping(resolved, source=run_id)
    record: dict[str, Any] = {"run_id": run_id, "warnings": list(config.warnings)}
    ratio = options["ratio"]
    cert = _certificate(config, options) if options.get("certificate", True) else None
    push = options.get("push")
    found_push = push_analysis(config, **push, ratio=ratio, engine=engine) if push else None
    stability = options.get("basin_stability")
    found_stability = basin_stability(config, **stability, ratio=ratio, engine=engine) if stability else None
    if cert is not None:
        from .certificate import checked  # heavy: numba

        if found_push is not None:
            v0, name = found_push.fatal_starts()
            cert = checked(cert, v0, np.zeros(len(v0), dtype=bool), name)
        if found_stability is not None:
            b = found_stability
            cert = checked(cert, b.lyapunov_start, b.recovered,
                           lambda i: f"basin-stability draw {i} ({', '.join(f'{k} = {v:.4g}' for k, v in zip(b.keys, b.values[i]))})")
    c = (float(cert.sublevel) if cert.positive_definite else 0.0) if cert is not None else math.nan
    record["sublevel"], record["sublevel_bound"] = c, cert.sublevel_bound if cert is not None else ""
    verified = math.nan
    if options.get("verify"):
        from .verify import NotVerifiable, verify_sublevel  # heavy: python-flint

        try:
            proof = verify_sublevel(config)
            verified = proof.level
            record.update(sublevel_verified=verified, sublevel_verified_reason=proof.reason)
        except NotVerifiable as exc:
            record.update(sublevel_verified=math.nan, sublevel_verified_reason=str(exc))
    if cert is not None:
        record.update(sublevel_sampled=float(cert.sublevel_sampled), sublevel_settled=bool(cert.settled),
                      sublevel_history=[float(x) for x in cert.sublevel_history], runs_checked=int(cert.runs_checked),
                      samples=int(cert.n_samples), sublevel_estimate=cert.evidence, sublevel_notes=list(cert.notes))
    if found_push is not None:
        t = found_push.threshold
        record["push"] = {"minimum": found_push.minimum, "direction": found_push.minimum_direction.tolist(),
                          "grid_minimum": found_push.grid_minimum,
                          "median": float(np.median(t[np.isfinite(t)])) if np.isfinite(t).any() else math.inf,
                          "estimate": found_push.estimate(c), "verified": found_push.estimate(verified),
                          "non_monotone": int((~found_push.thresholds.monotone).sum()),
                          "directions": len(t), "units": found_push.units, "runs": found_push.runs}
    if found_stability is not None:
        b = found_stability
        inside = b.lyapunov_start <= c  # False where c is NaN (no certificate)
        record["stability"] = {"fraction": b.fraction, "low": b.interval[0], "high": b.interval[1],
                               "draws": b.draws, "recovered": int(b.recovered.sum()),
                               "inside": int(inside.sum()), "inside_recovered": int((inside & b.recovered).sum())}
    record["seconds"] = _time.perf_counter() - start
    return record


def recovery_across(spec, *, push: Mapping[str, Any] | None = None, basin_stability: Mapping[str, Any] | None = None,
                    output: str | os.PathLike = "results/analysis", ratio: float = DEFAULT_LYAPUNOV_RATIO,
                    engine: str = "compiled", executor=None, seed: int = 0, certificate: bool = True,
                    certificate_samples: int | None = None, overwrite: bool = False,
                    say: Callable[[str], None] | None = None, verify: bool = False) -> Recovery:
    """Push recovery and basin stability at every configuration of ``spec``.

    Parameters
    ----------
    spec : SweepSpec or path-like
        A sweep spec (:func:`rbstab.sweep.load_spec`).
    push, basin_stability : mapping, optional
        Keyword arguments of :func:`~rbstab.analysis.push.push_analysis` and
        :func:`~rbstab.analysis.push.basin_stability` (one of them at least).
    output : path-like
        Where ``<name>.recovery/`` goes.
    ratio : float
        Of the recovery rules.
    engine : {"compiled", "cuda"}
    executor : rbstab.sweep.executors.Executor, optional
        Takes the configurations (one whole configuration a task); None: this process.
    seed : int
        Of the certificates' sampling.
    certificate : bool
        Compute each configuration's certificate (its sublevel c; NaN without).
    certificate_samples : int, optional
        Its sampled states (default :data:`rbstab.analysis.certificate.DEFAULT_SAMPLES`, as
        a single analysis).
    overwrite : bool
        Replace records made with other options (without it: refused).
    verify : bool
        Prove each configuration's sublevel bound (:func:`rbstab.analysis.verify.verify_sublevel`;
        ``push_verified``: the pushes it holds). The spec's first configuration is checked
        against what the proof covers before anything runs.

    Raises
    ------
    ValueError
        For records of other options in the folder (without ``overwrite``), or neither
        question asked.
    """
    from ..io.atomic import atomic_path  # with the files it writes
    from .certificate import DEFAULT_SAMPLES  # heavy: numba
    from ..sweep import load_spec  # heavy: pydantic, numba
    from ..sweep.table import plan_table  # heavy: numba

    if not push and not basin_stability:
        raise ValueError("a sweep spec is analysed with --push and/or --basin-stability / --push-distribution")
    start = _time.perf_counter()
    if isinstance(spec, (str, os.PathLike)):
        spec = load_spec(spec)
    table = plan_table(spec)
    options = {"push": dict(push) if push else None, "basin_stability": dict(basin_stability) if basin_stability else None,
               "ratio": float(ratio), "seed": int(seed), "certificate": bool(certificate),
               "certificate_samples": int(DEFAULT_SAMPLES if certificate_samples is None else certificate_samples),
               "estimate": ESTIMATE_METHOD if certificate else None}
    if verify:
        from ..config.loader import config_from_mapping  # heavy: pydantic
        from .verify import check_verifiable  # raises NotVerifiable (a ValueError) with its reason

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if table.n:
                check_verifiable(config_from_mapping(table.resolved(0)))
        options["verify"] = True
    token = _options_hash(options)
    folder = Path(output) / f"{spec.name}{RECOVERY_SUFFIX}"
    points = folder / "points"
    done: dict[str, dict] = {}
    other = []
    for path in sorted(points.glob("*.json")) if points.is_dir() else []:
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            continue  # unreadable: computed again
        if record.get("options") == token:
            done[record["run_id"]] = record
        else:
            other.append(path)
    if other and not overwrite:
        raise ValueError(f"{folder} holds {len(other)} records made with other options: not replaced; --overwrite "
                         "replaces them, -o DIR writes elsewhere")
    for path in other:
        path.unlink()
    run_ids = [r.decode() for r in table.run_id]
    todo = [(rid, table.resolved(i)) for i, rid in enumerate(run_ids) if rid not in done]
    if say is not None:
        say(f"{spec.name}: {table.n} configurations, {len(done)} done before, {len(todo)} to compute")
        from ..config.loader import config_from_mapping  # heavy: pydantic
        from ..diagnostics import unbounded_fall_note  # heavy: numba

        with warnings.catch_warnings():  # shown once with the points' records
            warnings.simplefilter("ignore")
            fall = unbounded_fall_note(config_from_mapping(table.resolved(0))) if table.n else None
        if fall is not None:
            say(f"note: {fall}")

    def keep(record: dict) -> None:
        record["options"] = token
        with atomic_path(points / f"{record['run_id']}.json") as tmp:
            tmp.write_text(json.dumps(record, default=float))
        done[record["run_id"]] = record
        if say is not None:
            say(_line(record, len(done), table.n))

    if executor is None or len(todo) < 2:
        for item in todo:
            keep(_point(item, options, engine))
    else:
        executor.plan(len(todo))
        for item, record, exc in executor.imap_unordered(_point, todo, options, engine):
            if exc is not None:
                raise exc
            keep(record)
    values = {}
    for key in table.keys:
        column = np.asarray(table.columns[key])
        if column.dtype == object:
            values[key] = column.astype(str)
        elif column.ndim == 1:
            values[key] = column
        else:  # a vector or matrix key: one coordinate an entry (key.0, key.1 ...)
            flat = column.reshape(len(column), -1)
            for j in range(flat.shape[1]):
                values[f"{key}.{j}"] = flat[:, j]
    records = [done[rid] for rid in run_ids]
    return Recovery(name=spec.name, keys=list(values), values=values, records=records, options=options,
                    folder=folder, computed=len(todo), seconds=_time.perf_counter() - start,
                    slides=slide_parts(table.resolved(0)) if table.n else frozenset())


def _line(record: dict, k: int, n: int) -> str:
    """One progress line of a configuration's record (and a line a run that lowered its c)."""
    parts = [f"  [{k}/{n}] {record['run_id']}:"]
    p = record.get("push")
    if p:
        parts.append(f"smallest fatal push {p['minimum']:.4g} {p['units']} (estimate {p['estimate']:.3g}, from c = "
                     f"{record['sublevel']:.4g} J checked against {record.get('runs_checked', 0)} runs"
                     + ("" if record.get("sublevel_settled", True) else ", STILL MOVING") + ")")
        if "sublevel_verified" in record:
            parts.append(f"verified {p.get('verified', math.nan):.3g} (c = {record['sublevel_verified']:.4g} J, "
                         "interval arithmetic)" if np.isfinite(record["sublevel_verified"]) else
                         f"not verified ({record.get('sublevel_verified_reason', '')})")
    s = record.get("stability")
    if s:
        parts.append(f"basin stability {s['fraction']:.1%} ({s['low']:.1%} - {s['high']:.1%})")
    return "\n".join([" ".join(parts)] + [f"    note: {n}" for n in record.get("sublevel_notes", [])])


def recovery_content(result: Recovery, command_line: str | None = None) -> tuple[dict, dict, dict]:
    """(coordinates, variables, global attributes) of the curves file (module docstring)."""
    from ..io.metadata import provenance_attributes  # heavy: h5py, library versions
    from .dataset import FORMAT, _var  # heavy: h5netcdf

    n = len(result.records)
    coords = {"run_id": _var(("point",), np.array([r["run_id"] for r in result.records], dtype=object), "1",
                             "the configuration's run id in the spec's table")}
    for key in result.keys:
        values = np.asarray(result.values[key])
        coords[key] = _var(("point",), values if values.dtype.kind in "fiub" else values.astype(object),
                           parameter_attributes(key, result.slides).get("units"), f"varied key {key}")
        coords[key][2]["config_key"] = key
    data: dict[str, tuple] = {
        "sublevel": _var(("point",), [r["sublevel"] for r in result.records], "J",
                         "c of the inner estimate {v <= c}: sampled, refined by local search, checked against the "
                         "point's runs"),
        "sublevel_sampled": _var(("point",), [r.get("sublevel_sampled", math.nan) for r in result.records], "J",
                                 "c from the sampled states alone"),
        "sublevel_runs_checked": _var(("point",), [r.get("runs_checked", 0) for r in result.records], "1",
                                      "simulated runs c was checked against"),
        "sublevel_settled": _var(("point",), [int(r.get("sublevel_settled", False)) for r in result.records], "1",
                                 "c from N/2 samples within 1% of c from N (1), or still moving (0)"),
        "sublevel_notes": _var(("point",), np.array(["\n".join(r.get("sublevel_notes", [])) for r in result.records],
                                                    dtype=object), "1", "the runs that lowered c, one a line"),
    }
    if any("sublevel_verified" in r for r in result.records):
        data["sublevel_verified"] = _var(("point",), [r.get("sublevel_verified", math.nan) for r in result.records],
                                         "J", "c of {v <= c} proven positively invariant and inside the region of "
                                         "attraction (interval arithmetic; NaN: not verifiable)")
    push = [r.get("push") for r in result.records]
    if any(push):
        units = next(p["units"] for p in push if p)
        get = lambda k: [p[k] if p else math.nan for p in push]  # noqa: E731
        data.update({
            "push_minimum": _var(("point",), get("minimum"), units, "smallest fatal push over the directions"),
            "push_minimum_direction": _var(("point", "axis"), [p["direction"] if p else [math.nan] * 3 for p in push],
                                           "1", "its direction"),
            "push_median": _var(("point",), get("median"), units, "median over the directions of the smallest "
                                "fatal push"),
            "push_estimate": _var(("point",), get("estimate"), units,
                                  "smallest push the sublevel estimate {v <= c} holds: min over the directions of "
                                  "sqrt(c / dT(u)), below every simulated threshold"),
            **({"push_verified": _var(("point",), [p.get("verified", math.nan) if p else math.nan for p in push],
                                      units, "smallest push the verified set {v <= c} holds: min over the "
                                      "directions of sqrt(c / dT(u)), a proven bound")}
               if any(p and "verified" in p and np.isfinite(p["verified"]) for p in push) else {}),
            "push_non_monotone": _var(("point",), get("non_monotone"), "1",
                                      "directions along which recovery was not monotone in the magnitude"),
        })
    stability = [r.get("stability") for r in result.records]
    if any(stability):
        get = lambda k: [s[k] if s else math.nan for s in stability]  # noqa: E731
        data.update({
            "stability_fraction": _var(("point",), get("fraction"), "1", "basin stability: recovered draws / draws"),
            "stability_interval_low": _var(("point",), get("low"), "1", "Wilson interval, low end"),
            "stability_interval_high": _var(("point",), get("high"), "1", "Wilson interval, high end"),
            "stability_inside": _var(("point",), get("inside"), "1", "draws inside {v <= c}"),
            "stability_inside_recovered": _var(("point",), get("inside_recovered"), "1",
                                               "of them, draws that recovered"),
        })
    attrs = {"rbstab_format": FORMAT, "kind": "recovery", "name": result.name, "points": n,
             "options": json.dumps(result.options, default=lambda x: np.asarray(x).tolist()),
             **provenance_attributes(f"rbstab analyze {result.name}: push recovery across parameters",
                                     command_line=command_line)}
    coords["axis"] = _var(("axis",), np.array(["x", "y", "z"], dtype=object), "1", "vector component")
    along = " ".join(name for name in coords if name != "axis")
    for _, _, var_attrs in data.values():
        var_attrs["coordinates"] = along  # CF: the point's run id and varied values
    return coords, data, attrs

