"""``rbstab sensitivity``: Sobol' indices or Morris effects of summary figures (rbstab.studies)."""

from __future__ import annotations

import click

from ._common import command_line, load_configs
from .console import get_console
from .options import console_options, study_options


def study_error(exc) -> click.ClickException:
    """A study's exception as one CLI error (the option, the value, what is allowed)."""
    return click.ClickException("invalid study\n" + "\n".join("  " + line for line in exc.errors))


@click.command("sensitivity")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("-n", "n", type=int, required=True, metavar="N",
              help="Base samples N (sobol: a power of 2, N (D + 2) runs for D factors) or trajectories "
              "(morris: N (D + 1) runs).")
@click.option("--method", default="sobol", show_default=True, metavar="sobol|morris",
              help="Sobol' indices (Saltelli sampling) or Morris elementary effects.")
@click.option("--metric", "metrics", multiple=True, metavar="[log10:|rank:]NAME",
              help="A summary figure of the runs (docs/studies.md; a 3-vector figure gives its three "
              "components, a chain's per-joint figure one metric a joint), optionally through a transform: log10:NAME (a positive figure spread over "
              "decades), rank:NAME (the ranks of the runs' values). Repeatable  [default: "
              "max_abs_constraint_error, lyapunov_final, max_lyapunov_rate, converged].")
@click.option("--resamples", type=click.IntRange(min=10), default=200, show_default=True,
              help="Bootstrap resamples of the confidence intervals.")
@click.option("--confidence", type=click.FloatRange(0, 1, min_open=True, max_open=True), default=0.95,
              show_default=True, help="Level of the confidence intervals.")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None, metavar="N",
              help="Worker processes on this machine  [default: all CPUs].")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run on the Dask cluster at ADDRESS (tcp://HOST:PORT) instead of local processes.")
@click.option("--progress/--no-progress", default=None, help="Progress bar  [default: if stderr is a terminal].")
@study_options
@console_options
def sensitivity(config, n, method, metrics, resamples, confidence, jobs, scheduler, progress, vary, seed, name,
                overrides, engine, output, overwrite, as_json) -> None:
    """Global sensitivity of summary figures to the --vary factors of CONFIG.

    \b
    rbstab sensitivity configs/paper/case3_embedded.yaml -n 256 \\
        --vary controller.k_c=scale_uniform:[0.5,2] --vary controller.l_c=scale_uniform:[0.5,2] \\
        --vary body.mass=uniform:[30,50] --metric max_abs_constraint_error --metric lyapunov_final

    CONFIG may be a chain (bodies and joints): its keys name a body or a joint by index or
    name (bodies.1.mass, joints.hip.k_r.0, initial_state.trunk.theta.0), and its metrics are
    its figures per body or joint and axis, as its sweep's columns (max_abs_constraint_error_hip,
    final_theta_trunk_x); a name without its member or axis gives one metric a column.

    Draws the design with SALib, runs it as a sweep (OUTPUT/<name>/sweep/: the same command
    again resumes it) and writes first-order and total Sobol' indices (or Morris mu*, sigma)
    with bootstrap confidence intervals to OUTPUT/<name>/sensitivity.nc; `rbstab report
    OUTPUT/<name>` draws them. Options are checked before anything runs. With --json: one
    object per metric. Manual: docs/studies.md.
    """
    # heavy: h5py, numba, numpy, pandas, pydantic, xarray, yaml
    from rbstab.studies import StudyInputError, metric_records, sensitivity_analysis
    from rbstab.sweep import ExecutorError, SweepBusyError, SweepSpecError  # heavy: numba, numpy, pydantic, yaml

    (base,) = load_configs([config], overrides)
    console = get_console()
    try:
        ds = sensitivity_analysis(base, vary, n=n, method=method, metrics=metrics, seed=seed, output=output,
                                  name=name, num_resamples=resamples, conf_level=confidence, jobs=jobs,
                                  executor="dask" if scheduler else None, scheduler=scheduler, engine=engine,
                                  log=console.info, progress=False if console.verbosity < 0 else progress,
                                  command_line=command_line(), overwrite=overwrite)
    except StudyInputError as exc:
        raise study_error(exc)
    except SweepSpecError as exc:
        raise click.ClickException("invalid design\n" + "\n".join("  " + line for line in exc.errors))
    except (SweepBusyError, ExecutorError) as exc:
        raise click.ClickException(str(exc))
    from rbstab.studies.sensitivity import HEAVY_TAIL_DECADES, split_transform  # heavy: pandas, xarray

    records = metric_records(ds)
    for record in records:
        console.out(_describe(record))
        if record["note"]:
            console.out(f"  (!) {record['note']}")
        spread = record["decades"]
        if split_transform(record["metric"])[0] is None and spread is not None and spread > HEAVY_TAIL_DECADES:
            console.info(f"  note: {record['metric']} spans {spread:.1f} decades over the runs; its indices are more "
                         f"telling of log10:{record['metric']} or rank:{record['metric']} (--metric)")
        if as_json:
            console.emit(record)
    console.out(f"  -> {ds.attrs['path']}")


def _describe(record: dict) -> str:
    """A metric's indices in a few lines."""
    units = f" [{record['units']}]" if record["units"] not in ("", "1") else ""
    if record.get("reason"):
        return f"{record['metric']}{units} ({record['method']}, {record['n_runs']} runs): {record['reason']}"
    lines = [f"{record['metric']}{units} ({record['method']}, {record['n_runs']} runs"
             + (f", {record['n_nonfinite']} without a value: no indices" if record["n_nonfinite"] else "") + ")"]
    for factor, values in record["factors"].items():
        if record["method"] == "sobol":
            text = (f"S1 {_pm(values['S1'], values['S1_conf'])}{_mark(values, 'S1')}  "
                    f"ST {_pm(values['ST'], values['ST_conf'])}{_mark(values, 'ST')}")
        else:
            text = f"mu* {_pm(values['mu_star'], values['mu_star_conf'])}  sigma {_g(values['sigma'])}"
        lines.append(f"  {factor:<32} {text}")
    return "\n".join(lines)


def _mark(values: dict, index: str) -> str:
    """`` (!)`` after an index flagged unreliable."""
    return " (!)" if values.get(f"{index}_unreliable") else ""


def _g(value) -> str:
    return "n/a" if value is None else f"{value:.3g}"


def _pm(value, half) -> str:
    return "n/a" if value is None else f"{value:.3f} +- {_g(half)}"
