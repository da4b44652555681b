"""A 3D animation of a run: the body, its axes, the point C and its anchor (``rbstab animate``).

The animation is drawn from the stored trajectory, interpolated to the frame times (linear
in time between samples; nothing is integrated again). Its geometry is computed here as
pure functions of arrays, then drawn with matplotlib (``mpl_toolkits.mplot3d``,
``matplotlib.animation``):

- the body: the box of uniform density with the run's mass m and the principal moments of
  its inertia J (:func:`box_sides`), centred on the COM X, its edges along the columns of
  A Q (A = A(Theta), eq 2; Q the principal axes of J in the body frame, the identity for a
  diagonal J), :func:`box_corners`;
- the body axes: the columns of A, drawn from X;
- the point C of the body, C = X + A R, and its anchor R, the place of C at X = 0,
  Theta = 0 (the origin of E = X + A R - R, eq 4; every variant defines E so):
  the segment from the anchor to C is the constraint error E (:func:`attachment_point`;
  X between the samples from eq 4, :func:`scene`);
- the trace of the COM, the direction of gravity; the time, v(t) and |E| in a corner; a
  failed run is drawn up to its last finite sample, with its message.

A chain run is drawn so, body by body (one body is a tree of one, held at R by its joint):
each body's box and axes, the segments from each centre of mass to its joints' points, each
joint's two points joined by E_j, each hinge's axis through its point, and the ground points.

The scene's limits are fixed over the animation and its axes are equal
(:func:`scene_limits`). Outputs: an HTML snippet that plays offline (:func:`animation_html`,
matplotlib's ``to_jshtml`` with its frames embedded, its buttons made of text instead of
a web font), a page, a GIF or an MP4 (:func:`write_animation`), a still PNG
(:func:`write_still`).
"""

from __future__ import annotations

import difflib
import html
import re
import shutil
import tempfile
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..engine.status import fell
from ..io.atomic import atomic_path
from ..kinematics import rotation_matrix
from .load import RunData
from .render import Animation

__all__ = [
    "AnimationError",
    "BodyShape",
    "Scene",
    "FrameRenderer",
    "ANIMATION_SUFFIXES",
    "DEFAULT_VIEW",
    "FPS",
    "SPEED",
    "SIZE",
    "DPI",
    "box_sides",
    "body_shape",
    "box_corners",
    "attachment_point",
    "frame_times",
    "playback_frames",
    "scene",
    "scene_limits",
    "pick_run",
    "draw_animation",
    "animation_html",
    "report_animation",
    "write_animation",
    "write_still",
    "nearest_frame",
    "check_output",
]

#: File kinds ``rbstab animate -o`` writes (``.png``: one frame, a still).
ANIMATION_SUFFIXES = (".html", ".gif", ".mp4", ".png")
#: Playback: frames per second, and the run's time per second of playback (0.25: a 2 s run
#: plays in 8 s); size of a frame [inches] and its resolution [dots per inch] (480 x 360 pixels).
FPS, SPEED, SIZE, DPI = 20.0, 0.25, (6.0, 4.5), 80
#: Most frames of one animation.
MAX_FRAMES = 5000
#: A side of the box that the inertia cannot give (a moment above the sum of the other two:
#: no uniform body has it) is drawn this fraction of the longest side.
THIN_SIDE = 0.04
#: The 8 corners of a box as signs of its half sides, in the body frame.
_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
#: The 6 faces of the box as corner indices (each a quad in order around it).
BOX_FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))


class AnimationError(ValueError):
    """Raised for a run that cannot be animated or an output that cannot be written."""


# -- geometry (pure functions) ----------------------------------------------------------------

