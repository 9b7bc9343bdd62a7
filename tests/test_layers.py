"""The layers: dependencies flow one way, ``constraints <- controllers <- teleop <- web``,
with no circle between modules and no module too large to read.

The import graph of the four top-level packages is read with ``ast`` (no import is
executed). A module may import its own package or a lower one. An upward import is an
error wherever it is: at module level, in a class body, under ``if TYPE_CHECKING`` or
inside a function (a lazy import is still a dependency); there is no exception (``teleop
web`` is registered by ``web`` through an entry point, teleop/cli/commands.py).
``importlib.import_module("...")`` and ``__import__("...")`` with a literal name count as
imports too. The same graph, every import counted wherever it sits, has no circle: a
module that imports a module that imports it back, directly or through others (a package's
``__init__`` is a module like any other).

The last test checks that design citations name ``docs/design.md``.
"""

from __future__ import annotations

import ast
import subprocess
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: rank of each layer: a module may import packages of its own rank or lower
LAYERS = {"constraints": 0, "controllers": 1, "teleop": 2, "web": 3}
#: the largest source file of the four packages, in lines (one concept per file)
MAX_MODULE_LINES = 600
#: what counts as a source file of theirs: Python, and the compiled step's C++
SOURCE_SUFFIXES = (".py", ".cpp", ".hpp")


@dataclass(frozen=True)
class Import:
    source: str  # dotted module name of the importer, e.g. "teleop.cli.main"
    path: str  # its file, relative to the repository
    line: int
    target: str  # dotted name imported (resolved when relative), e.g. "web.cli"
    in_function: bool  # inside a def / async def / lambda (a lazy import)
    names: tuple[str, ...] = ()  # what ``from target import ...`` takes (may be submodules)

    @property
    def source_package(self) -> str:
        return self.source.split(".")[0]

    @property
    def target_package(self) -> str:
        return self.target.split(".")[0]

    @property
    def upward(self) -> bool:
        return (self.target_package in LAYERS
                and LAYERS[self.target_package] > LAYERS[self.source_package])

    def __str__(self) -> str:
        where = "in a function" if self.in_function else "at module level"
        return f"{self.path}:{self.line}: {self.source} imports {self.target} ({where})"


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def resolve(module: str, is_package: bool, name: str | None, level: int) -> str:
    """Absolute dotted name of ``from <level dots><name> import ...`` inside ``module``."""
    if level == 0:
        return name or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level - 1 > len(base) - 1:
        raise ValueError(f"relative import beyond the top-level package in {module}")
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def imports_of(source: str, module: str, is_package: bool, path: str) -> list[Import]:
    """Every import in ``source``, with whether it sits inside a function."""
    found: list[Import] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append(Import(module, path, node.lineno, alias.name, in_function))
        elif isinstance(node, ast.ImportFrom):
            target = resolve(module, is_package, node.module, node.level)
            if node.module is None:  # from . import a, b: each name may be a submodule
                for alias in node.names:
                    found.append(Import(module, path, node.lineno, f"{target}.{alias.name}",
                                        in_function))
            else:
                found.append(Import(module, path, node.lineno, target, in_function,
                                    tuple(alias.name for alias in node.names)))
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and ((isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                   or (isinstance(node.func, ast.Name)
                       and node.func.id in ("import_module", "__import__")))):
            found.append(Import(module, path, node.lineno, node.args[0].value, in_function))
        nested = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, nested)

    visit(ast.parse(source, filename=path), False)
    return found


def package_modules() -> list[Path]:
    return sorted(path for package in LAYERS for path in (ROOT / package).rglob("*.py")
                  if "__pycache__" not in path.parts)


def all_imports() -> list[Import]:
    found = []
    for path in package_modules():
        found += imports_of(path.read_text(encoding="utf-8"), module_name(path),
                            path.name == "__init__.py", str(path.relative_to(ROOT)))
    return found


