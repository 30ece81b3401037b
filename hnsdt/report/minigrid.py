"""The section on MiniGrid's own worlds: per world and fail_prob, the exact optimum beside MiniGrid's BabyAI bot."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.params import Params
from hnsdt.evaluation.minigrid import BOT, OPTIMUM, read_csv


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
            opt, bot = rows[(p, OPTIMUM)], rows[(p, BOT)]
            lines.append(f"| {env.id} | {p:g} | {opt['success_mean']:.3f} | {opt['steps_mean']:.1f} | "
                         f"{opt['reward_mean']:.3f} | {bot['success_mean']:.3f} | {bot['steps_mean']:.1f} "
                         f"({bot['steps_mean'] / opt['steps_mean']:.2f}×) | {bot['reward_mean']:.3f} |")
    return dict(minigrid_lines=lines, minigrid_worlds=worlds, minigrid_seeds=section.test_seeds.seeds,
                minigrid_bot_episodes=section.bot_episodes)
