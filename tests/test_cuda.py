"""The CUDA engine (rbstab.engine.cuda) without a GPU: its driver under numba's CUDA simulator
bit for bit against the CPU engine, its kernel compiled to PTX for sm_90, the streamed
summary against summary_table, and --engine cuda where no GPU is. Tests that need a real
GPU skip without one."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import rbstab
from rbstab.variants.paper import paper_form
from rbstab.layout import N_OUTPUTS
from rbstab.summary import ACCUMULATOR_SIZE, short_stencils, stencil_weights, stream_finish, stream_start

from conftest import ROOT, simulated_once
from reference import rotation

numba_cuda = pytest.importorskip("numba_cuda", reason="numba-cuda is not installed (pip install -e '.[test]')")
from numba import cuda  # noqa: E402  (numba-cuda's target)

CASE3 = str(ROOT / "configs" / "paper" / "case3_embedded.yaml")
SATURATED = str(ROOT / "configs" / "examples" / "saturated_pendulum.yaml")
#: The console script beside this interpreter.
RBSTAB = os.path.join(os.path.dirname(sys.executable), "rbstab")


def _has_gpu() -> bool:
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - no driver: no GPU
        return False


GPU = _has_gpu()


# -- the streamed summary (compiled for the CPU here) -------------------------------------------------
SATURATED_FALL = ["initial_state.theta=[0.45,0,0]"]  # the torque limit cannot hold it: flags set
PUSHED = str(ROOT / "configs" / "examples" / "saturated_push.yaml")
PUSHES = ["disturbances.1.start=0.7"]  # the impulse at 0.5 s and the pulse inside the run: 3 edges


@pytest.mark.parametrize("path, overrides", [
    (CASE3, []), (CASE3, ["simulation.max_steps=40"]), (CASE3, ["simulation.max_steps=13"]),
    (CASE3, ["simulation.max_steps=3"]), (SATURATED, SATURATED_FALL), (SATURATED, [*SATURATED_FALL, "simulation.max_steps=6"]),
    (PUSHED, PUSHES), (PUSHED, [*PUSHES, "simulation.max_steps=12"])],
    ids=["whole", "stopped", "short", "shorter", "saturated", "saturated-stopped", "pushed", "pushed-stopped"])
def test_streamed_summary_of_one_body_is_the_cpus(path, overrides):
    """Fed a one-body run's samples one at a time, as the GPU's one-body kernel feeds them
    (keep_sample of its TreeStreamSink with the body's record: body_stream_sample, the kept
    rows, the last sample), stream_finish / tree_stream_table give the CPU engine's figures
    from the run's samples, the same numbers: the saturated time fractions of a run whose
    torque is at its limit among them, the rate check of a pushed run (which leaves out the
    stencils across a push), and the figures of runs stopped after a few samples (the
    one-sided stencils of their own samples); and numerical_rate's dv/dt at the samples, for
    a run stopped early the first samples' up to rounding."""
    from rbstab.engine.cuda import TreeStreamSink
    from rbstab.engine.integrate import SampleRows, keep_sample
    from rbstab.jit import jit
    from rbstab.simulator import simulate
    from rbstab.summary import MEMBER_SLOTS, stream_member_start, tree_stream_table

    n = 101
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = rbstab.load_config(path, ["simulation.t_end=1.0", f"simulation.n_samples={n}", *overrides])
    result = simulate(config)
    variant = paper_form(config)
    states = np.column_stack([result.outputs[b] for b in variant.layout.blocks])
    samples = np.column_stack([states, result.outputs["disturbance_work"]])  # the state, then W
    taken = int(np.isfinite(states[:, 0]).sum())
    assert (taken == n) == ("simulation.max_steps" not in " ".join(overrides))
    time = np.linspace(0.0, 1.0, n)
    first, weights = stencil_weights(time)
    acc, members, last = np.empty(ACCUMULATOR_SIZE), np.empty((1, MEMBER_SLOTS)), np.empty(samples.shape[1])
    rates = np.full(n, -1.0)
    kept = SampleRows(np.full((n, states.shape[1]), -1.0), np.full(n, -1.0), 1)
    sink = TreeStreamSink(acc, members, np.zeros(N_OUTPUTS), np.empty((1, 3, 3)), last, first, weights, 1e-3, 0.0,
                          kept, rates, (np.empty(1), np.empty((1, 6)), np.empty((1, 3)), np.empty((1, 3))))
    keep = jit(lambda sink, code, p, j, t, sample, work: keep_sample(sink, code, p, j, t, sample, work))
    stream_start(acc)
    stream_member_start(members)
    for i in range(taken):
        keep(sink, variant.code, variant.parameters[0], i, time[i], samples[i], samples[i, -1])
    stream_finish(acc, first, weights, short_stencils(time), rates, 1)
    assert np.array_equal(last, samples[taken - 1])
    assert np.array_equal(kept.samples[:taken], states[:taken]) and np.array_equal(kept.work[:taken],
                                                                                  samples[:taken, -1])
    embedded = "controller_state" in variant.layout.blocks
    maximal = np.concatenate([result.outputs[b][taken - 1] for b in ("theta", "omega", "position", "velocity",
                                                                       *(["controller_state"] if embedded else []))])
    got = tree_stream_table(time, acc[None], members[None], maximal[None], 1, np.array([12 if embedded else -1]))
    assert set(got) == set(result.summary)
    for key, value in got.items():
        found = value[0, 0] if value.ndim == 3 else value[0]
        assert str(np.asarray(found).tolist()) == str(np.asarray(result.summary[key]).tolist()), key
    assert (got["fraction_saturated_torque_n"][0, 0, 0] > 0) == (path != CASE3)
    if path == PUSHED and taken == n:  # across the pushes the numerical dv/dt is no derivative: left out
        assert str(got["lyapunov_rate_check"][0]) == "pass"
    rate = result.outputs["lyapunov_rate_numerical"][:taken]
    if taken == n or taken < 7:  # the whole grid's stencils, or the first samples' own (short_stencils)
        np.testing.assert_array_equal(rates[:taken], rate)
    else:  # the whole grid's stencils, not the first samples' own: rounding
        scale = np.max(np.abs(result.outputs["lyapunov"][:taken]))
        np.testing.assert_allclose(rates[:taken], rate, rtol=0, atol=1e-12 * scale)
    assert np.all(rates[taken:] == -1.0)  # the samples never taken: the kernel's NaN rows


