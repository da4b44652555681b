"""Reliability under faults: full disks, wrong output folders, damaged files, interrupts
at random points, dead parents, Dask addresses that never answer.

Each test injects one fault and checks the promise of docs/reliability.md: one line in
words, a conventional exit status, the results written before intact, no temporary file
left, nothing damaged ever used.
"""

from __future__ import annotations

import errno
import os
import random
import re
import signal
import socket
import subprocess
import sys
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from rbstab.io.chunk import read_chunk_rows
from rbstab.io.hdf5 import NotAResultFile, read_summary
from rbstab.io.integrity import DamagedResultError, verify_file
from rbstab.sweep import open_sweep, read_index, run_sweep, spec_from_mapping
from rbstab.sweep.executors import DaskExecutor, Executor, ExecutorError
from rbstab_cli.main import cli

from conftest import ROOT

CASE1 = ROOT / "configs" / "paper" / "case1_permanent.yaml"
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
RBSTAB = Path(sys.executable).with_name("rbstab")
SHORT = ["--set", "simulation.t_end=0.2", "--set", "simulation.n_samples=21"]


class SerialExecutor(Executor):
    """Runs the chunks in this process, one after the other (so that a patched writer is
    the one the sweep uses)."""

    name = "serial"

    def parallelism(self) -> int:
        return 1

    def imap_unordered(self, fn, items, *args):
        for item in items:
            yield item, fn(item, *args), None


def _spec(name: str = "faults", n: int = 6, **sim):
    base = yaml.safe_load(CASE3.read_text())
    base["simulation"] = {**base.get("simulation", {}), "t_end": 0.1, "n_samples": 11, **sim}
    return spec_from_mapping({"name": name, "base": base, "random": {
        "n": n, "seed": 5, "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}}})


def _no_temporaries(folder: Path) -> None:
    assert not [p for p in folder.rglob(".*.tmp")], "a temporary file was left behind"


def _flip(path: Path, dataset: str, byte: int = 16) -> None:
    """Change one byte inside the first stored chunk of ``dataset``."""
    with h5py.File(path, "r") as f:
        offset = f[dataset].id.get_chunk_info(0).byte_offset
    data = bytearray(path.read_bytes())
    data[offset + byte] ^= 0x40
    path.write_bytes(bytes(data))


# -- full disk, output folders, temporaries -----------------------------------------------------


def test_full_disk_during_run_is_one_line_and_keeps_what_was_there(tmp_path, monkeypatch):
    out = tmp_path / "out"
    ok = CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(out), *SHORT])
    assert ok.exit_code == 0, ok.output
    before = (out / "case1_permanent.h5").read_bytes()

    def full_disk(self, data):  # the device fills up half-way through the file
        with open(self, "wb") as f:
            f.write(data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", full_disk)
    result = CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(out), "--set", "simulation.t_end=0.3",
                                      "--set", "simulation.n_samples=21", "--overwrite"])
    assert result.exit_code == 4  # a fault of the machine
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "No space left on device" in errors[0] and "0 of 1 results written" in errors[0]
    assert "Traceback" not in result.output
    assert (out / "case1_permanent.h5").read_bytes() == before  # the previous result, intact
    _no_temporaries(out)


def test_full_disk_stops_a_sweep_with_an_exact_index(tmp_path, monkeypatch):
    import rbstab.io.chunk as chunk

    spec = _spec()
    calls = {"n": 0}
    real = chunk.check_free_space

    def fills_up(folder, n_bytes, what="the file"):
        calls["n"] += 1
        if calls["n"] > 3:  # the first store file is written, then the disk is full
            raise OSError(errno.ENOSPC, "No space left on device", str(folder))
        real(folder, n_bytes, what)

    monkeypatch.setattr(chunk, "check_free_space", fills_up)
    with pytest.raises(OSError, match="No space left"):
        run_sweep(spec, tmp_path, executor=SerialExecutor(), chunk_size=3, progress=False)
    folder = tmp_path / "faults"
    index = read_index(folder)
    stored = {row["run_id"] for p in (folder / "runs").glob("chunk-*.h5") for row in read_chunk_rows(p)}
    assert set(index.loc[index["status"] == "success", "run_id"]) == stored and len(stored) == 3
    assert set(index.loc[index["status"] != "success", "status"]) == {"pending"}
    _no_temporaries(tmp_path)
    monkeypatch.undo()
    again = run_sweep(spec, tmp_path, executor=SerialExecutor(), chunk_size=3, progress=False)
    assert again.n_skipped == 3 and again.counts["success"] == 6


