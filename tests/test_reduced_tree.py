"""A tree in reduced coordinates (docs/physics.md, "A tree in reduced coordinates"), as the
plain-numpy model of tests/reference_tree.py writes it, against rbstab's two models of today:
one body on a permanent joint is the paper's reduced system (eqs 18-21, 32-35); the stance
double pendulum moves as the maximal-coordinate chain, with the same constraint forces; v is
conserved without damping and its rate is -sum Omega_j' L_r Omega_j; random trees of
permanent, free and visco-elastic joints have the chain's accelerations, Lambda_j, v and
dv/dt; random trees with hinges and stops have the reference's reduced rate; a push in
reduced coordinates is the chain's push."""

from __future__ import annotations

import dataclasses
import functools
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import reference_tree as T
from reference import hat, rotation
from rbstab.variants.paper import paper_form
from rbstab.chain import Body, Chain, Joint, Stop, hinge, slide, universal
from rbstab.config.loader import load_config
from rbstab.model import Saturation
from rbstab.simulator import simulate
from rbstab.variants import VARIANTS
from rbstab.variants import chain as C
from rbstab.variants.disturbances import IMPULSE

D = np.diag
ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "configs" / "examples"


def _load(path, overrides=()):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # plausibility notes: not what these tests look at
        return load_config(path, list(overrides))


# -- (a) one body on a permanent joint ----------------------------------------------------------------
@pytest.mark.parametrize("path", [EXAMPLES / "stance_ankle.yaml", ROOT / "configs" / "paper" / "case1_permanent.yaml"],
                         ids=["stance_ankle", "case1_permanent"])
def test_one_permanent_body_is_the_papers_reduced_system(path, rng):
    """The reduced tree of one body on a permanent joint has the mass matrix J_p = J - m hat(R)^2
    (eq 21) and, at random states, the rate, Lambda (eq 20), v and dv/dt of rbstab's
    ``permanent`` variant (with the ankle's clipped torque where the config limits it)."""
    config = _load(path)
    body, gains = paper_form(config).body, paper_form(config).gains
    sat = gains.saturation
    tree = T.Tree((T.Body(body.mass, body.inertia, gains.k_t, gains.l_t),),
                  (T.Joint(T.GROUND, body.attachment_point, body.attachment_point, T.PERMANENT, gains.k_r, gains.l_r,
                           torque_limit=None if sat is None else np.asarray(sat.torque_n, float)),),
                  body.gravity)
    variant = VARIANTS[config.chain.joints[0].variant](body, gains)
    r, m = body.attachment_point, body.mass
    clipped = 0
    for _ in range(20):
        y = np.concatenate([rng.normal(scale=0.3, size=3), rng.normal(scale=2.0, size=3)])
        ev = T.evaluate(tree, y)
        np.testing.assert_allclose(ev.mass, body.inertia - m * hat(r) @ hat(r), rtol=1e-13, atol=1e-12)
        theirs = variant.evaluate(y[None])
        expected = variant.rhs(0.0, y)
        np.testing.assert_allclose(ev.dy, expected, rtol=1e-11, atol=1e-11 * np.abs(expected).max())
        np.testing.assert_allclose(ev.lam[0], theirs["constraint_force"][0], rtol=1e-11,
                                   atol=1e-11 * np.abs(ev.lam).max())
        np.testing.assert_allclose(ev.conf.position[0], theirs["position"][0], atol=1e-14)  # X = R - A R (eq 32)
        np.testing.assert_allclose(ev.v[0], theirs["velocity"][0], atol=1e-13)  # V = A hat(R) Omega
        terms, rate = T.lyapunov(tree, y)
        assert sum(terms) + variant.lyapunov_offset == pytest.approx(float(theirs["lyapunov"][0]), rel=1e-11, abs=1e-9)
        assert rate == pytest.approx(float(theirs["lyapunov_rate"][0]), rel=1e-10, abs=1e-9)
        clipped += bool(np.any(ev.forces.n_j != ev.forces.n_command))
    if sat is not None:
        assert clipped > 0  # the clipped torque was exercised


# -- (b), (c) the stance double pendulum -------------------------------------------------------------
STANCE = EXAMPLES / "stance_ankle_hip.yaml"


def _stance_tree(l_r=((300.0, 300.0, 30.0), (100.0, 100.0, 20.0)), limited=True):
    """configs/examples/stance_ankle_hip.yaml written out by hand: legs on the ankle (ground),
    the trunk on the hip (legs); K_r, L_r and the torque limits of its joints."""
    legs, trunk = T.Body(22.54, D([1.77, 1.95, 0.22])), T.Body(47.46, D([2.97, 2.97, 0.42]))
    ankle = T.Joint(T.GROUND, np.zeros(3), np.array([0.0, 0.0, -0.475]), T.PERMANENT, D([1000.0, 1000.0, 100.0]),
                    D(l_r[0]), torque_limit=np.array([120.0, 120.0, np.inf]) if limited else None)
    hip = T.Joint(0, np.array([0.0, 0.0, 0.384]), np.array([0.0, 0.0, -0.316]), T.PERMANENT, D([500.0, 500.0, 100.0]),
                  D(l_r[1]), torque_limit=np.array([150.0, 150.0, np.inf]) if limited else None)
    return T.Tree((legs, trunk), (ankle, hip), np.array([0.0, 0.0, -9.81]))


