"""``rbstab analyze``: equilibrium, linearisation, Lyapunov certificate, basin map, robustness."""

from __future__ import annotations

import contextlib
from pathlib import Path

import click

from rbstab.engine.registry import DEFAULT_ENGINE, ENGINES
from rbstab.layout import is_chain

from ._common import check_engine, command_line, load_configs, show_config_warnings, spec_error
from .console import get_console
from .options import console_options, json_option, output_option, set_option


def _state_entries(option: str):
    """A click callback: the key of each ``KEY=...`` of ``option`` one entry of an initial
    state (:func:`rbstab.analysis.basin.state_entry`), else one line before anything runs."""

    def callback(ctx, param, values):
        from rbstab.analysis.basin import state_entry  # heavy: numba, numpy

        for text in values or ():
            key, sep, _ = str(text).partition("=")
            if not sep or not key.strip():
                continue  # the option's own parser says what it expects
            try:
                state_entry(key.strip())
            except ValueError as exc:
                raise click.ClickException(f"{option} {text!r}: {exc}") from None
        return values

    return callback


def _parse_axes(texts, configs):
    """Basin axes per config (checked against each one's state: one body's blocks, a tree's
    bodies); ClickException if invalid."""
    if not texts:
        return {}
    if len(texts) != 2:
        raise click.UsageError(f"--basin: give it exactly twice (two axes of the slice), found {len(texts)}")
    from rbstab.analysis import BasinAxis  # heavy: numba, numpy
    from rbstab.analysis.runs import check_axes  # heavy: numba, numpy

    axes, problems = {}, []
    for config in configs:
        try:
            axes[config.name] = [BasinAxis.parse(t) for t in texts]
            check_axes(config, axes[config.name])
        except ValueError as exc:
            problems.append(f"{config.name}: {exc}")
    if problems:
        raise click.ClickException(problems[0] if len(problems) == 1 else "invalid --basin\n" + "\n".join(problems))
    return axes


def _check_boundary_layer(configs, boundary_layer) -> None:
    """--boundary-layer against every config (only one body's pure sign law takes it)."""
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


def _vector(option: str, text: str) -> list[float]:
    """Three numbers of ``X,Y,Z``; UsageError naming the option otherwise."""
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3:
        raise click.UsageError(f"{option}: found {text!r}; expected three numbers X,Y,Z")
    return values


def _push_options(push, point, n_directions, directions, at, push_max, tol, rungs, ranges, distribution, draws,
                  seed, confidence) -> tuple[dict | None, dict | None]:
    """The keyword arguments of the push analysis and the basin stability (None: not asked
    for); UsageError for options that do not go together or bad values (one line each)."""
    from rbstab.analysis.push import check_push_options, parse_push_range  # heavy: numpy

    if push is None:
        for name, value in (("--push-point", point), ("--push-directions", n_directions),
                            ("--push-direction", directions), ("--push-max", push_max)):
            if value:
                raise click.UsageError(f"{name}: give it with --push force|torque")
        if distribution is not None:
            raise click.UsageError("--push-distribution: give the quantity pushed with --push force|torque")
    if directions and n_directions is not None:
        raise click.UsageError("--push-directions and --push-direction: give one of the two")
    if ranges and distribution is not None:
        raise click.UsageError("--basin-stability and --push-distribution: give one of the two")
    if (ranges or distribution is not None) and draws < 1:
        raise click.UsageError(f"-n: found {draws}; expected an integer >= 1 (draws)")
    point = _vector("--push-point", point) if point else None
    given = [_vector("--push-direction", d) for d in directions]
    push_options = stability = None
    try:
        if push is not None and (distribution is None or n_directions is not None or given):
            push_options = {"kind": push, "directions": given or (n_directions if n_directions is not None else 64),
                            "point": point, "at": at, "push_max": push_max, "tol": tol, "rungs": rungs, "seed": seed}
            check_push_options(push, **{k: v for k, v in push_options.items() if k not in ("kind", "seed")})
        if distribution is not None:
            check_push_options(push, point=point, at=at)
            stability = {"push": push, "push_range": parse_push_range(distribution), "point": point, "at": at,
                         "draws": draws, "seed": seed, "confidence": confidence}
        elif ranges:
            stability = {"ranges": list(ranges), "draws": draws, "seed": seed, "confidence": confidence}
    except ValueError as exc:
        raise click.UsageError(str(exc))
    return push_options, stability


