"""``rbstab`` command group: one module per subcommand, heavy imports inside commands.

Exit status of every command (``_common.EXIT_*``): 0 done, every run computed, whatever
its physics (a run that fell is a result; also when the reader of stdout closed it early,
``rbstab show ... | head``); 1 invalid input; 2 a usage error; 3 runs that could not be
computed (a solver failure, a non-finite state, a step, wall-time or switching limit, an
exception); 4 a fault of the machine (full disk, read-only or missing output folder, an
unreachable scheduler); each reported in one line without a traceback; 130 interrupted by
Ctrl-C (SIGINT), 143 by SIGTERM, after what was finished has been saved.
"""

import atexit
import gc
import os
import signal
import sys

import click

from rbstab import __version__

from ._common import MachineFault
from .analyze import analyze
from .importer import import_
from .animate import animate
from .report import report
from .run import run
from .sensitivity import sensitivity
from .show import show
from .sweep import sweep
from .tune import tune
from .validate import validate


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (everything that cleans up after an interrupt runs),
    with the exit status 128 + 15."""

    exit_code = 143


def _terminate(signum, frame) -> None:
    raise Terminated()


#: What an interrupted command leaves (after "interrupted: "), by subcommand; the default
#: for the others.
_AFTER_INTERRUPT = {
    "sweep": "finished runs are saved and the index is up to date; run the same command again to resume",
}
_AFTER_INTERRUPT_DEFAULT = "results finished before are saved and complete; run the same command again to finish"


class _Group(click.Group):
    """The command group, turning faults into one line and interrupts into 130 / 143."""

    def make_context(self, info_name, args, parent=None, **extra) -> click.Context:
        try:
            return super().make_context(info_name, args, parent=parent, **extra)
        except KeyboardInterrupt as exc:  # while the command line is read: nothing started yet
            click.echo("\ninterrupted", err=True)
            sys.exit(getattr(exc, "exit_code", 130))

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as exc:
            after = _AFTER_INTERRUPT.get(ctx.invoked_subcommand, _AFTER_INTERRUPT_DEFAULT)
            click.echo(f"\ninterrupted: {after}", err=True)
            ctx.exit(getattr(exc, "exit_code", 130))
        except BrokenPipeError:  # stdout closed by its reader (rbstab show ... | head): done, quietly
            _quiet_stdout()
            ctx.exit(0)
        except OSError as exc:  # a full disk, a read-only folder...: in words, not a traceback
            from rbstab.io.atomic import describe_os_error  # heavy at start-up: hashlib, socket

            raise MachineFault(describe_os_error(exc)) from None


def _quiet_stdout() -> None:
    """Point stdout at /dev/null, so that flushing it at exit does not fail again on the
    closed pipe (the standard library's advice for SIGPIPE)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no real stdout (a test runner's capture)
        pass


@click.group(cls=_Group)
@click.version_option(__version__, prog_name="rbstab")
def cli() -> None:
    """Lyapunov stability of constrained and embedded rigid bodies.

    \b
    rbstab run configs/paper/case3_embedded.yaml     # -> results/case3_embedded.h5
    rbstab show results/case3_embedded.h5
    rbstab validate configs/paper/*.yaml
    rbstab analyze configs/paper/case3_embedded.yaml  # -> results/analysis/case3_embedded.analysis.nc

    Every command takes -q/-v (less/more output) and --no-warn CODE (warning codes:
    README, section Warnings); run, show, validate, analyze, sensitivity and tune take --json. Also
    "python -m rbstab". Shell completion (bash): eval "$(_RBSTAB_COMPLETE=bash_source rbstab)".
    """


cli.add_command(run)
cli.add_command(validate)
cli.add_command(show)
cli.add_command(report)
cli.add_command(sweep)
cli.add_command(analyze)
cli.add_command(sensitivity)
cli.add_command(tune)
cli.add_command(animate)
cli.add_command(import_)


def main() -> None:
    """The ``rbstab`` console script (SIGTERM is handled like Ctrl-C).

    At exit, after every other ``atexit`` handler (they run last-registered first), the
    objects alive are frozen (:func:`gc.freeze`): the interpreter's shutdown still runs
    every handler and clears every module (reference counting frees what it frees), but
    its cyclic garbage collections (~50 ms each, over the objects of numba, numpy, pydantic
    and h5py) skip them; objects left in reference cycles go with the process, as Python
    allows. Those collections take ~0.2 s of ``rbstab run``'s ~0.9 s (docs/performance.md).
    Results are closed and renamed into place by their ``with`` blocks long before.
    """
    signal.signal(signal.SIGTERM, _terminate)
    atexit.register(gc.freeze)
    cli.main(prog_name="rbstab")