def _same_tree(tree, chain):
    """The hand-written tree is the config's chain (masses, inertias, points, gains, limits)."""
    for mine, body in zip(tree.bodies, chain.bodies):
        assert mine.mass == body.mass and np.array_equal(mine.inertia, body.inertia)
        assert not body.k_t.any() and not body.l_t.any()
    for mine, joint in zip(tree.joints, chain.joints):
        assert mine.parent == joint.parent and joint.variant == "permanent"
        for a, b in ((mine.parent_point, joint.parent_point), (mine.child_point, joint.child_point),
                     (mine.k_r, joint.k_r), (mine.l_r, joint.l_r), (mine.torque_limit, joint.saturation.torque_n)):
            assert np.array_equal(a, b)
        assert joint.saturation.shape == "clip"


#: The stance example as written (planar: it sways about x), and with a 3-D start whose
#: ankle torque reaches its limit.
STARTS = {
    "planar": [],
    "3d": ["initial_state.legs.omega=[0.4, -0.3, 0.5]", "initial_state.trunk.omega=[-0.6, 0.5, 1.2]",
           "initial_state.trunk.theta=[-0.05, 0.04, 0.1]"],
}
T_END = 2.0


@functools.lru_cache(maxsize=None)
def _stance_runs(start):
    """(rbstab's chain run of the stance example over 2 s at rtol 1e-10, the reference's
    trajectory at the same times, the tree)."""
    config = _load(STANCE, ["simulation.t_end=2.0", "simulation.n_samples=41", "simulation.rtol=1e-10",
                            "simulation.atol=1e-12", *STARTS[start]])
    run = simulate(config)
    assert run.status == "success", run.message
    tree = _stance_tree()
    _same_tree(tree, config.chain)
    y12 = np.concatenate([np.concatenate([config.initial_state[b.name][k] for k in ("theta", "omega", "position",
                                                                                    "velocity")])
                          for b in config.chain.bodies])
    sol = solve_ivp(lambda t, y: T.rate(tree, y), (0.0, T_END), T.reduced_state(tree, y12), method="DOP853",
                    rtol=1e-10, atol=1e-12, t_eval=run.time)
    assert sol.success
    return run, sol, tree


@pytest.mark.parametrize("start", sorted(STARTS))
def test_stance_double_pendulum_moves_as_the_maximal_coordinate_chain(start):
    """The reference's centres of mass and orientations follow rbstab's maximal-coordinate
    chain run to the solver's tolerance: 1e-8 m, 1e-7 rad over 2 s at rtol 1e-10."""
    run, sol, tree = _stance_runs(start)
    maximal = np.array([T.maximal_state(tree, y).reshape(2, 4, 3) for y in sol.y.T])
    assert np.abs(maximal[:, :, 2] - run.outputs["position"]).max() < 1e-8
    assert np.abs(maximal[:, :, 0] - run.outputs["theta"]).max() < 1e-7
    assert np.abs(maximal[:, :, 1] - run.outputs["omega"]).max() < 1e-6
    assert np.ptp(maximal[:, :, 0], axis=0).max() > 0.05  # it moves
    torque = np.array([T.evaluate(tree, y).forces.n_j for y in sol.y.T])
    if start == "3d":
        assert np.abs(torque[:, 0, 0]).max() == 120.0  # the ankle's limit was reached


@pytest.mark.parametrize("start", sorted(STARTS))
def test_constraint_forces_recovered_from_the_reduced_state_are_the_chains(start):
    """Lambda_j from the reduced state and its accelerations (Newton's equations, leaves first)
    equals the chain's Lambda_j of the stacked eq 15 at the same times, to 1e-6 of its size."""
    run, sol, tree = _stance_runs(start)
    lam = np.array([T.evaluate(tree, y).lam for y in sol.y.T])
    theirs = run.outputs["constraint_force"]
    assert np.abs(lam - theirs).max() < 1e-6 * np.abs(theirs).max()
    weight = sum(b.mass for b in tree.bodies) * 9.81
    assert np.abs(theirs[:, 0, 2]).max() == pytest.approx(weight, rel=0.2)  # the ankle carries the body


