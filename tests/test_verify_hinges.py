"""``rbstab analyze --verify`` of a tree of hinges (at most 3: 6 states): {v <= c} proven
positively invariant and inside the region of attraction by interval arithmetic over boxes
of the hinges' angles q. Checked against the compiled model (v at rest, its gradient and
Hessian inside the kernel's enclosures, stops and passive springs included), a closed form
(one inverted rod: the level where its clipped servo first reaches its limit, and a second
rest point above it), the sampled certificate, and runs from the level set that stay inside
and come back."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

pytest.importorskip("flint")

from rbstab.analysis import NotVerifiable, verify_sublevel  # noqa: E402
from rbstab.analysis.verify import _model, potential  # noqa: E402
from rbstab.config import config_from_mapping, load_config  # noqa: E402
from rbstab.simulator import simulate  # noqa: E402
from rbstab.variants import chain as C  # noqa: E402
from rbstab.variants.tree import expand_state, tree_layout  # noqa: E402

from conftest import ROOT  # noqa: E402

STANCE = ROOT / "configs/examples/stance_hinges.yaml"


def _rod(k=60.0, l=8.0, limit=6.0, mass=2.0, d=0.5):
    """One rod standing on a hinge about x (its centre of mass d [m] above the hinge), a
    servo k, l clipped to +-limit [N m]: P(q) = 1/2 k q^2 + m g d (cos q - 1)."""
    return {
        "name": "rod", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "rod", "mass": mass, "inertia": [0.2, 0.2, 0.01]}],
        "joints": [{"name": "ankle", "parent": "ground", "parent_point": [0.0, 0.0, 0.0], "child": "rod",
                    "child_point": [0.0, 0.0, -d], "variant": "hinge", "axis": [1.0, 0.0, 0.0], "k_r": k,
                    "l_r": l, "saturation": {"torque_n": limit}}],
        "initial_state": {"rod": {"q": 0.0}},
        "simulation": {"t_end": 10.0, "n_samples": 201},
    }


def _v_at_rest(compiled, layout, q) -> float:
    """The compiled model's v [J] at the joints' coordinates q (a universal joint's two) and u = 0."""
    yr = np.zeros(layout.n_r)
    yr[[int(layout.r_at[j]) + k for j, joint in enumerate(compiled.chain.joints)
        for k in range(2 if joint.variant == "universal" else 1)]] = q
    y = expand_state(compiled, layout, yr)
    n = compiled.size
    scalars = np.empty(5)
    C.chain_core(0.0, y, *compiled.args, np.empty(compiled.n_states), np.empty((n, 7, 3)), np.empty((n, 3)), scalars)
    return float(scalars[:4].sum() + compiled.offset)


def _kernel_holds(config, centres, rng, smooth=lambda lo, hi, x, h: True):
    """On small random boxes about ``centres`` (k, n) of the coordinates q, the compiled v at
    rest lies in the kernel's P(box), its central-difference gradient in the kernel's and,
    where ``smooth`` (lo, hi, x, step) says the second derivative does not jump, its Hessian
    in the kernel's; v is 0 at the rest state."""
    from flint import arb

    model, equilibrium = _model(config, arb)
    compiled = C.compile_chain(config.chain)
    layout = tree_layout(compiled)
    n, h = len(equilibrium), 1e-4
    eye = np.eye(n) * h

    def v(q):
        return _v_at_rest(compiled, layout, q)

    def inside(ball, x, slack):
        return float(ball.lower()) - slack <= x <= float(ball.upper()) + slack

    for centre in centres(equilibrium):
        lo, hi = centre - rng.uniform(0.0005, 0.002, n), centre + rng.uniform(0.0005, 0.002, n)
        p_box, grad, _, hess = model.evaluate(lo, hi, hessian=True)
        for x in rng.uniform(lo, hi, (6, n)):
            v0 = v(x)
            assert inside(p_box, v0, 1e-9 * (1 + abs(v0)))
            g = [(v(x + eye[a]) - v(x - eye[a])) / (2 * h) for a in range(n)]
            for a in range(n):
                assert inside(grad[a], g[a], 1e-5 * (1 + abs(g[a])))
                for b in range(n) if smooth(lo, hi, x, h) else ():
                    hs = (v(x + eye[a] + eye[b]) - v(x + eye[a] - eye[b]) - v(x - eye[a] + eye[b])
                          + v(x - eye[a] - eye[b])) / (4 * h * h)
                    assert inside(hess[a][b], hs, 2e-3 * (1 + abs(hs)))
    assert potential(config, equilibrium) == pytest.approx(0.0, abs=1e-9)  # v's zero at the rest state


def test_the_interval_kernel_holds_the_compiled_v_its_gradient_and_hessian():
    """The hinged stance (an asymmetric saturating ankle, the knee's passive spring and its
    stop, gravity): on random small boxes of q, some across the knee's stop, the compiled
    v at rest lies in P(box), its central-difference gradient and Hessian in the kernel's."""
    rng = np.random.default_rng(7)

    def centres(equilibrium):
        return [equilibrium + rng.normal(scale=0.3, size=3) for _ in range(8)] + [
            np.array([0.1, upper, -0.2]) for upper in (0.049, 0.051, 0.06)]  # the knee's stop at 0.05 rad

    def smooth(lo, hi, x, h):  # the stop's second derivative jumps at 0.05 rad
        return not (lo[1] < 0.05 < hi[1] or abs(x[1] - 0.05) < 2 * h)

    _kernel_holds(load_config(STANCE), centres, rng, smooth)


def test_one_rods_level_is_where_its_servo_first_reaches_its_limit():
    """One inverted rod: the proof stops where the static torque -k q reaches the clip
    (q* = limit / k; the closed form P(q*) of v at rest), within the search's tolerance; a
    level holding the second rest point (m g d sin q = limit, where the clipped servo holds
    the rod against gravity) is refused, naming the box and the limit."""
    k, limit, mass, d = 60.0, 6.0, 2.0, 0.5
    config = config_from_mapping(_rod(k=k, limit=limit, mass=mass, d=d))
    mgd = mass * 9.81 * d

    def closed(q):
        return 0.5 * k * q * q + mgd * (math.cos(q) - 1.0)

    onset = closed(limit / k)
    result = verify_sublevel(config)
    assert (1 - 0.011) * onset <= result.level <= onset, (result.level, onset)
    assert "ankle" in result.reason and "[-6, 6] N m" in result.reason
    assert potential(config, np.array([0.3])) == pytest.approx(closed(0.3), rel=1e-12)
    second = math.asin(limit / mgd)  # at rest there: the clipped servo balances gravity
    with pytest.raises(NotVerifiable, match=r"not proven: box q in .*ankle.*reaches its limits"):
        verify_sublevel(config, level=closed(second))


def test_a_range_that_is_an_admissible_region_bounds_the_proven_level():
    """The rod's range [-0.04, 0.05] rad as an admissible region, inside the clip's onset
    (0.1 rad): the proof's domain ends there, so c stops at P(-0.04), the nearer end's,
    within the search's tolerance, naming the range."""
    k, mgd = 60.0, 2.0 * 9.81 * 0.5
    data = _rod(k=k)
    data["joints"][0]["range"] = {"lower": -0.04, "upper": 0.05, "kind": "region"}
    result = verify_sublevel(config_from_mapping(data))
    edge = 0.5 * k * 0.04 ** 2 + mgd * (math.cos(0.04) - 1.0)
    assert (1 - 0.011) * edge <= result.level <= edge, (result.level, edge)
    assert "q of ankle = -0.04 rad (joints.ankle.range, an admissible region)" in result.reason


def test_a_rest_state_outside_a_range_that_is_an_admissible_region_is_refused_by_the_analysis():
    """The rod hanging on its hinge, gravity tilted so that it rests at q = 0.0043 rad: with
    its range [-0.001, 0.001] as an admissible region, the analysis says the rest state lies
    outside it, naming the joint and the end; with [-0.05, 0.05] it analyses."""
    from rbstab.analysis import analyze
    from rbstab.analysis.analyze import OutsideLimits

    data = _rod(k=60.0)
    data["joints"][0]["child_point"] = [0.0, 0.0, 0.5]
    data["gravity"] = [0.0, 0.3, -9.81]
    data["joints"][0]["range"] = {"lower": -0.05, "upper": 0.05, "kind": "region"}
    rest = analyze(config_from_mapping(data), simulate=False, certificate=False).linearisation.equilibrium
    assert 0.004 < rest[0] < 0.005
    data["joints"][0]["range"] = {"lower": -0.001, "upper": 0.001, "kind": "region"}
    with pytest.raises(OutsideLimits, match=r"outside joints.ankle.range \(an admissible region\): its q is above "
                                            r"0.001 rad"):
        analyze(config_from_mapping(data), simulate=False, certificate=False)


def test_the_hinged_stances_verified_level_holds_where_its_runs_go():
    """The hinged stance's verified c lies at or below the sampled certificate's estimate
    (to the search's tolerance), and runs from states on {v = c} (the directions where the
    certificate's search found dv/dt largest, and random ones), written as each hinge's
    initial q and u, never rise above c, never leave the admissible region and come back."""
    from rbstab.analysis import analyze
    from rbstab.analysis.certificate import ChainModel, level_states

    config = load_config(STANCE, ["simulation.n_samples=301", "simulation.t_end=8"])
    analysis = analyze(config, samples=300, falsification_runs=0, simulate=False)
    proven, estimate = verify_sublevel(config, rtol=0.05).level, analysis.certificate.sublevel
    assert 0.9 * estimate < proven <= estimate * (1 + 0.02), (proven, estimate)
    model = ChainModel(C.compile_chain(config.chain))
    names = analysis.layout.state_names()
    at_level = dataclasses.replace(analysis.certificate, sublevel=proven)
    for z in level_states(model, analysis.linearisation, at_level, 6, seed=11):
        start = {name.split(".")[0]: {} for name in names}
        for name, value in zip(names, z):
            body, block = name.split(".")
            start[body][block] = float(value)
        result = simulate(config_from_mapping({**config.resolved, "initial_state": start}))
        v = result.outputs["lyapunov"]
        assert result.status == "success", result.message
        assert v[0] == pytest.approx(proven, rel=1e-6)
        assert v.max() <= v[0] * (1 + 1e-9) and v[-1] < 0.05 * v[0]


@pytest.mark.parametrize("change, expected", [
    (lambda d: d["joints"][0].update(l_r=0.0), "joints.ankle.l_r: found 0"),
    (lambda d: d["joints"][0]["saturation"].update(shape="smooth"), "joints.ankle.saturation.shape"),
    (lambda d: d["simulation"].update(limits={"omega": [5.0, 5.0, 5.0]}), "simulation.limits"),
    (lambda d: (d["bodies"].append({"name": "head", "mass": 1.0, "inertia": [0.01, 0.01, 0.01]}),
                d["joints"].append({"name": "neck", "parent": "rod", "parent_point": [0.0, 0.0, 0.5], "child": "head",
                                    "child_point": [0.0, 0.0, -0.1], "variant": "permanent", "k_r": [5.0] * 3,
                                    "l_r": [1.0] * 3})),
     "joints.neck.variant: found 'permanent' in a tree with a hinge"),
])
def test_what_the_hinge_proof_does_not_cover_is_refused_in_one_line(change, expected):
    data = _rod()
    change(data)
    with pytest.raises(NotVerifiable, match=expected):
        verify_sublevel(config_from_mapping(data))


# -- slides: a tree of hinges and slides ------------------------------------------------------------
CART_POLE = ROOT / "configs/examples/cart_pole_imported.yaml"


def _block(k=400.0, l=6.0, limit=30.0, mass=2.0, q_ref=0.1):
    """A block on a vertical slide, a servo k, l about q_ref clipped to +-limit [N]:
    P(q) = 1/2 k (q - q_ref)^2 + m g q + h."""
    return {
        "name": "block", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "block", "mass": mass, "inertia": [0.1, 0.2, 0.15]}],
        "joints": [{"name": "rail", "parent": "ground", "child": "block", "variant": "slide", "axis": [0.0, 0.0, 1.0],
                    "k_r": k, "l_r": l, "theta_ref": q_ref, "saturation": {"torque_n": limit}}],
        "initial_state": {"block": {"q": 0.0}},
        "simulation": {"t_end": 3.0, "n_samples": 101},
    }


