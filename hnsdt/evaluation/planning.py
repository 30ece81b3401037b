"""Does the planning module over the whole map (:class:`hnsdt.models.plan.MapPlanner`) plan? It is trained alone
— its cell layers, backups and own action head, from noisy-planner episodes of GoTo sub-goals on generated maps
(:func:`train_alone`) — then scored on maps it never saw (:func:`shortest_way_shares`): at every cell, with the key
held and the door open, is the module's action from its neighbours' read-out a shortest way to the exit? Over all
cells, and over the cells whose shortest way starts by stepping away from the exit (what the cells around the agent
and the target's direction cannot tell). Breadth-first search scores the answers here only; it never feeds the
module. Used by ``benchmarks/plan_module.py`` and the tests."""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from hnsdt.data.collect import Behaviour, CollectConfig, collect_episodes
from hnsdt.envs.generate import generate
from hnsdt.envs.layout import MOVES, Layout, reachable_cells
from hnsdt.envs.observation import whole_map
from hnsdt.models.plan import MapPlanner


def demonstrations(family: str, maps: int, side: int) -> list[torch.Tensor]:
    """(agent states, whole maps, sub-goal targets, actions) of every step with a target of 32 noisy-planner
    episodes on each of the family's first ``maps`` layouts, as tensors."""
    parts = []
    for seed in range(maps):
        layout = generate(family, seed)
        cfg = CollectConfig(env_id="gen", layout=layout, max_steps=150, fail_probs=[0.0], seed=seed,
                            behaviours=[Behaviour("noisy_planner", 16, start, 0.1) for start in ("layout", "random")])
        for ep in collect_episodes(cfg, progress=False):
            t = len(ep["actions"])
            has = np.asarray(ep["subgoal_targets"])[:, 0] >= 0
            states = ep["states"][:t][has]
            parts.append((states, whole_map(layout, states, side).reshape(len(states), -1),
                          np.asarray(ep["subgoal_targets"])[has], np.asarray(ep["actions"])[has]))
    return [torch.from_numpy(np.concatenate(col)) for col in zip(*parts)]


def train_alone(family: str, maps: int, steps: int, batch: int = 64, lr: float = 1e-2, backup: str = "moves",
                seed: int = 0, log: Callable[[str], None] = lambda line: None, **module_kw) -> MapPlanner:
    """The module trained alone (VIN's objective: its own action head's cross-entropy on the demonstrations'
    actions) on the family's first ``maps`` layouts, ``steps`` Adam steps of ``batch`` random steps each."""
    side = max(max(generate(family, s).shape) for s in range(maps))
    states, grids, targets, actions = demonstrations(family, maps, side)
    log(f"{len(actions)} steps with a target on {maps} maps (side {side}, at most {MapPlanner.iterations(side)} "
        "backups)")
    torch.manual_seed(seed)
    module = MapPlanner(16, states.shape[1] - 2, backup=backup, **module_kw)
    opt = torch.optim.Adam(module.parameters(), lr=lr)
    rng = np.random.default_rng(seed)
    for step in range(steps):
        b = torch.from_numpy(rng.choice(len(actions), batch))
        q, v = module._plan_rows(grids[b], states[b, 2:], targets[b], side)
        loss = F.cross_entropy(module.act(module.read(q, v, torch.arange(batch), states[b, :2])[:, -4:]),
                               actions[b])
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 250 == 0 or step == steps - 1:
            log(f"step {step}: loss {loss.item():.3f}")
    return module.eval()


LEGS = ("key", "door", "exit")  # a GoTo sub-goal's targets on a map with one key and one door, in order


def leg_state(layout: Layout, leg: str) -> tuple[tuple[int, int], np.ndarray, set[str]]:
    """The target cell of ``leg``, the flags while it is walked (the key held from the door on, the door open for
    the exit) and the doors open then; the key and door legs need a map with one key and one door."""
    flags = np.ones(layout.n_flags, dtype=np.int64)
    if leg == "exit":
        return layout.goal, flags, set(layout.doors)
    if len(layout.keys) != 1 or len(layout.doors) != 1:
        raise ValueError(f"{layout.name}: the {leg} leg needs one key and one door")
    flags[:] = 0
    if leg == "key":
        return next(iter(layout.keys.values())), flags, set()
    flags[:1] = 1
    (door, cell), = layout.doors.items()
    return cell, flags, {door}  # (the door its own search's origin: a closed door's cell would reach nothing)


def shortest_way_shares(module: MapPlanner, layouts: list[Layout], iterations: int | None = None,
                        leg: str = "exit") -> tuple[float, float]:
    """(share of all cells, share of walk-away cells) of ``layouts`` from which the module's action is a shortest
    way to ``leg``'s target (:func:`leg_state`: by default the exit, with the key held and the door open);
    ``iterations``: that many backups instead of side² (0: cut, each cell's own values only)."""
    good, away = [], []
    for layout in layouts:
        target, flags, open_doors = leg_state(layout, leg)
        side, goal = max(layout.shape), np.array(target)
        reach = reachable_cells(layout, target, open_doors)  # (moves are reversible: steps to it)
        closed = {cell for d, cell in layout.doors.items() if d not in open_doors}
        dist = np.full(layout.shape, -1)
        for cell, d in reach.items():
            dist[cell] = d
        cells = np.array([cell for cell in np.argwhere(dist > 0) if tuple(cell) not in closed])
        state = np.concatenate([cells[:1], flags[None]], axis=1)
        grid = torch.from_numpy(whole_map(layout, state, side).reshape(1, -1))
        with torch.no_grad():
            q, v = module._plan_rows(grid, torch.from_numpy(flags[None]).float(), torch.tensor([target]), side,
                                     iterations)
            read = module.read(q, v, torch.zeros(len(cells), dtype=torch.long), torch.from_numpy(cells))
            chosen = module.act(read[:, -4:]).argmax(-1).numpy()
        for (r, c), a in zip(cells, chosen):
            steps = [(r + dr, c + dc) for dr, dc in MOVES]
            best = [n for n in steps if 0 <= n[0] < layout.shape[0] and 0 <= n[1] < layout.shape[1]
                    and dist[n] == dist[r, c] - 1]
            ok = bool(a < 4 and steps[a] in best)
            good.append(ok)
            if all(np.abs(np.array(n) - goal).sum() > np.abs(np.array((r, c)) - goal).sum() for n in best):
                away.append(ok)
    return float(np.mean(good)), float(np.mean(away)) if away else float("nan")