def test_an_unwritable_index_is_an_os_error_and_the_results_stay(tmp_path):
    """(It crashed the sweep with a traceback; the CLI now says it in one line, exit 1.)"""
    spec = _spec(n=2)
    (tmp_path / "faults" / "index.csv").mkdir(parents=True)  # something in the index's way
    with pytest.raises(IsADirectoryError, match="index.csv"):
        run_sweep(spec, tmp_path, executor=SerialExecutor(), progress=False)
    (tmp_path / "faults" / "index.csv").rmdir()
    again = run_sweep(spec, tmp_path, executor=SerialExecutor(), progress=False)
    assert again.n_skipped == 2 and again.counts["success"] == 2
    _no_temporaries(tmp_path)


def test_output_folder_faults_are_one_line_before_any_run(tmp_path, monkeypatch):
    import rbstab_cli._common as common

    (tmp_path / "afile").write_text("")
    below_a_file = CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(tmp_path / "afile" / "sub")])
    assert below_a_file.exit_code == 4 and "not a folder" in below_a_file.output

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", str(tmp_path / "ro"))

    monkeypatch.setattr(common.tempfile, "mkstemp", read_only)
    refused = CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(tmp_path / "ro")])
    assert refused.exit_code == 4 and "read-only" in refused.output and "Traceback" not in refused.output
    monkeypatch.undo()
    monkeypatch.setattr(common.os, "pathconf", lambda path, name: 32)  # a file system of short names
    too_long = CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(tmp_path / "short")])
    assert too_long.exit_code == 4 and "name is too long" in too_long.output
    assert not list((tmp_path / "short").glob("*.h5"))


def test_temporaries_of_dead_writers_are_removed_and_live_ones_kept(tmp_path):
    from rbstab.io.atomic import _HOST, remove_stale_temporaries

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".run.h5.{dead.pid}@{_HOST}.abcd1234.tmp"
    live = tmp_path / f".run.h5.{os.getpid()}@{_HOST}.abcd1234.tmp"
    foreign = tmp_path / f".run.h5.{dead.pid}@{'0000' if _HOST != '0000' else '1111'}.abcd1234.tmp"
    legacy = tmp_path / ".run.h5.x1y2z3w4.tmp"
    for path in (stale, live, foreign, legacy):
        path.write_text("partial")
    os.utime(legacy, (time.time() - 7200, time.time() - 7200))
    assert remove_stale_temporaries(tmp_path) == 2
    assert not stale.exists() and not legacy.exists() and live.exists() and foreign.exists()


# -- damaged files ------------------------------------------------------------------------------


def _contents(path: Path):
    with h5py.File(path, "r") as f:
        data = {k: (f[k][()].tolist() if f[k].dtype.kind == "O" else f[k][()].tobytes()) for k in f}
        return data, {k: str(v) for k, v in f.attrs.items()}


@pytest.mark.parametrize("kind", ["run", "store"])
def test_random_byte_flips_never_pass_unnoticed(tmp_path, kind):
    """Any changed bit is either refused or changes nothing that is read (free space)."""
    if kind == "run":
        assert CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(tmp_path), *SHORT]).exit_code == 0
        path = tmp_path / "case1_permanent.h5"
        read = read_summary
    else:
        run_sweep(_spec(n=3), tmp_path, executor=SerialExecutor(), progress=False, store="full")
        path = next((tmp_path / "faults" / "runs").glob("chunk-*.h5"))
        read = lambda p: read_chunk_rows(p, data=True)  # noqa: E731
    original, reference = path.read_bytes(), _contents(path)
    rng = random.Random(16)
    refused = 0
    for _ in range(40 if kind == "run" else 25):
        data = bytearray(original)
        data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        damaged = tmp_path / "damaged.h5"
        damaged.write_bytes(bytes(data))
        try:
            read(damaged)
        except NotAResultFile:  # DamagedResultError included
            refused += 1
            continue
        assert _contents(damaged) == reference
    assert refused >= 3  # some flips did land in what matters


