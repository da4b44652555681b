"""The CUDA engine's one-body runs under numba's CUDA simulator against the CPU engine, run by
tests/test_cuda.py in a process of its own (the simulator is chosen when numba starts:
``NUMBA_ENABLE_CUDASIM=1``).

Prints one JSON object: for each run of every variant and method (runs that reach t_end and
runs stopped by their step limit), which of its status, message, solver counts, summary
figures and outputs at the samples differ from the CPU engine's, for each ``keep``; whether
a basin map's outcomes, times to converge and v(t_end) equal the CPU engine's; a launch's
deadline; the types every launch passes.
"""

from __future__ import annotations

import json
import os
import sys
import warnings

import numpy as np

#: One config of each variant (sliding with its boundary layer: on the GPU).
CONFIGS = ["configs/paper/case1_permanent.yaml", "configs/paper/case2_visco_elastic.yaml",
           "configs/paper/case3_embedded.yaml", "configs/examples/free_gravity.yaml",
           "configs/examples/sliding.yaml"]


def configs(root: str):
    """Each config with each method, as it is, stopped by its step limit, and with another
    t_end (a launch of its own); and a pure-sign-law run (the CPU engine's in both)."""
    import rbstab

    out = []
    for path in CONFIGS:
        for method in ("RK23", "RK45", "DOP853"):
            for extra in ([], ["simulation.max_steps=12"], ["simulation.t_end=0.3"]):
                out.append(rbstab.load_config(os.path.join(root, path), [
                    "simulation.t_end=0.5", "simulation.n_samples=401", f"simulation.method={method}", *extra]))
    out.append(rbstab.load_config(os.path.join(root, CONFIGS[-1]), [
        "simulation.t_end=0.05", "simulation.n_samples=51", "controller.boundary_layer=0"]))
    # runs that leave their admissible region (simulation.limits): a bound of X (permanent) or
    # E (the others) on each variant, one of theta
    for path, bound in zip(CONFIGS, ("position=0.05", *["constraint_error=[0.01, 0.02, .inf]"] * 4)):
        out.append(rbstab.load_config(os.path.join(root, path), [
            "simulation.t_end=0.5", "simulation.n_samples=401", "simulation.method=RK45", f"simulation.limits.{bound}"]))
    out.append(rbstab.load_config(os.path.join(root, CONFIGS[1]), [
        "simulation.t_end=0.5", "simulation.n_samples=401", "simulation.limits.theta=[0.3, 0.2, 3]"]))
    return out


def main() -> None:
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"
    warnings.simplefilter("ignore")
    from rbstab.simulator import simulate_blocks

    recorded = record_launches()
    runs = configs(sys.argv[1])

    def collect(engine, keep):
        out = {}
        for indices, block in simulate_blocks(runs, engine=engine, keep=keep, full=False):
            for j, i in enumerate(indices):
                out[i] = (block.result(j), block.stride)
        return out

    reference = collect("compiled", "all")
    report = {"variants": sorted({c.chain.joints[0].variant for c in runs}),
              "methods": sorted({c.simulation.method for c in runs}),
              "statuses": sorted({r.status for r, _ in reference.values()}),
              "left_region": sorted({r.message.split(" = ")[0] for r, _ in reference.values()
                                     if r.message.startswith("left the admissible region")})}
    for keep in ("all", "thinned", "none"):
        found = collect("cuda", keep)
        differences = []
        for i, (ref, _) in reference.items():
            got, stride = found[i]
            for what in ("status", "message", "solver"):
                if getattr(ref, what) != getattr(got, what):
                    differences.append([i, what, str(getattr(ref, what)), str(getattr(got, what))])
            for key, value in ref.summary.items():
                if str(value) != str(got.summary[key]):
                    differences.append([i, key, str(value), str(got.summary[key])])
            if keep != "none":
                for key, value in ref.outputs.items():
                    a, b = value[::stride], got.outputs[key]
                    if not np.array_equal(a, b, equal_nan=True):
                        scale = float(np.nanmax(np.abs(a))) or 1.0
                        differences.append([i, key, ref.status, float(np.nanmax(np.abs(a - b))) / scale])
        report[keep] = {"runs": len(found), "strides": sorted({s for _, s in found.values()}),
                        "differences": differences}
    report["basin"] = basin()
    report["batch"] = batch()
    report["push"] = push(sys.argv[1])
    report["disturbed"] = disturbed()
    report["deadline"] = deadline()
    report["signatures"] = signatures(recorded)
    print(json.dumps(report))


