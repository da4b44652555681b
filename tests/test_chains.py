"""Chains of rigid bodies checked by physics (docs/physics.md, "Chains of rigid bodies"): a
one-body chain is today's body; the analytic dv/dt is the flow derivative of v for random
chains of every variant mix; a double pendulum conserves energy and moves as MuJoCo's; the
planar double inverted pendulum's linearisation has the eigenvalues of M q'' + L q' +
(K - G) q = 0 written by hand; a stiff visco-elastic joint approaches the permanent one."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import paper_body, paper_gains
from rbstab.chain import GROUND, Body, Chain, Joint, single
from rbstab.config.loader import config_from_mapping, load_config
from rbstab.model import Saturation
from rbstab.variants import VARIANTS
from rbstab.variants import chain as C

D = np.diag
ROOT = Path(__file__).resolve().parents[1]
ALL = sorted(VARIANTS)


def _one_body(name, gravity):
    variant = VARIANTS[name](paper_body(gravity), paper_gains(boundary_layer=0.01) if name == "sliding"
                             else paper_gains())
    body, gains = variant.body, variant.gains
    chain = single(
        Body("body", body.mass, body.inertia, gains.k_t, gains.l_t),
        Joint("controller", GROUND, 0, body.attachment_point, body.attachment_point, name, gains.k_r, gains.l_r,
              gains.k_c, gains.l_c, gains.k_d, gains.l_d, gains.k_s, gains.boundary_layer),
        body.gravity)
    return variant, C.compile_chain(chain, offset=variant.lyapunov_offset)


def _rate(compiled, y, t=0.0):
    dy = np.empty(compiled.n_states)
    C.chain_rate(t, np.ascontiguousarray(y, dtype=float), *compiled.args, dy)
    return dy


@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -9.81)])
@pytest.mark.parametrize("name", ALL)
def test_a_one_body_chain_is_todays_body(name, gravity, rng):
    """Rate, v and dv/dt of the one-body chain equal the single body's at random states;
    ``permanent`` (a reduced 6-state model there) at states on its constraint."""
    variant, compiled = _one_body(name, gravity)
    for _ in range(10):
        y = rng.normal(scale=0.2, size=compiled.n_states)
        y[3:6] = rng.normal(scale=3.0, size=3)
        if name == "permanent":
            y = C._place(compiled, y)
            single_y = y[:6]
            mine, theirs = _rate(compiled, y)[:6], variant.rhs(0.0, single_y)
        else:
            single_y = y
            mine, theirs = _rate(compiled, y), variant.rhs(0.0, single_y)
        np.testing.assert_allclose(mine, theirs, rtol=1e-10, atol=1e-10 * np.abs(theirs).max())
        v, rate = C.lyapunov(compiled, y)
        expected = variant.evaluate(single_y[None])
        assert v == pytest.approx(float(expected["lyapunov"][0]), rel=1e-10, abs=1e-9)
        assert rate == pytest.approx(float(expected["lyapunov_rate"][0]), rel=1e-9, abs=1e-8)


def _random_chain(rng, n, variants):
    bodies, joints = [], []
    for i in range(n):
        inertia = D(rng.uniform(0.05, 0.5, 3))
        k_t = D(rng.uniform(0, 20, 3)) if rng.random() < 0.3 else np.zeros((3, 3))
        bodies.append(Body(f"b{i}", float(rng.uniform(0.5, 3.0)), inertia, k_t, 0.5 * k_t,
                           Saturation(np.full(3, np.inf), np.full(3, 5.0), np.full(3, np.inf), "clip")
                           if rng.random() < 0.3 else None))
        variant = variants[i]
        gains = {"k_c": D(rng.uniform(200, 800, 3)), "l_c": D(rng.uniform(5, 30, 3))} \
            if variant in ("visco_elastic", "embedded") else {}
        if variant == "embedded":
            gains |= {"k_d": D(rng.uniform(200, 800, 3)), "l_d": D(rng.uniform(5, 30, 3))}
        if variant == "sliding":
            gains |= {"k_s": float(rng.uniform(5, 20)), "boundary_layer": 0.02}
        limited = rng.random() < 0.5 and variant != "permanent"
        joints.append(Joint(
            f"j{i}", GROUND if i == 0 else int(rng.integers(0, i)), i, rng.normal(scale=0.2, size=3),
            rng.normal(scale=0.2, size=3), variant, D(rng.uniform(0, 30, 3)), D(rng.uniform(0, 5, 3)),
            saturation=Saturation(np.full(3, 2.0), np.full(3, np.inf), np.full(3, 20.0), "clip") if limited else None,
            **gains))
    return Chain(tuple(bodies), tuple(joints), np.array([0.0, 0.0, -9.81]))


@pytest.mark.parametrize("n", [2, 3, 5])
def test_analytic_lyapunov_rate_is_the_flow_derivative_of_v_for_random_chains(n, rng):
    """dv/dt (minus the dissipations, plus the saturation deficit and constraint powers) equals
    (v(y + h f) - v(y - h f)) / 2h at random states of random chains of every variant mix."""
    names = ["free", "permanent", "sliding", "visco_elastic", "embedded"]
    for trial in range(4):
        chain = _random_chain(rng, n, [names[(trial + i) % 5] for i in range(n)])
        compiled = C.compile_chain(chain, offset=0.0)
        for _ in range(5):
            y = C._place(compiled, rng.normal(scale=0.3, size=compiled.n_states))
            y[12 * np.arange(n)[:, None] + np.arange(6, 9)] += rng.normal(scale=0.02, size=(n, 3))  # E_j != 0
            f = _rate(compiled, y)
            h = 1e-6
            numerical = (C.lyapunov(compiled, y + h * f)[0] - C.lyapunov(compiled, y - h * f)[0]) / (2 * h)
            analytic = C.lyapunov(compiled, y)[1]
            assert analytic == pytest.approx(numerical, rel=1e-5, abs=1e-6 * (1 + np.abs(f).max())), (trial, chain)


def _pendulum():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config("configs/examples/double_pendulum.yaml")
    return config, C.compile_chain(config.chain)


def _solve(compiled, y0, t_end, t_eval):
    return solve_ivp(lambda t, y: _rate(compiled, y, t), (0.0, t_end), y0, method="DOP853", rtol=1e-11, atol=1e-12,
                     t_eval=t_eval)


def test_double_pendulum_conserves_energy_and_moves_as_mujocos():
    """Ball joints, gravity, no feedback: v (kinetic energy + gravity) constant, the joints
    hold, and both centres of mass follow MuJoCo's ball-joint model to 1e-6 m."""
    mujoco = pytest.importorskip("mujoco")
    config, compiled = _pendulum()
    t_end = 2.0
    t_eval = np.linspace(0.0, t_end, 21)
    sol = _solve(compiled, C.initial_state(config), t_end, t_eval)
    out = C.evaluate(compiled, sol.t, sol.y.T)
    kinetic = out["lyapunov_translational"] + out["lyapunov_rotational"]  # no feedback: the kinetic energy
    assert np.ptp(out["lyapunov"]) < 1e-8 * (1 + np.abs(kinetic).max())
    assert np.linalg.norm(out["constraint_error"], axis=-1).max() < 1e-8  # both joints permanent
    assert np.abs(kinetic).max() > 1.0  # it moves
    from reference_mujoco import double_pendulum

    model, data, qpos0 = double_pendulum(config, 1e-4)
    data.qpos[:] = qpos0
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    steps = int(round(0.1 / model.opt.timestep))
    for k, t in enumerate(t_eval):
        if k:
            mujoco.mj_step(model, data, nstep=steps)
        np.testing.assert_allclose(data.xipos[1:3], out["position"][k], atol=1e-6, err_msg=f"t = {t}")


