"""What the commands print: no silent overwrite, -q/-v, coded warnings, --json, show DIR, Dask timeout."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import threading

import pytest
import yaml
from click.testing import CliRunner

from conftest import PAPER_CONFIGS, ROOT
from rbstab_cli.main import cli

CASE1, CASE2, CASE3 = PAPER_CONFIGS
SHORT = ["--set", "simulation.t_end=0.2", "--set", "simulation.n_samples=21"]
INERTIA = "W001 body.inertia"


def invoke(*args, env=None):
    return CliRunner().invoke(cli, [str(a) for a in args], env=env)


def json_lines(text: str) -> list[dict]:
    return [json.loads(line) for line in text.splitlines()]


# -- no silent overwrite ------------------------------------------------------------------------


def test_run_refuses_to_replace_a_result_of_another_config(tmp_path):
    assert invoke("run", CASE1, "-o", tmp_path, *SHORT).exit_code == 0
    path = tmp_path / "case1_permanent.h5"
    before = path.read_bytes()
    other = invoke("run", CASE2, CASE1, "-o", tmp_path, *SHORT, "--set", "initial_state.omega.0=5")
    assert other.exit_code == 1
    assert "holds a result of a different configuration (initial_state.omega.0: 16.0 -> 5)" in other.stderr
    assert "--overwrite" in other.stderr and "-o DIR" in other.stderr and "nothing was run" in other.stderr
    assert "Traceback" not in other.output and isinstance(other.exception, SystemExit)
    assert path.read_bytes() == before
    assert not (tmp_path / "case2_visco_elastic.h5").exists()  # refused before anything ran

    same = invoke("run", CASE1, "-o", tmp_path, *SHORT)
    assert same.exit_code == 0, same.output
    assert "holds a result of the identical configuration; run again and replaced" in same.stderr

    forced = invoke("run", CASE1, "-o", tmp_path, *SHORT, "--set", "initial_state.omega.0=5", "--overwrite")
    assert forced.exit_code == 0, forced.output
    assert "replaced (--overwrite)" in forced.stderr
    assert yaml.safe_load(_config_text(path))["initial_state"]["omega"] == [5, 32.0, -16.0]


def _config_text(path) -> str:
    from rbstab.io.hdf5 import read_attributes

    return read_attributes(path)["config"]


# -- warnings, -q and -v ------------------------------------------------------------------------


def test_a_warning_is_one_short_line_once_per_command(tmp_path):
    result = invoke("run", *PAPER_CONFIGS, "-o", tmp_path, *SHORT)
    assert result.exit_code == 0, result.output
    lines = [line for line in result.stderr.splitlines() if INERTIA in line]
    assert len(lines) == 1 and len(lines[0]) < 160
    assert lines[0].startswith("warning: W001 body.inertia: principal moments (10, 8, 0.4) kg m^2")
    assert lines[0].endswith("(3 of 3 configs)")
    assert INERTIA not in result.stdout


def test_no_warn_silences_a_code_and_an_unknown_code_is_refused(tmp_path):
    configs = [*map(str, PAPER_CONFIGS)]
    assert INERTIA in invoke("validate", *configs).stderr
    assert INERTIA not in invoke("validate", *configs, "--no-warn", "w001").stderr
    assert INERTIA not in invoke("validate", *configs, "--no-warn", "all").stderr
    assert INERTIA not in invoke("validate", *configs, env={"RBSTAB_NO_WARN": "W002 W001"}).stderr
    bad = invoke("validate", *configs, "--no-warn", "W999")
    assert bad.exit_code == 2
    assert "'--no-warn': found W999; expected a warning code (W001, W002" in bad.stderr


def test_quiet_and_verbose(tmp_path):
    config = [CASE3, "-o", tmp_path, *SHORT]
    normal = invoke("run", *config, "--set", "name=a")
    assert "a: success" in normal.stdout and INERTIA in normal.stderr
    quiet = invoke("run", *config, "--set", "name=b", "-q")
    # -q keeps the results and drops the notes
    assert quiet.exit_code == 0 and "b: success" in quiet.stdout and INERTIA in quiet.stderr
    silent = invoke("run", *config, "--set", "name=c", "-qq")
    assert silent.exit_code == 0 and silent.output == ""
    assert (tmp_path / "c.h5").is_file()
    verbose = invoke("run", *config, "--set", "name=d", "-v")
    assert "W001: every real rigid body satisfies it" in verbose.stderr and "--no-warn W001" in verbose.stderr
    assert "  solver nfev " in verbose.stdout


def test_python_warnings_with_a_code_go_through_the_console(monkeypatch, tmp_path):
    """A coded warning raised anywhere during a command is shown like the others, once."""
    import warnings

    import rbstab.api

    original = rbstab.api.check_overwrite

    def noisy(*args, **kwargs):
        warnings.warn("somewhere: W003 simulation.n_samples: big", UserWarning)
        return original(*args, **kwargs)

    monkeypatch.setattr(rbstab.api, "check_overwrite", noisy)
    result = invoke("run", CASE1, CASE2, "-o", tmp_path, *SHORT, "--no-warn", "W001")
    assert result.exit_code == 0, result.output
    assert result.stderr.count("W003") == 1 and "warning: W003 simulation.n_samples: big (somewhere)" in result.stderr
    assert "W003" not in invoke("run", CASE1, "-o", tmp_path, *SHORT, "--no-warn", "W003").stderr


# -- --json ---------------------------------------------------------------------------------------


def test_run_json_is_one_object_per_config(tmp_path):
    result = invoke("run", CASE1, CASE3, "-o", tmp_path, *SHORT, "--json")
    assert result.exit_code == 0, result.output
    objects = json_lines(result.stdout)
    assert [o["name"] for o in objects] == ["case1_permanent", "case3_embedded"]
    first = objects[0]
    assert first["status"] == "success" and first["replaced"] is None and first["path"].endswith("case1_permanent.h5")
    assert first["summary"]["lyapunov_initial"] > 0 and len(first["summary"]["final_theta"]) == 3
    assert "case1_permanent: success" in result.stderr  # the text went to stderr


def test_show_and_validate_json(tmp_path):
    assert invoke("run", CASE2, "-o", tmp_path, *SHORT).exit_code == 0
    (tmp_path / "bad.h5").write_bytes(b"nope")
    shown = invoke("show", tmp_path / "case2_visco_elastic.h5", tmp_path / "bad.h5", "--json", "-q")
    assert shown.exit_code == 1
    run, bad = json_lines(shown.stdout)
    assert run["kind"] == "run" and run["variant"] == "visco_elastic" and run["summary"]["t_final"] == 0.2
    assert bad["kind"] == "error" and "not an HDF5 file" in bad["error"]
    checked = invoke("validate", CASE1, tmp_path / "missing.yaml", "--json", "--set", "simulation.n_samples=1")
    assert checked.exit_code == 1
    one, missing = json_lines(checked.stdout)
    assert one["valid"] is False and "config key 'simulation.n_samples': found 1" in one["errors"][0]
    assert missing["valid"] is False and "config file not found" in missing["errors"][0]
    ok = json_lines(invoke("validate", CASE3, "--json").stdout)[0]
    assert ok["valid"] and ok["variant"] == "embedded" and ok["warnings"][0].startswith(INERTIA)


# -- rbstab show DIR ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sweep_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweeps")
    result = invoke("sweep", CASE3, "-o", out, "-j", "1", "--grid", "body.mass=30,41,52", *SHORT, "--no-progress")
    assert result.exit_code == 0, result.output
    return out


def test_show_summarises_a_sweep_folder(sweep_folder):
    folder = sweep_folder / "case3_embedded"
    result = invoke("show", folder)
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "sweep      case3_embedded: 3 runs, 3 still settling" in out  # by outcome
    assert "varied     mass (body.mass): 30, 41, 52  [3 values]" in out
    assert "lyapunov_final             [J] min " in out
    assert len(re.findall(r"^  r\d{4}-\w{8} +success ", out, re.M)) == 3  # one line per run
    info = json_lines(invoke("show", folder, "--json", "-q").stdout)[0]
    assert info["kind"] == "sweep" and info["n_runs"] == 3 and info["status"] == {"success": 3}
    assert info["parameters"]["mass"] == {"key": "body.mass", "values": [30.0, 41.0, 52.0], "n_values": 3}
    assert info["metrics"]["lyapunov_final"]["min"] <= info["metrics"]["lyapunov_final"]["max"]


def test_show_lists_a_parameters_values_in_run_order_or_gives_its_range():
    import numpy as np
    import pandas as pd

    from rbstab_cli.show import _parameter_values

    index = pd.DataFrame({"mass": [52.0, 30.0, np.nan, 52.0, 41.0, 30.0, 41.0], "n": [3, 1, 2, 1, 2, 3, 3],
                          "variant": ["b", "a", "b", "c", "d", "e", "f"], "k": np.arange(7.0)[::-1]})
    assert _parameter_values(index, "mass") == {"values": [52.0, 30.0, 41.0], "n_values": 3}
    assert _parameter_values(index, "n") == {"values": [3, 1, 2], "n_values": 3}
    assert _parameter_values(index, "variant") == {"values": ["b", "a", "c", "d", "e", "f"], "n_values": 6}
    assert _parameter_values(index, "k") == {"min": 0.0, "max": 6.0, "n_values": 7}
    wide = pd.DataFrame({"base": pd.Series(list("gfedcba"), dtype="str")})
    assert _parameter_values(wide, "base") == {"values": list("gfedcb"), "n_values": 7}
    assert all(type(v) is float for v in _parameter_values(index, "k").values() if v != 7)


def test_show_a_folder_of_sweeps_and_a_folder_of_nothing(sweep_folder, tmp_path):
    parent = invoke("show", sweep_folder)
    assert parent.exit_code == 0 and "sweep      case3_embedded" in parent.stdout
    typo = invoke("show", sweep_folder / "case3_embeded")
    assert typo.exit_code == 1
    assert f"no such result file or folder: {sweep_folder / 'case3_embeded'}; did you mean " \
           f"{sweep_folder / 'case3_embedded'}?" in typo.stderr
    empty = invoke("show", tmp_path)
    assert empty.exit_code == 1
    assert "not a sweep folder (no sweep.yaml and index.csv) and without result files" in empty.stderr


# -- python -m rbstab, Dask ---------------------------------------------------------------------


def test_python_dash_m_rbstab():
    result = subprocess.run([sys.executable, "-m", "rbstab", "validate", str(CASE1), "-q"],
                            capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0 and result.stdout.startswith("ok: case1_permanent") and INERTIA in result.stderr
    version = subprocess.run([sys.executable, "-m", "rbstab", "--version"], capture_output=True, text=True)
    assert "rbstab, version" in version.stdout


def test_connect_timeout_reaches_the_dask_executor(tmp_path, silent_server):
    pytest.importorskip("distributed")
    result = invoke("sweep", CASE3, "-o", tmp_path / "o", "--scheduler", silent_server, "--connect-timeout", "0.5")
    assert result.exit_code == 4  # a fault of the machine
    assert f"cannot connect to the Dask scheduler at {silent_server}: no Dask scheduler answered within 0.5 s" \
        in result.stderr
    assert "Traceback" not in result.output and not (tmp_path / "o").exists()


def test_an_unreachable_host_is_reported_within_the_timeout(monkeypatch):
    """A host that drops the connection: the probe's time counts against the deadline."""
    pytest.importorskip("distributed")
    from rbstab.sweep import executors

    def dropped(address, timeout):
        assert timeout == 2.5
        raise TimeoutError("timed out")

    def never(*args, **kwargs):  # pragma: no cover - must not be reached
        raise AssertionError("the client is not tried after the deadline")

    monkeypatch.setattr(socket, "create_connection", dropped)
    monkeypatch.setattr(executors.threading, "Thread", never)
    with pytest.raises(executors.ExecutorError,
                       match=r"at tcp://10.1.2.3:8786: no answer within 2.5 s \(the host is unreachable"):
        executors.make_executor("dask", scheduler="tcp://10.1.2.3:8786", connect_timeout=2.5)


def test_connect_timeout_is_for_dask_only(tmp_path):
    result = invoke("sweep", CASE3, "-o", tmp_path, "--connect-timeout", "1")
    assert result.exit_code == 2 and "--connect-timeout is for --executor dask" in result.stderr
    result = invoke("sweep", CASE3, "-o", tmp_path, "--scheduler", "tcp://127.0.0.1:1", "--connect-timeout", "0")
    assert result.exit_code == 2 and "'--connect-timeout': 0.0 is not in the range x>0" in result.stderr