def record_launches() -> set:
    """Record numba's types of every simulated launch's arguments, with its kernel's tree
    shape and whether it is one body's: the set the launches of this process add to."""
    import numba

    import rbstab.engine.cuda as engine

    recorded = set()
    compiled = engine.compiled_tree_kernel

    class Recording:
        def __init__(self, fn, kernel):
            self.fn, self.kernel = fn, kernel

        def __getitem__(self, grid):
            launch = self.fn[grid]

            def call(*args):
                recorded.add((self.kernel, tuple(str(numba.typeof(engine._plain(a))) for a in args)))
                return launch(*args)

            return call

    engine.compiled_tree_kernel = lambda method, shape, one_body=False: Recording(compiled(method, shape, one_body),
                                                                                 (*shape, one_body))
    return recorded


def signatures(recorded: set) -> dict:
    """Whether every launch passed the arguments of rbstab.engine.cuda.tree_launch_signature."""
    from rbstab.engine.cuda import tree_launch_signature

    expected = tuple(str(t) for t in tree_launch_signature())
    return {"launches": len(recorded), "kernels": [list(k) for k in sorted({kernel for kernel, _ in recorded})],
            "mismatched": sorted(str(kernel) for kernel, types in recorded if types != expected)}


def deadline() -> dict:
    """Two launches of 600 Case 3 runs on a grid of 4 blocks: the first with no limit, the
    second with a 1 ns limit, every device array it gets poisoned (set to 7): what the
    second's runs report (every run is written, none starts after the deadline)."""
    import rbstab
    import rbstab.engine.cuda as engine
    from rbstab.engine.settings import settings_rows
    from rbstab.variants.paper import paper_initial_state
    from rbstab.engine.status import NOT_STARTED, status_message
    from rbstab.engine.systems import tree_system, with_offsets
    from rbstab.variants.chain import compile_chain

    config = rbstab.load_config(os.path.join(sys.argv[1], "configs/paper/case3_embedded.yaml"),
                                ["simulation.t_end=0.002"])
    compiled = compile_chain(config.chain)
    system = with_offsets(tree_system(compiled, config.simulation.limits), compiled.offset)
    k = 600
    y0 = np.repeat(paper_initial_state(config)[None], k, axis=0)
    rows = np.repeat(settings_rows([config.simulation]), k, axis=0)
    engine._resident_blocks = lambda fn, signature: 4

    def launch(limit):
        return engine.integrate_chain_runs_cuda(system, y0, rows, method=config.simulation.method, n_samples=5,
                                                max_wall_time=limit)

    first = launch(np.inf)
    allocate = engine.cuda.device_array
    engine.cuda.device_array = lambda shape, dtype=np.float64: engine.cuda.to_device(np.full(shape, 7, dtype=dtype))
    try:
        second = launch(1e-9)
    finally:
        engine.cuda.device_array = allocate
    outputs = (second.acc, second.members, second.last, second.samples, second.work)
    return {"first_success": int(np.sum(first.status == 0)),
            "not_started": int(np.sum(second.status == NOT_STARTED)),
            "t_stop_zero": bool(np.all(second.t_stop == 0)),
            "nfev_zero": bool(np.all(second.nfev == 0)) and bool(np.all(second.n_steps == 0)),
            "last_nan": bool(np.all(np.isnan(second.last))),
            "samples_nan": bool(np.all(np.isnan(second.samples)) and np.all(np.isnan(second.work))),
            "poison_left": int(sum(np.sum(a == 7) for a in outputs)),
            "message": status_message(NOT_STARTED, 0.0, 0.0, max_wall_time=1e-9)}


