"""Chains of rigid bodies: what a run and an evaluation of the chain's rate cost.

Prints (2 cores, warm numba cache):
- ms a run of each chain example (the hinged stance's too): its integration by scipy's ``solve_ivp`` over the
  compiled reduced rate (``rbstab.simulator.solve_tree``, ``--engine scipy``) and by the
  compiled driver (``rbstab.engine.integrate.integrate_chain_runs``), and the whole run
  ``rbstab run`` makes (``rbstab.simulator.simulate``: with its outputs and summary);
- ms the integration of the one-body paper cases on the one-body compiled engine and
  as a one-body chain on the compiled driver;
- s a 41 x 41 basin map of the stance example (``rbstab analyze --basin``, one process)
  and its smallest fatal push on the trunk over 64 directions (``--push``, 2 threads), and
  its analysis (``rbstab analyze``: the certificate and the simulation, one process);
- us an evaluation of the rate of a serial chain of n = 1..8 bodies (alternating permanent
  and visco-elastic joints with feedback, gravity) as the compiled driver makes it (the
  reduced rate with scratch arrays of its own), and that per body, beside one evaluation of
  Case 3's one-body rate;
- s a sweep over initial states (``rbstab.execute_sweep``, 2 local processes, ``--store
  summary``) of N runs (``--sweep-runs``, default 10,000) of two 3-body chains (a triple
  inverted pendulum held by its joints' feedback, t_end 2 s; three Case 3 bodies in a
  column, each joint Case 3's embedded law, :func:`three_case3`) and of the one-body Case 3
  config (t_end 2 s), the rate evaluations a run takes, and their ratios: a sweep's time,
  and its time per rate evaluation (a chain takes more steps than Case 3); and the time a
  run on one process that 3.5x Case 3's sweep allows, beside what a chain run's rate
  evaluations alone take (their count x us an evaluation at the initial state);
- us an evaluation of the rate of a serial chain of n = 1..8 bodies on permanent joints, in
  maximal coordinates (the chain's rate: the stacked solve for the constraint forces) and
  in reduced coordinates (:func:`rbstab.variants.tree.tree_rate`: no constraint force);
- s a sweep of the stance example over the trunk's mass (every run another chain: its
  rest state and h found again) and over the legs' initial tilt, ``--parameter-runs``
  runs (default 1,000) on one worker process, and their ratio; the same for the hinged
  stance (``stance_hinges``: over the trunk's mass and the shanks' initial angle);
- s ``rbstab run`` of the stance example with an empty compile cache (the engine's and a
  tree's kernels compiled once, :func:`rbstab.engine.ensure_compiled`), beside a warm one.

Run: python benchmarks/chains.py [--sweep-runs N] [--parameter-runs N] [--only-parameter] [--only-reduced]
[--only-cold]
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numba
import numpy as np

from rbstab.variants.paper import paper_form, paper_initial_state
from rbstab.analysis import BasinAxis, analyze, basin_map
from rbstab.analysis.push import push_analysis
from rbstab.chain import GROUND, Body, Chain, Joint
from rbstab.config import load_config
from rbstab.config.loader import config_from_mapping
from rbstab.config.loader import load_config
from rbstab.engine.integrate import integrate_chain_runs, integrate_runs
from rbstab.engine.settings import settings_rows
from rbstab.engine.systems import tree_system
from rbstab.simulator import simulate, solve_tree
from rbstab.variants import chain as C
from rbstab.variants import tree as R
from rbstab.variants.kernels import state_rate

ROOT = Path(__file__).resolve().parents[1]
D = np.diag


def _best(f, repeat=5):
    f()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


@numba.njit
def _body_loop(k, code, y, p, f):
    """k evaluations of one body's rate (the state nudged each time, so none is hoisted)."""
    total = 0.0
    for _ in range(k):
        y[0] += 1e-12
        state_rate(code, 0.0, y, p, f)
        total += f[3]
    return total


@numba.njit
def _chain_loop(k, y, args, dy, work):
    """k evaluations of a chain's rate with its scratch arrays, as the compiled driver makes them."""
    params, codes, parents, ppoints, d_at = args
    total = 0.0
    for _ in range(k):
        y[0] += 1e-12
        C.chain_evaluate(0.0, y, params, codes, parents, ppoints, d_at, dy, work.joints, work.bodies, work.scalars, work)
        total += dy[3]
    return total


