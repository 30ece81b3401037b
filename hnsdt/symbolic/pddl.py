"""Export a layout's symbolic domain and a planning problem as STRIPS PDDL (with typing).

Picking and opening are lifted actions. Moving is grounded per layout: reachability "through walls and open
doors" is not expressible in STRIPS, so every ordered pair of places gets one ``goto`` action per minimal set of
doors that must be open for the route, with those doors as preconditions. A STRIPS planner then finds plans
with the same number of operators as :func:`hnsdt.symbolic.plan` in ``bfs`` mode. PDDL is case-insensitive, so
objects are ``key-a``, ``door-a`` (door A), ``item-1``.

With the paper's operators (``operators="move"``) every non-wall cell is a place ``c-R-C`` and moving is lifted:
``move`` between adjacent places, out of a cell that is no door or out of an open door, and ``move-to-exit``
(the same, holding every item) also makes ``done`` true, so plans have the length of the ``move`` plans.
"""

from __future__ import annotations

from itertools import combinations
from pathlib import Path

from hnsdt.core.fileio import atomic_file
from hnsdt.envs.layout import Cell, Layout, reachable_cells
from hnsdt.symbolic.abstraction import SymbolicState


def _places(layout: Layout, state: SymbolicState) -> dict[str, Cell]:
    places = {"start": layout.start}
    places.update({f"p-key-{k}": c for k, c in layout.keys.items()})
    places.update({f"p-door-{d.lower()}": c for d, c in layout.doors.items()})
    places.update({f"p-item-{i}": c for i, c in layout.items.items()})
    places["p-exit"] = layout.goal
    if state.cell not in places.values():
        places[f"p-cell-{state.cell[0]}-{state.cell[1]}"] = state.cell
    return places


def _minimal_door_sets(layout: Layout, origin: Cell, target: Cell) -> list[frozenset[str]]:
    doors = list(layout.doors)
    found: list[frozenset[str]] = []
    for size in range(len(doors) + 1):
        for subset in map(frozenset, combinations(doors, size)):
            if any(f <= subset for f in found):
                continue
            if target in reachable_cells(layout, origin, set(subset)):
                found.append(subset)
    return found


def domain_pddl(layout: Layout, state: SymbolicState | None = None) -> str:
    state = state or SymbolicState.initial(layout)
    places = _places(layout, state)
    actions = [
        """  (:action pick-key
    :parameters (?k - key ?p - place)
    :precondition (and (at ?p) (key-at ?k ?p))
    :effect (has-key ?k))""",
        """  (:action open-door
    :parameters (?d - door ?k - key ?p - place)
    :precondition (and (at ?p) (door-at ?d ?p) (opens ?k ?d) (has-key ?k))
    :effect (door-open ?d))""",
        """  (:action pick-item
    :parameters (?i - item ?p - place)
    :precondition (and (at ?p) (item-at ?i ?p))
    :effect (has-item ?i))""",
    ]
    exit_pre = " ".join(f"(has-item item-{i})" for i in layout.items)
    for src, a in places.items():
        for dst, b in places.items():
            if src == dst or dst == "start" or dst.startswith("p-cell"):
                continue
            for n, doors in enumerate(_minimal_door_sets(layout, a, b)):
                pre = " ".join([f"(at {src})"] + [f"(door-open door-{d.lower()})" for d in sorted(doors)])
                eff = f"(at {dst}) (not (at {src}))"
                if dst == "p-exit":
                    pre += f" {exit_pre}" if exit_pre else ""
                    eff += " (done)"
                actions.append(
                    f"  (:action goto-{src}-to-{dst}-r{n}\n    :parameters ()\n"
                    f"    :precondition (and {pre})\n    :effect (and {eff}))"
                )
    return (
        f"; hnsdt key-door domain grounded on layout {layout.name}\n"
        "(define (domain hnsdt-keydoor)\n"
        "  (:requirements :strips :typing)\n"
        "  (:types place key door item)\n"
        "  (:predicates (at ?p - place) (has-key ?k - key) (door-open ?d - door) (has-item ?i - item)\n"
        "               (key-at ?k - key ?p - place) (door-at ?d - door ?p - place) (item-at ?i - item ?p - place)\n"
        "               (opens ?k - key ?d - door) (done))\n"
        + "\n".join(actions)
        + ")\n"
    )


def _cell_places(layout: Layout) -> dict[str, Cell]:
    h, w = layout.shape
    return {f"c-{r}-{c}": (r, c) for r in range(h) for c in range(w) if not layout.walls[r, c]}


def move_domain_pddl(layout: Layout) -> str:
    """The paper's domain: one-cell moves plus the lifted pick and open actions."""
    items = " ".join(f"(has-item item-{i})" for i in layout.items)
    moves = []
    for exit_move in (False, True):
        name, eff = ("move-to-exit", " (done)") if exit_move else ("move", "")
        params = "?a - place" if exit_move else "?a ?b - place"
        b = "p-exit" if exit_move else "?b"
        need = f" (exit-at {b}) {items}" if exit_move else ""
        moves.append(f"""  (:action {name}
    :parameters ({params})
    :precondition (and (at ?a) (adj ?a {b}) (no-door ?a){need})
    :effect (and (at {b}) (not (at ?a)){eff}))""")
        moves.append(f"""  (:action {name}-out-of-door
    :parameters ({params} ?d - door)
    :precondition (and (at ?a) (adj ?a {b}) (door-at ?d ?a) (door-open ?d){need})
    :effect (and (at {b}) (not (at ?a)){eff}))""")
    return (
        f"; hnsdt key-door domain with the paper's Move operators, layout {layout.name}\n"
        "(define (domain hnsdt-keydoor-move)\n"
        "  (:requirements :strips :typing)\n"
        "  (:types place key door item)\n"
        "  (:constants p-exit - place)\n"
        "  (:predicates (at ?p - place) (adj ?a ?b - place) (no-door ?p - place) (exit-at ?p - place)\n"
        "               (has-key ?k - key) (door-open ?d - door) (has-item ?i - item)\n"
        "               (key-at ?k - key ?p - place) (door-at ?d - door ?p - place) (item-at ?i - item ?p - place)\n"
        "               (opens ?k - key ?d - door) (done))\n"
        + "\n".join(moves) + "\n"
        """  (:action pick-key
    :parameters (?k - key ?p - place)
    :precondition (and (at ?p) (key-at ?k ?p))
    :effect (has-key ?k))
  (:action open-door
    :parameters (?d - door ?k - key ?p - place)
    :precondition (and (at ?p) (door-at ?d ?p) (opens ?k ?d) (has-key ?k))
    :effect (door-open ?d))
  (:action pick-item
    :parameters (?i - item ?p - place)
    :precondition (and (at ?p) (item-at ?i ?p))
    :effect (has-item ?i)))
"""
    )


