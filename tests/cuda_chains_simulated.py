"""The CUDA engine's tree kernel under numba's CUDA simulator against the compiled CPU
driver, run by tests/test_cuda_chains.py in a process of its own (the simulator is chosen
when numba starts: ``NUMBA_ENABLE_CUDASIM=1``).

Prints one JSON object (its last line): for each case, the runs' statuses and whether their
status, t_stop, nfev, n_steps, samples and work W at every sample are the CPU driver's bit
for bit (all samples and every 3rd), and whether ``simulate(engine="cuda")`` gives
``simulate(engine="compiled")``'s outputs and summary.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import warnings

import numpy as np


def pulsed_chain(theta: float, impulses: bool = False):
    """Three bodies hanging on permanent (ball) joints under gravity with joint springs (the
    elbow's relaxed at a reference posture, the wrist's with a passive torque too), a
    pulse of force on the lowest from 0.05 s to 0.15 s and an admissible region in theta;
    the upper body tilted ``theta`` [rad] about x. ``impulses``: also a torque impulse on the
    upper body at t = 0, and force impulses on the middle one at 0.12 s and at t_end."""
    from rbstab.config.loader import config_from_mapping

    body = {"mass": 1.5, "inertia": [0.1, 0.1, 0.03]}
    joint = {"parent_point": [0, 0, -0.3], "child_point": [0, 0, 0.3], "variant": "permanent", "k_r": [20, 20, 5],
             "l_r": [1.0, 1.0, 1.0]}
    return config_from_mapping({
        "name": "pulsed3", "gravity": [0, 0, -9.81],
        "bodies": [{"name": name, **body} for name in ("upper", "middle", "lower")],
        "joints": [{"name": "shoulder", "parent": "ground", "child": "upper", **joint, "parent_point": [0, 0, 0]},
                   {"name": "elbow", "parent": "upper", "child": "middle", **joint, "theta_ref": [0.05, 0.0, 0.0]},
                   {"name": "wrist", "parent": "middle", "child": "lower", **joint,
                    "passive": {"k_r": [3.0, 3.0, 1.0], "l_r": [0.1, 0.1, 0.1], "theta_ref": [0.1, 0.0, 0.0]}}],
        "initial_state": {"upper": {"theta": [theta, 0.0, 0.0]}},
        "disturbances": [{"kind": "pulse", "value": [0.0, 20.0, 1.0], "point": [0.0, 0.05, -0.2], "start": 0.05,
                          "duration": 0.1, "body": "lower"},
                         *([{"kind": "impulse", "quantity": "torque", "value": [0.05, 0.0, 0.0], "start": 0.0,
                             "body": "upper"},
                            *[{"kind": "impulse", "quantity": "force", "value": [0.0, 0.3, 0.0], "point": [0.0, 0.0, 0.1],
                               "start": at, "body": "middle"} for at in (0.12, 0.3)]] if impulses else [])],
        "simulation": {"t_end": 0.3, "n_samples": 31, "method": "RK45", "rtol": 1e-8, "atol": 1e-10,
                       "limits": {"theta": [0.5, 0.5, 3.2]}},
    })


def hinged_chain(theta: float):
    """:func:`pulsed_chain` with the elbow and the wrist hinges about oblique axes (the
    elbow's feedback clipped, stronger one way; the wrist's with a passive torque)."""
    from rbstab.config.loader import config_from_mapping

    data = pulsed_chain(theta).resolved
    data["name"] = "hinged3"
    for joint, axis in zip(data["joints"][1:], ([1.0, 0.2, 0.0], [0.3, 1.0, 0.4])):
        joint.update(variant="hinge", axis=axis, k_r=20.0, l_r=1.0, theta_ref=0.05)
    data["joints"][1]["saturation"] = {"torque_n": 0.5, "torque_n_lower": -0.2}
    data["joints"][2]["passive"] = {"k_r": 3.0, "l_r": 0.1, "theta_ref": 0.1}
    data["initial_state"] = {"upper": data["initial_state"]["upper"], "middle": {"q": -0.2, "u": -0.5},
                             "lower": {"q": 0.1}}
    return config_from_mapping(data)


def ranged_chain(rate: float):
    """:func:`hinged_chain` (tilted 0.2 rad) with the elbow's range [-0.23, 0.5] rad an
    admissible region, the elbow's q starting at -0.2 rad with the rate ``rate`` [rad/s]
    (-0.5: its q reaches -0.204 rad; -1.5 leaves the range)."""
    from rbstab.config.loader import config_from_mapping

    data = hinged_chain(0.2).resolved
    data["name"] = "ranged3"
    data["joints"][1]["range"] = {"lower": -0.23, "upper": 0.5, "kind": "region"}
    data["initial_state"]["middle"]["u"] = rate
    return config_from_mapping(data)


def stopped_chain(theta: float):
    """:func:`pulsed_chain` with the wrist's Euler angles within a stop (its theta_1 beyond
    [-0.03, 0.15] rad pushed back) and the shoulder's within an admissible region (theta_1
    in [-0.003, 0.42] rad: the upper body tilted 0.2 rad swings out of it through its lower
    end, the one tilted 0.4 rad leaves simulation.limits first)."""
    from rbstab.config.loader import config_from_mapping

    data = pulsed_chain(theta).resolved
    data["name"] = "stopped3"
    data["joints"][0]["range"] = {"lower": [-0.003, -1.0, -1.0], "upper": [0.42, 1.0, 1.0], "kind": "region"}
    data["joints"][2]["range"] = {"lower": [-0.03, -1.0, -1.0], "upper": [0.15, 1.0, 1.0], "k_r": [80.0, 80.0, 80.0],
                                  "l_r": 0.5}
    return config_from_mapping(data)


def universal_chain(rate: float):
    """:func:`hinged_chain` (tilted 0.2 rad) with the elbow a universal joint about two oblique
    axes (its second coordinate's feedback clipped, stronger one way; a passive torque; q_2's
    range [-0.4, 0.3] rad an admissible region), the elbow's q_2 starting at 0.1 rad with the
    rate ``rate`` [rad/s] (-0.5 stays inside; -8 leaves through the lower end)."""
    from rbstab.config.loader import config_from_mapping

    data = hinged_chain(0.2).resolved
    data["name"] = "universal3"
    data["joints"][1].update(variant="universal", axis=[[1.0, 0.2, 0.0], [0.1, 1.0, 0.3]], k_r=[20.0, 15.0],
                             l_r=[1.0, 0.8], theta_ref=[0.05, 0.0], saturation={"torque_n": [math.inf, 0.5],
                                                                                 "torque_n_lower": [-math.inf, -0.2]},
                             passive={"k_r": [2.0, 1.0], "l_r": 0.1}, range={"lower": [-1.0, -0.4], "upper": [1.0, 0.3],
                                                                               "kind": "region"})
    data["initial_state"]["middle"] = {"q": [-0.2, 0.1], "u": [0.3, rate]}
    return config_from_mapping(data)


def slide_chain(rate: float):
    """:func:`hinged_chain` (tilted 0.2 rad) with the elbow a slide along an oblique axis (its
    feedback clipped, stronger one way; a passive spring; its range [-0.5, 0.3] m an
    admissible region), starting 0.05 m out at ``rate`` [m/s] (-0.2 stays inside, its q down
    to -0.33 m; -3 leaves through the lower end)."""
    from rbstab.config.loader import config_from_mapping

    data = hinged_chain(0.2).resolved
    data["name"] = "slides3"
    data["joints"][1].update(variant="slide", axis=[0.2, 0.1, 1.0], k_r=200.0, l_r=10.0, theta_ref=0.02,
                             saturation={"torque_n": 8.0, "torque_n_lower": -3.0}, passive={"k_r": 50.0, "l_r": 1.0},
                             range={"lower": -0.5, "upper": 0.3, "kind": "region"})
    data["initial_state"]["middle"] = {"q": 0.05, "u": rate}
    return config_from_mapping(data)


def ball_chain(theta: float):
    """:func:`pulsed_chain` with impulses and every joint a quaternion ball (``variant: ball``:
    the elbow's spring about a reference turn, the wrist's passive torque too; the upper body
    tilted ``theta`` [rad]: the second run leaves simulation.limits)."""
    from rbstab.config.loader import config_from_mapping

    data = pulsed_chain(theta, impulses=True).resolved
    data["name"] = "balls3"
    for joint in data["joints"]:
        joint["variant"] = "ball"
    return config_from_mapping(data)


def cases(root: str):
    """name -> (configs of chains of one structure: its runs)."""
    from rbstab.config.loader import load_config

    stance = os.path.join(root, "configs", "examples", "stance_ankle_hip.yaml")
    knee = os.path.join(root, "configs", "examples", "knee.yaml")
    short = ["simulation.t_end=0.3", "simulation.n_samples=31"]
    return {
        "stance": [load_config(stance, [*short, *extra]) for extra in (
            [], ["initial_state.trunk.theta=[-0.1, 0.02, 0]"], ["initial_state.legs.theta=[0.05, -0.01, 0]"],
            ["simulation.max_steps=12"])],  # stopped by its step limit
        "knee": [load_config(knee, ["simulation.t_end=0.05", "simulation.n_samples=26", *extra]) for extra in (
            [], ["initial_state.shank.theta=[0.6, 0.1, 0]"])],
        # chains of one structure, each run its own: the masses, gains, a torque limit (the hip's
        # clipped), a parent point and the admissible region differ (one call, each run's tree its own record)
        "params": [load_config(stance, [*short, "initial_state.trunk.theta=[-0.1, 0.02, 0]", *extra]) for extra in (
            [], ["bodies.trunk.mass=40.0", "joints.hip.k_r=[700, 700, 100]", "joints.hip.saturation.torque_n=[5, 5, .inf]"],
            ["joints.hip.parent_point=[0, 0.02, 0.4]"],
            ["simulation.limits.theta=[0.101, 1.0, 1.0]", "initial_state.trunk.omega=[-0.5, 0, 0]"])],  # leaves its region
        # gimbal lock: of the hip's Theta_j (the trunk's joint), then of the ankle's (the legs')
        "locked": [load_config(stance, [*short, "simulation.limits=null", *extra]) for extra in (
            ["initial_state.trunk.theta=[0, 1.3, 0]", "initial_state.trunk.omega=[0, 4, 0]"],
            ["initial_state.legs.theta=[0, 1.2, 0]", "initial_state.legs.omega=[0, 6, 0]"])],
        "pulsed3": [pulsed_chain(theta) for theta in (0.2, 0.4)],  # the second leaves
        "pushed3": [pulsed_chain(theta, impulses=True) for theta in (0.2, 0.4)],
        "hinged3": [hinged_chain(theta) for theta in (0.2, 0.4)],
        "ranged3": [ranged_chain(rate) for rate in (-0.5, -1.5)],  # the second leaves
        "stopped3": [stopped_chain(theta) for theta in (0.2, 0.4)],  # both leave: the region, simulation.limits
        "universal3": [universal_chain(rate) for rate in (-0.5, -8.0)],  # the second leaves q_2's region
        "balls3": [ball_chain(theta) for theta in (0.2, 0.4)],  # the second leaves simulation.limits
        "slides3": [slide_chain(rate) for rate in (-0.2, -3.0)],  # the second leaves the slide's region
    }


def same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def main() -> None:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"
    warnings.simplefilter("ignore")
    from rbstab.engine.cuda import integrate_chain_runs_cuda
    from rbstab.engine.integrate import integrate_chain_runs
    from rbstab.engine.settings import settings_rows
    from rbstab.engine.systems import tree_system
    from rbstab.simulator import simulate
    from rbstab.variants import chain as C

    report = {}
    for name, configs in cases(sys.argv[1]).items():
        start = time.perf_counter()
        sim = configs[0].simulation
        systems = [tree_system(C.compile_chain(c.chain), c.simulation.limits) for c in configs]
        system, tree_of = systems[0], None
        if name == "params":  # a tree a run
            system = system._replace(params=np.stack([s.params for s in systems]),
                                     ppoints=np.stack([s.ppoints for s in systems]))
            tree_of = np.arange(len(configs))
        y0 = np.array([C.initial_state(c) for c in configs])
        settings = settings_rows([c.simulation for c in configs])
        cpu = integrate_chain_runs(system, y0, settings, method=sim.method, n_samples=sim.n_samples, tree_of=tree_of)
        found = {"bodies": int(len(system.codes)), "status": cpu.status.tolist(), "n_steps": cpu.n_steps.tolist(),
                 "differences": []}
        if tree_of is not None:  # each run as the run alone
            for i, alone in enumerate(systems):
                one = integrate_chain_runs(alone, y0[i:i + 1], settings[i:i + 1], method=sim.method,
                                           n_samples=sim.n_samples)
                if not (same(one.samples[0], cpu.samples[i]) and same(one.n_steps[0], cpu.n_steps[i])):
                    found["differences"].append(["alone", i])
        for stride in (1, 3):
            gpu = integrate_chain_runs_cuda(system, y0, settings, method=sim.method, n_samples=sim.n_samples,
                                            stride=stride, tree_of=tree_of)
            for what in ("status", "t_stop", "nfev", "n_steps"):
                if not same(getattr(cpu, what), getattr(gpu, what)):
                    found["differences"].append([stride, what, str(getattr(cpu, what)), str(getattr(gpu, what))])
            if not same(cpu.samples[:, ::stride], gpu.samples):
                found["differences"].append([stride, "samples"])
            if not same(cpu.work[:, ::stride], gpu.work):
                found["differences"].append([stride, "work"])
        ref, got = simulate(configs[-1], engine="compiled"), simulate(configs[-1], engine="cuda")
        found["result"] = [what for what in ("status", "message", "solver") if getattr(ref, what) != getattr(got, what)]
        found["result"] += [key for key in ref.outputs if not same(ref.outputs[key], got.outputs[key])]
        found["result"] += [key for key in ref.summary if not _same_figure(key, ref.summary[key], got.summary[key])]
        found["streamed"] = streamed_summaries(configs)
        found["seconds"] = round(time.perf_counter() - start, 2)
        report[name] = found
    report["runs"] = analysis_runs(cases(sys.argv[1])["stance"])
    report["basin"] = basin(cases(sys.argv[1])["params"][3])
    print(json.dumps(report))


def streamed_summaries(configs) -> list:
    """The figures of the configs' runs as one batch with no samples kept (``keep="none"``:
    the tree kernel's streamed summaries, :func:`rbstab.summary.tree_stream_table`) that
    differ from the CPU's (:func:`rbstab.summary.tree_summary_table` of its samples): [figure,
    largest difference relative to the figure's scale] (none: they are equal bit for bit)."""
    from rbstab.engine.batch import batch_of
    from rbstab.simulator import simulate_batch

    batch = batch_of(configs)
    tables = []
    for engine in ("compiled", "cuda"):
        blocks = list(simulate_batch(batch, full=False, engine=engine, keep="none"))
        assert len(blocks) == 1 and list(blocks[0][0]) == list(range(len(configs)))
        tables.append(blocks[0][1].summaries)
    cpu, gpu = tables
    differences = [[key, "missing"] for key in cpu.keys() ^ gpu.keys()]
    for key in cpu.keys() & gpu.keys():
        if not same(cpu[key], gpu[key]):
            a, b = np.asarray(cpu[key]), np.asarray(gpu[key])
            if a.dtype == object or a.shape != b.shape:
                if a.tolist() != b.tolist():
                    differences.append([key, "not equal"])
                continue
            scale = max(1e-300, float(np.nanmax(np.abs(a), initial=0.0)))
            nan_same = bool(np.array_equal(np.isnan(a), np.isnan(b)))
            relative = float(np.nanmax(np.abs(a - b), initial=0.0)) / scale
            if not (nan_same and relative <= ROUNDED.get(key, -1.0)):
                differences.append([key, relative if nan_same else "NaN"])
    return sorted(differences)


