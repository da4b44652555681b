"""The generated right-hand side (rbstab.traced) against the model it is generated from."""

from __future__ import annotations

import numpy as np
import pytest

from rbstab import traced
from rbstab.traced import traced_rhs
from test_batch import VARIANT_NAMES, make_variant

#: Variants whose model the tracer can record (sliding's law uses abs and tanh).
TRACEABLE = ("free", "permanent", "visco_elastic", "embedded")


@pytest.mark.parametrize("name", VARIANT_NAMES)
def test_traced_rhs_gives_the_models_bits_or_is_unavailable(name):
    variant = make_variant(name)
    fun = traced_rhs(variant)
    if name not in TRACEABLE:
        assert fun is None
        return
    assert fun is not None
    rng = np.random.default_rng(7)
    n = variant.layout.size
    for m in (1, 3, 500):
        y = rng.normal(0.0, 0.8, (m, n))
        y[:, 3:6] *= 30.0  # spins of tens of rad/s, as in the paper's cases
        assert np.array_equal(fun(0.0, y), variant.rhs(0.0, y))
    one = rng.normal(0.0, 0.3, n)
    assert np.array_equal(fun(0.0, one), variant.rhs(0.0, one))


def test_a_model_that_branches_on_the_state_is_not_traced(monkeypatch):
    variant = make_variant("embedded")
    original = type(variant).constraint_law

    def branching(self, q):
        lam = original(self, q)
        return lam if q["position"][0] > 0 else lam  # a branch on the state

    monkeypatch.setattr(type(variant), "constraint_law", branching)
    assert traced_rhs(variant) is None


def test_a_trace_that_misses_an_operation_is_rejected(monkeypatch):
    """An operation outside the tape (here math.exp on a traced value) poisons the trace;
    the build check against the model rejects it instead of baking in a wrong number."""
    import math

    variant = make_variant("embedded")
    original = type(variant).constraint_law

    def hidden(self, q):
        lam = original(self, q)
        x0 = q["position"][0]
        scale = math.exp(x0) if isinstance(x0, float) else np.exp(x0)
        return tuple(c * scale for c in lam)

    monkeypatch.setattr(type(variant), "constraint_law", hidden)
    assert np.isfinite(variant.rhs(0.0, np.zeros((2, variant.layout.size)))).all()
    assert traced_rhs(variant) is None


def test_registers_are_reused():
    variant = make_variant("embedded")
    ops, outputs = traced._trace(variant)
    source, n_registers, constants, rows = traced._source(ops, outputs, variant.layout.size)
    assert len(ops) > 150
    assert n_registers < len(ops) // 4
    assert len(rows) == variant.layout.size and constants


def test_a_constant_rate_component_is_reproduced(monkeypatch):
    """A state-rate component that does not depend on the state (a number in the tape's
    outputs, not a register) comes out as that number for every row."""
    variant = make_variant("embedded")
    original = type(variant).quantities_columns

    def constant_last(self, state, outputs=True):
        q = original(self, state, outputs=outputs)
        rate = list(q["state_rate"])
        rate[-1] = 0.25
        return {**q, "state_rate": tuple(rate)}

    monkeypatch.setattr(type(variant), "quantities_columns", constant_last)
    fun = traced_rhs(variant)
    assert fun is not None
    y = np.random.default_rng(3).normal(0.0, 0.5, (5, variant.layout.size))
    out = fun(0.0, y)
    assert np.array_equal(out, variant.rhs(0.0, y))
    assert np.all(out[:, -1] == 0.25)


def test_signed_zero_constants_stay_apart(monkeypatch):
    """0.0 and -0.0 compare equal; as constants of the generated code they must still be
    two numbers (x * 0.0 and x * -0.0 differ in the sign of the zero)."""
    variant = make_variant("embedded")
    original = type(variant).quantities_columns

    def signed_zeros(self, state, outputs=True):
        q = original(self, state, outputs=outputs)
        rate = list(q["state_rate"])
        rate[-1] = rate[-1] * 0.0
        rate[-2] = rate[-2] * -0.0
        return {**q, "state_rate": tuple(rate)}

    monkeypatch.setattr(type(variant), "quantities_columns", signed_zeros)
    fun = traced_rhs(variant)
    assert fun is not None
    y = np.random.default_rng(5).normal(0.0, 0.5, (64, variant.layout.size))
    out, model = fun(0.0, y), variant.rhs(0.0, y)
    assert np.array_equal(np.signbit(out), np.signbit(model)) and np.array_equal(out, model)
    assert np.signbit(out[:, -2]).any() and np.signbit(out[:, -1]).any()
