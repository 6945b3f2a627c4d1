"""The house's structure, read from the code's own imports (issue 20; no bpy).

* No import circle among Lanterna's modules (``engine/``, ``ops/``, ``ui/``, ``bench/`` and the
  add-on's ``__init__.py``), imports inside functions included: the imports form a ladder.
* No module uses another module's ``_private`` name (``from m import _x`` or ``m._x``).
* The core (``engine/`` but ``engine/blender/``) never imports ``bpy``; the leaves of the ladder
  (``settings``, ``sampling``, ``scene``, ``memory``, ``npzjson``, ``archive``) import no
  stage.
* The ladder as the README's Layout section writes it: each module imports only modules listed
  at or below its own rung.

The checker itself is tested on a small made-up package (it must find a circle hidden in a
function-level import, and a private name), so that a checker that finds nothing cannot pass
for a clean house.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "lanterna"
FOLDERS = ("engine", "ops", "ui", "bench")
LEAVES = ("settings", "sampling", "scene", "memory", "npzjson", "archive")


def module_files(root: Path, package: str = PACKAGE) -> dict[str, Path]:
    """{dotted module name: file} of the package rooted at ``root``."""
    files = {package: root / "__init__.py"} if (root / "__init__.py").exists() else {}
    for folder in FOLDERS:
        for path in sorted((root / folder).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            files[".".join((package,) + parts)] = path
    return files


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[:len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def imports_of(files: dict[str, Path]):
    """{module: {imported module: [names taken]}} over every import statement, at any depth
    (function bodies included), resolved to the package's own modules."""
    graph = {}
    for module, path in files.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_package = path.name == "__init__.py"
        edges: dict[str, list] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = (_resolve(module, is_package, node.level, node.module) if node.level
                          else node.module or "")
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in files:                  # "from . import x": the module x
                        edges.setdefault(sub, [])
                    elif target in files:
                        edges.setdefault(target, []).append(alias.name)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in files:
                        edges.setdefault(alias.name, [])
        edges.pop(module, None)
        graph[module] = edges
    return graph


def circles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, {}):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def private_uses(files, graph) -> list[str]:
    """``from m import _x`` and ``m._x`` where m is another of the package's modules."""
    found = []
    for module, edges in graph.items():
        for target, names in edges.items():
            found += [f"{module} imports {n} from {target}" for n in names
                      if n.startswith("_") and not n.startswith("__")]
        tree = ast.parse(files[module].read_text(encoding="utf-8"))
        aliases = {}
        is_package = files[module].name == "__init__.py"
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = (_resolve(module, is_package, node.level, node.module) if node.level
                          else node.module or "")
                for alias in node.names:
                    if f"{target}.{alias.name}" in files:
                        aliases[alias.asname or alias.name] = f"{target}.{alias.name}"
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                found.append(f"{module} uses {node.value.id}.{node.attr}")
    return sorted(set(found))


def test_the_checker_finds_a_hidden_circle_and_a_private_name(tmp_path):
    pkg = tmp_path / "engine"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import helper\n")
    (pkg / "b.py").write_text("def helper():\n    from . import a\n    return a._secret\n")
    (pkg / "c.py").write_text("from .a import _hidden\n")
    files = module_files(tmp_path, "fake")
    graph = imports_of(files)
    assert circles(graph) == [["fake.engine.a", "fake.engine.b"]]
    assert private_uses(files, graph) == ["fake.engine.b uses a._secret",
                                          "fake.engine.c imports _hidden from fake.engine.a"]


def test_no_import_circle_and_no_private_name_across_modules():
    files = module_files(ROOT)
    graph = imports_of(files)
    assert len(files) > 40
    assert circles(graph) == []
    assert private_uses(files, graph) == []


def test_the_core_never_imports_bpy_and_the_leaves_import_no_stage():
    files = module_files(ROOT)
    graph = imports_of(files)
    bad = []
    for module, path in files.items():
        if not module.startswith(f"{PACKAGE}.engine") or module.startswith(f"{PACKAGE}.engine.blender"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            bad += [f"{module} imports {n}" for n in names
                    if n.split(".")[0] in ("bpy", "mathutils", "gpu", "bpy_extras")]
    assert bad == []
    leaves = {f"{PACKAGE}.engine.{name}" for name in LEAVES}
    for leaf in leaves:
        assert set(graph[leaf]) <= leaves, (leaf, sorted(graph[leaf]))


def _readme_ladder() -> list[list[str]]:
    """The README's Layout ladder: lines '<n>. `module`, `module`, ...' from the bottom up."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Layout", 1)[1]
    rungs, current = [], None
    for line in section.splitlines():
        match = re.match(r"(\d+)\.\s+(.*)", line)
        if match:
            current = match.group(2)
            rungs.append(current)
        elif current is not None and line.startswith("   ") and line.strip():
            rungs[-1] += " " + line.strip()        # an item's continuation line
        else:
            current = None
    return [re.findall(r"`([\w./]+)`", rung) for rung in rungs]


def _module_of(entry: str) -> list[str]:
    """A README entry (`engine/photons.py`, `ui/`, `__init__.py`) -> dotted module prefixes."""
    entry = entry.rstrip("/")
    if entry.endswith(".py"):
        entry = entry[:-3]
    dotted = PACKAGE if entry == "__init__" else f"{PACKAGE}." + entry.replace("/", ".")
    return [dotted]


def test_modules_import_only_their_rung_and_below():
    """Every module of the package sits on one rung of the README's ladder and imports only
    modules of its own rung or lower ones."""
    rungs = _readme_ladder()
    assert len(rungs) >= 5, rungs
    files = module_files(ROOT)
    graph = imports_of(files)

    def rung(module):
        best, best_len = None, -1
        for i, entries in enumerate(rungs):
            for entry in entries:
                for prefix in _module_of(entry):
                    if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                        best, best_len = i, len(prefix)
        return best

    # Package folders whose __init__.py imports nothing of ours need no rung of their own.
    placed = [m for m in files if graph[m] or files[m].name != "__init__.py" or m == PACKAGE]
    unplaced = sorted(m for m in placed if rung(m) is None)
    assert unplaced == [], f"modules the README's Layout does not place: {unplaced}"
    upward = [f"{m} (rung {rung(m) + 1}) imports {t} (rung {rung(t) + 1})"
              for m in placed for t in graph[m] if rung(t) > rung(m)]
    assert upward == []
