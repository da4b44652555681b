"""Helpers for the subcommands: config loading with user-facing errors and warnings, output folders."""

from __future__ import annotations

import os
import shlex
import sys
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path

import click

from rbstab.api import load_config
from rbstab.engine.registry import get_engine

from .console import get_console


#: Exit statuses of every command (docs/reliability.md, section 5). A run that fell
#: (gimbal lock, the admissible region left) was computed: its command exits 0.
EXIT_INVALID_INPUT = 1
EXIT_USAGE = 2  # click's
EXIT_NOT_COMPUTED = 3
EXIT_MACHINE_FAULT = 4


class NotComputed(click.ClickException):
    """Runs that could not be computed (a solver failure, a non-finite state, a step,
    wall-time or switching limit, an exception): one line, status 3."""

    exit_code = EXIT_NOT_COMPUTED


class MachineFault(click.ClickException):
    """A fault of the machine (a full disk, a read-only or missing output folder, a name too
    long for the file system, an unreachable scheduler): one line, status 4."""

    exit_code = EXIT_MACHINE_FAULT


def command_line() -> str:
    """This process's command line, shell-quoted."""
    return " ".join(shlex.quote(a) for a in sys.argv)


def load_one(path: str, overrides: Sequence[str]):
    """``(config, error, warnings)`` of one config file: the RunConfig (one
    body's or a tree's) or None, the ConfigError or None, and its coded warning lines
    (:mod:`rbstab.warning_codes`)."""
    from rbstab.config import ConfigError, PhysicalPlausibilityWarning  # heavy: yaml

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PhysicalPlausibilityWarning)
        try:
            config = load_config(path, overrides)
        except ConfigError as exc:
            return None, exc, []
    for w in caught:
        if not issubclass(w.category, PhysicalPlausibilityWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return config, None, list(config.warnings)


def config_error_text(path: str, error) -> str:
    """A ConfigError as the CLI prints it: ``in <file>:`` and one line per problem."""
    return str(error) if error.source else f"in {path}:\n{_indent(str(error))}"


def show_config_warnings(found: dict[str, list[str]], n_configs: int, noun: str = "configs") -> None:
    """Each distinct warning once, with the configs it concerns: ``found`` maps a config's
    name to its warning lines (``noun``: what to count them as, ``"3 of 5 points"``)."""
    names: dict[str, list[str]] = {}
    for name, lines in found.items():
        for line in lines:
            names.setdefault(line, []).append(name)
    console = get_console()
    for line, which in names.items():
        where = "" if n_configs == 1 else which[0] if len(which) == 1 else f"{len(which)} of {n_configs} {noun}"
        console.warn(line, where)


def _stiffness_checked(*, one_body: bool, chain: bool, sign_law: bool = False, solve_ivp: bool = False) -> bool:
    """Whether W008 is to be checked (not silenced); if so, the kernels the linearisation
    runs (the analysis's: a tree's rest state) are compiled first where they are not yet
    (said as ``rbstab run`` says it)."""
    console = get_console()
    if console.silences("W008"):
        return False
    from rbstab.engine import ensure_compiled  # heavy: numba, numpy

    ensure_compiled(say=console.info, one_body=one_body, sign_law=sign_law, chain=chain, analysis=True,
                    solve_ivp=solve_ivp)
    return True


def stiffness_warnings(configs) -> dict[str, list[str]]:
    """Each config's W008 line (a stiff mode holds its explicit method to very many steps:
    :func:`rbstab.analysis.stiffness.stiffness_warning`, one linearisation each, 4-120 ms),
    by name: ``{name: [line]}`` for those that have one; none where W008 is silenced."""
    if not configs:
        return {}
    from rbstab.engine import kernel_groups  # heavy: numba, numpy

    if not _stiffness_checked(**kernel_groups(configs)):
        return {}
    from rbstab.analysis.stiffness import stiffness_warning  # heavy: numba, scipy

    return {c.name: [line] for c in configs if (line := stiffness_warning(c))}


def template_stiffness_warnings(loaded, table, *, sign_law: bool = False) -> list[str]:
    """The W008 lines of a planned sweep's templates
    (:func:`rbstab.analysis.stiffness.sweep_stiffness_warnings`); none where W008 is silenced.
    ``sign_law``: compile the sign law's kernels too where they are not yet (a sweep that
    runs compiles them all at once)."""
    if not _stiffness_checked(one_body=loaded.may_run_one_body, chain=loaded.may_run_tree, sign_law=sign_law):
        return []
    from rbstab.analysis.stiffness import sweep_stiffness_warnings  # heavy: numba, scipy

    return sweep_stiffness_warnings(table)


def load_configs(paths: Sequence[str], overrides: Sequence[str]):
    """Load and validate every config (one body's or a tree's) before anything runs.

    Shows each distinct warning once (e.g. an impossible inertia, ``W001``) on stderr;
    raises ``click.ClickException`` listing every invalid file, so the CLI exits non-zero
    without a traceback.
    """
    configs, problems, found = [], [], {}
    for path in paths:
        config, error, lines = load_one(path, overrides)
        if error is not None:
            problems.append(config_error_text(path, error))
            continue
        configs.append(config)
        found[config.name] = lines
    show_config_warnings(found, len(paths))
    if problems:
        raise click.ClickException("invalid configuration\n" + "\n".join(problems))
    names = [c.name for c in configs]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise click.ClickException(
            f"several configs have the same name {dups}: their result files would overwrite "
            "each other; give each a distinct 'name' (or --set name=...)"
        )
    return configs


def spec_error(path, errors: Sequence[str]) -> click.ClickException:
    """An invalid sweep spec as the CLI prints it: one problem on one line
    (``invalid sweep spec <path>: <problem>``), several one line each under that header."""
    if len(errors) == 1:
        return click.ClickException(f"invalid sweep spec {path}: {errors[0]}")
    return click.ClickException(f"invalid sweep spec {path}\n" + _indent("\n".join(errors)))


def _indent(text: str) -> str:
    return "\n".join("  " + line for line in text.splitlines())


def prepare_output(folder: Path, names: Sequence[str] = ()) -> None:
    """Make sure results can be written to ``folder`` before any work starts.

    Creates it, removes temporaries left there by killed writers, writes and removes a
    probe file, and checks each file name against the file system's limit. Raises
    ``click.ClickException`` with one line (a file in the way, a read-only or foreign
    folder, a name too long).
    """
    from rbstab.io.atomic import describe_os_error, remove_stale_temporaries  # heavy at start-up: hashlib, socket

    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not folder.is_dir():
            raise FileExistsError(17, "exists and is not a folder", str(folder))
        removed = remove_stale_temporaries(folder)
        if removed:
            get_console().info(f"removed {removed} temporary file(s) left in {folder} by interrupted runs")
        fd, probe = tempfile.mkstemp(prefix=".rbstab-probe-", suffix=".tmp", dir=folder)
        os.close(fd)
        os.unlink(probe)
        limit = os.pathconf(folder, "PC_NAME_MAX")
    except OSError as exc:
        raise MachineFault(describe_os_error(exc)) from None
    for name in names:
        longest = len(f".{name}.{2**22}@0000.abcdefgh.tmp".encode())  # its temporary while written
        if longest > limit:
            raise MachineFault(
                f"cannot write {folder / name}: the name is too long for this file system "
                f"({longest} bytes with its temporary suffix, at most {limit}); shorten the run's name"
            )


def check_engine(name: str | None) -> None:
    """``--engine NAME`` where it cannot run (a GPU engine without its GPU): one line naming
    what is missing, before anything starts or is written."""
    why = get_engine(name).unavailable()
    if why:
        raise click.ClickException(why)
