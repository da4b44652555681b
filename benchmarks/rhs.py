"""Benchmark: the variants' right-hand side ``variant.rhs(t, y)``.

Two shapes, as the two integrators call it:

- one state, ``y`` shape (n_state,), as :func:`scipy.integrate.solve_ivp` calls it
  (rbstab.simulator): microseconds per call;
- a stack, ``y`` shape (m, n_state) with m = ``--rows`` (1024 by default), as the batched
  compiled kernels are called from Python (Variant.rhs): microseconds per call and per row.

Also ``evaluate`` (every output) on 2001 states, the sampled trajectory of one run.

The body and gains are the paper's (Table 1, Appendix; m = 41 kg, J = diag(10, 8, 0.4)
kg m^2, R = (0.15, 0.10, -0.42) m) with gravity (0, 0, -10) m/s^2, sliding with the
boundary layer phi = 5 mm. States are seeded random (Theta, X, V, D ~ N(0, 0.2^2),
Omega ~ N(0, 5^2) rad/s). Each figure is the best of ``--repeat`` timings of a loop
long enough to take ~``--budget`` seconds, so the figures are the least-disturbed
ones on a busy machine.

The stacked figures also depend on the heap: a stacked call allocates a few hundred kB
of temporaries, and glibc's malloc may hand the freed top of the heap back to the
system after every call (M_TRIM_THRESHOLD, 128 kB by default), so that the next call
page-faults it in again. Whether it does depends on what else sits on the heap; the
column ``faults/call`` shows it (about 100 faults, worth a few hundred us, when it
happens). ``--steady-heap`` sets the trim and mmap thresholds to 1 GiB (glibc only) to
measure the right-hand side alone; ``MALLOC_TRIM_THRESHOLD_`` in the environment does the
same for any program.

Usage::

    python benchmarks/rhs.py [--rows 1024] [--repeat 7] [--budget 0.05]
                             [--variants embedded,free] [--blas-threads N] [--steady-heap]
"""

from __future__ import annotations

import argparse
import ctypes
import os
import sys
import timeit
import warnings
from pathlib import Path

try:
    import resource
except ImportError:  # not on Windows
    resource = None


def _early_blas_threads() -> None:
    """``--blas-threads N`` must act before numpy loads OpenBLAS."""
    if "--blas-threads" in sys.argv:
        n = sys.argv[sys.argv.index("--blas-threads") + 1]
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = n


_early_blas_threads()

import numpy as np  # noqa: E402

from rbstab.variants.paper import paper_form
from rbstab.config import PhysicalPlausibilityWarning, load_config  # noqa: E402
from rbstab.variants import VARIANTS  # noqa: E402

CASE3 = Path(__file__).resolve().parents[1] / "configs" / "paper" / "case3_embedded.yaml"


def paper_variant(name: str):
    """The registry variant ``name`` built from the shipped Case 3 config, gravity on.

    Case 3's body and gains (``configs/paper/case3_embedded.yaml``), the sliding gains of
    ``configs/examples/sliding.yaml`` and g = (0, 0, -10) m/s^2, so every term of every
    variant is exercised.
    """
    overrides = [
        f"controller.variant={name}",
        "body.gravity=[0, 0, -10]",
        "controller.k_s=2000",
        "controller.boundary_layer=0.005",
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PhysicalPlausibilityWarning)
        return paper_form(load_config(CASE3, overrides))


def random_states(variant, n: int, seed: int = 0) -> np.ndarray:
    """Seeded states, shape (n, n_state)."""
    rng = np.random.default_rng(seed)
    y = rng.normal(scale=0.2, size=(n, variant.layout.size))
    y[:, variant.layout.slice("omega")] = rng.normal(scale=5.0, size=(n, 3))
    return y


def best_time(fn, repeat: int, budget: float) -> float:
    """Best time of one call of ``fn`` [s] over ``repeat`` loops of ~``budget`` seconds."""
    timer = timeit.Timer(fn)
    number, _ = timer.autorange()
    number = max(1, int(number * budget / 0.2))
    return min(timer.repeat(repeat=repeat, number=number)) / number


def minor_faults() -> int:
    """Minor page faults of this process so far (0 where unavailable)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt if resource else 0


def steady_heap() -> bool:
    """Stop glibc malloc from trimming the heap and from mmapping large blocks."""
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3
    return bool(libc.mallopt(m_trim_threshold, 1 << 30) and libc.mallopt(m_mmap_threshold, 1 << 30))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1024, help="rows of the stacked state")
    parser.add_argument("--repeat", type=int, default=7, help="timings per figure (best kept)")
    parser.add_argument("--budget", type=float, default=0.05, help="seconds per timing")
    parser.add_argument("--variants", default=",".join(sorted(VARIANTS)), help="comma-separated names")
    parser.add_argument("--blas-threads", type=int, default=None, help="BLAS threads (set before numpy loads)")
    parser.add_argument("--steady-heap", action="store_true", help="no heap trimming (glibc mallopt)")
    args = parser.parse_args(argv)
    if args.steady_heap and not steady_heap():
        print("--steady-heap: mallopt unavailable, ignored")

    names = args.variants.split(",")
    # warm up (CPU clock, the allocator's thresholds) so the first variant is not penalised
    for name in names:
        measure(paper_variant(name), args, warm_up=True)

    heap = "steady heap" if args.steady_heap else "default heap"
    print(f"numpy {np.__version__}, rows = {args.rows}, best of {args.repeat}, {heap}")
    header = (
        f"{'variant':<15}{'one state [us]':>16}{'stack [us/call]':>17}{'stack [us/row]':>16}"
        f"{'faults/call':>13}{'evaluate 2001 [ms]':>20}"
    )
    print(header)
    print("-" * len(header))
    for name in names:
        t_one, t_stack, faults, t_eval = measure(paper_variant(name), args)
        print(
            f"{name:<15}{1e6 * t_one:>16.1f}{1e6 * t_stack:>17.1f}"
            f"{1e6 * t_stack / args.rows:>16.3f}{faults:>13.1f}{1e3 * t_eval:>20.2f}"
        )


def measure(variant, args, warm_up: bool = False):
    """Seconds per rhs call of one state and of a stack, page faults per stacked call,
    seconds per ``evaluate`` of 2001 states."""
    one = random_states(variant, 1)[0]
    stack = random_states(variant, args.rows)
    samples = random_states(variant, 2001, seed=1)
    if warm_up:
        best_time(lambda: variant.rhs(0.0, stack), 1, args.budget)
        return None
    t_one = best_time(lambda: variant.rhs(0.0, one), args.repeat, args.budget)
    t_stack = best_time(lambda: variant.rhs(0.0, stack), args.repeat, args.budget)
    faults = minor_faults()
    for _ in range(20):
        variant.rhs(0.0, stack)
    faults = (minor_faults() - faults) / 20
    t_eval = best_time(lambda: variant.evaluate(samples), args.repeat, args.budget)
    return t_one, t_stack, faults, t_eval


if __name__ == "__main__":
    main()
