"""The one place rbstab compiles code: numba's ``njit`` with an on-disk cache.

Every compiled function of rbstab is decorated with :func:`jit` (``numba.njit`` with
``cache=True``). Numba keys a cached function on its own source file only, so a change to
a function it calls in another file would leave a stale kernel in the cache; rbstab
therefore keeps its cache in a folder named after a digest of every source file of the
compiled layers (:data:`COMPILED_LAYERS`: the kinematics, model, variants and engine,
with the layout, summary and convergence modules and this one), their folder and numba's version:
``$NUMBA_CACHE_DIR/rbstab-<digest>`` if that variable is set, else
``$XDG_CACHE_HOME/rbstab/numba-<digest>`` (``~/.cache``). A new version of the code
compiles once, into a new folder.

:func:`cache_is_warm` and :func:`mark_warm` record which groups of kernels a cache folder
holds; the engine compiles them (:func:`rbstab.engine.ensure_compiled`).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba
from numba.core import config as _numba_config

__all__ = ["jit", "CACHE_DIR", "COMPILED_LAYERS", "compiled_sources", "cache_is_warm", "mark_warm"]

_PACKAGE = Path(__file__).resolve().parent
_WARM_FILE = "warm"
#: The compiled layers, relative to the package: every module that compiles code or whose
#: constants the kernels compile in (``engine/tableaus.py``, ``layout.py``'s offsets) is
#: one of them or inside one, however it imports :func:`jit`.
COMPILED_LAYERS = ("jit.py", "layout.py", "kinematics.py", "model.py", "summary.py", "convergence.py", "variants",
                   "engine")


def compiled_sources() -> list[Path]:
    """Every source file of :data:`COMPILED_LAYERS`, sorted: what the cache's digest covers."""
    files = []
    for name in COMPILED_LAYERS:
        path = _PACKAGE / name
        files.extend(path.rglob("*.py") if path.is_dir() else [path])
    return sorted(files)


def _source_digest() -> str:
    # numba files its cache under each source's folder path, so a copy of rbstab elsewhere
    # (an installed one beside a checkout) is another cache: the path is part of the digest
    digest = hashlib.sha256(numba.__version__.encode() + str(_PACKAGE).encode())
    for path in compiled_sources():
        digest.update(path.relative_to(_PACKAGE).as_posix().encode())
        digest.update(path.read_bytes())
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
    gives the same code but types and lowers each inlined call again: for those small
    functions, called from many places, the engine's cold compile took ~1.3x as long (the
    outputs ~4x). The driver's parts, each called from one place (a step attempt, a pass of
    the run's loop, a run), are ``@jit(inline="always")``: every function numba compiles
    on its own is optimised and emitted with everything it calls linked in, so a stack of
    ``forceinline`` parts compiles the driver once per level (a chain's driver took 2.7x
    as long that way, the one-body engine's 1.6x). Numba passes ``forceinline`` on to a
    function that does not set it when a ``forceinline`` caller compiles it first, and
    keeps that compilation for every later caller: a function that the driver's
    ``forceinline`` overloads call (:mod:`rbstab.engine.systems`) therefore says which it
    is, so that its code does not depend on which caller compiled it first (the tree's rate
    and admissible margin inlined into the steps; its impulses, rare, a call, compiled once
    rather than at each of the driver's three places that apply them).

    The functions a run's loops call with arrays (a step, a stage's rate, a sample's
    outputs, the admissible region, the overloads of :mod:`rbstab.engine.systems`) take
    numba's ``_nrt=False``: compiled without reference counting. A numba function counts a
    reference to every array it is passed on entry and drops it on exit, an atomic operation
    each, and a tree's system and scratch arrays are ~30-60 arrays: that counting took a
    third of a chain run's time (the knee example's integration 2.1x faster without it, a
    chain's outputs 3.5x with :func:`rbstab.variants.chain.chain_evaluate` inlined). Such a
    function allocates no array and returns none (numba refuses to compile an allocation
    there); the arrays it is passed outlive the call. The CUDA target counts no references.
    """
    kwargs.setdefault("cache", True)
    kwargs.setdefault("error_model", "numpy")  # x / 0 is inf or NaN, as in numpy: no exception
    if args and callable(args[0]):
        return numba.njit(**kwargs)(args[0])
    return numba.njit(*args, **kwargs)


def _marker(group: str) -> Path:
    return CACHE_DIR / (_WARM_FILE if group == "engine" else f"{_WARM_FILE}-{group}")


def cache_is_warm(group: str = "engine") -> bool:
    """Whether this version's kernels of ``group`` (``"engine"`` or ``"sign_law"``, the
    groups of :func:`rbstab.engine.ensure_compiled`) are in :data:`CACHE_DIR`."""
    return _marker(group).exists()


def mark_warm(group: str, note: str = "") -> None:
    """Record that the kernels of ``group`` are in :data:`CACHE_DIR` (``note``: the file's
    text, e.g. how long they took). A read-only cache is left as it is: it still works,
    the kernels are only compiled again next time."""
    try:
        CACHE_DIR.mkdir(parents=True, exist_ok=True)
        _marker(group).write_text(note)
    except OSError:
        pass