#: Figures equal to a relative difference, not bit for bit: the centre of pressure's, whose
#: reactions the device solves from the reduced state its driver holds and the CPU from the
#: reduced state its samples give back (rbstab.simulator._ground_wrenches).
ROUNDED = {"cop_excursion": 1e-12}


def _same_figure(key: str, a, b) -> bool:
    """Whether a run's summary figure ``key`` is ``a`` on the CPU and ``b`` on the device:
    bit for bit, or within :data:`ROUNDED`."""
    if key not in ROUNDED or a is None or b is None:
        return str(a) == str(b)
    a, b = float(a), float(b)
    return (math.isnan(a) and math.isnan(b)) or abs(a - b) <= ROUNDED[key] * max(abs(a), abs(b))


def basin(config) -> dict:
    """A basin map of a stance chain with an admissible region (rbstab.analysis.basin_map:
    on the GPU each run's time to converge streamed, no sample back) against the CPU's: its
    counts, and the fields that differ (outcome, time to converge, v(0), v(t_end), the
    failures' messages)."""
    from rbstab.analysis.basin import BasinAxis, basin_map

    axes = [BasinAxis.parse("initial_state.legs.theta.0=-0.06:0.06:3"),
            BasinAxis.parse("initial_state.trunk.omega.0=-1:1:3")]
    cpu, gpu = (basin_map(config, axes, ratio=0.5, n_samples=31, engine=engine) for engine in ("compiled", "cuda"))
    fields = ("outcome", "time_to_converge", "lyapunov_initial", "lyapunov_final")
    return {"counts": cpu.counts(), "messages": sorted(cpu.messages),
            "differences": [f for f in fields if not same(getattr(cpu, f), getattr(gpu, f))]
            + ([] if cpu.messages == gpu.messages else ["messages"])}


def analysis_runs(configs) -> dict:
    """An analysis's runs of a tree (rbstab.analysis.runs.Runs: pushes, basin stability,
    basin maps) on the GPU against the CPU: the outcomes and the traces of v of the runs
    from the configs' initial states."""
    from rbstab.analysis.runs import Runs
    from rbstab.variants import chain as C

    states = np.array([C.initial_state(c) for c in configs[:3]])
    cpu, gpu = (Runs(configs[0], engine=engine) for engine in ("compiled", "cuda"))
    outcomes = cpu.outcomes(states), gpu.outcomes(states)
    traces = cpu.traces(states, 7), gpu.traces(states, 7)
    return {"success": outcomes[0][0].tolist(), "outcomes": same(*outcomes),
            "traces": [same(a, b) if isinstance(a, np.ndarray) else a == b for a, b in zip(*traces)]}


if __name__ == "__main__":
    main()
