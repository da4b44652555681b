"""Draw a report's figures and animations in worker processes (``rbstab report -j N``).

Each figure of a run, the comparison figures and each animation are drawn by one
function from picklable arguments (:class:`~rbstab.report.load.RunData`,
:class:`~rbstab.report.figures.FigureWriter`, numbers) that writes its own files and
returns what the page shows (:class:`~rbstab.report.figures.FigureFile`,
:class:`~rbstab.report.render.Animation`). Such :class:`Task` s are independent, so
:func:`draw` runs them in ``jobs`` local processes: a :class:`rbstab.sweep.LocalExecutor`,
whose processes fork from a server that has already imported matplotlib and the report's
modules (:data:`PRELOAD`); processes, because matplotlib is not thread-safe. The results
come back in the order of the tasks, whatever order they finish in, and a figure's files
are the same bytes whichever process drew it. With one job they are drawn in this
process, one after the other.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["Task", "draw", "PRELOAD"]

#: Modules the fork server imports before it forks the workers, so that each starts with
#: them (``tests/test_report.py`` imports each: the standard library skips one that fails).
PRELOAD = ("numpy", "h5py", "matplotlib.figure", "matplotlib.backends.backend_agg", "rbstab.report.figures",
           "rbstab.report.animate")


@dataclass(frozen=True)
class Task:
    """``fn(*args)``: a module-level function (workers import it by name) and picklable arguments."""

    fn: Callable[..., Any]
    args: tuple = ()


def _run(item: tuple[int, Task]) -> Any:
    return item[1].fn(*item[1].args)


def draw(tasks: Sequence[Task], jobs: int = 1) -> list:
    """The result of every task, in the order of ``tasks``.

    Parameters
    ----------
    tasks : sequence of Task
        Independent tasks; best with the longest first (they start in this order).
    jobs : int
        Worker processes, >= 1 (at most one per task); 1: every task in this process, one
        after the other.

    Returns
    -------
    list
        ``task.fn(*task.args)`` for each task.

    Raises
    ------
    Exception
        The exception of the first task to fail, as it raised it (in a worker: with the
        worker's traceback as its cause); the tasks in flight are dropped.
    rbstab.sweep.ExecutorError
        When the worker processes die (killed, out of memory) before finishing their tasks.
    """
    if jobs <= 1 or len(tasks) <= 1:
        return [task.fn(*task.args) for task in tasks]

    from concurrent.futures.process import BrokenProcessPool  # heavy: multiprocessing

    from ..sweep.executors import ExecutorError, LocalExecutor  # heavy: multiprocessing

    results: dict[int, Any] = {}
    with LocalExecutor(jobs, preload=PRELOAD, task="a report") as executor:
        executor.plan(len(tasks))
        try:
            for (index, _), result, error in executor.imap_unordered(_run, enumerate(tasks)):
                if isinstance(error, BrokenProcessPool):
                    raise ExecutorError(f"a worker process died (killed or crashed) while drawing the report: {error}")
                if error is not None:
                    raise error
                results[index] = result
        except BaseException:
            executor.abort()  # the tasks in flight are dropped
            raise
    return [results[i] for i in range(len(tasks))]
