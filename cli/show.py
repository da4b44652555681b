"""``rbstab show``: print the summary of result files."""

from __future__ import annotations

import click


def _fmt(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:.6g}" for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _show_chunk(path: str) -> None:
    """One line per run of a chunk file (``rbstab sweep --layout chunk``)."""
    from rbstab.io.chunk import read_chunk_rows

    rows = read_chunk_rows(path)
    first = rows[0] if rows else {}
    click.echo(f"{path}")
    click.echo(f"  chunk file: {len(rows)} runs, store {first.get('store', '?')}, created {first.get('created', '?')}")
    click.echo(f"  {'run':<20} {'status':<8} {'v(0) -> v(t_end) [J]':<24} {'max dv/dt [W]':>14} "
               f"{'max|E| [m]':>11}  rate check")
    for r in rows:
        v = f"{_fmt(r.get('summary_lyapunov_initial', ''))} -> {_fmt(r.get('summary_lyapunov_final', ''))}"
        e = r.get("summary_max_abs_constraint_error")
        e = _fmt(max(e)) if isinstance(e, list) and e else ""
        click.echo(f"  {r['name']:<20} {r['status']:<8} {v:<24} {_fmt(r.get('summary_max_lyapunov_rate', '')):>14} "
                   f"{e:>11}  {r.get('summary_lyapunov_rate_check', '')}")
        if r["status"] != "success":
            click.echo(f"    {r.get('message', '')}")


@click.command("show")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
def show(files) -> None:
    """Print status, solver statistics and summary figures of FILE.h5...

    A chunk file of a sweep (--layout chunk) is shown as one line per run.
    """
    from rbstab.io.chunk import is_chunk_file
    from rbstab.io.hdf5 import NotAResultFile, read_summary

    bad = 0
    for path in files:
        try:
            if is_chunk_file(path):
                _show_chunk(path)
                continue
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