def test_a_blocks_level_is_where_its_slides_force_first_reaches_its_limit():
    """A block held up by a sprung slide: the proof stops where the static force -k (q - q_ref)
    first reaches its clip, at the level (limit - m g)^2 / (2 k) above the rest state (the
    closed form), within the search's tolerance, naming the slide and its limits in N; P is
    1/2 k (q - q_e)^2 there."""
    k, limit, mass, q_ref = 400.0, 30.0, 2.0, 0.1
    config = config_from_mapping(_block(k=k, limit=limit, mass=mass, q_ref=q_ref))
    onset = (limit - mass * 9.81) ** 2 / (2 * k)
    result = verify_sublevel(config)
    assert (1 - 0.011) * onset <= result.level <= onset, (result.level, onset)
    assert "rail" in result.reason and "[-30, 30] N" in result.reason and "force" in result.reason
    rest = q_ref - mass * 9.81 / k
    assert potential(config, np.array([0.3])) == pytest.approx(0.5 * k * (0.3 - rest) ** 2, rel=1e-12)


def test_the_interval_kernel_holds_a_cart_poles_compiled_v_its_gradient_and_hessian():
    """The shipped cart-pole (a slide with a spring, a passive spring and a saturating servo,
    a hinge across it): on random small boxes of (q_cart [m], q_pole [rad]), the compiled v at
    rest lies in P(box), its central-difference gradient and Hessian in the kernel's."""
    rng = np.random.default_rng(3)
    _kernel_holds(load_config(CART_POLE), lambda e: [e + rng.normal(scale=0.3, size=2) for _ in range(8)], rng)


