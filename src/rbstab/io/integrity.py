"""Checksums of result files and store files, and their verification.

Every file rbstab writes (a run's ``<name>.h5``, a sweep's ``runs/chunk-*.h5``) carries two
kinds of checksums, so that bytes changed after the file was written (a bad disk, a bad
copy, an editor) are found before they are used:

- **numbers**: every numeric dataset is written with HDF5's Fletcher-32 filter, a checksum
  of each chunk that HDF5 verifies on every read of it: a damaged chunk raises instead of
  returning wrong numbers, in every reader (h5py, h5netcdf, xarray, netCDF-C);
- **everything else**: the text (a store's ``config``, ``status``, ``message`` columns, the
  ``axis`` labels), every attribute (a run file's status, config and summary figures, the
  units) and the structure (each dataset's name, type, shape and filter) lie outside
  those chunks (HDF5 keeps strings in a heap without checksums); their SHA-256, the
  :func:`content_digest`, is the root attribute :data:`DIGEST_ATTR`.

:func:`verify_file` checks both: the digest, then every chunk of every numeric dataset
(read block by block, at most :data:`VERIFY_BLOCK_BYTES` at a time). A file written
before checksums existed (no :data:`DIGEST_ATTR`) is accepted as unverified.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from .hdf5 import NotAResultFile

__all__ = [
    "DIGEST_ATTR",
    "DamagedResultError",
    "content_digest",
    "verify_file",
    "verify_open_file",
    "fletcher32_chunks",
    "VERIFY_BLOCK_BYTES",
]

#: Root attribute holding the file's :func:`content_digest` (hex SHA-256).
DIGEST_ATTR = "rbstab_digest"
#: Most bytes of a dataset read at once by :func:`verify_file`.
VERIFY_BLOCK_BYTES = 32 * 2**20
#: Attributes left out of the digest: the digest itself, and the bookkeeping of dimension
#: scales (object references, whose values are file addresses). Names starting with
#: ``_`` (netCDF's ``_Netcdf4Dimid``, ``_FillValue`` ...) are left out as well.
_BOOKKEEPING = frozenset({DIGEST_ATTR, "DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME"})


class DamagedResultError(NotAResultFile):
    """A result or store file whose checksums do not match its content: it was changed
    after rbstab wrote it. Its runs must not be used (a sweep reruns them)."""


def fletcher32_chunks(shape: tuple[int, ...], itemsize: int = 8, target: int = 2**20) -> tuple[int, ...] | None:
    """Chunk shape for a Fletcher-32 dataset of ``shape`` (rows of at most ~``target``
    bytes per chunk, whole rows); None for an empty dataset (nothing to check)."""
    if not shape or 0 in shape:
        return None
    row = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    return (max(1, min(shape[0], target // max(row, 1))), *shape[1:])


def _canonical(value: Any) -> bytes:
    """Bytes of an attribute or text value, the same whichever way h5py returned it."""
    if isinstance(value, bytes):
        value = value.decode("utf-8", "surrogateescape")
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogateescape")
    array = np.asarray(value)
    if array.dtype.kind in "OSU":
        return b"a" + repr(array.shape).encode() + b"".join(
            _canonical(x) + b"\x1f" for x in array.ravel().tolist())
    return array.dtype.str.encode() + repr(array.shape).encode() + np.ascontiguousarray(array).tobytes()


def content_digest(f) -> str:
    """SHA-256 (hex) of what the Fletcher-32 chunks do not cover (module docstring).

    Parameters
    ----------
    f : h5py.File
        An open file (rbstab's files are flat: datasets at the root).
    """
    h = hashlib.sha256()

    def feed(tag: str, value: Any) -> None:
        h.update(tag.encode() + b"\x1e" + _canonical(value) + b"\x1d")

    def attributes(obj, where: str) -> None:
        for key in sorted(obj.attrs):
            if key not in _BOOKKEEPING and not key.startswith("_"):
                feed(f"{where}@{key}", obj.attrs[key])

    attributes(f, "/")
    for name in sorted(f):
        obj = f[name]
        if not hasattr(obj, "dtype"):  # a group: rbstab writes none
            feed(f"/{name}", "group")
            continue
        feed(f"/{name}", f"{obj.dtype.str} {obj.shape} fletcher32={bool(obj.fletcher32)}")
        attributes(obj, f"/{name}")
        if obj.dtype.kind in "OSU":
            feed(f"/{name}=", obj[...])
    return h.hexdigest()


def _read_all(dataset, name: str, path: str) -> None:
    """Read every chunk of a numeric dataset (HDF5 checks Fletcher-32 on each)."""
    try:
        if dataset.chunks is None or dataset.size == 0:
            dataset[...]
            return
        rows = max(1, VERIFY_BLOCK_BYTES // max(1, dataset.nbytes // max(dataset.shape[0], 1)))
        rows = max(dataset.chunks[0], rows - rows % dataset.chunks[0])
        for lo in range(0, dataset.shape[0], rows):
            dataset[lo : lo + rows]
    except OSError as exc:
        raise DamagedResultError(
            f"{path}: damaged: the data of '{name}' fail their checksum ({exc}); the file was changed "
            "after rbstab wrote it"
        ) from None


def verify_open_file(f, path: str | os.PathLike, *, data: bool = True) -> bool:
    """:func:`verify_file` of an open h5py file; returns whether it had checksums."""
    stored = f.attrs.get(DIGEST_ATTR)
    if stored is None:
        return False  # written before checksums: accepted, unverified
    stored = stored.decode() if isinstance(stored, bytes) else str(stored)
    try:
        actual = content_digest(f)
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise DamagedResultError(f"{path}: damaged: cannot read its attributes or text ({exc})") from None
    if actual != stored:
        raise DamagedResultError(
            f"{path}: damaged: its attributes, text or structure do not match their checksum "
            f"({DIGEST_ATTR}); the file was changed after rbstab wrote it"
        )
    if data:
        for name in sorted(f):
            obj = f[name]
            if hasattr(obj, "dtype") and obj.dtype.kind not in "OSU":
                _read_all(obj, name, str(path))
    return True


def verify_file(path: str | os.PathLike, *, data: bool = True) -> bool:
    """Verify a result or store file's checksums (module docstring).

    Parameters
    ----------
    path : path-like
    data : bool
        Also read every chunk of every numeric dataset (Fletcher-32); without it only the
        digest of the attributes, text and structure is checked (the numbers are then
        checked when they are read).

    Returns
    -------
    bool
        True when the file carried checksums and they match; False for a file written
        before checksums existed (accepted, unverified).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotAResultFile
        If it is not an HDF5 file.
    DamagedResultError
        If a checksum does not match.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such result file: {path}")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise NotAResultFile(f"{path}: not an HDF5 file ({exc})") from None
    with f:
        return verify_open_file(f, path, data=data)
