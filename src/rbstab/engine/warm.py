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
from ..kinematics import rotation_matrix
from ..chain import GROUND, Body, Joint, single
from ..model import PARAMETERS
from ..summary import numerical_rate, pressure_samples, warm_up_balance
from ..variants import chain as C
from ..variants.base import N_OUTPUTS
from ..variants.paper import has_paper_form
from ..variants.disturbances import next_breakpoint
from ..variants.tree import (range_margin, reaction_samples, reduce_state, tree_expand, tree_impulses, tree_layout,
                             tree_rate, tree_work)
from ..variants.kernels import PERMANENT, STATE_SIZE, body_pressures, run_outputs, state_rates
from .integrate import admissible, integrate_chain_runs, integrate_runs
from .registry import DEFAULT_ENGINE, get_engine
from .status import RANGE_LEFT
from .switching import warm_up as warm_up_sign_law
from .systems import tree_system
from .tableaus import METHODS

__all__ = ["GROUPS", "warm_up", "ensure_compiled", "kernel_groups"]

#: Kernel groups, each compiled (and marked warm in the cache) as a whole: one body's
#: right-hand side, integrator and outputs (the paper's one body, in either spelling); the
#: sign law's event-driven integrator, which only pure-sign-law runs need; a tree's
#: driver and outputs, which only trees of other shapes need; what an analysis of one
#: body adds (the tree's rest state and its rates at many states), which the chain group
#: also compiles; what scipy's methods call (``--engine scipy``, the implicit methods), which
#: only their runs need. Both run groups share the summary's kernels (parts of :func:`warm_up`).
GROUPS = {"engine": ("rates", "outputs", "summary"), "sign_law": ("switching",), "chain": ("driver", "chains", "summary"),
          "analysis": ("rest",), "solve_ivp": ("solve_ivp",)}
#: Cold compile time of each part of :func:`warm_up` relative to the others (one core: rates
#: ~60 s, outputs ~15 s, summary ~8 s, the sign law ~22 s, a tree's driver ~95 s, its
#: outputs and rest state ~55 s, rest ~35 s, scipy's methods' ~30 s), by which
#: :func:`ensure_compiled` shares them between its two processes.
WEIGHTS = {"rates": 6, "outputs": 2, "summary": 1, "switching": 2, "driver": 10, "chains": 6, "rest": 3, "solve_ivp": 3}


def _tree_example():
    """A one-body tree that is not the paper's one body (its joint's points differ), so that
    it runs on the tree's kernels."""
    eye = np.eye(3)
    return single(Body("body", 1.0, eye), Joint("joint", GROUND, 0, np.zeros(3), np.array([0.0, 0.0, -1.0]),
                                                "permanent", eye, eye), np.array([0.0, 0.0, -1.0]))


def _warm_up_driver() -> None:
    """A tree's run on the compiled driver, with and without an admissible region (the
    driver's argument types do not depend on the tree's size)."""
    compiled = C.compile_chain(_tree_example(), offset=0.0)
    y = C._place(compiled, np.zeros(compiled.n_states))
    settings = np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3, 10.0, np.inf]])
    for limits in (None, np.ones((5, 3))):
        integrate_chain_runs(tree_system(compiled, limits), y[None], settings, method="DOP853", n_samples=2)


def _warm_up_states(compiled, y) -> None:
    """An analysis's kernels at the states ``y`` (k, n_states) of a tree: its rates at a
    stack of states (the linearisation; sample times writable and read-only, two
    signatures), its full states and a state's quantities (v and its terms, the gimbal
    angles, the admissible margin: :func:`rbstab.variants.chain.chain_core` from Python)."""
    fixed = np.zeros(len(y))
    fixed.setflags(write=False)
    for times in (np.zeros(len(y)), fixed):
        C.chain_rates(times, y, *compiled.args, np.empty_like(y))
    n = compiled.size
    C.chain_core(0.0, y[0], *compiled.args, np.empty(y.shape[1]), np.empty((n, 7, 3)), np.empty((n, 3)), np.empty(5))


