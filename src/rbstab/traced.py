"""A variant's right-hand side for stacks as straight-line numpy code, generated from the model.

:meth:`~rbstab.variants.base.Variant.quantities_columns` is the only definition of the
dynamics. :func:`traced_rhs` runs it once on its one-state (float) path with symbolic
floats that record every ``+ - * /``, negation and ``cos``/``sin`` (the model's constants
stay numbers), and writes the recorded tape as one Python function in which each
operation is one numpy ufunc call writing into a row of a register matrix: the state's
components are copied into its first rows (one transposed copy, so every operand is a
contiguous row), a row is reused after its value's last use, constants are 0-d arrays
(numpy takes them faster than Python floats), and the rate is gathered from its rows at
the end. That is the model's own stack path without its Python bookkeeping (helper
calls, ``isinstance`` dispatch, temporaries, strided state columns): the same operations
on the same operands in the same order, so the same bits, for about half its time per
call on a 500-run batch (paper Case 3: median ~260 us against ~410 us, best 143 against
313 us, on the 2-core development machine).

Every function is checked when it is built: at random states it must give exactly the
bits of ``variant.rhs``. A model that cannot be traced (a branch on the state, an
operation the tape does not record: ``abs``, ``tanh`` of the ``sliding`` law) or whose
trace does not reproduce it gives None, and the caller uses ``variant.rhs``; a change to
a variant can therefore make this path unavailable, never different.
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable

import numpy as np

from . import kinematics

__all__ = ["traced_rhs", "TracingError"]

#: Random states at which a generated right-hand side must reproduce ``variant.rhs``.
CHECK_STATES = 16


class TracingError(Exception):
    """The model did something on the traced state that the tape cannot record."""


class _Tape:
    def __init__(self) -> None:
        self.ops: list[tuple[str, str, tuple]] = []  # (result, ufunc name, operands)

    def record(self, ufunc: str, *operands) -> "_Sym":
        name = f"t{len(self.ops)}"
        self.ops.append((name, ufunc, operands))
        return _Sym(self, name)


def _untraceable(*_args, **_kwargs):
    raise TracingError("the model branches on, compares or converts a traced state value")


class _Sym(float):
    """A float standing for a value of the traced state; its own value is NaN, so an
    operation the tape misses poisons the result (and the build check rejects it)."""

    def __new__(cls, tape: _Tape, name: str) -> "_Sym":
        obj = float.__new__(cls, math.nan)
        obj.tape, obj.name = tape, name
        return obj

    def _binary(self, ufunc: str, other, reflected: bool = False) -> "_Sym":
        if not isinstance(other, (_Sym, float, int)) or isinstance(other, bool):
            return NotImplemented
        a, b = (other, self) if reflected else (self, other)
        return self.tape.record(ufunc, a, b)

    def __add__(self, o): return self._binary("add", o)
    def __radd__(self, o): return self._binary("add", o, True)
    def __sub__(self, o): return self._binary("subtract", o)
    def __rsub__(self, o): return self._binary("subtract", o, True)
    def __mul__(self, o): return self._binary("multiply", o)
    def __rmul__(self, o): return self._binary("multiply", o, True)
    def __truediv__(self, o): return self._binary("divide", o)
    def __rtruediv__(self, o): return self._binary("divide", o, True)
    def __neg__(self): return self.tape.record("negative", self)

    __lt__ = __le__ = __gt__ = __ge__ = __eq__ = __ne__ = __bool__ = _untraceable
    __abs__ = __pow__ = __rpow__ = __floordiv__ = __rfloordiv__ = __mod__ = __rmod__ = _untraceable
    __divmod__ = __rdivmod__ = __pos__ = __int__ = __float__ = __round__ = __trunc__ = _untraceable
    __hash__ = float.__hash__


def _trace(variant) -> tuple[list, list]:
    """(ops, outputs) of ``variant``'s state rate; outputs are _Sym or numbers."""
    tape = _Tape()
    n = variant.layout.size
    state = [_Sym(tape, f"y{j}") for j in range(n)]

    def recording(ufunc: str):
        def record(x):
            if not isinstance(x, _Sym):
                return getattr(math, ufunc)(x)
            return tape.record(ufunc, x)
        return record

    saved = kinematics.math
    kinematics.math = types.SimpleNamespace(cos=recording("cos"), sin=recording("sin"))
    try:
        rate = list(variant.quantities_columns(state, outputs=False)["state_rate"])
    finally:
        kinematics.math = saved
    if len(rate) != n:
        raise TracingError(f"state rate of {len(rate)} components for {n} states")
    return tape.ops, rate