@numba.njit
def _tree_loop(k, y, args, layout, dy, work):
    """k evaluations of a tree's rate in reduced coordinates (:func:`rbstab.variants.tree.tree_rate`)."""
    params, codes, parents, ppoints, d_at = args
    r_at, u_at, rd_at = layout
    total = 0.0
    for _ in range(k):
        y[0] += 1e-12
        R.tree_rate(0.0, y, params, codes, parents, ppoints, d_at, r_at, u_at, rd_at, dy, work)
        total += dy[3]
    return total


def serial(n: int, laws: tuple = ("permanent", "visco_elastic")) -> Chain:
    """A serial chain of n links 0.6 m long, its joints' laws in turn from ``laws``."""
    bodies = tuple(Body(f"link{i}", 2.0, D([0.2, 0.2, 0.02])) for i in range(n))
    joints = []
    for i in range(n):
        law = laws[i % len(laws)]
        gains = {"k_c": D([5e4] * 3), "l_c": D([500.0] * 3)} if law == "visco_elastic" else {}
        joints.append(Joint(f"joint{i}", GROUND if i == 0 else i - 1, i, np.zeros(3) if i == 0 else np.array([0, 0, 0.3]),
                            np.array([0, 0, -0.3]), law, D([400.0, 400.0, 100.0]), D([40.0, 40.0, 10.0]), **gains))
    return Chain(bodies, tuple(joints), np.array([0.0, 0.0, -9.81]))


def reduced_rates() -> None:
    """us an evaluation of a serial chain of permanent joints' rate, n = 1..8: the
    maximal-coordinate chain's (the stacked solve for Lambda_j) and the reduced tree's."""
    print("permanent joints only, us an evaluation: maximal coordinates (stacked solve) | reduced coordinates")
    k = 100_000
    for n in range(1, 9):
        compiled = C.compile_chain(serial(n, ("permanent",)), offset=0.0)
        layout = R.tree_layout(compiled)
        y = C._place(compiled, np.random.default_rng(n).normal(scale=0.1, size=compiled.n_states))
        yr = R.reduce_state(compiled, layout, y)
        dy, dyr = np.empty(compiled.n_states), np.empty(layout.n_r)
        work, tree_work = C.chain_work(n), R.tree_work(n, compiled.n_states)
        _chain_loop(10, y.copy(), compiled.args, dy, work)
        _tree_loop(10, yr.copy(), compiled.args, layout.args, dyr, tree_work)
        maximal = _best(lambda: _chain_loop(k, y.copy(), compiled.args, dy, work), 3) / k
        reduced = _best(lambda: _tree_loop(k, yr.copy(), compiled.args, layout.args, dyr, tree_work), 3) / k
        print(f"  n = {n}: {1e6 * maximal:7.3f} | {1e6 * reduced:7.3f}  ({reduced / maximal:.2f}x)")


def _compiled_run(compiled, y0, sim):
    system = tree_system(compiled, sim.limits)
    settings = settings_rows([sim])
    return lambda: integrate_chain_runs(system, y0[None], settings, method=sim.method, n_samples=sim.n_samples)


def triple_pendulum() -> dict:
    """A 3-body chain config: three 10 kg links (1 m) in a column, permanent joints with
    feedback strong enough to hold them upright under gravity."""
    gains = {"k_r": [1500.0, 1500.0, 150.0], "l_r": [300.0, 300.0, 30.0]}
    joints = [{"name": f"j{i}", "parent": "ground" if i == 0 else f"link{i - 1}",
               "parent_point": [0.0, 0.0, 0.0 if i == 0 else 0.5], "child": f"link{i}",
               "child_point": [0.0, 0.0, -0.5], "variant": "permanent", **gains} for i in range(3)]
    return {"name": "triple", "gravity": [0.0, 0.0, -9.81],
            "bodies": [{"name": f"link{i}", "mass": 10.0, "inertia": [0.85, 0.85, 0.05]} for i in range(3)],
            "joints": joints, "initial_state": {"link0": {"theta": [0.05, 0.0, 0.0]}},
            "simulation": {"t_end": 2.0, "n_samples": 201, "method": "DOP853", "rtol": 1e-8, "atol": 1e-10}}


