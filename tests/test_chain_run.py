"""rbstab run, show, report and animate of chains of bodies: the file layout (body and joint
dimensions, names as coordinates, CF attributes), the summary with its rate check, the API,
the report's chain section and the animation, and the admissible region's stop."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from click.testing import CliRunner

import rbstab
from rbstab.config.loader import load_config
from rbstab.io.hdf5 import CHAIN_FORMAT, read_attributes
from rbstab_cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["--set", "simulation.t_end=0.5", "--set", "simulation.n_samples=501"]


def test_run_json_of_a_chain_is_one_bodys_record(tmp_path):
    """rbstab run --json: a chain's object has the keys of one body's (the rate check's
    reason included), its variant "chain"."""
    import json

    result = CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "paper" / "case1_permanent.yaml"),
                                      str(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"), *SHORT, "--json",
                                      "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    body, chain = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
    assert set(body) == set(chain) and "rate_check_reason" in chain
    assert (body["variant"], chain["variant"]) == ("permanent", "chain")


@pytest.mark.parametrize("name", ["double_pendulum", "stance_ankle_hip", "knee"])
def test_run_writes_a_chain_file_with_body_and_joint_dimensions(name, tmp_path):
    result = CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "examples" / f"{name}.yaml"), *SHORT,
                                      "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "a chain of 2 bodies" in result.output and "rate check pass" in result.output
    path = tmp_path / f"{name}.h5"
    attrs = read_attributes(path, data=True)  # every checksum verified
    assert attrs["rbstab_format"] == CHAIN_FORMAT and attrs["variant"] == "chain"
    config = load_config(ROOT / "configs" / "examples" / f"{name}.yaml")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert list(ds["body"].values) == list(config.chain.body_names)
        assert list(ds["joint"].values) == list(config.chain.joint_names)
        assert ds["theta"].dims == ("time", "body", "axis") and ds["torque_n"].dims == ("time", "joint", "axis")
        assert ds["constraint_error"].dims == ("time", "joint", "axis") and ds["lyapunov"].dims == ("time",)
        assert ds["joint_theta"].attrs["units"] == "rad" and ds["constraint_force"].attrs["units"] == "N"
        np.testing.assert_array_equal(ds["theta"].values[0, 1], config.initial_state[config.chain.body_names[1]]["theta"])
        v = ds["lyapunov"].values
    assert attrs["summary_lyapunov_initial"] == pytest.approx(v[0])
    assert attrs["summary_lyapunov_rate_check"] == "pass"
    shown = CliRunner().invoke(cli, ["show", str(path)])
    assert shown.exit_code == 0 and f"bodies     {','.join(config.chain.body_names)}" in shown.output


def test_the_api_runs_a_chain_and_opens_its_file(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        path = rbstab.run(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml", tmp_path,
                          overrides=["simulation.t_end=0.3", "simulation.n_samples=301"])
    ds = rbstab.open_result(path)
    assert ds.attrs["variant"] == "chain" and ds["force_h"].dims == ("time", "body", "axis")
    assert float(ds["lyapunov"][-1]) < float(ds["lyapunov"][0])  # feedback and no saturation reached: v falls


def test_a_report_draws_and_animates_a_chains_bodies_and_joints(tmp_path):
    out = tmp_path / "results"
    assert CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"),
                                    str(ROOT / "configs" / "paper" / "case1_permanent.yaml"), *SHORT,
                                    "-o", str(out)]).exit_code == 0
    path = out / "stance_ankle_hip.h5"
    report = tmp_path / "report"
    made = CliRunner().invoke(cli, ["report", str(path), str(out / "case1_permanent.h5"), "-o", str(report),
                                    "--animation-frames", "4"])
    assert made.exit_code == 0, made.output
    page = (report / "index.html").read_text()
    tables = (report / "summary.md").read_text()  # one table of runs: the chain's figures by body and joint
    assert "| stance_ankle_hip | stance_ankle_hip.h5 | chain | success |" in tables
    assert "| stance_ankle_hip | legs [" in tables and "; trunk [" in tables and "| ankle [" in tables
    assert "ankle: torque_n [120, 120, inf], clip; hip: torque_n [150, 150, inf], clip" in tables
    assert "stance_ankle_hip: the motion" in page and "4 frames evenly" in page
    for kind in ("rotational", "translational", "forces", "lyapunov", "phase"):  # one body's figures, by member
        assert (report / "figures" / f"stance_ankle_hip_{kind}.png").stat().st_size > 10_000
    assert "H is zero throughout (no such feedback): not drawn" in page  # the stance has no K_t, L_t
    for name in ("compare_rotational", "compare_translational", "compare_lyapunov", "norms"):  # with the body
        assert (report / "figures" / f"{name}.png").stat().st_size > 10_000
    assert (report / "figures" / "case1_permanent_rotational.png").exists()  # the one-body run as before
    import pandas as pd

    summary = pd.read_csv(report / "summary.csv").set_index("run")  # a row a run; the chain's figures per member
    assert set(summary.index) == {"case1_permanent", "stance_ankle_hip"}
    assert np.isnan(summary.loc["stance_ankle_hip", "final_theta_1"]) and np.isnan(
        summary.loc["case1_permanent", "max_abs_constraint_error_hip_x"])
    assert summary.loc["stance_ankle_hip", [f"max_abs_constraint_error_hip_{a}" for a in "xyz"]].max() < 1e-6
    chain = summary.loc["stance_ankle_hip"]
    assert chain["final_theta_trunk_x"] == pytest.approx(rbstab.open_result(path)["theta"][-1, 1, 0].item())
    assert chain["rest"] in ("settled", "not settled", "rest away from equilibrium", "unstable rest")
    assert chain["fraction_saturated_torque_n_ankle_x"] == 0.0
    for name in ("a.gif", "a.png"):
        result = CliRunner().invoke(cli, ["animate", str(path), "-o", str(tmp_path / name), "--speed", "1"])
        assert result.exit_code == 0, result.output
        assert (tmp_path / name).stat().st_size > 5_000


def test_a_chain_run_stops_where_it_leaves_the_admissible_region(tmp_path):
    """simulation.limits bound every body's Theta, Omega, X, V and every joint's E_j: a push
    of the trunk past 0.2 rad stops the run, failed, naming the body, the quantity and the time."""
    result = CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"),
                                      "--set", "simulation.limits.theta=0.2", "--set", "initial_state.trunk.omega=[-3,0,0]",
                                      *SHORT, "-o", str(tmp_path)])
    assert result.exit_code == 0 and "Traceback" not in result.output  # it fell: a result
    assert "stance_ankle_hip: failed, fell (" in result.output
    assert "left the admissible region: |theta_1| of trunk reached simulation.limits.theta = 0.2 rad at t = " in result.output
    with xr.open_dataset(tmp_path / "stance_ankle_hip.h5", engine="h5netcdf") as ds:
        theta = ds["theta"].values
    finite = np.isfinite(theta[:, 1, 0])
    assert not finite.all() and np.abs(theta[finite, 1, 0]).max() <= 0.2 + 1e-9


def test_the_runs_of_one_chain_come_in_blocks_of_at_most_postprocess_block_runs():
    """simulate_blocks integrates and post-processes the runs of one chain
    POSTPROCESS_BLOCK at a time (the samples and outputs held at once), and a run's outputs
    do not depend on the others of its call: they equal simulate's, bit for bit."""
    from rbstab.simulator import POSTPROCESS_BLOCK, simulate, simulate_blocks

    path = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    n = POSTPROCESS_BLOCK + 3
    configs = [load_config(path, ["simulation.t_end=0.2", "simulation.n_samples=21",
                                      f"initial_state.trunk.theta.0={0.1 * k / n}"]) for k in range(n)]
    blocks = list(simulate_blocks(configs))
    assert [members for members, _ in blocks] == [list(range(POSTPROCESS_BLOCK)), list(range(POSTPROCESS_BLOCK, n))]
    last, alone = blocks[1][1].result(2), simulate(configs[-1])
    assert last.status == alone.status == "success"
    for name in ("theta", "joint_theta", "constraint_error", "lyapunov"):
        np.testing.assert_array_equal(last.outputs[name], alone.outputs[name])


