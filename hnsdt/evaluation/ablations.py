"""What each ingredient of the unseen-layout experiment buys: measured variants, the report's ablation table and
its scaling figure (held-out steps / optimum against the number of training maps).

A variant is the experiment with some knobs changed — the encoder, the number of training maps, turned maps,
relabelled rounds of the learner's own states, the operators the planner hands out — run by ``python
benchmarks/generalisation.py --record NAME --ingredient I``
through the experiment's own stage functions. ``dvc repro`` does not rerun them (one costs minutes to half an
hour of 2 cores; 4,000 maps more), so each row carries what made it: the command, the git revision, the digest
of the params and of the dataset it trained on, the CPU and the time. The file is kept in git
(``benchmarks/results/generalisation.csv``) and read by the report stage.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from hnsdt.core.fileio import atomic_file  # noqa: E402
from hnsdt.core.methods import LEARNED, METHODS, PROPOSED  # noqa: E402

# reference: the row the others change (40 maps as collected, GoTo operators)
INGREDIENTS = ("reference", "encoder", "maps", "augmentation", "relabelling", "family", "operators")
COLUMNS = [  # one row per variant x method x split
    "variant", "ingredient", "family", "train_layouts", "episodes_per_map", "encoder", "relabel_rounds", "seeds",
    "method", "split", "success", "success_std", "steps_ratio", "validation_steps",
    "command", "revision", "params_digest", "dataset_digest", "cpu", "seconds"]


def read(path: str | Path) -> pd.DataFrame:
    """The recorded rows; one clear error when the file is not such a table."""
    rows = pd.read_csv(path)
    missing = [c for c in COLUMNS if c not in rows]
    if missing:
        raise ValueError(f"{path}: not a table of measured variants (missing columns: {', '.join(missing)})")
    unknown = sorted(set(rows.ingredient) - set(INGREDIENTS))
    if unknown:
        raise ValueError(f"{path}: unknown ingredient(s) {unknown}; expected one of {', '.join(INGREDIENTS)}")
    return rows[COLUMNS]


def record(path: str | Path, rows: pd.DataFrame) -> None:
    """Add one variant's rows to the file at ``path`` (written whole, atomically): a method measured again
    replaces its rows of that variant, another method joins them (so a variant's methods may be measured one run
    at a time); the variants keep their order."""
    if rows.variant.nunique() != 1:
        raise ValueError("record() takes the rows of one variant")
    if rows.ingredient.iloc[0] not in INGREDIENTS:
        raise ValueError(f"unknown ingredient {rows.ingredient.iloc[0]!r}; expected one of {', '.join(INGREDIENTS)}")
    path = Path(path)
    old = read(path) if path.is_file() else pd.DataFrame(columns=COLUMNS)
    measured = set(zip(rows.variant, rows.method))
    kept = old[[key not in measured for key in zip(old.variant, old.method)]]
    new = pd.concat([kept, rows[COLUMNS]], ignore_index=True) if len(kept) else rows[COLUMNS].reset_index(drop=True)
    order = list(dict.fromkeys([*old.variant, rows.variant.iloc[0]]))
    new = new.iloc[np.argsort([order.index(v) for v in new.variant], kind="stable")]
    with atomic_file(path) as tmp:
        new.to_csv(tmp, index=False, float_format="%.6f")


def scaling_points(rows: pd.DataFrame) -> pd.DataFrame:
    """The variants that differ from their family's first row in their maps alone: per family, method and split,
    the number of training maps (and episodes per map) against success and steps / optimum. A family's first row
    is the reference (its family) or a variant that changes only the family, with no relabelled rounds; a later
    variant of that family with the same maps and encoder (the same executor measured again after a change that
    leaves its encoder's name, ingredient ``encoder``) takes its place, so that the line starts from the latest
    measurement; the ``maps`` variants with that encoder make the rest of the line. A family measured at one map
    count has no line."""
    if not (rows.ingredient == "reference").any():
        return rows.iloc[:0]
    keep = []
    for _, d in rows[rows.relabel_rounds == 0].groupby("family", sort=False):
        first = d[d.ingredient.isin(["reference", "family"])]
        if first.empty:
            continue
        encoder, maps, episodes = first[["encoder", "train_layouts", "episodes_per_map"]].iloc[0]
        again = d[d.ingredient.isin(["reference", "family", "encoder"]) & (d.encoder == encoder)
                  & (d.train_layouts == maps) & (d.episodes_per_map == episodes)]
        line = d[(d.variant == again.variant.iloc[-1]) | ((d.ingredient == "maps") & (d.encoder == encoder))]
        if line.train_layouts.nunique() >= 2:  # (one map count makes no line)
            keep.append(line)
    return pd.concat(keep) if keep else rows.iloc[:0]


SPLITS = {"heldout": "held-out", "minigrid": "MiniGrid 8×8", "minigrid_16x16": "MiniGrid 16×16", "drawn": "hand-drawn"}
# the unseen splits, short names for the table's columns (report.py's SPLIT_LABELS are the long ones; it imports this
# module, which therefore cannot import it: tests/test_layers.py forbids the cycle)


def _label(method: str) -> str:
    return METHODS[method].label if method in METHODS else method


def _cell(success: float, ratio: float) -> str:
    if pd.isna(success):
        return "–"
    return f"{success:.3f}" + ("" if pd.isna(ratio) else f" ({ratio:.2f}×)")


def ablation_table(rows: pd.DataFrame) -> str:
    """Markdown: per variant and method, the validation measure and success (steps / optimum) on each unseen
    split, with the revision that measured it."""
    splits = [s for s in SPLITS if s in set(rows.split)]
    lines = ["| variant | ingredient | training maps × episodes | encoder | seeds | method | validation steps | "
             + " | ".join(SPLITS[s] for s in splits) + " | revision |",
             "|---" * (8 + len(splits)) + "|"]
    rank = {m: i for i, m in enumerate(dict.fromkeys([PROPOSED, *METHODS]))}  # HNSDT first, then the paper's order
    variants = list(dict.fromkeys(rows.variant))
    keys = sorted(dict.fromkeys(zip(rows.variant, rows.method)),
                  key=lambda k: (variants.index(k[0]), rank.get(k[1], len(rank))))
    for variant, method in keys:
        d = rows[(rows.variant == variant) & (rows.method == method)]
        r, by = d.iloc[0], d.set_index("split")
        cells = " | ".join(_cell(by.success.get(s), by.steps_ratio.get(s)) for s in splits)
        relabel = f", {r.relabel_rounds} relabelled round(s)" if r.relabel_rounds else ""
        validation = "–" if pd.isna(r.validation_steps) else f"{r.validation_steps:.1f}"
        lines.append(f"| {variant} | {r.ingredient} | {r.train_layouts:,} × {r.episodes_per_map} `{r.family}`{relabel} "
                     f"| {r.encoder} | {r.seeds} | {_label(method)} | "
                     f"{validation} | {cells} | `{r.revision}` |")
    return "\n".join(lines)


def scaling_figure(rows: pd.DataFrame, path: Path) -> bool:
    """Held-out and hand-drawn steps / optimum (left) and success (right) against the number of training maps,
    one line per family, method and split through the variant with the most episodes per map at each count
    (fewer episodes per map: hollow markers beside it; each point labelled with its episodes per map; the
    reference's family solid and dashed, another family dash-dotted, with its name). False (no figure) when no
    family was measured at two map counts."""
    points = scaling_points(rows)
    if points.empty:  # (scaling_points keeps only families measured at two map counts or more)
        return False
    reference, reference_encoder = rows[rows.ingredient == "reference"][["family", "encoder"]].iloc[0]
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.2))
    for (family, method, split), d in points[points.split.isin(["heldout", "drawn"])].groupby(
            ["family", "method", "split"], sort=False):
        d = d.sort_values(["train_layouts", "episodes_per_map"], kind="stable")
        most = d.groupby("train_layouts").episodes_per_map.transform("max") == d.episodes_per_map
        style = {"marker": "o" if split == "heldout" else "s", "linestyle": "-" if split == "heldout" else "--"}
        label = f"{_label(method)}, {SPLITS[split]}"
        if family != reference:  # (and its encoder where it is not the reference's)
            encoder = "" if d.encoder.iloc[0] == reference_encoder else f"; {d.encoder.iloc[0]}"
            style, label = {"marker": "^", "linestyle": "-."}, f"{label} ({family}{encoder})"
        for ax, column in zip(axes, ("steps_ratio", "success")):
            line, = ax.plot(d.train_layouts[most], d[column][most], label=label, **style)
            ax.plot(d.train_layouts[~most], d[column][~most], marker=style["marker"], linestyle="none",
                    markerfacecolor="none", color=line.get_color())  # fewer episodes per map: hollow, apart
            if column == "steps_ratio":
                for x, y, eps in zip(d.train_layouts, d[column], d.episodes_per_map):
                    ax.annotate(f"{eps}/map", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7,
                                color=line.get_color())
    counts = sorted(set(points.train_layouts))
    for ax, title in zip(axes, ("steps / optimum (successful episodes)", "success rate")):
        ax.set_xscale("log")
        ax.set_xticks(counts, [f"{c:,}" for c in counts])
        ax.minorticks_off()
        ax.set_xlim(counts[0] / 1.5, counts[-1] * 1.5)
        ax.set_xlabel("training maps")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].axhline(1.10, color="k", lw=0.8, ls=":")
    axes[1].axhline(0.95, color="k", lw=0.8, ls=":")
    axes[1].set_ylim(0, 1.05)
    axes[1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))  # (beside: the lines fill the axes)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")  # (the legend beside the axes)
    plt.close(fig)
    return True


def ablation_context(path: str | Path, figure: Path) -> dict:
    """The report's section on measured variants (empty when the file does not exist)."""
    if not Path(path).is_file():
        return {"ablations": ""}
    rows = read(path)
    rows = rows[rows.method.isin(LEARNED)]  # (the planner with hand-written controllers is the same in every one)
    return {"ablations": ablation_table(rows), "ablations_file": str(path),
            "ablations_scaling": scaling_figure(rows, figure),
            "ablations_revisions": sorted(set(rows.revision))}
