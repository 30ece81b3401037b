"""Imports run one way: the package is a stack of layers, and a module imports only its own layer and those below
it — at the top of a file, inside a function, or by a ``"module:attribute"`` string that is imported later (the
implementations table). No two modules import each other in a circle.

The package root (``hnsdt/__init__.py``) stands outside the stack: it registers the environments' gymnasium ids,
so that ``import hnsdt`` is enough for ``gymnasium.make``."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from conftest import REPO

PACKAGE = Path(REPO) / "hnsdt"
LAYERS = (  # bottom to top
    ("ground", ("hnsdt.core",)),  # file I/O, reproducibility, the method registry (facts), provenance, the task runner
    ("world", ("hnsdt.envs", "hnsdt.symbolic", "hnsdt.minigrid")),  # the grid worlds, the symbolic planner, MiniGrid
    ("networks", ("hnsdt.models",)),  # the trained networks and how they are fitted
    ("policies", ("hnsdt.agents", "hnsdt.baselines", "hnsdt.implementations")),  # agents, and what implements a method
    ("data", ("hnsdt.data", "hnsdt.logs")),  # LeRobot datasets and episode recordings
    ("evaluation", ("hnsdt.evaluation",)),  # evaluations, their tables, the theorem checks
    ("composition", ("hnsdt.compose",)),  # params, settings, the experiments' splits, training plans
    ("report", ("hnsdt.report",)),  # report.md and its figures
    ("stages", ("hnsdt.stages",)),  # one module per DVC stage
    ("command line", ("hnsdt.cli",)),
)
REFERENCE = re.compile(r"^(hnsdt(?:\.\w+)+):\w+$")  # "module:attribute", resolved on use


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, top_level_only: bool = False, strings: bool = False) -> set[str]:
    """The hnsdt modules a file imports (anywhere in it, or only at module level; with ``strings``, also the
    modules its ``"module:attribute"`` strings name)."""
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else ast.walk(tree)
    out = set()
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("hnsdt"):
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("hnsdt")}
        elif strings and isinstance(node, ast.Constant) and isinstance(node.value, str):
            if m := REFERENCE.match(node.value):
                out.add(m.group(1))
    return out


def under(module: str, prefixes) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def layer_of(module: str) -> int | None:
    """The index of ``module``'s layer in LAYERS (None for the package root)."""
    found = [i for i, (_, prefixes) in enumerate(LAYERS) if under(module, prefixes)]
    return found[0] if found else None


def upward_imports(files: dict[str, Path]) -> dict[str, list[str]]:
    """``module -> the modules of higher layers it imports``, over ``files`` (module name -> path)."""
    offenders = {}
    for name, path in files.items():
        here = layer_of(name)
        if here is None:
            continue
        bad = sorted(m for m in imports(path, strings=True) if (there := layer_of(m)) is not None and there > here)
        if bad:
            offenders[name] = [f"{m} ({LAYERS[layer_of(m)][0]} above {LAYERS[here][0]})" for m in bad]
    return offenders


def test_every_module_has_a_layer():
    modules = {module_name(p) for p in PACKAGE.rglob("*.py")} - {"hnsdt"}
    assert not sorted(m for m in modules if layer_of(m) is None)


def test_no_module_imports_a_layer_above_it_not_even_by_a_string():
    assert not upward_imports({module_name(p): p for p in PACKAGE.rglob("*.py")})


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


def test_the_checks_can_fail(tmp_path):
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
    assert under("hnsdt.data.windows", ("hnsdt.data",)) and not under("hnsdt.database", ("hnsdt.data",))
    ground = tmp_path / "ground.py"
    ground.write_text('def f():\n    from hnsdt.stages.common import run\n')
    named = tmp_path / "named.py"
    named.write_text('AGENT = "hnsdt.agents.symbolic:make_agent"\n')
    found = upward_imports({"hnsdt.core.ground": ground, "hnsdt.core.named": named, "hnsdt.stages.fine": ground})
    assert found == {"hnsdt.core.ground": ["hnsdt.stages.common (stages above ground)"],
                     "hnsdt.core.named": ["hnsdt.agents.symbolic (policies above ground)"]}