# -- the driver under the CUDA simulator ------------------------------------------------------------------
@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """tests/cuda_simulated.py's findings (~40 s), run once a test session
    (:func:`conftest.simulated_once`)."""
    return simulated_once(tmp_path_factory, "cuda_simulated.py")


def test_simulated_driver_covers_every_variant_and_method(simulated):
    assert simulated["variants"] == ["embedded", "free", "permanent", "sliding", "visco_elastic"]
    assert simulated["methods"] == ["DOP853", "RK23", "RK45"]
    assert simulated["statuses"] == ["failed", "success"]
    assert simulated["left_region"] == [  # the limits runs leave their region, each at the bound it names
        "left the admissible region: |E_1| reached simulation.limits.constraint_error",
        "left the admissible region: |X_1| reached simulation.limits.position",
        "left the admissible region: |theta_2| reached simulation.limits.theta"]
    assert simulated["thinned"]["strides"] == [1, 2] and simulated["all"]["strides"] == [1]  # 1: the sign law (CPU)


@pytest.mark.parametrize("keep", ["all", "thinned", "none"])
def test_simulated_driver_is_the_cpu_engine_bit_for_bit(simulated, keep):
    """Status, message, nfev, steps, every summary figure (streamed on the device) and every
    output at the kept samples equal the CPU engine's, but a thinned trace's numerical dv/dt
    of a run stopped early (taken on the device with the whole grid's stencils: rounding)."""
    found = simulated[keep]
    assert found["runs"] == 52
    for run, what, status, relative in found["differences"]:
        assert keep == "thinned" and what == "lyapunov_rate_numerical" and status == "failed", (run, what, status)
        assert relative < 1e-12


