"""CF attributes and provenance of the files rbstab writes (rbstab.io.metadata).

Every variable of a run file and of a sweep store file has a ``long_name`` and, when it
holds numbers, ``units``; every summary figure has units; every file says ``Conventions =
"CF-1.10"`` and records the git commit with a dirty flag and the versions of Python and
of the libraries that computed and wrote it. The checksums still verify.
"""

from __future__ import annotations

import json
import platform
import subprocess
from importlib import metadata as importlib_metadata
from pathlib import Path

import h5py
import numpy as np
import pytest

from rbstab import __version__
from rbstab.config import load_config
from rbstab.io import metadata
from rbstab.io.chunk import ChunkWriter, StoreRow, read_chunk_rows
from rbstab.io.hdf5 import read_attributes, read_summary, write_result
from rbstab.io.integrity import verify_file
from rbstab.simulator import simulate

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["simulation.t_end=0.2", "simulation.n_samples=201"]

pytestmark = pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning")


@pytest.fixture(scope="module")
def results():
    """One run of each kind of output: embedded (D), and the pure sign law (switchings)."""
    embedded = simulate(load_config(ROOT / "configs/paper/case3_embedded.yaml", SHORT))
    sign_law = simulate(load_config(ROOT / "configs/examples/sliding.yaml",
                                    [*SHORT, "controller.boundary_layer=0"]))
    assert embedded.status == sign_law.status == "success"
    assert getattr(sign_law, "switching", None) is not None
    return {"embedded": embedded, "sign_law": sign_law}


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _check_variables(f: h5py.File) -> list[str]:
    """Every variable has a long_name; every numeric one has units (CF 3.1, 3.2)."""
    checked = []
    for name, var in f.items():
        if _text(var.attrs.get("NAME", "")).startswith("This is a netCDF dimension but not a netCDF variable"):
            continue  # a dimension without a variable (a text's string<width>): no variable to describe
        assert _text(var.attrs.get("long_name", "")).strip(), f"{name}: no long_name"
        if var.dtype.kind in "fiu":
            assert "units" in var.attrs, f"{name}: no units"
        checked.append(name)
    return checked


def _check_provenance(attrs: dict) -> None:
    assert attrs["Conventions"] == "CF-1.10"
    assert attrs["title"] and attrs["history"].startswith(attrs["created"])
    versions = {"rbstab": __version__, "python": platform.python_version()}
    versions.update({lib: importlib_metadata.version(lib) for lib in ("numpy", "scipy", "h5py", "numba")})
    for lib, version in versions.items():
        assert attrs[f"{lib}_version"] == version, lib
    assert attrs["hdf5_version"] == h5py.version.hdf5_version
    commit, dirty = metadata.git_state()
    assert (attrs["git_commit"], attrs["git_dirty"]) == (commit, dirty)
    assert attrs["git_dirty"] in ("true", "false", "unknown")


@pytest.mark.parametrize("kind", ["embedded", "sign_law"])
def test_run_file_is_cf_with_provenance_and_verifies(results, kind, tmp_path):
    path = write_result(results[kind], tmp_path / f"{kind}.h5", command_line="rbstab run x.yaml")
    with h5py.File(path, "r") as f:
        names = _check_variables(f)
        assert f["theta"].attrs["long_name"] == "Euler angles Theta"
        assert _text(f["constraint_force"].attrs["units"]) == "N"
    assert "controller_state" in names if kind == "embedded" else {"sliding_mode", "switching_time"} <= set(names)
    attrs = read_attributes(path)
    _check_provenance(attrs)
    assert attrs["command_line"] == "rbstab run x.yaml" and attrs["history"].endswith("rbstab run x.yaml")
    # the units of every summary figure, and nothing else, in units_of_summary
    units = json.loads(attrs["units_of_summary"])
    figures = {k[len("summary_"):] for k in attrs if k.startswith("summary_")}
    assert set(units) == figures
    assert units["lyapunov_final"] == "J" and units["final_omega"] == "rad s-1"
    assert all(units[k] for k in figures if not isinstance(attrs[f"summary_{k}"], str)), units
    assert set(read_summary(path)["summary"]) == figures  # checksums verify, figures unchanged
    verify_file(path, data=True)


@pytest.mark.parametrize("store", ["full", "thinned"])
def test_store_file_is_cf_with_provenance_and_verifies(results, store, tmp_path):
    path = tmp_path / "runs" / "chunk-r0-test.h5"
    rows = [StoreRow(0, "r0", "case3"), StoreRow(1, "r1", "sliding")]
    with ChunkWriter(path, rows, store=store, command_line="rbstab sweep s.yaml", sweep="s") as writer:
        writer.add("r0", results["embedded"])
        writer.add("r1", results["sign_law"])
    with h5py.File(path, "r") as f:
        names = _check_variables(f)
        attrs = {k: _text(v) if isinstance(v, bytes) else v for k, v in f.attrs.items()}
        for name, (units, _) in metadata.SUMMARY_FIGURES.items():
            for column in (name, *(f"{name}_{a}" for a in "xyz")):
                if column in f and f[column].dtype.kind == "f":
                    assert _text(f[column].attrs["units"]) == units, column
        assert _text(f["omega"].attrs["long_name"]) == metadata.LONG_NAMES["omega"]
    assert {"lyapunov_final", "max_abs_constraint_error_x", "omega"} <= set(names)
    _check_provenance(attrs)
    assert attrs["sweep"] == "s" and "s" in attrs["title"]
    assert [r["status"] for r in read_chunk_rows(path, data=True)] == ["success", "success"]
    verify_file(path, data=True)


def test_every_variable_has_units_long_name_and_description():
    for name in metadata.VARIABLE_UNITS:
        attrs = metadata.variable_attributes(name)
        assert attrs["long_name"] and attrs["description"], name
    assert "units" not in metadata.variable_attributes("axis")  # text: no units (CF 3.1)
    with pytest.raises(KeyError):
        metadata.variable_attributes("no_such_variable")


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=repo,
                          check=True, capture_output=True, text=True).stdout.strip()


def test_git_state_flags_changed_tracked_files_only(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    _git(repo, "init", "-q")
    (repo / "a.txt").write_text("1\n")
    _git(repo, "add", "a.txt")
    _git(repo, "commit", "-q", "-m", "one")
    commit = _git(repo, "rev-parse", "HEAD")
    assert metadata.git_state_of([repo]) == (commit, "false")
    (repo / "untracked.txt").write_text("x\n")
    assert metadata.git_state_of([repo]) == (commit, "false")
    (repo / "a.txt").write_text("2\n")
    assert metadata.git_state_of([repo]) == (commit, "true")
    assert metadata.git_state_of([tmp_path / "nowhere", tmp_path]) == ("unknown", "unknown")


def test_provenance_is_one_table_for_every_writer():
    attrs = metadata.provenance_attributes("t", command_line="c", created="2026-01-01T00:00:00+00:00")
    assert attrs["history"] == "2026-01-01T00:00:00+00:00 c"
    assert {f"{lib}_version" for lib in metadata.LIBRARIES} <= set(attrs)
    assert np.all([isinstance(v, str) for v in attrs.values()])  # netCDF text attributes
