"""A sweep killed with SIGKILL part-way loses no finished run and leaves no corrupt file.

The sweep runs as ``rbstab sweep`` in its own process group; once a few result files exist
the whole group (parent and workers, possibly mid-write) is killed with SIGKILL. Resuming
must finish every run, and every file must equal the one of a clean, uninterrupted sweep.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml

from rbstab.io.hdf5 import read_attributes
from rbstab.sweep import expand, load_spec, run_sweep

from test_sweep import CASE3, data_equal

pytestmark = [
    pytest.mark.filterwarnings("ignore::rbstab.config.PhysicalPlausibilityWarning"),
    pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs POSIX process groups"),
]

RBSTAB = Path(sys.executable).with_name("rbstab")


def kill_when_written(command: list[str], runs_dir: Path, pattern: str, count: int, poll: float) -> list[Path]:
    """Start ``command`` in its own process group, SIGKILL the whole group (parent and
    workers, wherever they are) once ``count`` files match ``pattern`` in ``runs_dir``;
    returns the files under a final name after the kill."""
    proc = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if runs_dir.is_dir() and len(list(runs_dir.glob(pattern))) >= count:
                break
            time.sleep(poll)
        assert proc.poll() is None, f"the sweep ended before it could be killed: {proc.stderr.read().decode()}"
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        if proc.poll() is None:
            proc.wait(timeout=30)
        proc.stderr.close()
    time.sleep(0.5)
    return sorted(runs_dir.glob(pattern))


def test_sigkill_then_resume_equals_clean_run(tmp_path):
    spec_path = tmp_path / "kill.yaml"
    spec_path.write_text(
        yaml.safe_dump(
            {
                "name": "kill",
                "base": str(CASE3),
                "random": {"n": 10, "seed": 3, "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}},
            }
        )
    )
    overrides = ["--set", "simulation.t_end=0.3", "--set", "simulation.n_samples=201"]
    command = [str(RBSTAB), "sweep", str(spec_path), "-o", str(tmp_path / "killed"), "-j", "2", "--no-progress",
               "--layout", "run", *overrides]
    runs_dir = tmp_path / "killed" / "kill" / "runs"

    finished = kill_when_written(command, runs_dir, "*.h5", 3, poll=0.02)
    assert 3 <= len(finished) < 10
    for path in finished:  # whatever is under a final name is a whole, readable result
        assert read_attributes(path)["status"] == "success"
    assert not (tmp_path / "killed" / "kill" / "index.csv").exists()  # killed before the end

    resumed = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(finished)} skipped" in resumed.stdout or f"{len(finished)} already done" in resumed.stderr

    spec = load_spec(spec_path, [o for o in overrides if o != "--set"])
    runs = expand(spec)
    clean = run_sweep(spec, tmp_path / "clean", jobs=2, chunk_size=3, progress=False, layout="run")
    assert clean.counts["success"] == 10
    index = pd.read_csv(tmp_path / "killed" / "kill" / "index.csv")
    assert list(index["run_id"]) == [r.run_id for r in runs]
    assert (index["status"] == "success").all()
    assert not list(runs_dir.glob(".*.tmp"))
    for run in runs:
        data_equal(runs_dir / f"{run.run_id}.h5", tmp_path / "clean" / "kill" / "runs" / f"{run.run_id}.h5")


def test_sigkill_of_the_default_store_then_resume_equals_clean_run(tmp_path):
    """Store files (the default layout) are written whole or not at all: a sweep killed
    while chunks are in flight keeps the finished chunks, and the next invocation runs the
    rest; the index and the stored values equal a clean run's."""
    spec_path = tmp_path / "killc.yaml"
    spec_path.write_text(yaml.safe_dump({
        "name": "killc", "base": str(CASE3),
        "random": {"n": 12, "seed": 3, "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16], "std": 4}}}},
    }))
    overrides = ["--set", "simulation.t_end=0.3", "--set", "simulation.n_samples=201"]
    command = [str(RBSTAB), "sweep", str(spec_path), "-o", str(tmp_path / "killed"), "-j", "2", "--no-progress",
               "--chunk-size", "2", *overrides]
    runs_dir = tmp_path / "killed" / "killc" / "runs"
    from rbstab.io.chunk import read_chunk_rows

    finished = kill_when_written(command, runs_dir, "chunk-*.h5", 1, poll=0.01)
    assert 1 <= len(finished) < 6
    for path in finished:  # a final name holds a whole, readable store file
        assert all(row["status"] == "success" for row in read_chunk_rows(path))
    resumed = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    spec = load_spec(spec_path, [o for o in overrides if o != "--set"])
    runs = expand(spec)
    clean = run_sweep(spec, tmp_path / "clean", jobs=2, chunk_size=5, progress=False)
    assert clean.counts["success"] == 12
    a = pd.read_csv(tmp_path / "killed" / "killc" / "index.csv").drop(columns=["wall_time", "file", "file_row"])
    b = pd.read_csv(tmp_path / "clean" / "killc" / "index.csv").drop(columns=["wall_time", "file", "file_row"])
    pd.testing.assert_frame_equal(a, b)
    assert not list(runs_dir.glob(".*.tmp"))
