"""One convergence rule (rbstab.convergence.converged) for sweeps, basin maps and robustness."""

import numpy as np
import pytest

from rbstab.convergence import DEFAULT_LYAPUNOV_RATIO, ROUND_OFF, converged


def test_converged_keeps_a_ratio_of_the_initial_lyapunov_function():
    assert converged(True, 100.0, 0.09)  # the default ratio 1e-3
    assert not converged(True, 100.0, 0.11)
    assert converged(True, 100.0, 0.11, ratio=2e-3)
    assert not converged(False, 100.0, 0.0)  # a failed run never converged
    assert not converged(True, 100.0, -50.0)  # fell below the equilibrium's v (an inverted pendulum)
    assert converged(True, 100.0, -0.05)
    assert converged(True, 0.0, 0.5 * ROUND_OFF) and not converged(True, 0.0, 2 * ROUND_OFF)  # at the equilibrium
    for bad in (float("nan"), float("inf"), None, "", "n/a"):
        assert not converged(True, 100.0, bad) and not converged(True, bad, 0.0)
    assert converged(True, "100.0", "0.09")  # an index read back from CSV
    assert type(converged(True, 100.0, 0.09)) is bool


def test_converged_on_arrays_is_the_rule_element_by_element():
    rng = np.random.default_rng(3)
    v0 = rng.uniform(-1.0, 1.0, 400) * 10.0 ** rng.integers(-14, 3, 400)
    v1 = v0 * rng.uniform(-2e-3, 2e-3, 400) + rng.uniform(-2e-12, 2e-12, 400)
    v1[::37] = np.nan
    ok = rng.random(400) < 0.8
    got = converged(ok, v0, v1, 1e-3)
    assert got.shape == (400,) and got.dtype == bool
    assert got.tolist() == [converged(bool(a), float(b), float(c), 1e-3) for a, b, c in zip(ok, v0, v1)]
    assert 0 < got.sum() < ok.sum()
    np.testing.assert_array_equal(converged(True, v0[0], np.full((2, 3), v0[0] * 1e-4)), np.ones((2, 3), bool))


def test_one_default_ratio_everywhere():
    """The sweeps' convergence.lyapunov_ratio, the basin map's and rbstab analyze --ratio
    default to the one the docs state (1e-3)."""
    import inspect

    from rbstab.analysis.analyze import analyze
    from rbstab.analysis.basin import basin_map
    from rbstab.sweep import DEFAULT_LYAPUNOV_RATIO as sweep_default
    from rbstab.sweep.spec import SweepSpec
    from rbstab_cli.analyze import analyze as analyze_command

    assert DEFAULT_LYAPUNOV_RATIO == 1e-3 and sweep_default is DEFAULT_LYAPUNOV_RATIO
    assert SweepSpec.__dataclass_fields__["lyapunov_ratio"].default == DEFAULT_LYAPUNOV_RATIO
    for function in (analyze, basin_map):
        assert inspect.signature(function).parameters["ratio"].default == DEFAULT_LYAPUNOV_RATIO
    (option,) = [p for p in analyze_command.params if p.name == "ratio"]
    assert option.default == DEFAULT_LYAPUNOV_RATIO


def test_time_to_converge_is_the_first_sample_from_which_every_sample_converged():
    from rbstab.analysis.basin import time_to_converge

    t = np.linspace(0.0, 1.0, 11)
    v = np.array([10.0, 5.0, -0.5, 0.02, 0.009, 0.001, -0.002, 0.0, 1e-4, 0.0, 0.0])
    assert time_to_converge(t, v, 1e-3) == pytest.approx(0.4)
    reached = converged(True, v[0], v, 1e-3)
    assert reached[4:].all() and not reached[3]


def test_the_rule_as_text_is_the_rule_of_the_code(tmp_path):
    """The text a sweep's summary states is the convergence module's, with the absolute
    values and the round-off floor the code applies."""
    import pandas as pd

    from rbstab.convergence import RULE, SAMPLE_RULE
    from rbstab.sweep.folder import summarize_columns

    assert ("|lyapunov_final| <= lyapunov_ratio * max(|lyapunov_initial|, lyapunov_initial + max_lyapunov_increase)"
            " + 1e-12 J") in RULE and f"{ROUND_OFF:g}" in RULE
    assert SAMPLE_RULE.startswith("|v| <= ratio v_ref + 1e-12 J, v_ref = max(|v(0)|, v(0) + the largest rise")
    # the text's reference is the code's: v(0) plus the largest rise
    assert converged(True, 1.0, 0.0015, 1e-3, 1.0) and not converged(True, 1.0, 0.0015, 1e-3, 0.0)
    index = pd.DataFrame({"run_id": ["r0"], "base": ["b"], "status": ["success"], "converged": [True],
                          "wall_time": [0.1]})
    assert summarize_columns(index, name="s", ratio=1e-3)["convergence"]["definition"] == RULE