def _planar_stance(k_r=(800.0, 300.0), l_r=(150.0, 40.0)):
    """Two bodies tilting about y: legs on an ankle at the origin (COM c1 above it, hip l1
    above it), trunk on the hip (COM c2 above it); joint feedback about y only."""
    m1, m2, i1, i2, c1, l1, c2 = 28.0, 42.0, 2.6, 2.3, 0.45, 0.9, 0.3
    spring = [D([1e3, k, 1e3]) for k in k_r]
    damper = [D([1e2, d, 1e2]) for d in l_r]
    chain = Chain(
        (Body("legs", m1, D([i1, i1, 0.1])), Body("trunk", m2, D([i2, i2, 0.4]))),
        (Joint("ankle", GROUND, 0, np.zeros(3), np.array([0, 0, -c1]), "permanent", spring[0], damper[0]),
         Joint("hip", 0, 1, np.array([0, 0, l1 - c1]), np.array([0, 0, -c2]), "permanent", spring[1], damper[1])),
        np.array([0.0, 0.0, -9.81]))
    g = 9.81
    m_abs = np.array([[i1 + m1 * c1**2 + m2 * l1**2, m2 * l1 * c2], [m2 * l1 * c2, i2 + m2 * c2**2]])
    g_abs = np.diag([(m1 * c1 + m2 * l1) * g, m2 * c2 * g])  # -d2U/dalpha2 at upright
    t = np.array([[1.0, 0.0], [1.0, 1.0]])  # absolute tilts = T (ankle, hip)
    m, gg = t.T @ m_abs @ t, t.T @ g_abs @ t
    stiff, damp = np.diag(k_r) - gg, np.diag(l_r)
    closed = np.linalg.eigvals(np.block([[np.zeros((2, 2)), np.eye(2)],
                                         [-np.linalg.solve(m, stiff), -np.linalg.solve(m, damp)]]))
    return chain, closed


def _planar_state(compiled, q, qd):
    y = np.zeros(compiled.n_states)
    y[1], y[13] = q[0], q[0] + q[1]
    y[4], y[16] = qd[0], qd[0] + qd[1]
    return C._place(compiled, y)


@pytest.mark.parametrize("k_r", [(800.0, 300.0), (400.0, 300.0)])
def test_planar_double_inverted_pendulum_eigenvalues_are_the_closed_forms(k_r):
    """The linearisation in the independent coordinates (ankle tilt, hip angle) about the
    upright, by central differences of the chain's rate, has the eigenvalues of
    M q'' + L q' + (K - G) q = 0 written by hand; with a weak ankle the upright is unstable
    in both."""
    chain, closed = _planar_stance(k_r)
    compiled = C.compile_chain(chain, offset=0.0)

    def accel(z):
        dy = _rate(compiled, _planar_state(compiled, z[:2], z[2:]))
        return np.array([dy[4], dy[16] - dy[4]])

    jac = np.zeros((4, 4))
    jac[:2, 2:] = np.eye(2)
    h = 1e-6
    for k in range(4):
        step = np.zeros(4)
        step[k] = h
        jac[2:, k] = (accel(step) - accel(-step)) / (2 * h)
    mine = np.linalg.eigvals(jac)
    key = lambda z: (round(z.real, 6), round(z.imag, 6))  # noqa: E731
    np.testing.assert_allclose(sorted(mine, key=key), sorted(closed, key=key), rtol=1e-6, atol=1e-6)
    assert (closed.real.max() > 0) == (k_r[0] == 400.0)