def box_sides(moments: Sequence[float], mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Side lengths of the uniform box with the principal moments ``moments`` and mass ``mass``.

    A box of sides (a1, a2, a3) and mass m has j1 = m (a2^2 + a3^2) / 12 (and cyclic), so
    a1^2 = 6 (j2 + j3 - j1) / m. A moment larger than the sum of the other two (the paper's
    (10, 8, 0.4) kg m^2) has no such box: that side is drawn :data:`THIN_SIDE` times the
    longest one and flagged.

    Parameters
    ----------
    moments : sequence of 3 float
        Principal moments of inertia (j1, j2, j3) [kg m^2] about the COM.
    mass : float
        m [kg], > 0.

    Returns
    -------
    sides : ndarray, shape (3,)
        Side lengths [m] along the principal axes.
    thin : ndarray of bool, shape (3,)
        True where the side is not the inertia's (drawn thin).
    """
    j = np.asarray(moments, dtype=float)
    squared = 6.0 * (j.sum() - 2.0 * j) / float(mass)
    thin = squared <= 0.0
    sides = np.sqrt(np.clip(squared, 0.0, None))
    longest = sides.max() if sides.max() > 0 else 1.0
    return np.where(thin, THIN_SIDE * longest, sides), thin


@dataclass(frozen=True)
class BodyShape:
    """What is drawn of a body.

    Attributes
    ----------
    sides : ndarray, shape (3,)
        Box sides [m] along the principal axes (:func:`box_sides`).
    thin : ndarray of bool, shape (3,)
        Sides the inertia cannot give (drawn thin).
    principal_axes : ndarray, shape (3, 3)
        Q: its columns are the principal axes of J in the body frame (the identity for a
        diagonal J).
    attachment_point : ndarray, shape (3,)
        R [m], the point C in the body frame.
    """

    sides: np.ndarray
    thin: np.ndarray
    principal_axes: np.ndarray
    attachment_point: np.ndarray


def body_shape(config: dict) -> BodyShape:
    """The :class:`BodyShape` of a run's resolved configuration (``body.mass``,
    ``body.inertia``: 3 principal moments or a 3x3 matrix, ``body.attachment_point``).

    Raises
    ------
    AnimationError
        If a key is missing or not numeric.
    """
    body = config.get("body") or {}
    try:
        mass = float(body["mass"])
        inertia = np.asarray(body["inertia"], dtype=float)
        r = np.asarray(body["attachment_point"], dtype=float).reshape(3)
    except (KeyError, TypeError, ValueError) as exc:
        raise AnimationError(f"the run's config has no usable body.mass, body.inertia, body.attachment_point ({exc})") from None
    if inertia.shape == (3,) or np.allclose(inertia, np.diag(np.diag(inertia))):
        moments, q = (inertia if inertia.ndim == 1 else np.diag(inertia)), np.eye(3)
    else:
        moments, q = np.linalg.eigh(0.5 * (inertia + inertia.T))
    sides, thin = box_sides(moments, mass)
    return BodyShape(sides, thin, q, r)


def attachment_point(position: np.ndarray, rotation: np.ndarray, r: np.ndarray) -> np.ndarray:
    """C = X + A R [m], inertial frame (eq 4: E = C - R).

    Parameters
    ----------
    position : ndarray, shape (n, 3)
        X [m], inertial frame.
    rotation : ndarray, shape (n, 3, 3)
        A(Theta), body frame to inertial frame.
    r : ndarray, shape (3,)
        R [m], body frame.

    Returns
    -------
    ndarray, shape (n, 3)
    """
    return position + rotation @ r


def box_corners(position: np.ndarray, rotation: np.ndarray, shape: BodyShape) -> np.ndarray:
    """Corners of the box, X + A Q (s * half sides), inertial frame [m], shape (n, 8, 3).

    Corner k has the signs :data:`_CORNER_SIGNS` [k]; :data:`BOX_FACES` lists the faces.
    The edges are along the columns of A Q (of A for a diagonal inertia).
    """
    offsets = (_CORNER_SIGNS * (0.5 * shape.sides)) @ shape.principal_axes.T  # (8, 3), body frame
    return position[:, None, :] + np.einsum("nij,kj->nki", rotation, offsets)


def frame_times(t_start: float, t_end: float, n_frames: int) -> np.ndarray:
    """``n_frames`` times [s] evenly from ``t_start`` to ``t_end`` (both included)."""
    return np.linspace(float(t_start), float(t_end), max(int(n_frames), 2))


def playback_frames(duration: float, fps: float, speed: float) -> int:
    """Frames that play ``duration`` seconds of the run at ``speed`` times real time at ``fps``
    frames per second (at least 2)."""
    return max(2, int(round(duration / speed * fps)) + 1)


@dataclass(frozen=True)
class Scene:
    """Everything drawn of a run, per frame (k frames, n bodies, n joints: joint j holds body
    j to its parent; one body is a tree of one, held to the ground at R by its joint).

    Attributes
    ----------
    time, lyapunov : ndarray, shape (k,)
        Frame times [s]; the stored v [J], interpolated.
    rotation : ndarray, shape (k, n, 3, 3)
        A(Theta_i) of each body.
    position : ndarray, shape (k, n, 3)
        X_i [m], each body's COM.
    corners : ndarray, shape (k, n, 8, 3)
        Each body's box (:func:`box_corners`).
    shapes : list of BodyShape
        Each body's box; ``attachment_point`` its joint's R_c.
    point_c : ndarray, shape (k, n, 3)
        Each joint's point on its child, X_c + A_c R_c [m].
    parent_point : ndarray, shape (k, n, 3)
        Each joint's point on its parent, X_p + A_p R_p [m] (the ground point R_p itself,
        where C is at E = 0: one body's anchor R).
    anchor : ndarray, shape (g, 3)
        The ground points of the joints held to the ground [m].
    constraint_error : ndarray, shape (k, 3)
        At each frame, the E_j of largest magnitude over the joints [m] (one body's E).
    trace : ndarray, shape (m, n, 3)
        Every stored X_i up to the last frame; ``trace_time`` (m,) their times.
    bodies, joints : list of str
        Their names (one body's: ``body``, ``controller``).
    parents : list of int
        Each joint's parent body (-1: the ground).
    label, variant, status, message : str
        The run's.
    t_failed : float or None
        Time of the last finite sample of a failed run; None for a successful run.
    gravity : ndarray, shape (3,)
        g [m/s^2], inertial frame (zero when absent).
    hinge_axis : ndarray, shape (k, n, 3)
        Each hinge's unit axis A_c a in the inertial frame (NaN for any other joint).
    """

    time: np.ndarray
    lyapunov: np.ndarray
    rotation: np.ndarray
    position: np.ndarray
    corners: np.ndarray
    shapes: list
    point_c: np.ndarray
    parent_point: np.ndarray
    anchor: np.ndarray
    constraint_error: np.ndarray
    trace: np.ndarray
    trace_time: np.ndarray
    bodies: list
    joints: list
    parents: list
    label: str = ""
    variant: str = ""
    status: str = "success"
    message: str = ""
    t_failed: float | None = None
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    hinge_axis: np.ndarray | None = None

    @property
    def shape(self) -> BodyShape:
        """The bodies' shapes as one for the notes: a side drawn thin on any body."""
        thin = np.any([b.thin for b in self.shapes], axis=0)
        first = self.shapes[0]
        return BodyShape(first.sides, thin, first.principal_axes, first.attachment_point)


def _interpolate(t: np.ndarray, samples: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``samples`` (shape (n,) or (n, 3)) linearly interpolated to ``times``."""
    if samples.ndim == 1:
        return np.interp(times, t, samples)
    return np.stack([np.interp(times, t, samples[:, i]) for i in range(samples.shape[1])], axis=1)


def _trajectory(run: RunData, n_frames: int | None, fps: float, speed: float) -> tuple[dict, slice, np.ndarray]:
    """(the run's stored theta, position, constraint_error, lyapunov with their time, each
    with a body or joint axis (one body's: one); the samples up to its last finite one; the
    frame times): AnimationError where the file keeps no trajectory, fewer than 2 finite
    samples, or more than :data:`MAX_FRAMES` frames."""
    s = run.series("theta", "position", "constraint_error", "lyapunov")
    missing = [n for n in ("time", "theta", "position", "constraint_error", "lyapunov") if n not in s]
    if missing:
        raise AnimationError(f"{run.label}: no stored trajectory to animate (the file lacks {', '.join(missing)}; "
                             "a sweep's --store summary keeps none)")
    for name in ("theta", "position", "constraint_error"):
        if s[name].ndim == 2:  # one body's (n, 3): its one body or joint
            s[name] = s[name][:, None]
    finite = np.isfinite(s["time"]) & np.isfinite(s["lyapunov"])
    for name in ("theta", "position", "constraint_error"):
        finite &= np.all(np.isfinite(s[name]).reshape(len(finite), -1), axis=1)
    last = int(np.flatnonzero(finite)[-1]) if finite.any() else -1
    if last < 1 or not finite[: last + 1].all():
        raise AnimationError(f"{run.label}: fewer than 2 finite samples: nothing to animate")
    keep = slice(0, last + 1)
    t = s["time"][keep]
    count = n_frames or playback_frames(t[-1] - t[0], fps, speed)
    if count > MAX_FRAMES:
        raise AnimationError(f"speed {speed:g} at {fps:g} frames/s gives {count} frames for the {t[-1] - t[0]:.4g} s "
                             f"of {run.label}; at most {MAX_FRAMES}: raise the speed or lower the frame rate")
    return s, keep, frame_times(t[0], t[-1], count)


def _tree(config: dict) -> tuple[list[BodyShape], list[int], np.ndarray, list[str], list[str], np.ndarray]:
    """(each body's BodyShape, its joint's R_c; each joint's parent index, -1 ground; each
    joint's R_p (n, 3); the bodies' and joints' names; g) of a run's resolved configuration
    (one body: its body ``body`` held to the ground at R by its joint ``controller``)."""
    if "bodies" not in config:
        shape = body_shape(config)
        gravity = (config.get("body") or {}).get("gravity")
        return ([shape], [-1], shape.attachment_point[None].copy(), ["body"], ["controller"],
                np.asarray(gravity if gravity is not None else np.zeros(3), dtype=float).reshape(3))
    try:
        bodies, joints = list(config["bodies"]), list(config["joints"])
        names = [b["name"] for b in bodies]
        by_child = {j["child"]: j for j in joints}
        shapes, parents, points = [], [], []
        for body in bodies:
            joint = by_child[body["name"]]
            shape = body_shape({"body": {"mass": body["mass"], "inertia": body["inertia"],
                                         "attachment_point": joint["child_point"]}})
            shapes.append(shape)
            parents.append(-1 if joint["parent"] == "ground" else names.index(joint["parent"]))
            points.append(np.asarray(joint["parent_point"], dtype=float).reshape(3))
        joint_names = [by_child[b]["name"] for b in names]
    except (KeyError, TypeError, ValueError) as exc:
        raise AnimationError(f"the run's config has no usable bodies and joints ({exc})") from None
    return (shapes, parents, np.array(points), names, joint_names,
            np.asarray(config.get("gravity") or np.zeros(3), dtype=float).reshape(3))


def _hinge_axes(config: dict) -> np.ndarray:
    """Each body's joint's unit axis a (n, 3) where it is a hinge or a slide (the child's
    frame; a universal joint's second axis a_2, the one fixed in the child's frame), NaN for
    any other joint (one body's: NaN)."""
    if "bodies" not in config:
        return np.full((1, 3), np.nan)
    by_child = {j["child"]: j for j in config["joints"]}
    out = np.full((len(config["bodies"]), 3), np.nan)
    for i, body in enumerate(config["bodies"]):
        joint = by_child[body["name"]]
        if joint.get("variant") in ("hinge", "universal", "slide") and joint.get("axis") is not None:
            axis = np.asarray(joint["axis"], dtype=float).reshape(-1, 3)[-1]
            out[i] = axis / np.linalg.norm(axis)
    return out


def scene(run: RunData, n_frames: int | None = None, fps: float = FPS, speed: float = SPEED) -> Scene:
    """The :class:`Scene` of a run (one body or a chain), from its stored series (Theta_i,
    X_i, E_j, v) interpolated linearly to the frame times; the bodies' shapes, names and the
    joints' points from its configuration.

    A body held to the ground (one body's, or a chain's on a ground joint) follows eq 4 for
    X: X = R_p + E - A R_c, so that its C lies at the stored E from its ground point at every
    frame (at a pinned body's anchor) and X is the stored X at the sample times (between
    them it differs from the linear interpolation of X by that of A R_c, O(dt^2
    (|dOmega/dt| + |Omega|^2) |R_c|)); a body on another body's joint follows its stored X.

    Parameters
    ----------
    run : RunData
        A run of a result file or a store file (``theta``, ``position``,
        ``constraint_error``, ``lyapunov`` stored).
    n_frames : int, optional
        Frames, evenly in time over the stored trajectory; default: as many as play it at
        ``fps`` frames per second and ``speed`` times real time (:func:`playback_frames`).
    fps, speed : float
        Used when ``n_frames`` is None.

    Returns
    -------
    Scene
        For a failed run the frames end at its last finite sample.

    Raises
    ------
    AnimationError
        If the run has no stored trajectory (a ``summary`` store) or fewer than 2 finite
        samples, or the frames would be more than :data:`MAX_FRAMES`.
    """
    s, keep, frames = _trajectory(run, n_frames, fps, speed)
    t = s["time"][keep]
    shapes, parents, r_p, names, joint_names, gravity = _tree(run.config)
    n = len(shapes)
    theta, x, e = s["theta"][keep], s["position"][keep], s["constraint_error"][keep]
    if theta.shape[1] != n:
        raise AnimationError(f"{run.label}: the file holds {theta.shape[1]} bodies, its config {n}")
    rotation = np.stack([rotation_matrix(_interpolate(t, theta[:, i], frames)) for i in range(n)], axis=1)
    error = np.stack([_interpolate(t, e[:, j], frames) for j in range(n)], axis=1)
    position = np.stack([r_p[i] + error[:, i] - rotation[:, i] @ shapes[i].attachment_point if parents[i] < 0
                         else _interpolate(t, x[:, i], frames) for i in range(n)], axis=1)  # eq 4 on the ground
    point_c = np.stack([attachment_point(position[:, i], rotation[:, i], shapes[i].attachment_point)
                        for i in range(n)], axis=1)
    parent_point = np.stack([np.broadcast_to(r_p[j], (len(frames), 3)) if parents[j] < 0 else
                             attachment_point(position[:, parents[j]], rotation[:, parents[j]], r_p[j])
                             for j in range(n)], axis=1)
    largest = np.argmax(np.linalg.norm(error, axis=-1), axis=1)
    hinge_axis = np.einsum("kiab,ib->kia", rotation, _hinge_axes(run.config))  # A_c a: a turns with the child
    return Scene(
        time=frames, lyapunov=_interpolate(t, s["lyapunov"][keep], frames), rotation=rotation, position=position,
        corners=np.stack([box_corners(position[:, i], rotation[:, i], shapes[i]) for i in range(n)], axis=1),
        shapes=shapes, point_c=point_c, parent_point=parent_point,
        anchor=np.array([r_p[j] for j in range(n) if parents[j] < 0]).reshape(-1, 3),
        constraint_error=error[np.arange(len(frames)), largest], trace=x, trace_time=t,
        bodies=names, joints=joint_names, parents=parents,
        label=run.label, variant=run.variant, status=run.status, message=run.message,
        t_failed=None if run.ok else float(t[-1]), gravity=gravity, hinge_axis=hinge_axis,
    )


def scene_limits(sc: Scene, margin: float = 0.05) -> tuple[np.ndarray, float]:
    """Centre [m] (shape (3,)) and half width [m] of the cube that holds every frame's box,
    C, the anchor and the trace, widened by ``margin`` (a fraction): equal axes, fixed
    limits."""
    points = np.concatenate([np.reshape(a, (-1, 3)) for a in (sc.corners, sc.point_c, sc.anchor, sc.trace)])
    low, high = points.min(axis=0), points.max(axis=0)
    return 0.5 * (low + high), 0.5 * float((high - low).max()) * (1.0 + margin)


def pick_run(path: str | Path, run_id: str | None = None) -> RunData:
    """The run to animate: the run of a run file, or run ``run_id`` of a sweep folder or a
    store file (needed when it holds more than one run).

    Raises
    ------
    ReportInputError
        If ``path`` is not a result (:func:`rbstab.report.load.load_inputs`), ``run_id`` is
        missing for several runs, or no run has that id (the closest ids named).
    """

    from .load import ReportInputError, load_inputs  # heavy: pydantic or the report's loaders, needed only when a run is animated

    inputs = load_inputs([path])
    if inputs.sweeps:
        sweep = inputs.sweeps[0]
        ids, runs = sweep.run_ids, sweep.runs
    else:
        ids, runs = [r.name for r in inputs.runs], list(inputs.runs)
    if run_id is None:
        if len(runs) == 1 and runs[0] is not None:
            return runs[0]
        raise ReportInputError([(f"{path} holds {len(ids)} runs: choose one with --run ID "
                                 f"(e.g. {', '.join(ids[:3])}; rbstab show {path} lists them)")])
    if run_id not in ids:
        close = difflib.get_close_matches(run_id, ids, n=3, cutoff=0.5)
        hint = f"; did you mean {', '.join(close)}?" if close else f" (it holds {len(ids)} runs; rbstab show {path} lists them)"
        raise ReportInputError([f"--run: found {run_id!r}, which is not a run of {path}{hint}"])
    run = runs[ids.index(run_id)]
    if run is None:
        raise ReportInputError([f"run {run_id} of {path} has no result file (its status in index.csv says why)"])
    return run


# -- drawing (matplotlib) -----------------------------------------------------------------------

#: Colours of the body axes x_b, y_b, z_b, of C and E, of the anchor and of the COM.
AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")
C_COLOUR, ANCHOR_COLOUR, COM_COLOUR = "darkorange", "black", "0.35"
#: JPEG quality of the frames of an HTML player (Pillow's scale, 1-95).
JPEG_QUALITY = 55
#: Default view (azimuth, elevation) [degrees].
DEFAULT_VIEW = (-60.0, 22.0)


def _corner_text(sc: Scene, k: int) -> str:
    """Time, v and |E| at frame k (the corner of the view)."""
    e = float(np.linalg.norm(sc.constraint_error[k]))
    e_text = f"{100 * e:.3g} cm" if e >= 1e-4 else f"{e:.2g} m"
    return f"t = {sc.time[k]:6.3f} s\nv = {sc.lyapunov[k]:.4g} J\n|E| = {e_text}"


def _notes(sc: Scene) -> list[tuple[str, str]]:
    """Lines under the view and their colours: a failure and its message, which says when
    (red), a box side the inertia cannot give (grey)."""
    notes = []
    if sc.t_failed is not None:
        notes.append((f"{'fell' if fell(sc.status, sc.message) else sc.status}: {sc.message}", "#b00000"))
    if sc.shape.thin.any():
        which = ", ".join(f"{'xyz'[i]}_b" for i in np.flatnonzero(sc.shape.thin))
        notes.append((f"the inertia has no uniform box (a moment exceeds the sum of the other two): side along "
                      f"{which} drawn thin", "0.3"))
    return notes


class _Artists:
    """The artists of an animation and how frame k moves them: a box a body (each its own
    tint), each body's axes x_b, y_b, z_b from its COM, the segments from each COM to its
    joints' points (the skeleton, grey), each joint's two points joined by E_j (orange: one
    body's anchor R to its C), the COMs, the ground points and the trace of the last body's
    COM; the time, v and |E| in a corner."""

    _TINTS = ((0.45, 0.62, 0.85), (0.85, 0.62, 0.45), (0.5, 0.78, 0.5), (0.78, 0.55, 0.78),
              (0.85, 0.8, 0.4), (0.5, 0.75, 0.8), (0.7, 0.7, 0.7), (0.9, 0.55, 0.6))

    def __init__(self, ax, sc: Scene) -> None:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # heavy: mpl_toolkits

        self.sc = sc
        self.axes3d = ax
        one = len(sc.bodies) == 1
        self.boxes = []
        for i, name in enumerate(sc.bodies):
            box = Poly3DCollection(self._faces(0, i), facecolor=(*self._TINTS[i % len(self._TINTS)], 0.28),
                                   edgecolor="0.2", linewidths=0.8, label=None if one else name)
            ax.add_collection3d(box)
            self.boxes.append(box)
        self.length = 0.6 * float(max(shape.sides.max() for shape in sc.shapes))
        self.axes = [ax.plot([], [], [], color=c, lw=2.0 if one else 1.2, label=f"body axis ${'xyz'[i]}_b$")[0]
                     for i, c in enumerate(AXIS_COLOURS)]
        self.skeleton = ax.plot([], [], [], color="0.3", lw=1.2, label="COM to joints")[0]
        self.coms = ax.plot([], [], [], "o", color=COM_COLOUR, ms=4, label="COM X" if one else "COMs X_i")[0]
        self.trace = ax.plot([], [], [], color=COM_COLOUR, lw=1.0, ls="-" if one else ":",
                             label="COM trace" if one else f"trace of {sc.bodies[-1]}")[0]
        if len(sc.anchor):
            ax.plot(sc.anchor[:, 0], sc.anchor[:, 1], sc.anchor[:, 2], "x", color=ANCHOR_COLOUR, ms=9, mew=2,
                    label="anchor of C (E = 0)" if one else "ground points")
        if np.any(sc.gravity):
            _gravity_arrow(ax, sc.gravity)
        self.error = ax.plot([], [], [], color=C_COLOUR, lw=2.5, label="E (anchor to C)" if one else
                             "E_j (joint's points)")[0]
        self.joints = ax.plot([], [], [], "o", color=C_COLOUR, ms=6 if one else 5,
                              label="C = X + A R" if one else "joints' points C")[0]
        self.hinged = [] if sc.hinge_axis is None else \
            [j for j in range(len(sc.joints)) if np.all(np.isfinite(sc.hinge_axis[0, j]))]
        self.hinges = ax.plot([], [], [], color="k", lw=2.0, label="hinge axes")[0] if self.hinged else None
        self.text = ax.text2D(0.01, 0.99, "", transform=ax.transAxes, va="top", ha="left", family="monospace",
                              fontsize=8, bbox={"facecolor": "white", "edgecolor": "0.7", "alpha": 0.85})
        self.trace_index = np.searchsorted(sc.trace_time, sc.time, side="right")

    def _faces(self, k: int, i: int) -> list:
        corners = self.sc.corners[k, i]
        return [corners[list(face)] for face in BOX_FACES]

    @staticmethod
    def _segments(pairs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y, z of line segments separated by NaN (one artist draws them all)."""
        out = [[], [], []]
        for a, b in pairs:
            for d in range(3):
                out[d] += [a[d], b[d], np.nan]
        return tuple(np.array(d, dtype=float) for d in out)

    def update(self, k: int) -> list:
        sc = self.sc
        n = len(sc.bodies)
        for i, box in enumerate(self.boxes):
            box.set_verts(self._faces(k, i))
        x = sc.position[k]
        for a, line in enumerate(self.axes):
            line.set_data_3d(*self._segments([(x[i], x[i] + self.length * sc.rotation[k, i][:, a]) for i in range(n)]))
        pairs = [(x[i], sc.point_c[k, i]) for i in range(n)]
        self.skeleton.set_data_3d(*self._segments(pairs + self._parent_pairs(k)))
        self.coms.set_data_3d(x[:, 0], x[:, 1], x[:, 2])
        self.error.set_data_3d(*self._segments([(sc.parent_point[k, j], sc.point_c[k, j]) for j in range(n)]))
        points = np.concatenate([sc.point_c[k], sc.parent_point[k]])
        self.joints.set_data_3d(points[:, 0], points[:, 1], points[:, 2])
        path = np.vstack([sc.trace[: self.trace_index[k], -1], x[-1]])
        self.trace.set_data_3d(path[:, 0], path[:, 1], path[:, 2])
        self.text.set_text(_corner_text(sc, k))
        moved = [*self.boxes, *self.axes, self.skeleton, self.coms, self.trace, self.error, self.joints, self.text]
        if self.hinges is not None:  # each hinge's axis through its point, as long as the body axes
            half = 0.5 * self.length
            self.hinges.set_data_3d(*self._segments([(sc.point_c[k, j] - half * sc.hinge_axis[k, j],
                                                      sc.point_c[k, j] + half * sc.hinge_axis[k, j])
                                                     for j in self.hinged]))
            moved.append(self.hinges)
        return moved

    def _parent_pairs(self, k: int) -> list:
        """(a parent's COM, its point of joint j) for each joint with a parent body."""
        sc = self.sc
        return [(sc.position[k, p], sc.parent_point[k, j]) for j, p in enumerate(sc.parents) if p >= 0]


def _gravity_arrow(ax, gravity: np.ndarray) -> None:
    """An arrow along g in a top corner of the view (its direction only; fixed)."""
    (x0, x1), (y0, y1), (z0, z1) = ax.get_xlim(), ax.get_ylim(), ax.get_zlim()
    length = 0.2 * (x1 - x0)
    u = gravity / np.linalg.norm(gravity)
    start = np.array([x0 + 0.1 * (x1 - x0), y1 - 0.1 * (y1 - y0), z1 - 0.05 * (z1 - z0)]) - np.clip(u, 0, None) * length
    ax.quiver(*start, *(u * length), color="tab:purple", lw=1.5, arrow_length_ratio=0.3,
              label=f"g = {np.linalg.norm(gravity):.3g} m/s$^2$")


def _figure(sc: Scene, view: tuple[float, float], size: tuple[float, float], dpi: int):
    """The figure, its 3D axes with fixed equal limits, and the artists of the scene."""

    from matplotlib.backends.backend_agg import FigureCanvasAgg  # heavy: matplotlib
    from matplotlib.figure import Figure  # heavy: matplotlib
    from matplotlib.ticker import MaxNLocator  # heavy: matplotlib

    fig = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(fig)
    notes = _notes(sc)
    bottom = 0.08 + 0.045 * sum(len(textwrap.wrap(n, 95)) for n, _ in notes)
    ax = fig.add_axes((-0.03, bottom, 0.8, 0.93 - bottom), projection="3d")
    centre, half = scene_limits(sc)
    for axis, c in zip("xyz", centre):
        getattr(ax, f"set_{axis}lim")(c - half, c + half)
        getattr(ax, f"set_{axis}label")(f"{axis} [m]", fontsize=8, labelpad=-2)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.tick_params(labelsize=7, pad=0)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    ax.view_init(elev=view[1], azim=view[0])
    artists = _Artists(ax, sc)
    artists.update(0)
    fig.legend(loc="center right", fontsize=7, frameon=False, bbox_to_anchor=(0.995, 0.55))
    fig.text(0.5, 0.975, f"{sc.label} ({sc.variant})", ha="center", va="top", fontsize=10, parse_math=False)
    y = bottom - 0.02
    for note, colour in notes:  # a run's name and message are shown as written (parse_math off)
        wrapped = "\n".join(textwrap.wrap(note, 95))
        fig.text(0.02, y, wrapped, ha="left", va="top", fontsize=7, color=colour, parse_math=False)
        y -= 0.045 * wrapped.count("\n") + 0.045
    return fig, artists


class FrameRenderer:
    """Frames of a scene as RGBA pixels, drawn by blitting: the figure's fixed parts (axes,
    ticks, legend, titles, the anchor) are drawn once, then each frame only the moving
    artists (box, body axes, trace, C, E, the corner text) over them, the box first.

    Attributes
    ----------
    figure : matplotlib.figure.Figure
        The 3D view (Agg canvas).
    artists : _Artists
        Its moving artists; :meth:`_Artists.update` places them at a frame.
    """

    def __init__(self, sc: Scene, view: tuple[float, float] = DEFAULT_VIEW,
                 size: tuple[float, float] = SIZE, dpi: int = 80) -> None:
        self.figure, self.artists = _figure(sc, view, size, dpi)
        self._moving = self.artists.update(0)
        for artist in self._moving:
            artist.set_visible(False)
        canvas = self.figure.canvas
        canvas.draw()
        self._background = canvas.copy_from_bbox(self.figure.bbox)
        for artist in self._moving:
            artist.set_visible(True)

    def render(self, k: int) -> np.ndarray:
        """Frame k, shape (height, width, 4), uint8."""
        canvas = self.figure.canvas
        canvas.restore_region(self._background)
        ax = self.artists.axes3d
        for artist in self.artists.update(k):
            if hasattr(artist, "do_3d_projection"):
                artist.do_3d_projection()
            ax.draw_artist(artist)
        return np.asarray(canvas.buffer_rgba()).copy()


def draw_animation(sc: Scene, fps: float = FPS, view: tuple[float, float] = DEFAULT_VIEW,
                   size: tuple[float, float] = SIZE, dpi: int = 80):
    """A matplotlib ``FuncAnimation`` of the scene (Agg canvas; no display needed).

    Its figure shows the frames of a :class:`FrameRenderer` as they are, so that a writer
    (``to_jshtml``, ``PillowWriter``, ``FFMpegWriter``) saves each frame without drawing the
    3D view's fixed parts again; save it at the figure's ``dpi``.

    Parameters
    ----------
    sc : Scene
    fps : float
        Frames per second of playback.
    view : (float, float)
        Azimuth and elevation of the view [degrees].
    size : (float, float)
        Figure size [inches]; frames are ``size * dpi`` pixels.
    dpi : int
        Dots per inch of the frames.

    Returns
    -------
    matplotlib.animation.FuncAnimation
    """
    from matplotlib.animation import FuncAnimation  # heavy: matplotlib
    from matplotlib.artist import Artist  # heavy: matplotlib
    from matplotlib.figure import Figure  # heavy: matplotlib

    class Pixels(Artist):
        """A frame's pixels, drawn as they are (no resampling: the figure has the frame's size)."""

        def __init__(self) -> None:
            super().__init__()
            self.pixels = np.zeros((1, 1, 4), dtype=np.uint8)

        def draw(self, renderer) -> None:
            gc = renderer.new_gc()
            renderer.draw_image(gc, 0, 0, self.pixels)
            gc.restore()

    renderer = FrameRenderer(sc, view, size, dpi)
    fig = Figure(figsize=size, dpi=dpi)  # its canvas draws only when saved: one draw per frame
    image = Pixels()
    fig.add_artist(image)

    def show(k: int) -> list:
        image.pixels = np.ascontiguousarray(renderer.render(k)[::-1])  # rows from the bottom
        return [image]

    show(0)
    return FuncAnimation(fig, show, frames=len(sc.time), interval=1000.0 / fps, blit=False, repeat=True)


#: Buttons of matplotlib's HTML player as text (its template asks a web font for icons).
_BUTTONS = {
    "fa-minus": "&minus;", "fa-fast-backward": "|&#9664;&#9664;", "fa-step-backward": "|&#9664;",
    "fa-play fa-flip-horizontal": "&#9664;", "fa-pause": "&#10074;&#10074;", "fa-play": "&#9654;",
    "fa-step-forward": "&#9654;|", "fa-fast-forward": "&#9654;&#9654;|", "fa-plus": "+",
}
_ICON = re.compile(r'<i class="fa ([^"]*)"></i>')
_REMOTE_STYLE = re.compile(r'<link[^>]*href="https?://[^"]*"[^>]*>\s*')


def _offline(snippet: str) -> str:
    """matplotlib's player without anything from the network: icons as text."""
    snippet = _REMOTE_STYLE.sub("", snippet)
    return _ICON.sub(lambda m: _BUTTONS.get(m.group(1), m.group(1).replace("fa-", "")), snippet)


def animation_html(sc: Scene, fps: float = FPS, view: tuple[float, float] = DEFAULT_VIEW,
                   size: tuple[float, float] = SIZE, dpi: int = 80, quality: int = JPEG_QUALITY) -> str:
    """An HTML snippet that plays the scene offline: matplotlib's ``to_jshtml`` player
    (``HTMLWriter`` with its frames embedded; play/pause, a time slider), the frames as
    JPEG of ``quality`` (1-95; about 22 kB a frame in the page at the defaults), the buttons as
    text.
    """

    from matplotlib.animation import HTMLWriter  # heavy: matplotlib

    anim = draw_animation(sc, fps, view, size, dpi)
    writer = HTMLWriter(fps=fps, embed_frames=True, default_mode="loop", embed_limit=1000.0)
    writer.frame_format = "jpeg"
    with tempfile.TemporaryDirectory() as folder:
        page = Path(folder) / "animation.html"
        anim.save(str(page), writer=writer, dpi=dpi, savefig_kwargs={"pil_kwargs": {"quality": quality, "optimize": True}})
        return _offline(page.read_text(encoding="utf-8"))


def report_animation(run: RunData, frames: int):
    """A report's animation of a run, one body's or a chain's, with ``frames`` frames and its
    caption (:class:`rbstab.report.render.Animation`), or a line saying why there is none."""
    try:
        sc = scene(run, n_frames=frames)
    except AnimationError as exc:
        return f"No animation: {exc}"
    one = len(sc.bodies) == 1
    return Animation(
        f"{run.label}: the motion", f"{len(sc.time)} frames evenly over t = {sc.time[0]:.4g} to {sc.time[-1]:.4g} s, "
        "interpolated from the stored trajectory: "
        + ("the uniform box with the body's mass and principal moments, its axes x_b (red), y_b (green), z_b "
           "(blue), the point C = X + A R (orange dot), its anchor R where E = 0 (black cross), the constraint "
           "error E between them (orange segment), the COM's trace" if one else
           "each body as the uniform box with its mass and principal moments, with its axes x_b (red), y_b "
           "(green), z_b (blue), the segments from each centre of mass to its joints' points, each joint's points "
           "joined by E_j (orange), the ground points (black crosses), the trace of the last body's centre of mass")
        + " and the direction of gravity (purple, when not zero); slider and buttons under the view."
        + (f" The run {run.status} at t = {sc.t_failed:.4g} s: the animation stops there." if sc.t_failed is not None
           else ""),
        animation_html(sc),
    )


def check_output(path: str | Path) -> str:
    """The kind of an output file (``html``, ``gif``, ``mp4``, ``png``) from its suffix.

    Raises
    ------
    AnimationError
        For another suffix, or ``.mp4`` when ffmpeg is not on PATH (one line naming it).
    """
    import matplotlib  # heavy: matplotlib

    suffix = Path(path).suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise AnimationError(f"output {path}: found the suffix {suffix or '(none)'!r}; expected one of "
                             f"{', '.join(ANIMATION_SUFFIXES)}")
    if suffix == ".mp4" and shutil.which(matplotlib.rcParams["animation.ffmpeg_path"]) is None:
        raise AnimationError(f"cannot write {path}: an MP4 needs ffmpeg, which is not on PATH "
                             "(install ffmpeg, or write .gif or .html)")
    return suffix[1:]


def _page(sc: Scene, snippet: str) -> str:
    """A page holding the player alone."""

    title = html.escape(f"{sc.label} ({sc.variant})")
    notes = "".join(f"<p>{html.escape(n)}</p>" for n, _ in _notes(sc))
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title></head>\n'
            f'<body style="font-family: system-ui, sans-serif">\n<h1 style="font-size: 1.2em">{title}</h1>\n'
            f"{snippet}\n{notes}</body></html>\n")


def write_animation(sc: Scene, path: str | Path, fps: float = FPS, view: tuple[float, float] = DEFAULT_VIEW,
                    dpi: int = DPI, at: float | None = None) -> Path:
    """Write the scene to ``path``: ``.html`` (a page with the player, :func:`animation_html`),
    ``.gif`` (Pillow), ``.mp4`` (ffmpeg) or ``.png`` (the frame nearest the time ``at`` [s],
    the last without it; :func:`write_still`); the file appears whole or not at all.

    Raises
    ------
    AnimationError
        For another suffix or an MP4 without ffmpeg (:func:`check_output`).
    OSError
        If the file cannot be written.
    """

    path = Path(path)
    kind = check_output(path)
    with atomic_path(path, suffix=path.suffix) as tmp:  # the writers read the format from the name
        if kind == "html":
            tmp.write_text(_page(sc, animation_html(sc, fps, view, dpi=dpi)), encoding="utf-8")
        elif kind == "png":
            write_still(sc, tmp, nearest_frame(sc, at), view, dpi)
        else:
            from matplotlib.animation import FFMpegWriter, PillowWriter  # heavy: matplotlib

            writer = PillowWriter(fps=fps) if kind == "gif" else FFMpegWriter(fps=fps)
            draw_animation(sc, fps, view, dpi=dpi).save(str(tmp), writer=writer, dpi=dpi)
    return path


def nearest_frame(sc: Scene, at: float | None) -> int:
    """Index of the frame nearest the time ``at`` [s] (the last frame for None)."""
    return len(sc.time) - 1 if at is None else int(np.abs(sc.time - at).argmin())


def write_still(sc: Scene, path: str | Path, frame: int = -1, view: tuple[float, float] = DEFAULT_VIEW,
                dpi: int = DPI) -> Path:
    """Frame ``frame`` of the scene (the last by default) as a PNG, drawn whole."""
    fig, artists = _figure(sc, view, SIZE, dpi)
    artists.update(range(len(sc.time))[frame])
    fig.savefig(path, format="png", dpi=dpi, metadata={"Software": f"rbstab {__version__}"})
    return Path(path)