def test_the_cart_poles_verified_level_holds_where_its_runs_go():
    """The cart-pole's verified c lies at or below the sampled certificate's estimate, and runs
    from states on {v = c} (written as the slide's and the hinge's q and u) never rise above c
    and come back."""
    from rbstab.analysis import analyze
    from rbstab.analysis.certificate import ChainModel, level_states

    config = load_config(CART_POLE, ["simulation.n_samples=301", "simulation.t_end=10"])
    analysis = analyze(config, samples=300, falsification_runs=0, simulate=False)
    proven, estimate = verify_sublevel(config, rtol=0.05).level, analysis.certificate.sublevel
    assert 0.0 < proven <= estimate * (1 + 0.02), (proven, estimate)
    model = ChainModel(C.compile_chain(config.chain))
    names = analysis.layout.state_names()
    key = {"translation": "q", "translation_rate": "u", "q": "q", "u": "u"}
    at_level = dataclasses.replace(analysis.certificate, sublevel=proven)
    for z in level_states(model, analysis.linearisation, at_level, 6, seed=5):
        start = {name.split(".")[0]: {} for name in names}
        for name, value in zip(names, z):
            body, block = name.split(".")
            start[body][key[block]] = float(value)
        result = simulate(config_from_mapping({**config.resolved, "initial_state": start}))
        v = result.outputs["lyapunov"]
        assert result.status == "success", result.message
        assert v[0] == pytest.approx(proven, rel=1e-6)
        assert v.max() <= v[0] * (1 + 1e-9) and v[-1] < 0.05 * v[0]


