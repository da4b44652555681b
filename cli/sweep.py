"""``rbstab sweep``: run a parameter sweep (grid x zip x random) locally or on Dask."""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import click

from rbstab.api import execute_sweep
from rbstab.engine.registry import get_engine
from rbstab.warning_codes import coded

from ._common import MachineFault, NotComputed, check_engine, command_line, spec_error, template_stiffness_warnings
from .console import get_console
from .options import console_options, engine_option, keys_checked, output_option, set_option


_RANGE = re.compile(r"\s*(log:)?([^:,\[\]]+):([^:,\[\]]+):([^:,\[\]]+)\s*")


def grid_values(key: str, text: str) -> str:
    """The values of ``--grid KEY=...`` as YAML list items: ``V1,V2,...`` as given, or a
    range ``LO:HI:N`` (N evenly spaced values from LO to HI) or ``log:LO:HI:N`` (N values
    evenly spaced in log10, LO and HI > 0), for scalar keys and scale factors; a bad
    range is a usage error naming the key, the value and what is allowed."""
    match = _RANGE.fullmatch(text)
    if match is None:
        return text
    log, lo, hi, n = match.groups()
    allowed = (f"--grid {key}={text}: expected LO:HI:N (N >= 2 values from LO to HI) or log:LO:HI:N "
               "(LO, HI > 0), e.g. 100:1000:12 or log:1e2:1e4:5")
    try:
        lo_value, hi_value, count = float(lo), float(hi), int(n)
    except ValueError:
        raise click.ClickException(allowed) from None
    if count < 2 or not all(math.isfinite(v) for v in (lo_value, hi_value)) or (
            log and (lo_value <= 0 or hi_value <= 0)):
        raise click.ClickException(allowed)
    if log:
        values = [10 ** (math.log10(lo_value) + i * (math.log10(hi_value) - math.log10(lo_value)) / (count - 1))
                  for i in range(count)]
        values[0], values[-1] = lo_value, hi_value
    else:
        values = [lo_value + i * (hi_value - lo_value) / (count - 1) for i in range(count)]
        values[-1] = hi_value
    return ",".join(repr(float(f"{v:.12g}")) for v in values)


def _scaled_grid(spec: str, overrides, key: str, text: str) -> tuple[str, str]:
    """``--grid KEY:scale=...``: the factors times KEY's value in the base config SPEC, as
    a grid over KEY (a list-valued key gives one list per level)."""
    from rbstab.config import ConfigError, load_config  # heavy: numba, pydantic (~0.4 s at the command's start)
    from rbstab.config.paths import parse_key  # heavy: pydantic

    base = key.removesuffix(":scale")
    try:
        resolved = load_config(spec, [o for o in overrides if not o.startswith("sweep.")]).resolved
    except (ConfigError, OSError) as exc:
        raise click.ClickException(f"--grid {key}={text}: a scale factor needs a run config to scale "
                                   f"({spec}: {str(exc).splitlines()[0]})") from None
    value = parse_key(base).get(resolved, None)
    if not isinstance(value, (int, float, list)) or isinstance(value, bool):
        raise click.ClickException(f"--grid {key}={text}: {base} is {value!r} in {spec}; a scale factor needs "
                                   "a number or a list of numbers there")

    def scaled(v, f):
        return [scaled(x, f) for x in v] if isinstance(v, list) else float(f"{v * f:.12g}")

    factors = [float(x) for x in grid_values(key, text).split(",")]
    return base, ",".join(json.dumps(scaled(value, f)) for f in factors)


def _sweep_overrides(grid, zipped, random, n, seed, spec: str = "", overrides=()) -> list[str]:
    """The command-line sweep options as ``sweep.*`` overrides of the spec."""
    out = []
    for key, values in map(_key_value, grid):
        if key.endswith(":scale"):
            key, values = _scaled_grid(spec, overrides, key, values)
        else:
            values = grid_values(key, values)
        out.append(f"sweep.grid.{key}=[{values}]")
    out += [f"sweep.zip.{key}=[{values}]" for key, values in map(_key_value, zipped)]
    for key, text in map(_key_value, random):
        name, sep, rest = text.partition(":")
        dist = text if text.lstrip().startswith("{") or not sep else f"{{{name.strip()}: {rest}}}"
        out.append(f"sweep.random.params.{key}={dist}")
    if n is not None:
        out.append(f"sweep.random.n={n}")
    if seed is not None:
        out.append(f"sweep.random.seed={seed}")
    return out