def test_the_planar_stances_mode_shapes_are_the_closed_forms():
    """The mode shapes on the bodies' tilts (:func:`rbstab.analysis.linearise.mode_shapes`
    of the chain's linearisation) are the eigenvectors of M q'' + L q' + (K - G) q = 0
    written by hand in the joint angles q (ankle, hip), mapped to the tilts T q; the slow mode
    leans both bodies one way (the ankle strategy), the fast one turns them against each
    other (the hip strategy)."""
    from rbstab.analysis.linearise import linearise_chain, mode_shapes

    chain, _ = _planar_stance()
    m1, m2, i1, i2, c1, l1, c2 = 28.0, 42.0, 2.6, 2.3, 0.45, 0.9, 0.3
    g, t = 9.81, np.array([[1.0, 0.0], [1.0, 1.0]])
    m = t.T @ np.array([[i1 + m1 * c1**2 + m2 * l1**2, m2 * l1 * c2], [m2 * l1 * c2, i2 + m2 * c2**2]]) @ t
    stiff = np.diag([800.0, 300.0]) - t.T @ np.diag([(m1 * c1 + m2 * l1) * g, m2 * c2 * g]) @ t
    damp = np.diag([150.0, 40.0])
    block = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.linalg.solve(m, stiff), -np.linalg.solve(m, damp)]])
    closed, vectors = np.linalg.eig(block)
    lin, coordinates = linearise_chain(C.compile_chain(chain, offset=0.0))
    assert [c[:2] for c in coordinates] == [("legs", "theta"), ("legs", "omega"), ("trunk", "theta"), ("trunk", "omega")]
    shapes = mode_shapes(lin, [1, 7])  # theta_2 of legs and trunk: the tilts about y
    full = mode_shapes(lin, range(lin.eigenvalues.size))
    np.testing.assert_allclose(lin.jacobian @ full.T, full.T * lin.eigenvalues, atol=1e-6 * np.abs(lin.jacobian).max())
    signs = []
    for s, q in zip(closed, vectors[:2].T):
        k = int(np.argmin(np.abs(lin.eigenvalues - s)))
        assert abs(lin.eigenvalues[k] - s) < 1e-6 * abs(s)
        tilt = t @ q
        tilt = tilt / tilt[np.argmax(np.abs(tilt))]
        np.testing.assert_allclose(shapes[k], tilt, atol=1e-6)
        signs.append((abs(s), np.sign(tilt.real.prod())))
    assert [sign for _, sign in sorted(signs)][0] == 1 and [sign for _, sign in sorted(signs)][-1] == -1


def test_a_symmetric_trees_double_real_modes_are_real():
    """A column of 8 axisymmetric bodies on permanent joints with the same feedback about x
    and y: each mode about x has its twin about y, a real one a double eigenvalue.
    Rounding in the Jacobian would make a pair Re s +- 1e-13 i of it (zeta -1 with a
    phase between theta_1 and theta_2); its eigenvalues are real and its mode shapes are
    real eigenvectors, the eigen equation holding for every mode."""
    from rbstab.analysis.linearise import linearise_config, mode_shapes

    names = [f"b{i}" for i in range(8)]
    config = config_from_mapping({
        "name": "column", "gravity": [0, 0, -9.81],
        "bodies": [{"name": n, "mass": 5.0, "inertia": [0.1, 0.1, 0.02]} for n in names],
        "joints": [{"name": f"j{i}", "parent": "ground" if i == 0 else names[i - 1],
                    "parent_point": [0, 0, 0] if i == 0 else [0, 0, 0.15], "child": n, "child_point": [0, 0, -0.15],
                    "variant": "permanent", "k_r": [400, 400, 100], "l_r": [40, 40, 10]} for i, n in enumerate(names)],
        "simulation": {"t_end": 1.0}})
    lin = linearise_config(config)
    s = lin.eigenvalues
    real = np.flatnonzero(s.imag == 0)
    twin = lin.tolerance  # a double eigenvalue: equal within the rounding that decides Re s
    assert lin.verdict == "unstable" and s[0].real > 0 and abs(s[0] - s[1]) <= twin  # it falls, about x or y
    assert not np.any((np.abs(s.imag) <= lin.tolerance) & (s.imag != 0))
    assert sum(np.sum(np.abs(s - value) <= twin) == 2 for value in s[real]) >= 4  # about x, twins about y
    full = mode_shapes(lin, range(s.size))
    np.testing.assert_allclose(lin.jacobian @ full.T, full.T * s, atol=1e-6 * np.abs(lin.jacobian).max())
    assert np.all(full[real].imag == 0)