def three_case3() -> dict:
    """A 3-body chain of Case 3's physics: three of its bodies in a column (no gravity), each
    joint Case 3's embedded law and gains (the first to the ground at its point R, the others
    0.84 m apart, top of the parent to the bottom of the child), the first body with its
    K_t, L_t and initial Omega, DOP853 over 2 s at its tolerances and 2001 samples."""
    import yaml

    case3 = yaml.safe_load((ROOT / "configs" / "paper" / "case3_embedded.yaml").read_text())
    control = {k: v for k, v in case3["controller"].items() if k not in ("k_t", "l_t")}
    point = case3["body"]["attachment_point"]
    anchor = {"k_t": case3["controller"]["k_t"], "l_t": case3["controller"]["l_t"]}
    bodies = [{"name": f"body{i}", "mass": case3["body"]["mass"], "inertia": case3["body"]["inertia"],
               **(anchor if i == 0 else {})} for i in range(3)]
    joints = [{"name": f"j{i}", "parent": "ground" if i == 0 else f"body{i - 1}",
               "parent_point": point if i == 0 else [0.0, 0.0, 0.42], "child": f"body{i}",
               "child_point": point if i == 0 else [0.0, 0.0, -0.42], **control} for i in range(3)]
    return {"name": "three_case3", "gravity": [0.0, 0.0, 0.0], "bodies": bodies, "joints": joints,
            "initial_state": {"body0": {"omega": case3["initial_state"]["omega"]}, "body1": {"x": [0.0, 0.0, 0.84]},
                              "body2": {"x": [0.0, 0.0, 1.68]}},
            "simulation": case3["simulation"]}


def _chain_rate_us(data: dict) -> float:
    """us an evaluation of the rate of the chain config ``data`` at its initial state."""
    config = config_from_mapping(data)
    compiled = C.compile_chain(config.chain)
    layout = R.tree_layout(compiled)
    y = R.reduce_state(compiled, layout, C.initial_state(config))
    dy, work = np.empty(layout.n_r), R.tree_work(config.chain.size, compiled.n_states)
    _tree_loop(10, y.copy(), compiled.args, layout.args, dy, work)
    k = 100_000
    return 1e6 * _best(lambda: _tree_loop(k, y.copy(), compiled.args, layout.args, dy, work), 3) / k


def sweeps(n: int) -> None:
    """Seconds of an initial-state sweep of ``n`` runs of two 3-body chains and of Case 3,
    and what the target (3.5x Case 3's sweep) leaves a chain's run beside the time its rate
    evaluations alone take."""
    import tempfile

    import yaml

    import rbstab

    side = int(round(n ** 0.5))
    levels = np.linspace(-0.1, 0.1, side).tolist()
    case3 = yaml.safe_load((ROOT / "configs" / "paper" / "case3_embedded.yaml").read_text())
    chains = {"3-body chain": triple_pendulum(), "3 Case 3 bodies": three_case3()}
    specs = {"3-body chain": {"name": "triple", "base": chains["3-body chain"],
                              "grid": {"initial_state.link0.theta.0": levels, "initial_state.link2.theta.1": levels}},
             "3 Case 3 bodies": {"name": "three", "base": chains["3 Case 3 bodies"],
                                 "grid": {"initial_state.body0.theta.0": levels, "initial_state.body2.theta.1": levels}},
             "one-body Case 3": {"name": "case3", "base": case3,
                                 "grid": {"initial_state.theta.0": levels, "initial_state.theta.1": levels}}}
    seconds, nfev = {}, {}
    for label, spec in specs.items():
        with tempfile.TemporaryDirectory() as out:
            small = {**spec, "name": "warm", "grid": {k: v[:2] for k, v in spec["grid"].items()}}
            rbstab.execute_sweep(small, out, jobs=2, store="summary", progress=False)  # the kernels compiled
            t0 = time.perf_counter()
            outcome = rbstab.execute_sweep(spec, out, jobs=2, store="summary", progress=False)
            seconds[label] = time.perf_counter() - t0
            nfev[label] = float(rbstab.open_sweep(outcome.directory)["solver_nfev"].mean())
            print(f"  {label}: {outcome.n_runs} runs in {seconds[label]:.2f} s ({1e3 * seconds[label] / outcome.n_runs:.2f}"
                  f" ms a run on 2 processes; {outcome.counts['success']} succeeded; {nfev[label]:.0f} rate evaluations"
                  f" a run)")
    one = "one-body Case 3"
    budget = 3.5 * seconds[one] / n * 2  # s a run a process that the target allows
    for chain, data in chains.items():
        rate = _chain_rate_us(data)
        print(f"  ratio {chain} / Case 3: {seconds[chain] / seconds[one]:.2f} (a sweep); "
              f"{seconds[chain] / nfev[chain] / (seconds[one] / nfev[one]):.2f} (a rate evaluation in the sweep); "
              f"the target (3.5x) allows {1e3 * budget:.2f} ms a run a process, its {nfev[chain]:.0f} rate evaluations "
              f"alone take {1e-3 * rate * nfev[chain]:.2f} ms ({rate:.3f} us each)")