def push(root: str) -> dict:
    """The smallest fatal push of two directions of the saturated pendulum (a short ladder,
    a loose tolerance: few runs) on the CPU engine and on the GPU: the thresholds, the
    ladders' outcomes and the counts of runs."""
    from rbstab import load_config
    from rbstab.analysis.push import push_analysis

    config = load_config(os.path.join(root, "configs/examples/saturated_pendulum.yaml"),
                         ["simulation.n_samples=41", "simulation.t_end=2.0", "simulation.rtol=1e-6",
                          "simulation.atol=1e-8"])
    found = {engine: push_analysis(config, "torque", directions=[[1.0, 0.0, 0.0], [0.3, 1.0, 0.0]], push_max=2.0,
                                   rungs=4, tol=0.05, engine=engine) for engine in ("compiled", "cuda")}
    a, b = found["compiled"], found["cuda"]
    return {"thresholds": a.threshold.tolist(), "runs": a.runs,
            "equal": {"threshold": bool(np.array_equal(a.threshold, b.threshold)),
                      "ladder": bool(np.array_equal(a.thresholds.ladder_recovered, b.thresholds.ladder_recovered)),
                      "runs": a.runs == b.runs}}


def batch() -> dict:
    """A sweep table's batch of runs (every variant, each run its own body and gains, and a
    body with saturating actuators) on the GPU against the CPU engine (rbstab.simulator.simulate_batch): how many runs, and
    which of their figures and outputs differ."""
    from rbstab.simulator import simulate_batch
    from rbstab.sweep import plan_table, spec_from_mapping

    rng = np.random.default_rng(5)
    n = 3
    bases = [*CONFIGS, "configs/examples/saturated_pendulum.yaml"]  # and saturating actuators
    spec = spec_from_mapping({"name": "b", "base": [os.path.join(sys.argv[1], c) for c in bases], "zip": {
        "body.mass": rng.uniform(20, 60, n).tolist(),
        "controller.k_t.1": rng.uniform(3000, 5000, n).tolist(),
        "initial_state.omega": rng.normal([16, 32, -16], 4, (n, 3)).tolist(),
        "simulation.t_end": [0.2] * n, "simulation.n_samples": [401] * n}})
    runs = plan_table(spec).slice(np.arange(len(bases) * n)).batch()
    blocks = {engine: {i: block.result(j) for rows, block in simulate_batch(runs, engine=engine, keep="thinned")
                       for j, i in enumerate(rows)} for engine in ("compiled", "cuda")}
    differences = []
    for i, ref in blocks["compiled"].items():
        got = blocks["cuda"][i]
        differences += [[i, key] for key, value in ref.summary.items() if str(value) != str(got.summary[key])]
        differences += [[i, key] for key, value in ref.outputs.items()
                        if not np.array_equal(value[::2], got.outputs[key], equal_nan=True)]
    return {"runs": len(blocks["cuda"]), "differences": differences}


