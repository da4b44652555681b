"""Options shared by several subcommands (one registry, as in rasterio's ``rio/options.py``)."""

from __future__ import annotations

import functools

import click

from rbstab.engine.registry import DEFAULT_ENGINE, ENGINES
from rbstab.warning_codes import WARNING_CODES

from ._common import check_engine
from .console import CONSOLE_KEY, Console

def key_of(text: str, option: str, *, suffix: str = "", prefix: str = "") -> None:
    """The key of an option's ``KEY=...`` value read by :func:`rbstab.config.paths.parse_key`
    (``prefix``, e.g. ``sweep.grid.``, and ``suffix``, e.g. ``:scale``, taken off first); a key that names nothing is refused in
    one line naming the option, its value, the wrong segment and what is allowed, before the
    command reads or writes anything. A value without ``=`` is left to the command."""
    from rbstab.config.paths import KeyPathError, parse_any_key  # heavy: pydantic

    key, sep, _ = str(text).partition("=")
    if not sep or not key.strip():
        return
    key = key.strip().removeprefix(prefix)
    if suffix and key.endswith(suffix):
        key = key[: -len(suffix)]
    try:
        parse_any_key(key)
    except KeyPathError as exc:
        raise click.ClickException(f"{option} {text!r}: {exc.problem}") from None


def keys_checked(option: str, *, suffix: str = ""):
    """A click callback checking the key of each ``KEY=...`` value of ``option`` (:func:`key_of`)."""

    def callback(ctx, param, values):
        for text in values or ():
            key_of(text, option, suffix=suffix)
        return values

    return callback


#: Prefixes of a sweep's ``--set`` overrides whose rest is a config key (the others name the spec's own keys).
_SWEEP_KEY_SECTIONS = ("sweep.grid.", "sweep.zip.", "sweep.random.params.")


def _overrides_checked(ctx, param, values):
    """--set: each override's config key (a sweep's ``sweep.grid.KEY=...`` too) checked by
    :func:`key_of`; an override without ``=`` or without a key refused alike, in one line."""
    from rbstab.config.paths import KeyPathError, parse_key  # heavy: pydantic

    for text in values or ():
        stripped = str(text).strip()
        key, sep, _ = stripped.partition("=")
        if not sep:
            raise click.ClickException(f"--set {text!r}: no '='; expected KEY.PATH=VALUE, e.g. simulation.t_end=1.5")
        if not key.strip():
            try:
                parse_key(key.strip())
            except KeyPathError as exc:
                raise click.ClickException(f"--set {text!r}: {exc.problem}") from None
        prefix = next((p for p in _SWEEP_KEY_SECTIONS if stripped.startswith(p)), None)
        if prefix is not None:
            key_of(text, "--set", prefix=prefix)
        elif not stripped.startswith("sweep."):
            key_of(text, "--set")
    return values


set_option = click.option(
    "--set",
    "overrides",
    multiple=True,
    callback=_overrides_checked,
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


def engine_option(**kwargs):
    """``--engine NAME``, a name of :data:`rbstab.engine.ENGINES` (each one's line in the help)."""
    lines = "; ".join(f"{engine.name}: {engine.summary}" for engine in ENGINES.values())
    return click.option("--engine", type=click.Choice(list(ENGINES)), default=None,
                        help=f"How runs are integrated (docs/performance.md): {lines}  [default: {DEFAULT_ENGINE}].",
                        **kwargs)


json_option = click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object per item to stdout (one line each); the text goes to stderr.",
)


def _no_warn_codes(ctx, param, values):
    """--no-warn values, upper-cased; a code that is not registered is a usage error."""
    codes = [v.strip().upper() for v in values if v.strip()]
    bad = [v for v in codes if v != "ALL" and v not in WARNING_CODES]
    if bad:
        raise click.BadParameter(f"found {', '.join(bad)}; expected a warning code ({', '.join(WARNING_CODES)}) "
                                 "or all (README, section Warnings)")
    return tuple(codes)


def console_options(command):
    """``-q/--quiet``, ``-v/--verbose`` and ``--no-warn CODE`` on a command (the decorator
    just above its ``def``: they come last in its ``--help``). The command finds its
    :class:`~rbstab_cli.console.Console` with :func:`~rbstab_cli.console.get_console`;
    Python warnings with a code raised while it runs go to it."""
    @functools.wraps(command)
    def wrapper(*args, quiet: int, verbose: int, no_warn: tuple, **kwargs):
        console = Console(verbose - quiet, no_warn, json=kwargs.get("as_json", False))
        click.get_current_context().meta[CONSOLE_KEY] = console
        with console.catching_warnings():
            return command(*args, **kwargs)

    options = [
        click.option("-q", "--quiet", count=True,
                     help="Print less: -q the results, warnings and errors (no notes or progress), -qq only errors "
                     "(and --json output)."),
        click.option("-v", "--verbose", count=True,
                     help="Print more: each warning's explanation, every run, solver statistics."),
        click.option("--no-warn", "no_warn", multiple=True, metavar="CODE", callback=_no_warn_codes,
                     envvar="RBSTAB_NO_WARN",
                     help="Silence the warnings of CODE (e.g. W001; all: every one). Repeatable; "
                     "also $RBSTAB_NO_WARN (codes separated by spaces). Codes: README, section Warnings."),
    ]
    for option in reversed(options):
        wrapper = option(wrapper)
    return wrapper


def _usable_engine(ctx, param, value):
    """``--engine NAME`` where it cannot run: one line, before the command starts."""
    check_engine(value)
    return value


def study_options(command):
    """Options of the commands that run studies (``sensitivity``, ``tune``): ``--vary``,
    ``--seed``, ``--name``, ``--set``, ``--engine``, ``-o``, ``--overwrite`` and ``--json``."""
    options = [
        click.option("--vary", "vary", multiple=True, required=True, metavar="KEY=DISTRIBUTION",
                     callback=keys_checked("--vary"),
                     help="A varied config key with a sweep distribution, e.g. body.mass=uniform:[30,50], "
                     "controller.k_c=scale_uniform:[0.5,2] (one factor scaling the whole gain); a chain's keys by "
                     "body or joint, e.g. joints.hip.k_r.0=uniform:[400,800]. Repeatable."),
        click.option("--seed", type=int, default=0, show_default=True, help="Seed of the sampler."),
        click.option("--name", default=None, help="The study's name and folder OUTPUT/NAME  [default: the config's name]."),
        set_option,
        engine_option(callback=_usable_engine),
        output_option("results/studies", "Parent folder; the study writes OUTPUT/<name>/."),
        click.option("--overwrite", is_flag=True,
                     help="Replace a study of other inputs in OUTPUT/<name>/ (without it: refused; the same "
                     "inputs again resume it)."),
        json_option,
    ]
    for option in reversed(options):
        command = option(command)
    return command