def test_v_is_conserved_without_damping_and_its_rate_is_the_joints_dissipation(rng):
    """With L_r = 0 (and no torque limits) v of the stance double pendulum stays constant along
    a 3-D motion of the reference; with L_r, the derivative of v along the flow is
    -sum_j Omega_j' L_r Omega_j, Omega_j read from the state: no constraint-force term."""
    tree = _stance_tree(l_r=(np.zeros(3), np.zeros(3)), limited=False)
    y0 = np.array([0.05, -0.02, 0.1, 0.4, -0.3, 0.5, -0.1, 0.04, 0.1, -0.6, 0.5, 1.2])
    sol = solve_ivp(lambda t, y: T.rate(tree, y), (0.0, 1.0), y0, method="DOP853", rtol=1e-10, atol=1e-12,
                    t_eval=np.linspace(0.0, 1.0, 11))
    terms = np.array([T.lyapunov(tree, y)[0] for y in sol.y.T])
    v = terms.sum(axis=1)
    assert np.ptp(v) < 1e-8 * np.abs(terms).max()
    assert np.ptp(terms[:, 0]) > 1.0  # energy moves between its terms
    damped = _stance_tree(limited=False)
    l_r = [j.l_r for j in damped.joints]
    for _ in range(10):
        y = np.concatenate([rng.normal(scale=0.2, size=3), rng.normal(size=3), rng.normal(scale=0.2, size=3),
                            rng.normal(size=3)])
        f = T.rate(damped, y)
        h = 1e-6
        numerical = (sum(T.lyapunov(damped, y + h * f)[0]) - sum(T.lyapunov(damped, y - h * f)[0])) / (2 * h)
        dissipation = y[3:6] @ l_r[0] @ y[3:6] + y[9:12] @ l_r[1] @ y[9:12]
        assert numerical == pytest.approx(-dissipation, rel=1e-6, abs=1e-6)
        assert T.lyapunov(damped, y)[1] == pytest.approx(-dissipation, rel=1e-12)


# -- random trees: every body's Euler equation, and the chain's rate ------------------------------------
def _random_tree(rng, laws):
    bodies, joints = [], []
    for i, law in enumerate(laws):
        k_t = D(rng.uniform(0.0, 20.0, 3)) if rng.random() < 0.5 else np.zeros((3, 3))
        bodies.append(T.Body(float(rng.uniform(0.5, 3.0)), D(rng.uniform(0.05, 0.5, 3)), k_t, 0.5 * k_t))
        point_law = dict(k_c=D(rng.uniform(200.0, 800.0, 3)), l_c=D(rng.uniform(5.0, 30.0, 3))) \
            if law == T.VISCO_ELASTIC else {}
        joints.append(T.Joint(T.GROUND if i == 0 else int(rng.integers(0, i)), rng.normal(scale=0.2, size=3),
                              rng.normal(scale=0.2, size=3), law, D(rng.uniform(0.0, 30.0, 3)),
                              D(rng.uniform(0.0, 5.0, 3)),
                              torque_limit=np.full(3, 2.0) if rng.random() < 0.5 else None, **point_law))
    return T.Tree(tuple(bodies), tuple(joints), np.array([0.0, 0.0, -9.81]))


def _chain(tree):
    """rbstab's chain of the same tree."""
    inf = np.full(3, np.inf)
    bodies = tuple(Body(f"b{i}", b.mass, b.inertia, b.k_t, b.l_t) for i, b in enumerate(tree.bodies))
    joints = tuple(Joint(f"j{i}", j.parent, i, j.parent_point, j.child_point, j.law, j.k_r, j.l_r,
                         **({"k_c": j.k_c, "l_c": j.l_c} if j.law == T.VISCO_ELASTIC else {}),
                         saturation=None if j.torque_limit is None else Saturation(j.torque_limit, inf, inf, "clip"))
                   for i, j in enumerate(tree.joints))
    return Chain(bodies, joints, tree.gravity)


LAW_MIXES = {
    "permanent": [T.PERMANENT] * 4,
    "mixed": [T.PERMANENT, T.VISCO_ELASTIC, T.PERMANENT, T.FREE],
    "free_root": [T.FREE, T.PERMANENT, T.VISCO_ELASTIC, T.PERMANENT],
    "no_permanent": [T.FREE, T.VISCO_ELASTIC, T.VISCO_ELASTIC, T.FREE],
}


def _random_state(rng, tree):
    """Angles, positions and speeds of 0.3, angular velocities of 2 rad/s (standard deviations)."""
    starts, size = T.state_blocks(tree)
    y = rng.normal(scale=0.3, size=size)
    for s in starts:
        y[s + 3: s + 6] = rng.normal(scale=2.0, size=3)
    return y