def parameter_vs_initial_state(n: int, example: str = "stance_ankle_hip",
                               tilt: tuple = ("legs tilt", "initial_state.legs.theta.0=uniform:[-0.1,0.1]")) -> None:
    """Wall seconds of ``rbstab sweep`` of a stance example (t_end 2 s, ``--store
    summary``, one worker process: ``-j 1``) over the trunk's mass (every run another
    chain, so another rest state and h) and over an initial tilt (one chain), each
    the best of two after a 20-run sweep of its own (the worker's kernels loaded), and
    their ratio."""
    import subprocess
    import sys
    import tempfile

    rbstab = str(Path(sys.executable).parent / "rbstab")
    stance = str(ROOT / "configs" / "examples" / f"{example}.yaml")
    seconds = {}
    for label, axis in (("trunk mass", "bodies.trunk.mass=uniform:[40,55]"), tilt):
        for runs in (20, n, n):
            with tempfile.TemporaryDirectory() as folder:
                start = time.perf_counter()
                subprocess.run([rbstab, "sweep", stance, "--random", axis, "-n", str(runs), "-j", "1", "--store",
                                "summary", "--no-progress", "--set", "simulation.t_end=2", "-o", folder],
                               check=True, capture_output=True)
                if runs == n:
                    seconds[label] = min(seconds.get(label, np.inf), time.perf_counter() - start)
        print(f"  {example} over the {label}: {n} runs in {seconds[label]:.2f} s "
              f"({1e3 * seconds[label] / n:.2f} ms a run, start to exit)")
    print(f"  ratio trunk mass / {tilt[0]}: {seconds['trunk mass'] / seconds[tilt[0]]:.2f}")


