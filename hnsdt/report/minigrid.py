"""The section on MiniGrid's own worlds: per world and fail_prob, the exact optimum beside MiniGrid's BabyAI bot and
the symbolic agent (planner + hand-written controllers)."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.params import Params
from hnsdt.evaluation.minigrid import BOT, OPTIMUM, SYMBOLIC, read_csv


def minigrid_context(params: Params, folder: Path) -> dict:
    """The template's ``minigrid_*`` values from ``folder``/NAME/reference/summary.csv for every world of
    ``minigrid.envs`` (an empty dict when the section has none)."""
    section = params.minigrid
    if section is None or not section.envs:
        return {}
    lines, worlds = [], []
    for name, env in section.envs.items():
        path = folder / name / "reference" / "summary.csv"
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no references of MiniGrid world {name} "
                                    f"(run `dvc repro minigrid_reference@{name}`)")
        rows = {(r["fail_prob"], r["method"]): r for r in read_csv(path.read_text())}
        worlds.append(f"{env.id} (`{name}`, {rows[next(iter(rows))]['worlds']} worlds)")
        for p in sorted({p for p, _ in rows}):
            opt = rows[(p, OPTIMUM)]
            played = [rows[(p, m)] for m in (SYMBOLIC, BOT)]
            lines.append(f"| {env.id} | {p:g} | {opt['success_mean']:.3f} | {opt['steps_mean']:.1f} | "
                         f"{opt['reward_mean']:.3f} | "
                         + " | ".join(f"{r['success_mean']:.3f} | {r['steps_mean']:.1f} "
                                      f"({r['steps_mean'] / opt['steps_mean']:.2f}×) | {r['reward_mean']:.3f}"
                                      for r in played) + " |")
    return dict(minigrid_lines=lines, minigrid_worlds=worlds, minigrid_seeds=section.test_seeds.seeds,
                minigrid_episodes=section.episodes)