def test_a_universal_rods_level_is_where_its_servo_first_reaches_its_limit():
    """One inverted rod on a universal joint about x then y, a servo k, l on each angle
    clipped to +-limit: P(q) = 1/2 k (q_1^2 + q_2^2) + m g d (cos q_1 cos q_2 - 1); the proof
    stops at the rod's closed-form level, where a coordinate's torque first clips (its
    minimum over q_2 at q_2 = 0, k > m g d), naming the coordinate; the kernel holds the
    compiled v, its gradient and Hessian."""
    k, limit, mass, d = 60.0, 6.0, 2.0, 0.5
    data = _rod(k=k, limit=limit, mass=mass, d=d)
    data["joints"][0].update(variant="universal", axis=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], k_r=[k, k], l_r=[8.0, 8.0])
    data["initial_state"]["rod"] = {"q": [0.0, 0.0]}
    config = config_from_mapping(data)
    mgd = mass * 9.81 * d
    onset = 0.5 * k * (limit / k) ** 2 + mgd * (math.cos(limit / k) - 1.0)
    result = verify_sublevel(config)
    assert (1 - 0.011) * onset <= result.level <= onset, (result.level, onset)
    assert "ankle.q_" in result.reason and "[-6, 6] N m" in result.reason
    q = np.array([0.3, -0.2])
    closed = 0.5 * k * q @ q + mgd * (math.cos(q[0]) * math.cos(q[1]) - 1.0)
    assert potential(config, q) == pytest.approx(closed, rel=1e-12)
    rng = np.random.default_rng(4)
    _kernel_holds(config, lambda e: [e + rng.normal(scale=0.3, size=2) for _ in range(6)], rng)


