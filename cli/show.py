"""``rbstab show``: print the summary of result files, store files and sweep folders."""

from __future__ import annotations

import difflib
import json
from pathlib import Path

import click

from .console import get_console
from .options import console_options, json_option


def _fmt(value, members: list[str] | None = None) -> str:
    """A figure as text; a chain's figure per body or joint (``members``, their names) as
    ``legs [...]; trunk [...]``."""
    if isinstance(value, list) and members is not None and len(value) == len(members):
        return "; ".join(f"{m} {_fmt(v)}" for m, v in zip(members, value))
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


#: Runs of a sweep listed by default (-v: all; the index has all).
_MAX_LISTED = 20
#: Index columns whose spread a sweep's summary gives (min, median, max).
_METRICS = ("lyapunov_final", "max_abs_constraint_error", "max_lyapunov_rate", "wall_time")


def _failed_checks(rows) -> list[str]:
    """The run ids of the ``rows`` whose rate check failed."""
    return [r["run_id"] for r in rows if r.get("lyapunov_rate_check") == "fail"]


def _run_lines(rows, ratio: float | None = None, configs=None) -> None:
    """One line per run: id, status, outcome (:func:`rbstab.diagnostics.outcome`, with the
    sweep's ``ratio``), v(0) -> v(t_end), max dv/dt, max |E_i|, rate check; below a failed
    rate check its reason, from the run's resolved configuration in ``configs`` (run id ->
    mapping; :func:`rbstab.diagnostics.simulation_rate_check_reason`)."""
    from rbstab.convergence import DEFAULT_LYAPUNOV_RATIO  # heavy: numpy

    ratio = DEFAULT_LYAPUNOV_RATIO if ratio is None else ratio
    out = get_console().out
    from rbstab.diagnostics import outcome, simulation_rate_check_reason  # heavy: numpy

    out(f"  {'run':<20} {'status':<8} {'outcome':<21} {'v(0) -> v(t_end) [J]':<24} {'max dv/dt [W]':>14} "
        f"{'max|E| [m]':>11}  rate check")
    for r in rows:
        v = f"{_fmt(r.get('lyapunov_initial', ''))} -> {_fmt(r.get('lyapunov_final', ''))}"
        e = [v for k, v in r.items() if k.startswith("max_abs_constraint_error_")]  # per axis, or a chain's per joint and axis
        numbers = [abs(float(x)) for x in e if isinstance(x, (int, float)) and x == x]  # none/NaN: another chain's joint
        e = _fmt(max(numbers)) if numbers else ""
        switchings = [r.get(f"switching_count_{a}") for a in "xyz"]  # the pure sign law of sliding
        located = (f"  {int(sum(switchings))} switchings"
                   if all(isinstance(x, (int, float)) and x == x for x in switchings) else "")
        ended = r.get("outcome") or outcome(r["status"], r.get("message"), r.get("lyapunov_initial"),
                                            r.get("lyapunov_final"), r.get("max_lyapunov_increase"), ratio)
        out(f"  {r['run_id']:<20} {r['status']:<8} {ended:<21} {v:<24} {_fmt(r.get('max_lyapunov_rate', '')):>14} "
            f"{e:>11}  {r.get('lyapunov_rate_check', '')}{located}")
        if r["status"] != "success":
            out(f"    {r.get('message', '')}")
        if r["run_id"] in (configs or {}):
            out(f"    rate check fail: {simulation_rate_check_reason(r, configs[r['run_id']]['simulation'])}")


def _show_chunk(path: str) -> None:
    """One line per run of a store file (``rbstab sweep``, layout chunk)."""
    from rbstab.io.chunk import read_chunk_rows  # heavy: numpy

    console = get_console()
    rows = read_chunk_rows(path, data=True)  # every checksum verified
    first = rows[0] if rows else {}
    if console.json:
        console.emit({"path": path, "kind": "store", "n_runs": len(rows), "store": first.get("store"), "runs": rows})
    console.out(f"{path}")
    console.out(f"  store file: {len(rows)} runs, store {first.get('store', '?')}, created {first.get('created', '?')}")
    failed = set(_failed_checks(rows))
    _run_lines(rows, configs={r["run_id"]: json.loads(r["config"]) for r in rows if r["run_id"] in failed})