@pytest.mark.parametrize("mix", sorted(LAW_MIXES))
def test_recovered_constraint_forces_close_every_bodys_euler_equation(mix, rng):
    """The Lambda_j recovered from the bodies' Newton equations also satisfy every body's Euler
    equation J dOmega/dt + Omega x J Omega = (applied torque) + R_c x A'Lambda_c -
    sum_k R_p,k x A'Lambda_k: the projected equations lose nothing."""
    for _ in range(3):
        tree = _random_tree(rng, LAW_MIXES[mix])
        for _ in range(3):
            ev = T.evaluate(tree, _random_state(rng, tree))
            for i, body in enumerate(tree.bodies):
                torque = ev.forces.torque[i].copy()
                if tree.permanent(i):
                    torque += T.cross(tree.joints[i].child_point, ev.conf.rot[i].T @ ev.lam[i])
                for k in tree.children(i):
                    if tree.permanent(k):
                        torque -= T.cross(tree.joints[k].parent_point, ev.conf.rot[i].T @ ev.lam[k])
                inertial = body.inertia @ ev.omega_dot[i] + T.cross(ev.omega[i], body.inertia @ ev.omega[i])
                np.testing.assert_allclose(inertial, torque, atol=1e-10 * (1 + np.abs(torque).max()))


@pytest.mark.parametrize("mix", sorted(LAW_MIXES))
def test_random_trees_have_the_chains_accelerations_forces_and_v(mix, rng):
    """At random reduced states of random trees (permanent, free and visco-elastic joints,
    body feedback, clipped joint torques, gravity), the maximal image of the state has, in
    rbstab's chain, the reference's body accelerations, Lambda_j of every joint, the terms of
    v and dv/dt (the chain's F_j' Lambda_j is 0 there)."""
    for _ in range(3):
        tree = _random_tree(rng, LAW_MIXES[mix])
        compiled = C.compile_chain(_chain(tree), offset=0.0)
        n = tree.size
        for _ in range(4):
            y = _random_state(rng, tree)
            y12 = T.maximal_state(tree, y)
            np.testing.assert_allclose(T.reduced_state(tree, y12), y, atol=1e-13)
            dy, joints, scalars = np.empty(compiled.n_states), np.empty((n, 7, 3)), np.empty(5)
            bodies = np.empty((n, 3))
            C.chain_core(0.0, y12, *compiled.args, dy, joints, bodies, scalars)
            ev = T.evaluate(tree, y)
            theirs = dy[:12 * n].reshape(n, 4, 3)
            scale = np.abs(theirs).max()
            np.testing.assert_allclose(ev.omega_dot, theirs[:, 1], atol=1e-12 * scale)
            np.testing.assert_allclose(ev.v_dot, theirs[:, 3], atol=1e-12 * scale)
            np.testing.assert_allclose(ev.lam, joints[:, 2], atol=1e-12 * (1 + np.abs(ev.lam).max()))
            np.testing.assert_allclose(ev.forces.n_j, joints[:, 3], atol=1e-12 * (1 + np.abs(ev.forces.n_j).max()))
            np.testing.assert_allclose(ev.forces.e, joints[:, 0], atol=1e-13)  # E_j: 0 where permanent
            np.testing.assert_allclose(ev.forces.f, joints[:, 1], atol=1e-12)  # F_j: 0 where permanent
            terms, rate = T.lyapunov(tree, y)
            np.testing.assert_allclose(terms, scalars[:4], atol=1e-12 * (1 + np.abs(scalars[:4]).max()))
            assert rate == pytest.approx(scalars[4], rel=1e-11, abs=1e-11)


def _jointed_tree(rng, laws):
    """A random tree of ``laws`` (hinges and slides along random axes, balls, free and
    visco-elastic joints; body feedback, clipped joint torques, gravity) whose hinges, slides
    and balls have stops on their coordinates, narrow enough that random states press them."""
    tree = _random_tree(rng, [T.PERMANENT if law in T.COORDINATES else law for law in laws])
    joints = []
    for joint, law in zip(tree.joints, laws):
        n = T.COORDINATES.get(law, 3)
        stop = (-rng.uniform(0.05, 0.3, n), rng.uniform(0.05, 0.3, n), rng.uniform(50.0, 200.0, n),
                rng.uniform(0.0, 5.0, n)) if law in (*T.COORDINATES, T.PERMANENT) else None
        axis, axis_2 = rng.normal(size=3), rng.normal(size=3)
        joints.append(dataclasses.replace(
            joint, law=law, stop=stop, axis=axis / np.linalg.norm(axis) if law in T.COORDINATES else None,
            axis_2=axis_2 / np.linalg.norm(axis_2) if law == T.UNIVERSAL else None))
    return dataclasses.replace(tree, joints=tuple(joints))


