"""The CUDA engine's tree kernel (rbstab.engine.cuda.tree_kernel_function) without a GPU:
under numba's CUDA simulator its runs are the compiled CPU driver's bit for bit, and it
compiles to PTX for sm_90."""

from __future__ import annotations

import pytest

from conftest import simulated_once
from rbstab.engine.status import gimbal_status, limit_status, range_status

numba_cuda = pytest.importorskip("numba_cuda", reason="numba-cuda is not installed (pip install -e '.[test]')")
from test_cuda import _compilers, ptx_for_sm_90  # noqa: E402


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """tests/cuda_chains_simulated.py's findings (a few seconds with a warm cache), run once
    a test session (:func:`conftest.simulated_once`)."""
    return simulated_once(tmp_path_factory, "cuda_chains_simulated.py")


@pytest.mark.parametrize("case, bodies, status", [
    ("stance", 2, [0, 0, 0, -3]), ("params", 2, [0, 0, 0, limit_status(0, 0, 1)]), ("knee", 2, [0, 0]),
    ("pulsed3", 3, [0, limit_status(0, 0, 2)]), ("pushed3", 3, [0, limit_status(0, 0, 2)]),  # |theta_1| of body 1, 2
    ("hinged3", 3, [0, limit_status(0, 0, 2)]), ("ranged3", 3, [0, range_status(1, 0, False)]),
    ("stopped3", 3, [range_status(0, 0, False), limit_status(0, 0, 2)]),
    ("universal3", 3, [0, range_status(1, 1, False)]), ("balls3", 3, [0, limit_status(0, 0, 2)]),
    ("slides3", 3, [0, range_status(1, 0, False)]),
    ("locked", 2, [gimbal_status(1, True), gimbal_status(0, True)])])  # the hip's, the ankle's Theta_j
def test_simulated_tree_kernel_is_the_cpu_driver_bit_for_bit(simulated, case, bodies, status):
    """The stance example (permanent joints, saturated torques; one run stopped by its step
    limit; two stopped at the gimbal lock of the hip's and of the ankle's Theta_j, the
    message naming it), the knee (visco-elastic and embedded joints), three bodies with a pulse and an
    admissible region that one run leaves, the same with impulses at 0, inside the run
    and at t_end, and with two hinges (one clipped, one with a passive torque), one run
    leaving the elbow's range (an admissible region) at its lower end, and with ball joints'
    ranges (the elbow's stop, the shoulder's region, which one run leaves), and with a
    universal elbow (one coordinate clipped, a passive torque, one run leaving q_2's region), and
    on quaternion balls with impulses (one run leaving simulation.limits), and with a slide
    elbow (clipped, a passive spring, one run leaving its range, an admissible region);
    runs of stance chains with other masses, gains, a parent point and an
    admissible region, a tree a run in one call (each run as the run alone): every run's status, t_stop, nfev, n_steps and its state and work W at every
    sample (and every 3rd, stride 3) equal the CPU driver's; simulate(engine="cuda")
    gives simulate(engine="compiled")'s status, message, solver counts, outputs and
    summary; and the runs' summaries streamed on the device with no sample kept (a sweep's
    --store summary; the hip's clipped torque counted in one run) are the CPU's, computed
    from its samples, figure by figure, bit for bit (the centre of pressure's excursion to
    1e-12: its reactions solved from the reduced state the driver holds, and the one its
    samples give back)."""
    found = simulated[case]
    assert found["bodies"] == bodies
    assert found["status"] == status
    assert found["differences"] == []
    assert found["result"] == []
    assert found["streamed"] == []


def test_simulated_analysis_runs_of_a_tree_are_the_cpus(simulated):
    """An analysis's runs of the stance example (rbstab.analysis.runs.Runs, what pushes,
    basin stability and basin maps integrate) on the GPU: the outcomes (success, v(0),
    v(t_end)) and the traces of v (with why each run stopped) of the CPU's, bit for bit."""
    found = simulated["runs"]
    assert found["success"] == [1.0, 1.0, 1.0]
    assert found["outcomes"] and found["traces"] == [True, True, True]


def test_simulated_basin_map_of_a_tree_streams_the_cpus_map(simulated):
    """A basin map of a stance chain with an admissible region on the GPU (each run's time to
    converge streamed, no sample back; rbstab.analysis.runs.Runs.streamed): every point's
    outcome, time to converge, v(0) and v(t_end), and the failures' messages, are the CPU's
    from its samples, bit for bit, with points of every outcome."""
    found = simulated["basin"]
    assert found["differences"] == []
    assert all(found["counts"][outcome] > 0 for outcome in ("converged", "not converged", "failed")), found
    assert found["messages"] == ["left the admissible region: |theta_1| of trunk reached simulation.limits.theta = 0.101 rad"]


@pytest.mark.slow
@pytest.mark.skipif(not _compilers(), reason="NVVM and NVRTC (numba-cuda[cu12]'s compiler wheels) are not installed")
def test_tree_kernel_compiles_to_ptx_for_sm_90(monkeypatch):
    """The tree kernel (DOP853, every joint variant's physics, the reduced rate's Cholesky
    solve, the permanent joints' impulsive reactions, disturbances and the admissible
    region; tree_launch_signature's types) compiles for CUDA from the CPU driver's source,
    its thread-local arrays sized for a tree of 2 bodies on permanent joints."""
    from rbstab.engine.cuda import tree_kernel_function, tree_launch_signature
    from rbstab.engine.rk import DOP853

    ptx_for_sm_90(monkeypatch, tree_kernel_function(DOP853, (2, 2, 0)), tree_launch_signature())


def _halved(x):
    return 0.5 * x


def _tripled(x):
    return 3.0 * x


@pytest.mark.skipif(not _compilers(), reason="NVVM and NVRTC (numba-cuda[cu12]'s compiler wheels) are not installed")
def test_functions_not_inlined_stay_calls_in_optimised_ptx(monkeypatch):
    """A function of NOT_INLINED (the tree's rate) is a function of its own in the optimised
    PTX, called where the kernel calls it, while NVVM inlines the others: a small one of
    each, called twice."""
    import re

    import numba.cuda.dispatcher
    from numba import cuda, float64

    from rbstab.engine import cuda as engine_cuda
    from rbstab.jit import jit

    class Device:  # numba-cuda asks the current device's compute capability for called dispatchers
        compute_capability = (9, 0)

    monkeypatch.setattr(numba.cuda.dispatcher, "get_current_device", lambda: Device())
    monkeypatch.setattr(engine_cuda, "NOT_INLINED", engine_cuda.NOT_INLINED | {(__name__, "_halved")})
    engine_cuda.tree_kernel_function(2, (1, 1, 0))  # what sets the lowering up
    halved, tripled = jit(cache=False)(_halved), jit(cache=False)(_tripled)

    def kernel(x):
        x[0] = halved(x[0]) + halved(x[1]) + tripled(x[2]) + tripled(x[3])

    ptx, _ = cuda.compile_ptx(kernel, (float64[::1],), cc=(9, 0), opt=True)
    functions = re.findall(r"^\.(?:visible |weak )?\.func\s+(?:\([^)]*\)\s*)?(\S+?)\(", ptx, re.M)
    assert any("_halved" in name for name in functions), functions
    assert not any("_tripled" in name for name in functions), functions
    assert len(re.findall(r"call\.uni[^;]*_halved", ptx)) == 2  # a call statement each time the kernel calls it
