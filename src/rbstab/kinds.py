"""The kinds of input rbstab reads, and the one registry that tells them apart.

- ``run``: a run's result file (``rbstab run``: ``<name>.h5``), loaded by
  :func:`rbstab.io.hdf5.read_dataset`; ``chain_run``: a chain run's, the same way;
- ``store``: a sweep's store file of many runs (``runs/chunk-*.h5``), loaded by
  :func:`rbstab.io.chunk.read_chunk_rows`;
- ``sweep``: a sweep folder (``sweep.yaml`` and ``index.csv``), loaded by
  :func:`rbstab.sweep.folder.open_sweep`;
- ``analysis``: an analysis file (``rbstab analyze``: ``*.analysis.nc``), loaded by
  :func:`rbstab.analysis.dataset.read_analysis`;
- ``sensitivity``, ``tuning``: a study's file (``sensitivity.nc``, ``tuning.nc``) or its
  folder (``rbstab sensitivity``, ``rbstab tune``), loaded by :mod:`rbstab.studies`.

As xarray's backends do, each kind is a ``can_open`` test and a loader (:class:`InputKind`),
and :func:`kind_of` dispatches: the first kind whose ``can_open`` says yes. ``rbstab show``,
``rbstab report`` and :func:`rbstab.open_result` go through it, each with the kinds it
takes; a path none of them can open is refused with what it is (not an HDF5 file, an HDF5
file rbstab did not write, another kind, a folder that is not a sweep folder).

The ``can_open`` tests and loaders belong to the module that writes each format (the
run-file writer :mod:`rbstab.io.hdf5`, the store writer :mod:`rbstab.io.chunk`, the sweep
folder's reader and writer :mod:`rbstab.sweep.folder`, the analysis writer
:mod:`rbstab.analysis.dataset`): the file kinds tell themselves apart by their
``rbstab_format`` attribute, a sweep folder by its two files. This module only lists
them, so it sits above the io, sweep and analysis layers and below the report and the CLI
that use it; :func:`rbstab.sweep.folder.open_sweep`, the sweep kind's loader, checks its
input with its own format's test (:func:`rbstab.sweep.folder.is_sweep_folder`).

A plain folder (neither a sweep folder nor an incomplete one: :func:`is_plain_folder`)
stands for the inputs in it: :func:`inputs_in` lists the files whose names match a kind's
pattern (every one, so that a bad file is reported rather than skipped) and the folders a
folder kind can open.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .io.chunk import is_chunk_file, read_chunk_rows
from .io.hdf5 import NotAResultFile, is_chain_run_file, is_run_file, read_dataset, read_format
from .sweep.folder import INDEX_FILE, SPEC_FILE, has_index, is_sweep_folder, open_sweep

__all__ = ["InputKind", "RUN", "CHAIN_RUN", "STORE", "SWEEP", "ANALYSIS", "SENSITIVITY", "TUNING", "KINDS", "kind_of", "open_input", "is_plain_folder",
           "inputs_in"]


@dataclass(frozen=True)
class InputKind:
    """One kind of input.

    Attributes
    ----------
    name : str
        ``run``, ``store``, ``sweep`` or ``analysis`` (the ``kind`` of ``rbstab show
        --json``).
    noun : str
        What it is, in words (``run result`` ...).
    hint : str
        How to read it, for a command that does not take it.
    pattern : str or None
        Names of such files in a plain folder (a glob); None for a folder kind.
    can_open : callable
        ``can_open(path) -> bool``; never raises.
    open : callable
        ``open(path)``: the loader (its errors: the file is damaged, not complete ...).
    """

    name: str
    noun: str
    hint: str
    pattern: str | None
    can_open: Callable[[Path], bool]
    open: Callable[[Path], Any]


def _is_analysis_file(path: Path) -> bool:
    # late import: the rbstab.analysis package imports the compiler (numba, ~0.5 s), which
    # reading run files, stores and sweeps does not need
    from .analysis.dataset import is_analysis_file

    return is_analysis_file(path)


def _read_analysis(path: Path):
    # late import: as in _is_analysis_file (numba)
    from .analysis.dataset import read_analysis

    return read_analysis(path)


RUN = InputKind("run", "run result", "rbstab show or rbstab.open_result read it", "*.h5", is_run_file, read_dataset)
CHAIN_RUN = InputKind("chain_run", "chain run result",
                      "rbstab show, report, animate or rbstab.open_result read it", "*.h5",
                      is_chain_run_file, read_dataset)
STORE = InputKind("store", "store file of a sweep (many runs)",
                  "open its sweep folder with rbstab.open_sweep(folder), or rbstab show it", "*.h5", is_chunk_file,
                  read_chunk_rows)
SWEEP = InputKind("sweep", "sweep folder", "rbstab show or rbstab.open_sweep read it", None, is_sweep_folder,
                  open_sweep)
ANALYSIS = InputKind("analysis", "analysis file", "rbstab report shows it", "*.analysis.nc", _is_analysis_file,
                     _read_analysis)


def _study_test(name: str) -> Callable[[Path], bool]:
    def can_open(path: Path) -> bool:
        from .studies.files import study_kind  # heavy: xarray

        return study_kind(path) == name

    return can_open


def _read_sensitivity(path: Path):
    from .studies import read_sensitivity  # heavy: xarray, pandas

    return read_sensitivity(path)


def _read_tuning(path: Path):
    from .studies import read_tuning  # heavy: xarray, pandas

    return read_tuning(path)


SENSITIVITY = InputKind("sensitivity", "sensitivity study (its sensitivity.nc or folder)", "rbstab report draws it",
                        "sensitivity.nc", _study_test("sensitivity"), _read_sensitivity)
TUNING = InputKind("tuning", "tuning study (its tuning.nc or folder)", "rbstab report draws it", "tuning.nc",
                   _study_test("tuning"), _read_tuning)
#: Every kind, in the order :func:`kind_of` tries them.
KINDS = (RUN, CHAIN_RUN, STORE, SWEEP, ANALYSIS, SENSITIVITY, TUNING)


def _a(noun: str) -> str:
    return f"{'an' if noun[0] in 'aeiou' else 'a'} {noun}"


def _nouns(kinds: Sequence[InputKind]) -> str:
    nouns = [k.noun for k in kinds]
    return nouns[0] if len(nouns) == 1 else f"{', '.join(nouns[:-1])} or {nouns[-1]}"


def kind_of(path: str | os.PathLike, kinds: Sequence[InputKind] = KINDS) -> InputKind:
    """The kind of ``path``: the first of ``kinds`` that can open it.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    rbstab.io.hdf5.NotAResultFile
        If none of ``kinds`` can open it; the message says what it is: not an HDF5 file,
        an HDF5 file without rbstab's ``rbstab_format`` attribute, another kind (and how
        to read it), a folder that is not a sweep folder or an incomplete one.
        :class:`rbstab.io.integrity.DamagedResultError` (a subclass) for a file whose
        attributes cannot be read.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such result file or folder: {p}")
    for kind in kinds:
        if kind.can_open(p):
            return kind
    other = next((k for k in KINDS if k not in kinds and k.can_open(p)), None)
    if other is not None:
        raise NotAResultFile(f"{p}: {_a(other.noun)}, not {_a(_nouns(kinds))}; {other.hint}")
    if p.is_dir():
        spec, index = (p / SPEC_FILE).is_file(), has_index(p)
        if SWEEP not in kinds:
            raise NotAResultFile(f"{p}: a folder, not {_a(_nouns(kinds))}")
        if spec != index:
            lacking = INDEX_FILE if spec else SPEC_FILE
            raise NotAResultFile(f"{p}: incomplete sweep folder (no {lacking})")
        raise NotAResultFile(f"{p}: a folder, but not a sweep folder (no {SPEC_FILE} and {INDEX_FILE})")
    found = read_format(p)  # raises for a file that is not HDF5 or is damaged, in the reader's words
    what = ("an HDF5 file without an rbstab_format attribute" if found is None
            else f"rbstab_format {found!r}, of no kind this version reads")
    raise NotAResultFile(f"{p}: not an rbstab {_nouns(kinds)} ({what})")


