"""The import structure of ``src/wott_hub`` (docs/architecture.md): no cycles, imports only along the
layers, and a hub package whose modules never import its top.

The graph is built from the modules' own source (``ast``), not by importing them: every
import counts, at module level, inside a function (a lazy import still ties the two modules
together) or under ``if TYPE_CHECKING:`` (a module that needs another's types to be checked
depends on it as much: hiding a cycle there is still a cycle). ``from x import y`` is an
edge to ``x.y`` when that is a module, else to ``x``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import wott_hub

SRC = Path(wott_hub.__file__).parent


def _modules() -> dict[str, Path]:
    out = {}
    for path in SRC.rglob("*.py"):
        parts = ["wott_hub", *path.relative_to(SRC).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement, wherever it is (``if TYPE_CHECKING:`` included)."""
    return [node for node in ast.walk(tree) if isinstance(node, ast.Import | ast.ImportFrom)]


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> set[str]:
    if isinstance(node, ast.Import):
        return {a.name for a in node.names}
    if node.level:  # relative: from the module's package
        package = module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
        for _ in range(node.level - 1):
            package = package.rpartition(".")[0]
        base = f"{package}.{node.module}" if node.module else package
    else:
        base = node.module or ""
    out = set()
    for alias in node.names:
        sub = f"{base}.{alias.name}"
        out.add(sub if sub in MODULES else base)
    return out


def import_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        edges = set()
        for node in _imports(tree):
            for target in _targets(module, node):
                while target and target not in MODULES and target.startswith("wott_hub."):
                    target = target.rpartition(".")[0]  # a name inside a module
                if target in MODULES and target != module:
                    edges.add(target)
        graph[module] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle through each strongly connected component of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                components.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return [_a_cycle(graph, comp) for comp in components]


def _a_cycle(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """A shortest path from the component's first module back to itself (breadth first)."""
    members = set(component)
    start = component[0]
    paths = {start: [start]}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v] & members):
            if w == start:
                return [*paths[v], start]
            if w not in paths:
                paths[w] = [*paths[v], w]
                queue.append(w)
    return component


def test_the_graph_sees_the_imports_it_must():
    graph = import_graph()
    assert "wott_hub.hub.lifecycle" in graph["wott_hub.hub"]  # relative, from a package
    assert "wott_hub.runtime.pipeline" in graph["wott_hub.runtime.worker"]
    assert "wott_hub.tactile.processing" in graph["wott_hub.runtime.pipeline"]  # inside a function
    assert "wott_hub.hub.lifecycle" not in graph["wott_hub.hub.status"]  # not imported at all
    assert "wott_hub.hub.devices" in graph["wott_hub.hub.status"]  # only under TYPE_CHECKING: counts too


def test_src_has_no_import_cycle():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_no_module_of_the_hub_package_imports_the_package_top():
    graph = import_graph()
    offenders = sorted(m for m, edges in graph.items()
                       if m.startswith("wott_hub.hub.") and "wott_hub.hub" in edges)
    assert offenders == []


def test_no_module_of_the_runtime_package_imports_the_package_top():
    graph = import_graph()
    offenders = sorted(m for m, edges in graph.items()
                       if m.startswith("wott_hub.runtime.") and "wott_hub.runtime" in edges)
    assert offenders == []


# docs/architecture.md, "Direction of imports": a module imports only from its own layer or the
# layers above it. Keys are the first name under wott_hub (a package or a top-level module).
LAYERS: dict[str, int] = {
    "errors": 1, "tactile": 1,
    "td": 2, "sim": 2, "events": 2, "configspec": 2, "types": 2, "examples": 2,
    "drivers": 3,
    "plugins": 4,
    "discovery": 5,
    "runtime": 6,
    "history": 7, "web": 7, "servient": 7, "security": 7, "mqtt": 7, "robotics": 7,
    "network": 8, "config": 8, "config_docs": 8, "config_rules": 8,
    "hub": 9,
    "cli": 10, "plugin_api": 10, "": 10,  # "": the package face, wott_hub/__init__.py
}


