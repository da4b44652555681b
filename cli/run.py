"""``rbstab run``: integrate configs and write one HDF5 result per config (:func:`rbstab.api.run`)."""

from __future__ import annotations

import time
from pathlib import Path

import click

from rbstab.api import ResultExistsError, check_overwrite
from rbstab.api import run as run_one
from rbstab.resources import memory_problem
from rbstab.warning_codes import coded

from ._common import (MachineFault, NotComputed, command_line, load_configs, prepare_output, show_config_warnings,
                      stiffness_warnings)
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


def rate_check_text(summary: dict, path: Path) -> str:
    """``pass``, ``n/a``, or ``fail (<why>)`` (:func:`rbstab.diagnostics.file_rate_check_reason`,
    with the fastest mode of the run's linearisation at rest)."""
    from rbstab.diagnostics import file_rate_check_reason  # heavy: numpy, h5py

    check = str(summary.get("lyapunov_rate_check", "n/a"))
    if check != "fail":
        return check
    from rbstab.analysis.stiffness import fastest_rate  # heavy: numba, scipy

    try:
        return f"fail ({file_rate_check_reason(path, summary, fastest_rate)})"
    except (OSError, KeyError):
        return check


def _report(config, path: Path, mode: str) -> dict:
    """Print the run's line (or JSON object) from its file's attributes; return them."""
    import numpy as np  # heavy

    from rbstab.diagnostics import CONVERGED, outcome  # heavy: numpy
    from rbstab.io.hdf5 import read_attributes  # heavy: numpy

    console = get_console()
    attrs = read_attributes(path, verify=False)
    s = {k[len("summary_"):]: v for k, v in attrs.items() if k.startswith("summary_")}
    settled = outcome(attrs["status"], attrs["message"], s["lyapunov_initial"], s["lyapunov_final"],
                      s.get("max_lyapunov_increase"), disturbed=_disturbed(config.resolved))
    check = rate_check_text(s, path)
    variant = attrs["variant"]
    chain = variant == "chain"  # a tree's file (of any number of bodies) names its joints
    if console.json:
        console.emit({"name": config.name, "path": str(path), "variant": variant, "status": attrs["status"],
                      "converged": settled == "converged", "outcome": settled, "message": attrs["message"],
                      "wall_time": attrs["wall_time"], "config_hash": attrs["config_hash"],
                      "replaced": _REPLACED[mode], "summary": s,
                      "rate_check_reason": check[len("fail ("):-1] if check.startswith("fail (") else None})
    what = f"a chain of {_bodies(len(attrs['joints'].split(',')))}" if chain else variant
    console.out(
        f"{config.name}: {attrs['status']}, {settled} ({what}, {attrs['wall_time']:.3g} s) "
        f"v {s['lyapunov_initial']:.4g} -> {s['lyapunov_final']:.4g} J, "
        f"max dv/dt {s['max_lyapunov_rate']:.3g} W, max|E{'_j' if chain else ''}| "
        f"{np.max(s['max_abs_constraint_error']):.3g} m, rate check {check} -> {path}"
    )
    console.detail("  solver " + ", ".join(f"{k[len('solver_'):]} {v}" for k, v in attrs.items()
                                          if k.startswith("solver_") and k != "solver_message"))
    if attrs["status"] == "success" and settled != CONVERGED:
        _why_not_converged(config, s)
    return attrs


def _why_not_converged(config, summary: dict) -> None:
    """What a run that reached t_end without converging may hide: v ended above v(0) with
    nothing feeding it energy, and a body under gravity without an admissible region (W009)."""
    from rbstab.diagnostics import risen_without_disturbance, unbounded_fall_note  # heavy: numpy

    console = get_console()
    if not _disturbed(config.resolved):
        risen = risen_without_disturbance(summary["lyapunov_initial"], summary["lyapunov_final"])
        if risen:
            click.echo(f"  {config.name}: {risen}", err=True)
    note = unbounded_fall_note(config)
    if note is not None:
        console.warn(note, config.name)


def _disturbed(resolved) -> bool:
    """Whether a resolved configuration (a mapping) has disturbances."""
    return bool(resolved.get("disturbances"))