def test_simulated_basin_map_is_the_cpu_engines(simulated):
    """A basin map on the GPU (each run's time to converge streamed): the CPU engine's
    outcomes (converged, not converged and failed among them), times, v(t_end), messages."""
    basin = simulated["basin"]["plain"]
    assert basin["outcomes"] == [0, 1, 2]
    assert basin["equal"] == {"outcome": True, "time_to_converge": True, "lyapunov_final": True,
                              "lyapunov_initial": True}
    assert basin["messages"]


def test_simulated_disturbed_basin_map_is_the_cpu_engines(simulated):
    """A basin map with saturating actuators and disturbances on the GPU: the CPU engine's
    outcomes, times, v(t_end) and messages; the disturbances act (v(t_end) is not that of
    the map without them at any point)."""
    basin = simulated["basin"]["disturbed"]
    assert basin["outcomes"] == [0, 1]
    assert basin["equal"] == {"outcome": True, "time_to_converge": True, "lyapunov_final": True,
                              "lyapunov_initial": True}
    assert basin["messages"] and basin["pushed"]


def test_simulated_push_thresholds_are_the_cpu_engines(simulated):
    """The push analysis (a saturated impulse ladder and bisection, batches of pushed runs)
    on the GPU finds the CPU engine's thresholds, ladders and runs."""
    push = simulated["push"]
    assert push["equal"] == {"threshold": True, "ladder": True, "runs": True}
    assert all(0 < t < 2.0 for t in push["thresholds"]) and push["runs"] > 8


def test_simulated_batch_is_the_cpu_engines(simulated):
    """A sweep table's batch (5 variants and a body with saturating actuators, each run its
    own record; no config objects) on the GPU: every summary figure and thinned output equal
    to the CPU engine's."""
    assert simulated["batch"] == {"runs": 18, "differences": []}


def test_simulated_disturbed_runs_are_the_cpu_engines(simulated):
    """Disturbed runs (every kind, forces at a point and torques, impulses at t = 0, at a
    sample time, at t_end, on the pinned body and out of the admissible region; saturating
    actuators; each method), each a sweep table's batch, on the GPU: status, message,
    solver counts, every summary figure and thinned output (disturbance_power and
    disturbance_work among them) equal to the CPU engine's. The runs did take the
    disturbances: W(t_end) is not 0 in any that reaches it, and an impulse at t_end changes
    the last sample only, by its jump."""
    found = simulated["disturbed"]
    assert found["runs"] == 7 and found["differences"] == []
    assert sorted(set(found["variants"])) == ["embedded", "free", "permanent", "sliding", "visco_elastic"]
    assert found["methods"] == ["DOP853", "RK23", "RK45"]
    assert found["kinds"] == ["impulse", "noise", "pulse", "sine", "step"]
    assert all(w != 0.0 and np.isfinite(w) for w in found["work"][:6])
    # the last: its impulse at 0.1 s takes V_2 beyond its bound, where the run stops
    assert found["messages"][6].startswith("left the admissible region: |V_2| reached simulation.limits.velocity")
    assert found["messages"][6].endswith("at t = 0.1 s") and np.isnan(found["work"][6])
    # a torque impulse at t_end (embedded) and a force's at a point (sliding), against the
    # same runs without them: only the last sample differs, by the jump of the velocities
    # (J dOmega = L or R_p x A'P, dV = P/m) and of W by the jump of T
    kinds = []
    for run in found["impulse_at_t_end"]:
        assert run["earlier_equal"]
        (theta, theta_0), (omega, omega_0), (v, v_0), (w, w_0) = (
            np.array(run[k]) for k in ("theta", "omega", "velocity", "disturbance_work"))
        m, j, value = run["mass"], np.array(run["inertia"]), np.array(run["value"])
        np.testing.assert_array_equal(theta, theta_0)
        moment = value if run["torque"] else np.cross(run["point"], rotation(theta).T @ value)
        np.testing.assert_allclose(j @ (omega - omega_0), moment, rtol=1e-12, atol=1e-12 * np.abs(moment).max())
        np.testing.assert_allclose(v - v_0, 0.0 if run["torque"] else value / m, rtol=1e-12, atol=1e-14)
        energy = [0.5 * m * u @ u + 0.5 * o @ j @ o for u, o in ((v, omega), (v_0, omega_0))]
        np.testing.assert_allclose(w - w_0, energy[0] - energy[1], rtol=1e-9)
        kinds.append(run["torque"])
    assert kinds == [True, False]


