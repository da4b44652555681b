"""``rbstab run``: integrate configs and write one HDF5 result per config."""

from __future__ import annotations

from pathlib import Path

import click

from ._common import command_line, load_configs, prepare_output
from .options import method_option, output_option, set_option


@click.command("run")
@click.argument("configs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@output_option("results", "Folder for the <name>.h5 result files.")
@set_option
@method_option
def run(configs, output, overrides, method) -> None:
    """Run CONFIG... and write OUTPUT/<name>.h5 for each.

    Every config is validated, and the output folder checked, before the first one runs.
    Exits with status 1 when a run failed (gimbal lock, solver failure, non-finite state,
    step or wall-time limit); its file is still written with status "failed" and the
    reason. A file that cannot be written (full disk, read-only folder) stops the command
    with one line; files written before are complete, and no temporary file is left.
    """
    from rbstab.io.atomic import describe_os_error
    from rbstab.io.hdf5 import write_result
    from rbstab.jit import ensure_compiled
    from rbstab.resources import memory_problem
    from rbstab.simulate import is_sign_law, simulate

    if method is not None:
        overrides = (*overrides, f"simulation.method={method}")
    loaded = load_configs(configs, overrides)
    for config in loaded:
        refusal, note = memory_problem(config.simulation.n_samples, config.name)
        if refusal:
            raise click.ClickException(refusal)
        if note:
            click.echo(f"note: {note}", err=True)
    out = Path(output)
    prepare_output(out, [f"{c.name}.h5" for c in loaded])
    failed = written = 0
    ensure_compiled(say=lambda line: click.echo(line, err=True), sign_law=any(is_sign_law(c) for c in loaded))
    for config in loaded:
        result = simulate(config)
        try:
            path = write_result(result, out / f"{config.name}.h5", command_line=command_line())
        except OSError as exc:
            raise click.ClickException(f"{describe_os_error(exc)} ({written} of {len(loaded)} results written)")
        written += 1
        s = result.summary
        max_e = max(s["max_abs_constraint_error"])
        click.echo(
            f"{config.name}: {result.status} ({config.variant}, {result.wall_time:.2f} s) "
            f"v {s['lyapunov_initial']:.4g} -> {s['lyapunov_final']:.4g} J, "
            f"max dv/dt {s['max_lyapunov_rate']:.3g} W, max|E| {max_e:.3g} m, "
            f"rate check {s['lyapunov_rate_check']} -> {path}"
        )
        if not result.ok:
            failed += 1
            click.echo(f"  {config.name}: {result.message}", err=True)
    if failed:
        raise click.ClickException(f"{failed} of {len(loaded)} runs failed")
