"""Experiment (issue 5): a compiled right-hand side generated from the model by tracing.

Not used by rbstab: this measures what the next step of issue 5 would buy. It runs a
variant's :meth:`~rbstab.variants.base.Variant.quantities_columns` once on the one-state
(float) path with symbolic "floats" that record every arithmetic operation and every
``cos``/``sin``, so the model itself is the only definition of the dynamics; writes the
recorded tape as one flat Python function over the rows of a stack; compiles it with
numba (``njit``, no fastmath: no reassociation, no FMA contraction) when numba is
installed; and checks it against the numpy paths bit for bit and times both.

Prints the number of operations per evaluation, numba's import and compile time, whether
the compiled kernel gives the same bits as the numpy stack path and the float path, and
microseconds per call for one state and for ``--rows`` states.

Usage::

    pip install numba          # optional: without it only the tape is built and checked
    python benchmarks/traced_rhs.py [--config configs/paper/case3_embedded.yaml] [--rows 500]
"""

from __future__ import annotations

import argparse
import math
import time
import types
import warnings
from pathlib import Path

import numpy as np

import rbstab.kinematics as kinematics
from rbstab.config import load_config

ROOT = Path(__file__).resolve().parents[1]


class _Tape:
    """The operations recorded while the model runs on :class:`_Sym` values."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.count = 0

    def new(self) -> str:
        self.count += 1
        return f"t{self.count}"


TAPE = _Tape()


def _term(x) -> str:
    return x.name if isinstance(x, _Sym) else repr(float(x))


class _Sym(float):
    """A float that records each operation on it (so the model's ``isinstance(x, float)``
    one-state path runs); its value is meaningless."""

    def __new__(cls, name: str) -> "_Sym":
        obj = float.__new__(cls, 0.0)
        obj.name = name
        return obj

    def _op(self, other, op: str, reflected: bool = False) -> "_Sym":
        out = TAPE.new()
        a, b = (_term(other), self.name) if reflected else (self.name, _term(other))
        TAPE.lines.append(f"{out} = {a} {op} {b}")
        return _Sym(out)

    def __add__(self, o): return self._op(o, "+")
    def __radd__(self, o): return self._op(o, "+", True)
    def __sub__(self, o): return self._op(o, "-")
    def __rsub__(self, o): return self._op(o, "-", True)
    def __mul__(self, o): return self._op(o, "*")
    def __rmul__(self, o): return self._op(o, "*", True)
    def __truediv__(self, o): return self._op(o, "/")
    def __rtruediv__(self, o): return self._op(o, "/", True)

    def __neg__(self) -> "_Sym":
        out = TAPE.new()
        TAPE.lines.append(f"{out} = -{self.name}")
        return _Sym(out)


def _recording(function: str):
    def record(x):
        out = TAPE.new()
        TAPE.lines.append(f"{out} = math.{function}({_term(x)})")
        return _Sym(out)

    return record


def trace_rhs(variant) -> str:
    """Source of ``kernel(Y, OUT)``: OUT[i] = the state rate at Y[i], for every row i."""
    n = variant.layout.size
    saved = kinematics.math
    kinematics.math = types.SimpleNamespace(cos=_recording("cos"), sin=_recording("sin"))
    try:
        rate = list(variant.quantities_columns([_Sym(f"y{j}") for j in range(n)], outputs=False)["state_rate"])
    finally:
        kinematics.math = saved
    lines = ["def kernel(Y, OUT):", "    for i in range(Y.shape[0]):"]
    lines += [f"        y{j} = Y[i, {j}]" for j in range(n)]
    lines += ["        " + line for line in TAPE.lines]
    lines += [f"        OUT[i, {j}] = {_term(r)}" for j, r in enumerate(rate)]
    return "\n".join(lines)


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
    if variant.name == "sliding":
        raise SystemExit("sliding: tanh is not traced by this experiment")
    source = trace_rhs(variant)
    print(f"{variant.name}: {len(TAPE.lines)} operations per right-hand-side evaluation "
          f"({variant.layout.size} states)")
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
    kernel = numba.njit(namespace["kernel"])
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
