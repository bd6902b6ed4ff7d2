"""The layer contract of docs/ARCHITECTURE.md, read off the import graph: no module imports a
higher layer, and no two modules import each other, directly or round a circle (imports inside
functions included: they are the same dependency, only later)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2] / "src" / "robocal"
DOC = Path(__file__).resolve().parents[2] / "docs" / "ARCHITECTURE.md"


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = ("robocal",) + path.relative_to(ROOT).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _imports(name: str) -> set[str]:
    """The robocal modules ``name`` imports; ``from . import x`` is module x, not the package."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            subs = {f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in MODULES}
            out |= subs if subs and len(subs) == len(node.names) else subs | {base}
    return {m for m in out if m in MODULES and m != name}


def _layers() -> dict[str, int]:
    """Package (or top-level module) → layer, from the table of docs/ARCHITECTURE.md."""
    layers, current = {}, None
    for line in DOC.read_text(encoding="utf-8").splitlines():
        m = re.match(r"\|\s*(\d) [^|]*\|\s*([^|]+)\|", line) or re.match(r"\|\s*\|\s*([^|]+)\|", line)
        if not m:
            continue
        if len(m.groups()) == 2:
            current, cell = int(m.group(1)), m.group(2)
        else:
            cell = m.group(1)
        for name in re.findall(r"`([a-z_][a-z_0-9]*)(?:\.py)?`", cell):
            layers[name] = current
    return layers


LAYERS = _layers()


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if len(parts) == 1:
        return 0  # the package root holds the version and a lazy map of names (importlib, at use)
    if parts[1] == "__main__":
        return 6  # the entry point sits on top
    return LAYERS.get(parts[1])


def test_every_package_has_a_layer():
    missing = sorted({m.split(".")[1] for m in MODULES if "." in m and _layer(m) is None})
    assert missing == []


def test_no_module_imports_a_higher_layer():
    upward = [f"{a} ({_layer(a)}) → {b} ({_layer(b)})" for a in sorted(MODULES) for b in sorted(_imports(a))
              if _layer(b) > _layer(a)]
    assert upward == []


def test_no_import_circle():
    graph = {m: _imports(m) for m in MODULES}
    index, low, stack, on, circles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
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
                circles.append(sorted(component))

    for m in graph:
        if m not in index:
            visit(m)
    assert circles == []
