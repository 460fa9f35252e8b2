"""The import graph of `sensorimotor.*`, read from the source with `ast` (imports inside functions
too): no cycles, and nothing imports upwards - tools may import everything, agent and worlds import
protocol (never each other), protocol imports only itself (DESIGN.md, import rules)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "agent", "worlds", "tools")
#: what each top-level package may import besides itself
ALLOWED = {"protocol": set(), "agent": {"protocol"}, "worlds": {"protocol"}, "tools": {"protocol", "agent", "worlds"}}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts.pop()
            out["sensorimotor." + ".".join(parts)] = path
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The `sensorimotor` modules `path` imports: a name imported from a package is its submodule
    when there is one, else the package itself."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("sensorimotor.")}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the module's package
                pkg = name.split(".") if is_pkg else name.split(".")[:-1]
                base = ".".join(pkg[: len(pkg) - node.level + 1] + ([base] if base else []))
            if not base.startswith("sensorimotor."):
                continue
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.add(sub if sub in known else base)
    return {m for m in found if m != name}


def graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    g = {m: _imports(m, p, known) for m, p in mods.items()}
    unknown = {(m, d) for m, ds in g.items() for d in ds if d not in known and not d.endswith("_pb2")}
    assert not unknown, f"imports of modules that do not exist: {sorted(unknown)}"
    return {m: {d for d in ds if d in known} for m, ds in g.items()}


def _layer(module: str) -> str:
    return module.split(".")[1]


def upward_imports(g: dict[str, set[str]]) -> list[str]:
    return sorted(
        f"{m} imports {d}"
        for m, ds in g.items()
        for d in ds
        if _layer(d) != _layer(m) and _layer(d) not in ALLOWED[_layer(m)]
    )


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def test_no_module_imports_upwards_and_agent_and_worlds_never_meet():
    assert upward_imports(graph()) == []


def test_the_import_graph_has_no_cycles():
    assert cycles(graph()) == []


def test_the_checks_see_a_cycle_and_an_upward_import():
    g = {
        "sensorimotor.tools.a": {"sensorimotor.tools.b"},
        "sensorimotor.tools.b": {"sensorimotor.tools.a"},
        "sensorimotor.agent.x": {"sensorimotor.worlds.y"},
        "sensorimotor.worlds.y": {"sensorimotor.protocol.z"},
        "sensorimotor.protocol.z": {"sensorimotor.tools.a"},
    }
    assert cycles(g) == [["sensorimotor.tools.a", "sensorimotor.tools.b"]]
    assert upward_imports(g) == [
        "sensorimotor.agent.x imports sensorimotor.worlds.y",
        "sensorimotor.protocol.z imports sensorimotor.tools.a",
    ]
    assert cycles({"sensorimotor.tools.a": {"sensorimotor.tools.b"}, "sensorimotor.tools.b": set()}) == []