def test_a_stiff_visco_elastic_joint_approaches_the_permanent_joint():
    """The double pendulum with a visco-elastic elbow of stiffness k_c: its motion differs from
    the ball joint's by O(1/k_c)."""
    config, permanent = _pendulum()
    t_eval = np.linspace(0.0, 0.3, 7)
    y0 = C.initial_state(config)
    reference = _solve(permanent, y0, 0.3, t_eval).y
    errors = []
    for k_c in (1e4, 1e5, 1e6):
        elbow = config.chain.joints[1]
        joint = Joint(elbow.name, elbow.parent, elbow.child, elbow.parent_point, elbow.child_point, "visco_elastic",
                      elbow.k_r, elbow.l_r, k_c=D([k_c] * 3), l_c=D([2 * np.sqrt(k_c)] * 3))
        chain = Chain(config.chain.bodies, (config.chain.joints[0], joint), config.chain.gravity)
        y = _solve(C.compile_chain(chain, offset=0.0), y0, 0.3, t_eval).y
        errors.append(np.abs(y[:12] - reference[:12]).max())
    assert errors[0] > 5 * errors[1] > 25 * errors[2] > 0


@pytest.mark.parametrize("name", ALL)
def test_a_one_body_chains_linearisation_is_todays(name):
    """Under gravity, the one-body chain's rest state in its independent coordinates
    ((Theta, Omega) for permanent, the body's state otherwise) and its eigenvalues equal the
    single body's (the paper's variant's, ``paper_model.linearise``)."""
    from paper_model import linearise

    from rbstab.analysis.linearise import linearise_chain

    variant, compiled = _one_body(name, (0.0, 0.0, -9.81))
    mine, coordinates = linearise_chain(compiled)
    theirs = linearise(variant)
    assert [c[:2] for c in coordinates][:2] == [("body", "theta"), ("body", "omega")]
    assert mine.is_rest_point and theirs.is_rest_point
    np.testing.assert_allclose(mine.equilibrium, theirs.equilibrium, atol=1e-9)
    np.testing.assert_allclose(mine.eigenvalues, theirs.eigenvalues, rtol=1e-6, atol=1e-6)
    assert mine.verdict == theirs.verdict


def test_analyze_gives_the_stance_verdict_and_flips_it_below_gravitys_stiffness():
    """The stance example is stable upright (its K_r - G positive definite); with ankle
    stiffness below gravity's (652 N m/rad about x) it is unstable; v is zero at rest."""
    from rbstab.analysis import analyze

    path = "configs/examples/stance_ankle_hip.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stable = analyze(load_config(path), certificate=False, simulate=False)
        weak = analyze(load_config(path, ["joints.ankle.k_r.0=400"]), certificate=False, simulate=False)
    assert stable.verdict == "asymptotically stable" and stable.linearisation.is_rest_point
    assert weak.verdict == "unstable"
    compiled = C.compile_chain(load_config(path).chain)
    assert abs(C.lyapunov(compiled, stable.rest_state)[0]) < 1e-9
    record = stable.as_dict()
    assert set(record["rest_state"]) == {"legs", "trunk"} and record["verdict"] == "asymptotically stable"
    # one body's record besides: the coordinates and each mode's frequency, damping and time constant
    lin = stable.linearisation
    assert record["state"][:3] == ["legs.theta_1", "legs.theta_2", "legs.theta_3"] and len(record["state"]) == 12
    np.testing.assert_array_equal(record["damping_ratio"], lin.damping_ratio)
    assert record["time_constant"][0] == pytest.approx(-1.0 / lin.eigenvalues[0].real)


def test_a_tree_is_analysed_by_one_bodys_steps_its_limits_and_notes_included():
    """A tree's analysis takes one body's steps: a rest state outside simulation.limits is
    refused in one line naming the body (OutsideLimits), the configuration's warnings are
    among its notes, and each part's time is recorded."""
    import dataclasses

    from rbstab.analysis import OutsideLimits, analyze
    from rbstab.model import Limits

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config("configs/examples/stance_ankle_hip.yaml")
    low = dataclasses.replace(config, simulation=dataclasses.replace(config.simulation,
                                                                     limits=Limits.of(position=[1.0, 1.0, 0.5])))
    with pytest.raises(OutsideLimits, match=r"rest state lies outside simulation.limits: \|X_3\| of body 'trunk' = "
                                            r"[0-9.]+ m > 0.5 m \(simulation.limits.position\)"):
        analyze(low, certificate=False, simulate=False)
    warned = dataclasses.replace(config, warnings=("W001 a warning of the configuration",))
    found = analyze(warned, certificate=False, simulate=False)
    assert "W001 a warning of the configuration" in found.notes
    assert set(found.timing) == {"linearisation"}
    # an arm whose centre of mass is beside its pin: gravity's torque at rest exceeds the 2 N m
    # limit until the arm hangs at -0.54 rad, where the clipped torque holds it (slope 0)
    pin = {"name": "pin", "parent": "ground", "parent_point": [0, 0, 0], "child": "arm", "child_point": [0.3, 0, 0.3],
           "variant": "permanent", "k_r": [200, 200, 200], "l_r": [20, 20, 20]}
    arm = {"name": "arm", "gravity": [0, 0, -9.81], "bodies": [{"name": "arm", "mass": 2.0, "inertia": [0.2, 0.2, 0.05]}],
           "simulation": {"t_end": 2.0, "n_samples": 101}}
    held = analyze(config_from_mapping({**arm, "joints": [pin]}), certificate=False, simulate=False)
    assert held.verdict == "asymptotically stable" and not any("saturate" in n for n in held.notes)
    clipped = analyze(config_from_mapping({**arm, "joints": [{**pin, "saturation": {"torque_n": 2.0}}]}),
                      certificate=False, simulate=False)
    assert clipped.linearisation.is_rest_point and clipped.rest_state[1] == pytest.approx(-0.5428, abs=1e-4)
    notes = " ".join(clipped.notes)
    assert clipped.verdict == "marginal" and "at the rest state the actuators saturate (|torque_n_2| of joint 'pin' = " \
        in notes and ">= its limit 2 N m, as commanded)" in notes


