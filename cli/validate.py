"""``rbstab validate``: check configs without running them."""

from __future__ import annotations

import click

from ._common import load_configs
from .options import set_option


@click.command("validate")
@click.argument("configs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@set_option
def validate(configs, overrides) -> None:
    """Validate CONFIG... (with --set overrides applied); exit non-zero if any is invalid."""
    for config in load_configs(configs, overrides):
        sim = config.simulation
        click.echo(
            f"ok: {config.name} ({config.variant}, t_end {sim.t_end:g} s, "
            f"{sim.n_samples} samples, {sim.method})"
        )
