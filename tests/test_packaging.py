"""What a plain ``pip install rbstab`` brings: every package rbstab's code imports.

The test extra installs more (dask comes with ``distributed``), so a module imported by
rbstab but declared only in an extra passes every other test and fails a user who
installed rbstab alone (``rbstab.open_sweep`` needed ``dask`` and raised
``ModuleNotFoundError`` after ``pip install .``).
"""

from __future__ import annotations

import ast
import functools
import importlib.metadata as metadata
import sys
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [ROOT / "src" / "rbstab", ROOT / "cli"]
LOCAL = {"rbstab", "rbstab_cli"}

#: Imported modules that a plain install need not have, and the extra that brings each
#: (their import is guarded: a clear message names the extra).
OPTIONAL = {"distributed": "dask", "flint": "verify", "mujoco": "import"}


def _imported_modules() -> dict[str, Path]:
    """Top-level module -> a file of rbstab that imports it (every import statement,
    at module level or inside a function)."""
    found: dict[str, Path] = {}
    for folder in SOURCES:
        for path in sorted(folder.rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    found.setdefault(name.partition(".")[0], path)
    return found


def _third_party(modules: dict[str, Path]) -> dict[str, Path]:
    return {m: p for m, p in modules.items() if m not in sys.stdlib_module_names and m not in LOCAL}


def _requirements() -> tuple[set[str], dict[str, set[str]]]:
    """(the distributions of a plain install, extra -> its distributions) of rbstab, from
    its installed metadata (``Requires-Dist``)."""
    core: set[str] = set()
    extras: dict[str, set[str]] = {}
    for req in map(Requirement, metadata.requires("rbstab") or []):
        name = canonicalize_name(req.name)
        if req.marker is None or req.marker.evaluate({"extra": ""}):
            core.add(name)
        for extra in metadata.metadata("rbstab").get_all("Provides-Extra") or []:
            if req.marker is not None and req.marker.evaluate({"extra": extra}):
                extras.setdefault(extra, set()).add(name)
    return core, extras


@functools.cache
def _module_distributions() -> dict[str, list[str]]:
    return metadata.packages_distributions()


def _distributions(module: str) -> set[str]:
    return {canonicalize_name(d) for d in _module_distributions().get(module, [])}


def test_the_scan_finds_the_imports_it_must_check():
    third = _third_party(_imported_modules())
    # the readers' and the engine's imports, one inside a function (dask in open_sweep)
    assert {"numpy", "numba", "h5py", "xarray", "dask", "distributed"} <= set(third), sorted(third)
    assert "os" not in third and "rbstab" not in third


def test_every_module_rbstab_imports_comes_with_a_plain_install():
    core, extras = _requirements()
    missing = []
    for module, path in sorted(_third_party(_imported_modules()).items()):
        provided_by = _distributions(module)
        assert provided_by, f"{module} (imported in {path.relative_to(ROOT)}) is not installed"
        if module in OPTIONAL:
            assert provided_by & extras.get(OPTIONAL[module], set()), (module, OPTIONAL[module], extras)
        elif not provided_by & core:
            missing.append(f"{module} (imported in {path.relative_to(ROOT)}; distribution {sorted(provided_by)})")
    assert not missing, "imported but not in [project] dependencies: " + "; ".join(missing)