#: Disturbed runs, each a base and its overrides (t_end 0.2 s, 201 samples: 0.05, 0.1 and
#: 0.15 s are sample times): every kind, forces at a point and torques, impulses at t = 0, at
#: a sample time inside the run and at t_end (on ``permanent`` too), edges between samples
#: and on them, actuators that saturate (clip and smooth), each method; an impulse that
#: takes the state out of the admissible region.
DISTURBED = [
    ("configs/paper/case2_visco_elastic.yaml", [
        "simulation.method=RK45",
        "disturbances=[{kind: impulse, value: [0, 20, 5], point: [0, 0.1, 0.2], start: 0},"
        " {kind: pulse, value: [0, 400, 100], point: [0.1, 0, 0], start: 0.05, duration: 0.0375},"
        " {kind: step, quantity: torque, value: [20, 0, -10], start: 0.1},"
        " {kind: sine, quantity: torque, value: [10, 20, 0], frequency: 10, phase: 0.5, start: 0.0625}]"]),
    ("configs/paper/case3_embedded.yaml", [
        "controller.saturation={torque_n: 400, force_h: [300, 300, 500], constraint_force: 2000}",
        "disturbances=[{kind: noise, rms: [200, 100, 0], band: [2, 30], seed: 7, point: [0, 0, 0.1], start: 0.02},"
        " {kind: impulse, quantity: torque, value: [1, 0, 0.2], start: 0.2}]"]),
    ("configs/paper/case1_permanent.yaml", [
        "simulation.method=RK23",
        "disturbances=[{kind: impulse, value: [0, 15, 0], point: [0, 0, 0.2], start: 0.1},"
        " {kind: sine, value: [50, 0, 30], point: [0.1, 0, 0], frequency: 4, start: 0}]"]),
    ("configs/examples/free_gravity.yaml", [
        "controller.saturation={torque_n: 600, force_h: 800, shape: smooth}",
        "disturbances=[{kind: impulse, quantity: torque, value: [2, -3, 0.5], start: 0},"
        " {kind: step, value: [100, 0, 50], point: [0, 0.2, 0], start: 0.15},"
        " {kind: noise, quantity: torque, rms: 20, band: [0, 40], seed: 2, start: 0.03}]"]),
    ("configs/examples/sliding.yaml", [
        "controller.saturation={constraint_force: 1500}",
        "disturbances=[{kind: pulse, quantity: torque, value: [0, 30, 0], start: 0.1, duration: 0.05},"
        " {kind: impulse, value: [10, 0, -10], point: [0.1, 0.1, 0], start: 0.2}]"]),
    ("configs/examples/saturated_pendulum.yaml", [
        "disturbances=[{kind: impulse, quantity: torque, value: [0.2, 0, 0], start: 0.05},"
        " {kind: pulse, value: [3, 0, 0], point: [0, 0, 0.5], start: 0.12, duration: 0.013}]"]),
    # an impulse that takes V out of the admissible region (simulation.limits) at t = 0.1 s
    ("configs/paper/case3_embedded.yaml", [
        "simulation.limits.velocity=[.inf, 5, .inf]",
        "disturbances=[{kind: sine, quantity: torque, value: [5, 5, 0], frequency: 3, start: 0},"
        " {kind: impulse, value: [0, 328, 0], start: 0.1}]"]),
]


def disturbed() -> dict:
    """The runs of :data:`DISTURBED`, each a sweep table's batch of one run (its
    disturbances the table's columns), on the GPU against the CPU engine
    (rbstab.simulator.simulate_batch, thinned): which summary figures and outputs differ,
    the variants, methods and kinds run, each run's W at its last sample [J] and message,
    and for each run with an
    impulse at t_end: the impulse, the body's m and J, whether theta, omega, V and W equal
    those of the same run without it (CPU engine) before the last sample, and both runs'
    at the last."""
    from rbstab.engine import METHODS
    from rbstab.model import DISTURBANCE_KINDS
    from rbstab.simulator import simulate_batch
    from rbstab.sweep import plan_table, spec_from_mapping

    names = {float(code): kind for kind, code in DISTURBANCE_KINDS.items()}
    differences, variants, methods, kinds, work, last_jump, messages = [], [], [], set(), [], [], []
    for n, (base, overrides) in enumerate(DISTURBED):
        spec = spec_from_mapping({"name": "d", "base": os.path.join(sys.argv[1], base), "zip": {
            "simulation.t_end": [0.2]}}, overrides=["simulation.n_samples=201", *overrides])
        runs = plan_table(spec).slice(np.arange(1)).batch()
        p = runs.params[0, 0]
        kinds |= {names[float(k)] for k in p["disturbance_kind"][: int(p["disturbance_count"])]}
        found = {engine: [(block.result(0), block.stride, block.variants[0]) for _, block in
                          simulate_batch(runs, engine=engine, keep="thinned")] for engine in ("compiled", "cuda")}
        (ref, _, variant), (got, stride, _) = found["compiled"][0], found["cuda"][0]
        variants.append(variant)
        methods.append(METHODS[int(runs.settings["method"][0])])
        differences += [[n, key] for key, value in ref.summary.items() if str(value) != str(got.summary[key])]
        differences += [[n, key] for key, value in ref.outputs.items()
                        if not np.array_equal(value[::stride], got.outputs[key], equal_nan=True)]
        differences += [[n, what] for what in ("status", "message", "solver") if str(getattr(ref, what)) != str(
            getattr(got, what))]
        work.append(float(ref.outputs["disturbance_work"][-1]))
        messages.append(ref.message)
        at_end = (p["disturbance_kind"] == DISTURBANCE_KINDS["impulse"]) & (p["disturbance_start"] == 0.2)
        if at_end.any():  # the same run without its impulse at t_end
            (i,) = np.flatnonzero(at_end)
            impulse = {"value": p["disturbance_value"][i].tolist(), "point": p["disturbance_point"][i].tolist(),
                       "torque": bool(p["disturbance_torque"][i]), "mass": float(p["mass"]),
                       "inertia": p["inertia"].tolist()}
            runs.params["disturbance_value"][0, 0, i] = 0.0
            (_, block), = simulate_batch(runs, engine="compiled")
            without = block.result(0).outputs
            keys = ("theta", "omega", "velocity", "disturbance_work")
            last_jump.append({"earlier_equal": all(np.array_equal(ref.outputs[k][:-1], without[k][:-1]) for k in keys),
                              **impulse, **{k: [np.atleast_1d(o[k][-1]).tolist() for o in (ref.outputs, without)]
                                            for k in keys}})
    return {"runs": len(DISTURBED), "differences": differences, "variants": variants, "methods": sorted(set(methods)),
            "kinds": sorted(kinds), "work": work, "messages": messages, "impulse_at_t_end": last_jump}