def _check_push_targets(configs, ranges) -> None:
    """--basin-stability entries against every config's states (one line each)."""
    if not ranges:
        return
    from rbstab.analysis.runs import check_entries  # heavy: numba, numpy
    from rbstab.analysis.push import parse_ranges  # heavy: numba, numpy

    problems = []
    for config in configs:
        try:
            check_entries(config, [a for a, _, _ in parse_ranges(ranges)])
        except ValueError as exc:
            problems.append(f"{config.name}: {str(exc).replace('--basin ', '--basin-stability ')}")
    if problems:
        raise click.ClickException("\n".join(problems))


def _split_specs(paths) -> tuple[list[str], list[str]]:
    """(config paths, sweep-spec paths): a YAML file with a ``base`` is a sweep spec."""
    from rbstab.config import ConfigError  # heavy: pydantic
    from rbstab.config.yaml_io import read_yaml_file  # heavy: yaml

    configs, specs = [], []
    for path in paths:
        try:
            data = read_yaml_file(path)
        except ConfigError:
            data = None  # the config loader says what is wrong with it
        (specs if isinstance(data, dict) and "base" in data else configs).append(path)
    return configs, specs


def _chain_spec_bodies(specs, overrides) -> dict[str, list[str]]:
    """The bodies of each sweep spec of chains among ``specs`` (by path; the bodies every base
    has, in its first base's order); a spec that does not load is left to
    :func:`_analyse_spec`, which says why."""
    from rbstab.sweep import SweepSpecError, load_spec  # heavy: numba, pandas, pydantic

    out = {}
    for path in specs:
        try:
            spec = load_spec(path, overrides)
        except SweepSpecError:
            continue
        if spec.is_chain:
            names = [[b.get("name") for b in base.data.get("bodies") or [] if isinstance(b, dict)]
                     for base in spec.bases]
            out[path] = [n for n in names[0] if all(n in other for other in names[1:])]
    return out


def _analyse_spec(path, out: Path, push, stability, *, ratio, engine, jobs, samples, seed, certificate, overwrite,
                  overrides, as_json, verify=False) -> None:
    """Push recovery and basin stability at every configuration of the spec ``path``."""
    from rbstab.analysis.dataset import analysis_path, write_analysis  # heavy: numba, numpy
    from rbstab.analysis.recovery import RECOVERY_SUFFIX, recovery_across  # heavy: numba, numpy
    from rbstab.sweep import LocalExecutor, SweepSpecError, load_spec  # heavy: numba, pandas, pydantic

    console = get_console()
    try:
        spec = load_spec(path, overrides)
    except SweepSpecError as exc:
        raise spec_error(path, exc.errors)
    workers = LocalExecutor(jobs, task="a push analysis") if jobs > 1 and engine == DEFAULT_ENGINE else None
    try:
        with workers if workers is not None else contextlib.nullcontext():
            result = recovery_across(spec, push=push, basin_stability=stability, output=out, ratio=ratio,
                                     engine=engine, executor=workers, seed=seed, certificate=certificate,
                                     certificate_samples=samples, overwrite=overwrite, say=console.out,
                                     verify=verify)
    except SweepSpecError as exc:
        raise spec_error(path, exc.errors)
    except ValueError as exc:
        raise click.ClickException(f"{spec.name}: {exc}")
    show_config_warnings({r["run_id"]: r.get("warnings", []) for r in result.records}, len(result.records),
                         noun="points")
    target = write_analysis(result, analysis_path(out, f"{spec.name}{RECOVERY_SUFFIX}"), command_line=command_line())
    console.out(f"  -> {target} ({result.computed} computed now, {len(result.records) - result.computed} read back "
                f"from {result.folder})")
    if as_json:
        console.emit({"kind": "recovery", "name": result.name, "keys": result.keys,
                      "values": {k: v.tolist() for k, v in result.values.items()}, "points": result.records})