def _jointed_chain(tree):
    """rbstab's chain of a tree of :func:`_jointed_tree`: a hinge its gains about its axis, a
    slide's along it, a universal joint's per coordinate."""
    single = (T.HINGE, T.SLIDE)
    chain = _chain(dataclasses.replace(tree, joints=tuple(dataclasses.replace(j, law=T.PERMANENT)
                                                          if j.law in T.COORDINATES else j for j in tree.joints)))
    joints = []
    for i, (joint, mine) in enumerate(zip(tree.joints, chain.joints)):
        stop = None if joint.stop is None else Stop(*(x if joint.law not in single else float(x[0])
                                                      for x in joint.stop))
        if joint.law == T.UNIVERSAL:  # its numbers per coordinate, entries 0-1 of the stop's 3-vectors
            stop = Stop(*(np.append(x, fill) for x, fill in zip(joint.stop, (-np.inf, np.inf, 0.0, 0.0))))
            limit = None if joint.torque_limit is None else (-joint.torque_limit[:2], joint.torque_limit[:2])
            joints.append(universal(mine.name, joint.parent, i, joint.parent_point, joint.child_point,
                                    (joint.axis, joint.axis_2), np.diag(joint.k_r)[:2], np.diag(joint.l_r)[:2],
                                    limits=limit, stop=stop))
        elif joint.law in single:
            limit = None if joint.torque_limit is None else (-float(joint.torque_limit[0]),
                                                             float(joint.torque_limit[0]))
            joints.append((hinge if joint.law == T.HINGE else slide)(
                mine.name, joint.parent, i, joint.parent_point, joint.child_point, joint.axis, float(joint.k_r[0, 0]),
                float(joint.l_r[0, 0]), limits=limit, stop=stop))
        else:
            joints.append(dataclasses.replace(mine, stop=stop))
    return dataclasses.replace(chain, joints=tuple(joints))


@pytest.mark.parametrize("laws", [[T.HINGE] * 4, [T.HINGE, T.PERMANENT, T.HINGE, T.FREE],
                                  [T.FREE, T.HINGE, T.VISCO_ELASTIC, T.PERMANENT],
                                  [T.SLIDE, T.HINGE, T.SLIDE, T.PERMANENT], [T.FREE, T.SLIDE, T.VISCO_ELASTIC, T.SLIDE],
                                  [T.UNIVERSAL, T.SLIDE, T.UNIVERSAL, T.HINGE], [T.FREE, T.UNIVERSAL, T.PERMANENT,
                                                                                 T.UNIVERSAL],
                                  [T.BALL, T.HINGE, T.BALL, T.SLIDE], [T.FREE, T.BALL, T.UNIVERSAL, T.BALL]],
                         ids=["hinges", "mixed", "free_root", "slides", "free_slides", "universal", "free_universal",
                              "balls", "free_balls"])
def test_random_trees_of_hinges_balls_and_stops_have_the_references_rate_and_v(laws, rng):
    """At random reduced states of random trees of hinges and slides (random axes), balls,
    free and visco-elastic joints, the hinges, slides and balls pressing their stops (a ball's
    on each Euler angle, N_s = B' f), rbstab's reduced-coordinate rate (tree_rate) is the
    plain-numpy reference's to 1e-11 (1e-8 with quaternion balls, whose reference torque is the
    central difference of their spring's potential), with its joint torques, a slide's force,
    the terms of v and every placed joint's reaction, and its maximal image is the reference's."""
    from rbstab.variants.tree import expand_state, reduce_state, tree_layout, tree_rate, tree_reactions, tree_work

    tol = 1e-8 if T.BALL in laws else 1e-11  # the reference's ball torque: a central difference of its potential
    for _ in range(3):
        tree = _jointed_tree(rng, laws)
        compiled = C.compile_chain(_jointed_chain(tree), offset=0.0)
        layout = tree_layout(compiled)
        starts, size = T.state_blocks(tree)
        assert layout.n_r == size and list(layout.r_at) == starts
        pressed = 0
        for _ in range(4):
            y = rng.normal(scale=0.3, size=size)
            for i, s in enumerate(starts):  # angular rates of 2 rad/s (a slide's 2 m/s)
                if tree.single(i):
                    m = tree.m(i)
                    y[s + m: s + 2 * m] = rng.normal(scale=2.0, size=m)
                elif tree.joints[i].law == T.BALL:  # a unit quaternion (w > 0), turned up to ~1 rad
                    quaternion = np.array([1.0, *rng.normal(scale=0.3, size=3)])
                    y[s: s + 4] = quaternion / np.linalg.norm(quaternion)
                    y[s + 4: s + 7] = rng.normal(scale=2.0, size=3)
                else:
                    y[s + 3: s + 6] = rng.normal(scale=2.0, size=3)
            ev = T.evaluate(tree, y)
            work = tree_work(compiled.size, compiled.n_states)
            dy = np.empty(size)
            tree_rate(0.0, y, *compiled.args, *layout.args, dy, work)
            np.testing.assert_allclose(dy, ev.dy, rtol=0, atol=tol * np.abs(ev.dy).max())
            n_j = work.chain.joints[:, 3]
            np.testing.assert_allclose(n_j, ev.forces.n_j, rtol=0, atol=tol * (1 + np.abs(ev.forces.n_j).max()))
            slides = [i for i in range(tree.size) if tree.slide(i)]  # a slide's force at C
            np.testing.assert_allclose(work.chain.joints[slides, 2], ev.forces.lam[slides], rtol=0,
                                       atol=tol * (1 + np.abs(ev.forces.lam).max()))
            out, fixed = np.full((tree.size, 3), 7.0), compiled.permanent  # every placed joint's whole reaction
            tree_reactions(0.0, y, *compiled.args, *layout.args, np.empty(size + 1), work, np.empty((tree.size, 6)),
                           out, np.empty((tree.size, 3)))
            np.testing.assert_allclose(out[fixed], ev.lam[fixed], rtol=0, atol=tol * (1 + np.abs(ev.lam).max()))
            maximal = T.maximal_state(tree, y)
            np.testing.assert_allclose(expand_state(compiled, layout, y), maximal, rtol=0, atol=1e-13)
            np.testing.assert_allclose(reduce_state(compiled, layout, maximal), y, rtol=0, atol=1e-12)
            terms, _ = T.lyapunov(tree, y)
            scalars = work.chain.scalars[:4]
            np.testing.assert_allclose(scalars, terms, rtol=0, atol=tol * (1 + np.abs(terms).max()))
            pressed += sum(T.stop_terms(j, *T.coordinates(tree, ev, k))[1] > 0 for k, j in enumerate(tree.joints))
        assert pressed > 0  # the stops act


