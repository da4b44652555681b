"""``rbstab validate``: check configs and sweep specs without running them."""

from __future__ import annotations

import click

from ._common import load_configs
from .options import set_option


def _is_spec(path: str) -> bool:
    from rbstab.config import ConfigError
    from rbstab.config.yaml_io import read_yaml_file

    try:
        data = read_yaml_file(path, "file")
    except ConfigError:
        return False  # reported by the config loader
    return isinstance(data, dict) and "base" in data


@click.command("validate")
@click.argument("configs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@set_option
def validate(configs, overrides) -> None:
    """Validate CONFIG... and sweep specs (with --set overrides applied); exit non-zero if any is invalid.

    A sweep spec (a file with a ``base`` key) is expanded: every run's config is validated.
    """
    specs = [c for c in configs if _is_spec(c)]
    problems = []
    for path in specs:
        from rbstab.sweep import SweepSpecError, expand, load_spec

        try:
            loaded = load_spec(path, overrides)
            runs = expand(loaded)
        except SweepSpecError as exc:
            problems.append(f"invalid sweep spec {path}\n" + "\n".join("  " + e for e in exc.errors))
            continue
        click.echo(f"ok: sweep {loaded.name} ({len(runs)} runs)")
    for config in load_configs([c for c in configs if c not in specs], overrides) if len(specs) < len(configs) else ():
        sim = config.simulation
        click.echo(
            f"ok: {config.name} ({config.variant}, t_end {sim.t_end:g} s, "
            f"{sim.n_samples} samples, {sim.method})"
        )
    if problems:
        raise click.ClickException("\n".join(problems))
