"""Imports run one way: the world (envs, symbolic), the networks (models) and the policies (agents) never import
the data layer, the evaluation or the experiments' wiring, and no two modules import each other in a circle."""

from __future__ import annotations

import ast
from pathlib import Path

from conftest import REPO

PACKAGE = Path(REPO) / "hnsdt"
LOWER = ("hnsdt.envs", "hnsdt.symbolic", "hnsdt.models", "hnsdt.agents")
UPPER = ("hnsdt.data", "hnsdt.evaluation", "hnsdt.logs", "hnsdt.compose.generalisation", "hnsdt.compose.training",
         "hnsdt.compose.config", "hnsdt.cli")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, top_level_only: bool = False) -> set[str]:
    """The hnsdt modules a file imports (anywhere in it, or only at module level)."""
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else ast.walk(tree)
    out = set()
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("hnsdt"):
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("hnsdt")}
    return out


def under(module: str, prefixes) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def test_the_lower_layers_never_import_the_upper_ones():
    offenders = {}
    for path in PACKAGE.rglob("*.py"):
        name = module_name(path)
        if under(name, LOWER):
            bad = {m for m in imports(path) if under(m, UPPER)}
            if bad:
                offenders[name] = sorted(bad)
    assert not offenders, offenders


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph, or None."""
    state: dict[str, int] = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt, stack + [nxt])):
                return found
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node, [node])):
            return found
    return None


def test_no_import_cycle_not_even_through_imports_inside_functions():
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {name: {m for m in imports(path) if m in modules and m != name}
             for name, path in modules.items()}
    assert _cycle(graph) is None, _cycle(graph)


def test_the_checks_can_fail():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
    assert under("hnsdt.data.windows", UPPER) and not under("hnsdt.database", UPPER)
