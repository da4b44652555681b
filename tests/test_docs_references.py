"""Every file path and every ``rbstab`` name that README.md and docs/*.md quote exists.

What is checked, in each page's inline code spans (`` `...` ``, split into words) and link
targets (``[text](target)``), and in its ``python`` code blocks (names only):

- **Paths** (a word with a ``/``). Only paths into the repository's tracked source are
  checked: those whose first component is one of :data:`SOURCE_ROOTS` (``configs/paper/
  case1_permanent.yaml``, ``benchmarks/throughput.py``, ``src/rbstab/jit.py``), ``rbstab/``
  (read under ``src/``) or a subpackage of ``src/rbstab`` (``engine/rk.py``,
  ``variants/base.py``, as pages write them inside the package). Anything else is an
  output or a placeholder (``results/...``, ``runs/chunk-*.h5``, ``<sweep>/index.csv``,
  ``/dev/zero``, ``~/.bashrc``) and is not checked. ``*`` and ``<name>`` are read as
  wildcards that must match at least one file. ``variants/permanent.quantities`` (a module
  path with a name after it) must name an attribute of that module.
- **File names** without a folder ending in ``.py`` or ``.md`` (``kinematics.py``,
  ``sliding.md``): some file of that name exists under :data:`SOURCE_ROOTS` or at the root,
  unless it is one of the report's pages (:data:`OUTPUT_NAMES`). (Other bare names,
  ``index.csv``, ``sweep.yaml``, ``<name>.h5``, are outputs and not checked.)
- **Links**: a relative target (no scheme, no bare ``#anchor``) exists relative to the page.
- **Names**: every dotted name starting with ``rbstab.`` or ``rbstab_cli.``
  (``rbstab.open_sweep``, ``rbstab.engine.warm_up``, ``rbstab.io.chunk``), or with a module of
  rbstab written without ``rbstab.`` in a code span (``model.PARAMETERS``,
  ``engine.warm_up``; :data:`SHORT_MODULES`), resolves: the longest prefix that imports as
  a module, then attributes (``getattr``) for the rest.
- **Class names** in code spans (``RunResult``, ``ChunkWriter.add_block``: two capitals or
  more): defined in ``src/rbstab`` or ``cli/`` (``class RunResult`` or ``RunResult = ...``),
  the attribute named there, unless Python's (``AttributeError``) or another library's
  (:data:`OTHER_CLASSES`).

A failure lists every bad reference as ``file:line``.
"""

from __future__ import annotations

