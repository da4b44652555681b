"""Atomic file writing: a temporary name in the target folder, renamed into place.

A reader (or a resumed sweep) therefore sees either the old file or the complete new one,
never a half-written file, whatever interrupts the writer (Ctrl-C, SIGTERM, SIGKILL, a
full disk). The temporary file's data are flushed to the device (``fsync``) before the
rename, and the folder after it, so that after a power loss the final name holds the old
file or the new one, never a file of the right name with missing data.

Temporaries are hidden files ``.<name>.<pid>@<host>.<random>.tmp``. One whose writer
raised is removed at once; one left by a killed writer (SIGKILL, power loss) is removed
by the next writer to the folder (:func:`remove_stale_temporaries`), which knows from its
name whether its writer still runs.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import socket
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = [
    "atomic_path",
    "write_bytes_atomic",
    "write_text_atomic",
    "file_mode",
    "remove_stale_temporaries",
    "check_free_space",
    "as_os_error",
    "describe_os_error",
    "LEGACY_TEMPORARY_AGE",
]

#: Age [s] after which a temporary without a writer's pid (rbstab < 0.2) is stale.
LEGACY_TEMPORARY_AGE = 3600.0
_HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:4]
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)@(?P<host>[0-9a-f]{4})\.[^./]+\.tmp(\.[A-Za-z0-9]+)?$")


def file_mode() -> int:
    """Permissions of a new file under the current umask (``mkstemp`` alone gives 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync_folder(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - a folder that cannot be opened (Windows)
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - file systems without directory fsync
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` when the block ends.

    ``suffix`` (e.g. ``".gif"``) ends the temporary's name, for a writer that reads the
    format from the name.

    The folder is created if missing. If the block raises (anything, KeyboardInterrupt
    included), the temporary file is removed and ``path`` is left untouched. The
    temporary file's data are fsynced before the rename, the folder after it.

    Raises
    ------
    OSError
        If the folder cannot be created or written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}@{_HOST}.", suffix=f".tmp{suffix}", dir=path.parent)
    try:
        os.fchmod(fd, file_mode())
        os.close(fd)
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror, str(path)) from None  # the file meant, not its temporary
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``Path(path)``."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (newlines as given); returns ``Path(path)``."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
    return Path(path)


def _writer_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike, *, everything: bool = False) -> int:
    """Remove the temporaries of writers that are gone from ``folder``; returns how many.

    A temporary of this host whose writer's pid no longer runs is stale (a pid reused by
    another process keeps it until that one ends: a temporary is never removed under a
    live writer); one of another host is left alone; one without a pid (rbstab < 0.2) is
    stale after :data:`LEGACY_TEMPORARY_AGE`. ``everything`` removes every temporary
    (for a caller that holds the folder's lock, e.g. a sweep).
    """
    n = 0
    now = time.time()
    try:
        candidates = [p for p in Path(folder).glob(".*.tmp*") if p.suffix == ".tmp" or _TEMPORARY.match(p.name)]
    except OSError:
        return 0
    for path in candidates:
        match = _TEMPORARY.match(path.name)
        try:
            if everything:
                stale = True
            elif match is not None:
                stale = match["host"] == _HOST and not _writer_alive(int(match["pid"]))
            else:
                stale = now - path.stat().st_mtime > LEGACY_TEMPORARY_AGE
            if stale and path.is_file():
                path.unlink()
                n += 1
        except OSError:
            continue
    return n


def check_free_space(folder: str | os.PathLike, n_bytes: int, what: str = "the file") -> None:
    """Raise ``OSError(ENOSPC)`` unless ``folder``'s file system has ``n_bytes`` free.

    Used before a writer hands data to HDF5, which must never meet a full disk itself
    (see :func:`rbstab.io.hdf5.write_run`).
    """
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):  # pragma: no cover - no statvfs: the write will tell
        return
    free = st.f_bavail * st.f_frsize
    if free < n_bytes:
        raise OSError(errno.ENOSPC, f"No space left on device: {what} needs ~{n_bytes / 2**20:.3g} MiB, "
                      f"{free / 2**20:.3g} MiB free", str(folder))


_HDF5_ERRNO = re.compile(r"errno = (\d+)")


def as_os_error(exc: BaseException, path: str | os.PathLike) -> OSError:
    """An HDF5 write failure (h5py raises ``RuntimeError`` or ``OSError`` with the errno in
    its text) as an ``OSError`` with that errno (``ENOSPC`` for a full disk)."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return exc
    match = _HDF5_ERRNO.search(str(exc))
    code = int(match.group(1)) if match else errno.EIO
    return OSError(code, os.strerror(code), str(path))


def describe_os_error(exc: OSError) -> str:
    """One line for an I/O failure: what failed, where, and what to do for the usual ones."""
    where = f" {exc.filename}" if exc.filename else ""
    reason = exc.strerror or str(exc)
    hints = {
        errno.ENOSPC: "free some space and run the same command again (finished results are kept)",
        errno.EDQUOT: "the disk quota is exhausted; free some space and run the same command again",
        errno.EROFS: "the file system is read-only; choose another output folder (-o)",
        errno.EACCES: "no permission to write there; choose another output folder (-o)",
        errno.EPERM: "no permission to write there; choose another output folder (-o)",
        errno.ENOTDIR: "a part of the output path is a file, not a folder; choose another output folder (-o)",
        errno.EEXIST: "a file is in the way of the output folder; choose another output folder (-o)",
        errno.ENAMETOOLONG: "the file name is too long for this file system; shorten the run's name",
    }
    hint = hints.get(exc.errno or 0)
    return f"cannot write{where}: {reason}" + (f"; {hint}" if hint else "")