def _warm_up_chains() -> None:
    """What a tree's run needs beside its driver: its bodies placed on their joints (the
    loader's rotations), its h (the rest state under gravity), its outputs at the samples
    (of a batch's runs: their times a writable copy; of a run: its time grid, read-only; two
    signatures) and what an analysis adds (:func:`_warm_up_states`)."""
    rotation_matrix(np.zeros((1, 3)))
    compiled = C.compile_chain(_tree_example())
    y = C._place(compiled, np.zeros(compiled.n_states))
    C.evaluate(compiled, np.zeros(1), np.stack([y[None], y[None]]))
    C.evaluate(compiled, np.zeros(1), y[None])
    reactions = np.zeros((compiled.size, 3, 1))  # and the joints to the ground's reactions and moments
    angles = np.zeros((1, compiled.size, 3))
    reaction_samples(np.zeros(1), y[None], angles, angles, C.records_of([compiled]), compiled.codes, compiled.parents,
                     compiled.ppoints[None], compiled.d_at, *tree_layout(compiled).args, np.zeros(1, np.int64),
                     reactions, reactions.copy())
    pressure_samples(reactions, reactions.copy(), np.stack([compiled.ppoints]), compiled.codes, compiled.parents,
                     C.records_of([compiled]), np.zeros(1, np.int64), np.empty((1, 3)),
                     np.empty((1, compiled.size, 3)))  # their centres of pressure
    _warm_up_states(compiled, y[None])


def _warm_up_solve_ivp() -> None:
    """What scipy's methods call on a tree's reduced rate from Python
    (:func:`rbstab.simulator.solve_tree`: ``--engine scipy``, the implicit methods), for one
    body and trees alike: its scratch arrays, rate, impulses, maximal image, ranges and the
    disturbances' breakpoints."""
    compiled = C.compile_chain(_tree_example(), offset=0.0)
    layout = tree_layout(compiled)
    tree, n = (*compiled.args, *layout.args), compiled.size
    yr = reduce_state(compiled, layout, C._place(compiled, np.zeros(compiled.n_states)))
    work = tree_work(n, compiled.n_states)
    tree_rate(0.0, yr, *tree, np.empty(layout.n_r), work)
    tree_impulses(0.0, yr, *tree, work)
    tree_expand(yr, *tree, np.empty(compiled.n_states), np.empty((n, 3, 3)), np.empty((n, 3, 3)), True)
    range_margin(yr, compiled.params, compiled.codes, layout.r_at, np.inf, 0, RANGE_LEFT)
    next_breakpoint(compiled.params[0], 0.0, 1.0)


def _warm_up_rest() -> None:
    """What an analysis of one body compiles beyond a run's kernels: the rest state of a
    one-body tree under gravity (:func:`rbstab.variants.chain.rest_state`: the potential, its
    gradient and the accelerations) and its kernels at a state (:func:`_warm_up_states`)."""
    eye, point = np.eye(3), np.array([0.0, 0.0, -1.0])
    chain = single(Body("body", 1.0, eye), Joint("joint", GROUND, 0, point, np.zeros(3), "permanent", eye, eye),
                   point)
    compiled = C.compile_chain(chain)  # h: the rest state's potential
    _warm_up_states(compiled, C.full_state(compiled, np.zeros((1, 6))))


def _warm_up_paper_permanent() -> None:
    """A run of the paper's one body on a permanent joint as every one-body run goes
    (:func:`rbstab.engine.integrate.integrate_chain_runs`): its reduced samples (Theta,
    Omega) expanded to the chain's state (:func:`rbstab.variants.tree.expand_samples`); from
    its reduced state (one body's spelling) and from the chain's state (a tree's,
    :func:`rbstab.variants.tree.reduce_states`)."""
    eye, point = np.eye(3), np.array([0.0, 0.0, -1.0])
    chain = single(Body("body", 1.0, eye), Joint("joint", GROUND, 0, point, point, "permanent", eye, eye), -point)
    compiled = C.compile_chain(chain, offset=0.0)
    settings = np.array([[1e-3, 1e-3, 1e-6, np.inf, 1e-3, 10.0, np.inf]])
    for y0 in (np.zeros(6), C._place(compiled, np.zeros(compiled.n_states))):
        integrate_chain_runs(tree_system(compiled), y0[None], settings, method="DOP853", n_samples=2)