import builtins
import glob
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SRC = ROOT / "src"
PACKAGE = SRC / "rbstab"
#: Top-level folders of tracked source; a quoted path starting with one must exist.
SOURCE_ROOTS = ("benchmarks", "cli", "configs", "docs", "src", "tests", ".ci")
#: Bare file names that pages quote as what rbstab writes (a report folder's pages), not as
#: files of the repository.
OUTPUT_NAMES = ("index.md", "summary.md")
#: Subpackages of rbstab: ``engine/rk.py`` in a page means ``src/rbstab/engine/rk.py``.
SUBPACKAGES = tuple(sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py")))

FENCE = re.compile(r"^```(?P<lang>[\w-]*)\n(?P<body>.*?)^```", re.M | re.S)
SPAN = re.compile(r"(`+)(?P<code>.+?)\1")
LINK = re.compile(r"\]\((?P<target>[^)\s]+)\)")
NAME = re.compile(r"(?<![\w/.\-])(?P<name>rbstab(?:_cli)?(?:\.[A-Za-z_]\w*)+)(?![\w/\-])")
#: Modules of rbstab that pages name without ``rbstab.`` (``model.PARAMETERS``); ``sweep`` and
#: ``config`` are left out: ``sweep.random.n`` is a key of a spec file.
SHORT_MODULES = tuple(sorted(({p.stem for p in PACKAGE.glob("[!_]*.py")} | set(SUBPACKAGES)) - {"sweep", "config"}))
SHORT_NAME = re.compile(rf"(?<![\w/.\-])(?P<name>(?:{'|'.join(SHORT_MODULES)})(?:\.[A-Za-z_]\w*)+)(?![\w/\-])")
#: A class name (two capitals or more, ``RunResult``), maybe with an attribute (``ChunkWriter.add_block``).
CLASS_NAME = re.compile(r"(?<![\w.])(?P<name>[A-Z][a-z0-9]+(?:[A-Z][A-Za-z0-9]*)+)(?:\.(?P<attr>[A-Za-z_]\w*))?(?!\w)")
#: Classes of other libraries that pages name (Dask's).
OTHER_CLASSES = ("LocalCluster",)
#: What a file name ends with: ``summary.csv`` is a file, not a name in ``rbstab.summary``.
FILE_SUFFIX = re.compile(r"\.(?:csv|json|h5|nc|ya?ml|md|py|html|png|pdf|svg|txt)$")
WORD_SPLIT = re.compile(r"[\s=,;()\[\]'\"]+")
PATH_WORD = re.compile(r"^[\w.*<>\-]+(?:/[\w.*<>\-]*)+$")
FILE_WORD = re.compile(r"^[\w<>*\-]+(?:\.[\w<>*\-]+)*\.(?:py|md)$")


def _source() -> str:
    """The text of rbstab's and its command line's Python files."""
    return "\n".join(p.read_text(encoding="utf-8") for d in (PACKAGE, ROOT / "cli") for p in sorted(d.rglob("*.py")))


def _check_class(name: str, attr: str | None, source: str) -> str | None:
    """None if class ``name`` is defined in rbstab (and ``attr`` occurs there), else why not."""
    if name in OTHER_CLASSES or hasattr(builtins, name):
        return None
    if not re.search(rf"^\s*(?:class\s+{name}\b|{name}\s*(?::[^=\n]*)?=)", source, re.M):
        return "no class or name of that name is defined in src/ or cli/"
    if attr is not None and not re.search(rf"\b{re.escape(attr)}\b", source):
        return f"{attr!r} occurs nowhere in src/ or cli/"
    return None


def _pages() -> list[tuple[str, str, str, list[tuple[str, int, str]]]]:
    """(page name, text, text with code blocks blanked out, [(language, offset, body)])."""
    out = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        blocks = []

        def blank(m: re.Match) -> str:
            blocks.append((m["lang"], m.start("body"), m["body"]))
            return re.sub(r"[^\n]", " ", m.group(0))

        prose = FENCE.sub(blank, text)
        out.append((path.relative_to(ROOT).as_posix(), text, prose, blocks))
    return out


def _line(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def _references(page) -> tuple[list, list, list]:
    """(paths, links, names, classes) of a page, each a list of (line, text), classes of
    (line, (name, attribute or None))."""
    name, text, prose, blocks = page
    paths, links, names, classes = [], [], [], []
    for m in SPAN.finditer(prose):
        line = _line(text, m.start())
        code = m["code"]
        names += [(line, n["name"]) for n in NAME.finditer(code)]
        names += [(line, f"rbstab.{n['name']}") for n in SHORT_NAME.finditer(code) if not FILE_SUFFIX.search(n["name"])]
        classes += [(line, (c["name"], c["attr"])) for c in CLASS_NAME.finditer(code)]
        for word in WORD_SPLIT.split(code):
            word = word.rstrip(".:")
            if "://" not in word and (PATH_WORD.match(word) or FILE_WORD.match(word)):
                paths.append((line, word))
    for m in LINK.finditer(prose):
        links.append((_line(text, m.start()), m["target"]))
    for lang, start, body in blocks:
        if lang == "python":
            names += [(_line(text, start + n.start()), n["name"]) for n in NAME.finditer(body)]
    return paths, links, names, classes


def _resolve(dotted: str) -> str | None:
    """None if ``dotted`` names a module or an attribute chain under one, else why not."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        module_name = ".".join(parts[:i])
        try:
            obj = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name or module_name.startswith(f"{exc.name}."):
                continue  # no such module: try the next shorter prefix
            return f"importing {module_name} fails: {exc}"
        for j, attr in enumerate(parts[i:], start=i):
            try:
                obj = getattr(obj, attr)
            except AttributeError:
                return f"{'.'.join(parts[:j])} has no attribute {attr!r}"
        return None
    return f"no module {parts[0]!r}"


def _glob_exists(pattern: Path) -> bool:
    text = re.sub(r"<[^>]*>", "*", str(pattern))
    return bool(glob.glob(text)) if "*" in text else Path(text).exists()


def _check_path(word: str) -> str | None:
    """None if the quoted path exists or is not one to check (module docstring), else why not."""
    if "/" not in word:
        if word in OUTPUT_NAMES:
            return None
        names = re.sub(r"<[^>]*>", "*", word)
        roots = [ROOT / r for r in SOURCE_ROOTS]
        if any(ROOT.glob(names)) or any(any(r.rglob(names)) for r in roots if r.is_dir()):
            return None
        return "no file of that name in the repository"
    first = word.split("/", 1)[0]
    if first in SOURCE_ROOTS:
        base = ROOT
    elif first == "rbstab":
        base = SRC
    elif first in SUBPACKAGES:
        base = PACKAGE
    else:
        return None  # an output, a placeholder or a path outside the repository
    target = base / word.rstrip("/")
    if _glob_exists(target):
        return None
    module, dot, attr = target.name.partition(".")
    if dot and "." not in attr and (target.parent / f"{module}.py").is_file():
        # ``variants/permanent.quantities``: a module path and a name in it
        dotted = ".".join(target.parent.relative_to(SRC).parts + (module, attr))
        why = _resolve(dotted)
        return None if why is None else f"{why} ({dotted})"
    return f"{target.relative_to(ROOT)} does not exist"


def _check_link(page: str, target: str) -> str | None:
    if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
        return None
    path = (ROOT / page).parent / target.split("#", 1)[0]
    return None if path.exists() else f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path} does not exist"


def bad_references(pages=None) -> list[str]:
    """``file:line: `reference`: why`` for every quoted path, link or name that is wrong."""
    bad = []
    source = _source()
    for page in pages if pages is not None else _pages():
        name = page[0]
        paths, links, names, classes = _references(page)
        for line, word in paths:
            if (why := _check_path(word)) is not None:
                bad.append(f"{name}:{line}: path `{word}`: {why}")
        for line, target in links:
            if (why := _check_link(name, target)) is not None:
                bad.append(f"{name}:{line}: link ({target}): {why}")
        for line, dotted in names:
            if (why := _resolve(dotted)) is not None:
                bad.append(f"{name}:{line}: name `{dotted}`: {why}")
        for line, (cls, attr) in classes:
            if (why := _check_class(cls, attr, source)) is not None:
                bad.append(f"{name}:{line}: class `{cls}{'.' + attr if attr else ''}`: {why}")
    return sorted(bad, key=lambda b: (b.split(":")[0], int(b.split(":")[1])))


def test_source_roots_are_the_repository_s_folders():
    assert all((ROOT / r).is_dir() for r in SOURCE_ROOTS), [r for r in SOURCE_ROOTS if not (ROOT / r).is_dir()]
    assert {"engine", "variants", "io", "sweep"} <= set(SUBPACKAGES), SUBPACKAGES


def test_the_docs_quote_paths_and_names():
    """The check sees what the pages quote (so that it cannot pass by finding nothing)."""
    counts = [0, 0, 0, 0]
    for page in _pages():
        for i, found in enumerate(_references(page)):
            counts[i] += len(found)
    assert counts[0] > 50 and counts[1] > 5 and counts[2] > 20 and counts[3] > 10, counts


def test_every_quoted_path_and_name_exists():
    bad = bad_references()
    assert not bad, f"{len(bad)} quoted references do not exist:\n" + "\n".join(bad)


@pytest.mark.parametrize("quote, fragment", [
    ("`docs/no-such-page.md`", "path `docs/no-such-page.md`"),
    ("`physics-notes.md`", "path `physics-notes.md`"),
    ("`engine/no_such_module.py`", "path `engine/no_such_module.py`"),
    ("`variants/permanent.NoSuchThing`", "path `variants/permanent.NoSuchThing`"),
    ("[notes](no-such-page.md)", "link (no-such-page.md)"),
    ("`rbstab.no_such_name`", "name `rbstab.no_such_name`"),
    ("`rbstab.io.no_such_module`", "name `rbstab.io.no_such_module`"),
    ("`rbstab.io.chunk.NoSuchClass`", "name `rbstab.io.chunk.NoSuchClass`"),
    ("`engine.no_such_function`", "name `rbstab.engine.no_such_function`"),
    ("`PermanentFullState`", "class `PermanentFullState`"),
    ("`rbstab.simulator.NoSuchRun`", "name `rbstab.simulator.NoSuchRun`"),
    ("`ChunkWriter.no_such_method`", "class `ChunkWriter.no_such_method`"),
])
def test_a_broken_reference_is_reported_with_its_place(quote, fragment):
    text = f"# A page\n\nSome text, then {quote}.\n"
    bad = bad_references([("docs/x.md", text, text, [])])
    assert len(bad) == 1 and bad[0].startswith(f"docs/x.md:3: {fragment}"), bad


def test_outputs_and_placeholders_are_not_checked():
    text = ("`results/sweeps/gains_case3/index.csv` `<sweep>/runs/chunk-*.h5` `/dev/zero` "
            "`runs/<run_id>.h5` `~/.bashrc` `index.csv` `summary.csv` `sweep.random.n` `KeyError` "
            "[site](https://example.org) [up](#commands)\n")
    assert bad_references([("docs/x.md", text, text, [])]) == []
