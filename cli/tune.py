"""``rbstab tune``: search gains that meet a specification best, by Optuna (rbstab.studies)."""

from __future__ import annotations

import click

from ._common import command_line, load_configs
from .console import get_console
from .options import console_options, keys_checked, study_options
from .sensitivity import study_error


@click.command("tune")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--trials", type=int, required=True, metavar="N",
              help="Complete trials the study should have (a resumed study runs the missing ones).")
@click.option("--minimize", "minimize", multiple=True, metavar="METRIC",
              help="A summary figure to minimize (docs/studies.md). Give one objective, or two for a Pareto front.")
@click.option("--maximize", "maximize", multiple=True, metavar="METRIC", help="A summary figure to maximize.")
@click.option("--subject-to", "subject_to", multiple=True, metavar="METRIC<=VALUE",
              help="A constraint, METRIC<=VALUE or METRIC>=VALUE, e.g. 'max_abs_constraint_error_z<=0.05' (a "
              "chain's: 'max_abs_constraint_error_hip_z<=0.01'). Repeatable.")
@click.option("--over", "over", multiple=True, metavar="KEY=DISTRIBUTION", callback=keys_checked("--over"),
              help="Uncertain bodies: each trial runs --over-n bodies drawn from these distributions "
              "(e.g. body.mass=scale_uniform:[0.8,1.2]; a chain's: bodies.0.mass=scale_uniform:[0.9,1.1]) and "
              "takes their worst case. Repeatable.")
@click.option("--over-n", "over_n", type=int, default=16, show_default=True, metavar="N",
              help="Bodies per trial with --over (drawn once, the same for every trial).")
@click.option("--over-seed", "over_seed", type=int, default=0, show_default=True, help="Seed of the --over draw.")
@click.option("--quantile", type=float, default=1.0, show_default=True, metavar="Q",
              help="With --over: the Q-quantile of the bodies' badness instead of the worst case (1).")
@click.option("--sampler", default="tpe", show_default=True, metavar="tpe|cmaes",
              help="After the space-filling start: multivariate TPE (constraints, two objectives) or CMA-ES "
              "with restarts (one objective).")
@click.option("--generation", type=int, default=None, metavar="K",
              help="Trials asked and integrated at once, as one batch  [default: 32 on the CPU, 2048 with "
              "--engine cuda; CMA-ES: its population, 4 + 3 ln d].")
@click.option("--startup", type=int, default=None, metavar="N",
              help="Space-filling trials first (scrambled Sobol')  [default: the generation, at least 16; 0: none].")
@click.option("--restarts", default="ipop", show_default=True, metavar="ipop|bipop|none",
              help="CMA-ES restarts once converged: doubled population (ipop) or alternating large and small "
              "populations (bipop).")
@click.option("-j", "--jobs", type=int, default=None, metavar="N",
              help="Threads integrating each generation of up to 1,024 runs on the compiled engine (larger, "
              "--executor local or another engine: worker processes)  [default: this process].")
@click.option("--executor", type=click.Choice(["local", "dask"]), default=None,
              help="Where a generation's runs are integrated, as for rbstab sweep  [default: this process, or "
              "threads of this process with -j].")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (implies --executor dask).")
@click.option("--storage", default=None, metavar="URL",
              help="Optuna storage URL, e.g. sqlite:///studies.db or postgresql://...  "
              "[default: Optuna's journal storage in the SQLite file OUTPUT/<name>/journal.db].")
@study_options
@console_options
def tune(config, trials, minimize, maximize, subject_to, over, over_n, over_seed, quantile, sampler, generation,
         startup, restarts, jobs, executor, scheduler, storage, vary, seed, name, overrides, engine, output, overwrite,
         as_json) -> None:
    """Search the --vary keys of CONFIG for the best value of --minimize/--maximize.

    \b
    rbstab tune configs/paper/case3_embedded.yaml --trials 100 \\
        --vary controller.k_c=scale_uniform:[0.25,4] --vary controller.l_c=scale_uniform:[0.25,4] \\
        --minimize lyapunov_final --subject-to 'max_abs_constraint_error_z<=0.1'

    CONFIG may be a chain (bodies and joints): its keys name a body or a joint by index or
    name (joints.hip.l_r.0, bodies.trunk.mass, also in --over), and its metrics are its
    figures per body or joint and axis, as its sweep's columns (max_abs_constraint_error_hip,
    final_theta_trunk_x); a generation's runs of one chain are integrated together.

    Trials come a generation at a time (space-filling first, then the sampler); each trial
    is one run (with --over, one per uncertain body), and a generation's runs are
    integrated as one batch. The study is kept in an Optuna storage: the same command
    again resumes it at its last finished generation, and several processes can work on
    one study. Writes OUTPUT/<name>/best.yaml (`rbstab run` takes it as it is), trials.csv
    and tuning.nc (`rbstab report OUTPUT/<name>` draws it). Options are checked before
    anything runs. With --json: the best value, the best parameters and the trial count.
    Manual: docs/studies.md.
    """
    from rbstab.studies import StudyInputError  # heavy: h5py, numba, numpy, pandas, pydantic, xarray, yaml
    from rbstab.studies import tune as run_tuning  # heavy: h5py, numba, numpy, pandas, pydantic, xarray, yaml

    (base,) = load_configs([config], overrides)
    console = get_console()
    try:
        result = run_tuning(base, vary, trials=trials, minimize=minimize, maximize=maximize, subject_to=subject_to,
                            over=over, over_n=over_n, over_seed=over_seed, quantile=quantile, sampler=sampler,
                            seed=seed, storage=storage, output=output, name=name, engine=engine,
                            generation=generation, startup=startup, restarts=restarts, jobs=jobs, executor=executor,
                            scheduler=scheduler, log=console.info, command_line=command_line(), overwrite=overwrite)
    except StudyInputError as exc:
        raise study_error(exc)
    record = result.record()
    objectives = ", ".join([*(f"min {m}" for m in minimize), *(f"max {m}" for m in maximize)])
    console.out(f"{result.name}: {result.n_trials} complete trials ({result.n_failed} failed); {objectives}")
    if result.best_trial is None:
        console.out("  no feasible trial")
    else:
        from rbstab.io.chunk import figure_attributes  # heavy: numpy (loaded by now)
        from rbstab.layout import CONFIG_QUANTITIES, display_units  # light; beside its heavy neighbour

        metrics = [*minimize, *maximize]
        values = result.best_values
        shown = ", ".join(f"{m} {v:.6g}" + (f" {u}" if (u := display_units(figure_attributes(m)[0]))
                                            not in ("", "1") else "") for m, v in zip(metrics, values))
        console.out(f"  best trial {result.best_trial}: {shown}")
        for key, value in result.best_params.items():
            q = CONFIG_QUANTITIES.get(key.split("[")[0])
            unit = f" {q.display_units}" if q is not None and q.units not in (None, "", "1") else ""
            console.out(f"    {key} = {value:.6g}{unit}" if isinstance(value, float) else f"    {key} = {value}")
        for line in result.at_edge:
            console.warn(line)
    console.out(f"  -> {result.folder}")
    if as_json:
        console.emit(record)