def _spread(index, column: str) -> dict | None:
    """min, median, max of a numeric column over the runs that have it (None if none)."""
    values = index[column].dropna() if column in index else None
    if values is None or values.empty or values.dtype.kind not in "fi":
        return None
    return {"min": float(values.min()), "median": float(values.median()), "max": float(values.max())}


def _parameter_values(index, column: str) -> dict:
    """The values a varied parameter takes (an index column): the first 6 distinct ones
    in run order, or its range (min, max) for a numeric column of more; and how many."""
    values = index[column].dropna().unique()  # in order of appearance
    if len(values) <= 6 or values.dtype.kind not in "biuf":
        return {"values": values[:6].tolist(), "n_values": len(values)}
    return {"min": values.min().item(), "max": values.max().item(), "n_values": len(values)}


def sweep_overview(path: str) -> dict:
    """What ``rbstab show`` says about a sweep folder, as one JSON-able mapping."""
    from rbstab.sweep.folder import index_outcomes, read_index, read_parameters, read_spec  # heavy: numpy
    from rbstab.diagnostics import OUTCOMES  # heavy: numpy
    from rbstab.engine.status import fell_mask  # heavy: numba, numpy (rbstab.engine)

    index = read_index(path)  # checksum verified
    if "max_abs_constraint_error_x" in index:
        index["max_abs_constraint_error"] = index[[f"max_abs_constraint_error_{a}" for a in "xyz"]].abs().max(axis=1)
    spec = read_spec(path)
    converged = int(index["converged"].astype(str).eq("True").sum()) if "converged" in index else 0
    counts = {s: int(n) for s, n in index["status"].value_counts().items()}
    n_fell = int(fell_mask(index["status"], index["message"]).sum()) if "message" in index else 0
    ratio = (spec.get("convergence") or {}).get("lyapunov_ratio")
    ended = index_outcomes(index, *([float(ratio)] if ratio is not None else []))
    return {
        "path": path, "kind": "sweep", "name": spec.get("name", Path(path).name), "n_runs": len(index),
        "status": counts, "outcomes": {w: int((ended == w).sum()) for w in OUTCOMES if (ended == w).any()},
        "n_fell": n_fell, "n_converged": converged,
        "lyapunov_ratio": ratio,
        "parameters": {column: {"key": key, **_parameter_values(index, column)}
                       for column, key in read_parameters(path, index).items() if column in index},
        "metrics": {m: s for m in _METRICS if (s := _spread(index, m)) is not None},
        "created": (spec.get("generated") or {}).get("created"),
        "index": index,
    }


def _show_sweep(path: str) -> None:
    """A sweep folder: counts per status, converged fraction, varied parameters, the spread
    of the main figures, the first runs (every run with -v)."""
    from rbstab.io.chunk import PER_RUN, SUMMARY_FIGURES  # heavy: numpy
    from rbstab.sweep.folder import resolved_configs  # heavy: numpy, pydantic

    console = get_console()
    info = sweep_overview(path)
    index = info.pop("index")
    if console.json:
        console.emit(info)
    n = info["n_runs"]
    console.out(f"{path}")
    console.out(f"  sweep      {info['name']}: {n} runs, " + ", ".join(f"{v} {k}" for k, v in info["outcomes"].items()))
    console.out(f"  converged  {info['n_converged']} of {n} ({100.0 * info['n_converged'] / max(n, 1):.1f}%; "
                f"v(t_end) <= {info['lyapunov_ratio']} of the energy to lose)")
    for column, p in info["parameters"].items():
        shown = (", ".join(_fmt(v) for v in p["values"]) + (" ..." if p["n_values"] > len(p["values"]) else "")
                 if "values" in p else f"{_fmt(p['min'])} .. {_fmt(p['max'])}")
        console.out(f"  varied     {column} ({p['key']}): {shown}  [{p['n_values']} values]")
    units = {**{k: u for k, (u, _) in SUMMARY_FIGURES.items()}, **{k: u for k, (u, _) in PER_RUN.items()}}
    for metric, s in info["metrics"].items():
        console.out(f"  {metric:<26} [{units.get(metric, '')}] min {_fmt(s['min'])}, median {_fmt(s['median'])}, "
                    f"max {_fmt(s['max'])}")
    listed = n if console.verbosity >= 1 else _MAX_LISTED
    rows = [{k: ("" if isinstance(v, float) and v != v else v) for k, v in r.items()}
            for r in index.head(listed).to_dict("records")]
    try:
        configs = resolved_configs(path, _failed_checks(rows))
    except (OSError, ValueError, KeyError):  # a result file gone or damaged: the runs without their reasons
        configs = {}
    _run_lines(rows, info["lyapunov_ratio"], configs)
    if n > listed:
        console.out(f"  ... and {n - listed} more runs (-v lists them; the index, rbstab.open_sweep)")


