"""The verified sublevel bound (``rbstab analyze --verify``): never contradicted by states
inside it (dv/dt <= 0 at 10,000 of them, recovery of the runs from the outermost), below
the closed-form level of a second rest point and refused above it, refused with its reason
on what it does not cover, and the CLI flag end to end."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import ROOT

pytest.importorskip("flint")

from rbstab.variants.paper import paper_form
from rbstab.analysis import NotVerifiable, Verification, read_analysis, verify_sublevel  # noqa: E402
from rbstab.analysis.push import runs_from_states  # noqa: E402
from rbstab.analysis.verify import DEFAULT_RTOL, potential  # noqa: E402
from rbstab.config import load_config  # noqa: E402
from rbstab_cli.main import cli  # noqa: E402

PENDULUM = ROOT / "configs/examples/saturated_pendulum.yaml"
STANCE = ROOT / "configs/examples/stance_ankle.yaml"


@pytest.fixture(scope="module", params=[PENDULUM, STANCE], ids=["pendulum", "stance"])
def verified(request):
    config = load_config(request.param)
    return config, verify_sublevel(config)


def _inside(variant, level: float, n: int, seed: int) -> np.ndarray:
    """n states with v <= level, the outermost of 4 n drawn uniformly in the ellipsoid
    0.5 dy' H dy <= 1.3 level of v's Hessian H at the equilibrium."""
    from rbstab.analysis.derivatives import hessian

    y_e = np.asarray(variant.equilibrium, dtype=float)
    hess = hessian(lambda y: variant.lyapunov(y), y_e)[0]
    vals, vecs = np.linalg.eigh(0.5 * (hess + hess.T))
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(4 * n, 6))
    z *= (rng.random(4 * n) ** (1 / 6) / np.linalg.norm(z, axis=1))[:, None]
    y = y_e + (z * np.sqrt(2.6 * level / vals)) @ vecs.T
    v = variant.lyapunov(y)
    y, v = y[v <= level], v[v <= level]
    assert len(y) >= n, "too few samples inside the verified set"
    return y[np.argsort(v)[::-1][:n]]


def test_verified_level_is_never_contradicted(verified):
    config, result = verified
    assert isinstance(result, Verification) and result.level > 0 and result.boxes > 0
    variant = paper_form(config)
    y = _inside(variant, result.level, 10_000, seed=1)
    # dv/dt at every state: the analytic rate and the rate of v along the right-hand side
    rate = variant.evaluate(y)["lyapunov_rate"]
    f = variant.rhs(0.0, y)
    h = 1e-7 / np.maximum(np.linalg.norm(f, axis=1), 1.0)[:, None]
    numeric = (variant.lyapunov(y + h * f) - variant.lyapunov(y - h * f)) / (2 * h[:, 0])
    scale = 1e-9 * (1.0 + np.abs(rate)) + 1e-12
    assert np.all(rate <= scale), f"dv/dt > 0 inside the verified set: {rate.max():g} W"
    assert np.all(numeric <= 1e-5 * (1.0 + np.abs(rate))), f"numerical dv/dt > 0: {numeric.max():g} W"
    # the runs from the 200 outermost states recover (inside the domain, v ends below its start)
    from rbstab.variants import chain as C

    full = C.full_state(C.compile_chain(config.chain), y[:200])  # one body's coordinates are its own state
    ok, v0, v1 = runs_from_states(config, full)
    assert np.all(ok == 1) and np.all(v1 < 0.5 * v0), "a run from inside the verified set did not recover"


def test_potential_is_v_at_rest(verified):
    """P(Theta) of the interval kernel is the variant's v at Omega = 0 (same constant h)."""
    config, _ = verified
    variant = paper_form(config)
    theta = np.random.default_rng(3).normal(scale=0.4, size=(20, 3))
    v = variant.lyapunov(np.hstack([theta, np.zeros((20, 3))]))
    p = [potential(config, t) for t in theta]
    assert np.allclose(p, v, rtol=1e-12, atol=1e-12 * np.abs(v).max())


