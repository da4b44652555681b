"""Benchmark: a sweep's fixed costs, the time before its first line and to its exit.

Case 3 of the paper (``configs/paper/case3_embedded.yaml``) at rtol 1e-6, atol 1e-8, the
command ``rbstab sweep SPEC -j JOBS --no-progress`` in a new process each time (warm
compile cache, the environment without ``PYTHONDONTWRITEBYTECODE``). Prints, best and
worst of ``--repeat``:

- **first line**: seconds from the process's start to its first line of output (the
  sweep's "N runs on ..." line, said once every run is planned and validated and
  ``sweep.yaml`` is written), and the CPU seconds the command's process used until then
  (``/proc``: what the wall time would be on an otherwise idle machine, the workers'
  fork server, which starts at the same time, on the other core), for three specs
  written here:

  - ``explicit zip``: 10,000 runs spelled out as ``zip`` lists (body.mass,
    controller.k_c, l_c, k_t, initial_state.omega: 13 numbers a run, ~2.5 MB of YAML);
  - ``initial-state list``: 10,000 values of initial_state.omega as one ``zip`` list
    (~0.5 MB);
  - ``two runs``: a ``zip`` of two values of initial_state.omega;

- **exit**: seconds from the process's start to its exit of the 10,000-run initial-state
  sweep of ``benchmarks/throughput.py`` (Omega ~ N((16, 32, -16), 4^2), a ``random``
  spec), the default store;
- **YAML**: seconds to parse the explicit-zip spec in this process, with the loader rbstab
  uses (libyaml's parser) and with PyYAML's pure-Python one (the fallback where PyYAML
  has no libyaml).

Usage::

    python benchmarks/startup.py [--repeat 3] [--jobs 2] [--n 10000] [--rbstab COMMAND]

``--rbstab``: the command timed (default: the ``rbstab`` beside this Python), e.g. a
script that runs another checkout's ``python -m rbstab``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
CASE3 = ROOT / "configs" / "paper" / "case3_embedded.yaml"
TOLERANCES = ["simulation.rtol=1e-6", "simulation.atol=1e-8"]
RBSTAB = str(Path(sys.executable).parent / "rbstab")


def _numbers(values) -> list:
    """Plain floats with 14 significant digits (what a hand-written or generated spec holds)."""
    return np.vectorize(lambda v: float(f"{v:.14g}"), otypes=[object])(np.asarray(values)).tolist()


def specs(n: int) -> dict[str, dict]:
    """The three first-line specs (module docstring) of ``n`` runs."""
    rng = np.random.default_rng(0)
    omega = rng.normal([16, 32, -16], 4, size=(n, 3))
    gain = lambda base, lo, hi: np.asarray(base) * rng.uniform(lo, hi, (n, 1))  # noqa: E731
    zipped = {
        "body.mass": _numbers(41 * rng.uniform(0.5, 1.5, n)),
        "controller.k_c": _numbers(gain([12300, 12300, 9840], 0.5, 2)),
        "controller.l_c": _numbers(gain([600, 600, 420], 0.5, 2)),
        "controller.k_t": _numbers(gain([4100, 4100, 3280], 0.7, 1.4)),
        "initial_state.omega": _numbers(omega),
    }
    return {
        "explicit zip": {"name": "explicit-zip", "base": str(CASE3), "zip": zipped},
        "initial-state list": {"name": "initial-state-list", "base": str(CASE3),
                               "zip": {"initial_state.omega": _numbers(omega)}},
        "two runs": {"name": "two-runs", "base": str(CASE3), "zip": {"initial_state.omega": _numbers(omega[:2])}},
    }


def random_spec(n: int) -> dict:
    """The initial-state sweep of ``benchmarks/throughput.py``."""
    return {"name": "initial-state", "base": str(CASE3),
            "random": {"n": n, "seed": 0, "params": {"initial_state.omega": {"normal": {"mean": [16, 32, -16],
                                                                                        "std": 4}}}}}


def environment() -> dict:
    """This environment without ``PYTHONDONTWRITEBYTECODE`` (with it, every process compiles
    rbstab's modules from source, which a user's installation does not)."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def cpu_seconds(pid: int) -> float | None:
    """CPU seconds (user and system) process ``pid`` has used so far, or None where
    ``/proc`` does not say (not Linux)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def timed(cmd: list[str], stop_at_first_line: bool = False) -> tuple[float | None, float, int, float | None]:
    """(seconds to the first line of stdout or stderr, seconds to the exit, exit status,
    the command's own CPU seconds to its first line) of ``cmd``; ``stop_at_first_line``:
    its processes killed at the first line (status 0)."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=environment(),
                            start_new_session=True)
    first = cpu = None
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        sel.register(proc.stderr, selectors.EVENT_READ)
        while sel.get_map():
            for key, _ in sel.select():
                if key.fileobj.readline():
                    if first is None:
                        first, cpu = time.perf_counter() - start, cpu_seconds(proc.pid)
                    if stop_at_first_line:
                        os.killpg(proc.pid, signal.SIGKILL)  # its session: the sweep and its workers
                        proc.wait()
                        return first, time.perf_counter() - start, 0, cpu
                else:
                    sel.unregister(key.fileobj)
    rc = proc.wait()
    return first, time.perf_counter() - start, rc, cpu


