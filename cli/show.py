"""``rbstab show``: print the summary of result files."""

from __future__ import annotations

import click


def _fmt(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:.6g}" for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


#: Most runs listed for a sweep folder (the index has all).
_MAX_LISTED = 50


def _run_lines(rows) -> None:
    """One line per run: id, status, v(0) -> v(t_end), max dv/dt, max |E_i|, rate check."""
    click.echo(f"  {'run':<20} {'status':<8} {'v(0) -> v(t_end) [J]':<24} {'max dv/dt [W]':>14} "
               f"{'max|E| [m]':>11}  rate check")
    for r in rows:
        v = f"{_fmt(r.get('lyapunov_initial', ''))} -> {_fmt(r.get('lyapunov_final', ''))}"
        e = [r.get(f"max_abs_constraint_error_{a}") for a in "xyz"]
        e = _fmt(max(abs(float(x)) for x in e)) if all(isinstance(x, (int, float)) for x in e) else ""
        switchings = [r.get(f"switching_count_{a}") for a in "xyz"]  # the pure sign law of sliding
        located = (f"  {int(sum(switchings))} switchings"
                   if all(isinstance(x, (int, float)) and x == x for x in switchings) else "")
        click.echo(f"  {r['run_id']:<20} {r['status']:<8} {v:<24} {_fmt(r.get('max_lyapunov_rate', '')):>14} "
                   f"{e:>11}  {r.get('lyapunov_rate_check', '')}{located}")
        if r["status"] != "success":
            click.echo(f"    {r.get('message', '')}")


def _show_chunk(path: str) -> None:
    """One line per run of a store file (``rbstab sweep``, layout chunk)."""
    from rbstab.io.chunk import read_chunk_rows

    rows = read_chunk_rows(path, data=True)  # every checksum verified
    first = rows[0] if rows else {}
    click.echo(f"{path}")
    click.echo(f"  store file: {len(rows)} runs, store {first.get('store', '?')}, created {first.get('created', '?')}")
    _run_lines(rows)


def _show_sweep(path: str) -> None:
    """Counts per status and one line per run (the first :data:`_MAX_LISTED`) of a sweep folder."""
    from rbstab.sweep.folder import read_index, read_spec

    index = read_index(path)
    counts = index["status"].value_counts().to_dict()
    click.echo(f"{path}")
    click.echo(f"  sweep {read_spec(path).get('name', '?')}: {len(index)} runs, "
               + ", ".join(f"{n} {s}" for s, n in counts.items())
               + f"; converged {int(index['converged'].astype(str).eq('True').sum())}")
    rows = index.head(_MAX_LISTED).to_dict("records")
    _run_lines([{k: ("" if isinstance(v, float) and v != v else v) for k, v in r.items()} for r in rows])
    if len(index) > _MAX_LISTED:
        click.echo(f"  ... and {len(index) - _MAX_LISTED} more runs (see index.csv, or rbstab.open_sweep)")


@click.command("show")
@click.argument("files", nargs=-1, required=True, type=click.Path())
def show(files) -> None:
    """Print status, solver statistics and summary figures of FILE.h5... or sweep folders.

    A store file of a sweep, or a sweep folder, is shown as one line per run.
    """
    from rbstab.io.chunk import is_chunk_file
    from rbstab.io.hdf5 import NotAResultFile, read_summary
    from rbstab.sweep.folder import is_sweep_folder

    bad = 0
    for path in files:
        try:
            if is_sweep_folder(path):
                _show_sweep(path)
                continue
            if is_chunk_file(path):
                _show_chunk(path)
                continue
            info = read_summary(path)
        except (OSError, ValueError) as exc:  # FileNotFoundError, NotAResultFile, DamagedResultError ...
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
