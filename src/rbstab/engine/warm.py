"""Compiling the engine's kernels into the cache (:mod:`rbstab.jit`) before a command needs them.

:func:`ensure_compiled` compiles the entry points (the integrator and the outputs) the first
time a command needs them, printing one line that says so (numba compiles them in ~10-20 s;
later processes load them from the cache in ~0.5 s); :func:`warm_up` compiles (or loads)
them on a tiny input.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ..jit import CACHE_DIR, cache_is_warm, mark_warm
from ..chain import GROUND, Body, Joint, single
from ..model import PARAMETERS
from ..summary import numerical_rate, warm_up_balance
from ..variants import chain as C
from ..variants.base import N_OUTPUTS
from ..variants.kernels import STATE_SIZE, run_outputs, state_rates
from .integrate import admissible, integrate_chain_runs, integrate_runs
from .switching import warm_up as warm_up_sign_law
from .systems import tree_system
from .tableaus import METHODS

__all__ = ["GROUPS", "warm_up", "ensure_compiled"]

#: Kernel groups, each compiled (and marked warm in the cache) as a whole: the engine's
#: right-hand side, integrator and outputs; the sign law's event-driven integrator, which
#: only pure-sign-law runs need; a chain's rate, driver and outputs, which only chains need;
#: what an analysis of one body adds to the engine's (the tree's rest state and its
#: rates at many states), which the chain group also compiles (parts of :func:`warm_up`).
GROUPS = {"engine": ("rates", "outputs"), "sign_law": ("switching",), "chain": ("chains",), "analysis": ("rest",)}
#: Cold compile time of each part of :func:`warm_up` relative to the others (one core: rates
#: ~22 s, outputs ~8 s, the sign law ~22 s, chains ~84 s, rest ~14 s), by which
#: :func:`ensure_compiled` shares them between its two processes.
WEIGHTS = {"rates": 3, "outputs": 1, "switching": 3, "chains": 10, "rest": 2}


def _warm_up_chains() -> None:
    """A one-body chain's run on the compiled driver, its outputs, its rest state and its rates
    at a stack of states (the kernels every chain uses: their argument types do not depend on
    the chain's size)."""
    eye = np.eye(3)
    chain = single(Body("body", 1.0, eye), Joint("joint", GROUND, 0, np.zeros(3), np.array([0.0, 0.0, -1.0]),
                                                 "permanent", eye, eye), np.array([0.0, 0.0, -1.0]))
    compiled = C.compile_chain(chain)
    y = C._place(compiled, np.zeros(compiled.n_states))
    settings = np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3, 10.0, np.inf]])
    for limits in (None, np.ones((5, 3))):
        integrate_chain_runs(tree_system(compiled, limits), y[None], settings, method="DOP853", n_samples=2)
    C.evaluate(compiled, np.zeros(1), y[None])
    C.chain_rates(np.zeros(1), y[None], *compiled.args, np.empty((1, len(y))))  # an analysis's linearisation


def _warm_up_rest() -> None:
    """What an analysis of one body compiles beyond a run's kernels: the rest state of a
    one-body tree under gravity (:func:`rbstab.variants.chain.rest_state`: the potential, its
    gradient and the accelerations), its full states and its rates at a stack of states
    (:func:`rbstab.variants.chain.chain_rates`)."""
    eye, point = np.eye(3), np.array([0.0, 0.0, -1.0])
    chain = single(Body("body", 1.0, eye), Joint("joint", GROUND, 0, point, np.zeros(3), "permanent", eye, eye),
                   point)
    compiled = C.compile_chain(chain)  # h: the rest state's potential
    y = C.full_state(compiled, np.zeros((1, 6)))
    C.chain_rates(np.zeros(1), y, *compiled.args, np.empty_like(y))


def _warm_up_paper_permanent() -> None:
    """A run of the paper's one body on a permanent joint as every one-body run goes
    (:func:`rbstab.engine.integrate.integrate_chain_runs`): its reduced samples (Theta,
    Omega) expanded to the chain's state (:func:`rbstab.variants.tree.expand_samples`)."""
    eye, point = np.eye(3), np.array([0.0, 0.0, -1.0])
    chain = single(Body("body", 1.0, eye), Joint("joint", GROUND, 0, point, point, "permanent", eye, eye), -point)
    compiled = C.compile_chain(chain, offset=0.0)
    settings = np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3, 10.0, np.inf]])
    integrate_chain_runs(tree_system(compiled), np.zeros((1, 6)), settings, method="DOP853", n_samples=2)