# -- balls: a quaternion ball's rotation vector --------------------------------------------------------
def _ball_rod(k=(60.0, 60.0, 60.0), limit=6.0, mass=2.0, d=0.5, **joint):
    """:func:`_rod` on a quaternion ball: a servo k_i, l_i on each entry of the rotation vector
    phi of its turn from its reference, clipped to +-limit [N m] per axis."""
    data = _rod(limit=limit, mass=mass, d=d)
    data["joints"][0] = {**{key: data["joints"][0][key] for key in ("name", "parent", "parent_point", "child",
                                                                   "child_point")},
                         "variant": "ball", "k_r": list(k), "l_r": [8.0, 8.0, 1.0],
                         "saturation": {"torque_n": [limit] * 3}, **joint}
    data["initial_state"] = {}
    return data


def _ball_v(config, phi) -> float:
    """The compiled model's v [J] at rest at the ball's turn ``phi`` from its reference
    (its A_rel = A(Theta_ref) exp(phi), written as the child's initial rotation vector)."""
    from scipy.spatial.transform import Rotation

    ref = np.array(config.chain.joints[0].theta_ref, dtype=float)
    theta = (Rotation.from_rotvec(ref) * Rotation.from_rotvec(phi)).as_rotvec()
    compiled = C.compile_chain(config.chain)
    layout = tree_layout(compiled)
    w = Rotation.from_rotvec(theta).as_quat()  # (x, y, z, w)
    yr = np.zeros(layout.n_r)
    yr[:4] = [w[3], w[0], w[1], w[2]]
    y = expand_state(compiled, layout, yr)
    scalars = np.empty(5)
    C.chain_core(0.0, y, *compiled.args, np.empty(compiled.n_states), np.empty((1, 7, 3)), np.empty((1, 3)), scalars)
    return float(scalars[:4].sum() + compiled.offset)


def test_a_ball_rods_level_is_where_its_servo_first_reaches_its_limit():
    """One inverted rod on a quaternion ball with an isotropic servo k clipped to +-limit on
    each axis: -J_r(phi)^-T K phi = -k phi, and P(phi) = 1/2 k |phi|^2 + m g d (A_33 - 1),
    A_33 = cos t + (1 - cos t) phi_3^2 / t^2 (t = |phi|); the proof stops at the level of the
    universal rod's closed form, where an axis's torque first clips, naming the entry of phi."""
    k, limit, mass, d = 60.0, 6.0, 2.0, 0.5
    config = config_from_mapping(_ball_rod(k=(k, k, k), limit=limit, mass=mass, d=d))
    mgd = mass * 9.81 * d
    onset = 0.5 * k * (limit / k) ** 2 + mgd * (math.cos(limit / k) - 1.0)
    result = verify_sublevel(config)
    assert (1 - 0.011) * onset <= result.level <= onset, (result.level, onset)
    assert "ankle.phi_" in result.reason and "[-6, 6] N m" in result.reason
    phi = np.array([0.3, -0.2, 0.4])
    t = np.linalg.norm(phi)
    a33 = math.cos(t) + (1 - math.cos(t)) * phi[2] ** 2 / t ** 2
    assert potential(config, phi) == pytest.approx(0.5 * k * phi @ phi + mgd * (a33 - 1.0), rel=1e-12)
    with pytest.raises(NotVerifiable, match=r"not proven: box q in .*ankle\.phi_.*reaches its limits"):
        verify_sublevel(config, level=1.5 * onset)