def test_verified_level_is_near_the_checked_estimate(verified):
    config, result = verified
    # the sufficient condition's onset: the static torque K_r theta reaching the limit about a tilt axis
    # (the equilibrium at 0, theta along axis 1): P there is the closed form's least failing level
    p = paper_form(config).parameters[0]
    k, limit = float(p["k_r"][0, 0]), float(p["torque_limit"][0])
    onset = potential(config, np.array([limit / k, 0.0, 0.0]))
    assert result.level <= onset
    assert result.level >= 0.97 * onset, (result.level, onset)


@pytest.mark.parametrize("path", [PENDULUM, STANCE], ids=["pendulum", "stance"])
def test_refused_at_a_level_holding_a_second_rest_point(path):
    """At rest at theta* = arcsin(limit / (m g L)) the clipped torque holds the body against
    gravity: a rest point other than the equilibrium, which a level P(theta*) contains."""
    config = load_config(path)
    p = paper_form(config).parameters[0]
    mgl = float(p["mass"]) * 9.81 * float(-p["attachment_point"][2])
    theta_s = math.asin(float(p["torque_limit"][0]) / mgl)
    rest = np.array([theta_s, 0, 0, 0, 0, 0.0])
    assert np.abs(paper_form(config).rhs(0.0, rest)).max() < 1e-9 * mgl  # it is a rest point
    level = potential(config, rest[:3])
    assert verify_sublevel(config).level < level
    with pytest.raises(NotVerifiable, match="not proven: box theta in .*reaches its limit"):
        verify_sublevel(config, level=level)


def test_unlimited_body_is_bounded_by_the_domain():
    """Without limits (K_r > m g L: no other rest point) only the gimbal-lock margin bounds c."""
    config = load_config(PENDULUM, ["controller.saturation=null"])
    result = verify_sublevel(config)
    margin = np.pi / 2 - config.simulation.gimbal_margin
    face = min(potential(config, np.array([0.0, s * margin, 0.0])) for s in (-1, 1))
    assert "domain boundary |theta_2|" in result.reason
    assert 0.97 * face <= result.level <= face


@pytest.mark.parametrize("override, key", [
    ("controller.saturation.shape=smooth", "controller.saturation.shape"),
    ("controller.l_r=[[10,1,0],[1,10,0],[0,0,2]]", "controller.l_r"),
])
def test_refused_where_not_covered(override, key):
    config = load_config(PENDULUM, [override])
    with pytest.raises(NotVerifiable, match=key):
        verify_sublevel(config)


def test_refused_for_a_variant_on_more_states():
    config = load_config(ROOT / "configs/paper/case2_visco_elastic.yaml")
    with pytest.raises(NotVerifiable, match="controller.variant"):
        verify_sublevel(config)