def test_a_chains_time_scale_is_a_time_constant_an_e_folding_time_or_none():
    """Stable stance: the slowest time constant; ankle stiffness 600 N m/rad (below what
    gravity and the hip need, ~713): the e-folding time of the growing mode, which a small
    lean confirms by growing e-fold in it; the undamped double pendulum (imaginary
    eigenvalues): marginal, no number. Never a negative or astronomical time."""
    import json

    from rbstab.analysis import analyze
    from rbstab.analysis.text import describe
    from rbstab.simulator import simulate

    def text(analysis) -> str:
        return "\n".join(describe(analysis))

    path = "configs/examples/stance_ankle_hip.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stable = analyze(load_config(path), certificate=False, simulate=False)
        weak = analyze(load_config(path, ["joints.ankle.k_r.0=600"]), certificate=False, simulate=False)
        undamped = analyze(load_config("configs/examples/double_pendulum.yaml"), certificate=False, simulate=False)
    records = [json.loads(json.dumps(r.as_dict(), allow_nan=False)) for r in (stable, weak, undamped)]  # strict JSON
    s0 = [r.linearisation.eigenvalues[0].real for r in (stable, weak, undamped)]
    assert records[0]["slowest_time_constant"] == pytest.approx(-1.0 / s0[0]) and s0[0] < 0
    assert records[0]["shortest_e_folding_time"] is None
    assert f"slowest time constant {-1.0 / s0[0]:.4g} s" in text(stable)
    e_fold = records[1]["shortest_e_folding_time"]
    assert weak.verdict == "unstable" and e_fold == pytest.approx(1.0 / s0[1]) and s0[1] > 0
    assert records[1]["slowest_time_constant"] is None
    assert f"unstable: e-folding time {e_fold:.4g} s" in text(weak) and "time constant" not in text(weak)
    # a lean of the legs grows by e every e-folding time once the decaying modes have gone (~0.6 s each)
    lean = load_config(path, ["joints.ankle.k_r.0=600", "simulation.t_end=8", "simulation.n_samples=801",
                                  "initial_state.legs.theta=[0.001, 0, 0]", "initial_state.trunk.theta=[0, 0, 0]"])
    run = simulate(lean)
    grown = np.interp([4.0, 4.0 + e_fold], run.time, run.outputs["theta"][:, 0, 0])
    assert run.ok and grown[1] / grown[0] == pytest.approx(np.e, rel=1e-3)
    assert undamped.verdict == "marginal" and abs(s0[2]) <= undamped.linearisation.tolerance
    assert records[2]["slowest_time_constant"] is None and records[2]["shortest_e_folding_time"] is None
    assert "marginally stable (a zero or imaginary eigenvalue)" in text(undamped)
    lines = text(undamped).splitlines()
    scale = next(line for line in lines if "marginally stable" in line)
    assert "time constant" not in scale and "e-folding" not in scale
    header = next(k for k, line in enumerate(lines) if "e-folding [s]" in line)  # the table of the modes: no number
    rows = lines[header + 1: header + 1 + undamped.linearisation.eigenvalues.size]
    assert all(row.split()[-2:] == ["-", "-"] for row in rows), rows


def test_rbstab_analyze_prints_a_chains_verdict_and_refuses_one_body_options(tmp_path):
    from click.testing import CliRunner

    from rbstab.analysis import read_analysis
    from rbstab_cli.main import cli

    path = "configs/examples/stance_ankle_hip.yaml"
    weak = ["--set", "joints.ankle.k_r.0=400"]
    result = CliRunner().invoke(cli, ["analyze", path, *weak, "-o", str(tmp_path), "--samples", "300"])
    assert result.exit_code == 0, result.output
    assert result.output.startswith("stance_ankle_hip (chain): unstable") and "equilibrium: legs: theta (0, 0, 0) rad" \
        in result.output
    written = tmp_path / "stance_ankle_hip.analysis.nc"
    assert f"-> {written}" in result.output
    ds = read_analysis(written)  # one body's analysis file, its state blocks by body
    assert ds.attrs["variant"] == "chain" and ds.attrs["verdict"] == "unstable"
    assert list(ds["body"].values) == ["legs", "trunk"] and ds["equilibrium_theta"].dims == ("body", "axis")
    assert list(ds["state"].values[2:5]) == ["legs.theta_3", "legs.omega_1", "legs.omega_2"]
    assert list(ds["state"].values[6:7]) == ["trunk.theta_1"]
    assert ds["jacobian"].shape == (12, 12) and ds["eigenvalue_real"].values[0] > 0  # the ankle too weak
    assert list(ds["state_units"].values[:7]) == ["rad"] * 3 + ["rad s-1"] * 3 + ["rad"]
    assert ds.attrs["certificate_holds"] == 0 and ds["sublevel"].values == 0.0  # no region of an unstable rest
    refused_dir = tmp_path / "refused"
    refused = CliRunner().invoke(cli, ["analyze", path, "--verify", "-o", str(refused_dir)])
    assert refused.exit_code == 1 and "stance_ankle_hip: --verify: the proof covers one body held" in refused.output
    assert "this chain has 2 bodies" in refused.output
    assert "Traceback" not in refused.output and not refused_dir.exists()
    # another configuration of the same name does not replace the file without --overwrite
    before = written.read_bytes()
    other = CliRunner().invoke(cli, ["analyze", path, "-o", str(tmp_path), "--no-certificate"])
    assert other.exit_code == 1 and "holds the analysis of a different configuration" in other.output
    assert written.read_bytes() == before