def move_problem_pddl(layout: Layout, state: SymbolicState | None = None) -> str:
    from hnsdt.envs.layout import MOVES

    state = state or SymbolicState.initial(layout)
    places = _cell_places(layout)
    name = {cell: ("p-exit" if cell == layout.goal else p) for p, cell in places.items()}
    h, w = layout.shape
    door_cells = set(layout.doors.values())
    init = [f"(at {name[state.cell]})", "(exit-at p-exit)"]
    for cell in places.values():
        if cell not in door_cells:
            init.append(f"(no-door {name[cell]})")
        for dr, dc in MOVES:
            nb = (cell[0] + dr, cell[1] + dc)
            if 0 <= nb[0] < h and 0 <= nb[1] < w and not layout.walls[nb]:
                init.append(f"(adj {name[cell]} {name[nb]})")
    init += [f"(key-at key-{k} {name[c]})" for k, c in layout.keys.items() if k not in state.keys]
    init += [f"(door-at door-{d.lower()} {name[c]})" for d, c in layout.doors.items()]
    init += [f"(item-at item-{i} {name[c]})" for i, c in layout.items.items() if i not in state.items]
    init += [f"(opens key-{d.lower()} door-{d.lower()})" for d in layout.doors]
    init += [f"(has-key key-{k})" for k in sorted(state.keys)]
    init += [f"(door-open door-{d.lower()})" for d in sorted(state.doors)]
    init += [f"(has-item item-{i})" for i in sorted(state.items)]
    if state.done(layout):
        init.append("(done)")
    objects = [" ".join(n for n in name.values() if n != "p-exit") + " - place"]
    for kind, names in (("key", [f"key-{k}" for k in layout.keys]),
                        ("door", [f"door-{d.lower()}" for d in layout.doors]),
                        ("item", [f"item-{i}" for i in layout.items])):
        if names:
            objects.append(" ".join(names) + f" - {kind}")
    return (
        f"(define (problem hnsdt-move-{Path(layout.name).stem.lower().replace('_', '-').replace('<', '').replace('>', '')})\n"
        "  (:domain hnsdt-keydoor-move)\n"
        f"  (:objects {' '.join(objects)})\n"
        f"  (:init {' '.join(init)})\n"
        "  (:goal (done)))\n"
    )


def problem_pddl(layout: Layout, state: SymbolicState | None = None) -> str:
    state = state or SymbolicState.initial(layout)
    places = _places(layout, state)
    here = next(name for name, cell in places.items() if cell == state.cell)
    objects = [f"{' '.join(places)} - place"]
    if layout.keys:
        objects.append(" ".join(f"key-{k}" for k in layout.keys) + " - key")
    if layout.doors:
        objects.append(" ".join(f"door-{d.lower()}" for d in layout.doors) + " - door")
    if layout.items:
        objects.append(" ".join(f"item-{i}" for i in layout.items) + " - item")
    init = [f"(at {here})"]
    init += [f"(key-at key-{k} p-key-{k})" for k in layout.keys if k not in state.keys]
    init += [f"(door-at door-{d.lower()} p-door-{d.lower()})" for d in layout.doors]
    init += [f"(item-at item-{i} p-item-{i})" for i in layout.items if i not in state.items]
    init += [f"(opens key-{d.lower()} door-{d.lower()})" for d in layout.doors]
    init += [f"(has-key key-{k})" for k in sorted(state.keys)]
    init += [f"(door-open door-{d.lower()})" for d in sorted(state.doors)]
    init += [f"(has-item item-{i})" for i in sorted(state.items)]
    return (
        f"(define (problem hnsdt-{Path(layout.name).stem.lower().replace('_', '-').replace('<', '').replace('>', '')})\n"
        "  (:domain hnsdt-keydoor)\n"
        f"  (:objects {' '.join(objects)})\n"
        f"  (:init {' '.join(init)})\n"
        "  (:goal (done)))\n"
    )


def write_pddl(layout: Layout, out_dir: str | Path, state: SymbolicState | None = None,
               operators: str = "goto") -> tuple[Path, Path]:
    """``domain.pddl`` and ``problem.pddl`` for the operator set ``operators`` (``goto`` or ``move``)."""
    if operators not in ("goto", "move"):
        raise ValueError(f"unknown operator set {operators!r}; expected goto or move")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    domain, problem = out / "domain.pddl", out / "problem.pddl"
    texts = ((move_domain_pddl(layout), move_problem_pddl(layout, state)) if operators == "move"
             else (domain_pddl(layout, state), problem_pddl(layout, state)))
    for path, text in zip((domain, problem), texts):
        with atomic_file(path) as tmp:
            tmp.write_text(text)
    return domain, problem
