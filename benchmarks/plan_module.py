"""Does the planning module over the whole map (hnsdt.models.plan.MapPlanner) learn to plan? Trained alone — its
reward, backups and own action head, from noisy-planner episodes of GoTo sub-goals on generated maps — then scored
on maps it never saw: at every cell of each held-out map, with the key held and the door open, is the module's
action from its neighbours' values a shortest way to the exit? Reported over all cells, and over the cells whose
shortest way starts by stepping away from the exit (where the exit's direction misleads: what a 5 × 5 view and the
target's offset cannot do); beside the same weights cut to 0 backups (nothing planned: what the cells' own rewards
give). Breadth-first search scores the answers here only; it is never an input or a target.

Run: python benchmarks/plan_module.py [--family keydoor_maze] [--maps 8] [--steps 300] [--lr 3e-3] [--batch 64]
     [--heldout 5]
Prints the training loss every 50 steps, then `all cells: planned P (cut C)` and `walk-away cells: …`, and the time.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.core.reproducible import pin_process

pin_process()

from hnsdt.data.collect import Behaviour, CollectConfig, collect_episodes  # noqa: E402
from hnsdt.envs.generate import generate  # noqa: E402
from hnsdt.envs.layout import MOVES, reachable_cells  # noqa: E402
from hnsdt.envs.observation import N_CODES, whole_map  # noqa: E402
from hnsdt.models.plan import MapPlanner  # noqa: E402


def training_steps(family: str, maps: int, side: int):
    """(agent states, whole maps, sub-goal targets, actions) of every step with a target, as tensors."""
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


def scores(module, embed, family: str, heldout: int, iterations=None) -> tuple[float, float]:
    """(share of all cells, share of walk-away cells) whose chosen action is a shortest way to the exit."""
    if iterations is not None:
        module.iterations = lambda side: iterations  # (the instance's: the class keeps side²)
    good, away = [], []
    for seed in range(100_000, 100_000 + heldout):
        layout = generate(family, seed)
        side, goal = max(layout.shape), np.array(layout.goal)
        reach = reachable_cells(layout, layout.goal, set(layout.doors))  # (moves are reversible: steps to it)
        dist = np.full(layout.shape, -1)
        for cell, d in reach.items():
            dist[cell] = d
        cells = np.argwhere(dist > 0)
        held = np.concatenate([cells[:1], np.ones((1, layout.n_flags), dtype=np.int64)], axis=1)
        grid = torch.from_numpy(whole_map(layout, held, side).reshape(1, -1))
        with torch.no_grad():
            q, v = module._plan_rows(embed, grid, torch.ones(1, layout.n_flags), torch.tensor([layout.goal]), side)
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
    if iterations is not None:
        del module.iterations
    return float(np.mean(good)), float(np.mean(away)) if away else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="keydoor_maze")
    ap.add_argument("--maps", type=int, default=8)
    ap.add_argument("--heldout", type=int, default=5)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--lr", type=float, default=3e-3)
    args = ap.parse_args()
    start = time.time()
    side = max(max(generate(args.family, s).shape) for s in range(args.maps))
    states, grids, targets, actions = training_steps(args.family, args.maps, side)
    n_flags = states.shape[1] - 2
    print(f"{len(actions)} steps with a target on {args.maps} maps (side {side}, {MapPlanner.iterations(side)} "
          f"backups); collected in {time.time() - start:.0f} s")
    torch.manual_seed(0)
    embed, module = nn.Embedding(N_CODES, 16), MapPlanner(16, n_flags)
    opt = torch.optim.Adam([*embed.parameters(), *module.parameters()], lr=args.lr)
    rng = np.random.default_rng(0)
    for step in range(args.steps):
        b = torch.from_numpy(rng.choice(len(actions), args.batch))
        q, v = module._plan_rows(embed, grids[b], states[b, 2:], targets[b], side)
        logits = module.act(module.read(q, v, torch.arange(args.batch), states[b, :2])[:, -4:])
        loss = F.cross_entropy(logits, actions[b])
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 50 == 0 or step == args.steps - 1:
            print(f"step {step}: loss {loss.item():.3f}")
    module.eval()
    planned, cut = scores(module, embed, args.family, args.heldout), scores(module, embed, args.family,
                                                                             args.heldout, 0)
    print(f"all cells: planned {planned[0]:.3f} (cut {cut[0]:.3f}); walk-away cells: planned {planned[1]:.3f} "
          f"(cut {cut[1]:.3f}); {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
