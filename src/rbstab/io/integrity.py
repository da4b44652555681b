"""Checksums of result files and store files, and their verification.

Every file rbstab writes (a run's ``<name>.h5``, a sweep's ``runs/chunk-*.h5``) carries two
kinds of checksums, so that bytes changed after the file was written (a bad disk, a bad
copy, an editor) are found before they are used:

- **numbers**: every numeric dataset is written with HDF5's Fletcher-32 filter, a checksum
  of each chunk that HDF5 verifies on every read of it: a damaged chunk raises instead of
  returning wrong numbers, in every reader (h5py, h5netcdf, xarray, netCDF-C); and the
  SHA-256 of every numeric dataset's values, :func:`data_digest`, is the root attribute
  :data:`DATA_DIGEST_ATTR` (a damaged chunk *address* can make HDF5 read zeros past the
  end of the file, whose Fletcher-32 sum is zero too: found by random bit flips);
- **everything else**: the text (a store's ``config``, ``status``, ``message`` columns, the
  ``axis`` labels), every attribute (a run file's status, config and summary figures, the
  units) and the structure (each dataset's type, shape, chunks, filters and where its
  chunks are) lie outside those chunks (HDF5 keeps strings in a heap without
  checksums); their SHA-256, the :func:`content_digest`, is the root attribute
  :data:`DIGEST_ATTR`.

:func:`verify_file` checks the content digest and, with ``data``, reads every numeric
dataset block by block (at most :data:`VERIFY_BLOCK_BYTES` at a time: Fletcher-32 checked
by HDF5) and checks the data digest. A file written before checksums existed (no
:data:`DIGEST_ATTR`) is accepted as unverified.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "NotAResultFile",
    "DIGEST_ATTR",
    "DATA_DIGEST_ATTR",
    "DamagedResultError",
    "content_digest",
    "data_digest",
    "data_digest_of",
    "verify_file",
    "verify_open_file",
    "fletcher32_chunks",
    "VERIFY_BLOCK_BYTES",
    "reading",
    "open_result",
]

class NotAResultFile(ValueError):
    """Raised when a file is not an rbstab run result."""


#: Root attribute holding the file's :func:`content_digest` (hex SHA-256).
DIGEST_ATTR = "rbstab_digest"
#: Root attribute holding the file's :func:`data_digest` (hex SHA-256).
DATA_DIGEST_ATTR = "rbstab_data_digest"
#: Most bytes of a dataset read at once by :func:`verify_file`.
VERIFY_BLOCK_BYTES = 32 * 2**20
#: Attributes left out of the digest: the digest itself, and the bookkeeping of dimension
#: scales (object references, whose values are file addresses). Names starting with
#: ``_`` (netCDF's ``_Netcdf4Dimid``, ``_FillValue`` ...) are left out as well.
_BOOKKEEPING = frozenset({DIGEST_ATTR, DATA_DIGEST_ATTR, "DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME"})


class DamagedResultError(NotAResultFile):
    """A result or store file whose checksums do not match its content: it was changed
    after rbstab wrote it. Its runs must not be used (a sweep reruns them)."""


@contextmanager
def reading(path: str | os.PathLike) -> Iterator[None]:
    """Turn what h5py raises on a damaged file into :class:`DamagedResultError`.

    Wrap the reads of a file that opened as HDF5: a changed byte in its metadata makes
    h5py raise ``RuntimeError``, ``KeyError``, ``OSError``... instead of returning.
    """
    try:
        yield
    except (DamagedResultError, FileNotFoundError):
        raise
    except NotAResultFile:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError, AttributeError,
            UnicodeDecodeError) as exc:
        raise DamagedResultError(
            f"{path}: damaged: its HDF5 structure cannot be read ({type(exc).__name__}: {exc})"
        ) from None


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
    if array.dtype == np.dtype("S1") and array.ndim == 2:  # characters (run, string): their bytes
        return b"c" + repr(array.shape).encode() + np.ascontiguousarray(array).tobytes()
    if array.dtype.kind in "OSU":
        return b"a" + repr(array.shape).encode() + b"".join(_text_item(x) for x in array.ravel().tolist())
    return array.dtype.str.encode() + repr(array.shape).encode() + np.ascontiguousarray(array).tobytes()


def _text_item(x: Any) -> bytes:
    """``_canonical(x) + b"\\x1f"`` for an element of a text array (bytes decode and encode
    back to themselves under surrogateescape, so they are taken as they are)."""
    if type(x) is bytes:
        return b"s" + x + b"\x1f"
    if type(x) is str:
        return b"s" + x.encode("utf-8", "surrogateescape") + b"\x1f"
    return _canonical(x) + b"\x1f"


def _structure(dsid) -> str:
    """What HDF5 needs to decode a dataset's numbers (``dsid``: its h5py low-level id): its
    type (HDF5's encoding), shape, chunks, filters, and how many chunks are stored and
    their bytes (a chunk HDF5 believes unwritten would read as its fill value, with no
    checksum to fail)."""
    import h5py  # heavy: h5py

    dcpl = dsid.get_create_plist()
    chunks = dcpl.get_chunk() if dcpl.get_layout() == h5py.h5d.CHUNKED else None
    filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())] if chunks else []
    return (f"{dsid.get_type().encode().hex()} shape={dsid.shape} chunks={chunks} "
            f"filters={filters} stored={_chunk_places(dsid, chunks)} bytes={dsid.get_storage_size()}")


def _chunk_places(dsid, chunks) -> list:
    """(offset in the dataset, address in the file, size, filter mask) of each stored chunk:
    a chunk address changed to a place past the end of the file reads as zeros, whose
    Fletcher-32 checksum is zero too."""
    if not chunks:
        return []
    places: list = []
    record = lambda info: places.append((info.chunk_offset, info.byte_offset, info.size, info.filter_mask))  # noqa: E731
    try:
        dsid.chunk_iter(record)  # HDF5 >= 1.14: one pass over the chunk index
    except AttributeError:  # pragma: no cover - older HDF5: one lookup per chunk
        places = []
        for i in range(dsid.get_num_chunks()):
            record(dsid.get_chunk_info(i))
    return places


def _attribute_names(oid) -> list[str]:
    """The attribute names of an object (its h5py low-level id), sorted."""
    import h5py  # heavy: h5py

    names: list[str] = []
    h5py.h5a.iterate(oid, lambda name: names.append(name.decode("utf-8", "surrogateescape")))
    return sorted(names)


def _attribute(oid, key: str) -> Any:
    """An attribute's value through h5py's low-level API (``oid``: the object's id; twice as
    fast as ``obj.attrs[key]``, which matters for files of ~100 attributes); strings come
    back as bytes."""
    import h5py  # heavy: h5py

    aid = h5py.h5a.open(oid, key.encode("utf-8", "surrogateescape"))
    try:
        shape = aid.shape
        if shape is None:  # an empty (null) dataspace
            holder = h5py.Group(oid) if isinstance(oid, h5py.h5g.GroupID) else h5py.Dataset(oid)
            return holder.attrs[key]
        value = np.empty(shape, dtype=aid.dtype)
        aid.read(value)
        return value
    finally:
        aid.close()


def _text(dsid) -> np.ndarray:
    """The values of a text dataset (its low-level id), as ``dataset[...]`` gives them."""
    import h5py  # heavy: h5py

    if dsid.shape is None or 0 in dsid.shape:
        return h5py.Dataset(dsid)[...]
    value = np.empty(dsid.shape, dtype=dsid.dtype)
    dsid.read(h5py.h5s.ALL, h5py.h5s.ALL, value)
    return value


def content_digest(f, texts: Mapping[str, Any] | None = None,
                   attributes: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """SHA-256 (hex) of what the Fletcher-32 chunks do not cover (module docstring).

    Parameters
    ----------
    f : h5py.File
        An open file (rbstab's files are flat: datasets at the root).
    texts : mapping, optional
        Text dataset name -> the array of str just written to it: a writer's digest takes
        the text from there instead of reading it back (the same bytes: HDF5 stores str
        as UTF-8); readers leave it out.
    attributes : mapping, optional
        Object path (``"/"``, ``"/<dataset>"``) -> attribute name -> the array just
        written (a variable-length str, an int64 or float64 scalar): likewise taken instead
        of read back. Which attributes there are is always read from the file.

    Through h5py's low-level API (its high-level objects cost about as much as the reads).
    """
    import h5py  # heavy: h5py

    h = hashlib.sha256()

    def feed(tag: str, value: Any) -> None:
        h.update(tag.encode() + b"\x1e" + _canonical(value) + b"\x1d")

    def attributes_of(oid, where: str) -> None:
        known = attributes.get(where, {}) if attributes is not None else {}
        for key in _attribute_names(oid):
            if key not in _BOOKKEEPING and not key.startswith("_"):
                feed(f"{where}@{key}", known[key] if key in known else _attribute(oid, key))

    root = f["/"].id
    attributes_of(root, "/")
    for name in sorted(f):
        oid = h5py.h5o.open(root, name.encode("utf-8", "surrogateescape"))
        if not isinstance(oid, h5py.h5d.DatasetID):  # a group or a named type: rbstab writes none
            feed(f"/{name}", "Group" if isinstance(oid, h5py.h5g.GroupID) else "Datatype")
            continue
        feed(f"/{name}", _structure(oid))
        attributes_of(oid, f"/{name}")
        if oid.dtype.kind in "OSU":
            feed(f"/{name}=", texts[name] if texts is not None and name in texts else _text(oid))
    return h.hexdigest()


def _blocks(dataset):
    """The values of a dataset, block by block (whole chunks, ~VERIFY_BLOCK_BYTES each)."""
    if not dataset.shape or dataset.size == 0:
        yield dataset[()]
        return
    rows = max(1, VERIFY_BLOCK_BYTES // max(1, dataset.nbytes // dataset.shape[0]))
    if dataset.chunks:
        rows = max(dataset.chunks[0], rows - rows % dataset.chunks[0])
    for lo in range(0, dataset.shape[0], rows):
        yield dataset[lo : lo + rows]


def _digest_values(named) -> str:
    """SHA-256 of ``(name, dtype, shape, blocks of values)`` in the order given."""
    h = hashlib.sha256()
    for name, dtype, shape, blocks in named:
        h.update(f"{name}\x1e{np.dtype(dtype).str}{tuple(shape)}\x1d".encode())
        for block in blocks:
            h.update(np.ascontiguousarray(block, dtype=dtype))  # its buffer: no copy when contiguous
    return h.hexdigest()


def data_digest(f, path: str | os.PathLike = "") -> str:
    """SHA-256 (hex) of the values of every numeric dataset, by name, as HDF5 decodes them.

    Reads every chunk (so HDF5 checks each one's Fletcher-32 sum), at most
    :data:`VERIFY_BLOCK_BYTES` at a time.

    Raises
    ------
    DamagedResultError
        When a chunk fails its Fletcher-32 checksum.
    """
    import h5py  # heavy: h5py

    def checked(dataset, name):
        try:
            yield from _blocks(dataset)
        except OSError as exc:
            raise DamagedResultError(
                f"{path}: damaged: the data of '{name}' fail their checksum ({exc}); the file was changed "
                "after rbstab wrote it"
            ) from None

    def named():
        for name in sorted(f):
            dataset = f[name]
            if isinstance(dataset, h5py.Dataset) and dataset.dtype.kind not in "OSU":
                yield name, dataset.dtype, dataset.shape, checked(dataset, name)

    return _digest_values(named())


def data_digest_of(arrays) -> str:
    """:func:`data_digest` of the numeric arrays a writer is about to store (a mapping name ->
    array, the strings left out as the file's are): the same value, without reading back."""
    return _digest_values((name, np.asarray(arrays[name]).dtype, np.shape(arrays[name]), [arrays[name]])
                          for name in sorted(arrays) if np.asarray(arrays[name]).dtype.kind not in "OSU")


def verify_open_file(f, path: str | os.PathLike, *, data: bool = True) -> bool:
    """:func:`verify_file` of an open h5py file; returns whether it had checksums."""
    stored = f.attrs.get(DIGEST_ATTR)
    if stored is None:
        return False  # written before checksums: accepted, unverified
    stored = stored.decode() if isinstance(stored, bytes) else str(stored)
    try:
        actual = content_digest(f)
    except (OSError, RuntimeError, KeyError, ValueError, TypeError, AttributeError, IndexError) as exc:
        raise DamagedResultError(f"{path}: damaged: cannot read its attributes or text ({exc})") from None
    if actual != stored:
        raise DamagedResultError(
            f"{path}: damaged: its attributes, text or structure do not match their checksum "
            f"({DIGEST_ATTR}); the file was changed after rbstab wrote it"
        )
    if data:
        expected = f.attrs.get(DATA_DIGEST_ATTR)
        actual = data_digest(f, path)
        expected = expected.decode() if isinstance(expected, bytes) else expected
        if expected is not None and actual != str(expected):
            raise DamagedResultError(
                f"{path}: damaged: its numbers do not match their checksum ({DATA_DIGEST_ATTR}); the file was "
                "changed after rbstab wrote it"
            )
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
    with open_result(path) as f:
        return verify_open_file(f, path, data=data)


@contextmanager
def open_result(path: str | os.PathLike) -> Iterator[Any]:
    """An rbstab file open for reading (an ``h5py.File``), its reads wrapped in :func:`reading`.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NotAResultFile
        If it is not an HDF5 file.
    DamagedResultError
        For what h5py raises on a damaged file while the block reads it.
    """
    import h5py  # heavy: h5py

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such result file: {path}")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise NotAResultFile(f"{path}: not an HDF5 file ({exc})") from None
    with reading(path), f:
        yield f