def warm_up(parts: str = "rates,outputs,summary,switching,driver,chains,rest,solve_ivp") -> None:
    """Compile (or load from the cache) every kernel a run uses, on a tiny input.

    ``parts``: comma-separated, any of ``rates`` (one body's right-hand side and the
    Runge-Kutta integrator, and what a one-body run on it needs), ``outputs`` (one body's
    outputs at the samples), ``summary`` (the numerical dv/dt,
    :func:`rbstab.summary.numerical_rate`, and the balance figures,
    :func:`rbstab.summary.warm_up_balance`), ``switching`` (the sign law's event-driven
    integrator, :mod:`rbstab.engine.switching`), ``driver`` (a tree's rate on the compiled
    driver, :mod:`rbstab.engine.systems`), ``chains`` (a tree's h, outputs and rates at a
    stack of states), ``rest`` (an analysis's: a tree's rest state and its rates at a
    stack of states) and ``solve_ivp`` (what scipy's methods call, :func:`_warm_up_solve_ivp`);
    :func:`ensure_compiled` compiles some in a second process at the same time.
    """
    wanted = set(parts.split(","))
    params = np.zeros(1, dtype=PARAMETERS)
    params["mass"] = 1.0
    for name in ("inertia", "inertia_inv", "pivot_inertia", "pivot_inertia_inv"):
        params[name] = np.eye(3)
    if "switching" in wanted:
        warm_up_sign_law(params)
    if "driver" in wanted:
        _warm_up_driver()
    if "chains" in wanted:
        _warm_up_chains()
    if "rest" in wanted:
        _warm_up_rest()
    if "solve_ivp" in wanted:
        _warm_up_solve_ivp()
    for code, n in enumerate(STATE_SIZE):
        y = np.zeros((1, n))
        if "rates" in wanted:
            state_rates(code, np.zeros(1), y, params, np.empty_like(y))
        if "outputs" in wanted:  # sample times writable (a batch's) and read-only (a run's grid): two signatures
            fixed = np.zeros((1, 1))
            fixed.setflags(write=False)
            for times in (np.zeros((1, 1)), fixed):
                run_outputs(np.array([code]), params, times, y[None], np.empty((N_OUTPUTS, 1, 1)), True)
            if code == PERMANENT:  # a pinned body's centre of pressure
                body_pressures(code, params, np.zeros((N_OUTPUTS, 1, 1)), np.empty((1, 1, 3)))
    if "summary" in wanted:
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


def kernel_groups(configs, engine: str = DEFAULT_ENGINE) -> dict[str, bool]:
    """Which run kernels validated configurations (:class:`rbstab.config.RunConfig`) need on
    ``engine`` (:data:`rbstab.engine.ENGINES`), as :func:`ensure_compiled`'s ``one_body``,
    ``chain`` and ``solve_ivp``: the paper's one body's for a model that is one body held to the
    ground at its own point (:func:`rbstab.variants.paper.has_paper_form`, either spelling),
    a tree's for any other; scipy's methods' for a run the engine does not integrate (its
    method, or the engine ``scipy``) but the pure sign law's (its own integrator)."""
    paper = [has_paper_form(c.chain) for c in configs]
    solve_ivp = any(not c.chain.sign_law and not get_engine(engine).takes(c.simulation.method) for c in configs)
    return {"one_body": any(paper), "chain": not all(paper), "solve_ivp": solve_ivp}


def ensure_compiled(say=None, *, one_body: bool = True, sign_law: bool = False, chain: bool = False,
                    analysis: bool = False, solve_ivp: bool = False) -> None:
    """Compile the engine's kernels into the cache unless that was done before.

    ``say``: called with one line (str) before a cold compile, e.g. ``click.echo`` to
    stderr; nothing is said when the cache is warm. ``one_body``: the paper's one body's
    kernels (a configuration whose model is one body held to the ground at its own point,
    :func:`rbstab.variants.paper.has_paper_form`); ``sign_law``: the sign law's integrator;
    ``chain``: a tree's kernels (any other model); ``analysis``: what an analysis adds (its
    rest state, :data:`GROUPS`; a tree's kernels include them); ``solve_ivp``: what scipy's
    methods call (:func:`_warm_up_solve_ivp`). The parts are compiled in two
    processes at once (numba compiles on one core; each writes its own kernels into the cache folder).
    """
    wanted = {"engine": one_body, "sign_law": sign_law, "chain": chain, "analysis": analysis and not chain,
              "solve_ivp": solve_ivp}
    cold = [g for g, want in wanted.items() if want and not cache_is_warm(g)]
    if not cold:
        return
    if say is not None:
        took = "~2 min" if "chain" in cold else "~1 min"
        say(f"rbstab: compiling the engine once ({took} on 2 cores); cached in {CACHE_DIR}")
    start = time.perf_counter()
    here, there = [], []
    for part in sorted({p for g in cold for p in GROUPS[g]}, key=lambda p: (-WEIGHTS[p], p)):
        lighter = here if sum(map(WEIGHTS.get, here)) <= sum(map(WEIGHTS.get, there)) else there
        lighter.append(part)
    parts = here + there
    helper = _start_warm_up(",".join(there)) if there and (os.cpu_count() or 1) > 1 else None
    warm_up(",".join(here if helper is not None else parts))
    if helper is not None and helper.wait() != 0:
        warm_up(",".join(there))  # the second process failed: compile its parts here
    for group in cold:
        mark_warm(group, f"{time.perf_counter() - start:.1f} s\n")