def _source(ops: list, outputs: list, n: int) -> tuple[str, int, dict[str, float], list]:
    """Python source of ``kernel(R)``, R the rows of the register matrix W (shape
    (n_registers, m)).

    On entry rows 0 .. n-1 of W hold the state components ``y0 .. y{n-1}``; every
    operation writes one row, reusing a row after its value's last use. Returns the source,
    the number of registers, the constants (name -> value; the caller binds each name to a
    0-d array, which numpy takes ~0.5 us faster per call than a Python float; one name per
    ``repr``, so 0.0 and -0.0, equal as dict keys, stay two constants) and, per
    state-rate component, the row that holds it at the end or the number it equals.
    """
    last_use: dict[str, int] = {}
    for i, (_, _, operands) in enumerate(ops):
        for x in operands:
            if isinstance(x, _Sym):
                last_use[x.name] = i
    for x in outputs:
        if isinstance(x, _Sym):
            last_use[x.name] = len(ops)
    registers: dict[str, str] = {f"y{j}": f"r{j}" for j in range(n)}
    free: list[str] = [f"r{j}" for j in reversed(range(n)) if f"y{j}" not in last_use]
    n_registers = n
    names: dict[str, str] = {}  # repr(value) -> name
    constants: dict[str, float] = {}  # name -> value

    def operand(x) -> str:
        if isinstance(x, _Sym):
            return registers[x.name]
        value = float(x)
        name = names.setdefault(repr(value), f"c{len(names)}")
        constants[name] = value
        return name

    body = []
    for i, (result, ufunc, operands) in enumerate(ops):
        args = [operand(x) for x in operands]
        for x in {x.name for x in operands if isinstance(x, _Sym)}:
            if last_use[x] == i:
                free.append(registers[x])  # its register may take this op's result
        if result not in last_use:
            continue  # never used (e.g. a quantity only the outputs need)
        if free:
            register = free.pop()
        else:
            register = f"r{n_registers}"
            n_registers += 1
        registers[result] = register
        body.append(f"    _{ufunc}({', '.join(args)}, {register})")
    lines = ["def kernel(R):", f"    {', '.join(f'r{k}' for k in range(n_registers))}, = R", *body, ""]
    rows = [int(registers[x.name][1:]) if isinstance(x, _Sym) else float(x) for x in outputs]
    return "\n".join(lines), n_registers, constants, rows


_UFUNCS = {f"_{name}": getattr(np, name) for name in ("add", "subtract", "multiply", "divide", "negative", "cos", "sin")}


def traced_rhs(variant, *, seed: int = 0) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
    """``variant.rhs`` for stacks as generated straight-line numpy code, or None.

    Parameters
    ----------
    variant : rbstab.variants.base.Variant
    seed : int
        Seed of the random states of the build check.

    Returns
    -------
    callable or None
        ``fun(t, y)``: y of shape (m, n_state) -> dy/dt of shape (m, n_state), the same
        bits as ``variant.rhs(t, y)`` (``t`` [s] is unused, as there); one state (shape
        (n_state,)) goes to ``variant.rhs``. None when the model cannot be traced or the
        generated code does not reproduce it at :data:`CHECK_STATES` random states.
    """
    n = variant.layout.size
    try:
        ops, outputs = _trace(variant)
        source, n_registers, constants, rows = _source(ops, outputs, n)
        namespace = dict(_UFUNCS)
        namespace.update((name, np.array(value)) for name, value in constants.items())
        exec(compile(source, f"<traced rhs of {variant.name}>", "exec"), namespace)
    except Exception:  # whatever the model does to a traced value: use variant.rhs
        return None
    kernel = namespace["kernel"]
    from_register = np.array([r if isinstance(r, int) else 0 for r in rows], dtype=np.intp)
    numbers = [(j, r) for j, r in enumerate(rows) if not isinstance(r, int)]

    def rhs(t, y):
        y = np.asarray(y, dtype=float)
        if y.ndim != 2 or y.shape[1] != n:
            return variant.rhs(t, y)
        registers = np.empty((n_registers, len(y)))
        registers[:n] = y.T  # the state components as contiguous rows
        kernel(registers)
        out = np.take(registers, from_register, axis=0).T.copy()
        for j, value in numbers:
            out[:, j] = value
        return out

    rng = np.random.default_rng(seed)
    y = rng.normal(0.0, 0.5, (CHECK_STATES, n))
    with np.errstate(all="ignore"):
        if not np.array_equal(rhs(0.0, y), variant.rhs(0.0, y), equal_nan=True):
            return None
    return rhs
