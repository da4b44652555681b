"""Shared fixtures: the paper's body and gains (its Table 1)."""

from __future__ import annotations

import os
import socket
import threading
import types
from pathlib import Path

import numpy as np
import pytest

from rbstab.model import Gains, RigidBody

ROOT = Path(__file__).resolve().parents[1]
#: ``rbstab report`` draws an animation of each run (seconds each); the tests that do not look
#: at them leave them out (tests/test_animate.py asks for them with --animation-frames).
os.environ.setdefault("RBSTAB_ANIMATION_FRAMES", "0")
PAPER_CONFIGS = sorted((ROOT / "configs" / "paper").glob("*.yaml"))

D = np.diag


#: Scripts run under numba's CUDA simulator (:func:`simulated_once`) -> the test file that reads them.
SIMULATED = {"cuda_simulated.py": "test_cuda.py", "cuda_chains_simulated.py": "test_cuda_chains.py"}


def pytest_configure(config):
    """Each pytest-xdist worker on CPUs of its own (the machine's split evenly), inherited by
    the commands it starts: a command's default ``-j`` (its CPUs) is then its share, as on a
    machine running nothing else, instead of every command's worker processes competing for
    every CPU."""
    worker = getattr(config, "workerinput", None)
    if worker is None or not hasattr(os, "sched_setaffinity"):
        return
    cpus, n, k = sorted(os.sched_getaffinity(0)), int(worker["workercount"]), int(worker["workerid"][2:])
    if len(cpus) >= n:
        os.sched_setaffinity(0, cpus[k * len(cpus) // n: (k + 1) * len(cpus) // n])


def pytest_sessionstart(session):
    """Compile the engine's kernels (the engine, the sign law, chains, scipy's methods') into the cache once,
    before any test (and before pytest-xdist starts its workers, which then load them
    instead of each compiling them again); then start the CUDA simulator's scripts the
    session's tests read, in processes of their own, so that no worker waits for them."""
    if hasattr(session.config, "workerinput"):  # an xdist worker: the controller did it
        return
    from rbstab.engine import ensure_compiled

    ensure_compiled(sign_law=True, chain=True, solve_ivp=True)
    _start_simulated(session.config)


def _start_simulated(config) -> None:
    """Run each of :data:`SIMULATED` whose test file the session collects in the background;
    its output, error and exit status go to ``<script stem>.out/.err/.rc`` in a folder named
    by ``RBSTAB_SIMULATED`` (the workers inherit it)."""
    import importlib.util
    import shutil
    import subprocess
    import sys
    import tempfile

    if importlib.util.find_spec("numba_cuda") is None:
        return
    asked = [Path(str(a).split("::")[0]).resolve() for a in (config.args or ["."])]
    scripts = [s for s, test in SIMULATED.items()
               if any(p == ROOT / "tests" / test or p in (ROOT / "tests" / test).parents for p in asked)]
    if not scripts:
        return
    folder = Path(tempfile.mkdtemp(prefix="rbstab-simulated-"))
    os.environ["RBSTAB_SIMULATED"] = str(folder)
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    running = []
    for script in scripts:
        stem = folder / Path(script).stem
        Path(f"{stem}.out").touch()  # the workers' sign that it is under way
        command = (f'"{sys.executable}" "{ROOT / "tests" / script}" "{ROOT}" > "{stem}.out" 2> "{stem}.err"; '
                   f'echo $? > "{stem}.rc.tmp" && mv "{stem}.rc.tmp" "{stem}.rc"')
        running.append(subprocess.Popen(["sh", "-c", command], env=env, start_new_session=True))

    def stop():
        for process in running:
            if process.poll() is None:
                os.killpg(process.pid, 9)
        shutil.rmtree(folder, ignore_errors=True)

    config.add_cleanup(stop)


def pytest_collection_modifyitems(config, items):
    """The tests marked ``slow`` first (in their order): pytest-xdist's workers share out the
    short ones at the end instead of one running a long test alone."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def paper_body(gravity=(0.0, 0.0, 0.0)) -> RigidBody:
    return RigidBody(41.0, D([10.0, 8.0, 0.4]), np.array([0.15, 0.10, -0.42]), np.array(gravity, float))


def paper_gains(**changes) -> Gains:
    base = dict(
        k_t=D([4100.0, 4100, 3280]),
        l_t=D([200.0, 200, 140]),
        k_r=D([400.0, 400, 320]),
        l_r=D([60.0, 60, 42]),
        k_c=D([12300.0, 12300, 9840]),
        l_c=D([600.0, 600, 420]),
        k_d=D([12300.0, 12300, 9840]),
        l_d=D([1200.0, 1200, 840]),
        k_s=2000.0,
        boundary_layer=0.005,
    )
    base.update(changes)
    return Gains(**base)


def initial_blocks(omega=(16.0, 32.0, -16.0), theta=(0.0, 0.0, 0.0)) -> dict:
    return {
        "theta": np.array(theta, float),
        "omega": np.array(omega, float),
        "position": np.zeros(3),
        "velocity": np.zeros(3),
        "controller_state": np.zeros(3),
    }


def settings(**kw):
    base = dict(t_end=2.0, n_samples=2001, method="DOP853", rtol=1e-8, atol=1e-10, max_step=np.inf, gimbal_margin=1e-3)
    base.update(kw)
    return types.SimpleNamespace(**base)


def simulated_once(tmp_path_factory, script: str) -> dict:
    """The findings (the JSON of its last line) of ``tests/<script>`` run once a test
    session under numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, chosen when numba
    starts: a process of its own): started with the session (:func:`_start_simulated`), or
    else run by the first pytest-xdist worker to ask, the others waiting on a lock and
    reading its file in the session's temporary folder."""
    import fcntl
    import json
    import subprocess
    import sys
    import time

    started = os.environ.get("RBSTAB_SIMULATED")
    if started and (Path(started) / f"{Path(script).stem}.out").exists():  # started with the session
        stem = Path(started) / Path(script).stem
        deadline = time.monotonic() + 600
        while not stem.with_suffix(".rc").exists():
            assert time.monotonic() < deadline, f"{script} did not finish in 600 s"
            time.sleep(0.2)
        assert stem.with_suffix(".rc").read_text().strip() == "0", stem.with_suffix(".err").read_text()[-3000:]
        return json.loads(stem.with_suffix(".out").read_text().splitlines()[-1])
    folder = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):  # <session>/popen-gwN: the session's folder is its parent
        folder = folder.parent
    shared = folder / f"{Path(script).stem}.json"
    with open(folder / f"{Path(script).stem}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not shared.exists():
            env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
            done = subprocess.run([sys.executable, str(ROOT / "tests" / script), str(ROOT)], env=env,
                                  capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, done.stderr[-3000:]
            shared.write_text(done.stdout.splitlines()[-1])
    return json.loads(shared.read_text())


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


@pytest.fixture
def silent_server():
    """``tcp://127.0.0.1:PORT`` of a server that accepts connections and never says a word
    (no Dask scheduler: an HTTP server, say)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.1)
    stop, accepted = threading.Event(), []

    def serve():
        while not stop.is_set():
            try:
                accepted.append(server.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    stop.set()
    thread.join()
    for conn in accepted:
        conn.close()
    server.close()


def tree_spelling(config):
    """The one-body config ``config`` written in the tree's spelling (bodies, joints): its
    body ``body`` held to the ground at R by its joint ``controller``."""
    from rbstab.config.loader import config_from_mapping, tree_resolved  # heavy: pydantic, numba

    return config_from_mapping(tree_resolved(config.resolved))