def _key_value(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise click.UsageError(f"{text!r}: expected KEY=VALUES, e.g. body.mass=30,41,52")
    return key.strip(), value


@click.command("sweep")
@click.argument("spec", type=click.Path(dir_okay=False))
@output_option("results/sweeps", "Parent folder; the sweep writes OUTPUT/<name>/.")
@click.option(
    "-j", "--jobs", type=click.IntRange(min=1), default=None, metavar="N",
    help="Worker processes on this machine  [default: all CPUs; with --engine cuda, up to 4].",
)
@click.option(
    "--executor", type=click.Choice(["local", "dask"]), default=None,
    help="Where runs execute: local processes, or an existing Dask cluster (needs "
    '--scheduler and pip install "rbstab[dask]")  [default: local].',
)
@click.option(
    "--scheduler", metavar="ADDRESS", default=None,
    help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (implies --executor dask).",
)
@click.option(
    "--connect-timeout", type=click.FloatRange(min=0, min_open=True), default=None, metavar="SECONDS",
    help="How long to wait for the Dask scheduler before giving up with a message naming it  [default: 5].",
)
@set_option
@click.option("--grid", "grid", multiple=True, metavar="KEY=V1,V2,...|LO:HI:N|log:LO:HI:N",
              callback=keys_checked("--grid", suffix=":scale"),
              help="Vary KEY over the values (YAML, comma-separated; lists in brackets), or over N values "
              "from LO to HI (log: evenly in log10), as a grid level; KEY:scale (with a run config) scales "
              "KEY's value by the factors. "
              "Repeatable: the Cartesian product.")
@click.option("--zip", "zipped", multiple=True, metavar="KEY=V1,V2,...", callback=keys_checked("--zip"),
              help="Vary KEY together with the other --zip keys (lists of equal length).")
@click.option("--random", "random", multiple=True, metavar="KEY=DISTRIBUTION", callback=keys_checked("--random"),
              help="Draw KEY from a distribution of the spec files, e.g. body.mass=uniform:[30,50], "
              "controller.k_c=scale_uniform:[0.5,2], initial_state.omega='normal:{mean: [16,32,-16], std: 4}'.")
@click.option("-n", "n_random", type=click.IntRange(min=0), default=None, metavar="N",
              help="Random samples (sweep.random.n).")
@click.option("--seed", type=click.IntRange(min=0), default=None, help="Seed of the random samples.")
@click.option("--table", "table", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Runs given row by row: a CSV or Parquet file whose columns are dotted config keys "
              "(body.mass, initial_state.omega[1], body.inertia[0,0]); unlisted entries come from the base.")
@click.option(
    "--timeout", type=click.FloatRange(min=0, min_open=True), default=None, metavar="SECONDS",
    help="Per-run wall-time limit, instead of each config's simulation.max_wall_time; a run past it "
    "is recorded as failed.",
)
@engine_option()
@click.option(
    "--chunk-size", type=click.IntRange(min=1), default=None, metavar="N",
    help="Most runs per unit of work sent to a worker, and per store file  [default: 512 runs a store file, "
    "8192 with --store summary, a GPU launch's with --engine cuda; one result file per run (--layout run): "
    "256 with the compiled engine, 1 with scipy].",
)
@click.option(
    "--store", type=click.Choice(["full", "thinned", "summary"]), default="thinned", show_default=True,
    help="Traces kept per run: every variable at every sample (full), the state, E and v at "
    "<= 201 samples (thinned), or none (summary); summary figures and the index are the same.",
)
@click.option(
    "--layout", type=click.Choice(["chunk", "run"]), default=None,
    help="Store files of many runs along a 'run' dimension (runs/chunk-*.h5, netCDF-4), or one "
    "result file per run (runs/<run_id>.h5, the format of rbstab run)  [default: chunk; run for the "
    "traces of a sweep of different chains].",
)
@click.option(
    "--index", "index", type=click.Choice(["csv", "arrow"]), default=None,
    help="Index files: index.arrow and index.csv (csv), or index.arrow alone (arrow)  [default: csv up to "
    "100,000 runs, arrow above].",
)
@click.option("--retry-failed", is_flag=True, help="Also rerun runs whose result file says failed.")
@click.option("--dry-run", is_flag=True, help="Validate the spec, list the runs, write nothing.")
@click.option("--overwrite", is_flag=True,
              help="Replace the index of a sweep folder that holds other runs (another --grid of the same "
              "config; without it: refused).")
@click.option("--progress/--no-progress", default=None, help="Progress bar  [default: if stderr is a terminal].")
@console_options
def sweep(spec, output, jobs, executor, scheduler, connect_timeout, overrides, grid, zipped, random, n_random, seed,
          table, timeout, engine, chunk_size, store, layout, index, retry_failed, dry_run, progress,
          overwrite) -> None:
    """Run the sweep SPEC.yaml (or vary CONFIG.yaml); write OUTPUT/<name>/.

    SPEC is a sweep spec, or a run config to vary from the command line:

    \b
    rbstab sweep case3.yaml --grid body.mass=30,41,52 --grid controller.variant=visco_elastic,embedded
    rbstab sweep case3.yaml --grid body.mass=30:60:7 --grid controller.k_c:scale=log:0.5:4:12
    rbstab sweep case3.yaml --random controller.k_c=scale_uniform:[0.5,2] -n 100 --seed 1
    rbstab sweep case3.yaml --table design.csv          # one run per row

    Every run's config is validated before anything runs. Running the same command again
    skips the runs whose result exists and matches their config, and finishes the rest.
    A folder holding a sweep with runs this one does not have (another --grid of the same
    config) is refused unless --overwrite.
    --set KEY=VALUE overrides every base config; --set sweep.KEY=VALUE changes the spec
    itself (e.g. --set sweep.random.n=20). The resolved spec is written to
    OUTPUT/<name>/sweep.yaml: `rbstab sweep OUTPUT/<name>/sweep.yaml` reruns or resumes it.

    Exit status: 0 when every run succeeded, else the number of failed runs (at most 100);
    1 for an invalid spec (nothing is run), an unreachable Dask scheduler (within
    --connect-timeout) or a fault of the machine (full disk, read-only folder: one line);
    130 when interrupted by Ctrl-C, 143 by SIGTERM.
    """
    from rbstab.sweep.executors import LocalExecutor  # heavy: multiprocessing (~0.015 s, every command's start-up)

    if scheduler and executor == "local":
        raise click.UsageError("--scheduler is for --executor dask")
    executor = executor or ("dask" if scheduler else "local")
    if executor == "dask" and not scheduler:
        raise click.UsageError("--executor dask needs --scheduler tcp://HOST:PORT")
    if connect_timeout is not None and executor != "dask":
        raise click.UsageError("--connect-timeout is for --executor dask (the wait for its scheduler)")
    overrides = [*overrides, *_sweep_overrides(grid, zipped, random, n_random, seed, spec, overrides)]
    if not dry_run:
        check_engine(engine)
    if get_engine(engine).gpu:
        from rbstab.sweep.runner import cuda_jobs  # heavy: numba, pandas (~0.7 s at the command's start)

        jobs = cuda_jobs(jobs)
    if table is not None:
        overrides.append(f"sweep.table={json.dumps(os.path.abspath(table))}")
    if dry_run:
        return _dry_run(spec, overrides, store=store, layout=layout, jobs=jobs)
    # start the local workers' fork server first: it imports numpy, numba and h5py and loads
    # the kernels (~0.8 s of CPU) while this process imports its own modules and reads,
    # plans and validates the runs (~0.7 s for a 10,000-run initial-state spec)
    ex = LocalExecutor(jobs) if executor == "local" else executor
    if executor == "local":
        ex.start()
    try:
        loaded = _load(spec, overrides)  # read once; None: invalid, said with every problem below
        table = _plan(loaded)  # planned once; None: invalid, said with every problem below
        if not overwrite and table is not None:
            _check_folder(loaded, output, table)
        if table is not None:
            for line in template_stiffness_warnings(loaded, table, sign_law=True):  # before anything runs
                get_console().warn(line)
        outcome = _execute(spec if loaded is None else loaded, output, ex, path=spec, jobs=jobs, scheduler=scheduler,
                           connect_timeout=connect_timeout, overrides=overrides if loaded is None else (),
                           timeout=timeout, retry_failed=retry_failed, engine=engine,
                           chunk_size=chunk_size, store=store, layout=layout, index=index, table=table,
                           progress=False if get_console().verbosity < 0 else progress)
    finally:
        if not isinstance(ex, str):
            ex.close()
    _say_outcome(outcome)
    if outcome.n_not_computed:
        raise NotComputed(f"{outcome.n_not_computed} of {outcome.n_runs} runs could not be computed (listed above); "
                          "the same command with --retry-failed runs them again")


def _load(spec, overrides):
    """The loaded sweep spec, or None if it is invalid (the sweep then says why)."""
    from rbstab.sweep import SweepSpecError, load_spec  # heavy: numba, pandas, pydantic (~0.4-0.7 s at the start)

    try:
        return load_spec(spec, overrides)
    except SweepSpecError:
        return None


def _plan(loaded):
    """The planned runs of the loaded spec (:func:`rbstab.sweep.table.plan_table`), or None
    for an invalid spec or run (the sweep then says why)."""
    from rbstab.sweep import SweepSpecError  # heavy: numba, pandas, pydantic (~0.4-0.7 s at the start)
    from rbstab.sweep.table import plan_table  # heavy: numba, pydantic (~0.4 s at the start)

    if loaded is None:
        return None
    try:
        return plan_table(loaded)
    except SweepSpecError:
        return None


def _check_folder(loaded, output, table) -> None:
    """Refuse, before anything runs or is written, a sweep whose folder holds a sweep with
    runs this one does not have (another --grid, another spec of the same name): its index
    would be replaced. The same sweep again (resume), or one that only adds runs, goes on."""
    from rbstab.sweep.folder import is_sweep_folder, read_index  # heavy: numpy (~0.1 s at the start)

    folder = Path(output) / loaded.name
    if not is_sweep_folder(folder):
        return
    try:
        before = set(read_index(folder)["run_id"].astype(str))
    except (OSError, ValueError, KeyError):
        return  # a damaged folder: the sweep itself says so
    now = set(table.ids())
    gone = before - now
    if gone:
        raise click.ClickException(
            f"{folder} holds a sweep with {len(gone)} of its {len(before)} runs not in this one (another --grid, "
            "--zip, --random or base): not replaced; --overwrite replaces its index, -o DIR writes elsewhere, "
            "--set sweep.name=NAME gives this sweep another folder (nothing was run)")


def _dry_run(spec, overrides, *, store: str, layout: str, jobs: int | None) -> None:
    """--dry-run: plan and validate every run, print the count, the varied keys with their
    ranges, the first and last runs (all with -v), the estimated store size and wall time;
    write nothing."""
    from rbstab.sweep import SweepSpecError, default_jobs, load_spec  # heavy: numba, pandas, pydantic (~0.4-0.7 s)
    from rbstab.sweep.runner import sweep_layout  # heavy: numba, pandas
    from rbstab.sweep.table import estimate, plan_table  # heavy: numba, pydantic (~0.4 s at the start)

    console = get_console()
    try:
        loaded = load_spec(spec, overrides)
        table = plan_table(loaded)
    except SweepSpecError as exc:
        raise spec_error(spec, exc.errors)
    for line in [*table.warnings, *template_stiffness_warnings(loaded, table)]:
        console.warn(line)
    workers = jobs or default_jobs()
    size, seconds = estimate(table, store, workers)
    console.out(f"{loaded.name}: {table.n} runs (dry run: nothing run or written)")
    console.out(f"  store ~{size / 2**20:.3g} MiB (--store {store}, --layout {layout or sweep_layout(loaded, None, store)}); "
                f"wall time ~{seconds:.3g} s on {workers} worker(s) after the engine's start-up")
    console.out("varied:" if table.keys else "varied: nothing")
    for line in table.describe(every=console.verbosity >= 1):
        console.out(line)


def _execute(spec, output, ex, *, path, **options):
    """:func:`rbstab.api.execute_sweep` of ``spec`` (the file ``path`` or its loaded spec),
    its exceptions as one-line CLI errors."""
    from rbstab.sweep import ExecutorError, SweepBusyError, SweepSpecError  # heavy: numba, pandas (~0.4-0.7 s)

    try:
        return execute_sweep(spec, output, executor=ex, command_line=command_line(), log=get_console().info,
                             **options)
    except SweepBusyError as exc:
        raise click.ClickException(str(exc))
    except ExecutorError as exc:  # an unreachable scheduler, a pool of workers that keeps dying
        raise MachineFault(str(exc))
    except SweepSpecError as exc:
        raise spec_error(path, exc.errors)


def _ended(status: str, message) -> str:
    """The outcome of a run that did not reach t_end, in the words of ``rbstab run``."""
    from rbstab.diagnostics import outcome  # heavy: numpy

    return outcome(status, message if isinstance(message, str) else None, None, None)


def _say_outcome(outcome) -> None:
    """The sweep's warnings, counts, files and problems."""

    console = get_console()
    for line in outcome.warnings:
        console.warn(line)
    pct = 100.0 * outcome.n_converged / outcome.n_runs if outcome.n_runs else 0.0
    ended = ", ".join(f"{count} {word}" for word, count in outcome.outcomes.items() if count)
    console.out(
        f"{outcome.name}: {outcome.n_runs} runs ({outcome.n_skipped} skipped, {outcome.n_executed} run now): "
        f"{ended or 'none'} ({pct:.1f}% converged)"
    )
    console.out(f"  index   {outcome.index_path}")
    console.out(f"  summary {outcome.summary_path}")
    shown = len(outcome.problems) if console.verbosity >= 1 else 20
    for run_id, status, message in outcome.problems[:shown]:
        click.echo(f"  {run_id}: {_ended(status, message)}: {message}", err=True)
    if len(outcome.problems) > shown:
        click.echo(f"  ... and {len(outcome.problems) - shown} more (-v lists them; see the index)", err=True)
    if outcome.tracebacks:
        run_id, text = next(iter(outcome.tracebacks.items()))
        click.echo(f"traceback of {run_id} (a bug? please report it):\n{text}", err=True)
    if outcome.stale_files:
        console.warn(coded("W004", f"{len(outcome.stale_files)} result file(s) in {outcome.directory / 'runs'} are "
                                   "not runs of this spec (left in place)"))