def _layer(module: str) -> int:
    top = module.removeprefix("wott_hub").lstrip(".").partition(".")[0]
    assert top in LAYERS, f"{module}: no layer in docs/architecture.md; add its package there and here"
    return LAYERS[top]


def test_imports_go_only_to_the_same_layer_or_above():
    wrong = sorted(f"{m} (layer {_layer(m)}) imports {t} (layer {_layer(t)})"
                   for m, targets in import_graph().items() for t in targets if _layer(t) > _layer(m))
    assert not wrong, "imports against docs/architecture.md's layers:\n" + "\n".join(wrong)


# docs/architecture.md, "The size of a class": no class of shipped code over MAX_CLASS_LINES
# lines, but those the page names with their reason.
MAX_CLASS_LINES = 300
ROOT = Path(__file__).resolve().parents[1]
_NOT_SHIPPED = {"tests", "test", ".venv", "node_modules", "__pycache__", "build", "dist"}


def _shipped_files() -> list[Path]:
    """Every ``.py`` of ``src/`` and of every workspace member (``[tool.uv.workspace] members``,
    globs included: a plugin added tomorrow is in), its tests and build output aside."""
    import tomllib

    members = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["uv"]["workspace"]["members"]
    roots = [ROOT / "src", *(p for m in members for p in sorted(ROOT.glob(m)) if p.is_dir())]
    out = []
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            test = path.name.startswith("test_") or path.name == "conftest.py"
            if _NOT_SHIPPED.isdisjoint(path.relative_to(root).parts) and not test:
                out.append(path)
    return out


def class_lengths(path: Path) -> dict[str, int]:
    """``module.Class`` (nested: ``module.Outer.Inner``) -> its lines, decorators included."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    module = path.stem
    out: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                first = min([child.lineno, *(d.lineno for d in child.decorator_list)])
                name = f"{prefix}.{child.name}"
                out[name] = (child.end_lineno or child.lineno) - first + 1
                visit(child, name)
            else:
                visit(child, prefix)

    visit(tree, module)
    return out


def _allowed() -> dict[str, str]:
    """The table of docs/architecture.md's "The size of a class": ``module.Class`` -> its reason."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.partition("## The size of a class")[2].partition("\n## ")[0]
    rows = re.findall(r"^\|\s*`([\w.]+)`\s*\|[^|]*\|\s*(.*?)\s*\|\s*$", section, re.M)
    return {name: why for name, why in rows}


def test_the_class_lengths_are_measured_as_a_reader_sees_them(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("import dataclasses\n\n@dataclasses.dataclass\nclass A:\n    x: int = 0\n\n"
                    "    class B:\n        pass\n\n\ndef f():\n    class C:\n        y = 1\n        z = 2\n")
    assert class_lengths(path) == {"m.A": 6, "m.A.B": 2, "m.C": 3}
    files = {p.relative_to(ROOT).as_posix() for p in _shipped_files()}
    assert "src/wott_hub/history/writer.py" in files and "directory/src/wott_directory/directory.py" in files
    assert any(f.startswith("plugins/") for f in files) and any(f.startswith("client/") for f in files)
    assert not any("/tests/" in f or f.startswith("tests/") for f in files)


def test_no_class_of_shipped_code_is_over_300_lines_unless_the_architecture_page_says_why():
    allowed = _allowed()
    assert all(why for why in allowed.values()), "docs/architecture.md: each long class needs its reason"
    seen: dict[str, int] = {}
    for path in _shipped_files():
        for name, lines in class_lengths(path).items():
            seen[f"{path.relative_to(ROOT).as_posix()}: {name}"] = lines
    long = {name: n for name, n in seen.items() if n > MAX_CLASS_LINES}
    unexplained = sorted(f"{name} ({n} lines)" for name, n in long.items()
                         if name.partition(": ")[2] not in allowed)
    assert not unexplained, (f"classes over {MAX_CLASS_LINES} lines: split them into pieces of one job each, "
                             "or say in docs/architecture.md (\"The size of a class\") why one may be "
                             "longer:\n" + "\n".join(unexplained))
    stale = sorted(set(allowed) - {name.partition(": ")[2] for name in long})
    assert not stale, f"docs/architecture.md names classes no longer over {MAX_CLASS_LINES} lines: {stale}"