@pytest.mark.parametrize("store", ["thinned", "summary"])
def test_simulated_sweep_writes_the_cpu_engines_store(tmp_path, store):
    """``rbstab sweep --engine cuda`` (its workers' batch of runs on the GPU, under the
    simulator) writes the store the CPU engine writes: every variable equal but the wall
    times."""
    spec = [CASE3, "--random", "controller.k_c=scale_uniform:[0.5,2]", "--random", "body.mass=scale_uniform:[0.5,1.5]",
            "--random", "initial_state.omega=normal:{mean: [16,32,-16], std: 4}", "-n", "6", "--seed", "3",
            "--set", "simulation.t_end=0.4", "--set", "simulation.n_samples=401", "--store", store, "--no-progress"]
    stores = {}
    for engine in ("compiled", "cuda"):
        env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1" if engine == "cuda" else "0"}
        done = subprocess.run([RBSTAB, "sweep", *spec, "--engine", engine, "-o", str(tmp_path / engine)],
                              capture_output=True, text=True, env=env, timeout=600)
        assert done.returncode == 0, done.stderr
        stores[engine] = rbstab.open_sweep(tmp_path / engine / "case3_embedded")
    cpu, gpu = stores["compiled"], stores["cuda"]
    assert set(cpu.data_vars) == set(gpu.data_vars) and cpu.sizes == gpu.sizes
    assert ("time" in cpu.sizes) == (store == "thinned")
    for name in cpu.data_vars:
        if name != "wall_time":
            assert np.array_equal(cpu[name].values, gpu[name].values,
                                  equal_nan=cpu[name].dtype.kind == "f"), name


def test_simulated_launch_has_one_deadline_and_writes_every_run(simulated):
    """A launch of 600 runs on 4 blocks with a 1 ns limit, every device array it gets
    poisoned first (what memory may hold): no thread of any block starts a run after the
    launch's deadline, and every run's outputs are written: NOT_STARTED with its reason,
    t_stop 0, no evaluations, NaN samples and last state (the CPU engine's rows after a
    stop)."""
    found = simulated["deadline"]
    assert found["first_success"] == 600
    assert found["not_started"] == 600
    assert found["t_stop_zero"] and found["nfev_zero"] and found["last_nan"] and found["samples_nan"]
    assert found["poison_left"] == 0
    assert found["message"].startswith("not run:") and "1e-09 s" in found["message"]


def test_simulated_launches_pass_the_compiled_signature(simulated):
    """Every launch of the simulated runs (one body's three kernels: permanent, embedded and
    the others' joint) passes exactly the types of tree_launch_signature, the signature the
    GPU's kernels are compiled for (and the PTX tests compile): C-contiguous arrays, the
    aligned settings record."""
    found = simulated["signatures"]
    assert found["kernels"] == [[1, 0, 0, 0, 0, 0, 0, True], [1, 0, 1, 0, 0, 0, 0, True], [1, 1, 0, 0, 0, 0, 0, True]] \
        and found["launches"] >= 3
    assert found["mismatched"] == []


# -- compiled for a GPU, without one ------------------------------------------------------------------------
def _compilers() -> bool:
    """Whether NVVM and NVRTC (the CUDA 12 compiler wheels of numba-cuda[cu12]) are here."""
    try:
        from cuda.pathfinder import load_nvidia_dynamic_lib
        from numba.cuda.cudadrv import nvvm

        load_nvidia_dynamic_lib("nvrtc")
        return bool(nvvm.is_available())
    except Exception:  # noqa: BLE001 - no compiler wheels
        return False


