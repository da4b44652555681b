"""``rbstab analyze``: equilibrium, linearisation, Lyapunov certificate, basin map, robustness."""

from __future__ import annotations

from pathlib import Path

import click

from rbstab.engine.registry import DEFAULT_ENGINE, ENGINES

from ._common import check_engine, command_line, load_configs
from .console import get_console
from .options import console_options, json_option, output_option, set_option


def _parse_axes(texts, configs):
    """Basin axes per config (parsed against each variant's states); ClickException if invalid."""
    if not texts:
        return {}
    if len(texts) != 2:
        raise click.UsageError(f"--basin: give it exactly twice (two axes of the slice), found {len(texts)}")
    from rbstab.analysis import BasinAxis  # heavy: numba, numpy

    axes, problems = {}, []
    for config in configs:
        layout = config.make_variant().layout
        try:
            axes[config.name] = [BasinAxis.parse(t, layout) for t in texts]
        except ValueError as exc:
            problems.append(f"{config.name}: {exc}")
    if problems:
        raise click.ClickException("invalid --basin\n" + "\n".join(problems))
    return axes


def _check_boundary_layer(configs, boundary_layer) -> None:
    """--boundary-layer against every config (only the pure sign law takes it)."""
    from rbstab.analysis.analyze import analysed_config  # heavy: numba, numpy

    problems = []
    for config in configs:
        try:
            analysed_config(config, boundary_layer)
        except ValueError as exc:
            problems.append(f"{config.name}: {exc}")
    if problems:
        raise click.ClickException("\n".join(problems))


def _check_sweeps(paths) -> None:
    """Every ``--robustness`` path a sweep folder (:func:`rbstab.kinds.kind_of`), or one line each."""
    from rbstab.io.hdf5 import NotAResultFile  # heavy: numba, numpy, pydantic, yaml
    from rbstab.kinds import SWEEP, kind_of  # heavy: numba, numpy, pydantic, yaml

    problems = []
    for path in paths:
        try:
            kind_of(path, (SWEEP,))
        except (FileNotFoundError, NotAResultFile) as exc:
            problems.append(f"--robustness: {exc}")
    if problems:
        raise click.ClickException("\n".join(problems))


def _check_targets(loaded, out: Path) -> None:
    """Refuse, before anything runs, to replace an analysis file of another configuration
    (another config_hash) of the same name; the same configuration again is replaced."""
    import h5py  # heavy

    from rbstab.analysis.dataset import analysis_path  # heavy: numba, numpy
    from rbstab.config import canonical_config, config_hash  # heavy: numpy, pydantic

    refused = []
    for config in loaded:
        path = analysis_path(out, config.name)
        if not path.is_file():
            continue
        try:
            with h5py.File(path, "r") as f:
                stored = f.attrs.get("config_hash")
        except OSError:
            continue  # not readable as an analysis: replaced, as before
        stored = stored.decode() if isinstance(stored, bytes) else stored
        if stored is not None and stored != config_hash(canonical_config(config.resolved)):
            refused.append(f"{path} holds the analysis of a different configuration of the name {config.name!r}: "
                           "not replaced; --overwrite replaces it, -o DIR writes elsewhere, --set name=... gives "
                           "this one another file")
    if refused:
        raise click.ClickException("\n".join(refused) + "\n(nothing was run)")


@click.command("analyze")
@click.argument("configs", nargs=-1, type=click.Path(dir_okay=False))
@output_option("results/analysis", "Folder for the <name>.analysis.nc files.")
@json_option
@click.option("--basin", "basin", multiple=True, metavar="KEY=LO:HI:N",
              help="An axis of the basin map, twice, e.g. --basin initial_state.omega.0=-60:60:41 "
              "--basin initial_state.omega.1=-60:60:41 (one simulation per grid point).")
@click.option("--robustness", "sweeps", multiple=True, type=click.Path(file_okay=False), metavar="SWEEP_DIR",
              help="A sweep folder of perturbed parameters: stable fraction and separating parameters. Repeatable.")
@set_option
@click.option("--boundary-layer", type=float, default=None, metavar="PHI",
              help="phi [m] analysed in place of the pure sign law of sliding (boundary_layer 0)  [default: 1e-3].")
@click.option("--samples", type=click.IntRange(min=1), default=10_000, show_default=True, metavar="N",
              help="States sampled for the certificate's dv/dt check.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of that sampling.")