def test_the_interval_kernel_holds_a_balls_compiled_v_its_gradient_and_hessian():
    """A rod on a ball turned from its reference (Theta_ref a rotation vector), anisotropic
    servo gains, a passive spring relaxed at the same reference: on random small boxes of
    phi (some across phi = 0, where the series of the rotation's coefficients are used at
    s = |phi|^2 = 0), the compiled v at rest lies in P(box), its central-difference gradient
    and Hessian in the kernel's; its commanded torque -J_r^-T K phi (rbstab.kinematics) in
    the kernel's."""
    from flint import arb

    from rbstab.kinematics import right_jacobian_inverse

    data = _ball_rod(k=(60.0, 40.0, 10.0), theta_ref=[0.1, -0.05, 0.2],
                     passive={"k_r": [5.0, 3.0, 1.0], "l_r": [0.5, 0.5, 0.5], "theta_ref": [0.1, -0.05, 0.2]})
    config = config_from_mapping(data)
    model, equilibrium = _model(config, arb)
    assert abs(_ball_v(config, equilibrium)) < 1e-9  # v's zero at the rest state
    rng = np.random.default_rng(3)
    h, eye = 1e-4, np.eye(3) * 1e-4
    centres = [equilibrium + rng.normal(scale=0.4, size=3) for _ in range(5)] + [np.zeros(3)]
    for centre in centres:
        lo, hi = centre - rng.uniform(0.0005, 0.002, 3), centre + rng.uniform(0.0005, 0.002, 3)
        p_box, grad, tau, hess = model.evaluate(lo, hi, hessian=True)
        for x in rng.uniform(lo, hi, (4, 3)):
            v0 = _ball_v(config, x)
            assert float(p_box.lower()) - 1e-9 <= v0 <= float(p_box.upper()) + 1e-9
            torque = -np.asarray(right_jacobian_inverse(tuple(x))).T @ (np.array([60.0, 40.0, 10.0]) * x)
            for a in range(3):
                assert float(tau[a].lower()) - 1e-12 <= torque[a] <= float(tau[a].upper()) + 1e-12
                g = (_ball_v(config, x + eye[a]) - _ball_v(config, x - eye[a])) / (2 * h)
                assert float(grad[a].lower()) - 1e-5 * (1 + abs(g)) <= g <= float(grad[a].upper()) + 1e-5 * (1 + abs(g))
                for b in range(3):
                    hs = (_ball_v(config, x + eye[a] + eye[b]) - _ball_v(config, x + eye[a] - eye[b])
                          - _ball_v(config, x - eye[a] + eye[b]) + _ball_v(config, x - eye[a] - eye[b])) / (4 * h * h)
                    slack = 2e-3 * (1 + abs(hs))
                    assert float(hess[a][b].lower()) - slack <= hs <= float(hess[a][b].upper()) + slack


def test_a_balls_verified_level_holds_where_its_runs_go():
    """The anisotropic ball rod with its cone an admissible region: its verified c is below
    P at points on the cone, and runs from rest on {v = c} (turns in random directions,
    written as the child's Euler angles) never rise above c, never leave the cone and come
    back."""
    from scipy.spatial.transform import Rotation

    ref = np.array([0.1, -0.05, 0.0])
    data = _ball_rod(k=(60.0, 40.0, 10.0), theta_ref=ref.tolist(), range={"lower": 0.0, "upper": 0.5, "kind": "region"})
    data["simulation"].update(t_end=8.0, n_samples=161, rtol=1e-9, atol=1e-11)
    config = config_from_mapping(data)
    proven = verify_sublevel(config, rtol=0.05)
    assert proven.level > 0.0
    rng = np.random.default_rng(2)
    for e in rng.normal(size=(20, 3)):  # P at turns of 0.5 rad, on the cone, is above c
        on_cone = (Rotation.from_rotvec(ref).inv() * Rotation.from_rotvec(0.5 * e / np.linalg.norm(e))).as_rotvec()
        assert potential(config, on_cone) > proven.level
    for direction in rng.normal(size=(4, 3)):
        direction /= np.linalg.norm(direction)
        low, high = 0.0, 3.0
        for _ in range(60):  # the turn along ``direction`` with P = c
            mid = 0.5 * (low + high)
            low, high = (mid, high) if potential(config, mid * direction) < proven.level else (low, mid)
        theta = (Rotation.from_rotvec(ref) * Rotation.from_rotvec(low * direction)).as_euler("XYZ")  # A = Rx Ry Rz
        result = simulate(config_from_mapping({**config.resolved, "initial_state": {"rod": {"theta": theta.tolist()}}}))
        v = result.outputs["lyapunov"]
        assert result.status == "success", result.message
        assert v[0] == pytest.approx(proven.level, rel=1e-6)
        assert v.max() <= v[0] * (1 + 1e-9) and v[-1] < 0.05 * v[0]