def ptx_for_sm_90(monkeypatch, function, signature) -> str:
    """The PTX of the kernel ``function`` for sm_90 with the argument types ``signature``,
    checked: numba types and lowers every function it calls for CUDA, NVVM generates the
    PTX, and the PTX declares no external function (a call of numba's runtime or of a
    library the GPU lacks would be one, and would not link). Compiled without optimisation
    (a quarter of the time): the registers and local memory of the optimised kernel are
    ``benchmarks/gpu.py``'s, measured on a device."""
    import numba.cuda.dispatcher

    class Device:  # numba-cuda asks the current device's compute capability for called dispatchers
        compute_capability = (9, 0)

    if not GPU:
        monkeypatch.setattr(numba.cuda.dispatcher, "get_current_device", lambda: Device())
    ptx, _ = cuda.compile_ptx(function, signature, cc=(9, 0), opt=False)
    assert ".target sm_90" in ptx and ".entry" in ptx
    assert "globaltimer" in ptx  # the launch's wall-time limit reads the GPU's clock
    assert re.search(r"atom(\.global)?\.cas\.b64", ptx)  # the launch's one deadline
    externs = re.findall(r"^\s*\.extern\s+\.func\b.*$", ptx, re.M)
    assert not externs, externs[:3]
    return ptx


@pytest.mark.slow
@pytest.mark.skipif(not _compilers(), reason="NVVM and NVRTC (numba-cuda[cu12]'s compiler wheels) are not installed")
def test_one_body_kernel_compiles_to_ptx_for_sm_90(monkeypatch):
    """One body's kernel (every variant's physics, DOP853, outputs, streamed summary;
    tree_launch_signature's types) compiles for CUDA from the CPU engine's source."""
    from rbstab.engine.cuda import tree_kernel_function, tree_launch_signature
    from rbstab.engine.rk import DOP853

    ptx_for_sm_90(monkeypatch, tree_kernel_function(DOP853, (1, 0, 1), True), tree_launch_signature())


def _kernel_cache_keys() -> tuple[str, str]:
    """numba-cuda's cache key material of the one-body and the 2-body tree kernel in this process:
    the bytecode and the pickled closure of each (hashed)."""
    import hashlib

    from numba.cuda.serialize import dumps

    from rbstab.engine.cuda import tree_kernel_function

    return tuple(hashlib.sha256(f.__code__.co_code + dumps(tuple(c.cell_contents for c in f.__closure__ or ())))
                 .hexdigest() for f in (tree_kernel_function(2, (1, 0, 1), True), tree_kernel_function(2, (2, 2, 0))))


def test_kernel_cache_key_is_the_same_in_every_process():
    """numba-cuda keys its disk cache on a kernel's bytecode and the pickled contents of its
    closure: they must not change from one process to the next, or every command would
    compile the kernel again; nor in a sweep's worker, forked from a server that loaded the
    CPU kernels first (a numba type in the closure pickles with its type code, which counts
    the types made before: each worker would then compile the kernel again, ~2 minutes)."""
    from concurrent.futures import ProcessPoolExecutor

    from rbstab.sweep.executors import _mp_context

    script = "import sys; sys.path.insert(0, sys.argv[1]); import test_cuda; print(test_cuda._kernel_cache_keys())"
    here = os.path.dirname(__file__)
    keys = {subprocess.run([sys.executable, "-c", script, here], capture_output=True, text=True, check=True).stdout
            .strip() for _ in range(2)}
    with ProcessPoolExecutor(1, mp_context=_mp_context()) as pool:
        keys.add(str(pool.submit(_kernel_cache_keys).result()))
    assert len(keys) == 1, keys


def test_each_kernel_has_cache_files_of_its_own():
    """numba-cuda saves a kernel's cache index without a lock (read, update, write): two
    processes compiling two kernels that shared an index file could leave an entry naming the
    other's code. Each (method, tree shape, one body or not) kernel has index files of its
    own, as two processes find them."""
    from rbstab.engine.rk import DOP853, method_number

    RK45 = method_number("RK45")

    script = ("import sys; from numba.cuda.dispatcher import CUDACache; "
              "from rbstab.engine.cuda import tree_kernel_function\n"
              "f = tree_kernel_function(int(sys.argv[1]), (1, 0, int(sys.argv[2])), sys.argv[3] == '1')\n"
              "print(CUDACache(f)._cache_file._index_path)")
    paths = [subprocess.run([sys.executable, "-c", script, str(m), e, b], capture_output=True, text=True,
                            check=True).stdout.strip()
             for m, e, b in ((DOP853, "1", "1"), (RK45, "1", "1"), (DOP853, "0", "1"), (DOP853, "1", "0"))]
    assert len(set(paths)) == 4, paths
    assert all(p.endswith(".nbi") for p in paths)