def test_a_damaged_store_is_refused_by_readers_and_rerun_on_resume(tmp_path):
    spec = _spec()
    run_sweep(spec, tmp_path, executor=SerialExecutor(), chunk_size=3, progress=False)
    folder = tmp_path / "faults"
    files = sorted((folder / "runs").glob("chunk-*.h5"))
    _flip(files[0], "lyapunov", byte=8)
    with pytest.raises(DamagedResultError, match="lyapunov"):
        verify_file(files[0])
    shown = CliRunner().invoke(cli, ["show", str(files[0])])
    assert shown.exit_code == 1 and "damaged" in shown.output
    report = CliRunner().invoke(cli, ["report", str(folder), "-o", str(tmp_path / "report")])
    assert report.exit_code == 1 and "damaged" in report.output and not (tmp_path / "report").exists()
    with pytest.raises(DamagedResultError):
        open_sweep(folder)["lyapunov"].values  # noqa: B018 - the traces are read lazily, and checked then
    again = run_sweep(spec, tmp_path, executor=SerialExecutor(), chunk_size=3, progress=False)
    assert [name for name, _ in again.damaged] == [files[0].name]
    assert (folder / "runs" / (files[0].name + ".damaged")).exists() and not files[0].exists()
    assert again.n_skipped == 3 and again.counts["success"] == 6
    assert float(open_sweep(folder)["lyapunov"].max()) < 1e5  # the values of rerun runs


def test_open_sweep_checks_a_store_file_s_text_when_its_traces_are_read(tmp_path):
    """open_sweep lists the store files; a file whose text was changed (no HDF5 checksum
    covers it) is refused by the content digest when its traces are first read."""
    run_sweep(_spec(), tmp_path, executor=SerialExecutor(), chunk_size=3, progress=False)
    folder = tmp_path / "faults"
    files = sorted((folder / "runs").glob("chunk-*.h5"))
    text = bytearray(files[1].read_bytes())
    at = text.find(b"success")  # the status column's text, in HDF5's heap
    assert at > 0
    text[at] = ord("S")
    files[1].write_bytes(bytes(text))
    ds = open_sweep(folder)
    first = ds["lyapunov"].isel(run=slice(0, 3)).values  # the intact file's runs
    assert np.isfinite(first).all()
    with pytest.raises(DamagedResultError, match="attributes, text or structure"):
        ds["lyapunov"].values  # noqa: B018


def test_a_damaged_run_file_and_index_are_refused(tmp_path):
    assert CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(tmp_path), *SHORT]).exit_code == 0
    path = tmp_path / "case1_permanent.h5"
    text = bytearray(path.read_bytes())
    at = text.find(b"success")  # the status attribute's text, in HDF5's heap (no HDF5 checksum)
    text[at] = ord("S")
    path.write_bytes(bytes(text))
    with pytest.raises(DamagedResultError, match="attributes, text or structure"):
        read_summary(path)
    run_sweep(_spec(n=2), tmp_path, executor=SerialExecutor(), progress=False)
    folder = tmp_path / "faults"
    arrow = bytearray((folder / "index.arrow").read_bytes())  # what rbstab show reads
    (folder / "index.arrow").write_bytes(bytes(arrow.replace(b"success", b"failed\0", 1)))
    shown = CliRunner().invoke(cli, ["show", str(folder)])
    assert shown.exit_code == 1 and "index.arrow: does not match its checksum" in shown.output
    (folder / "index.arrow").unlink()  # a folder written before index.arrow: the CSV is read
    index = folder / "index.csv"
    index.write_text(index.read_text().replace("success", "failed", 1))
    shown = CliRunner().invoke(cli, ["show", str(folder)])
    assert shown.exit_code == 1 and "index.csv: does not match its checksum" in shown.output