@click.command("analyze")
@click.argument("configs", nargs=-1, type=click.Path(dir_okay=False))
@output_option("results/analysis", "Folder for the <name>.analysis.nc files.")
@json_option
@click.option("--basin", "basin", multiple=True, metavar="KEY=LO:HI:N", callback=_state_entries("--basin"),
              help="An axis of the basin map, twice, e.g. --basin initial_state.omega.0=-60:60:41 "
              "--basin initial_state.omega.1=-60:60:41 (one simulation per grid point).")
@click.option("--robustness", "sweeps", multiple=True, type=click.Path(file_okay=False), metavar="SWEEP_DIR",
              help="A sweep folder of perturbed parameters: stable fraction and separating parameters. Repeatable.")
@set_option
@click.option("--boundary-layer", type=float, default=None, metavar="PHI",
              help="phi [m] analysed in place of the pure sign law of sliding (boundary_layer 0)  [default: 1e-3].")
@click.option("--samples", type=click.IntRange(min=1), default=10_000, show_default=True, metavar="N",
              help="States sampled for the certificate's dv/dt check (then refined by local searches and checked "
              "against simulated runs; single configs and sweep specs alike).")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of that sampling.")
@click.option("--no-certificate", is_flag=True, help="Skip the Lyapunov certificate.")
@click.option("--no-simulation", is_flag=True, help="Skip the simulation from the configured initial state.")
@click.option("--ratio", type=click.FloatRange(0, 1, min_open=True, max_open=True), default=1e-3,
              show_default=True, help="Converged: |v| <= RATIO |v(0)| from then on (basin map, settling time).")
@click.option("--basin-samples", type=click.IntRange(min=2), default=201, show_default=True, metavar="N",
              help="Samples per basin run (the time-to-converge resolution is t_end / (N - 1)).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None, metavar="N",
              help="Threads for a configuration's runs (basin map, pushes, basin stability); local processes "
              "for a spec's configurations  [default: all CPUs].")
@click.option("--engine", type=click.Choice([e.name for e in ENGINES.values() if e.compiled]), default=DEFAULT_ENGINE,
              show_default=True,
              help="The basin map's engine: the CPU's, or cuda: an NVIDIA GPU, one thread a grid point "
              "(pip install \"rbstab[cuda]\").")
@click.option("--confidence", type=click.FloatRange(0, 1, min_open=True, max_open=True), default=0.95,
              show_default=True, help="Confidence level of the Wilson interval (--robustness).")
@click.option("--push", type=click.Choice(["force", "torque"]), default=None,
              help="The smallest fatal push of each direction: an impulse of a force (at --push-point, inertial "
              "frame) or of a torque (body frame) on the body at rest at its equilibrium.")
@click.option("--push-point", default=None, metavar="X,Y,Z",
              help="Where a force push acts [m], body frame, from the centre of mass  [default: 0,0,0].")
@click.option("--push-body", default=None, metavar="NAME",
              help="A chain's body that is pushed (its frame for --push-point and a torque); chains only (a chain "
              "of one body: that body by default).")
@click.option("--push-directions", type=int, default=None, metavar="N",
              help="N quasi-uniform directions on the sphere (seeded by --seed), then a local search around the "
              "weakest  [default: 64].")
@click.option("--push-direction", "push_direction", multiple=True, metavar="X,Y,Z",
              help="A direction of its own (repeatable; no local search).")