def test_rbstab_analyze_verifies_a_one_body_tree_as_the_one_body_model(tmp_path):
    """--verify of one body written as a tree (held to the ground at its own point) is the
    one-body config's analysis and proof: the same verified level, the same eigenvalues."""
    import yaml
    from click.testing import CliRunner

    from conftest import tree_spelling
    from rbstab.analysis import read_analysis
    from rbstab.config import load_config
    from rbstab_cli.main import cli

    path = ROOT / "configs" / "examples" / "saturated_pendulum.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(path)
    tree = tmp_path / "tree.yaml"
    tree.write_text(yaml.safe_dump(tree_spelling(config).resolved))
    short = ["--verify", "--samples", "500", "--no-simulation"]
    for given, out in ((tree, tmp_path / "tree"), (path, tmp_path / "body")):
        result = CliRunner().invoke(cli, ["analyze", str(given), *short, "-o", str(out)])
        assert result.exit_code == 0, result.output
    as_tree, as_body = (read_analysis(tmp_path / d / f"{config.name}.analysis.nc") for d in ("tree", "body"))
    assert as_tree.attrs["variant"] == "permanent" and np.isfinite(as_body["sublevel_verified"].values)
    for name in ("sublevel_verified", "eigenvalue_real", "eigenvalue_imag", "sublevel"):
        np.testing.assert_array_equal(as_tree[name].values, as_body[name].values, err_msg=name)


def test_rbstab_analyze_maps_a_chains_basin_and_refuses_a_key_naming_no_body(tmp_path):
    import json

    from click.testing import CliRunner

    from rbstab.analysis import read_analysis

    from rbstab_cli.main import cli

    path = "configs/examples/stance_ankle_hip.yaml"
    short = ["--set", "simulation.t_end=1", "--basin-samples", "51", "--no-certificate", "-o", str(tmp_path)]
    result = CliRunner().invoke(cli, ["analyze", path, "--json", "--basin", "initial_state.legs.theta.0=-0.1:0.1:3",
                                      "--basin", "initial_state.trunk.theta.0=-0.1:0.1:2", *short])
    assert result.exit_code == 0, result.output
    found = json.loads(result.stdout.strip().splitlines()[-1])
    assert found["kind"] == "chain" and np.shape(found["basin"]["outcome"]) == (3, 2)
    assert sum(found["basin"]["counts"].values()) == 6 and found["basin"]["axes"][1]["values"] == [-0.1, 0.1]
    ds = read_analysis(tmp_path / "stance_ankle_hip.analysis.nc")
    np.testing.assert_array_equal(ds["basin_outcome"].values, found["basin"]["outcome"])
    assert ds["basin_x"].attrs["config_key"] == "initial_state.legs.theta.0" and list(ds["basin_y"].values) == [-0.1, 0.1]
    np.testing.assert_array_equal(ds["eigenvalue_real"].values + 1j * ds["eigenvalue_imag"].values,
                                  [complex(*s) for s in found["eigenvalues"]])
    for body, blocks in found["rest_state"].items():
        np.testing.assert_array_equal(ds["equilibrium_theta"].sel(body=body).values, blocks["theta"])
    report = CliRunner().invoke(cli, ["report", str(tmp_path / "stance_ankle_hip.analysis.nc"), "-o",
                                      str(tmp_path / "report")])
    assert report.exit_code == 0, report.output
    assert (tmp_path / "report" / "figures" / "analysis_stance_ankle_hip_basin.png").is_file()
    assert "legs theta (0, 0, 0) rad; trunk theta (0, 0, 0) rad" in (tmp_path / "report" / "index.html").read_text()
    refused_dir = tmp_path / "refused"
    refused = CliRunner().invoke(cli, ["analyze", path, "--basin", "initial_state.hips.theta.0=-0.1:0.1:3",
                                       "--basin", "initial_state.trunk.theta.0=-0.1:0.1:2", *short[:-1],
                                       str(refused_dir)])
    assert refused.exit_code == 1 and "no body 'hips' in this chain (its bodies: legs, trunk" in refused.output
    assert "Traceback" not in refused.output and not refused_dir.exists()