def test_one_body_written_as_a_tree_runs_and_says_so(tmp_path):
    """A tree of one body on one permanent joint: rbstab run prints its line (one joint's
    figures are scalars in the file), in the singular."""
    stance = yaml.safe_load((ROOT / "configs" / "examples" / "stance_ankle.yaml").read_text())
    tree = {"name": "one_tree", "gravity": stance["body"]["gravity"],
            "bodies": [{"name": "body", "mass": stance["body"]["mass"], "inertia": stance["body"]["inertia"]}],
            "joints": [{"name": "ankle", "parent": "ground", "parent_point": [0.0, 0.0, 0.0], "child": "body",
                        "child_point": stance["body"]["attachment_point"], "variant": "permanent",
                        "k_r": stance["controller"]["k_r"], "l_r": stance["controller"]["l_r"]}],
            "initial_state": {"body": {"theta": stance["initial_state"]["theta"]}},
            "simulation": {"t_end": 0.5, "n_samples": 51}}
    path = tmp_path / "one_tree.yaml"
    path.write_text(yaml.safe_dump(tree))
    result = CliRunner().invoke(cli, ["run", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0 and "Traceback" not in result.output, result.output
    assert "one_tree: success" in result.output and "(a chain of 1 body, " in result.output


def test_simulate_takes_a_chain_and_gives_what_its_file_holds(tmp_path):
    """rbstab.simulate of a chain's file: the run file's variables, dimensions (body, joint
    with their names) and attributes, in memory."""
    path = ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"
    short = ["simulation.t_end=0.3", "simulation.n_samples=31"]
    ds = rbstab.simulate(path, overrides=short)
    written = rbstab.open_result(rbstab.run(path, tmp_path, overrides=short))
    assert ds["theta"].dims == ("time", "body", "axis") and list(ds["body"].values) == ["legs", "trunk"]
    assert ds["constraint_error"].dims == ("time", "joint", "axis") and list(ds["joint"].values) == ["ankle", "hip"]
    assert set(ds.data_vars) == set(written.data_vars) and set(ds.attrs) == set(written.attrs)
    for key in ds.data_vars:
        assert ds[key].dims == written[key].dims, key
        np.testing.assert_array_equal(ds[key].values, written[key].values, err_msg=key)


def _euler_rate(theta: np.ndarray) -> np.ndarray:
    """B(Theta) of eq 1 (docs/physics.md's middle row [s3, c3, 0]), (..., 3, 3), in numpy."""
    s2, c2 = np.sin(theta[..., 1]), np.cos(theta[..., 1])
    s3, c3 = np.sin(theta[..., 2]), np.cos(theta[..., 2])
    zero, one = np.zeros_like(s2), np.ones_like(s2)
    return np.stack([np.stack([c3 / c2, -s3 / c2, zero], -1), np.stack([s3, c3, zero], -1),
                     np.stack([-s2 * c3 / c2, s2 * s3 / c2, one], -1)], -2)


def test_a_chains_clipped_joint_torque_is_flagged_where_its_command_reaches_the_limit():
    """The stance double pendulum leaning 0.25 rad, the ankle's N_j clipped at 120 N m: torque_n_saturated is
    1 exactly where eq 23's command -B(Theta_j)'K_r Theta_j - L_r Omega_j (here in numpy,
    from the run's Theta_j and Omega_j) reaches the joint's limit, N_j is the clipped
    command, and the summary's fraction per joint and axis is the flags' mean; a body
    without limits on H and permanent joints (no Lambda law) are never flagged."""
    config = load_config(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml",
                             ["simulation.t_end=2.0", "simulation.n_samples=2001",
                              "initial_state.legs.theta.0=0.25"])
    result = rbstab.simulator.simulate(config)
    out, summary = result.outputs, result.summary
    assert result.status == "success"
    theta, omega = out["joint_theta"], out["joint_omega"]  # (m, joints, 3)
    k_r = np.array([[1000.0, 1000.0, 100.0], [500.0, 500.0, 100.0]])
    l_r = np.array([[300.0, 300.0, 30.0], [100.0, 100.0, 20.0]])
    limit = np.array([[120.0, 120.0, np.inf], [150.0, 150.0, np.inf]])
    command = -np.einsum("mjik,mji->mjk", _euler_rate(theta), k_r * theta) - l_r * omega
    expected = (np.abs(command) >= limit).astype(float)
    assert expected[:, 0, 0].sum() >= 20  # the ankle's sway torque is held at its limit for a while
    close = np.abs(np.abs(command) - limit) <= 1e-9 * np.minimum(limit, 1e300)  # on the limit to rounding
    np.testing.assert_array_equal(np.where(close, 0.0, out["torque_n_saturated"]), np.where(close, 0.0, expected))
    np.testing.assert_allclose(out["torque_n"], np.clip(command, -limit, limit), rtol=1e-12, atol=1e-9)
    assert out["torque_n_saturated"].shape == out["force_h_saturated"].shape == theta.shape
    assert not out["force_h_saturated"].any() and not out["constraint_force_saturated"].any()
    np.testing.assert_allclose(summary["fraction_saturated_torque_n"], out["torque_n_saturated"].mean(axis=0),
                               rtol=0, atol=1e-15)
    assert np.shape(summary["fraction_saturated_force_h"]) == np.shape(summary["final_theta"]) == (2, 3)
    np.testing.assert_array_equal(summary["final_theta"], out["theta"][-1])
    rising = np.sum(out["lyapunov_rate"] > 0.0) * (result.time[1] - result.time[0])
    assert summary["time_lyapunov_rising"] == pytest.approx(rising, rel=1e-12)


def test_a_chains_lyapunov_figure_is_one_bodys_with_v_minus_w(tmp_path, monkeypatch):
    """A chain run's v figure is one body's: its terms (the tree's), v beside v - W for a
    pushed chain (W from the file; the line drawn is the stored v - W), the analytic and
    numerical dv/dt and their difference; the push marked on every panel."""
    from rbstab.report.figures import FigureWriter, lyapunov_figure
    from rbstab.report.load import load_inputs

    saved = {}
    monkeypatch.setattr(FigureWriter, "_savefig", lambda self, fig, path, fmt: saved.setdefault(path.stem, fig))
    push = 'disturbances=[{kind: impulse, quantity: torque, value: [0, 5, 0], start: 0.3, body: trunk}]'
    done = CliRunner().invoke(cli, ["run", str(ROOT / "configs" / "examples" / "stance_ankle_hip.yaml"), "-o",
                                    str(tmp_path), "--set", "simulation.t_end=1", "--set", push])
    assert done.exit_code == 0, done.output
    (run,) = load_inputs([tmp_path / "stance_ankle_hip.h5"]).runs
    lyapunov_figure(run, FigureWriter(tmp_path))
    fig = saved["stance_ankle_hip_lyapunov"]
    assert len(fig.axes) == 4  # v and its terms; v, v - W, W; dv/dt; analytic - numerical
    s = run.series("lyapunov", "disturbance_work")
    (work,) = [line for ax in fig.axes for line in ax.get_lines() if line.get_gid() == "lyapunov-minus-work"]
    np.testing.assert_array_equal(work.get_ydata(), s["lyapunov"] - s["disturbance_work"])
    assert s["disturbance_work"][-1] > 0.0
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert any("translational" in label for label in labels) and any("rotational" in label for label in labels)
    for ax in fig.axes:
        (impulse,) = [line for line in ax.get_lines() if line.get_gid() == "disturbance-impulse"]
        assert list(impulse.get_xdata()) == [0.3, 0.3]