def basin() -> dict:
    """A basin map of Case 3 on the GPU against the CPU engine's (outcomes, times to
    converge, v(t_end), messages), ``plain``, and a small one with DISTURBED's saturation
    and disturbances, ``disturbed`` (with ``pushed``: its v(t_end) differs at every point
    from the map without them)."""
    import rbstab
    from rbstab.analysis.basin import BasinAxis, basin_map

    config = rbstab.load_config(os.path.join(sys.argv[1], "configs/paper/case3_embedded.yaml"),
                                ["simulation.t_end=0.3"])
    axes = [BasinAxis.parse("initial_state.omega.0=-60:60:4"), BasinAxis.parse("initial_state.theta.1=0.3:1.6:4")]
    maps = {engine: basin_map(config, axes, ratio=0.05, n_samples=61, engine=engine) for engine in ("compiled", "cuda")}
    # and a small one of a disturbed, saturated Case 3 (DISTURBED's)
    disturbed = rbstab.load_config(os.path.join(sys.argv[1], DISTURBED[1][0]), ["simulation.t_end=0.2",
                                                                                *DISTURBED[1][1]])
    axes = [BasinAxis.parse("initial_state.omega.0=-30:30:3"), BasinAxis.parse("initial_state.theta.1=0.3:0.9:2")]
    # ratio 0.5: against the energy to lose (v(0) plus what the disturbances added) one point converges
    pushed = {engine: basin_map(disturbed, axes, ratio=0.5, n_samples=41, engine=engine)
              for engine in ("compiled", "cuda")}
    out = {}
    for label, (a, b) in (("plain", (maps["compiled"], maps["cuda"])), ("disturbed", (pushed["compiled"],
                                                                                      pushed["cuda"]))):
        out[label] = {"outcomes": sorted(set(a.outcome.ravel().tolist())),
                      "equal": {name: bool(np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True))
                                for name in ("outcome", "time_to_converge", "lyapunov_final", "lyapunov_initial")},
                      "messages": a.messages == b.messages}
    # the disturbances act in the map: v(t_end) differs from the undisturbed map's
    plain = basin_map(rbstab.load_config(os.path.join(sys.argv[1], DISTURBED[1][0]), ["simulation.t_end=0.2"]), axes,
                      ratio=0.5, n_samples=41)
    out["disturbed"]["pushed"] = bool(np.all(pushed["compiled"].lyapunov_final != plain.lyapunov_final))
    return out


if __name__ == "__main__":
    main()
