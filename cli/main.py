"""``rbstab`` command group: one module per subcommand, heavy imports inside commands."""

import click

from rbstab import __version__

from .analyze import analyze
from .report import report
from .run import run
from .show import show
from .sweep import sweep
from .validate import validate


@click.group()
@click.version_option(__version__, prog_name="rbstab")
def cli() -> None:
    """Lyapunov stability of constrained and embedded rigid bodies.

    \b
    rbstab run configs/paper/case3_embedded.yaml     # -> results/case3_embedded.h5
    rbstab show results/case3_embedded.h5
    rbstab validate configs/paper/*.yaml
    rbstab analyze configs/paper/case3_embedded.yaml  # -> results/analysis/case3_embedded.analysis.nc
    """


cli.add_command(run)
cli.add_command(validate)
cli.add_command(show)
cli.add_command(report)
cli.add_command(sweep)
cli.add_command(analyze)


def main() -> None:
    """The ``rbstab`` console script."""
    cli.main(prog_name="rbstab")
