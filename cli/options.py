"""Options shared by several subcommands (one registry, as in rasterio's ``rio/options.py``)."""

from __future__ import annotations

import click

set_option = click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="KEY.PATH=VALUE",
    help="Override a config key (dotted path; YAML-typed value), e.g. "
    "--set simulation.t_end=1.5 --set controller.k_t=[1,2,3]. Repeatable.",
)

method_option = click.option(
    "--method",
    default=None,
    metavar="METHOD",
    help="scipy solve_ivp method (RK23, RK45, DOP853, Radau, BDF, LSODA); "
    "same as --set simulation.method=METHOD.",
)


def output_option(default: str, help_text: str):
    """``-o/--output DIR`` with a command-specific default."""
    return click.option(
        "-o",
        "--output",
        "output",
        type=click.Path(file_okay=False, writable=True),
        default=default,
        show_default=True,
        help=help_text,
    )
