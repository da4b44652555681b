"""The layering of rbstab, read from the source: every import of every module of
``src/rbstab`` and ``cli`` (function-level ones included, relative ones resolved) forms a
graph with no cycle, in which no module imports one of a higher layer:

    base -> kinematics -> model -> variants -> config -> engine -> simulate -> io
         -> sweep, analysis -> report -> api -> cli

``base`` holds what every layer may use and that imports nothing of rbstab: the package's
``__init__`` (its version; its public names are imported on first use, by name),
:mod:`rbstab.jit` (the compiler), :mod:`rbstab.layout` (the state and output blocks) and
:mod:`rbstab.warning_codes`. :mod:`rbstab.config` (validated input, built from the model
and the variants' registry) and :mod:`rbstab.resources` (the memory a run needs) sit
between the variants and the engine; :mod:`rbstab.summary` (compiled summary figures of a
run's outputs) and :mod:`rbstab.convergence` (the convergence rule) and :mod:`rbstab.results` (the result
types, below the simulator and the files that store them) sit with the engine;
:mod:`rbstab.kinds` (the registry of input kinds, each loaded by its format's module) with
the sweeps and analyses. Modules of one layer may import each other (without a cycle).

A function-level import is for an optional or heavy dependency only, and says which in a
comment on its line or the line above.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"rbstab": ROOT / "src" / "rbstab", "rbstab_cli": ROOT / "cli"}

#: Layers, lowest first: (name, module prefixes).
LAYERS = [
    ("base", ["rbstab", "rbstab.jit", "rbstab.layout", "rbstab.warning_codes"]),
    ("kinematics", ["rbstab.kinematics"]),
    ("model", ["rbstab.model", "rbstab.chain"]),
    ("variants", ["rbstab.variants"]),
    ("config", ["rbstab.config", "rbstab.resources"]),
    ("engine", ["rbstab.engine", "rbstab.summary", "rbstab.convergence", "rbstab.results", "rbstab.diagnostics"]),
    ("simulate", ["rbstab.simulator"]),
    ("io", ["rbstab.io"]),
    ("sweep/analysis", ["rbstab.sweep", "rbstab.analysis", "rbstab.kinds", "rbstab.studies"]),
    ("report", ["rbstab.report"]),
    ("api", ["rbstab.api"]),
    ("cli", ["rbstab_cli", "rbstab.__main__"]),
]


def _modules() -> dict[str, tuple[Path, bool]]:
    """Module name -> (file, is a package)."""
    found = {}
    for package, folder in PACKAGES.items():
        for path in sorted(folder.rglob("*.py")):
            parts = [package, *path.relative_to(folder).with_suffix("").parts]
            is_package = parts[-1] == "__init__"
            found[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return found


MODULES = _modules()


def _owner(name: str) -> str | None:
    """The module of ours that ``name`` (a module or a name in one) is, or None."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str) -> list[tuple[ast.stmt, list[str], bool]]:
    """(statement, imported names, inside a function) for every import of ``module``."""
    path, is_package = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module if is_package else module.rpartition(".")[0]
    late = {id(sub) for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            for sub in ast.walk(node)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module
            # ``from package import module`` depends on the module (its package runs first
            # in any import of a submodule); ``from module import name`` on the module
            names = [f"{base}.{alias.name}" for alias in node.names]
            if not all(name in MODULES for name in names):
                names.insert(0, base)
        else:
            continue
        found.append((node, names, id(node) in late))
    return found


def _graph() -> dict[str, dict[str, int]]:
    """Module -> {module it imports: line of the first such import}."""
    graph = {}
    for module in MODULES:
        edges = {}
        for node, names, _ in _imports(module):
            for name in names:
                target = _owner(name)
                if target is not None and target != module:
                    edges.setdefault(target, node.lineno)
        graph[module] = edges
    return graph


def _cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return components


def _cycle_in(component: list[str], graph: dict[str, dict[str, int]]) -> list[str]:
    """One cycle through the first module of ``component``: a -> b -> ... -> a."""
    start, members = component[0], set(component)
    paths, seen = [[start]], {start}
    while paths:
        path = paths.pop(0)
        for w in graph[path[-1]]:
            if w == start:
                return path + [start]
            if w in members and w not in seen:
                seen.add(w)
                paths.append(path + [w])
    return component


def layer_of(module: str) -> int:
    """Index in :data:`LAYERS` of ``module``'s layer (the longest matching prefix)."""
    best, best_length = None, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_length:
                best, best_length = i, len(prefix)
    if best is None:
        raise LookupError(f"{module} is in no layer of LAYERS")
    return best


GRAPH = _graph()


def test_every_module_has_a_layer():
    for module in MODULES:
        layer_of(module)


def test_the_import_graph_has_no_cycle():
    cycles = [" -> ".join(_cycle_in(c, GRAPH)) + f"  ({len(c)} modules: {', '.join(c)})"
              for c in _cycles(GRAPH)]
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_no_module_imports_a_higher_layer():
    upward = [f"{module} ({LAYERS[layer_of(module)][0]}) imports {target} ({LAYERS[layer_of(target)][0]}), "
              f"line {line}"
              for module, edges in GRAPH.items() for target, line in edges.items()
              if layer_of(target) > layer_of(module)]
    assert not upward, "imports up the layers:\n" + "\n".join(upward)


def test_function_level_imports_say_why():
    """A late import names its reason (an optional or heavy dependency) in a comment."""
    silent = []
    for module, (path, _) in MODULES.items():
        lines = path.read_text(encoding="utf-8").splitlines()
        for node, names, late in _imports(module):
            if late and "#" not in lines[node.lineno - 1] and not lines[node.lineno - 2].strip().startswith("#"):
                silent.append(f"{path.relative_to(ROOT)}:{node.lineno}: {names[0]}")
    assert not silent, "function-level imports without a comment saying why:\n" + "\n".join(silent)


def test_the_graph_sees_relative_and_late_imports(tmp_path):
    """The parser resolves ``from ..x import y`` and finds imports inside functions (a check
    of this test's own reading, on a module known to do both)."""
    assert "rbstab.kinematics" in GRAPH["rbstab.model"]
    assert any(late for _, _, late in _imports("rbstab_cli.run"))


@pytest.mark.parametrize("cycle", [{"a": {"b": 1}, "b": {"a": 2}}, {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1}}])
def test_a_cycle_is_found(cycle):
    (component,) = _cycles(cycle)
    path = _cycle_in(component, cycle)
    assert path[0] == path[-1] and len(path) == len(cycle) + 1