@pytest.mark.parametrize("change, expected", [
    (lambda j: j.update(range={"lower": 0.0, "upper": 0.5, "k_r": 100.0}), "joints.ankle.range: found a stop"),
    (lambda j: j.update(passive={"k_r": [1.0, 1.0, 1.0], "l_r": [0.1] * 3, "theta_ref": [0.1, 0.0, 0.0]}),
     "joints.ankle.passive.theta_ref"),
    (lambda j: j.update(l_r=[8.0, 8.0, 0.0]), "joints.ankle.l_r: found"),
    (lambda j: j.update(k_r=[[60.0, 1.0, 0.0], [1.0, 60.0, 0.0], [0.0, 0.0, 60.0]]), "non-diagonal"),
])
def test_what_the_ball_proof_does_not_cover_is_refused_in_one_line(change, expected):
    data = _ball_rod()
    change(data["joints"][0])
    with pytest.raises(NotVerifiable, match=expected):
        verify_sublevel(config_from_mapping(data))


def test_a_tree_with_a_ball_above_six_states_is_refused_in_one_line():
    data = _ball_rod()
    data["bodies"].append({"name": "head", "mass": 1.0, "inertia": [0.01, 0.01, 0.01]})
    data["joints"].append({"name": "neck", "parent": "rod", "parent_point": [0.0, 0.0, 0.5], "child": "head",
                           "child_point": [0.0, 0.0, -0.1], "variant": "hinge", "axis": [1.0, 0.0, 0.0], "k_r": 5.0,
                           "l_r": 1.0})
    with pytest.raises(NotVerifiable, match="this tree has 8 states; --verify covers at most 6"):
        verify_sublevel(config_from_mapping(data))


@pytest.mark.parametrize("kind", ["universal", "ball", "slide"])
def test_rbstab_analyze_verify_writes_each_coordinates_box_row(kind, tmp_path):
    """``rbstab analyze --verify`` of one rod on a universal joint, a ball, and of a block on
    a slide writes its analysis file with a row of the verified box for each coordinate,
    named (``<joint>.q_1``, ``<joint>.phi_1``, the slide's joint), the slide's in m."""
    import xarray as xr
    import yaml
    from click.testing import CliRunner

    from rbstab_cli.main import cli

    if kind == "slide":
        data, names = _block(), ["rail"]
    elif kind == "ball":
        data, names = _ball_rod(), ["ankle.phi_1", "ankle.phi_2", "ankle.phi_3"]
    else:
        data, names = _rod(), ["ankle.q_1", "ankle.q_2"]
        data["joints"][0].update(variant="universal", axis=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], k_r=[60.0, 60.0],
                                 l_r=[8.0, 8.0])
        data["initial_state"]["rod"] = {"q": [0.0, 0.0]}
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(data))
    result = CliRunner().invoke(cli, ["analyze", str(path), "--verify", "--no-certificate", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    with xr.open_dataset(tmp_path / f"{data['name']}.analysis.nc", engine="h5netcdf") as ds:
        box = ds["sublevel_verified_box"]
        assert list(ds["hinge"].values) == names and box.shape == (len(names), 2)
        assert np.all(box.values[:, 0] <= box.values[:, 1]) and float(ds["sublevel_verified"]) > 0
        assert box.attrs.get("units") == (None if kind == "slide" else "rad")
