"""The unseen-layout sections: success and steps / optimum per split, the targets, the drawn maps, the scaling and
ablation tables, and each further experiment."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from hnsdt.compose.params import Params  # noqa: E402
from hnsdt.core.methods import METHODS, OUR_DTS, PROPOSED, REFERENCE  # noqa: E402
from hnsdt.report.common import SPLIT_LABELS, fmt, label, methods_in, trained_seeds  # noqa: E402
from hnsdt.report.paper_arm import DECOMPOSITION_HEAD, decomposition_cells  # noqa: E402


TARGET_SUCCESS, TARGET_STEPS = 0.95, 1.10  # HNSDT on maps it never saw: of the optimum's success, its steps


def target_lines(summ: pd.DataFrame, method: str = PROPOSED, why: dict | None = None) -> list[str]:
    """Per unseen split, whether ``method`` reaches ``TARGET_SUCCESS`` × the exact optimum's success and at most
    ``TARGET_STEPS`` × its expected steps at every failure probability (each a mean over seeds), and if not,
    by how much at its worst failure probability, and (``why``, :func:`unseen_decomposition`) how its walking
    sub-goals (GoTo or Move) went there."""
    out = []
    for split, d in summ[(summ.method == method) & (summ.split != "train")].groupby("split", sort=False):
        share = d.success_mean / d.optimal_success
        worst_share, worst_steps = d.loc[share.idxmin()], d.loc[d.steps_ratio_mean.fillna(np.inf).idxmax()]
        met = share.min() >= TARGET_SUCCESS and worst_steps.steps_ratio_mean <= TARGET_STEPS
        steps = (f"most steps {worst_steps.steps_ratio_mean:.2f}× the optimum's (fail_prob {worst_steps.fail_prob:g})"
                 if d.steps_ratio_mean.notna().any() else "no episode reached the exit")
        line = (f"{SPLIT_LABELS.get(split, split)}: " + ("met" if met else "short") +
                f" — lowest success {share.min():.3f} of the optimum's (fail_prob {worst_share.fail_prob:g}), " + steps)
        if not met and why and split in why:
            ratio, right, reached, overran, ended = why[split]
            line += (f"; measured cause: its walking sub-goals took {ratio:.2f}× their minimum steps, {right:.3f} of "
                     f"their actions on a shortest path; {reached:.3f} were reached within their allowance, "
                     f"{overran:.3f} overran it (replanned), {ended:.3f} were still open at the step limit")
        out.append(line)
    return out


def unseen_decomposition(results: Path, episodes: pd.DataFrame, method: str = PROPOSED) -> tuple[list[str], dict]:
    """Where ``method``'s steps go on the unseen-layout splits, beside the symbolic baseline (the same planner,
    hand-written controllers): :func:`decomposition_cells` per split, over every seed and failure probability
    (``segments.csv``; ``episodes``: the ``episodes.csv`` beside it); and per split the measured cause behind
    :func:`target_lines`: ``{split: (steps / minimum of its GoTo or Move sub-goals, share of their actions on a shortest
    path, shares achieved, overran and still open at the episode's end)}``."""
    from hnsdt.core.methods import CONTROLLER_FLOOR

    seg_path = results / "segments.csv"
    if not seg_path.is_file() or seg_path.stat().st_size < 2:
        return [], {}
    seg = pd.read_csv(seg_path)
    pair = [method, CONTROLLER_FLOOR[method]]
    if "operator" not in seg or method not in set(seg.method):
        return [], {}
    seg = seg[seg.method.isin(pair)]
    n_ep = episodes[episodes.method.isin(pair)].groupby(["method", "split"]).size()
    lines = ["| split | sub-goal | " + " | ".join(f"{h}: {label(m)}" for m in pair
                                                 for h in DECOMPOSITION_HEAD) + " |",
             "|---|---|" + "---|" * 2 * len(DECOMPOSITION_HEAD)]
    for split, kind, *cells in decomposition_cells(seg, n_ep, ["split"], pair, sort=False):
        lines.append(f"| {SPLIT_LABELS.get(split, split)} | {kind} | " + " | ".join(cells) + " |")
    walks = seg[(seg.method == method) & seg.operator.str.startswith(("GoTo", "Move"))]
    why = {split: (d.steps.sum() / d.optimal_steps.sum(), d.right_actions.sum() / d.steps.sum(),
                   *(d.outcome.eq(o).mean() for o in ("achieved", "overran", "ended")))
           for split, d in walks.groupby("split", sort=False)}
    return lines, why


def generalisation_table(summ: pd.DataFrame) -> pd.DataFrame:
    """Per method × split: success and steps / optimum averaged over the failure probabilities (each a mean
    over seeds), their across-seed std averaged the same way."""
    g = summ.groupby(["method", "split"], sort=False)
    return g.agg(success=("success_mean", "mean"), success_std=("success_std", "mean"),
                 steps_ratio=("steps_ratio_mean", "mean")).reset_index()


def generalisation_figure(table: pd.DataFrame, path: Path) -> None:
    """Bars per method, one per split: success (left) and steps / optimum of the successful episodes (right)."""
    methods, splits = list(dict.fromkeys(table.method)), list(dict.fromkeys(table.split))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    width = 0.8 / len(splits)
    x = np.arange(len(methods))
    for k, split in enumerate(splits):
        d = table[table.split == split].set_index("method").reindex(methods)
        axes[0].bar(x + k * width, d.success, width, yerr=d.success_std.fillna(0), capsize=2,
                    label=SPLIT_LABELS.get(split, split))
        axes[1].bar(x + k * width, d.steps_ratio, width, label=SPLIT_LABELS.get(split, split))
    for ax, title in zip(axes, ("success rate (mean over fail_probs)", "steps / optimal (successful episodes)")):
        ax.set_xticks(x + width * (len(splits) - 1) / 2, [label(m) for m in methods], rotation=25, ha="right",
                      fontsize=8)
        ax.set_title(title)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylim(0, 1.05)
    axes[1].axhline(1.0, color="k", lw=0.8)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def drawn_lines(episodes: pd.DataFrame) -> str:
    """Per hand-drawn map: each method's success (mean over fail_probs, seeds and episodes) and HNSDT's steps /
    optimum — which shapes a method handles, where the split's mean hides it."""
    d = episodes[episodes.split == "drawn"]
    if d.empty:
        return ""
    methods = methods_in(d)
    lines = ["| map | " + " | ".join(label(m) for m in methods) + " | HNSDT steps / opt |",
             "|---|" + "---|" * (len(methods) + 1)]
    for layout, m in d.groupby("layout", sort=False):
        success = m.groupby("method").success.mean()
        won = m[(m.method == PROPOSED) & m.success]
        ratio = (won.steps / won.optimal_steps).mean() if len(won) else np.nan
        lines.append(f"| `{Path(layout).stem}` | " + " | ".join(fmt(success.get(x)) for x in methods)
                     + f" | {fmt(ratio, '.2f')} |")
    return "\n".join(lines)


def _split_table(table: pd.DataFrame) -> list[str]:
    """The markdown rows of :func:`generalisation_table`: per method, success ± std and steps / optimum on each
    split, and its held-out over its training success."""
    splits = list(dict.fromkeys(table.split))
    head = "| method | " + " | ".join(f"{SPLIT_LABELS.get(s, s)}: success | steps / opt" for s in splits)
    lines = [head + " | held-out / training success |", "|---" * (2 * len(splits) + 2) + "|"]
    for method in dict.fromkeys(table.method):
        d = table[table.method == method].set_index("split")
        cells = " | ".join(f"{fmt(d.success.get(s))} ± {fmt(d.success_std.get(s))} | {fmt(d.steps_ratio.get(s), '.2f')}"
                           for s in splits)
        ratio = (d.success.get("heldout", np.nan) / d.success.get("train", np.nan)
                 if d.success.get("train", 0) > 0 else np.nan)
        lines.append(f"| {label(method)} | {cells} | {fmt(ratio, '.2f')} |")
    return lines


def experiment_contexts(params: Params, folder: Path, reference: Path | None = None) -> list[dict]:
    """The report's lines of each experiment of ``unseen_experiments``, from ``folder``/NAME/results: what it
    changes, its table (:func:`_split_table`) and HNSDT against the target (:func:`target_lines`); ``summary``
    holds its summary table (the headline's line). An experiment whose planner hands out other operators than
    the main experiment's (results at ``reference``) is set beside it by :func:`operators_table`."""
    from hnsdt.compose.config import layout_executor, unseen_experiment

    main_operators = layout_executor(params, PROPOSED).operators
    main_episodes = None
    out = []
    for name, changes in params.unseen_experiments.items():
        results = Path(folder) / name / "results"
        if not (results / "summary.csv").is_file():
            raise FileNotFoundError(f"{results / 'summary.csv'}: no results of the unseen-layout experiment {name} "
                                    f"(run `dvc repro unseen_experiment@{name}`)")
        mine = unseen_experiment(params, name)
        summ = pd.read_csv(results / "summary.csv")
        operators = layout_executor(mine, PROPOSED).operators
        beside = []
        if reference is not None and operators != main_operators:
            if main_episodes is None:
                main_episodes = pd.read_csv(Path(reference) / "episodes.csv")
            beside = operators_table(main_episodes, pd.read_csv(results / "episodes.csv"),
                                     (main_operators, operators))
        written = {k: v if isinstance(v, str) else json.dumps(v) for k, v in changes.items()}  # as in YAML
        out.append({"name": name, "changes": ", ".join(f"`{k}: {v}`" for k, v in written.items()),
                    "family": mine.generalisation.family, "train": mine.generalisation.train_layouts,
                    "seeds": trained_seeds(summ), "operators": operators,
                    "results": str(results / "summary.csv"), "table": "\n".join(_split_table(generalisation_table(summ))),
                    "targets": target_lines(summ), "summary": summ, "operators_table": "\n".join(beside),
                    "reference_operators": OPERATOR_NAMES.get(main_operators, main_operators),
                    "reference": str(Path(reference) / "episodes.csv") if reference is not None else ""})
    return out


OPERATOR_NAMES = {"move": "Move", "goto": "GoTo"}


def executor_label(params: Params, method: str, run: str) -> str:
    """A row of :func:`executors_table`: the method, what its planner hands it (nothing for a DT without a sub-goal)
    and what it reads (the view, or the whole map through the planning module), the family it trained on, the run."""
    from hnsdt.compose.config import layout_executor

    g, m = params.generalisation, METHODS[method]
    side = 2 * g.view_radius + 1
    operators = OPERATOR_NAMES.get(layout_executor(params, method).operators, "?")
    if m.training == "none":
        handed, reads = operators, "the planner's way"
    else:
        handed = operators if m.condition == "subgoal" else "no sub-goal"
        reads = "whole map + planning module" if g.whole_map else f"{side} × {side} view"
    return f"{label(method)}: {handed}, {reads}; `{g.family}` ({run})"


# The rows of :func:`executors_table`: the planner's own controllers (the main run's), then our transformers
EXECUTOR_METHODS = (REFERENCE, PROPOSED, *(m for m in OUR_DTS if m != PROPOSED))


def executors_table(params: Params, main: pd.DataFrame, experiments: list[dict]) -> str:
    """Every way the unseen-layout runs execute a plan, in one table: the planner with hand-written controllers,
    HNSDT handed Move or GoTo sub-goals reading the view or the whole map, the pure DT with no sub-goal (each run's
    decision transformers and the main run's reference), per split success and steps / optimum (means over the
    failure probabilities of the means over seeds). ``main``: the main run's summary; ``experiments``:
    :func:`experiment_contexts`. A run of another family evaluates that family's own training and held-out maps."""
    from hnsdt.compose.config import unseen_experiment

    runs = [("main run", params, main)] + [(f"`{e['name']}`", unseen_experiment(params, e["name"]), e["summary"])
                                           for e in experiments]
    splits = list(dict.fromkeys(s for _, _, summ in runs for s in summ.split))
    lines = ["| executor: sub-goals, what it reads; training family (run) | "
             + " | ".join(SPLIT_LABELS.get(s, s) for s in splits) + " |", "|---|" + "---|" * len(splits)]
    for run, p, summ in runs:
        table = generalisation_table(summ)
        for method in EXECUTOR_METHODS:
            if method not in set(table.method) or (method == REFERENCE and run != "main run"):
                continue
            d = table[table.method == method].set_index("split")
            lines.append(f"| {executor_label(p, method, run)} | " + " | ".join(
                "–" if pd.isna(d.success.get(s)) else f"{fmt(d.success.get(s))} ({fmt(d.steps_ratio.get(s), '.2f')}×)"
                for s in splits) + " |")
    return "\n".join(lines)


def operators_table(reference: pd.DataFrame, other: pd.DataFrame, operators: tuple[str, str]) -> list[str]:
    """HNSDT handed one operator set (``reference``'s episodes) beside another (``other``'s), on the maps both
    evaluated in a split (a split where one evaluated maps the other did not says how many are shared): per
    split and fail_prob, success, sub-goals and the planner's calls per episode (means over seeds and episodes)
    — what coarser sub-goals save the planner and cost the transformer. Empty where the episodes carry no
    sub-goal counts or no map is shared."""
    a, b = (d[d.method == PROPOSED] for d in (reference, other))
    if not {"subgoals", "plans"} <= set(a.columns) & set(b.columns):
        return []
    names = [OPERATOR_NAMES.get(o, o) for o in operators]
    head = [f"{n}: {h}" for n in names for h in ("success", "sub-goals / episode", "planner calls / episode")]
    lines = []
    for split in dict.fromkeys(b.split):
        maps = [set(d.layout[d.split == split]) for d in (a, b)]
        shared = maps[0] & maps[1]
        if not shared:
            continue
        name = SPLIT_LABELS.get(split, split) + ("" if maps[0] == maps[1] else f" (the {len(shared)} maps of both)")
        cells = [d[(d.split == split) & d.layout.isin(shared)].groupby("fail_prob")[["success", "subgoals", "plans"]]
                 .mean() for d in (a, b)]
        for fp in cells[1].index:
            values = [f"{fmt(c.success.get(fp))} | {fmt(c.subgoals.get(fp), '.1f')} | {fmt(c.plans.get(fp), '.1f')}"
                      for c in cells]
            lines.append(f"| {name} | {fp:g} | " + " | ".join(values) + " |")
    if not lines:
        return []
    return ["| split | fail_prob | " + " | ".join(head) + " |", "|---|---|" + "---|" * len(head)] + lines


def generalisation_context(params: Params, results: Path, figure: Path) -> dict:
    """The report's unseen-layout section: the figure, the table and per-fail_prob numbers."""
    from hnsdt.compose.config import layout_executor

    summ = pd.read_csv(results / "summary.csv")
    layouts = pd.read_csv(results / "layouts.csv")
    episodes = pd.read_csv(results / "episodes.csv")
    table = generalisation_table(summ)
    generalisation_figure(table, figure)
    steps, why = unseen_decomposition(results, episodes)
    lines = _split_table(table)
    fps = sorted(set(summ.fail_prob))
    detail = ["| method | split | " + " | ".join(f"fail {f:g}" for f in fps) + " |", "|---|---|" + "---|" * len(fps)]
    for (method, split), d in summ.groupby(["method", "split"], sort=False):
        d = d.set_index("fail_prob")
        detail.append(f"| {label(method)} | {split} | " + " | ".join(
            f"{fmt(d.success_mean.get(f))} ({fmt(d.steps_ratio_mean.get(f), '.2f')}×)" for f in fps) + " |")
    g = params.generalisation
    counts = layouts.groupby("split", sort=False).layout.nunique()
    def span(v: pd.Series) -> str:
        return f"{v.min()}" if v.min() == v.max() else f"{v.min()}–{v.max()}"

    sizes = {s: f"{span(d.rows)} × {span(d.cols)}" for s, d in layouts.groupby("split")}
    return {"generalisation_table": "\n".join(lines), "generalisation_detail": "\n".join(detail),
            "generalisation_targets": target_lines(summ, why=why),
            "generalisation_steps": "\n".join(steps),
            "generalisation_validation": g.validation_layouts if g else 0,
            "generalisation_validation_families": list(g.validation_families) if g else [],
            "generalisation_family": g.family if g else "?", "generalisation_train": g.train_layouts if g else "?",
            "generalisation_radius": g.view_radius if g else "?",
            "generalisation_operators": layout_executor(params, PROPOSED).operators if g else "?",
            "generalisation_splits": [f"{SPLIT_LABELS.get(s, s)}: {n} ({sizes[s]} cells)" for s, n in counts.items()],
            "generalisation_seeds": trained_seeds(summ),
            "generalisation_episodes": int(episodes.groupby(["method", "seed", "layout", "fail_prob"]).size().max()),
            "generalisation_drawn": drawn_lines(episodes)}
