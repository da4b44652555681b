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
    source, n_registers = traced._source(ops, outputs, variant.layout.size)
    assert len(ops) > 150
    assert n_registers < len(ops) // 4
