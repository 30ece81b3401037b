"""The paper's own configuration of its transformers, and where the steps of a plan-following DT go (its sub-goal
segments against the hand-written controllers')."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from hnsdt.core.methods import METHODS, PAPER_ARM, PROPOSED
from hnsdt.report.common import fmt, label


def paper_arm_lines(summ: pd.DataFrame, results: Path) -> list[str]:
    """Both arms side by side (success, steps of successful episodes and their ratio to the exact optimum, per
    env × fail_prob), and where the paper's HNSDT's steps go (:func:`decomposition_lines`)."""
    planners = [name for name, m in METHODS.items() if m.training == "none"]  # the symbolic baseline
    methods = [m for m in (*planners, *[x for pair in PAPER_ARM.items() for x in pair]) if m in set(summ.method)]
    if not set(PAPER_ARM.values()) & set(methods):
        return []
    lines = ["| env | fail_prob | " + " | ".join(label(m) for m in methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    for (env, fp), c in summ.groupby(["env", "fail_prob"], sort=True):
        cells = []
        for m in methods:
            r = c[c.method == m]
            if r.empty:
                cells.append("–")
                continue
            r = r.iloc[0]
            ratio = f" ({r.steps_ratio:.2f}×)" if "steps_ratio" in c and not pd.isna(r.steps_ratio) else ""
            cells.append(f"{r.success_mean:.3f} / {fmt(r.steps_mean, '.1f')}{ratio}")
        lines.append(f"| {env} | {fp:g} | " + " | ".join(cells) + " |")
    lines += ["", "Each cell: success rate / mean steps of successful episodes (steps relative to the exact "
              "optimum), mean over seeds.", ""]
    return lines + decomposition_lines(results, PAPER_ARM[PROPOSED])


def step_decomposition(segments: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    """Sums and shares of ``results/segments.csv`` rows per ``by`` + sub-goal kind (the operator's name up to
    its bracket): segments, their steps and minimum steps, first actions right, right actions, reached."""
    kind = segments.operator.str.extract(r"^(\w+)", expand=False).rename("kind")
    return segments.groupby([*(segments[c] for c in by), kind]).agg(
        n=("steps", "size"), steps=("steps", "sum"), optimal=("optimal_steps", "sum"),
        first=("first_action_right", "mean"), right=("right_actions", "sum"), reached=("achieved", "mean"))


DECOMPOSITION_HEAD = ["segments / episode", "steps / episode (minimum)", "first action right", "reached"]


def decomposition_cells(seg: pd.DataFrame, n_ep: pd.Series, by: list[str], pair: list[str],
                        sort: bool = True) -> list[list]:
    """Rows ``[*group, kind, cells of pair[0], cells of pair[1]]`` of :data:`DECOMPOSITION_HEAD`, per ``by``
    group and kind of sub-goal (Move / GoTo first): the segments and steps per episode (``n_ep``: episodes per
    method + ``by`` group), the minimum steps beside them, the shares of first actions right and of sub-goals
    reached within their allowance. ``sort``: the groups in sorted order, else in ``seg``'s."""
    seg = seg.assign(kind=seg.operator.str.extract(r"^(\w+)", expand=False))
    t = step_decomposition(seg, ["method", *by])
    kinds = sorted(set(seg.kind), key=lambda k: (k not in ("Move", "GoTo"), k))
    rows = []
    for group, here in seg.groupby(by, sort=sort):
        group = group if isinstance(group, tuple) else (group,)
        for kind in [k for k in kinds if k in set(here.kind)]:  # (an env without items has no PickItem)
            cells = []
            for m in pair:
                key = (m, *group, kind)
                if key not in t.index or (m, *group) not in n_ep.index:
                    cells += ["–"] * len(DECOMPOSITION_HEAD)
                    continue
                r, n = t.loc[key], n_ep[(m, *group)]
                cells += [f"{r.n / n:.2f}", f"{r.steps / n:.1f} ({r.optimal / n:.1f})", f"{r['first']:.3f}",
                          f"{r.reached:.3f}"]
            rows.append([*group, kind, *cells])
    return rows


def decomposition_lines(results: Path, method: str) -> list[str]:
    """Where a plan-following DT's steps go, beside the hand-written controllers under the same planner (the
    floor a perfect executor of those sub-goals reaches): per kind of sub-goal, the steps spent per episode
    against the minimum expected for the sub-goals set (``optimal_steps``), the share of first actions that are
    right and of sub-goals reached within their allowance; then the replans per episode by reason."""
    from hnsdt.agents.executor import REPLAN_REASONS
    from hnsdt.core.methods import CONTROLLER_FLOOR

    seg_path, ep_path = results / "segments.csv", results / "episodes.csv"
    if not seg_path.is_file() or not ep_path.is_file():
        return []
    pair = [method, CONTROLLER_FLOOR[method]]
    seg = pd.read_csv(seg_path)
    seg = seg[seg.method.isin(pair)]
    if method not in set(seg.method) or "first_action_right" not in seg:
        return []
    episodes = pd.read_csv(ep_path)
    episodes = episodes[episodes.method.isin(pair)]
    n_ep = episodes.groupby(["method", "env", "fail_prob"]).size()
    lines = [f"Where the steps of {label(method)} go, beside {label(pair[1])} (the same planner, "
             "hand-written controllers: the floor of this design), per kind of sub-goal; steps per "
             "episode against the minimum expected for the sub-goals set (1 / (1 − fail_prob) per Move, 1 per "
             "pick / open), all seeds (`results/segments.csv`):", "",
             "| env | fail_prob | sub-goal | " + " | ".join(f"{h}: {m}" for m in ("DT", "controllers")
                                                          for h in DECOMPOSITION_HEAD)
             + " |", "|---|---|---|" + "---|" * 2 * len(DECOMPOSITION_HEAD)]
    for env, fp, kind, *cells in decomposition_cells(seg, n_ep, ["env", "fail_prob"], pair):
        lines.append(f"| {env} | {fp:g} | {kind} | " + " | ".join(cells) + " |")
    reasons = [f"replans_{r}" for r in REPLAN_REASONS]
    if set(reasons) <= set(episodes.columns):
        per = episodes.groupby(["env", "fail_prob", "method"])[["steps", *reasons]].mean()
        lines += ["", "Replans per episode by reason (overran: the sub-goal took more than its allowance; broken: "
                  "a step broke the rest of the plan's preconditions; exhausted: the plan ran out before the exit) "
                  "and steps per episode (all episodes; a failure counts its steps to the limit):", "",
                  "| env | fail_prob | method | steps | " + " | ".join(REPLAN_REASONS) + " |",
                  "|---|---|---|---|" + "---|" * len(reasons)]
        for (env, fp, m), r in per.iterrows():
            lines.append(f"| {env} | {fp:g} | {label(m)} | {r.steps:.1f} | "
                         + " | ".join(f"{r[c]:.2f}" for c in reasons) + " |")
    return lines
