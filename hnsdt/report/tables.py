"""The paper protocol's tables: results per method, env and fail_prob, the exact optimum, the targets, and what
each learned method was trained on."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from hnsdt.core.methods import METHODS, PROPOSED
from hnsdt.report.common import fmt, label, methods_in


def results_table(summ: pd.DataFrame) -> str:
    order = {m: i for i, m in enumerate(methods_in(summ))}
    summ = summ.sort_values(["env", "method", "fail_prob"], key=lambda c: c.map(order) if c.name == "method" else c)
    lines = ["| env | method | fail_prob | success | steps (success) | reward | success / opt | steps / opt | "
             "regret |", "|---|---|---|---|---|---|---|---|---|"]
    for r in summ.itertuples():
        steps = "–" if pd.isna(r.steps_mean) else f"{r.steps_mean:.1f} ± {r.steps_std:.1f}"
        lines.append(f"| {r.env} | {label(r.method)} | {r.fail_prob:g} | {r.success_mean:.3f} ± "
                     f"{r.success_std:.3f} | {steps} | {r.reward_mean:.3f} ± {r.reward_std:.3f} | "
                     f"{fmt(r.success_ratio)} | {fmt(r.steps_ratio)} | {fmt(r.regret)} |")
    return "\n".join(lines)


def optimum_table(summ: pd.DataFrame) -> str:
    cells = summ.drop_duplicates(["env", "fail_prob"]).sort_values(["env", "fail_prob"])
    lines = ["| env | fail_prob | optimal success | optimal expected steps | optimal expected return |",
             "|---|---|---|---|---|"]
    lines += [f"| {r.env} | {r.fail_prob:g} | {r.opt_success:.4f} | {r.opt_steps:.2f} | {r.opt_reward:.3f} |"
              for r in cells.itertuples()]
    return "\n".join(lines)


def paper_target_lines(summ: pd.DataFrame) -> list[str]:
    """Issue 5's target for HNSDT: success >= 0.98 x optimal and steps <= 1.05 x optimal, in every cell."""
    rows = summ[summ.method == PROPOSED]
    if rows.empty:
        return []
    met = (rows.success_ratio >= 0.98) & (rows.steps_ratio <= 1.05)
    out = [f"HNSDT meets the target (success ≥ 0.98 × optimal and steps ≤ 1.05 × optimal) in {int(met.sum())} of "
           f"{len(rows)} env × fail_prob cells."]
    for r in rows[~met].itertuples():
        out.append(f"- misses at {r.env}, fail_prob {r.fail_prob:g}: success ratio {fmt(r.success_ratio)}, "
                   f"steps ratio {fmt(r.steps_ratio)}")
    return out


def usage_lines(results: Path) -> list[str]:
    """What each learned method trained on (mean over seeds): env steps (online) or dataset frames, the passes
    over its training data (epochs), gradient steps and, stopped by a validation measure, the epoch (offline) or
    environment step (online) kept; for an online learner, how many of its training episodes ended at the exit,
    and below the table each online learner that never reached the exit in training, with what that means."""
    path = results / "training_usage.csv"
    if not path.is_file():
        return []
    u = pd.read_csv(path)
    if u.empty:
        return []
    for column in ("epochs", "epoch_kept", "env_steps_kept", "training_exits"):
        if column not in u:
            u[column] = float("nan")
    lines = ["| env | method | trains on | environment steps | dataset frames | epochs | gradient steps | "
             "epoch or step kept | training episodes at the exit |", "|---|---|---|---|---|---|---|---|---|"]
    order = {m: i for i, m in enumerate(METHODS)}
    g = u.groupby(["env", "method", "training"], as_index=False)[["env_steps", "dataset_frames", "epochs",
                                                                  "gradient_steps", "epoch_kept",
                                                                  "env_steps_kept", "training_exits"]].mean()
    g = g.sort_values(["env", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    for r in g.itertuples():
        lines.append(f"| {r.env} | {label(r.method)} | {'the environment' if r.training == 'online' else 'the dataset'}"
                     f" | {fmt(r.env_steps, ',.0f')} | {fmt(r.dataset_frames, ',.0f')} | "
                     f"{fmt(r.epochs, '.1f')} | {fmt(r.gradient_steps, ',.0f')} | "
                     f"{fmt(r.epoch_kept, '.1f') if pd.notna(r.epoch_kept) else fmt(r.env_steps_kept, ',.0f')} | "
                     f"{fmt(r.training_exits, ',.0f')} |")
    never = u[u.training == "online"].groupby(["env", "method"], sort=False).agg(
        seeds=("seed", "size"), blind=("training_exits", lambda x: int((x == 0).sum())), steps=("env_steps", "max"))
    notes = [f"- {label(method)} on {env}: {r.blind:.0f} of its {r.seeds:.0f} seeds never ended a training episode "
             f"at the exit in up to {r.steps:,.0f} environment steps. With the step penalty its only reward until "
             "then, nothing it learns points to the exit: this row measures its exploration, not what it would "
             "learn from a success." for (env, method), r in never[never.blind > 0].iterrows()]
    return lines + ([""] + notes if notes else [])