#: A process that compiles (here: a stand-in taking 1 s) the kernel of sys.argv[1] with a GPU
#: present, in the cache folder $NUMBA_CACHE_DIR, printing which kernel it got.
_COMPILING = """
import sys, time
from numba import cuda
import rbstab.engine.cuda as engine

engine.simulated = lambda: False
class Compiled(str):  # the kernel's name, and numba-cuda's cache statistics: loaded, not compiled
    stats = type("Stats", (), {"cache_misses": {}})()
def jit(signature, cache):
    def compile(function):
        time.sleep(1.0)
        return Compiled(function.__name__)
    return compile
cuda.jit = jit
print(engine.compiled_tree_kernel(int(sys.argv[1]), (1, 0, 1), True))
"""


def test_processes_compiling_at_once_take_turns(tmp_path):
    """Three processes that need kernels at once with a cold cache: each gets its own, they
    compile one at a time (under the cache folder's lock, so numba-cuda's cache files are
    never written by two at once), and the one-line notice appears once a kernel."""
    import time

    from rbstab.engine.rk import DOP853, method_number

    RK45 = method_number("RK45")

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    start = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", _COMPILING, str(m)], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for m in (DOP853, DOP853, RK45)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), [e for _, e in outs]
    assert [o.strip() for o, _ in outs] == ["run_body1_0p1e_DOP853", "run_body1_0p1e_DOP853", "run_body1_0p1e_RK45"]
    notices = "".join(e for _, e in outs)
    assert notices.count("compiling the CUDA kernel for one body's embedded joint with DOP853") == 1
    assert notices.count("compiling the CUDA kernel for one body's embedded joint with RK45") == 1
    assert time.perf_counter() - start >= 2.0  # the two DOP853 processes waited for each other


def test_a_kernel_the_cache_should_have_held_says_it_was_compiled_again(capsys):
    """Where the warm marker says the cache holds a kernel but numba-cuda compiled it (its
    cache key did not match: minutes on the CPU), one line says so; a first compile (the
    command said "compiling" before it) and a kernel loaded from the cache say nothing."""
    from collections import Counter

    from rbstab.engine.cuda import _say_cache_miss

    class Kernel:
        def __init__(self, misses):
            self.stats = type("Stats", (), {"cache_misses": Counter(misses)})()

    _say_cache_miss(Kernel({"sig": 1}), True, "the CUDA kernel for DOP853 with 15 states")
    assert capsys.readouterr().err.count("was not found in the cache") == 1
    _say_cache_miss(Kernel({"sig": 1}), False, "the kernel")
    _say_cache_miss(Kernel({}), True, "the kernel")
    assert capsys.readouterr().err == ""


def test_numba_cuda_loads_where_numpy_has_no_row_stack():
    """numpy 2.5 removed np.row_stack, which numba-cuda 0.30.4 overloads on numpy >= 2.0:
    imported through rbstab's engine, numba-cuda's CUDA target still loads."""
    script = ("import numpy as np\n"
              "if hasattr(np, 'row_stack'): del np.row_stack\n"
              "import rbstab.engine.cuda\n"
              "import numba.cuda.np.arrayobj\n"
              "print('loaded')")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env)
    assert done.returncode == 0 and done.stdout.strip() == "loaded", done.stderr[-2000:]


# -- without a GPU ------------------------------------------------------------------------------------------
@pytest.mark.skipif(GPU, reason="a GPU is here")
@pytest.mark.parametrize("command", [
    ["sweep", CASE3, "--random", "controller.k_c=scale_uniform:[0.5,2]", "-n", "4"],
    ["analyze", CASE3, "--basin", "initial_state.omega.0=-6:6:3", "--basin", "initial_state.omega.1=-6:6:3"],
    ["sensitivity", CASE3, "--vary", "body.mass=uniform:[30,50]", "-n", "8"],
], ids=["sweep", "analyze", "sensitivity"])
def test_engine_cuda_without_a_gpu_stops_in_one_line(tmp_path, command):
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    done = subprocess.run([RBSTAB, *command, "--engine", "cuda", "-o", str(out)], capture_output=True, text=True,
                          env=env)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--engine cuda" in lines[0] and 'pip install "rbstab[cuda]"' in lines[0], done.stderr
    assert "Traceback" not in done.stderr
    assert not out.exists()


