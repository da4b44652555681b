"""``rbstab show``: print the summary of result files."""

from __future__ import annotations

import click


def _fmt(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:.6g}" for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


@click.command("show")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
def show(files) -> None:
    """Print status, solver statistics and summary figures of FILE.h5..."""
    from rbstab.io.hdf5 import NotAResultFile, read_summary

    bad = 0
    for path in files:
        try:
            info = read_summary(path)
        except (FileNotFoundError, NotAResultFile) as exc:
            click.echo(f"error: {exc}", err=True)
            bad += 1
            continue
        click.echo(f"{path}")
        click.echo(f"  name       {info['name']}  (variant {info['variant']})")
        click.echo(f"  status     {info['status']}: {info['message']}")
        click.echo(f"  created    {info['created']}, wall time {_fmt(info['wall_time'])} s")
        solver = ", ".join(f"{k} {v}" for k, v in info["solver"].items() if k != "message")
        click.echo(f"  solver     {solver}")
        for key, value in info["summary"].items():
            click.echo(f"  {key:<32} {_fmt(value)}")
    if bad:
        raise click.ClickException(f"{bad} of {len(files)} files could not be read")
