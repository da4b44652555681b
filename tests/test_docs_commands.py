"""Every example command of the docs runs as written.

Each fenced ```` ```bash ```` block of README.md and docs/*.md that calls ``rbstab`` is run
with ``bash -euo pipefail`` in a fresh folder that looks like the repository's root (its
``configs/`` linked in), so each block must stand on its own, as a reader copies it. A
block passes when it exits with status 0 and every path that its comments promise
(``# -> results/sweeps/gains_case3/``; ``<name>`` read as any name) exists afterwards.

Synopses are fenced as ``text``, not ``bash``. A block that cannot run here says so in the
line before it: ``<!-- docs-test: skip (reason) -->`` (a Dask cluster at a given address);
a block that takes long (reports drawing ~20 figures, a 41 x 41 basin) is marked
``<!-- docs-test: slow -->`` and runs too, unless ``pytest -m "not slow"`` leaves it out.
A line that makes and activates a virtual environment and installs rbstab (README) stands
for the environment this test already runs in: the command after the installation is
run, except ``pytest``, which is this suite.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^(?:<!-- docs-test: (?P<mark>slow|skip \((?P<reason>[^)]*)\)) -->\n)?```bash\n(?P<body>.*?)^```",
                   re.M | re.S)
#: ``python3 -m venv .venv && . .venv/bin/activate && pip install ... && `` (README).
INSTALL = re.compile(r"^python3 -m venv \S+ && \. \S+/bin/activate && pip install [^&]+&& ")


@dataclass(frozen=True)
class Block:
    where: str  # file:line of the opening fence
    body: str
    skip: str | None  # why it cannot run here
    slow: bool


def _blocks() -> list[Block]:
    out = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            if re.search(r"(^|[\s;&|(])rbstab\s", m["body"]):
                line = text.count("\n", 0, m.start("body"))
                out.append(Block(f"{path.relative_to(ROOT)}:{line}", m["body"], m["reason"], m["mark"] == "slow"))
    return out


def _runnable(body: str) -> str:
    """The block with the environment set-up lines reduced to their command (module docstring)."""
    lines = []
    for line in body.splitlines():
        command = INSTALL.sub("", line)
        if command != line and command.strip() == "pytest":
            continue
        lines.append(command)
    return "\n".join(lines) + "\n"


def _promised(body: str) -> list[str]:
    """Paths the comments promise: ``... # -> results/x/`` (``<name>`` read as ``*``)."""
    paths = re.findall(r"#[^\n]*?->\s*(\S+)", body)
    return [re.sub(r"<[^>]*>", "*", p) for p in paths]


BLOCKS = _blocks()


def test_the_docs_have_command_blocks():
    found = {b.where.split(":")[0] for b in BLOCKS}
    assert {"README.md", "docs/report.md", "docs/sweeps.md", "docs/analysis.md"} <= found, found
    assert sum(b.skip is not None for b in BLOCKS) <= 1  # only the Dask cluster's address


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.pop("PYTHONWARNINGS", None)
    return env


@pytest.mark.parametrize("block", [pytest.param(b, id=b.where, marks=[pytest.mark.slow] if b.slow else [])
                                   for b in BLOCKS])
def test_docs_command_block_runs_as_written(block, tmp_path):
    if block.skip:
        pytest.skip(block.skip)
    if not (Path(sys.executable).parent / "rbstab").exists():
        pytest.skip("no rbstab command beside this Python (install the project: pip install -e .)")
    for tool in re.findall(r"\|\s*(\w+)", block.body):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")
    (tmp_path / "configs").symlink_to(ROOT / "configs")
    script = tmp_path / "block.sh"
    script.write_text(_runnable(block.body), encoding="utf-8")
    done = subprocess.run(["bash", "-euo", "pipefail", str(script)], cwd=tmp_path, env=_environment(),
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"{block.where} failed ({done.returncode}):\n{block.body}\n{done.stdout}\n{done.stderr}"
    for path in _promised(block.body):
        assert glob.glob(str(tmp_path / path)), f"{block.where}: {path} promised by a comment is missing"