def test_cli_verify(tmp_path):
    runner = CliRunner()
    result = runner.invoke(cli, ["analyze", str(PENDULUM), "--verify", "--no-simulation", "--samples", "400",
                                 "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "verified c = " in result.output and "interval arithmetic" in result.output
    ds = read_analysis(tmp_path / "saturated_pendulum.analysis.nc")
    level = float(ds["sublevel_verified"])
    assert level > 0 and "reaches its limit" in ds.attrs["sublevel_verified_reason"]
    report = runner.invoke(cli, ["report", str(tmp_path), "-o", str(tmp_path / "r"), "--format", "md"],
                           catch_exceptions=False)
    assert report.exit_code == 0, report.output
    text = "\n".join(p.read_text() for p in (tmp_path / "r").rglob("*.md"))
    assert "verified c of {v <= c}" in text and "reaches its limit 4 N m" in text
    refused = runner.invoke(cli, ["analyze", str(PENDULUM), "--verify", "--set", "controller.saturation.shape=smooth",
                                  "-o", str(tmp_path / "no")])
    assert refused.exit_code != 0
    assert "controller.saturation.shape" in refused.output and "Traceback" not in refused.output
    assert len(refused.output.strip().splitlines()) == 1
    assert not (tmp_path / "no").exists()


def test_spec_verify_draws_a_bound_below_every_threshold(tmp_path):
    """A spec over the ankle's torque limit with --verify: at each point the push the verified
    set holds lies below the smallest fatal push, and the report's recovery figure draws it."""
    spec = tmp_path / "spec.yaml"
    spec.write_text(f"name: limits\nbase: {STANCE}\ngrid:\n  controller.saturation.torque_n.0: [120, 180]\n")
    out = tmp_path / "analysis"
    runner = CliRunner()
    result = runner.invoke(cli, ["analyze", str(spec), "-o", str(out), "--push-tol", "1e-2", "-j", "1", "--samples",
                                 "300", "--push", "force", "--push-direction=0,-1,0", "--push-point", "0,0,0.3",
                                 "--verify"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    ds = read_analysis(out / "limits.recovery.analysis.nc")
    verified, fatal = ds["push_verified"].values, ds["push_minimum"].values
    assert np.all(np.isfinite(verified)) and np.all(verified < fatal)
    assert np.all(ds["sublevel_verified"].values <= ds["sublevel"].values * 1.001)
    assert np.diff(ds["sublevel_verified"].values)[0] > 0  # a larger limit, a larger proven set
    report = runner.invoke(cli, ["report", str(out / "limits.recovery.analysis.nc"), "-o", str(tmp_path / "r"),
                                 "--format", "md"], catch_exceptions=False)
    assert report.exit_code == 0, report.output
    text = "\n".join(p.read_text() for p in (tmp_path / "r").rglob("*.md"))
    assert "below the simulated threshold at every point" in text and "verified set" in text



def test_tilted_equilibrium_with_translational_gains_reaches_the_domain_boundary():
    """Case 1 (permanent, K_t and L_t, gravity: a tilted equilibrium, no limits): only the
    gimbal-lock margin bounds c, and the proof comes within 3 % of the least v there that the
    certificate finds by Newton steps on the boundary (an independent computation)."""
    from rbstab.analysis import analyze

    path = ROOT / "configs/paper/case1_permanent.yaml"
    boundary = analyze(path, samples=200, simulate=False, falsification_runs=0).certificate.boundary_level
    result = verify_sublevel(path)
    assert "gimbal-lock margin" in result.reason
    assert 0.97 * boundary <= result.level <= boundary


def test_interval_enclosures_hold_the_model_at_every_point():
    """The arb kernel against the compiled model at points of random boxes (Case 1: a tilted
    equilibrium, K_t, all three axes coupled): v at rest in P(box); its gradient and Hessian
    (central differences of v) in the enclosures; the commanded torque at rest in tau(box)."""
    from flint import arb

    from rbstab.analysis.verify import _Model

    config = load_config(ROOT / "configs/paper/case1_permanent.yaml")
    variant = paper_form(config)
    p = variant.parameters[0]
    model = _Model(p, p["attachment_point"], p["lyapunov_offset"], arb)  # held at its own point: R_p = R_c
    rng = np.random.default_rng(5)

    def v_at(theta):
        return variant.lyapunov(np.hstack([np.atleast_2d(theta), np.zeros((len(np.atleast_2d(theta)), 3))]))

    def inside(ball, x, slack):
        return float(ball.lower()) - slack <= x <= float(ball.upper()) + slack

    h = 1e-4
    eye = np.eye(3) * h
    for _ in range(12):
        lo = rng.uniform(-1.0, 1.0, 3)
        hi = lo + rng.uniform(0.001, 0.005, 3)  # small: enclosures a few per cent wide, so a wrong term shows
        p_box, grad, tau, hess = model.evaluate(lo, hi, hessian=True)
        points = rng.uniform(lo, hi, (10, 3))
        command = variant.evaluate(np.hstack([points, np.zeros((10, 3))]))["torque_n"]
        for x, n in zip(points, command):
            v0 = float(v_at(x)[0])
            assert inside(p_box, v0, 1e-9 * (1 + abs(v0)))
            g = (v_at(x + eye) - v_at(x - eye)) / (2 * h)
            hs = np.array([(v_at(x + eye[a] + eye) - v_at(x + eye[a] - eye) - v_at(x - eye[a] + eye)
                            + v_at(x - eye[a] - eye)) / (4 * h * h) for a in range(3)])
            for a in range(3):
                assert inside(grad[a], g[a], 1e-4 * (1 + abs(g[a])))
                assert inside(tau[a], n[a], 1e-9 * (1 + abs(n[a])))
                for b in range(3):
                    assert inside(hess[a][b], hs[a, b], 1e-3 * (1 + abs(hs[a, b])))


def test_a_body_held_elsewhere_than_its_own_point_is_verified_as_its_translate():
    """One body on a permanent joint whose ground point R_p is not its own point R_c: with
    K_t = 0 the body is the one-body model moved by R_p - R_c, its potential the same up to
    the constant h takes away, so its proof gives the one-body model's level (to the search's
    tolerance; and that level itself is proven for it). With K_t != 0 (the ground-anchored
    spring is not moved with it) the level differs."""
    from conftest import tree_spelling

    from rbstab.config import config_from_mapping

    config = load_config(PENDULUM)
    tree = dict(tree_spelling(config).resolved)
    joint = dict(tree["joints"][0])
    joint["parent_point"] = [0.3, -0.2, 1.5]  # C held 0.3, -0.2, 1.5 m from the origin; R_c = (0, 0, -0.5)
    moved = config_from_mapping({**tree, "joints": [joint]})
    assert moved.chain.joints[0].parent_point.tolist() != moved.chain.joints[0].child_point.tolist()
    mine, theirs = verify_sublevel(moved), verify_sublevel(config)
    assert mine.level == pytest.approx(theirs.level, rel=DEFAULT_RTOL) and mine.level > 0
    assert verify_sublevel(moved, level=theirs.level).level == theirs.level
    bodies = [{**tree["bodies"][0], "k_t": [10.0, 10.0, 10.0]}]  # K_t X at rest: ~1.5 N m about C, under the 4 N m limit
    sprung = verify_sublevel(config_from_mapping({**tree, "bodies": bodies, "joints": [joint]}))
    anchored = verify_sublevel(config_from_mapping({**tree, "bodies": bodies}))
    assert sprung.level > 0 and abs(sprung.level - anchored.level) > 1e-3 * anchored.level



def test_a_reference_posture_moves_the_proven_set_with_it():
    """Without gravity and limits, v = 1/2 Omega' J Omega + 1/2 dTheta' K_r dTheta about the
    reference posture, so the largest proven level is the least P on the gimbal-lock face
    nearest the reference, 1/2 k_2 (pi/2 - gimbal_margin - |theta_ref_2|)^2 (diagonal K_r; 246 J
    without the reference),
    and the equilibrium is the reference itself."""
    from conftest import tree_spelling

    from rbstab.config import config_from_mapping

    tree = dict(tree_spelling(load_config(PENDULUM, ["controller.saturation=null"])).resolved)
    reference = [0.2, 0.3, -0.1]
    config = config_from_mapping({**tree, "gravity": [0.0, 0.0, 0.0],
                                  "joints": [{**tree["joints"][0], "theta_ref": reference}]})
    k_r = config.chain.joints[0].k_r
    assert not np.any(k_r - np.diag(np.diag(k_r)))
    k = np.diag(k_r)
    result = verify_sublevel(config)
    face = 0.5 * k[1] * (np.pi / 2 - config.simulation.gimbal_margin - reference[1]) ** 2
    assert 0.97 * face <= result.level <= face  # the search resolves the face to its box widths
    assert "domain boundary |theta_2|" in result.reason
    assert potential(config, np.array(reference)) == pytest.approx(0.0, abs=1e-12)


def test_a_passive_spring_adds_to_the_proven_potential():
    """Without gravity and limits the feedback's spring about Theta_ref and a passive spring
    about Theta_p sum to one spring K = K_r + K_p about c = K^-1 (K_r Theta_ref + K_p Theta_p)
    plus a constant that h removes: the proven level is the least of that sum on the nearest
    gimbal-lock face, 1/2 k_2 (pi/2 - gimbal_margin - c_2)^2 (diagonal springs)."""
    from conftest import tree_spelling

    from rbstab.config import config_from_mapping

    tree = dict(tree_spelling(load_config(PENDULUM, ["controller.saturation=null"])).resolved)
    reference, passive = [0.2, 0.3, -0.1], {"k_r": [100.0, 300.0, 20.0], "l_r": [1.0, 1.0, 1.0],
                                            "theta_ref": [0.0, -0.2, 0.1]}
    config = config_from_mapping({**tree, "gravity": [0.0, 0.0, 0.0],
                                  "joints": [{**tree["joints"][0], "theta_ref": reference, "passive": passive}]})
    k_r, k_p = np.diag(config.chain.joints[0].k_r), np.array(passive["k_r"])
    k = k_r + k_p
    centre = (k_r * reference + k_p * np.array(passive["theta_ref"])) / k
    result = verify_sublevel(config)
    face = 0.5 * k[1] * (np.pi / 2 - config.simulation.gimbal_margin - centre[1]) ** 2
    assert 0.97 * face <= result.level <= face
    assert potential(config, centre) == pytest.approx(0.0, abs=1e-9)


def test_a_verified_level_with_a_passive_spring_and_saturation_is_never_contradicted():
    """The saturated pendulum with a passive spring and damper and a reference posture (so
    the tree's kernels, not the paper's, run it): inside its proven level dv/dt <= 0 at
    every sampled state, and runs from the outermost ones recover."""
    from conftest import tree_spelling

    from rbstab.config import config_from_mapping
    from rbstab.variants import chain as C

    tree = dict(tree_spelling(load_config(PENDULUM)).resolved)
    passive = {"k_r": [20.0, 20.0, 5.0], "l_r": [2.0, 2.0, 0.5], "theta_ref": [0.02, 0.0, 0.0]}
    config = config_from_mapping({**tree, "joints": [{**tree["joints"][0], "theta_ref": [0.0, 0.02, 0.0],
                                                      "passive": passive}]})
    result = verify_sublevel(config)
    assert result.level > 0
    compiled = C.compile_chain(config.chain)
    assert not compiled.one_body
    rng = np.random.default_rng(4)
    rest = C.rest_state(compiled)[0][:3]
    j_p = np.diag(compiled.params[0]["pivot_inertia"])
    k = np.diag(compiled.params[0]["k_r"] + compiled.params[0]["passive_k_r"])
    half = np.sqrt(2.0 * result.level / np.concatenate([k, j_p]))  # about the level set on each axis
    z = np.concatenate([rest, np.zeros(3)]) + rng.uniform(-1.0, 1.0, size=(20_000, 6)) * half
    y = C.full_state(compiled, z)
    terms = np.array([C.lyapunov(compiled, row) for row in y])
    inside = terms[:, 0] <= result.level
    assert inside.sum() > 500 and (~inside).sum() > 500  # the box reaches past the level set
    rate = terms[inside, 1]
    assert np.all(rate <= 1e-9 * (1.0 + np.abs(rate))), f"dv/dt > 0 inside the verified set: {rate.max():g} W"
    outermost = y[inside][np.argsort(terms[inside, 0])[::-1][:100]]
    ok, v0, v1 = runs_from_states(config, outermost)
    assert np.all(ok == 1) and np.all(v1 < 0.5 * v0), "a run from inside the verified set did not recover"