def test_the_cache_digest_covers_every_module_that_compiles():
    """Every module that imports the compiler (:mod:`rbstab.jit`, or numba itself), in any
    style, is a source of the compiled kernels' cache digest."""
    from rbstab.jit import compiled_sources

    sources = {path.resolve() for path in compiled_sources()}
    compiling = [module for module in MODULES
                 if "rbstab.jit" in GRAPH[module]
                 or any(name.split(".")[0] == "numba" for _, names, _ in _imports(module) for name in names)]
    assert "rbstab.variants.kernels" in compiling and "rbstab.engine.integrate" in compiling
    missing = [m for m in compiling if MODULES[m][0].resolve() not in sources]
    assert not missing, f"compiling modules outside the cache digest: {missing}"


def test_the_cache_digest_changes_with_a_compiled_source(tmp_path, monkeypatch):
    """The digest is of the files' text: a change anywhere in a compiled layer (here a
    comment in the layout) makes another cache folder."""
    import rbstab.jit as jit

    copy = tmp_path / "rbstab"
    for path in jit.compiled_sources():
        target = copy / path.relative_to(jit._PACKAGE)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(path.read_bytes())
    monkeypatch.setattr(jit, "_PACKAGE", copy)
    before = jit._source_digest()
    (copy / "layout.py").write_text((copy / "layout.py").read_text() + "\n# changed\n")
    assert jit._source_digest() != before


def test_every_module_the_fork_server_preloads_imports():
    """``set_forkserver_preload`` silently skips a name that fails to import: each must."""
    import importlib

    from rbstab.sweep.executors import FORKSERVER_PRELOAD

    for name in FORKSERVER_PRELOAD:
        importlib.import_module(name)


def test_the_engine_takes_its_settings_as_one_record():
    """The compiled engine's functions take a run's settings (tolerances, limits, method,
    sample grid) as one record (:data:`rbstab.engine.settings.SETTINGS`) and its work
    arrays as one :class:`~rbstab.engine.settings.Work`: none takes 10 parameters, but the
    CUDA kernels, whose parameters are their launch's device arrays (one a column of results)."""
    kernels = {"rbstab.engine.cuda.run_all", "rbstab.engine.cuda.run_tree"}
    long = []
    for module, (path, _) in MODULES.items():
        if not module.startswith("rbstab.engine"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                count = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                if count >= 10 and f"{module}.{node.name}" not in kernels:
                    long.append(f"{module}.{node.name}: {count}")
    assert not long, "engine functions with 10 or more parameters:\n" + "\n".join(long)


def test_no_engine_name_is_compared_outside_the_registry():
    """What an engine can do is asked of :data:`rbstab.engine.ENGINES`
    (:mod:`rbstab.engine.registry`): no other module compares a value with an engine's
    name (``engine == "cuda"``, ``engine in ("compiled", "cuda")``)."""
    from rbstab.engine.registry import ENGINES

    def names(node) -> set:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return {node.value} & set(ENGINES)
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return set().union(*(names(e) for e in node.elts)) if node.elts else set()
        return set()

    found = []
    for module, (path, _) in MODULES.items():
        if module == "rbstab.engine.registry":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare):
                hit = set().union(*(names(n) for n in [node.left, *node.comparators]))
                if hit:
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {', '.join(sorted(hit))}")
    assert not found, "engine names compared outside rbstab.engine.registry:\n" + "\n".join(found)