def test_a_push_in_reduced_coordinates_is_the_chains_push():
    """M du = J_P' P: the velocities just after a push on the trunk, the kinetic energy's jump
    and the joints' impulsive reactions are those of the chain's push (the stacked eq 15 with
    the impulse); the ankle's reaction takes the push's momentum less the bodies'."""
    tree = _stance_tree()
    y = np.array([0.05, -0.02, 0.1, 0.4, -0.3, 0.5, -0.1, 0.04, 0.1, -0.6, 0.5, 1.2])
    point, impulse = np.array([0.05, -0.1, 0.2]), np.array([12.0, -30.0, 5.0])
    after, reactions = T.push(tree, y, 1, point, impulse)
    compiled = C.compile_chain(_chain(tree), offset=0.0)
    y12 = T.maximal_state(tree, y)
    pushed = y12.copy()
    work = C.chain_work(2)
    jump = C.chain_push_with(pushed, *compiled.args[:4], 1, point, impulse, False, work)
    np.testing.assert_allclose(T.maximal_state(tree, after), pushed, atol=1e-12)
    kinetic = [sum(T.lyapunov(tree, s)[0][:2]) for s in (y, after)]  # the configuration does not move
    assert kinetic[1] - kinetic[0] == pytest.approx(jump, rel=1e-11)
    np.testing.assert_allclose(reactions, work.joints[:, 2], atol=1e-11 * np.abs(reactions).max())
    masses = np.array([b.mass for b in tree.bodies])
    momentum_jump = masses @ (pushed.reshape(2, 4, 3)[:, 3] - y12.reshape(2, 4, 3)[:, 3])
    np.testing.assert_allclose(momentum_jump, impulse + reactions[0], atol=1e-11 * np.abs(impulse).max())
    assert np.array_equal(rotation(after[:3]), rotation(y[:3]))  # the configuration does not move


def test_the_joint_kind_table_gives_each_law_its_reduced_coordinates():
    """Each joint law's kind (docs/physics.md, "Joint kinds"): ``permanent`` is the ball,
    whose child is carried by eq 21's reduced states (Theta_j, Omega_j: the one-body
    ``permanent`` layout) with its point held; the four point laws pull a free body (its 12
    body states, the one-body layouts less D); the hinge holds its point and has one angle
    and its rate, the universal joint two, the quaternion ball 4 coordinates and 3 velocities,
    the slide one displacement and its rate. The sizes a tree's layout reads from the table are checked against the
    reference in test_the_compiled_reduced_rate_is_the_references."""
    from rbstab.layout import JOINT_CODES, JOINT_KIND_OF, JOINT_KINDS, REDUCED_STATES, VARIANT_LAYOUTS, VELOCITIES, \
        point_fixed

    assert set(JOINT_KIND_OF) == set(VARIANT_LAYOUTS) | {"hinge", "universal", "ball", "slide"}
    assert set(JOINT_KIND_OF.values()) == set(JOINT_KINDS)
    for law, layout in VARIANT_LAYOUTS.items():
        kind = JOINT_KINDS[JOINT_KIND_OF[law]]
        assert kind.point_fixed == point_fixed(law) == (law == "permanent")
        assert kind.size == layout.size - (3 if "controller_state" in layout.blocks else 0)
        assert JOINT_CODES[law] == list(VARIANT_LAYOUTS).index(law)
    hinge = JOINT_KINDS["hinge"]
    assert (hinge.n_q, hinge.n_v, hinge.point_fixed, point_fixed("hinge")) == (1, 1, True, True)
    assert (REDUCED_STATES[JOINT_CODES["hinge"]], VELOCITIES[JOINT_CODES["hinge"]]) == (2, 1)
    universal = JOINT_KINDS["universal"]
    assert (universal.n_q, universal.n_v, universal.point_fixed, point_fixed("universal")) == (2, 2, True, True)
    assert (REDUCED_STATES[JOINT_CODES["universal"]], VELOCITIES[JOINT_CODES["universal"]]) == (4, 2)
    ball = JOINT_KINDS["ball"]  # the quaternion ball: 4 coordinates, 3 velocities
    assert (ball.n_q, ball.n_v, ball.point_fixed, point_fixed("ball")) == (4, 3, True, True)
    assert (REDUCED_STATES[JOINT_CODES["ball"]], VELOCITIES[JOINT_CODES["ball"]]) == (7, 3)
    slide = JOINT_KINDS["slide"]  # a translation along its axis, placed from its parent by q
    assert (slide.n_q, slide.n_v, slide.point_fixed, point_fixed("slide")) == (1, 1, True, True)
    assert (REDUCED_STATES[JOINT_CODES["slide"]], VELOCITIES[JOINT_CODES["slide"]]) == (2, 1)
    assert not point_fixed("socket") and not point_fixed(None)


