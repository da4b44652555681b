"""Helpers for the subcommands: config loading with user-facing errors, warnings to stderr."""

from __future__ import annotations

import shlex
import sys
import warnings
from collections.abc import Sequence

import click


def command_line() -> str:
    """This process's command line, shell-quoted."""
    return " ".join(shlex.quote(a) for a in sys.argv)


def load_configs(paths: Sequence[str], overrides: Sequence[str]):
    """Load and validate every config before anything runs.

    Prints warnings (e.g. an impossible inertia) to stderr; raises ``click.ClickException``
    listing every invalid file, so the CLI exits non-zero without a traceback.
    """
    from rbstab.config import ConfigError, PhysicalPlausibilityWarning, load_config

    configs, problems = [], []
    for path in paths:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PhysicalPlausibilityWarning)
            try:
                configs.append(load_config(path, overrides))
            except ConfigError as exc:
                problems.append(str(exc) if exc.source else f"in {path}:\n{_indent(str(exc))}")
        for w in caught:
            if issubclass(w.category, PhysicalPlausibilityWarning):
                click.echo(f"warning: {w.message}", err=True)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
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


def _indent(text: str) -> str:
    return "\n".join("  " + line for line in text.splitlines())