def _show_result(path: str) -> None:
    """A run's result file: identity, status, solver statistics, summary figures."""
    from rbstab.io.hdf5 import read_summary  # heavy: numpy

    from rbstab.diagnostics import outcome  # heavy: numpy

    from .run import rate_check_text  # heavy: rbstab.api

    console = get_console()
    info = read_summary(path)  # every checksum verified
    summary = info["summary"]
    settled = outcome(info["status"], info.get("message"), summary.get("lyapunov_initial"),
                      summary.get("lyapunov_final"), summary.get("max_lyapunov_increase"),
                      disturbed=_file_disturbed(path))
    check = rate_check_text(summary, Path(path))
    if console.json:
        console.emit({"path": path, "kind": "run", **info, "converged": settled == "converged", "outcome": settled,
                      "rate_check_reason": check[len("fail ("):-1] if check.startswith("fail (") else None})
    console.out(f"{path}")
    console.out(f"  name       {info['name']}  (variant {info['variant']})")
    names = {}
    if info["variant"] == "chain":  # a chain's file: per-body and per-joint variables, names as coordinates
        from rbstab.io.hdf5 import read_attributes  # heavy: numpy
        from rbstab.layout import SUMMARY_FIGURES  # heavy: numpy

        attrs = read_attributes(path, verify=False)
        console.out(f"  bodies     {attrs['bodies']}; joints {attrs['joints']}")
        bodies, joints = attrs["bodies"].split(","), attrs["joints"].split(",")
        names = {key: bodies if key in SUMMARY_FIGURES and SUMMARY_FIGURES[key].member == "body" else joints
                 for key in summary}
    console.out(f"  status     {info['status']}, {settled}: {info['message']}")
    console.out(f"  created    {info['created']}, wall time {_fmt(info['wall_time'])} s")
    console.out("  solver     " + ", ".join(f"{k} {v}" for k, v in info["solver"].items() if k != "message"))
    width = max([32, *(len(key) for key in summary)])
    for key, value in summary.items():
        console.out(f"  {key:<{width}} {check if key == 'lyapunov_rate_check' else _fmt(value, names.get(key))}")


def _file_disturbed(path: str) -> bool | None:
    """Whether a result file's configuration has disturbances (None: not readable)."""
    import h5py  # heavy
    import yaml  # heavy

    try:
        with h5py.File(path, "r") as f:
            text = f.attrs.get("config", "")
        text = text.decode() if isinstance(text, bytes) else text
        return bool((yaml.safe_load(text) or {}).get("disturbances"))
    except (OSError, yaml.YAMLError, AttributeError):
        return None


def _expand(path: str) -> list[str]:
    """A plain folder (not a sweep folder) stands for the sweep folders and result files in it."""
    from rbstab.kinds import CHAIN_RUN, RUN, STORE, SWEEP, inputs_in, is_plain_folder  # heavy: numba, numpy, pydantic, yaml

    folder = Path(path)
    if not folder.exists():
        raise ValueError(f"no such result file or folder: {path}" + _did_you_mean(folder))
    if not is_plain_folder(folder):
        return [path]
    inside = [str(p) for p in inputs_in(folder, (RUN, CHAIN_RUN, STORE, SWEEP))]
    if not inside:
        raise ValueError(f"{path}: a folder, but not a sweep folder (no sweep.yaml and index.csv) and without "
                         "result files (*.h5) or sweep folders in it")
    return inside


def _did_you_mean(missing: Path) -> str:
    """``"; did you mean X?"`` naming the closest entry of its folder, or ``""``."""
    parent = missing.parent
    names = [p.name for p in parent.iterdir()] if parent.is_dir() else []
    close = difflib.get_close_matches(missing.name, names, n=1, cutoff=0.6)
    return f"; did you mean {parent / close[0]}?" if close else ""


def _show(path: str) -> None:
    """``path`` shown as its kind says (:func:`rbstab.kinds.kind_of`)."""
    from rbstab.kinds import CHAIN_RUN, RUN, STORE, SWEEP, kind_of  # heavy: numba, numpy, pydantic, yaml

    show_kind = {RUN: _show_result, CHAIN_RUN: _show_result, STORE: _show_chunk, SWEEP: _show_sweep}
    show_kind[kind_of(path, tuple(show_kind))](path)