@click.option("--no-certificate", is_flag=True, help="Skip the Lyapunov certificate.")
@click.option("--no-simulation", is_flag=True, help="Skip the simulation from the configured initial state.")
@click.option("--ratio", type=click.FloatRange(0, 1, min_open=True, max_open=True), default=1e-3,
              show_default=True, help="Converged: |v| <= RATIO |v(0)| from then on (basin map, settling time).")
@click.option("--basin-samples", type=click.IntRange(min=2), default=201, show_default=True, metavar="N",
              help="Samples per basin run (the time-to-converge resolution is t_end / (N - 1)).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None, metavar="N",
              help="Local processes for the basin map  [default: all CPUs].")
@click.option("--engine", type=click.Choice([e.name for e in ENGINES.values() if e.compiled]), default=DEFAULT_ENGINE,
              show_default=True,
              help="The basin map's engine: the CPU's, or cuda: an NVIDIA GPU, one thread a grid point "
              "(pip install \"rbstab[cuda]\").")
@click.option("--confidence", type=click.FloatRange(0, 1, min_open=True, max_open=True), default=0.95,
              show_default=True, help="Confidence level of the Wilson interval (--robustness).")
@click.option("--overwrite", is_flag=True,
              help="Replace an analysis file of another configuration of the same name (without it: refused).")
@console_options
def analyze(configs, output, as_json, basin, sweeps, overrides, boundary_layer, samples, seed, no_certificate,
            no_simulation, ratio, basin_samples, jobs, engine, confidence, overwrite) -> None:
    """Analyse the stability of the equilibrium of each CONFIG; write OUTPUT/<name>.analysis.nc.

    \b
    Per config: the equilibrium and rest check, the eigenvalues of the Jacobian there
    (damping ratio, natural frequency, time constant, verdict), the Lyapunov certificate
    (Hessians of v and dv/dt, dv/dt <= 0 on sampled states, a sublevel set of v as a
    sampling-based inner estimate of the region of attraction) and, with --basin, the
    basin of attraction over a 2-D slice of initial states by simulation.
    With --robustness SWEEP_DIR: the stable fraction of a sweep's runs with its Wilson
    interval, and the parameters that separate stable from unstable runs.
    Every input is checked before anything runs. Method and limits: docs/analysis.md.
    With --json: one object per config ("kind": "configuration") and per sweep ("robustness").
    """
    from rbstab.analysis import analyze as run_analysis  # heavy: numba, numpy
    from rbstab.analysis import robustness, write_analysis  # heavy: numba, numpy
    from rbstab.analysis.dataset import analysis_path  # heavy: numba, numpy
    from rbstab.analysis.text import describe, describe_robustness  # heavy: numba, numpy
    from rbstab.engine import ensure_compiled  # heavy: numba, numpy
    from rbstab.sweep.executors import default_jobs  # heavy: multiprocessing (every command's start-up)

    if not configs and not sweeps:
        raise click.UsageError("give CONFIG files and/or --robustness SWEEP_DIR")
    if basin:
        check_engine(engine)
    loaded = load_configs(configs, overrides)
    axes = _parse_axes(basin, loaded)
    _check_boundary_layer(loaded, boundary_layer)
    _check_sweeps(sweeps)
    console = get_console()
    say = console.out
    out = Path(output)
    if not overwrite:
        _check_targets(loaded, out)
    ensure_compiled(say=console.info)
    for config in loaded:
        try:
            result = run_analysis(config, boundary_layer=boundary_layer, certificate=not no_certificate,
                                  samples=samples, seed=seed, simulate=not no_simulation,
                                  basin=axes.get(config.name), basin_samples=basin_samples, ratio=ratio,
                                  jobs=jobs or default_jobs(), engine=engine)
        except ValueError as exc:
            raise click.ClickException(f"{config.name}: {exc}")
        path = write_analysis(result, analysis_path(out, config.name), command_line=command_line())
        for line in describe(result):
            say(line)
        say(f"  -> {path}")
        if as_json:
            console.emit({"kind": "configuration", **result.to_json()})
    for folder in sweeps:
        result = robustness(folder, confidence=confidence)
        path = write_analysis(result, analysis_path(out, f"{result.sweep}.robustness"), command_line=command_line())
        for line in describe_robustness(result):
            say(line)
        say(f"  -> {path}")
        if as_json:
            console.emit({"kind": "robustness", **result.to_json()})

