"""The integration engines, one table: :data:`ENGINES` maps each engine's name to an
:class:`Engine` that says what it integrates, whether it can run here (and why not) and
its batch entry point. The simulator, the sweep's workers and runner, the basin map, the
studies and the command line ask this table; none compares an engine's name.

- ``compiled`` (the default): scipy's RK23, RK45 and DOP853 compiled with the model
  (:func:`rbstab.engine.integrate.integrate_chain_runs`), many runs per call, the steps
  ``solve_ivp`` takes.
- ``scipy`` (the reference): one :func:`scipy.integrate.solve_ivp` call per run, any method.
- ``cuda``: the compiled engine's steps on an NVIDIA GPU, one thread a run
  (:func:`rbstab.engine.cuda.integrate_chain_runs_cuda`).

With every engine, a run whose method the engine does not integrate (Radau, BDF, LSODA on
``compiled`` or ``cuda``) goes through ``solve_ivp``, and the pure sign law of ``sliding``
(``boundary_layer`` 0) through the event-driven integrator :mod:`rbstab.engine.switching`,
on the CPU.

This module imports nothing heavy: the command line reads it at start-up.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Engine", "ENGINES", "DEFAULT_ENGINE", "COMPILED_METHODS", "get_engine"]

#: The methods the compiled engines integrate (:data:`rbstab.engine.tableaus.METHODS`, which
#: ``tests/test_engines.py`` checks against this), named here without importing numpy.
COMPILED_METHODS = ("RK23", "RK45", "DOP853")


@dataclass(frozen=True)
class Engine:
    """One integration engine (module docstring).

    Attributes
    ----------
    name : str
        What ``--engine`` and every ``engine=`` argument take.
    summary : str
        One line for the command line's help.
    methods : tuple of str or None
        The ``simulation.method`` values it integrates itself (None: every one); runs of
        other methods go through ``solve_ivp``.
    gpu : bool
        Whether it runs on an NVIDIA GPU (:mod:`rbstab.engine.cuda`): a launch integrates
        many runs, a sweep's ``timeout`` is each launch's limit.
    chunk_size : int
        A sweep's runs per unit of work by default with one result file per run: one for
        ``solve_ivp`` a run; for a compiled engine enough runs that the costs of a chunk
        (a task's round trip, opening a file) are small, and few enough that every worker
        gets work early.
    """

    name: str
    summary: str
    methods: tuple[str, ...] | None
    gpu: bool
    chunk_size: int

    @property
    def compiled(self) -> bool:
        """Whether it integrates runs in batches with the compiled model (not one
        ``solve_ivp`` call per run)."""
        return self.methods is not None

    def takes(self, method: str, sign_law: bool = False) -> bool:
        """Whether it integrates a run of ``method`` in its batches (``sign_law``: the
        pure sign law, which goes to :mod:`rbstab.engine.switching`)."""
        return self.compiled and method in self.methods and not sign_law

    def unavailable(self) -> str | None:
        """Why it cannot run here (one line: what is missing, how to install it), or None."""
        if not self.gpu:
            return None
        from . import cuda  # heavy: numba, numba-cuda (the GPU engine only)

        try:
            cuda.check_available()
        except cuda.CudaUnavailable as exc:
            return str(exc)
        return None

    def check_available(self) -> None:
        """Return if it can run here, else raise
        :class:`rbstab.engine.cuda.CudaUnavailable` (the GPU engine) with one line naming
        what is missing."""
        if self.gpu:
            from . import cuda  # heavy: numba, numba-cuda (the GPU engine only)

            cuda.check_available()


#: Engine name -> :class:`Engine`, the default first.
ENGINES = {
    engine.name: engine
    for engine in (
        Engine("compiled", "RK23, RK45 and DOP853 compiled with the model, many runs per call (the default)",
               COMPILED_METHODS, gpu=False, chunk_size=256),
        Engine("scipy", "one solve_ivp call per run, the reference", None, gpu=False, chunk_size=1),
        Engine("cuda", "on an NVIDIA GPU, one thread a run (pip install \"rbstab[cuda]\")", COMPILED_METHODS,
               gpu=True, chunk_size=8192),
    )
}
#: The engine of a run or sweep that names none.
DEFAULT_ENGINE = next(iter(ENGINES))


def get_engine(name: str | None = None) -> Engine:
    """The engine ``name`` (None: :data:`DEFAULT_ENGINE`).

    Raises
    ------
    ValueError
        For a name not in :data:`ENGINES`.
    """
    engine = ENGINES.get(DEFAULT_ENGINE if name is None else name)
    if engine is None:
        raise ValueError(f"engine: found {name!r}; expected one of {', '.join(ENGINES)}")
    return engine
