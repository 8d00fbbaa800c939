"""The layers of docs/architecture.md, checked on the source: every ``import`` of every
csdf module (at module level and inside functions alike) is read with ``ast``, and

* no import cycle exists among csdf's modules;
* each module imports only from its own layer or the layers below, apart from the
  documented convenience calls upward (:data:`UPCALLS`);
* nothing outside the field layer (``csdf.field``, ``csdf.fieldset``) and
  ``csdf.backends`` imports an evaluator module;
* no module imports a private (``_name``) module or name from another package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / "src"
PKG = SRC / "csdf"

#: layer of each module, by the longest matching dotted prefix (lowest first)
LAYERS: dict[str, int] = {
    # 0 expression: the op set, interval arithmetic, slot numbering, the DAG, poses
    "csdf.errors": 0, "csdf.ops": 0, "csdf.interval": 0, "csdf.layout": 0,
    "csdf.expr": 0, "csdf.vec": 0, "csdf.points": 0, "csdf.version": 0,
    "csdf.parallel": 0, "csdf.memory": 0, "csdf.cache": 0, "csdf.pose": 0,
    "csdf.opformula": 0, "csdf.bvh": 0, "csdf.exprgrad": 0,
    "csdf.cellsort": 0,  # points grouped by cell (a counting sort)
    "csdf.seeds": 0,  # the seed argument, checked
    "csdf.meshdata": 0,  # a closed triangle mesh, the data block of mesh calls
    # 1 shapes: primitives, operators, and the text language that builds them
    "csdf.shapes": 1, "csdf.lang": 1, "csdf.zoo": 1,
    "csdf.shapes.exprfield": 1, "csdf.lang.vm": 1,  # a field from an expression; .vm in
    "csdf.lang.source": 1,  # checks shared by the text readers
    "csdf.lang.csg": 1,  # OpenSCAD .csg (and .scad through openscad) in
    # 2 compiler: tape, bytecode, simplification
    "csdf.compiler": 2,
    # 3 evaluators
    "csdf.backends": 3, "csdf.backends.meshdist": 3,  # exact distance to a mesh
    # 4 the field layer
    "csdf.field": 4, "csdf.fieldset": 4, "csdf.colors": 4,  # colours at points
    # 5 consumers
    "csdf.mesh": 5, "csdf.render": 5, "csdf.sample": 5, "csdf.slicing": 5, "csdf.scan": 5,
    "csdf.raster": 5, "csdf.scene": 5, "csdf.plan": 5, "csdf.synth": 5, "csdf.metrics": 5,
    "csdf.fit": 5, "csdf.detect": 5, "csdf.distributed": 5,  # Dask (the dask extra)
    "csdf.infer": 5,  # CSG trees from scans
    "csdf.io": 5, "csdf.io.vm": 5,  # .vm out (and in, from csdf.lang.vm)
    # 6 apps
    "csdf.cli": 6, "csdf.editor": 6, "csdf.demo": 6, "csdf": 6,
}
LAYER_NAMES = ["expression", "shapes", "compiler", "evaluators", "field", "consumers", "apps"]

#: the only imports from a lower layer into a higher one: convenience methods that call
#: the next stage (a shape compiles itself, a program evaluates itself), imported inside
#: the method so that the lower layer does not need the higher one to load
UPCALLS: set[tuple[str, str]] = {
    ("csdf.shapes.base", "csdf.compiler.tape"),       # Shape.compile()
    ("csdf.compiler.program", "csdf.backends"),       # Program.__call__ and friends
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


MODULES = _modules()


def _package(name: str, path: Path) -> list[str]:
    parts = name.split(".")
    return parts if path.name == "__init__.py" else parts[:-1]


def _imports(name: str, path: Path) -> list[tuple[str, str, int]]:
    """``(target module, imported name or '', line)`` for every csdf import in a file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    pkg = _package(name, path)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod != "csdf" and not mod.startswith("csdf."):
                continue
            for alias in node.names:
                full = f"{mod}.{alias.name}"
                if full in MODULES:  # `from pkg import module`
                    out.append((full, "", node.lineno))
                else:
                    out.append((mod, alias.name, node.lineno))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == "csdf" or alias.name.startswith("csdf."):
                    out.append((alias.name, "", node.lineno))
    return out


def _layer(name: str) -> int:
    best = None
    for prefix in LAYERS:
        if (name == prefix or name.startswith(prefix + ".")) and (
                best is None or len(prefix) > len(best)):
            best = prefix
    if best is None:
        raise AssertionError(f"{name} has no layer: add it to LAYERS in "
                             "tests/test_layering.py and to docs/architecture.md")
    return LAYERS[best]


def _top_package(name: str) -> str:
    parts = name.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 else name


EDGES = {name: _imports(name, path) for name, path in MODULES.items()}


def test_every_module_has_a_layer():
    for name in MODULES:
        _layer(name)


def test_no_import_cycles():
    graph = {name: {t for t, _, _ in deps if t in MODULES and t != name}
             for name, deps in EDGES.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
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
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_layers_import_only_downwards():
    bad = []
    for name, deps in EDGES.items():
        mine = _layer(name)
        for target, _, line in deps:
            if target not in MODULES:
                continue
            if _layer(target) > mine and (name, _top_of(target)) not in UPCALLS \
                    and (name, target) not in UPCALLS:
                bad.append(f"{MODULES[name].relative_to(SRC)}:{line}: {name} "
                           f"({LAYER_NAMES[mine]}) imports {target} "
                           f"({LAYER_NAMES[_layer(target)]})")
    assert not bad, "imports up the layers:\n" + "\n".join(bad)


def _top_of(target: str) -> str:
    """``csdf.backends`` for ``csdf.backends.x`` (upcalls name a package or a module)."""
    return _top_package(target)


def test_only_the_field_layer_names_evaluator_modules():
    bad = []
    for name, deps in EDGES.items():
        if name.startswith("csdf.backends") or name in ("csdf.field", "csdf.fieldset"):
            continue
        for target, _, line in deps:
            if target == "csdf.backends" or target.startswith("csdf.backends."):
                if (name, "csdf.backends") in UPCALLS:
                    continue
                bad.append(f"{MODULES[name].relative_to(SRC)}:{line}: {name} imports "
                           f"{target}")
    assert not bad, "evaluator modules named outside csdf.field:\n" + "\n".join(bad)


def test_no_private_imports_across_packages():
    bad = []
    for name, deps in EDGES.items():
        path = MODULES[name]
        here = ".".join(_package(name, path))
        for target, imported, line in deps:
            tpath = MODULES.get(target)
            there = ".".join(_package(target, tpath)) if tpath is not None else target
            if there == here:
                continue
            private_module = any(p.startswith("_") and not p.startswith("__")
                                 for p in target.split("."))
            private_name = imported.startswith("_") and not imported.startswith("__")
            if private_module or private_name:
                what = f"{target}.{imported}" if imported else target
                bad.append(f"{path.relative_to(SRC)}:{line}: {name} imports {what}")
    assert not bad, "private names imported from another package:\n" + "\n".join(bad)


@pytest.mark.parametrize("rule", sorted(UPCALLS))
def test_upcalls_are_real(rule):
    """Each allowed upward import still exists (a stale exception would hide nothing)."""
    src, dst = rule
    assert any(t == dst or t.startswith(dst + ".") for t, _, _ in EDGES[src]), rule
