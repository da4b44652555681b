"""The 3D animation of a run (``rbstab animate``, the animations of ``rbstab report``).

Geometry against an independent construction: A(Theta) = Rx Ry Rz written out here,
C = X + A R against the drawn C and the stored E, the box's edges against the columns of A
and the uniform box's moments; a few frames of each variant drawn at a low resolution;
the CLI end to end on short runs (0.5 s, 201 samples).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import PAPER_CONFIGS, ROOT
from rbstab.report.animate import (
    DPI,
    FPS,
    SPEED,
    FrameRenderer,
    body_shape,
    box_corners,
    box_sides,
    pick_run,
    playback_frames,
    scene,
    write_still,
)
from rbstab.report.build import ANIMATION_FRAMES, ANIMATION_FRAMES_RANGE
from rbstab_cli import animate as animate_cli
from rbstab_cli import report as report_cli
from rbstab_cli.main import cli

SHORT = ["--set", "simulation.n_samples=201", "--set", "simulation.t_end=0.5"]
EXAMPLES = [ROOT / "configs" / "examples" / f"{n}.yaml" for n in ("free_gravity", "sliding")]
VARIANTS = {"case1_permanent": "permanent", "case2_visco_elastic": "visco_elastic", "case3_embedded": "embedded",
            "free_gravity": "free", "sliding": "sliding"}
STORE = ROOT / "tests" / "data" / "store_file_6596935.h5"


def _invoke(*args, env=None):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=True, env=env)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """One short run of each variant, and a run that fails (gimbal lock) after a few samples."""
    out = tmp_path_factory.mktemp("runs")
    result = _invoke("run", *PAPER_CONFIGS, *EXAMPLES, "-o", out, *SHORT)
    assert result.exit_code == 0, result.output
    failed = _invoke("run", PAPER_CONFIGS[1], "-o", out, "--set", "simulation.n_samples=2001", "--set",
                     "simulation.t_end=0.5", "--set", "initial_state.theta=[0, 1.5, 0]",
                     "--set", "initial_state.omega=[0, 32, 0]", "--set", "name=gimbal")
    assert failed.exit_code == 0 and "failed, fell (" in failed.output and "gimbal lock" in failed.output, \
        failed.output  # a fall is a result
    files = {p.stem: p for p in out.glob("*.h5")}
    assert set(files) == {*VARIANTS, "gimbal"}
    return files


def _rotation(theta: np.ndarray) -> np.ndarray:
    """A = Rx(t1) Ry(t2) Rz(t3) (eq 2), written out independently of rbstab.kinematics."""
    c, s = np.cos(theta), np.sin(theta)
    one, zero = np.ones(len(theta)), np.zeros(len(theta))
    rx = np.stack([[one, zero, zero], [zero, c[:, 0], -s[:, 0]], [zero, s[:, 0], c[:, 0]]]).transpose(2, 0, 1)
    ry = np.stack([[c[:, 1], zero, s[:, 1]], [zero, one, zero], [-s[:, 1], zero, c[:, 1]]]).transpose(2, 0, 1)
    rz = np.stack([[c[:, 2], -s[:, 2], zero], [s[:, 2], c[:, 2], zero], [zero, zero, one]]).transpose(2, 0, 1)
    return rx @ ry @ rz


def _drawn(renderer: FrameRenderer, k: int) -> dict[str, np.ndarray]:
    """Where frame k draws one body's C, its anchor-to-C segment, its COM and its axes (the
    artists draw every body's: one here)."""
    art = renderer.artists
    art.update(k)
    segment = np.array(art.error.get_data_3d()).T[:2]  # (2, 3): anchor, C (then a NaN row between segments)
    axes = np.array([np.array(line.get_data_3d()).T[1] - np.array(line.get_data_3d()).T[0] for line in art.axes])
    return {"c": np.array(art.joints.get_data_3d()).T[0], "segment": segment,
            "com": np.array(art.coms.get_data_3d()).ravel(), "axes": axes.T}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_drawn_c_is_x_plus_a_r_and_the_drawn_segment_is_the_stored_e_at_every_frame(runs, name):
    run = pick_run(runs[name])
    assert run.variant == VARIANTS[name]
    s = run.series("theta", "position", "constraint_error", "omega")
    r = np.asarray(run.config["body"]["attachment_point"], dtype=float)
    sc = scene(run, n_frames=11)  # frame k at sample 20 k: the stored states themselves
    samples = np.abs(s["time"][:, None] - sc.time).argmin(axis=0)
    np.testing.assert_allclose(s["time"][samples], sc.time, rtol=0, atol=1e-12)
    renderer = FrameRenderer(sc, dpi=40)
    a = _rotation(s["theta"][samples])
    scale = 1.0 + np.abs(s["position"]).max()
    for k, i in enumerate(samples):
        drawn = _drawn(renderer, k)
        c = s["position"][i] + a[k] @ r
        np.testing.assert_allclose(drawn["c"], c, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(drawn["segment"][1] - drawn["segment"][0], s["constraint_error"][i],
                                   rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(drawn["segment"][0], r, rtol=0, atol=0)  # the anchor: R, where E = 0
        np.testing.assert_allclose(drawn["com"], s["position"][i], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(drawn["axes"] / renderer.artists.length, a[k], rtol=0, atol=1e-12)
    # between the samples: the drawn segment is the interpolated stored E, and X (from eq 4) is off
    # the linear interpolation of X by that of A R, at most dt^2/8 (|dOmega/dt| + |Omega|^2) |R|
    between = scene(run, n_frames=37)
    np.testing.assert_allclose(between.point_c[:, 0] - between.anchor, between.constraint_error, rtol=0,
                               atol=1e-12 * scale)
    dt = float(np.diff(s["time"]).max())
    omega = np.linalg.norm(s["omega"], axis=1)
    omega_dot = np.linalg.norm(np.diff(s["omega"], axis=0), axis=1) / np.diff(s["time"])
    bound = dt**2 / 8 * (omega_dot.max() + omega.max() ** 2) * np.linalg.norm(r)
    linear = np.stack([np.interp(between.time, s["time"], s["position"][:, j]) for j in range(3)], axis=1)
    gap = np.linalg.norm(between.position[:, 0] - linear, axis=1).max()
    assert gap <= bound, (gap, bound)


def test_a_pinned_body_keeps_c_at_its_anchor_and_a_free_body_does_not(runs):
    pinned = scene(pick_run(runs["case1_permanent"]), n_frames=23)
    stored = np.abs(pick_run(runs["case1_permanent"]).series("constraint_error")["constraint_error"]).max()
    assert np.abs(pinned.point_c[:, 0] - pinned.anchor).max() <= stored + 1e-12
    assert np.abs(pinned.position).max() > 0.05  # the body does swing about C
    free = scene(pick_run(runs["free_gravity"]), n_frames=23)
    assert np.linalg.norm(free.point_c[:, 0] - free.anchor, axis=1).max() > 0.01


def test_the_box_edges_are_the_columns_of_a_and_its_moments_are_the_bodys(runs, rng):
    sc = scene(pick_run(runs["case3_embedded"]), n_frames=9)
    for k in range(len(sc.time)):
        corners = sc.corners[k, 0]
        for i, other in enumerate((4, 2, 1)):  # corner 0 and the corners across each edge from it
            edge = corners[other] - corners[0]
            np.testing.assert_allclose(edge, sc.shape.sides[i] * sc.rotation[k, 0][:, i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(corners.mean(axis=0), sc.position[k, 0], rtol=0, atol=1e-12)
    # a realisable inertia: the uniform box of sides (a1, a2, a3) has j1 = m (a2^2 + a3^2) / 12 ...
    sides, mass = rng.uniform(0.1, 2.0, 3), rng.uniform(1.0, 100.0)
    moments = mass / 12 * np.array([sides[1] ** 2 + sides[2] ** 2, sides[0] ** 2 + sides[2] ** 2,
                                    sides[0] ** 2 + sides[1] ** 2])
    found, thin = box_sides(moments, mass)
    np.testing.assert_allclose(found, sides, rtol=1e-12)
    assert not thin.any()
    # ... the paper's (10, 8, 0.4) kg m^2 violate j1 <= j2 + j3: no side along x_b, drawn thin and said so
    found, thin = box_sides([10.0, 8.0, 0.4], 41.0)
    assert thin.tolist() == [True, False, False]
    np.testing.assert_allclose(found[1:], np.sqrt(6 * np.array([10 + 0.4 - 8, 10 + 8 - 0.4]) / 41), rtol=1e-12)
    assert 0 < found[0] < 0.1 * found[2]


def test_an_inertia_matrix_gives_the_uniform_box_with_that_inertia(rng):
    """A full J = Q diag(j) Q': the box's edges are along the principal axes Q, and the inertia
    of the uniform box with those edges, sum m (s_j^2 + s_k^2) / 12 u_i u_i', is J again."""
    q = _rotation(rng.uniform(-1.0, 1.0, (1, 3)))[0]
    sides, mass = rng.uniform(0.1, 2.0, 3), rng.uniform(1.0, 100.0)
    moments = mass / 12 * (np.sum(sides**2) - sides**2)
    inertia = q @ np.diag(moments) @ q.T
    shape = body_shape({"body": {"mass": mass, "inertia": inertia.tolist(), "attachment_point": [0.1, 0.2, 0.3]}})
    corners = box_corners(np.zeros((1, 3)), np.eye(3)[None], shape)[0]
    edges = np.array([corners[4] - corners[0], corners[2] - corners[0], corners[1] - corners[0]])
    lengths = np.linalg.norm(edges, axis=1)
    units = edges / lengths[:, None]
    box = sum(mass / 12 * (np.sum(lengths**2) - lengths[i] ** 2) * np.outer(units[i], units[i]) for i in range(3))
    np.testing.assert_allclose(box, inertia, rtol=1e-10, atol=1e-12 * np.abs(inertia).max())
    np.testing.assert_allclose(np.sort(lengths), np.sort(sides), rtol=1e-10)


def test_the_scene_limits_hold_every_frame_with_equal_axes(runs):
    sc = scene(pick_run(runs["case2_visco_elastic"]), n_frames=15)
    renderer = FrameRenderer(sc, dpi=40)
    ax = renderer.artists.axes3d
    limits = np.array([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()])
    widths = np.diff(limits, axis=1).ravel()
    np.testing.assert_allclose(widths, widths[0], rtol=1e-12)  # equal axes
    points = np.concatenate([sc.corners.reshape(-1, 3), sc.point_c.reshape(-1, 3), sc.trace.reshape(-1, 3)])
    assert np.all(points >= limits[:, 0]) and np.all(points <= limits[:, 1])
    for k in (7, 14):
        renderer.render(k)
        assert np.array_equal([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()], limits)  # fixed


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_a_few_frames_of_each_variant_render_and_differ(runs, name, tmp_path):
    sc = scene(pick_run(runs[name]), n_frames=3)
    renderer = FrameRenderer(sc, dpi=40)
    first, last = renderer.render(0), renderer.render(2)
    assert first.shape == (180, 240, 4) and first.dtype == np.uint8
    assert (first[..., :3] < 250).any()  # something drawn
    assert np.abs(first.astype(int) - last.astype(int)).sum() > 0  # the body moved
    still = write_still(sc, tmp_path / "still.png", frame=1, dpi=40)
    assert still.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_failed_run_plays_up_to_its_failure_and_says_why(runs):
    run = pick_run(runs["gimbal"])
    s = run.series("theta")
    finite = np.isfinite(s["theta"]).all(axis=1)
    assert run.status == "failed" and 2 <= finite.sum() < len(finite)
    sc = scene(run, n_frames=5)
    assert sc.t_failed == sc.time[-1] == s["time"][finite][-1]
    assert np.isfinite(sc.point_c).all()
    texts = [t.get_text() for t in FrameRenderer(sc, dpi=40).figure.texts]
    (note,) = [t for t in texts if "gimbal lock" in t]
    assert note.startswith("fell: gimbal lock") and note.count("t = ") == 1, note  # one event, one time: its own


# -- the command -------------------------------------------------------------------------------------

def test_animate_writes_a_page_that_plays_offline(runs, tmp_path):
    out = tmp_path / "case3.html"
    result = _invoke("animate", runs["case3_embedded"], "-o", out, "--fps", "4", "--speed", "2", "--dpi", "40",
                     "--view", "30,10")
    assert result.exit_code == 0, result.output
    frames = playback_frames(0.5, 4.0, 2.0)
    assert f"({frames} frames, 0.5 s of the run)" in result.output
    page = out.read_text()
    assert page.count("data:image/jpeg;base64,") == frames
    assert 'id="_anim_slider' in page and "play_animation()" in page
    assert not re.search(r'<(link|script)[^>]*(href|src)="https?:', page)  # nothing from the network
    assert 'class="fa' not in page  # the web font's icons replaced by text


def test_animate_writes_a_gif_and_names_what_an_mp4_lacks(runs, tmp_path):
    from PIL import Image

    gif = tmp_path / "gimbal.gif"
    result = _invoke("animate", runs["gimbal"], "-o", gif, "--fps", "10", "--speed", "0.01", "--dpi", "40")
    assert result.exit_code == 0, result.output
    with Image.open(gif) as im:
        assert im.n_frames >= 2 and im.size == (240, 180)
    result = _invoke("animate", runs["gimbal"], "-o", tmp_path / "gimbal.mp4", env={"PATH": str(tmp_path)})
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.output.strip().splitlines() == [
        f"Error: cannot write {tmp_path / 'gimbal.mp4'}: an MP4 needs ffmpeg, which is not on PATH "
        "(install ffmpeg, or write .gif or .html)"]
    assert not (tmp_path / "gimbal.mp4").exists()


def test_animate_picks_a_run_of_a_store_file_with_run(tmp_path):
    result = _invoke("animate", STORE, "-o", tmp_path / "a.gif", "--dpi", "40")
    assert result.exit_code == 1 and "holds 2 runs: choose one with --run ID" in result.output
    assert "r0000-d9362a0e" in result.output
    result = _invoke("animate", STORE, "--run", "r0001-9d69bf1", "-o", tmp_path / "a.gif")
    assert result.exit_code == 1 and "--run: found 'r0001-9d69bf1'" in result.output
    assert "did you mean r0001-9d69bf1f" in result.output
    result = _invoke("animate", STORE, "--run", "r0001-9d69bf1f", "-o", tmp_path / "a.gif", "--fps", "5",
                     "--speed", "1", "--dpi", "40")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "a.gif").is_file()


@pytest.mark.parametrize("args, fragment", [
    (["-o", "x.avi"], "found the suffix '.avi'; expected one of .html, .gif, .mp4, .png"),
    (["--view", "1,2,3"], "--view': found '1,2,3'; expected two numbers AZIMUTH,ELEVATION"),
    (["--fps", "0"], "--fps"),
    (["--speed", "1e-5"], "speed 1e-05 at 20 frames/s gives 1000001 frames for the 0.5 s of case1_permanent; "
                          "at most 5000"),
])
def test_animate_refuses_bad_options_in_one_line(runs, args, fragment, tmp_path):
    result = _invoke("animate", runs["case1_permanent"], *args)
    assert result.exit_code in (1, 2) and "Traceback" not in result.output
    assert fragment in result.output, result.output
    assert not list(Path.cwd().glob("x.avi"))


def test_cli_defaults_are_the_library_defaults():
    assert (animate_cli._FPS, animate_cli._SPEED, animate_cli._DPI) == (FPS, SPEED, DPI)
    from rbstab.report.animate import DEFAULT_VIEW

    assert animate_cli._VIEW == DEFAULT_VIEW
    assert report_cli._ANIMATION_FRAMES == ANIMATION_FRAMES
    assert report_cli._ANIMATION_FRAMES_RANGE == ANIMATION_FRAMES_RANGE


# -- in the report -----------------------------------------------------------------------------------

def test_the_report_embeds_one_animation_per_run_and_can_leave_them_out(runs, tmp_path, monkeypatch):
    from rbstab.report import build
    from rbstab.report.figures import FigureWriter

    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: None)  # figures drawn, not saved: faster
    monkeypatch.setattr(build, "_jobs", lambda options: 1)  # drawn here, where the patch holds
    monkeypatch.setattr(build, "MAX_ANIMATIONS", 1)  # the first run animated, the second told how
    inputs = [runs["gimbal"], runs["case1_permanent"]]
    result = _invoke("report", *inputs, "-o", tmp_path / "r", "--animation-frames", "3", "--format", "html",
                     "--format", "md")
    assert result.exit_code == 0, result.output
    page = (tmp_path / "r" / "index.html").read_text()
    assert page.count('<figure class="animation">') == 1
    assert page.count("data:image/jpeg;base64,") == 3
    assert "The run failed at t = " in page  # the gimbal run's, animated up to its failure
    assert f"No animation: the page animates the first 1 runs (rbstab animate {runs['case1_permanent']} " in page
    assert not re.search(r'<(link|script)[^>]*(href|src)="https?:', page)
    assert "index.html plays it" in (tmp_path / "r" / "index.md").read_text()
    summary = (tmp_path / "r" / "summary.md").read_text()
    assert "index.html plays it" not in summary and "base64" not in summary  # tables and words only
    # other inputs: another folder (a report of other inputs is not replaced)
    result = _invoke("report", runs["gimbal"], "-o", tmp_path / "r2", "--no-animations")
    assert result.exit_code == 0, result.output
    assert '<figure class="animation">' not in (tmp_path / "r2" / "index.html").read_text()
    result = _invoke("report", runs["gimbal"], "-o", tmp_path / "r2", "--animation-frames", "1")
    assert result.exit_code == 2 and "expected 0 (no animations) or 2 to 500" in result.output
