"""The files of studies: a netCDF-4 file per study (``sensitivity.nc``, ``tuning.nc``),
marked by its ``rbstab_study`` attribute; written atomically, read into memory."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import xarray as xr

from ..io.atomic import atomic_path

__all__ = ["study_kind", "read_study_file", "write_study_file", "check_same_inputs", "KINDS"]

#: Study kind -> its file in the study folder.
KINDS = {"sensitivity": "sensitivity.nc", "tuning": "tuning.nc"}


def _file(path: str | os.PathLike, kind: str | None = None) -> Path:
    """The study file meant by ``path``: itself, or the study file in a study folder."""
    p = Path(path)
    if not p.is_dir():
        return p
    names = [KINDS[kind]] if kind else list(KINDS.values())
    return next((p / n for n in names if (p / n).is_file()), p / names[0])


def study_kind(path: str | os.PathLike) -> str | None:
    """``"sensitivity"`` or ``"tuning"`` for a study's file or folder, else None."""
    p = _file(path)
    if not p.is_file() or p.suffix != ".nc":
        return None
    try:
        with h5py.File(p, "r") as f:
            value = f.attrs.get("rbstab_study")
    except OSError:
        return None
    value = value.decode() if isinstance(value, bytes) else value
    return value if value in KINDS else None


def read_study_file(path: str | os.PathLike, kind: str):
    """Read a study's file (or the study folder) of ``kind`` into memory (``attrs["path"]``:
    the file).

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If it is not a study file of ``kind``.
    """
    p = _file(path, kind)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    if study_kind(p) != kind:
        raise ValueError(f"{p}: not the file of a {kind} study (rbstab {'tune' if kind == 'tuning' else kind})")
    with xr.open_dataset(p, engine="h5netcdf") as ds:
        out = ds.load()
    out.attrs["path"] = str(p)
    return out


def write_study_file(ds, path: str | os.PathLike) -> Path:
    """Write a study's Dataset to ``path`` atomically (netCDF-4 by h5netcdf); its
    ``path`` attribute, if any, is left out."""
    with atomic_path(path) as tmp:
        out = ds.copy(deep=False)
        out.attrs = {k: v for k, v in ds.attrs.items() if k != "path"}
        out.to_netcdf(tmp, engine="h5netcdf")
    return Path(path)


def check_same_inputs(path: str | os.PathLike, expected: dict, *, overwrite: bool = False) -> None:
    """Refuse (:class:`rbstab.studies.StudyInputError`) to replace the study file ``path``
    when its attributes differ from ``expected`` (attribute -> the new study's value): a
    study of other inputs under the same name; the same inputs again resume it.
    Nothing is refused with ``overwrite``, or when there is no readable file."""
    from .design import StudyInputError  # design imports the config and the sweep: only when checked

    path = Path(path)
    if overwrite or not path.is_file():
        return
    try:
        with h5py.File(path, "r") as f:
            stored = {k: f.attrs.get(k) for k in expected}
    except OSError:
        return
    def text(value) -> str:  # an attribute as netCDF keeps it (bytes, a 1-element array) as text
        if hasattr(value, "tolist"):
            value = value.tolist()
        if isinstance(value, list) and len(value) == 1:
            value = value[0]
        return value.decode() if isinstance(value, bytes) else str(value)

    differ = [k for k, v in expected.items() if stored[k] is not None and text(stored[k]) != str(v)]
    if differ:
        raise StudyInputError([f"{path.parent} holds a study of other inputs ({', '.join(differ)} differ): not "
                               "replaced; --overwrite (overwrite=True) replaces it, -o DIR writes elsewhere, "
                               "--name NAME gives this study another folder (nothing was run)"])