@click.option("--push-at", type=float, default=0.0, show_default=True, metavar="T0", help="The push's time [s].")
@click.option("--push-max", type=float, default=None, metavar="P",
              help="The top of each direction's ladder [N s or N m s]  [default: found by doubling].")
@click.option("--push-tol", type=float, default=1e-3, show_default=True, metavar="TOL",
              help="Relative tolerance of each threshold.")
@click.option("--push-rungs", type=int, default=16, show_default=True, metavar="N",
              help="Rungs of each direction's ladder (a recovery above a fatal rung flags non-monotone recovery).")
@click.option("--basin-stability", "stability_ranges", multiple=True, metavar="KEY=LO:HI",
              callback=_state_entries("--basin-stability"),
              help="An initial-state entry drawn uniformly in [LO, HI] (repeatable): the fraction of -n draws that "
              "recover, with its Wilson interval.")
@click.option("--push-distribution", default=None, metavar="LO:HI",
              help="Basin stability over random pushes (with --push): a direction uniform on the sphere and a "
              "magnitude uniform in [LO, HI].")
@click.option("-n", "--draws", type=int, default=1000, show_default=True, metavar="N",
              help="Draws of the basin stability.")
@click.option("--verify", is_flag=True,
              help="Prove a sublevel bound {v <= c} positively invariant and inside the region of attraction "
              "(interval arithmetic, branch and bound; the reduced 6-state model of permanent with clipped "
              "torque limits: a one-body config, or a chain of one body on a permanent joint to the ground). Needs "
              "python-flint (pip install \"rbstab[verify]\").")
@click.option("--overwrite", is_flag=True,
              help="Replace an analysis file of another configuration of the same name (without it: refused).")