# -- the compiled reduced rate (rbstab.variants.tree) against the reference ------------------------------
@pytest.mark.parametrize("mix", sorted(LAW_MIXES))
def test_the_compiled_reduced_rate_is_the_references(mix, rng):
    """rbstab's compiled rate of a tree in reduced coordinates (no constraint force in it)
    equals the reference's at random states of random trees (permanent, free and
    visco-elastic joints, body feedback, clipped joint torques, gravity), with the same
    terms of v; its maximal image is the reference's, and the chain's state reduces back."""
    from rbstab.variants import tree as R

    for _ in range(3):
        tree = _random_tree(rng, LAW_MIXES[mix])
        compiled = C.compile_chain(_chain(tree), offset=0.0)
        layout = R.tree_layout(compiled)
        assert layout.n_r == T.state_blocks(tree)[1] and layout.n_u == T.velocity_blocks(tree)[1]
        work = R.tree_work(tree.size, compiled.n_states)
        for _ in range(4):
            y = _random_state(rng, tree)
            dyr = np.empty(layout.n_r)
            R.tree_rate(0.0, y, *compiled.args, *layout.args, dyr, work)
            ev = T.evaluate(tree, y)
            np.testing.assert_allclose(dyr, ev.dy, rtol=0, atol=1e-12 * np.abs(ev.dy).max())
            maximal = T.maximal_state(tree, y)
            np.testing.assert_allclose(R.expand_state(compiled, layout, y), maximal, rtol=0, atol=1e-14)
            np.testing.assert_allclose(R.reduce_state(compiled, layout, maximal), y, rtol=0, atol=1e-13)
            terms, _ = T.lyapunov(tree, y)
            np.testing.assert_allclose(work.chain.scalars[:4], terms, rtol=0, atol=1e-12 * (1 + np.abs(terms).max()))


@pytest.mark.parametrize("mix", sorted(LAW_MIXES))
def test_reactions_from_the_reduced_motion_are_the_references(mix, rng):
    """A point-fixed joint's Lambda_j recovered from the reduced rate (every body's
    acceleration, Newton's law on the bodies it carries, leaves first) equals the reference's
    (the stacked eq 15 solved for the constraint forces) at random states of random trees;
    the rows of the other joints are left as they were."""
    from rbstab.variants import tree as R

    for _ in range(3):
        tree = _random_tree(rng, LAW_MIXES[mix])
        compiled = C.compile_chain(_chain(tree), offset=0.0)
        layout = R.tree_layout(compiled)
        work, fixed = R.tree_work(tree.size, compiled.n_states), compiled.permanent
        for _ in range(4):
            y = _random_state(rng, tree)
            out = np.full((tree.size, 3), 7.0)
            R.tree_reactions(0.0, y, *compiled.args, *layout.args, np.empty(layout.n_r + 1), work,
                             np.empty((tree.size, 6)), out, np.empty((tree.size, 3)))
            ev = T.evaluate(tree, y)
            np.testing.assert_allclose(out[fixed], ev.lam[fixed], rtol=0, atol=1e-11 * (1 + np.abs(ev.lam).max()))
            assert np.all(out[~fixed] == 7.0)


@pytest.mark.parametrize("path", [EXAMPLES / "stance_ankle.yaml", ROOT / "configs" / "paper" / "case1_permanent.yaml"],
                         ids=["stance_ankle", "case1_permanent"])
