"""What a command prints and where: one :class:`Console` per command.

Streams: the command's own output (result lines, ``rbstab show``'s summaries) on stdout;
warnings, notes and progress on stderr. With ``--json`` stdout holds only JSON objects,
one per line and per item, and the text goes to stderr.

Verbosity (``-v`` minus ``-q``): -2 errors only (and ``--json`` objects); -1 the output
(results: stdout) and warnings, without notes and progress; 0 (default) notes too; 1 details (a warning's explanation, every run of a
sweep, solver statistics).

Warnings carry a code (:mod:`rbstab.warning_codes`); each distinct one is printed once
per command, in one line, unless ``--no-warn CODE`` (or ``all``) silenced it.
"""

from __future__ import annotations

import contextlib
import json
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import click

from rbstab.warning_codes import WARNING_CODES, code_of, split_code

#: Key of the command's Console in ``click.Context.meta``.
CONSOLE_KEY = "rbstab.console"


class Console:
    """Printing for one command (see the module docstring).

    Parameters
    ----------
    verbosity : int
        ``verbose - quiet``.
    silenced : iterable of str
        Warning codes not to print (``"all"``: none).
    json : bool
        stdout is for JSON objects only.
    """

    def __init__(self, verbosity: int = 0, silenced: Iterable[str] = (), json: bool = False) -> None:
        self.verbosity = verbosity
        self.silenced = {c.upper() for c in silenced}
        self.json = json
        self._seen: set[str] = set()
        self._explained: set[str] = set()

    def out(self, line: str = "") -> None:
        """The command's output: stdout (stderr with ``--json``); kept by ``-q`` (but with
        ``--json``, whose objects hold it), hidden by ``-qq``."""
        if self.verbosity >= (0 if self.json else -1):
            click.echo(line, err=self.json)

    def detail(self, line: str) -> None:
        """Output shown with ``-v`` only."""
        if self.verbosity >= 1:
            click.echo(line, err=self.json)

    def info(self, line: str) -> None:
        """A note or progress message: stderr; hidden by ``-q``."""
        if self.verbosity >= 0:
            click.echo(line, err=True)

    def emit(self, obj: dict[str, Any]) -> None:
        """One JSON object on one line of stdout (with ``--json``; always, even with ``-q``)."""
        click.echo(json.dumps(plain_json(obj), default=str, allow_nan=False))

    def silences(self, code: str | None) -> bool:
        """Whether warnings of ``code`` are silenced (``--no-warn``)."""
        return code is not None and ("ALL" in self.silenced or code in self.silenced)

    def warn(self, text: str, where: str = "") -> None:
        """Print a coded warning once per command: ``warning: W001 body.inertia: ... (where)``.

        ``text`` may hold something before its code (``"case1.yaml: W001 ..."``, ``"6 of 6
        runs: W001 ..."``): it goes to the end, in parentheses, with ``where``.
        """
        code, before, message = split_code(text)
        if self.silences(code) or self.verbosity < -1 or message in self._seen:
            return
        self._seen.add(message)
        context = ", ".join(p for p in (before.strip().rstrip(":"), where) if p)
        click.echo(f"warning: {message}" + (f" ({context})" if context else ""), err=True)
        if code is not None and self.verbosity >= 1 and code not in self._explained:
            self._explained.add(code)
            click.echo(f"  {code}: {WARNING_CODES[code].explanation}; --no-warn {code} silences it", err=True)

    @contextlib.contextmanager
    def catching_warnings(self) -> Iterator[None]:
        """Python warnings with a code (:mod:`rbstab.warning_codes`) go to :meth:`warn`,
        every time they are raised (the console prints each once). Others (a library's
        numerical warning, e.g. scipy's or numpy's RuntimeWarning) are no finding of rbstab's:
        with ``-v`` one line each, once; otherwise not shown (what they would have said
        about the physics, rbstab's own warnings and messages say)."""
        with warnings.catch_warnings():
            warnings.filterwarnings("always", message=r".*\bW\d{3}\b")

            def show(message, category, filename, lineno, file=None, line=None) -> None:
                if code_of(str(message)) is not None:
                    self.warn(str(message))
                    return
                text = " ".join(str(message).split())
                if self.verbosity >= 1 and text not in self._seen:
                    self._seen.add(text)
                    click.echo(f"note: {category.__name__} from {Path(filename).name}:{lineno}: {text}", err=True)

            warnings.showwarning = show
            yield


def get_console() -> Console:
    """The running command's Console (a default one outside a command)."""
    ctx = click.get_current_context(silent=True)
    console = ctx.meta.get(CONSOLE_KEY) if ctx is not None else None
    return console if console is not None else Console()


def plain_json(value: Any) -> Any:
    """``value`` with numpy values as Python ones and NaN and infinities as None (JSON has
    neither), recursively."""
    if isinstance(value, float):
        return value if value == value and abs(value) != float("inf") else None
    if isinstance(value, dict):
        return {k: plain_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_json(v) for v in value]
    if hasattr(value, "tolist"):
        return plain_json(value.tolist())
    return value
