"""The registry of input kinds (rbstab.kinds): each kind recognised by its own test, the
others refused with what they are, and the commands that read inputs going through it."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr
from click.testing import CliRunner

import rbstab
from rbstab.io.hdf5 import NotAResultFile
from rbstab.kinds import ANALYSIS, KINDS, RUN, STORE, SWEEP, inputs_in, is_plain_folder, kind_of, open_input
from rbstab.studies.files import write_study_file
from rbstab.sweep import run_sweep, spec_from_mapping
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"
CASE1 = ROOT / "configs" / "paper" / "case1_permanent.yaml"
SHORT = ["simulation.t_end=0.1", "simulation.n_samples=11"]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """One input of each kind, and things that are none."""
    from rbstab.analysis import analyze, write_analysis

    root = tmp_path_factory.mktemp("kinds")
    spec = spec_from_mapping({"name": "two", "base": str(CASE1), "grid": {"body.mass": [40.0, 41.0]}}, overrides=SHORT)
    sweep = run_sweep(spec, root, jobs=1, progress=False).directory
    analysis = write_analysis(analyze(CASE1, certificate=False, simulate=False), root / "case1_permanent.analysis.nc")
    foreign = root / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3.0)
    other_format = root / "other.h5"
    with h5py.File(other_format, "w") as f:
        f.attrs["rbstab_format"] = "rbstab-future-9"
    text = root / "notes.h5"
    text.write_text("not HDF5")
    studies = {}
    for name in ("sensitivity", "tuning"):
        (root / name).mkdir()
        studies[name] = write_study_file(xr.Dataset({"x": ("i", np.arange(2.0))}, attrs={"rbstab_study": name}),
                                         root / name / f"{name}.nc")
    plain = root / "plain"
    plain.mkdir()
    incomplete = root / "incomplete"
    incomplete.mkdir()
    shutil.copy(sweep / "sweep.yaml", incomplete / "sweep.yaml")
    chain_run = rbstab.run(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", root / "chain",
                           overrides=["simulation.t_end=0.1", "simulation.n_samples=11"])
    return {"run": DATA / "run_file_6596935.h5", "chain_run": chain_run, "store": DATA / "store_file_6596935.h5",
            "sweep": sweep,
            "analysis": analysis, "foreign": foreign, "other_format": other_format, "text": text, "plain": plain,
            "incomplete": incomplete, **studies}


def test_each_kind_is_recognised_by_its_own_test_only(inputs):
    for kind in KINDS:
        assert kind_of(inputs[kind.name]) is kind
        assert [k.name for k in KINDS if k.can_open(inputs[kind.name])] == [kind.name]
    for name in ("foreign", "other_format", "text", "plain", "incomplete"):
        assert not any(k.can_open(inputs[name]) for k in KINDS), name


def test_each_kind_opens_with_its_loader(inputs):
    assert open_input(inputs["run"]).attrs["rbstab_format"] == "rbstab-run-1"
    assert [row["file_row"] for row in open_input(inputs["store"])] == [0, 1]
    assert open_input(inputs["sweep"]).sizes["run"] == 2
    assert open_input(inputs["analysis"]).attrs["rbstab_format"] == "rbstab-analysis-1"
    for name in ("sensitivity", "tuning"):
        assert open_input(inputs[name]).attrs["rbstab_study"] == name
        assert kind_of(inputs[name].parent).name == name  # a study's folder stands for its file


@pytest.mark.parametrize("name, message", [
    ("foreign", "not an rbstab run result, chain run result, store file of a sweep (many runs), sweep folder, "
                "analysis file, "
                "sensitivity study (its sensitivity.nc or folder) or tuning study (its tuning.nc or folder) "
                "(an HDF5 file without an rbstab_format attribute)"),
    ("other_format", "rbstab_format 'rbstab-future-9', of no kind this version reads"),
    ("text", "not an HDF5 file"),
    ("plain", "a folder, but not a sweep folder (no sweep.yaml and index.csv)"),
    ("incomplete", "incomplete sweep folder (no index.csv)"),
])
def test_what_no_kind_opens_is_refused_saying_what_it_is(inputs, name, message):
    with pytest.raises(NotAResultFile) as refused:
        kind_of(inputs[name])
    assert str(refused.value).startswith(f"{inputs[name]}: ") and message in str(refused.value)


def test_a_kind_not_taken_is_refused_with_how_to_read_it(inputs, tmp_path):
    with pytest.raises(NotAResultFile, match=r"a store file of a sweep \(many runs\), not a run result; open its "
                                             r"sweep folder with rbstab.open_sweep"):
        kind_of(inputs["store"], (RUN,))
    with pytest.raises(NotAResultFile, match="an analysis file, not a run result, store file of a sweep"):
        kind_of(inputs["analysis"], (RUN, STORE, SWEEP))
    with pytest.raises(NotAResultFile, match="a folder, not a run result"):
        kind_of(inputs["plain"], (RUN,))
    with pytest.raises(FileNotFoundError, match="no such result file or folder"):
        kind_of(tmp_path / "missing.h5")


def test_a_plain_folder_stands_for_the_inputs_in_it(inputs, tmp_path):
    for name in ("run", "store", "analysis", "text"):
        shutil.copy(inputs[name], tmp_path / inputs[name].name)
    shutil.copytree(inputs["sweep"], tmp_path / "sweep")
    shutil.copytree(inputs["incomplete"], tmp_path / "incomplete")
    (tmp_path / "readme.txt").write_text("x")
    assert is_plain_folder(tmp_path) and not is_plain_folder(inputs["sweep"])
    assert not is_plain_folder(inputs["incomplete"]) and not is_plain_folder(inputs["run"])
    names = lambda kinds: [p.name for p in inputs_in(tmp_path, kinds)]  # noqa: E731
    assert names((RUN, STORE)) == sorted(inputs[n].name for n in ("run", "store", "text"))  # a bad .h5 too
    assert names((SWEEP,)) == ["sweep"]
    assert names((ANALYSIS,)) == [inputs["analysis"].name]


def test_show_and_open_result_go_through_the_registry(inputs):
    import rbstab

    shown = CliRunner().invoke(cli, ["show", str(inputs["analysis"])])
    assert shown.exit_code == 1 and "an analysis file, not a run result, chain run result, store file of a sweep" \
        in shown.output
    assert "Traceback" not in shown.output
    incomplete = CliRunner().invoke(cli, ["show", str(inputs["incomplete"])])
    assert incomplete.exit_code == 1 and "incomplete sweep folder (no index.csv)" in incomplete.output
    with pytest.raises(NotAResultFile, match="open its sweep folder with rbstab.open_sweep"):
        rbstab.open_result(inputs["store"])