def test_show_refuses_a_file_with_only_some_attributes(tmp_path):
    path = tmp_path / "partial.h5"
    with h5py.File(path, "w") as f:
        f.attrs.update(rbstab_format="rbstab-run-1", name="x")
    result = CliRunner().invoke(cli, ["show", str(path)])
    assert result.exit_code == 1 and "without the attributes variant" in result.output
    assert "Traceback" not in result.output


# -- interrupts and dead parents (real processes) ----------------------------------------------


def _stat(pid: int) -> list[str]:
    """The fields of /proc/<pid>/stat after the command's name (field 3, the state, first)."""
    return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()


def _descendants(pid: int) -> list[tuple[int, str]]:
    """(pid, start time) of every descendant of ``pid``: the start time tells a process from
    a later one given the same pid."""
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return []
    found = []
    for child in map(int, children):
        try:
            found.append((child, _stat(child)[19]))
        except OSError:
            continue
        found.extend(_descendants(child))
    return found


def _alive(processes) -> list[int]:
    """The pids of ``processes`` (:func:`_descendants`) that still run (not zombies)."""
    alive = []
    for pid, start in processes:
        try:
            fields = _stat(pid)
        except OSError:
            continue
        if fields[0] != "Z" and fields[19] == start:
            alive.append(pid)
    return alive