def _show_run(path: str, run_id: str) -> None:
    """One run of a sweep folder: its status, outcome and summary figures (its index row) as
    YAML comments, then its resolved configuration rebuilt from its result, so that the
    output is a config file for ``rbstab run``."""
    from rbstab.config import dump_yaml  # heavy: numpy, pydantic
    from rbstab.diagnostics import outcome  # heavy: numpy
    from rbstab.io.chunk import PER_RUN, SUMMARY_FIGURES  # heavy: numpy
    from rbstab.sweep.folder import is_sweep_folder, read_index, resolved_config  # heavy: numpy, pydantic

    if not is_sweep_folder(path):
        raise ValueError(f"{path}: --run needs a sweep folder (sweep.yaml and index.arrow or index.csv)")
    try:
        config = resolved_config(path, run_id)
    except KeyError as exc:
        raise ValueError(exc.args[0]) from None
    index = read_index(path)
    rows = index[index["run_id"].astype(str) == run_id].to_dict("records")
    row = {k: v for k, v in rows[0].items() if not (isinstance(v, float) and v != v)} if rows else {}
    ended = row.get("outcome") or outcome(row.get("status", "pending"), row.get("message"),
                                          row.get("lyapunov_initial"), row.get("lyapunov_final"),
                                          row.get("max_lyapunov_increase"))
    console = get_console()
    if console.json:
        console.emit({"path": path, "kind": "config", "run_id": run_id, "status": row.get("status"),
                      "outcome": ended, "message": row.get("message"),
                      "summary": {k: v for k, v in row.items() if isinstance(v, (int, float)) and k != "run"},
                      "config": config})
    console.out(f"# {path}: run {run_id} (rbstab run of this file repeats it)")
    console.out(f"# status   {row.get('status', 'pending')}, {ended}" +
                (f": {row['message']}" if row.get("status", "success") != "success" and row.get("message") else ""))
    units = {**{k: u for k, (u, _) in SUMMARY_FIGURES.items()}, **{k: u for k, (u, _) in PER_RUN.items()}}
    for key, value in row.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool) and key not in ("run", "file_row"):
            unit = next((u for name, u in units.items() if key == name or key.startswith(name + "_")), "")
            console.out(f"#   {key:<40} {_fmt(value)}" + (f" [{unit}]" if unit and unit != "1" else ""))
    console.out(dump_yaml(config).rstrip())


@click.command("show")
@click.argument("files", nargs=-1, required=True, type=click.Path())
@click.option("--run", "run_id", metavar="ID", default=None,
              help="With a sweep folder: print run ID's status, outcome and summary figures, then its resolved "
                   "configuration (rebuilt from its result) as YAML.")
@json_option
@console_options
def show(files, run_id, as_json) -> None:
    """Print status, solver statistics and summary figures of FILE.h5..., store files and sweep folders.

    A sweep folder (sweep.yaml + index.csv) is summarised: runs per status, converged
    fraction, the varied parameters, the spread of the main figures and its first runs
    (-v: all). A folder of sweeps or of result files (e.g. results/) shows each of them.
    With --json: one object per file or sweep ("kind": run, store, sweep or error).
    --run ID prints a sweep run's status, outcome and summary figures as comments, then its
    configuration as YAML (a config file for rbstab run).
    """
    console = get_console()
    bad = shown = 0
    for given in files:
        try:
            paths = _expand(given)
        except ValueError as exc:
            paths, bad = [], bad + 1
            click.echo(f"error: {exc}", err=True)
            if console.json:
                console.emit({"path": given, "kind": "error", "error": str(exc)})
        for path in paths:
            shown += 1
            try:
                _show(path) if run_id is None else _show_run(path, run_id)
            except BrokenPipeError:  # the reader is gone (| head): nothing more to show
                raise
            except (OSError, ValueError) as exc:  # FileNotFoundError, NotAResultFile, DamagedResultError ...
                click.echo(f"error: {exc}", err=True)
                if console.json:
                    console.emit({"path": path, "kind": "error", "error": str(exc)})
                bad += 1
    if bad:
        raise click.ClickException(f"{bad} of {max(shown, len(files))} inputs could not be read")