def imported_modules(item: Import, modules: set[str]) -> set[str]:
    """The Python modules of the four packages that ``item`` loads: each ``from X import
    name`` that is a submodule, and ``X`` itself unless every name is one. A name outside
    ``modules`` (another package, the compiled step) leads nowhere in this graph."""
    found = {f"{item.target}.{name}" for name in item.names} & modules
    if len(found) < len(item.names) or not item.names:  # a name defined in the module X
        found |= {item.target} & modules
    return found


def import_graph(imports: list[Import]) -> dict[str, dict[str, list[Import]]]:
    """``graph[a][b]``: the imports by which module ``a`` loads module ``b`` (no self-loops)."""
    modules = {module_name(path) for path in package_modules()}
    graph: dict[str, dict[str, list[Import]]] = {module: defaultdict(list) for module in modules}
    for item in imports:
        for target in imported_modules(item, modules) - {item.source}:
            graph[item.source][target].append(item)
    return graph


def strongly_connected(graph: dict[str, dict[str, list[Import]]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one module, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in graph[module]:
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(components)


def describe_circle(component: list[str], graph: dict[str, dict[str, list[Import]]]) -> str:
    """The circle's modules and every import between them, ``file:line`` each."""
    members = set(component)
    lines = [f"circle of {len(component)} modules: {', '.join(component)}"]
    lines += [f"  {item}" for source in component for target in sorted(graph[source])
              if target in members for item in graph[source][target]]
    return "\n".join(lines)


# -- the walker itself -------------------------------------------------------------------

def test_the_walker_resolves_relative_lazy_and_dynamic_imports():
    source = "\n".join([
        "from __future__ import annotations",
        "import numpy as np",
        "from .app import TeleopApp",
        "from ..robots import Robot",
        "from . import plots",
        "import teleop.loop",
        "class A:",
        "    from controllers import CJMController",
        "def f():",
        "    from web.cli import main",
        "    import importlib",
        "    return importlib.import_module('web.ui')",
        "g = lambda: __import__('web')",
    ])
    found = imports_of(source, "teleop.experiments.compare", False, "teleop/experiments/compare.py")
    assert [(i.target, i.in_function) for i in found] == [
        ("__future__", False), ("numpy", False), ("teleop.experiments.app", False),
        ("teleop.robots", False), ("teleop.experiments.plots", False), ("teleop.loop", False),
        ("controllers", False), ("web.cli", True), ("importlib", True), ("web.ui", True),
        ("web", True)]
    assert [i.target for i in found if i.upward] == ["web.cli", "web.ui", "web"]
    assert resolve("web", True, "app", 1) == "web.app"  # in web/__init__.py
    with pytest.raises(ValueError):
        resolve("teleop.cli.main", False, "x", 4)


def test_the_walker_sees_the_whole_graph():
    """The four packages exist and the known downward edges are found (no silent pass)."""
    edges = {(i.source_package, i.target_package) for i in all_imports()}
    assert len(package_modules()) >= 20
    for edge in (("controllers", "constraints"), ("teleop", "controllers"),
                 ("teleop", "constraints"), ("web", "teleop"), ("web", "constraints")):
        assert edge in edges, edge


# -- the layering ------------------------------------------------------------------------

def test_no_module_imports_a_higher_layer_at_module_level():
    violations = [str(i) for i in all_imports() if i.upward and not i.in_function]
    assert not violations, "upward imports at module level:\n" + "\n".join(violations)


def test_no_module_imports_a_higher_layer_lazily_either():
    violations = [str(i) for i in all_imports() if i.upward and i.in_function]
    assert not violations, "upward imports inside functions:\n" + "\n".join(violations)


# -- circles -------------------------------------------------------------------------------

def test_the_circle_finder_finds_circles_and_only_them():
    """A graph written here: a -> b -> c -> a (one lazily), d -> a, e alone."""
    def edge(source: str, target: str, lazy: bool = False) -> Import:
        return Import(source, source.replace(".", "/") + ".py", 1, target, lazy)

    graph = {"a": {"b": [edge("a", "b")]}, "b": {"c": [edge("b", "c")]},
             "c": {"a": [edge("c", "a", lazy=True)]}, "d": {"a": [edge("d", "a")]}, "e": {}}
    assert strongly_connected(graph) == [["a", "b", "c"]]
    text = describe_circle(["a", "b", "c"], graph)
    assert text.startswith("circle of 3 modules: a, b, c")
    assert "c.py:1: c imports a (in a function)" in text and "d imports" not in text


def test_the_graph_resolves_submodules_names_and_packages():
    modules = {"teleop", "teleop.experiments", "teleop.experiments.plots",
               "teleop.experiments.compare", "controllers.cjm"}
    def item(target: str, *names: str) -> Import:
        return Import("teleop.experiments.report", "x.py", 1, target, False, names)

    assert imported_modules(item("teleop.experiments", "plots"), modules) == {
        "teleop.experiments.plots"}
    assert imported_modules(item("teleop.experiments", "plots", "Plan"), modules) == {
        "teleop.experiments.plots", "teleop.experiments"}
    assert imported_modules(item("teleop.experiments.compare", "compare"), modules) == {
        "teleop.experiments.compare"}
    assert imported_modules(item("teleop.experiments.compare"), modules) == {
        "teleop.experiments.compare"}
    assert imported_modules(item("controllers.cjm._step"), modules) == set()  # compiled
    assert imported_modules(item("numpy", "linalg"), modules) == set()


def test_no_import_circle_between_modules():
    graph = import_graph(all_imports())
    circles = strongly_connected(graph)
    assert not circles, "import circles:\n" + "\n".join(describe_circle(c, graph)
                                                         for c in circles)


# -- size -----------------------------------------------------------------------------------

def test_no_source_file_is_over_the_line_limit():
    sources = sorted(path for package in LAYERS for path in (ROOT / package).rglob("*")
                     if path.suffix in SOURCE_SUFFIXES and "__pycache__" not in path.parts)
    sizes = {str(path.relative_to(ROOT)): len(path.read_text(encoding="utf-8").splitlines())
             for path in sources}
    assert len(sizes) >= 20
    too_large = [f"{path}: {lines} lines" for path, lines in sorted(sizes.items(),
                                                                      key=lambda kv: -kv[1])
                 if lines > MAX_MODULE_LINES]
    assert not too_large, (f"files over {MAX_MODULE_LINES} lines (split by concern):\n"
                           + "\n".join(too_large))


# -- citations -----------------------------------------------------------------------------

OLD_NAME = "DESIGN" + ".md"  # spelled in two parts so that this file does not mention it
NEW_NAME = "docs/design.md"


def repository_files() -> list[Path]:
    """The repository's files (tracked or new, not ignored), else every file but .git."""
    try:
        listed = subprocess.run(
            ["git", "-C", str(ROOT), "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
            capture_output=True, text=True, timeout=60, check=True).stdout
        return sorted({ROOT / name for name in listed.split("\0") if name and (ROOT / name).is_file()})
    except (OSError, subprocess.SubprocessError):
        return sorted(p for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts)


def test_the_design_doc_is_cited_as_docs_design_md():
    """No .py, .md or .toml file of the repository mentions a top-level design file
    outside it: the design is cited as ``docs/design.md``."""
    offenders = []
    for path in repository_files():
        relative = path.relative_to(ROOT).as_posix()
        if path.suffix not in (".py", ".md", ".toml") or relative == NEW_NAME:
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace")
                                      .splitlines(), 1):
            if OLD_NAME in line:
                offenders.append(f"{relative}:{number}: {line.strip()}")
    assert not offenders, (f"{len(offenders)} mention(s) of {OLD_NAME}; cite {NEW_NAME}:\n"
                           + "\n".join(offenders))