def test_the_compiled_reduced_rate_of_one_permanent_body_is_the_papers(path, rng):
    """A one-body tree on a permanent joint, in reduced coordinates, has the rate of rbstab's
    ``permanent`` variant (eq 21's 6 states) at random states."""
    from rbstab.variants import tree as R

    config = _load(path)
    variant = VARIANTS[config.chain.joints[0].variant](paper_form(config).body, paper_form(config).gains)
    compiled = C.compile_chain(config.chain, offset=0.0)
    layout = R.tree_layout(compiled)
    assert layout.n_r == 6
    work = R.tree_work(1, compiled.n_states)
    for _ in range(20):
        y = np.concatenate([rng.normal(scale=0.3, size=3), rng.normal(scale=2.0, size=3)])
        dyr = np.empty(6)
        R.tree_rate(0.0, y, *compiled.args, *layout.args, dyr, work)
        expected = variant.rhs(0.0, y)
        np.testing.assert_allclose(dyr, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def _maximal_run(compiled, y0, sim, at=None):
    """The maximal-coordinate chain (the stacked eq 15, :func:`rbstab.variants.chain.chain_rate`)
    integrated by solve_ivp at ``sim``'s tolerances on its sample grid, with the chain's
    impulses applied at ``at`` [s] (the sample there shows the state after them): (samples
    (n_samples, n_states), the impulses' energy [J])."""
    from scipy.integrate import solve_ivp

    time = np.linspace(0.0, sim.t_end, sim.n_samples)
    dy = np.empty(compiled.n_states)

    def rhs(t, y):
        C.chain_rate(t, y, *compiled.args, dy)
        return dy.copy()

    edges = [0.0, sim.t_end] if at is None else [0.0, at, sim.t_end]
    y, out, jump = y0.copy(), np.empty((time.size, y0.size)), 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        if a > 0.0:  # every impulse that starts at a, one after the other, on the maximal state
            for i, p in enumerate(compiled.params):
                for k in range(int(p["disturbance_count"])):
                    if p["disturbance_kind"][k] == IMPULSE and p["disturbance_start"][k] == a:
                        jump += C.chain_push(y, *compiled.args[:4], i, p["disturbance_point"][k],
                                             p["disturbance_value"][k], bool(p["disturbance_torque"][k]))
        rows = np.flatnonzero((time >= a) & ((time < b) if b < sim.t_end else (time <= b)))
        t_eval = time[rows] if b == sim.t_end else np.append(time[rows], b)
        sol = solve_ivp(rhs, (a, b), y, method=sim.method, t_eval=t_eval, rtol=sim.rtol, atol=sim.atol)
        out[rows] = sol.y[:, : rows.size].T
        y = sol.y[:, -1].copy()
    return out, jump


@pytest.mark.parametrize("start", sorted(STARTS))
def test_the_compiled_driver_integrates_the_reduced_tree_as_the_maximal_chain(start):
    """The compiled driver on the stance double pendulum in reduced coordinates (its system
    a TreeSystem) follows the maximal-coordinate chain (the stacked eq 15, integrated by
    solve_ivp) to the solver's tolerance, with its joints held to rounding (E_j of the
    samples' maximal image ~1e-16 m); with an impulse on the trunk both take the same jump,
    and the disturbances' work W is the jump's energy."""
    from rbstab.engine.integrate import integrate_chain_runs
    from rbstab.engine.settings import settings_rows
    from rbstab.engine.systems import tree_system
    from rbstab.variants import tree as R

    impulse = ["disturbances=[{kind: impulse, body: trunk, value: [0, 20, 0], point: [0, 0, 0.2], start: 0.5}]"]
    for extra in ([], impulse):
        config = _load(STANCE, ["simulation.t_end=2.0", "simulation.n_samples=41", "simulation.rtol=1e-10",
                                "simulation.atol=1e-12", *STARTS[start], *extra])
        compiled = C.compile_chain(config.chain)
        layout = R.tree_layout(compiled)
        y0 = C.initial_state(config)
        rows = settings_rows([config.simulation])
        rows[:, 6] = np.inf
        sim = config.simulation
        a, jump = _maximal_run(compiled, y0, sim, 0.5 if extra else None)
        reduced = integrate_chain_runs(tree_system(compiled, sim.limits),
                                       R.reduce_state(compiled, layout, y0)[None], rows, method=sim.method,
                                       n_samples=sim.n_samples)
        assert reduced.status[0] == 0
        b = reduced.samples[0].reshape(41, -1)
        bodies = [slice(12 * i, 12 * i + 12) for i in range(2)]
        for s in bodies:
            np.testing.assert_allclose(b[:, s], a[:, s], rtol=0, atol=1e-7)
        assert np.ptp(a[:, 6:9], axis=0).max() > 0.01  # it moves
        n = compiled.size
        for row in b:
            joints = np.empty((n, 7, 3))
            C.chain_core(0.0, row, *compiled.args, np.empty(compiled.n_states), joints, np.empty((n, 3)),
                         np.empty(5))
            assert np.abs(joints[:, 0]).max() < 1e-14  # E_j: held by construction
        assert reduced.work[0, -1] == pytest.approx(jump, rel=1e-9, abs=1e-12)
        if extra:
            assert np.abs(reduced.work[0, -1]) > 1.0  # the push did work
