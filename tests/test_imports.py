"""The package's import graph has no cycles.

Every module of ``jaxgear`` is parsed with :mod:`ast` (nothing is imported) and every
import of a jaxgear module is an edge: absolute and relative, at module level and inside
functions, ``from . import _x`` (an edge to the submodule) and ``from .. import name``
(an edge to the package ``__init__``). A cycle is a strongly connected component of
more than one module (or a module importing itself); the test lists each one.
"""

from __future__ import annotations

import ast
from pathlib import Path

import jaxgear

PACKAGE = Path(jaxgear.__file__).parent


def modules(root: Path, name: str) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of the package at ``root``."""
    out = {}
    for p in sorted(root.rglob("*.py")):
        if "__pycache__" in p.parts:
            continue
        parts = [name, *p.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _known(target: str, mods: dict[str, Path]) -> str | None:
    """The module ``target`` names, or the closest enclosing module of the package."""
    while target and target not in mods:
        if "." not in target:
            return None
        target = target.rsplit(".", 1)[0]
    return target or None


def import_graph(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the package modules it imports anywhere in its source."""
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        package = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package[: len(package) - (node.level - 1)]
                    src = ".".join(base + ([node.module] if node.module else []))
                else:
                    src = node.module or ""
                targets = [f"{src}.{a.name}" if f"{src}.{a.name}" in mods else src for a in node.names]
            for t in targets:
                t = _known(t, mods)
                if t is not None and t != mod:
                    graph[mod].add(t)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm,
    iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return sorted(out)


def test_no_import_cycles():
    mods = modules(PACKAGE, "jaxgear")
    assert len(mods) > 50 and "jaxgear.analysis._method" in mods and "jaxgear.sweep._basins" in mods
    found = cycles(import_graph(mods))
    assert not found, "import cycles in jaxgear:\n" + "\n".join(", ".join(c) for c in found)


def _package(tmp_path: Path, files: dict[str, str]) -> dict[str, Path]:
    for rel, text in files.items():
        p = tmp_path / "pkg" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return modules(tmp_path / "pkg", "pkg")


def test_the_check_finds_cycles_of_every_kind_of_import(tmp_path):
    """A made-up package: a cycle through a relative import inside a function, one through
    ``from . import`` of a sibling package's module, and one through the package
    ``__init__``; a chain without a cycle is not reported."""
    mods = _package(tmp_path, {
        "__init__.py": "from .a import f\n",
        "a.py": "def f():\n    from .b import g\n    return g\n",
        "b.py": "import pkg.a\n",
        "sub/__init__.py": "",
        "sub/c.py": "from .. import d\n",
        "d.py": "from .sub import c\n",
        "e.py": "from . import f\n",           # a module, not the package __init__ ...
        "f.py": "",
        "g.py": "from .h import x\n",         # ... and a plain chain
        "h.py": "import os\n",
    })
    graph = import_graph(mods)
    assert graph["pkg.e"] == {"pkg.f"} and graph["pkg.g"] == {"pkg.h"} and graph["pkg.sub.c"] == {"pkg.d"}
    assert cycles(graph) == [["pkg.a", "pkg.b"], ["pkg.d", "pkg.sub.c"]]
    mods3 = _package(tmp_path / "three", {"__init__.py": "from .x import y\n", "x.py": "from .w import v\n",
                                          "w.py": "from pkg import y\n"})
    assert cycles(import_graph(mods3)) == [["pkg", "pkg.w", "pkg.x"]]
