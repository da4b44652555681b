"""``rbstab`` command group: one module per subcommand, heavy imports inside commands."""

import click

from rbstab import __version__

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
    """


cli.add_command(run)
cli.add_command(validate)
cli.add_command(show)
cli.add_command(report)
cli.add_command(sweep)


def main() -> None:
    """The ``rbstab`` console script: :func:`cli`, then an immediate process exit.

    Once the command has finished (its files closed and renamed into place, its output
    printed), the interpreter's teardown only frees memory: unloading numpy, h5py and
    pydantic and running the libraries' exit hooks takes ~0.1 s, a noticeable share of a
    one-shot sweep or run. So the exit status of the command is passed to ``os._exit``
    after flushing stdout and stderr. An exception click does not handle (a bug) still
    exits through Python, with its traceback.
    """
    import os
    import sys

    try:
        cli.main(prog_name="rbstab")  # standalone: always ends in SystemExit
    except SystemExit as exc:
        code = exc.code
    else:  # pragma: no cover - click's standalone mode always exits
        code = 0
    if code is None:
        code = 0
    elif not isinstance(code, int):
        print(code, file=sys.stderr)  # what Python prints for sys.exit("message")
        code = 1
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # a closed or broken pipe: nothing more to say
            pass
    os._exit(code)