def test_simulate_without_a_gpu_raises_cuda_unavailable():
    from rbstab.engine.cuda import CudaUnavailable

    if GPU:
        pytest.skip("a GPU is here")
    with pytest.raises(CudaUnavailable, match="--engine cuda"):
        rbstab.simulate(CASE3, ["simulation.t_end=0.1"], engine="cuda")


# -- on a GPU -----------------------------------------------------------------------------------------------
@pytest.mark.skipif(not GPU, reason="no NVIDIA GPU here")
def test_gpu_sweep_agrees_with_the_cpu_engine():
    """On a real GPU: statuses and step counts equal, final states within the tolerance's
    scale of the CPU engine's (the GPU's fused multiply-adds and its sin/cos differ in rounding)."""
    from rbstab.simulator import simulate_blocks

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        configs = [rbstab.load_config(CASE3, ["simulation.t_end=0.5", "simulation.n_samples=101",
                                              f"initial_state.omega=[{16 + i},32,-16]"]) for i in range(64)]
    ref = {i: block.result(j) for idx, block in simulate_blocks(configs) for j, i in enumerate(idx)}
    got = {i: block.result(j) for idx, block in simulate_blocks(configs, engine="cuda") for j, i in enumerate(idx)}
    for i, r in ref.items():
        g = got[i]
        assert r.status == g.status
        assert abs(r.solver["n_steps"] - g.solver["n_steps"]) <= 2
        final_r, final_g = np.asarray(r.summary["final_omega"]), np.asarray(g.summary["final_omega"])
        np.testing.assert_allclose(final_g, final_r, rtol=1e-4, atol=1e-6)


@pytest.mark.skipif(not GPU, reason="no NVIDIA GPU here")
def test_gpu_cli_sweep_finishes(tmp_path):
    """On a real GPU: ``rbstab sweep --engine cuda`` (its worker processes, each launching
    the kernel) ends with every run computed. If it has not ended within 300 s, every
    process of the command dumps its Python stack (faulthandler, SIGABRT) into the failure:
    where the parent and its workers wait."""
    import signal

    cmd = [RBSTAB, "sweep", CASE3, "--random", "body.mass=scale_uniform:[0.5,1.5]", "--random",
           "controller.k_c=scale_uniform:[0.5,2]", "-n", "2000", "--set", "simulation.rtol=1e-6", "--set",
           "simulation.atol=1e-8", "--engine", "cuda", "--store", "summary", "--no-progress", "-o", str(tmp_path)]
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"} | {"PYTHONFAULTHANDLER": "1"}
    process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                               start_new_session=True)
    try:
        out, err = process.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGABRT)
        out, err = process.communicate()
        pytest.fail(f"rbstab sweep --engine cuda had not ended after 300 s; the stacks of its processes:\n{err}")
    assert process.returncode == 0, err  # every run computed (a fall is a result)
    assert "2000 runs" in err + out, err + out


def test_kernel_resources_ask_the_dispatcher_by_signature():
    """numba-cuda's dispatcher takes a signature object (``sig.args``) in
    ``get_regs_per_thread`` and ``get_local_mem_per_thread``, not the tuple of argument
    types: the occupancy of every launch on a GPU reads them."""
    from rbstab.engine.cuda import kernel_resources, tree_launch_signature

    class Dispatcher:  # what numba-cuda's CUDADispatcher does with the signature it is given
        def get_regs_per_thread(self, signature):
            return 200 if signature.args == self.args else 0

        def get_local_mem_per_thread(self, signature):
            return 7000 if signature.args == self.args else 0

    args = tree_launch_signature()
    fn = Dispatcher()
    fn.args = tuple(args)
    assert kernel_resources(fn, args) == (200, 7000)