def test_rbstab_analyze_pushes_a_chains_body_and_draws_its_basin_stability(tmp_path):
    import json

    from click.testing import CliRunner

    from rbstab.analysis import read_analysis

    from rbstab_cli.main import cli

    path = "configs/examples/stance_ankle_hip.yaml"
    short = ["--set", "simulation.limits.theta=[0.6,0.6,3.2]", "-o", str(tmp_path), "--json", "--no-certificate"]
    pushed = CliRunner().invoke(cli, ["analyze", path, "--push", "force", "--push-body", "trunk", "--push-point",
                                      "0,0,0.2", "--push-direction", "0,-1,0", *short])
    assert pushed.exit_code == 0, pushed.output
    push = json.loads(pushed.stdout.strip().splitlines()[-1])["push"]
    assert push["body"] == "trunk" and push["point"] == [0.0, 0.0, 0.2] and 1.0 < push["threshold"][0] < 1e3
    ds = read_analysis(tmp_path / "stance_ankle_hip.analysis.nc")
    assert ds.attrs["push_body"] == "trunk" and ds.attrs["push_kind"] == "force"
    assert list(ds["push_threshold"].values) == push["threshold"] and list(ds["push_point"].values) == [0.0, 0.0, 0.2]
    drawn = CliRunner().invoke(cli, ["analyze", path, "--basin-stability", "initial_state.legs.theta.0=-0.5:0.5",
                                     "-n", "30", *short])
    assert drawn.exit_code == 0, drawn.output
    stability = json.loads(drawn.stdout.strip().splitlines()[-1])["basin_stability"]
    assert stability["draws"] == 30 and 0 < stability["recovered"] < 30  # the box reaches beyond the basin
    ds = read_analysis(tmp_path / "stance_ankle_hip.analysis.nc")  # the same configuration's file, replaced
    assert "push_threshold" not in ds and ds["stability_recovered"].size == 30
    refused_dir = tmp_path / "refused"
    short[short.index("-o") + 1] = str(refused_dir)
    for args, says in ((["--push", "force"], "--push-body: found none for stance_ankle_hip; expected the body"),
                       (["--basin-stability", "initial_state.arms.theta.0=-1:1"], "no body 'arms' in this chain")):
        refused = CliRunner().invoke(cli, ["analyze", path, *args, *short])
        assert refused.exit_code != 0 and says in refused.output and "Traceback" not in refused.output
    one_body = CliRunner().invoke(cli, ["analyze", "configs/paper/case1_permanent.yaml", "--push", "torque",
                                        "--push-body", "trunk", "-o", str(refused_dir)])
    assert one_body.exit_code == 2 and "--push-body: names the body of a chain" in one_body.output
    assert not refused_dir.exists()