def _bodies(n: int) -> str:
    return f"{n} bod{'y' if n == 1 else 'ies'}"


def _load_kernels(loaded) -> None:
    """Load the compiled kernels from numba's cache (and scipy's optimizers, which find the
    equilibrium under gravity) before the first run, so that its ``wall_time`` is its own
    (the load, ~0.4-0.7 s, is said with -v)."""
    from rbstab.engine import GROUPS, kernel_groups, warm_up  # heavy: numba, numpy
    from rbstab.simulator import is_sign_law, uses_compiled_engine  # heavy: numba, numpy

    groups = {**kernel_groups(loaded), "sign_law": any(is_sign_law(c) for c in loaded)}  # either spelling
    groups["engine"] = kernel_groups([c for c in loaded if uses_compiled_engine(c, "compiled")])["one_body"]
    parts = [p for group in ("engine", "sign_law", "chain", "solve_ivp") if groups[group] for p in GROUPS[group]]
    start = time.perf_counter()
    if any(c.chain.gravity.any() for c in loaded):
        import scipy.optimize  # noqa: F401  (heavy: scipy) the equilibrium under gravity
    if parts:
        warm_up(",".join(parts))
    if parts or any(c.chain.gravity.any() for c in loaded):
        get_console().detail(f"compiled kernels loaded in {time.perf_counter() - start:.2f} s "
                             "(not in the runs' wall time)")


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

    Each line says the solver's status (success: t_end reached) and the run's outcome:
    converged (v(t_end) <= 0.001 of the energy it had to lose, the rule of sweeps), still
    settling (a longer t_end, other gains), moving away (v(t_end) < 0), fell or could not be
    computed (README, "What a run prints"). With --json: one object per config ("name",
    "path", "status", "converged", "outcome", "message", "summary", "rate_check_reason",
    "replaced": null, "identical" or "other").

    Every config is validated, and the output folder checked, before the first one runs.
    A result file made from another configuration (another config_hash) is not replaced
    unless --overwrite; one of the identical configuration is run again and replaced.
    A run that fell (gimbal lock, the admissible region left) is a result: its line says
    "fell at t = ...", its file has status "failed" and the reason, and the command exits 0.
    Exits with status 3 when a run could not be computed (solver failure, non-finite state,
    step or wall-time limit; its file is written too, with the reason). A file that cannot
    be written (full disk, read-only folder) stops the command with one line (status 4);
    files written before are complete, and no temporary file is left.
    """
    from rbstab.engine import ensure_compiled, kernel_groups  # heavy: numba, numpy
    from rbstab.io.atomic import describe_os_error  # heavy at start-up: hashlib, socket
    from rbstab.engine.status import computed  # heavy: numba, numpy (rbstab.engine)
    from rbstab.simulator import is_sign_law  # heavy: numba, numpy

    if method is not None:
        overrides = (*overrides, f"simulation.method={method}")
    loaded = load_configs(configs, overrides)
    _check_memory(loaded)
    out = Path(output)
    how = _check_targets(loaded, out, overwrite)
    prepare_output(out, [f"{c.name}.h5" for c in loaded])
    ensure_compiled(say=get_console().info, **kernel_groups(loaded), sign_law=any(is_sign_law(c) for c in loaded),
                    analysis=not get_console().silences("W008"))
    _load_kernels(loaded)
    show_config_warnings(stiffness_warnings(loaded), len(loaded))
    not_computed = 0
    for written, config in enumerate(loaded):
        try:
            path = run_one(config, out, overwrite=True, command_line=command_line())
        except OSError as exc:
            raise MachineFault(f"{describe_os_error(exc)} ({written} of {len(loaded)} results written)")
        attrs = _report(config, path, how[config.name])
        if attrs["status"] != "success":
            not_computed += not computed(attrs["status"], attrs["message"])
            click.echo(f"  {config.name}: {attrs['message']}", err=True)
    if not_computed:
        raise NotComputed(f"{not_computed} of {len(loaded)} runs could not be computed (written with the reason)")
