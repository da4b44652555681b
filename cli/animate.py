"""``rbstab animate``: a 3D animation of a run (HTML page, GIF or MP4)."""

from __future__ import annotations

from pathlib import Path

import click

from .console import get_console
from .options import console_options

# Defaults repeated here (not imported) so that ``rbstab --help`` does not import the
# report package; tests/test_animate.py checks they equal rbstab.report.animate's.
_FPS = 20.0
_SPEED = 0.25
_VIEW = (-60.0, 22.0)
_DPI = 80


def _view(ctx, param, value) -> tuple[float, float]:
    """``--view AZIMUTH,ELEVATION`` in degrees."""
    if value is None:
        return _VIEW
    parts = [p.strip() for p in value.split(",")]
    try:
        azimuth, elevation = (float(p) for p in parts)
    except ValueError:
        raise click.BadParameter(f"found {value!r}; expected two numbers AZIMUTH,ELEVATION in degrees, "
                                 "e.g. -60,22") from None
    return azimuth, elevation


@click.command("animate")
@click.argument("result", type=click.Path())
@click.option("--run", "run_id", default=None, metavar="ID",
              help="The run to animate, for a sweep folder or a store file (its run_id; rbstab show lists them).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Output file: .html (a page that plays offline), .gif, .mp4 (needs ffmpeg) or .png "
              "(one frame, see --at) [default: <run>.html beside RESULT].")
@click.option("--fps", type=click.FloatRange(min=1.0, max=120.0), default=_FPS, show_default=True,
              help="Frames per second of playback.")
@click.option("--speed", type=click.FloatRange(min=0.0, min_open=True), default=_SPEED, show_default=True,
              metavar="X", help="Playback speed, times real time (0.25: a 2 s run plays in 8 s).")
@click.option("--view", "view", default=None, callback=_view, metavar="AZIMUTH,ELEVATION",
              help=f"Direction of the view [degrees; default: {_VIEW[0]:g},{_VIEW[1]:g}].")
@click.option("--at", type=float, default=None, metavar="SECONDS",
              help="Time of the frame a .png shows [s; default: the last frame].")
@click.option("--dpi", type=click.IntRange(40, 300), default=_DPI, show_default=True,
              help="Resolution of the frames [dots per inch; a frame is 6 x 4.5 inches: 480 x 360 pixels at 80].")
@console_options
def animate(result, run_id, output, fps, speed, view, at, dpi) -> None:
    """Animate the run of RESULT (a run file, or a sweep folder or store file with --run) in 3D.

    Draws the body as the uniform box with its mass and principal moments of inertia, its
    body axes, the point C, its anchor and the constraint error E between them, the COM's
    trace, and the time, v(t) and |E| in a corner, from the stored trajectory (interpolated
    to the frames). A failed run plays up to its failure and says why.
    """
    from rbstab.report.animate import (  # heavy: numpy, pydantic
        AnimationError,
        check_output,
        nearest_frame,
        pick_run,
        scene,
        write_animation,
    )
    from rbstab.report.load import ReportInputError, safe_filename  # heavy: numpy, pydantic

    try:
        run = pick_run(result, run_id)
        target = Path(output) if output else run.path.parent / f"{safe_filename(run.label)}.html"
        check_output(target)
        sc = scene(run, fps=fps, speed=speed)
        write_animation(sc, target, fps=fps, view=view, dpi=dpi, at=at)
    except ReportInputError as exc:
        raise click.ClickException("\n".join(exc.problems)) from None
    except AnimationError as exc:
        raise click.ClickException(str(exc)) from None
    if target.suffix.lower() == ".png":
        get_console().out(f"still: {target} (t = {sc.time[nearest_frame(sc, at)]:.4g} s)")
    else:
        get_console().out(f"animation: {target} ({len(sc.time)} frames, {sc.time[-1] - sc.time[0]:.4g} s of the run)")