@console_options
def analyze(configs, output, as_json, basin, sweeps, overrides, boundary_layer, samples, seed, no_certificate,
            no_simulation, ratio, basin_samples, jobs, engine, confidence, push, push_point, push_directions,
            push_direction, push_at, push_max, push_tol, push_rungs, stability_ranges, push_distribution, draws,
            verify, overwrite, push_body) -> None:
    """Analyse the stability of the equilibrium of each CONFIG; write OUTPUT/<name>.analysis.nc.

    \b
    Per config: the equilibrium and rest check, the eigenvalues of the Jacobian there
    (damping ratio, natural frequency, time constant, verdict), the Lyapunov certificate
    (Hessians of v and dv/dt, dv/dt <= 0 on sampled states, a sublevel set of v as an
    estimate of an inner part of the region of attraction: sampled, refined by local
    search, checked against every run of the command) and, with --basin, the
    basin of attraction over a 2-D slice of initial states by simulation.
    With --robustness SWEEP_DIR: the stable fraction of a sweep's runs with its Wilson
    interval, and the parameters that separate stable from unstable runs.
    Every input is checked before anything runs. Method and limits: docs/analysis.md.
    With --push force|torque: the smallest fatal push of each direction (a ladder of magnitudes,
    then bisection; every direction in one batch per step on --engine). With --basin-stability
    KEY=LO:HI ... or --push-distribution LO:HI: the fraction of -n random perturbations that
    recover, with its Wilson interval.
    With --verify: a sublevel bound proven by interval arithmetic (docs/analysis.md, "verified").
    With --json: one object per config ("kind": "configuration") and per sweep ("robustness").
    """
    from rbstab.analysis import analyze as run_analysis  # heavy: numba, numpy
    from rbstab.analysis import robustness, write_analysis  # heavy: numba, numpy
    from rbstab.analysis.dataset import analysis_path  # heavy: numba, numpy
    from rbstab.analysis.text import describe, describe_robustness  # heavy: numba, numpy
    from rbstab.engine import ensure_compiled, kernel_groups  # heavy: numba, numpy
    from rbstab.sweep.executors import default_jobs  # heavy: multiprocessing (every command's start-up)

    if not configs and not sweeps:
        raise click.UsageError("give CONFIG files and/or --robustness SWEEP_DIR")
    push_options, stability_options = _push_options(push, push_point, push_directions, push_direction, push_at,
                                                    push_max, push_tol, push_rungs, stability_ranges,
                                                    push_distribution, draws, seed, confidence)
    if basin or push_options or stability_options:
        check_engine(engine)
    configs, specs = _split_specs(configs)
    loaded = load_configs(configs, overrides)
    trees = {c.name: list(c.chain.body_names) for c in loaded if is_chain(c)}
    bodies = {**trees, **_chain_spec_bodies(specs, overrides)}
    pushed = push_options is not None or (stability_options is not None and stability_options.get("push"))
    if push_body is not None and len(bodies) < len(loaded) + len(specs):
        raise click.UsageError("--push-body: names the body of a chain that is pushed; a one-body config has one")
    for what, names in bodies.items():
        if pushed and push_body not in names and not (push_body is None and len(names) == 1):
            found = "none" if push_body is None else f"'{push_body}'"
            raise click.UsageError(f"--push-body: found {found} for {what}; expected the body of the chain that is "
                                   f"pushed ({', '.join(names)})")
    if push_body is not None:
        if push_options is not None:
            push_options = {**push_options, "body": push_body}
        if stability_options is not None and stability_options.get("push") is not None:
            stability_options = {**stability_options, "body": push_body}
    if specs:
        if not (push_options or stability_options):
            raise click.UsageError(f"{specs[0]}: a sweep spec is analysed with --push and/or --basin-stability / "
                                   "--push-distribution (the curves over its configurations)")
        if basin or sweeps:
            raise click.UsageError("--basin and --robustness take configs, not a sweep spec")
    _check_push_targets(loaded, stability_ranges)
    axes = _parse_axes(basin, loaded)
    _check_boundary_layer(loaded, boundary_layer)
    if verify:
        _check_verifiable(loaded, specs)
    _check_sweeps(sweeps)
    console = get_console()
    say = console.out
    out = Path(output)
    if not overwrite:
        _check_targets(loaded, out)
    ensure_compiled(say=console.info, **kernel_groups(loaded, engine), analysis=True)
    for config in loaded:
        try:
            result = run_analysis(config, boundary_layer=boundary_layer, certificate=not no_certificate,
                                  samples=samples, seed=seed, simulate=not no_simulation,
                                  basin=axes.get(config.name), basin_samples=basin_samples, ratio=ratio,
                                  jobs=jobs or default_jobs(), engine=engine, push=push_options,
                                  basin_stability=stability_options, verify=verify)
        except ValueError as exc:
            raise click.ClickException(f"{config.name}: {exc}")
        path = write_analysis(result, analysis_path(out, config.name), command_line=command_line())
        for line in describe(result):
            say(line)
        say(f"  -> {path}")
        if as_json:
            console.emit({"kind": result.kind, **result.to_json()})
    for spec in specs:
        _analyse_spec(spec, out, push_options, stability_options, ratio=ratio, engine=engine,
                      jobs=jobs or default_jobs(), samples=samples, seed=seed, certificate=not no_certificate,
                      overwrite=overwrite, overrides=overrides, as_json=as_json, verify=verify)
    for folder in sweeps:
        result = robustness(folder, confidence=confidence)
        path = write_analysis(result, analysis_path(out, f"{result.sweep}.robustness"), command_line=command_line())
        for line in describe_robustness(result):
            say(line)
        say(f"  -> {path}")
        if as_json:
            console.emit({"kind": "robustness", **result.to_json()})


def _check_verifiable(loaded, specs) -> None:
    """--verify: every config covered by the verification (one line otherwise), before anything runs."""
    from rbstab.analysis.verify import NotVerifiable, check_verifiable  # heavy: numpy

    for config in loaded:
        try:
            check_verifiable(config)
        except NotVerifiable as exc:
            raise click.ClickException(f"{config.name}: --verify: {exc}")