def sweep_command(path: Path, out: Path, jobs: int, rbstab: str = RBSTAB) -> list[str]:
    return [rbstab, "sweep", str(path), "-o", str(out), "-j", str(jobs), "--no-progress",
            *[a for t in TOLERANCES for a in ("--set", t)]]


def parse_times(text: str) -> tuple[float, float]:
    """(seconds with rbstab's loader, seconds with PyYAML's pure-Python one) of ``text``."""
    from rbstab.config import yaml_io

    paused = getattr(yaml_io, "gc_paused", contextlib.nullcontext)

    def best(loader) -> float:
        times = []
        for _ in range(3):
            start = time.perf_counter()
            with paused():
                yaml.load(text, Loader=loader)  # noqa: S506 - safe loaders
            times.append(time.perf_counter() - start)
        return min(times)

    return best(getattr(yaml_io, "LOADER", yaml_io._Loader)), best(yaml_io._Loader)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--n", type=int, default=10_000)
    parser.add_argument("--rbstab", default=RBSTAB, help="the command timed")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        subprocess.run([args.rbstab, "run", str(CASE3), "-o", str(folder / "warm")], env=environment(),
                       capture_output=True, check=True)  # the compile cache and the bytecode caches warm
        print(f"{'what':<34} {'size':>9} {'best [s]':>9} {'worst [s]':>10} {'CPU [s]':>12}")
        for i, (what, data) in enumerate(specs(args.n).items()):
            path = folder / f"spec-{i}.yaml"
            path.write_text(yaml.safe_dump(data, default_flow_style=None, sort_keys=False))
            firsts, cpus = [], []
            for r in range(args.repeat):
                first, _, rc, cpu = timed(sweep_command(path, folder / f"out-{i}-{r}", args.jobs, args.rbstab),
                                          stop_at_first_line=True)
                if rc != 0:
                    raise SystemExit(f"{what}: exit status {rc}")
                firsts.append(first)
                cpus.append(cpu)
            size = path.stat().st_size / 1e6
            cpu = "" if None in cpus else f"{min(cpus):.2f}-{max(cpus):.2f}"
            print(f"first line, {what:<22} {size:>7.2f}MB {min(firsts):>9.2f} {max(firsts):>10.2f} {cpu:>12}",
                  flush=True)
            if i == 0:
                text = path.read_text()
        path = folder / "random.yaml"
        path.write_text(yaml.safe_dump(random_spec(args.n)))
        exits = []
        for r in range(args.repeat):
            _, wall, rc, _ = timed(sweep_command(path, folder / f"out-random-{r}", args.jobs, args.rbstab))
            if rc != 0:
                raise SystemExit(f"initial-state sweep: exit status {rc}")
            exits.append(wall)
        print(f"exit, initial-state sweep of {args.n:<6} {'':>9} {min(exits):>9.2f} {max(exits):>10.2f}"
              f"   (-j {args.jobs})")
        fast, slow = parse_times(text)
        print(f"YAML of the explicit zip: rbstab's loader {fast:.2f} s, PyYAML's pure-Python loader {slow:.2f} s")


if __name__ == "__main__":
    main()
