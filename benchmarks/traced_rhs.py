"""Experiment (issue 5): the traced right-hand side compiled with numba.

rbstab's batch engine uses :func:`rbstab.traced.traced_rhs`: the model's
``quantities_columns`` traced once on its float path and written as straight-line numpy
code. This measures the next step, not taken: the same tape (:func:`rbstab.traced._trace`)
written as one loop over the rows of a stack and compiled with numba (``njit``, no
fastmath: no reassociation, no FMA contraction; ``error_model="numpy"``: x / 0 is inf, as
in numpy), checked against the numpy paths bit for bit and timed against both.

Prints the number of operations per evaluation, numba's import and compile time, whether
the compiled kernel gives the same bits as the model's stack path and float path, and
microseconds per call for one state and for ``--rows`` states.

Usage::

    pip install numba          # optional: without it only the tape is built and checked
    python benchmarks/traced_rhs.py [--config configs/paper/case3_embedded.yaml] [--rows 500]
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

from rbstab.config import load_config
from rbstab.traced import _Sym, _trace, traced_rhs

ROOT = Path(__file__).resolve().parents[1]
_INFIX = {"add": "+", "subtract": "-", "multiply": "*", "divide": "/"}


def _term(x) -> str:
    return x.name if isinstance(x, _Sym) else repr(float(x))


def loop_source(variant) -> tuple[str, int]:
    """Source of ``kernel(Y, OUT)``: OUT[i] = the state rate at Y[i], for every row i;
    and the number of operations."""
    ops, outputs = _trace(variant)
    lines = ["def kernel(Y, OUT):", "    for i in range(Y.shape[0]):"]
    lines += [f"        y{j} = Y[i, {j}]" for j in range(variant.layout.size)]
    for result, ufunc, operands in ops:
        if ufunc in _INFIX:
            text = f" {_INFIX[ufunc]} ".join(_term(x) for x in operands)
        elif ufunc == "negative":
            text = f"-{_term(operands[0])}"
        else:
            text = f"math.{ufunc}({_term(operands[0])})"
        lines.append(f"        {result} = {text}")
    lines += [f"        OUT[i, {j}] = {_term(x)}" for j, x in enumerate(outputs)]
    return "\n".join(lines), len(ops)


def per_call(fn, repeat: int) -> float:
    start = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - start) / repeat


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default=str(ROOT / "configs" / "paper" / "case3_embedded.yaml"))
    p.add_argument("--rows", type=int, default=500)
    args = p.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        variant = load_config(args.config).make_variant()
    if traced_rhs(variant) is None:
        raise SystemExit(f"{variant.name}: the model cannot be traced (rbstab uses variant.rhs)")
    source, n_ops = loop_source(variant)
    print(f"{variant.name}: {n_ops} operations per right-hand-side evaluation ({variant.layout.size} states)")
    namespace = {"math": math}
    exec(source, namespace)
    rng = np.random.default_rng(0)
    y = rng.normal(0.0, 0.3, (args.rows, variant.layout.size))
    out = np.empty_like(y)
    namespace["kernel"](y[:3], out[:3])  # the tape in plain Python: the same bits as the model
    assert np.array_equal(out[:3], variant.rhs(0.0, y[:3])), "the traced tape differs from the model"
    try:
        start = time.perf_counter()
        import numba
    except ImportError:
        print("numba is not installed: the tape matches the model; nothing compiled")
        return
    imported = time.perf_counter() - start
    start = time.perf_counter()
    kernel = numba.njit(error_model="numpy")(namespace["kernel"])
    kernel(y, out)
    compiled = time.perf_counter() - start
    print(f"numba {numba.__version__}: import {imported:.2f} s, compile {compiled:.2f} s")
    print(f"same bits as the numpy stack path: {np.array_equal(out, variant.rhs(0.0, y))}; "
          f"as the one-state float path: {all(np.array_equal(out[i], variant.rhs(0.0, y[i])) for i in range(5))}")
    for m in (1, args.rows):
        ym, om = y[:m], out[:m]
        t_numba = per_call(lambda: kernel(ym, om), 2000)
        t_numpy = per_call(lambda: variant.rhs(0.0, ym if m > 1 else ym[0]), 300)
        print(f"{m} state{'s' if m > 1 else ''}: compiled {t_numba * 1e6:.1f} us per call, "
              f"rbstab's {'stack' if m > 1 else 'float'} path {t_numpy * 1e6:.1f} us")


if __name__ == "__main__":
    main()
