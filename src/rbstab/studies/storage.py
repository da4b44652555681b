"""Where a tuning study is kept: Optuna's journal storage in an SQLite file, or any Optuna URL.

By default a study lives in ``<output>/<name>/journal.db``: Optuna's
:class:`~optuna.storages.JournalStorage` (every change to the study is a log record, the
study the replay of its records) over :class:`SQLiteJournal`, a journal backend
(:class:`optuna.storages.journal.BaseJournalBackend`) that keeps the records in one table
of an SQLite file in write-ahead-log mode. Several processes append to one file (SQLite's
lock orders them) and each replays what the others appended. A generation of trials is
appended in one transaction (:meth:`SQLiteJournal.transaction`): it is in the file whole or
not at all, even when the process is killed, and it costs one commit instead of one
per trial. Optuna's relational storage on SQLite writes a trial in ~15 statements of its
object-relational mapping (~5 ms of CPU a trial, ~1 s for 240 trials); the journal writes
240 trials in ~0.03 s.

A folder holding ``study.db`` (Optuna's relational schema) and no ``journal.db`` is a study
of that kind, and resumes in it; ``--storage URL`` names any Optuna storage (``sqlite:///``,
``postgresql://``, ...). :func:`optuna_storage` opens a study folder's storage for Optuna's
own tools (``optuna.load_study``, its plots).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import sqlite3
import threading
from pathlib import Path
from typing import Any

import optuna  # ~1 s to import: this module is imported when a study runs
from optuna.storages.journal import BaseJournalBackend

from .design import StudyInputError

__all__ = ["JOURNAL_FILE", "RDB_FILE", "SQLiteJournal", "default_storage", "is_journal", "open_storage",
           "optuna_storage", "storage_lock"]

#: The default storage of a study folder: Optuna's journal in an SQLite file.
JOURNAL_FILE = "journal.db"
#: Optuna's relational storage in an SQLite file (the URL ``sqlite:///<folder>/study.db``).
RDB_FILE = "study.db"


class SQLiteJournal(BaseJournalBackend):
    """Optuna journal backend keeping the log records in an SQLite file (module docstring).

    Records are rows ``(number, log)`` of the table ``journal``; ``number`` counts from 1
    in the order appended (an ``INTEGER PRIMARY KEY``: one more than the largest, given
    under SQLite's write lock), the record numbered n is Optuna's log n - 1.

    Parameters
    ----------
    path : str or PathLike
        The SQLite file (made if missing).
    timeout : float
        Seconds to wait for another process's write lock.
    """

    def __init__(self, path: str | os.PathLike, timeout: float = 60.0) -> None:
        self.path = Path(path)
        self._connection = sqlite3.connect(self.path, timeout=timeout, isolation_level=None, check_same_thread=False)
        if self._connection.execute("PRAGMA journal_mode").fetchone()[0] != "wal":
            self._connection.execute("PRAGMA journal_mode=WAL")  # readers do not wait for a writer
        self._connection.execute("PRAGMA synchronous=NORMAL")  # a commit costs no fsync; a crash loses, never corrupts
        self._connection.execute("CREATE TABLE IF NOT EXISTS journal (number INTEGER PRIMARY KEY, log TEXT NOT NULL)")
        self._lock = threading.RLock()
        self._open = False  # inside transaction(): appends wait for its commit

    def read_logs(self, log_number_from: int) -> list[dict[str, Any]]:
        """The records from Optuna's log ``log_number_from`` on (this process's uncommitted
        ones included, inside :meth:`transaction`)."""
        with self._lock:
            rows = self._connection.execute("SELECT log FROM journal WHERE number > ? ORDER BY number",
                                            (int(log_number_from),)).fetchall()
        return [json.loads(text) for (text,) in rows]

    def append_logs(self, logs: list[dict[str, Any]]) -> None:
        """Append ``logs`` in one transaction (or in the open :meth:`transaction`)."""
        rows = [(json.dumps(log, separators=(",", ":")),) for log in logs]
        with self._lock:
            if self._open:
                self._connection.executemany("INSERT INTO journal (log) VALUES (?)", rows)
                return
            self._connection.execute("BEGIN IMMEDIATE")
            try:
                self._connection.executemany("INSERT INTO journal (log) VALUES (?)", rows)
            except BaseException:
                self._connection.execute("ROLLBACK")
                raise
            self._connection.execute("COMMIT")

    @contextlib.contextmanager
    def transaction(self):
        """Append everything of the block in one transaction, holding the file's write lock
        (other processes' appends wait): committed at the end, rolled back on an exception.
        After a rollback the Optuna storage of this backend no longer matches the file
        (it replayed the rolled-back records): open it again."""
        with self._lock:
            self._connection.execute("BEGIN IMMEDIATE")
            self._open = True
            try:
                yield
            except BaseException:
                self._connection.execute("ROLLBACK")
                raise
            else:
                self._connection.execute("COMMIT")
            finally:
                self._open = False

    def close(self) -> None:
        self._connection.close()


def default_storage(folder: Path) -> str:
    """The storage of the study folder ``folder``: its ``study.db`` URL where it holds that
    and no journal (a study made in Optuna's relational schema resumes there), else the path
    of its ``journal.db``."""
    if (folder / RDB_FILE).is_file() and not (folder / JOURNAL_FILE).is_file():
        return f"sqlite:///{(folder / RDB_FILE).resolve()}"
    return str((folder / JOURNAL_FILE).resolve())


def is_journal(storage: str) -> bool:
    """Whether ``storage`` (a URL or a path) is an SQLite journal file: a path, no URL."""
    return "://" not in storage and storage != "memory"


def open_storage(storage: str) -> tuple[Any, SQLiteJournal | None]:
    """(Optuna's storage ``storage``, its :class:`SQLiteJournal` or None): a path is an
    SQLite journal (:class:`SQLiteJournal` under :class:`optuna.storages.JournalStorage`);
    a URL an Optuna relational storage (an SQLite URL's file in write-ahead-log mode,
    synchronised at checkpoints); ``"memory"``: None (an in-memory study).

    Raises
    ------
    StudyInputError
        If no storage can be opened there (the message names it).
    """
    if storage == "memory":
        return None, None
    if is_journal(storage):
        try:
            with storage_lock(storage):
                journal = SQLiteJournal(storage)
                return optuna.storages.JournalStorage(journal), journal
        except sqlite3.Error as exc:
            raise StudyInputError([f"{storage}: cannot open it as a study's journal ({exc})"]) from None
    import sqlalchemy.exc  # heavy: sqlalchemy (optuna's relational storage)

    kwargs = {}
    if storage.startswith("sqlite:///"):
        path = storage[len("sqlite:///"):]

        def connect():
            connection = sqlite3.connect(path, timeout=60, check_same_thread=False)
            connection.execute("PRAGMA journal_mode=WAL")
            connection.execute("PRAGMA synchronous=NORMAL")
            return connection

        kwargs = {"engine_kwargs": {"creator": connect}}
    try:
        with storage_lock(storage):
            return optuna.storages.RDBStorage(storage, **kwargs), None
    except sqlalchemy.exc.SQLAlchemyError as exc:
        raise StudyInputError([f"--storage {storage!r}: cannot open it ({str(exc).splitlines()[0]})"]) from None
    except (ValueError, ImportError) as exc:
        raise StudyInputError([f"--storage {storage!r}: {exc}; expected an Optuna storage URL, e.g. "
                               "sqlite:///study.db or postgresql://user@host/db"]) from None


def optuna_storage(folder: str | os.PathLike):
    """The Optuna storage of a study folder (``OUTPUT/<name>``: its ``journal.db``, or its
    ``study.db``), for Optuna's tools::

        study = optuna.load_study(study_name="case2", storage=optuna_storage("results/studies/case2"))

    Raises
    ------
    FileNotFoundError
        If the folder holds neither.
    """
    folder = Path(folder)
    if not (folder / JOURNAL_FILE).is_file() and not (folder / RDB_FILE).is_file():
        raise FileNotFoundError(f"{folder}: no {JOURNAL_FILE} or {RDB_FILE} (a tuning study's storage)")
    return open_storage(default_storage(folder))[0]


@contextlib.contextmanager
def storage_lock(storage: str):
    """Hold ``<file>.lock`` beside an SQLite file (a journal or an ``sqlite:///`` URL's):
    while its storage is opened (two processes that start one study at once would both make
    its tables; Optuna's relational storage does not guard that), and while a process reads
    the stored trials and writes the study's files (so the last process to write them
    writes every trial: its own are stored before, and so are those of a process that
    wrote before it). Other storages: nothing."""
    if storage.startswith("sqlite:///"):
        path = Path(storage[len("sqlite:///"):] + ".lock")
    elif is_journal(storage):
        path = Path(storage + ".lock")
    else:
        yield
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
