"""``rbstab run``: integrate configs and write one HDF5 result per config (:func:`rbstab.api.run`)."""

from __future__ import annotations

from pathlib import Path

import click

from rbstab.api import ResultExistsError, check_overwrite
from rbstab.api import run as run_one
from rbstab.resources import memory_problem
from rbstab.warning_codes import coded

from ._common import command_line, load_configs, prepare_output
from .console import get_console
from .options import console_options, json_option, method_option, output_option, set_option


def _check_memory(loaded) -> None:
    """Refuse runs that do not fit in memory; warn (W003) about large ones."""
    for config in loaded:
        refusal, note = memory_problem(config.simulation.n_samples, config.name)
        if refusal:
            raise click.ClickException(refusal)
        if note:
            get_console().warn(coded("W003", f"simulation.n_samples: {note}"))


def _check_targets(loaded, out: Path, overwrite: bool) -> dict[str, str]:
    """How each result file is written (``new``, ``identical``, ``replace``); every refusal
    at once as a ClickException, before anything runs."""
    how, refused = {}, []
    for config in loaded:
        try:
            how[config.name] = check_overwrite(config, out / f"{config.name}.h5", overwrite=overwrite)
        except ResultExistsError as exc:
            refused.append(str(exc))
    if refused:
        raise click.ClickException("\n".join(refused) + "\n(nothing was run)")
    for name, mode in how.items():
        path = out / f"{name}.h5"
        if mode == "identical":
            get_console().info(f"{name}: {path} holds a result of the identical configuration; run again and replaced")
        elif mode == "replace":
            get_console().info(f"{name}: {path} holds another result; replaced (--overwrite)")
    return how


#: check_overwrite's answer -> the "replaced" field of --json: what was there before.
_REPLACED = {"new": None, "identical": "identical", "replace": "other"}


def _report(config, path: Path, mode: str) -> dict:
    """Print the run's line (or JSON object) from its file's attributes; return them."""
    from rbstab.io.hdf5 import read_attributes  # heavy: numpy

    console = get_console()
    attrs = read_attributes(path, verify=False)
    s = {k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")}
    if console.json:
        console.emit({"name": config.name, "path": str(path), "variant": config.variant, "status": attrs["status"],
                      "message": attrs["message"], "wall_time": attrs["wall_time"], "config_hash": attrs["config_hash"],
                      "replaced": _REPLACED[mode], "summary": s})
    console.out(
        f"{config.name}: {attrs['status']} ({config.variant}, {attrs['wall_time']:.3g} s) "
        f"v {s['lyapunov_initial']:.4g} -> {s['lyapunov_final']:.4g} J, "
        f"max dv/dt {s['max_lyapunov_rate']:.3g} W, max|E| {max(s['max_abs_constraint_error']):.3g} m, "
        f"rate check {s['lyapunov_rate_check']} -> {path}"
    )
    console.detail("  solver " + ", ".join(f"{k[len('solver_'):]} {v}" for k, v in attrs.items()
                                          if k.startswith("solver_") and k != "solver_message"))
    return attrs


@click.command("run")
@click.argument("configs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@output_option("results", "Folder for the <name>.h5 result files.")
@set_option
@method_option
@click.option("--overwrite", is_flag=True,
              help="Replace result files made from another configuration (without it they are refused).")
@json_option
@console_options
def run(configs, output, overrides, method, overwrite, as_json) -> None:
    """Run CONFIG... and write OUTPUT/<name>.h5 for each.

    With --json: one object per config ("name", "path", "status", "message", "summary",
    "replaced": null, "identical" or "other").

    Every config is validated, and the output folder checked, before the first one runs.
    A result file made from another configuration (another config_hash) is not replaced
    unless --overwrite; one of the identical configuration is run again and replaced.
    Exits with status 1 when a run failed (gimbal lock, solver failure, non-finite state,
    step or wall-time limit); its file is still written with status "failed" and the
    reason. A file that cannot be written (full disk, read-only folder) stops the command
    with one line; files written before are complete, and no temporary file is left.
    """
    from rbstab.engine import ensure_compiled  # heavy: numba, numpy
    from rbstab.io.atomic import describe_os_error  # heavy at start-up: hashlib, socket
    from rbstab.simulator import is_sign_law  # heavy: numba, numpy

    if method is not None:
        overrides = (*overrides, f"simulation.method={method}")
    loaded = load_configs(configs, overrides)
    _check_memory(loaded)
    out = Path(output)
    how = _check_targets(loaded, out, overwrite)
    prepare_output(out, [f"{c.name}.h5" for c in loaded])
    ensure_compiled(say=get_console().info, sign_law=any(is_sign_law(c) for c in loaded))
    failed = 0
    for written, config in enumerate(loaded):
        try:
            path = run_one(config, out, overwrite=True, command_line=command_line())
        except OSError as exc:
            raise click.ClickException(f"{describe_os_error(exc)} ({written} of {len(loaded)} results written)")
        attrs = _report(config, path, how[config.name])
        if attrs["status"] != "success":
            failed += 1
            click.echo(f"  {config.name}: {attrs['message']}", err=True)
    if failed:
        raise click.ClickException(f"{failed} of {len(loaded)} runs failed")