def warm_up(parts: str = "rates,outputs,switching,chains,rest") -> None:
    """Compile (or load from the cache) every kernel a run uses, on a tiny input.

    ``parts``: comma-separated, any of ``rates`` (the right-hand side and the Runge-Kutta
    integrator, and what a one-body run on it needs), ``outputs`` (every output at the samples, the numerical dv/dt,
    :func:`rbstab.summary.numerical_rate`, and the balance figures,
    :func:`rbstab.summary.warm_up_balance`) and ``switching`` (the sign
    law's event-driven integrator, :mod:`rbstab.engine.switching`), ``chains`` (a
    chain's rate, compiled driver and outputs, :mod:`rbstab.engine.systems`) and ``rest`` (an
    analysis's: a tree's rest state and its rates at a stack of states);
    :func:`ensure_compiled` compiles some in a second process at the same time.
    """
    wanted = set(parts.split(","))
    params = np.zeros(1, dtype=PARAMETERS)
    params["mass"] = 1.0
    for name in ("inertia", "inertia_inv", "pivot_inertia", "pivot_inertia_inv"):
        params[name] = np.eye(3)
    if "switching" in wanted:
        warm_up_sign_law(params)
    if "chains" in wanted:
        _warm_up_chains()
    if "rest" in wanted:
        _warm_up_rest()
    for code, n in enumerate(STATE_SIZE):
        y = np.zeros((1, n))
        if "rates" in wanted:
            state_rates(code, np.zeros(1), y, params, np.empty_like(y))
        if "outputs" in wanted:  # sample times writable (a batch's) and read-only (a run's grid): two signatures
            fixed = np.zeros((1, 1))
            fixed.setflags(write=False)
            for times in (np.zeros((1, 1)), fixed):
                run_outputs(np.array([code]), params, times, y[None], np.empty((N_OUTPUTS, 1, 1)), True)
    if "outputs" in wanted:
        numerical_rate(np.linspace(0.0, 1.0, 8), np.zeros((1, 8)))
        warm_up_balance(params)  # the summary's settling time and centre of mass
    if "rates" in wanted:
        admissible(0, np.zeros(12), params[0], 1.0)  # the scipy reference's event
        settings = np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3]])
        for method in METHODS:
            integrate_runs([0], params, np.zeros((1, 12)), settings, method=method, n_samples=2)
        _warm_up_paper_permanent()


def _start_warm_up(parts: str):
    """A process running :func:`warm_up` (``parts``), or None if it cannot start."""
    code = f"from rbstab.engine import warm_up; warm_up({parts!r})"
    here = str(Path(__file__).resolve().parents[2])  # this rbstab, whatever the child's sys.path
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [here, os.environ.get("PYTHONPATH")]))}
    try:
        return subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None


def ensure_compiled(say=None, *, sign_law: bool = False, chain: bool = False, analysis: bool = False) -> None:
    """Compile the engine's kernels into the cache unless that was done before.

    ``say``: called with one line (str) before a cold compile, e.g. ``click.echo`` to
    stderr; nothing is said when the cache is warm. ``sign_law``: also the sign law's
    integrator; ``chain``: also a chain's kernels; ``analysis``: also what an analysis adds (its
    rest state, :data:`GROUPS`; a chain's kernels include them). The parts are compiled in two
    processes at once (numba compiles on one core; each writes its own kernels into the cache folder).
    """
    wanted = {"engine": True, "sign_law": sign_law, "chain": chain, "analysis": analysis and not chain}
    cold = [g for g, want in wanted.items() if want and not cache_is_warm(g)]
    if not cold:
        return
    if say is not None:
        took = "~65 s" if "chain" in cold else "~25 s"
        say(f"rbstab: compiling the engine once ({took} on 2 cores); cached in {CACHE_DIR}")
    start = time.perf_counter()
    here, there = [], []
    for part in sorted((p for g in cold for p in GROUPS[g]), key=WEIGHTS.get, reverse=True):
        lighter = here if sum(map(WEIGHTS.get, here)) <= sum(map(WEIGHTS.get, there)) else there
        lighter.append(part)
    parts = here + there
    helper = _start_warm_up(",".join(there)) if there and (os.cpu_count() or 1) > 1 else None
    warm_up(",".join(here if helper is not None else parts))
    if helper is not None and helper.wait() != 0:
        warm_up(",".join(there))  # the second process failed: compile its parts here
    for group in cold:
        mark_warm(group, f"{time.perf_counter() - start:.1f} s\n")
