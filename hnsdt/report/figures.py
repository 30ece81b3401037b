"""The paper protocol's figures: the environments, success / steps / reward against the failure probability, the
paradigms, the success heatmap and the regret."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from hnsdt.core.methods import METHODS, PARADIGMS  # noqa: E402
from hnsdt.report.common import METRICS, label, methods_in, line_style  # noqa: E402


def environment_figure(envs: dict, path: Path) -> None:
    """The paper's Figures 2 and 3, drawn from the layout files: walls, keys, doors, items, start and exit."""
    from hnsdt.envs.render import COLOURS, render_rgb, symbol_grid
    from hnsdt.symbolic.abstraction import SymbolicState

    px = 40
    fig, axes = plt.subplots(1, len(envs), figsize=(4.4 * len(envs), 5.2), squeeze=False)
    for ax, (name, env) in zip(axes[0], envs.items()):
        layout = env.layout
        state = SymbolicState.initial(layout).to_observation(layout)
        ax.imshow(render_rgb(layout, state, px))
        for r, row in enumerate(symbol_grid(layout, state)):
            for c, ch in enumerate(row):
                mark = {"@": "S", "G": "G"}.get(ch, ch if ch not in ".#" else "")
                if mark:
                    ax.text(c * px + px / 2, r * px + px / 2, mark, ha="center", va="center", fontsize=11,
                            fontweight="bold", color="white" if ch == "@" else "black")
        h, w = layout.shape
        ax.set_xticks(np.arange(w) * px + px / 2, range(w))
        ax.set_yticks(np.arange(h) * px + px / 2, range(h))
        ax.set_title(f"{name}: {h}×{w}, {len(layout.keys)} key(s), {len(layout.doors)} door(s), "
                     f"{len(layout.items)} item(s)", fontsize=10)
    handles = [plt.Rectangle((0, 0), 1, 1, color=np.array(COLOURS[k]) / 255) for k in
               ("wall", "floor", "key", "door_closed", "item", "goal", "agent")]
    fig.legend(handles, ["wall", "floor", "key (a, b, …)", "locked door (A, B, …)", "item (1, 2, …)", "exit (G)",
                         "agent at the start (S)"], loc="lower center", ncol=4, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.13, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def comparison_figure(summ: pd.DataFrame, path: Path) -> None:
    envs = list(dict.fromkeys(summ.env))
    fig, axes = plt.subplots(len(METRICS), len(envs), figsize=(5 * len(envs), 9), squeeze=False)
    for j, env in enumerate(envs):
        for i, (metric, title) in enumerate(METRICS):
            ax = axes[i, j]
            methods = methods_in(summ)
            for k, method in enumerate(methods):
                d = summ[(summ.env == env) & (summ.method == method)].sort_values("fail_prob")
                st = line_style(k, len(methods))
                ax.errorbar(d.fail_prob + st.pop("offset"), d[f"{metric}_mean"], yerr=d[f"{metric}_std"],
                            label=label(method), **st)
            ax.set_title(f"{env}: {title}")
            ax.set_xlabel("action failure probability")
            ax.grid(alpha=0.3)
            if metric == "success":
                ax.set_ylim(-0.05, 1.05)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def paradigm_table(summ: pd.DataFrame) -> pd.DataFrame:
    """Per env × method: success and reward averaged over the failure probabilities, with the paradigm."""
    g = summ.groupby(["env", "method"])
    out = g.agg(success=("success_mean", "mean"), success_std=("success_std", "mean"),
                reward=("reward_mean", "mean"), reward_std=("reward_std", "mean")).reset_index()
    out["paradigm"] = [METHODS[m].paradigm if m in METHODS else "other" for m in out.method]
    return out


def paradigm_figure(summ: pd.DataFrame, path: Path) -> None:
    """The paper's comparison by architectural paradigm: bars per method, grouped by paradigm, per env."""
    table = paradigm_table(summ)
    envs = list(dict.fromkeys(summ.env))
    methods = methods_in(summ)
    paradigms = [p for p in PARADIGMS if p in set(table.paradigm)] + sorted(set(table.paradigm) - set(PARADIGMS))
    colors = dict(zip(PARADIGMS, plt.get_cmap("tab10").colors))
    fig, axes = plt.subplots(2, len(envs), figsize=(6 * len(envs), 7), squeeze=False)
    for j, env in enumerate(envs):
        for i, (metric, title) in enumerate((("success", "success rate"), ("reward", "average reward"))):
            ax, x, ticks, labels = axes[i, j], 0.0, [], []
            for paradigm in paradigms:
                members = [m for m in methods if (METHODS[m].paradigm if m in METHODS else "other") == paradigm]
                start = x
                for m in members:
                    r = table[(table.env == env) & (table.method == m)]
                    if r.empty:
                        continue
                    ax.bar(x, r[metric].iloc[0], yerr=r[f"{metric}_std"].iloc[0], capsize=3, width=0.8,
                           color=colors.get(paradigm, "grey"), edgecolor="k", linewidth=0.5)
                    ax.text(x, r[metric].iloc[0], f"{r[metric].iloc[0]:.2f}", ha="center",
                            va="bottom" if r[metric].iloc[0] >= 0 else "top", fontsize=7)
                    ticks.append(x)
                    labels.append(label(m))
                    x += 1
                if x > start:
                    ax.axvspan(start - 0.5, x - 0.5, color=colors.get(paradigm, "grey"), alpha=0.07)
                    ax.text((start + x - 1) / 2, 1.02, paradigm, transform=ax.get_xaxis_transform(), ha="center",
                            fontsize=8)
                x += 0.6
            ax.set_xticks(ticks, labels, rotation=35, ha="right", fontsize=8)
            ax.set_title(f"{env}: {title}, mean over failure probabilities", pad=16)
            ax.grid(axis="y", alpha=0.3)
            if metric == "success":
                ax.set_ylim(0, 1.1)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def heatmap_figure(summ: pd.DataFrame, path: Path) -> None:
    methods = methods_in(summ)
    cols = sorted({(e, f) for e, f in zip(summ.env, summ.fail_prob)}, key=lambda ef: (list(summ.env).index(ef[0]),
                                                                                       ef[1]))
    grid = np.full((len(methods), len(cols)), np.nan)
    for r in summ.itertuples():
        grid[methods.index(r.method), cols.index((r.env, r.fail_prob))] = r.success_mean
    fig, ax = plt.subplots(figsize=(1.2 * len(cols) + 2, 0.7 * len(methods) + 1.5))
    im = ax.imshow(grid, cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(cols)), [f"{e}\n{f:g}" for e, f in cols])
    ax.set_yticks(range(len(methods)), [label(m) for m in methods])
    for (i, j), v in np.ndenumerate(grid):
        if not np.isnan(v):
            ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=9)
    ax.set_title("success rate by method x (environment, failure probability)")
    fig.colorbar(im, ax=ax, fraction=0.03)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def regret_figure(summ: pd.DataFrame, path: Path) -> None:
    envs = list(dict.fromkeys(summ.env))
    fig, axes = plt.subplots(1, len(envs), figsize=(5 * len(envs), 3.8), squeeze=False)
    for j, env in enumerate(envs):
        ax = axes[0, j]
        methods = methods_in(summ)
        for k, method in enumerate(methods):
            d = summ[(summ.env == env) & (summ.method == method)].sort_values("fail_prob")
            st = line_style(k, len(methods))
            ax.errorbar(d.fail_prob + st.pop("offset"), d.regret, yerr=d.reward_std, label=label(method), **st)
        ax.set_title(f"{env}: regret V* - V^pi (expected return)")
        ax.set_xlabel("action failure probability")
        ax.axhline(0, color="k", lw=0.8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