def open_input(path: str | os.PathLike, kinds: Sequence[InputKind] = KINDS) -> Any:
    """``path`` read by the loader of its kind (:func:`kind_of`, whose errors it raises,
    and the loader's)."""
    return kind_of(path, kinds).open(Path(path))


def is_plain_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a folder that is not an input itself: neither a sweep folder
    nor an incomplete one (it holds no ``sweep.yaml`` and no index)."""
    p = Path(path)
    return p.is_dir() and not (p / SPEC_FILE).is_file() and not has_index(p)


def inputs_in(folder: str | os.PathLike, kinds: Sequence[InputKind] = KINDS) -> list[Path]:
    """The inputs of ``kinds`` in a plain folder (not recursive), sorted by name: every
    file whose name matches a kind's pattern (whether or not it can be opened, so that a
    bad file is reported, not skipped) and every sub-folder a folder kind can open."""
    folder = Path(folder)
    patterns = {k.pattern for k in kinds if k.pattern is not None}
    folders = [k for k in kinds if k.pattern is None]
    found = {p for pattern in patterns for p in folder.glob(pattern) if p.is_file()}
    found |= {p for p in folder.iterdir() if p.is_dir() and any(k.can_open(p) for k in folders)} if folders else set()
    return sorted(found, key=str)