def _sweep_process(tmp_path: Path, name: str) -> tuple[subprocess.Popen, Path, list[str]]:
    spec = tmp_path / f"{name}.yaml"
    # 64 runs of ~20-50 ms on 2 workers: still running well after the test's signal (~0.4 s
    # after the second file; 16 runs could all finish before it on a fast moment)
    spec.write_text(yaml.safe_dump({"name": name, "base": str(CASE3), "random": {
        "n": 64, "seed": 9, "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}}}))
    command = [str(RBSTAB), "sweep", str(spec), "-o", str(tmp_path / "out"), "-j", "2", "--no-progress",
               "--engine", "scipy", "--chunk-size", "1", "--set", "simulation.t_end=0.5", "--set",
               "simulation.n_samples=51"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    runs = tmp_path / "out" / name / "runs"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and len(list(runs.glob("chunk-*.h5"))) < 2:
        time.sleep(0.01)
    assert proc.poll() is None, proc.stderr.read()
    return proc, runs, command


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads the process tree from /proc")
def test_sigterm_at_a_random_point_leaves_an_exact_index(tmp_path):
    """SIGTERM goes through the path of Ctrl-C (a KeyboardInterrupt), with status 143; the
    workers are stopped before the index is written, so it lists exactly the files on disk."""
    proc, runs, _ = _sweep_process(tmp_path, "intr")
    time.sleep(random.Random(15).uniform(0.0, 0.4))
    workers = _descendants(proc.pid)
    proc.send_signal(signal.SIGTERM)
    status, said = proc.wait(timeout=60), proc.stderr.read()
    assert status == 143 and "interrupted" in said, (status, said)
    deadline = time.monotonic() + 10  # a worker reaped by the parent is gone; a helper (the resource
    while time.monotonic() < deadline and _alive(workers):  # tracker) sees its pipe close and ends
        time.sleep(0.05)
    assert not _alive(workers)
    _no_temporaries(runs.parent)
    index = pd.read_csv(runs.parent / "index.csv")
    stored = {row["run_id"] for p in runs.glob("chunk-*.h5") for row in read_chunk_rows(p)}
    assert set(index.loc[index["status"] == "success", "run_id"]) == stored
    assert set(index.loc[~index["run_id"].isin(stored), "status"]) <= {"pending"}


def test_ctrl_c_exits_130_with_a_word(tmp_path, monkeypatch):
    import rbstab.simulator

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(rbstab.simulator, "simulate", interrupted)
    result = CliRunner().invoke(cli, ["run", str(CASE1), "-o", str(tmp_path), *SHORT])
    assert result.exit_code == 130 and "interrupted" in result.output and "Aborted" not in result.output


def test_an_interrupted_sweep_says_once_that_it_can_resume(tmp_path, monkeypatch):
    """The CLI's one interrupt handler gives a sweep its own words (the index is up to date)."""
    import rbstab_cli.sweep

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(rbstab_cli.sweep, "execute_sweep", interrupted)  # the command's rbstab.api.execute_sweep
    spec = ROOT / "configs" / "sweeps" / "gains.yaml"
    result = CliRunner().invoke(cli, ["sweep", str(spec), "-o", str(tmp_path), "--no-progress"])
    assert result.exit_code == 130 and "Aborted" not in result.output
    assert result.output.count("interrupted") == 1 and "the index is up to date" in result.output


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads the process tree from /proc")
def test_workers_exit_when_the_parent_dies_unreaped(tmp_path):
    proc, runs, _ = _sweep_process(tmp_path, "orphan")
    workers = _descendants(proc.pid)
    assert workers
    os.kill(proc.pid, signal.SIGKILL)  # not reaped yet: the parent stays a zombie meanwhile
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and _alive(workers):
        time.sleep(0.05)
    assert Path(f"/proc/{proc.pid}/stat").read_text().split()[2] == "Z"
    assert not _alive(workers)
    proc.wait()
    proc.stderr.close()


# -- local workers that die ---------------------------------------------------------------


def _die_on(item, die, marker_dir):
    """A worker's task: its process exits at once on an item of ``die`` (the first time
    only if ``marker_dir`` is given), as a killed or crashed worker does."""
    marker = Path(marker_dir) / str(item) if marker_dir else None
    if item in die and not (marker and marker.exists()):
        if marker:
            marker.touch()
        os._exit(3)
    return -item


def _local_results(die, marker_dir=None, n=6) -> tuple[dict, dict]:
    from rbstab.sweep.executors import LocalExecutor

    results, errors = {}, {}
    with LocalExecutor(1, max_in_flight=1) as ex:  # one item at a time: a deterministic order
        for item, result, exc in ex.imap_unordered(_die_on, range(n), die, marker_dir):
            (results if exc is None else errors)[item] = result if exc is None else exc
    return results, errors


def test_a_worker_dying_fails_its_run_and_the_pool_goes_on():
    results, errors = _local_results({2})
    assert results == {0: 0, 1: -1, 3: -3, 4: -4, 5: -5}
    assert list(errors) == [2] and isinstance(errors[2], BrokenProcessPool)


def test_a_pool_that_dies_before_finishing_anything_is_tried_once_more(tmp_path):
    results, errors = _local_results({0}, tmp_path)  # the first worker dies at its first item only
    assert results == {i: -i for i in range(6)} and not errors
    with pytest.raises(ExecutorError, match="died twice in a row before finishing anything"):
        _local_results({0})


def test_a_script_without_the_main_guard_is_told_so(tmp_path):
    """Every local worker runs the caller's script again before it takes work: a sweep at a
    script's top level is refused in the script's process, before anything starts."""
    body = (f"import rbstab\n"
            f"spec = {{'name': 's', 'base': {str(CASE3)!r}, 'grid': {{'body.mass': [30.0, 50.0]}}}}\n"
            f"{{}}ds = rbstab.sweep_dataset(spec, 'out', overrides={{'simulation.t_end': 0.2}}, jobs=2)\n"
            f"{{}}print(sorted(set(ds.status.values)))\n")
    unguarded = tmp_path / "unguarded.py"
    unguarded.write_text(body.replace("{}", ""))
    bad = subprocess.run([sys.executable, unguarded.name], cwd=unguarded.parent, capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode != 0
    # refused in the script's own process, before any worker starts or anything is written
    assert "rbstab.sweep_dataset() at the top level of " in bad.stderr
    assert f"{unguarded.name} (line 3) starts local worker processes" in bad.stderr
    assert 'if __name__ == "__main__":' in bad.stderr and "died" not in bad.stderr
    assert "SweepBusyError" not in bad.stderr
    assert not (unguarded.parent / "out").exists()  # nothing ran, nothing was written
    # the script mended (the sweep under the main guard): it runs
    unguarded.write_text(body.replace("{}ds", "if __name__ == '__main__':\n    ds").replace("{}print", "    print"))
    mended = subprocess.run([sys.executable, unguarded.name], cwd=unguarded.parent, capture_output=True, text=True,
                            timeout=300)
    assert mended.returncode == 0 and mended.stdout.strip() == "['success']", mended.stderr
    assert set(pd.read_csv(unguarded.parent / "out" / "s" / "index.csv").status) == {"success"}


# -- Dask -----------------------------------------------------------------------------------


def test_dask_addresses_that_never_answer_fail_fast_naming_them(silent_server):
    pytest.importorskip("distributed")
    start = time.monotonic()
    with pytest.raises(ExecutorError, match=f"at {silent_server}: no Dask scheduler answered"):
        DaskExecutor(silent_server, connect_timeout=1.0)
    assert time.monotonic() - start < 5
    with pytest.raises(ExecutorError, match="at http://127.0.0.1:8787: not a valid address"):
        DaskExecutor("http://127.0.0.1:8787")
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    start = time.monotonic()
    with pytest.raises(ExecutorError, match=f"127.0.0.1:{port}: connection refused"):
        DaskExecutor(f"tcp://127.0.0.1:{port}")
    assert time.monotonic() - start < 2


def test_dask_with_no_workers_left_stops_naming_the_scheduler():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster, \
            distributed.Client(cluster, set_as_default=False) as client:
        ex = DaskExecutor(client=client, no_workers_grace=0.5)
        with pytest.raises(ExecutorError, match=f"no workers left on the Dask scheduler at {cluster.scheduler_address}"):
            list(ex.imap_unordered(abs, [-1, -2]))
        ex.close()


# -- what the inputs say, shown as text ---------------------------------------------------------


def test_report_shows_names_from_files_as_text_in_every_format(tmp_path):
    """A result file may come from anywhere: its name and messages are text in the page,
    never HTML, a link or a figure's mathtext (a '$' in a name broke matplotlib)."""
    import dataclasses

    from rbstab.config import load_config
    from rbstab.io.hdf5 import write_result
    from rbstab.simulator import simulate

    config = load_config(CASE1, ["simulation.t_end=0.2", "simulation.n_samples=21"])
    evil = "<script>alert(1)</script> $\\frac{$ [x](javascript:alert(1)) | `code`"
    result = simulate(dataclasses.replace(config, name=evil, resolved={**config.resolved, "name": evil}))
    write_result(result, tmp_path / "evil.h5")
    built = CliRunner().invoke(cli, ["report", str(tmp_path / "evil.h5"), "-o", str(tmp_path / "report"),
                                     "--format", "html", "--format", "md"])
    assert built.exit_code == 0, built.output
    for page in ("index.html", "index.md", "summary.md"):
        text = (tmp_path / "report" / page).read_text()
        assert "<script>" not in text and "&lt;script&gt;" in text, page
        assert page.endswith(".html") or not re.search(r"(?<!\\)\]\(javascript:", text), page  # no link
    assert "| `code`" not in (tmp_path / "report" / "index.md").read_text()


@pytest.mark.parametrize("name", ["run_file_6596935.h5", "store_file_6596935.h5"])
def test_files_written_by_an_earlier_version_still_verify(name):
    """The digests are part of the file format: a file written before the writer and the
    digest were rewritten for speed (commit 6596935: Case 1 run, 2-run Case 3 thinned
    store, t_end 0.1 s) still verifies, text, attributes, structure and numbers."""
    assert verify_file(ROOT / "tests" / "data" / name, data=True)
