"""The one place rbstab compiles code: numba's ``njit`` with an on-disk cache.

Every compiled function of rbstab is decorated with :func:`jit` (``numba.njit`` with
``cache=True``). Numba keys a cached function on its own source file only, so a change to
a function it calls in another file would leave a stale kernel in the cache; rbstab
therefore keeps its cache in a folder named after a digest of every source file that
compiles code (and of ``engine/tableaus.py`` and ``layout.py``, whose numbers the kernels
compile in as constants), their folder and numba's version: ``$NUMBA_CACHE_DIR/rbstab-<digest>`` if
that variable is set, else ``$XDG_CACHE_HOME/rbstab/numba-<digest>`` (``~/.cache``). A new version of
the code compiles once, into a new folder.

:func:`ensure_compiled` compiles the entry points (the integrator and the outputs) the first
time they are needed by a command, printing one line that says so (numba compiles them in
~10-20 s; later processes load them from the cache in ~0.5 s).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba
from numba.core import config as _numba_config

__all__ = ["jit", "CACHE_DIR", "cache_is_warm", "ensure_compiled"]

_PACKAGE = Path(__file__).resolve().parent
_MARKER = "from .jit import jit"
_MARKER_UP = "from ..jit import jit"
_WARM_FILE = "warm"
#: Files without compiled code whose module constants the kernels compile in.
_COMPILED_IN = ("engine/tableaus.py", "layout.py")


def _source_digest() -> str:
    # numba files its cache under each source's folder path, so a copy of rbstab elsewhere
    # (an installed one beside a checkout) is another cache: the path is part of the digest
    digest = hashlib.sha256(numba.__version__.encode() + str(_PACKAGE).encode())
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        name = path.relative_to(_PACKAGE).as_posix()
        compiles = _MARKER.encode() in text or _MARKER_UP.encode() in text
        if path.name == "jit.py" or name in _COMPILED_IN or compiles:
            digest.update(str(path.relative_to(_PACKAGE)).encode())
            digest.update(text)
    return digest.hexdigest()[:16]


def _cache_dir() -> Path:
    base = os.environ.get("NUMBA_CACHE_DIR")
    digest = _source_digest()
    if base:
        return Path(base) / f"rbstab-{digest}"
    home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return home / "rbstab" / f"numba-{digest}"


#: Folder of rbstab's compiled kernels (see the module docstring).
CACHE_DIR: Path = _cache_dir()
_numba_config.CACHE_DIR = str(CACHE_DIR)


def jit(*args, **kwargs):
    """``numba.njit(..., cache=True, error_model="numpy")``: compile a function of plain
    numbers and arrays (a division by zero gives inf or NaN, as in numpy).

    Used bare (``@jit``) or with numba's options. The physics' small functions are
    ``@jit(forceinline=True)``: LLVM inlines them into the kernels that call them (a
    right-hand side made of calls costs twice as much). Numba's own ``inline="always"``
    gives the same code but types and lowers each inlined call again: the engine's cold
    compile took ~1.3x as long (the outputs ~4x).
    """
    kwargs.setdefault("cache", True)
    kwargs.setdefault("error_model", "numpy")  # x / 0 is inf or NaN, as in numpy: no exception
    if args and callable(args[0]):
        return numba.njit(**kwargs)(args[0])
    return numba.njit(*args, **kwargs)


#: Kernel groups, each compiled (and marked warm in the cache) as a whole: the engine's
#: right-hand side, integrator and outputs; the sign law's event-driven integrator, which
#: only pure-sign-law runs need (parts of :func:`rbstab.engine.warm_up`).
GROUPS = {"engine": ("rates", "outputs"), "sign_law": ("switching",)}


def cache_is_warm(group: str = "engine") -> bool:
    """Whether this version's kernels of ``group`` (:data:`GROUPS`) are in :data:`CACHE_DIR`."""
    return (CACHE_DIR / (_WARM_FILE if group == "engine" else f"{_WARM_FILE}-{group}")).exists()


def _start_warm_up(parts: str):
    """A process running :func:`rbstab.engine.warm_up` (``parts``), or None if it cannot start."""
    import subprocess
    import sys

    code = f"from rbstab.engine import warm_up; warm_up({parts!r})"
    here = str(Path(__file__).resolve().parents[1])  # this rbstab, whatever the child's sys.path
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [here, os.environ.get("PYTHONPATH")]))}
    try:
        return subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None


def ensure_compiled(say=None, *, sign_law: bool = False) -> None:
    """Compile the engine's kernels into the cache unless that was done before.

    ``say``: called with one line (str) before a cold compile, e.g. ``click.echo`` to
    stderr; nothing is said when the cache is warm. ``sign_law``: also the sign law's
    integrator (:data:`GROUPS`). The parts are compiled in two processes at once (numba
    compiles on one core; each writes its own kernels into the cache folder).
    """
    cold = [g for g in ("engine", "sign_law") if (g == "engine" or sign_law) and not cache_is_warm(g)]
    if not cold:
        return
    import time

    if say is not None:
        say(f"rbstab: compiling the engine once (~30-60 s on 2 cores); cached in {CACHE_DIR}")
    start = time.perf_counter()
    from .engine import warm_up

    parts = [p for g in cold for p in GROUPS[g]]
    here, there = parts[:1], parts[1:]
    helper = _start_warm_up(",".join(there)) if there and (os.cpu_count() or 1) > 1 else None
    warm_up(",".join(here if helper is not None else parts))
    if helper is not None and helper.wait() != 0:
        warm_up(",".join(there))  # the second process failed: compile its parts here
    try:
        CACHE_DIR.mkdir(parents=True, exist_ok=True)
        for group in cold:
            marker = _WARM_FILE if group == "engine" else f"{_WARM_FILE}-{group}"
            (CACHE_DIR / marker).write_text(f"{time.perf_counter() - start:.1f} s\n")
    except OSError:  # a read-only cache still works, it only compiles again next time
        pass