def cold_run(repeat: int = 2) -> None:
    """``rbstab run`` of the stance example and of a paper case (Case 1), process start to
    exit, with an empty compile cache (``NUMBA_CACHE_DIR``, compiling the kernels each
    model needs once: a tree's, the paper's one body's), alternated ``repeat`` times, and
    warm (best of 3); the stance's cold run over the paper case's."""
    import os
    import subprocess
    import tempfile

    def run(path, env=None) -> float:
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            subprocess.run(["rbstab", "run", str(path), "-o", out], check=True, capture_output=True, env=env)
            return time.perf_counter() - start

    stance, paper = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", ROOT / "configs" / "paper" / \
        "case1_permanent.yaml"
    warm = min(run(stance) for _ in range(3))
    cold: dict = {stance: [], paper: []}
    for _ in range(repeat):
        for path in (stance, paper):
            with tempfile.TemporaryDirectory() as cache:
                cold[path].append(run(path, dict(os.environ, NUMBA_CACHE_DIR=cache)))
    print(f"rbstab run stance_ankle_hip: warm {warm:.2f} s, cold (a tree's kernels compiled) "
          f"{' / '.join(f'{t:.1f}' for t in cold[stance])} s; case1_permanent cold (the one body's) "
          f"{' / '.join(f'{t:.1f}' for t in cold[paper])} s; ratio {min(cold[stance]) / min(cold[paper]):.2f} "
          "(best of each)")


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep-runs", type=int, default=10_000, help="runs of each sweep (0: none)")
    parser.add_argument("--parameter-runs", type=int, default=1000,
                        help="runs of the stance sweeps over a parameter and an initial state (0: none)")
    parser.add_argument("--only-parameter", action="store_true", help="only those two sweeps")
    parser.add_argument("--only-reduced", action="store_true",
                        help="only the rates of serial chains of permanent joints, maximal and reduced")
    parser.add_argument("--only-cold", action="store_true", help="only rbstab run with an empty compile cache")
    options = parser.parse_args()
    warnings.simplefilter("ignore")
    if options.only_cold:
        cold_run()
        return
    if options.only_reduced:
        reduced_rates()
        return
    if options.parameter_runs:
        print("a sweep over a parameter against one over an initial state (one worker process, store summary):")
        parameter_vs_initial_state(options.parameter_runs)
        parameter_vs_initial_state(options.parameter_runs, "stance_hinges",
                                   ("shanks tilt", "initial_state.shanks.q=uniform:[-0.1,0.1]"))
        if options.only_parameter:
            return
    print("runs, integration only (ms a run, best of 5): scipy's solve_ivp over the compiled rate | the compiled "
          "driver | rbstab run's whole run (compiled, with outputs and summary)")
    for name in ("double_pendulum", "stance_ankle_hip", "knee", "stance_hinges"):
        config = load_config(ROOT / "configs" / "examples" / f"{name}.yaml")
        compiled = C.compile_chain(config.chain)
        scipy_s = _best(lambda: solve_tree(config, compiled=compiled))
        driver_s = _best(_compiled_run(compiled, C.initial_state(config), config.simulation))
        whole_s = _best(lambda: simulate(config))
        print(f"  {name:18s} {config.chain.size} bodies, t_end {config.simulation.t_end:g} s: {1e3 * scipy_s:8.1f} | "
              f"{1e3 * driver_s:7.1f} | {1e3 * whole_s:7.1f}  ({scipy_s / driver_s:.1f}x)")
    for case in ("case3_embedded", "case2_visco_elastic", "case1_permanent"):
        config = load_config(ROOT / "configs" / "paper" / f"{case}.yaml")
        sim = config.simulation
        variant = paper_form(config)
        y0 = paper_initial_state(config, variant)
        params = np.atleast_1d(variant.parameters)
        one = _best(lambda: integrate_runs([variant.code], params, y0[None], settings_rows([sim]), method=sim.method,
                                           n_samples=sim.n_samples))
        compiled = C.compile_chain(config.chain, offset=0.0)
        as_chain = _best(_compiled_run(compiled, y0, sim))
        print(f"  {case}, t_end {sim.t_end:g} s: one-body engine {1e3 * one:6.2f} ms, as a one-body chain on the "
              f"compiled driver {1e3 * as_chain:6.2f} ms ({as_chain / one:.2f}x)")
    stance = load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml",
                             ["simulation.limits.theta=[0.6, 0.6, 3.2]"])
    axes = [BasinAxis.parse("initial_state.legs.theta.0=-0.4:0.4:41"),
            BasinAxis.parse("initial_state.trunk.omega.0=-3:3:41")]
    basin_map(stance, [BasinAxis.parse("initial_state.legs.theta.0=-0.4:0.4:2"), axes[1]])  # compiled
    start = time.perf_counter()
    found = basin_map(stance, axes)
    print(f"  basin map of stance_ankle_hip (limits.theta 0.6 rad), 41 x 41 over legs theta_1 x trunk omega_1, "
          f"t_end 5 s: {time.perf_counter() - start:.2f} s ({found.counts()})")
    push_analysis(stance, "force", directions=np.array([[0.0, -1.0, 0.0]]), body="trunk", point=[0, 0, 0.2])
    start = time.perf_counter()
    pushed = push_analysis(stance, "force", directions=64, body="trunk", point=[0, 0, 0.2], jobs=2)
    print(f"  smallest fatal push of stance_ankle_hip (limits.theta 0.6 rad) on the trunk at (0, 0, 0.2) m, 64 "
          f"directions and the local search, 2 threads: {time.perf_counter() - start:.2f} s ({pushed.runs} runs; "
          f"minimum {pushed.minimum:.4g} N s along ({', '.join(f'{x:+.3f}' for x in pushed.minimum_direction)}))")
    plain = load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml")
    analyze(plain)  # compiled
    start = time.perf_counter()
    analysed = analyze(plain)
    print(f"  analysis of stance_ankle_hip (rbstab analyze in one process: rest state, linearisation, the certificate "
          f"of 10,000 states checked against runs, the simulation): {time.perf_counter() - start:.2f} s "
          f"(c = {analysed.certificate.sublevel:.4g} J)")
    print("rate evaluations, compiled (us an evaluation; per body); one-body Case 3's rate for comparison:")
    code, p = variant.code, params[0]
    f = np.empty(y0.size)
    _body_loop(10, code, y0.copy(), p, f)
    k = 200_000
    seconds = _best(lambda: _body_loop(k, code, y0.copy(), p, f), 3) / k
    print(f"  case3_embedded (one body): {1e6 * seconds:7.3f} us")
    for n in range(1, 9):
        compiled = C.compile_chain(serial(n), offset=0.0)
        layout = R.tree_layout(compiled)
        y = R.reduce_state(compiled, layout,
                           C._place(compiled, np.random.default_rng(n).normal(scale=0.1, size=compiled.n_states)))
        dy = np.empty(layout.n_r)
        work = R.tree_work(n, compiled.n_states)
        _tree_loop(10, y.copy(), compiled.args, layout.args, dy, work)
        seconds = _best(lambda: _tree_loop(k, y.copy(), compiled.args, layout.args, dy, work), 3) / k
        print(f"  n = {n}: {1e6 * seconds:7.3f} us  ({1e6 * seconds / n:6.3f} us a body)")
    reduced_rates()
    if options.sweep_runs:
        print("sweeps over initial states (2 local processes, store summary):")
        sweeps(options.sweep_runs)
    cold_run()


if __name__ == "__main__":
    main()