def test_rbstab_analyze_pushes_a_chains_body_across_a_spec(tmp_path):
    """A sweep spec of chains with --push and --push-body: the smallest fatal push at each
    configuration, as push_analysis gives it for that configuration alone; a spec of chains
    without --push-body, with a body it has not, or with --verify is refused in one line
    before anything runs, and --push-body with a one-body spec."""
    from click.testing import CliRunner

    from rbstab.analysis import read_analysis
    from rbstab.analysis.push import push_analysis
    from rbstab_cli.main import cli

    stance = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    spec = tmp_path / "stance_mass.yaml"
    spec.write_text(f"name: stance_mass\nbase: {stance}\ngrid:\n  bodies.trunk.mass: [40.0, 60.0]\n"
                    "  simulation.limits.theta: [[0.6, 0.6, 3.2]]\n")
    push = ["--push", "force", "--push-direction", "0,1,0", "--push-tol", "0.01"]
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["analyze", str(spec), *push, "--push-body", "trunk", "--no-certificate", "-j", "1",
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    ds = read_analysis(out / "stance_mass.recovery.analysis.nc")
    assert list(ds["bodies.trunk.mass"].values) == [40.0, 60.0]
    minima = ds["push_minimum"].values
    assert np.all(np.isfinite(minima)) and minima[0] != minima[1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        heavy = load_config(stance, ["bodies.trunk.mass=60.0", "simulation.limits.theta=[0.6, 0.6, 3.2]"])
    alone = push_analysis(heavy, "force", directions=np.array([[0.0, 1.0, 0.0]]), tol=0.01, body="trunk")
    assert minima[1] == alone.minimum
    refused_dir = tmp_path / "refused"
    for args, says in (([], "--push-body: found none for"), (["--push-body", "arms"], "found 'arms' for"),
                       (["--push-body", "trunk", "--verify"], "the proof covers one body held to the ground by a "
                                                              "permanent joint, the reduced 6-state model of 'permanent' "
                                                              "(eq 21), or a tree of hinges, slides, universal "
                                                              "joints and balls of at most 6 states; this chain "
                                                              "has 2 bodies")):
        refused = CliRunner().invoke(cli, ["analyze", str(spec), *push, *args, "-o", str(refused_dir)])
        assert refused.exit_code != 0 and says in refused.output and "Traceback" not in refused.output
    one_body = CliRunner().invoke(cli, ["analyze", str(ROOT / "configs" / "sweeps" / "gains.yaml"), *push,
                                        "--push-body", "trunk", "-o", str(refused_dir)])
    assert one_body.exit_code == 2 and "--push-body: names the body of a chain" in one_body.output
    assert not refused_dir.exists()


@pytest.mark.parametrize("mass", [44.0, 45.0, 48.0])
def test_v_is_zero_at_the_stance_rest_state_for_every_trunk_mass(mass):
    """h puts v's minimum at the rest state whatever the trunk's mass: v there is 0 and
    every body's acceleration vanishes (a rest point: the minimiser's, where polishing it
    leaves the model's domain)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        config = load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", [f"bodies.trunk.mass={mass}"])
    compiled = C.compile_chain(config.chain)
    rest, _ = C.rest_state(compiled)
    v, rate = C.lyapunov(compiled, rest)
    assert abs(v) < 1e-9 * abs(compiled.offset) and abs(rate) < 1e-9
    # the compiled configuration's bodies sit on their joints, as the state's placement puts them
    np.testing.assert_allclose(C._place(compiled, rest), rest, rtol=0, atol=1e-15)
    assert np.abs(_rate(compiled, rest)).max() < 1e-6


@pytest.mark.parametrize("n", [1, 2, 4])
def test_a_trees_v_changes_by_the_disturbances_work_and_its_analytic_rate_along_a_run(n, rng):
    """Along a run of a random tree (every law mix, damping, clipped controls, a sine force on
    one body and a torque pulse on another), v(t) - v(0) - W(t) is the time integral of the
    analytic dv/dt less the disturbances' power (the dissipation, the saturation deficit
    and constraint powers, W the work the driver integrates with the state), to the
    quadrature's error; and dv/dt is the derivative of v along the run (away from the
    windows' edges, where it jumps)."""
    import dataclasses

    from scipy.integrate import cumulative_simpson

    from rbstab.engine.integrate import integrate_chain_runs
    from rbstab.engine.settings import settings_rows
    from rbstab.engine.systems import tree_system
    from rbstab.model import Disturbance
    from rbstab.simulator import numerical_rate

    names = ["free", "permanent", "sliding", "visco_elastic", "embedded"]
    sine = Disturbance("sine", "force", np.array([3.0, -2.0, 1.0]), np.array([0.0, 0.05, 0.1]), 0.1, 0.0, 2.0, 0.3)
    pulse = Disturbance("pulse", "torque", np.array([0.0, 0.5, -0.3]), np.zeros(3), 0.4, 0.3)
    for trial in range(2):
        chain = _random_chain(rng, n, [names[(trial * 2 + i) % 5] for i in range(n)])
        bodies = list(chain.bodies)
        bodies[0] = dataclasses.replace(bodies[0], disturbances=(sine,))
        bodies[-1] = dataclasses.replace(bodies[-1], disturbances=bodies[-1].disturbances + (pulse,))
        chain = dataclasses.replace(chain, bodies=tuple(bodies))
        compiled = C.compile_chain(chain, offset=0.0)
        y0 = C._place(compiled, rng.normal(scale=0.1, size=compiled.n_states))
        sim = type("Settings", (), dict(t_end=1.0, rtol=1e-10, atol=1e-12, max_step=np.inf, gimbal_margin=1e-3,
                                        max_steps=10**6, max_wall_time=600.0))
        sol = integrate_chain_runs(tree_system(compiled), y0[None], settings_rows([sim]), method="DOP853",
                                   n_samples=4001)
        assert sol.status[0] == 0, (trial, chain)
        time = np.linspace(0.0, 1.0, 4001)
        out = C.evaluate(compiled, time, sol.samples[0], sol.work[0])
        v, w = out["lyapunov"], out["disturbance_work"]
        assert abs(w[-1]) > 1e-3  # the disturbances do work
        inner = cumulative_simpson(out["lyapunov_rate"] - out["disturbance_power"], x=time, initial=0.0)
        scale = 1.0 + np.abs(v).max()
        assert np.abs((v - v[0] - w) - inner).max() < 1e-5 * scale, (trial, chain)
        # and the analytic dv/dt is the derivative of v along the run
        smooth = np.ones(time.size, dtype=bool)
        for edge in time[np.flatnonzero(np.diff(out["disturbance_edges"])) + 1]:  # the sine's start, the pulse's
            smooth &= np.abs(time - edge) > 0.002
        assert np.abs(numerical_rate(time, v) - out["lyapunov_rate"])[smooth].max() < 1e-3 * (
            1.0 + np.abs(out["lyapunov_rate"]).max())


def test_rbstab_analyze_takes_one_body_and_a_chain_in_one_command(tmp_path):
    """One command analyses a one-body config and a chain together (one path for both):
    each writes its analysis file and its record, the chain's as rbstab.analyze gives it
    for the chain alone; a --boundary-layer, which only one body's sign law takes, is
    refused for the chain in one line before anything runs."""
    import json

    from click.testing import CliRunner

    import rbstab
    from rbstab.config.loader import load_config

    from rbstab_cli.main import cli

    chain = "configs/examples/stance_ankle_hip.yaml"
    both = CliRunner().invoke(cli, ["analyze", "configs/paper/case1_permanent.yaml", chain, "--json",
                                    "--no-certificate", "-o", str(tmp_path)])
    assert both.exit_code == 0, both.output
    records = [json.loads(line) for line in both.stdout.splitlines() if line.startswith("{")]
    assert [r["kind"] for r in records] == ["configuration", "chain"]
    assert (tmp_path / "case1_permanent.analysis.nc").is_file() and (tmp_path / "stance_ankle_hip.analysis.nc").is_file()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = rbstab.analyze(load_config(chain), certificate=False)
    assert alone.kind == "chain" and records[1]["eigenvalues"] == alone.to_json()["eigenvalues"]
    from rbstab.engine.cuda import CudaUnavailable
    from rbstab.engine.registry import get_engine

    def on_gpu():  # the chain's basin map on the GPU, as one body's
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return rbstab.analyze(load_config(chain), certificate=False, engine="cuda", basin_samples=21,
                                  basin=["initial_state.legs.theta.0=-0.1:0.1:3", "initial_state.trunk.theta.0=0:0.1:2"])

    if get_engine("cuda").unavailable():
        with pytest.raises(CudaUnavailable):
            on_gpu()
    else:
        assert on_gpu().basin.outcome.shape == (3, 2)
    refused = CliRunner().invoke(cli, ["analyze", chain, "--boundary-layer", "0.01", "-o", str(tmp_path / "no")])
    assert refused.exit_code == 1 and "a chain has no pure sign law to replace" in refused.output
    assert "Traceback" not in refused.output and not (tmp_path / "no").exists()
