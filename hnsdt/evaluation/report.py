"""The report stage: matplotlib figures and a ``report.md`` that traces every figure to its inputs.

Each figure is listed with the git revision, a digest of the params and the md5 of every dataset and model it
came from, as recorded in ``dvc.lock`` by the stages that produced them.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import yaml  # noqa: E402

from hnsdt.core.fileio import atomic_dir  # noqa: E402
from hnsdt.core.params import Params  # noqa: E402
from hnsdt.core.methods import METHODS, PAPER_ARM, PARADIGMS, PROPOSED  # noqa: E402
from hnsdt.core.provenance import git_revision, params_digest  # noqa: E402

METHOD_LABELS = {name: m.label for name, m in METHODS.items()}
METRICS = [("success", "success rate"), ("steps", "steps (successful episodes)"), ("reward", "average reward")]
STYLES = [("o", "-"), ("s", "--"), ("^", ":"), ("D", "-."), ("v", "-"), ("P", "--"), ("X", ":")]


def _style(i: int, n: int) -> dict:
    """Distinct marker and line per method, and a small x offset so identical curves stay visible."""
    marker, line = STYLES[i % len(STYLES)]
    return {"marker": marker, "linestyle": line, "capsize": 3, "offset": 0.004 * (i - (n - 1) / 2)}


def lock_outputs(lock_path: str | Path = "dvc.lock") -> dict[str, str]:
    """{output path: md5} for every stage output recorded in dvc.lock (datasets, models)."""
    path = Path(lock_path)
    if not path.is_file():
        return {}
    lock = yaml.safe_load(path.read_text()) or {}
    outs = {}
    for stage in (lock.get("stages") or {}).values():
        for out in stage.get("outs", []) or []:
            outs[out["path"]] = out.get("md5", "?")
    return outs


def render_template(name: str, **context) -> str:
    """A template of ``hnsdt/evaluation/templates`` filled with ``context``; an unknown name in the template is
    an error, not an empty string."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).with_name("templates")),
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                             keep_trailing_newline=True, autoescape=False)
    return env.get_template(name).render(**context)


def _label(method: str) -> str:
    return METHOD_LABELS.get(method, method)


def trained_seeds(summ: pd.DataFrame) -> str:
    """How many training seeds the learned methods of a summary ran: "2 seeds", or "5 seeds for HNSDT (ours),
    2 for the others" where they differ (``generalisation.method_seeds``)."""
    learned = summ[summ.method.map(lambda m: m not in METHODS or METHODS[m].training != "none")]
    counts = learned.groupby("method", sort=False).seeds.max()
    usual = int(counts.mode().max())

    def n(k: int) -> str:
        return f"{k} seed{'s' if k != 1 else ''}"

    odd = counts[counts != usual]
    other = [f"{n(int(k))} for {' and '.join(_label(m) for m in ms.index)}" for k, ms in odd.groupby(odd, sort=False)]
    return ", ".join([*other, f"{usual} for the others"]) if other else n(usual)


def _methods(summ: pd.DataFrame) -> list[str]:
    """Methods in the paper's order (by paradigm), unknown names last."""
    present = set(summ.method)
    return [m for m in METHODS if m in present] + sorted(present - set(METHODS))


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
                label = {"@": "S", "G": "G"}.get(ch, ch if ch not in ".#" else "")
                if label:
                    ax.text(c * px + px / 2, r * px + px / 2, label, ha="center", va="center", fontsize=11,
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
            methods = _methods(summ)
            for k, method in enumerate(methods):
                d = summ[(summ.env == env) & (summ.method == method)].sort_values("fail_prob")
                st = _style(k, len(methods))
                ax.errorbar(d.fail_prob + st.pop("offset"), d[f"{metric}_mean"], yerr=d[f"{metric}_std"],
                            label=_label(method), **st)
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
    methods = _methods(summ)
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
                    labels.append(_label(m))
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
    methods = _methods(summ)
    cols = sorted({(e, f) for e, f in zip(summ.env, summ.fail_prob)}, key=lambda ef: (list(summ.env).index(ef[0]),
                                                                                       ef[1]))
    grid = np.full((len(methods), len(cols)), np.nan)
    for r in summ.itertuples():
        grid[methods.index(r.method), cols.index((r.env, r.fail_prob))] = r.success_mean
    fig, ax = plt.subplots(figsize=(1.2 * len(cols) + 2, 0.7 * len(methods) + 1.5))
    im = ax.imshow(grid, cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(cols)), [f"{e}\n{f:g}" for e, f in cols])
    ax.set_yticks(range(len(methods)), [_label(m) for m in methods])
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
        methods = _methods(summ)
        for k, method in enumerate(methods):
            d = summ[(summ.env == env) & (summ.method == method)].sort_values("fail_prob")
            st = _style(k, len(methods))
            ax.errorbar(d.fail_prob + st.pop("offset"), d.regret, yerr=d.reward_std, label=_label(method), **st)
        ax.set_title(f"{env}: regret V* - V^pi (expected return)")
        ax.set_xlabel("action failure probability")
        ax.axhline(0, color="k", lw=0.8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(v, spec=".3f", dash="–"):
    return dash if pd.isna(v) else format(v, spec)


def _table(summ: pd.DataFrame) -> str:
    order = {m: i for i, m in enumerate(_methods(summ))}
    summ = summ.sort_values(["env", "method", "fail_prob"], key=lambda c: c.map(order) if c.name == "method" else c)
    lines = ["| env | method | fail_prob | success | steps (success) | reward | success / opt | steps / opt | "
             "regret |", "|---|---|---|---|---|---|---|---|---|"]
    for r in summ.itertuples():
        steps = "–" if pd.isna(r.steps_mean) else f"{r.steps_mean:.1f} ± {r.steps_std:.1f}"
        lines.append(f"| {r.env} | {_label(r.method)} | {r.fail_prob:g} | {r.success_mean:.3f} ± "
                     f"{r.success_std:.3f} | {steps} | {r.reward_mean:.3f} ± {r.reward_std:.3f} | "
                     f"{_fmt(r.success_ratio)} | {_fmt(r.steps_ratio)} | {_fmt(r.regret)} |")
    return "\n".join(lines)


def _optimum_table(summ: pd.DataFrame) -> str:
    cells = summ.drop_duplicates(["env", "fail_prob"]).sort_values(["env", "fail_prob"])
    lines = ["| env | fail_prob | optimal success | optimal expected steps | optimal expected return |",
             "|---|---|---|---|---|"]
    lines += [f"| {r.env} | {r.fail_prob:g} | {r.opt_success:.4f} | {r.opt_steps:.2f} | {r.opt_reward:.3f} |"
              for r in cells.itertuples()]
    return "\n".join(lines)


def _target_lines(summ: pd.DataFrame) -> list[str]:
    """Issue 5's target for HNSDT: success >= 0.98 x optimal and steps <= 1.05 x optimal, in every cell."""
    rows = summ[summ.method == PROPOSED]
    if rows.empty:
        return []
    met = (rows.success_ratio >= 0.98) & (rows.steps_ratio <= 1.05)
    out = [f"HNSDT meets the target (success ≥ 0.98 × optimal and steps ≤ 1.05 × optimal) in {int(met.sum())} of "
           f"{len(rows)} env × fail_prob cells."]
    for r in rows[~met].itertuples():
        out.append(f"- misses at {r.env}, fail_prob {r.fail_prob:g}: success ratio {_fmt(r.success_ratio)}, "
                   f"steps ratio {_fmt(r.steps_ratio)}")
    return out


CLAIMS = Path(__file__).with_name("paper_claims.yaml")  # the paper's claims, as data


@lru_cache(maxsize=4)
def paper_claims(path: str | Path = CLAIMS) -> dict:
    """The claims file, read once (callers only read the mapping)."""
    return yaml.safe_load(Path(path).read_text())


def _cell(summ: pd.DataFrame, env: str, fail_prob: float, method: str, metric: str = "success"):
    r = summ[(summ.env == env) & (summ.method == method) & np.isclose(summ.fail_prob, fail_prob)]
    if r.empty:
        return None, None
    return r[f"{metric}_mean"].iloc[0], r[f"{metric}_std"].iloc[0]


SOLVED = 0.9  # a training seed "solves" an env when it succeeds in at least this share of its episodes
BOOTSTRAP = 10_000  # resamples of the seeds for the confidence intervals


def seed_view(episodes: pd.DataFrame, seed: int = 0) -> pd.DataFrame:
    """Per env × method: how many training seeds solve the env (success ≥ SOLVED over all its episodes, every
    fail_prob) and a 95% percentile-bootstrap interval, over seeds, of the mean success. With few seeds an
    online learner's mean hides a bimodal outcome; this says it in seeds, not in a mean."""
    rng = np.random.default_rng(seed)
    per_seed = episodes.groupby(["env", "method", "seed"], sort=True).success.mean().reset_index()
    rows = []
    for (env, method), g in per_seed.groupby(["env", "method"], sort=True):
        x = g.success.to_numpy(np.float64)
        means = x[rng.integers(0, len(x), (BOOTSTRAP, len(x)))].mean(axis=1)
        rows.append({"env": env, "method": method, "seeds": len(x), "solved": int((x >= SOLVED).sum()),
                     "success": float(x.mean()), "ci_low": float(np.quantile(means, 0.025)),
                     "ci_high": float(np.quantile(means, 0.975))})
    return pd.DataFrame(rows)


def _seeds_phrase(view: pd.DataFrame | None, env: str, method: str) -> str:
    if view is None or view.empty:
        return ""
    r = view[(view.env == env) & (view.method == method)]
    if r.empty:
        return ""
    r = r.iloc[0]
    return (f"; solves it in {r.solved} of {r.seeds} seeds, mean over seeds {r.success:.3f}, "
            f"95% bootstrap CI [{r.ci_low:.3f}, {r.ci_high:.3f}]")


def seed_lines(view: pd.DataFrame) -> list[str]:
    lines = [f"| env | method | seeds that solve it (≥ {SOLVED:g} success) | mean success over seeds | "
             "95% bootstrap CI over seeds |", "|---|---|---|---|---|"]
    order = {m: i for i, m in enumerate(METHODS)}
    view = view.sort_values(["env", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    lines += [f"| {r.env} | {_label(r.method)} | {r.solved} of {r.seeds} | {r.success:.3f} | "
              f"[{r.ci_low:.3f}, {r.ci_high:.3f}] |" for r in view.itertuples()]
    return lines


def arm_table(table: pd.DataFrame, arm: str) -> pd.DataFrame:
    """The rows of one arm's comparison: the shared baselines plus that arm's transformers, which take the
    names of ours (``hnsdt``, ``pure_dt``) so that the paper's claims read the same for both arms."""
    ours = table.method.map(lambda m: METHODS[m].arm == "ours")  # the paper arm's floor is no claim's subject
    if arm == "ours":
        return table[ours]
    rename = {paper: ours for ours, paper in PAPER_ARM.items()}
    kept = table[(ours & ~table.method.isin(PAPER_ARM.keys())) | table.method.isin(PAPER_ARM.values())]
    return kept.assign(method=kept.method.map(lambda m: rename.get(m, m)))


def claim_lines(summ: pd.DataFrame, view: pd.DataFrame | None = None, arm: str = "ours"
                ) -> tuple[list[str], list[dict]]:
    """Where our measurements agree or disagree with the paper's claims, one row per claim. A point value
    agrees when ours lies within ``within_std`` of the paper's standard deviations of the paper's mean
    (``paper_claims.yaml``). Claims about
    learners whose seeds disagree also say how many seeds solve the env (``view``, from :func:`seed_view`).
    ``arm`` picks whose HNSDT and pure DT the claims are about: ours or the paper's build (:func:`arm_table`)."""
    summ = arm_table(summ, arm)
    view = arm_table(view, arm) if view is not None else None
    paper_names = PAPER_ARM if arm == "paper" else {}

    def _label(method: str) -> str:
        return METHOD_LABELS.get(paper_names.get(method, method), method)

    claims = paper_claims()
    near_zero, within = claims["near_zero"], claims["within_std"]
    rows = []
    for p in claims["points"]:
        ours, ours_std = _cell(summ, p["env"], p["fail_prob"], p["method"], p["metric"])
        if ours is None:
            continue
        unit = "%" if p["metric"] == "success" else " steps"
        scale = 100 if p["metric"] == "success" else 1
        verdict = ("no successful episode to compare" if pd.isna(ours)
                   else "agrees" if abs(ours - p["mean"]) <= within * p["std"]
                   else f"disagrees: ours is {'higher' if ours > p['mean'] else 'lower'}")
        rows.append({"claim": f"{_label(p['method'])} {p['metric']} on {p['env']} at fail_prob {p['fail_prob']:g}",
                     "paper": f"{p['mean'] * scale:.0f} ± {p['std'] * scale:.0f}{unit}",
                     "ours": "–" if pd.isna(ours) else f"{ours * scale:.1f} ± {ours_std * scale:.1f}{unit}",
                     "verdict": verdict})
    best = claims["best_everywhere"]
    strict = tied = beaten = 0
    for _, c in summ.groupby(["env", "fail_prob"]):
        h = c[c.method == best["method"]].success_mean
        others = c[c.method != best["method"]].success_mean
        if h.empty or others.empty:
            continue
        best_other = others.max()
        strict += int(h.iloc[0] > best_other + 1e-9)
        tied += int(abs(h.iloc[0] - best_other) <= 1e-9)
        beaten += int(h.iloc[0] < best_other - 1e-9)
    if strict + tied + beaten:
        rows.append({"claim": best["claim"], "paper": best["paper"],
                     "ours": f"strictly best in {strict}, tied for best in {tied}, beaten in {beaten} of "
                             f"{strict + tied + beaten} cells",
                     "verdict": "agrees" if tied == beaten == 0 else
                     ("partly: never beaten, but tied" if beaten == 0 else "disagrees")})
    for a in claims["above"]:
        ours, _ = _cell(summ, a["env"], a["fail_prob"], a["method"])
        if ours is not None:
            rows.append({"claim": a["claim"], "paper": f"> {a['value']:g}", "ours": f"{ours:.3f}",
                         "verdict": "agrees" if ours > a["value"] else "disagrees"})
    col = claims["collapse"]
    for method in col["methods"]:
        ours, _ = _cell(summ, col["env"], col["fail_prob"], method)
        if ours is not None:
            rows.append({"claim": f"{_label(method)} collapses to near-zero success on {col['env']} at fail_prob "
                                  f"{col['fail_prob']:g}",
                         "paper": f"near zero (we read ≤ {near_zero:g})",
                         "ours": f"{ours:.3f}{_seeds_phrase(view, col['env'], method)}",
                         "verdict": "agrees" if ours <= near_zero else "disagrees"})
    mid = claims["intermediate"]
    env, fp = mid["env"], mid["fail_prob"]
    low = [v for m in mid["low"] if (v := _cell(summ, env, fp, m)[0]) is not None]
    high, _ = _cell(summ, env, fp, mid["high"])
    for method in mid["methods"]:
        ours, _ = _cell(summ, env, fp, method)
        if ours is not None and low and high is not None:
            inside = max(low) < ours < high
            rows.append({"claim": f"{_label(method)} is intermediate on {env} at fail_prob {fp:g} (between "
                                  f"{mid['low_name']} and {mid['high_name']})", "paper": "intermediate",
                         "ours": f"{ours:.3f} ({mid['low_name']} best {max(low):.3f}, {mid['high_name']} "
                                 f"{high:.3f}){_seeds_phrase(view, env, method)}",
                         "verdict": "agrees" if inside else "disagrees"})
    top_paradigm = claims["best_paradigm"]
    table = paradigm_table(summ)
    for env in dict.fromkeys(summ.env):
        t = table[table.env == env]
        best = t.groupby("paradigm").success.max()
        if top_paradigm in best:
            top = best[best >= best.max() - 1e-9].index.tolist()
            rows.append({"claim": f"the {top_paradigm} paradigm has the highest success on {env} (mean over "
                                  "fail_prob, best method of each paradigm)", "paper": "yes",
                         "ours": ", ".join(f"{p} {v:.3f}" for p, v in best.sort_values(ascending=False).items()),
                         "verdict": "agrees" if top == [top_paradigm] else
                         ("partly: tied with " + ", ".join(p for p in top if p != top_paradigm)
                          if top_paradigm in top else "disagrees")})
    lines = ["| claim (paper, Section 5) | paper | ours | verdict |", "|---|---|---|---|"]
    lines += [f"| {r['claim']} | {r['paper']} | {r['ours']} | {r['verdict']} |" for r in rows]
    return lines, rows


def paper_arm_lines(summ: pd.DataFrame, results: Path) -> list[str]:
    """Both arms side by side (success, steps of successful episodes and their ratio to the exact optimum, per
    env × fail_prob), and where the paper's HNSDT's steps go (:func:`decomposition_lines`)."""
    planners = [name for name, m in METHODS.items() if m.training == "none"]  # the symbolic baseline
    methods = [m for m in (*planners, *[x for pair in PAPER_ARM.items() for x in pair]) if m in set(summ.method)]
    if not set(PAPER_ARM.values()) & set(methods):
        return []
    lines = ["| env | fail_prob | " + " | ".join(_label(m) for m in methods) + " |",
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
            cells.append(f"{r.success_mean:.3f} / {_fmt(r.steps_mean, '.1f')}{ratio}")
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
    lines = [f"Where the steps of {_label(method)} go, beside {_label(pair[1])} (the same planner, "
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
            lines.append(f"| {env} | {fp:g} | {_label(m)} | {r.steps:.1f} | "
                         + " | ".join(f"{r[c]:.2f}" for c in reasons) + " |")
    return lines


def usage_lines(results: Path) -> list[str]:
    """What each learned method trained on (mean over seeds): env steps (online) or dataset frames, the passes
    over its training data (epochs), gradient steps and, stopped by a validation measure, the epoch kept
    (offline)."""
    path = results / "training_usage.csv"
    if not path.is_file():
        return []
    u = pd.read_csv(path)
    if u.empty:
        return []
    for column in ("epochs", "epoch_kept"):
        if column not in u:
            u[column] = float("nan")
    lines = ["| env | method | trains on | environment steps | dataset frames | epochs | gradient steps | "
             "epoch kept |", "|---|---|---|---|---|---|---|---|"]
    order = {m: i for i, m in enumerate(METHODS)}
    g = u.groupby(["env", "method", "training"], as_index=False)[["env_steps", "dataset_frames", "epochs",
                                                                  "gradient_steps", "epoch_kept"]].mean()
    g = g.sort_values(["env", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    for r in g.itertuples():
        lines.append(f"| {r.env} | {_label(r.method)} | {'the environment' if r.training == 'online' else 'the dataset'}"
                     f" | {_fmt(r.env_steps, ',.0f')} | {_fmt(r.dataset_frames, ',.0f')} | "
                     f"{_fmt(r.epochs, '.1f')} | {_fmt(r.gradient_steps, ',.0f')} | {_fmt(r.epoch_kept, '.1f')} |")
    return lines


def _largest_informative_d(m: int, K: int, delta: float) -> float:
    """The largest VC-dimension proxy for which Theorem 2's bound is still above 0 (bisection)."""
    from hnsdt.evaluation.theorems import pac_bound

    if pac_bound(m, K, 1e-6, delta) <= 0:
        return 0.0
    lo, hi = 1e-6, float(max(m, 1))
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if pac_bound(m, K, mid, delta) > 0 else (lo, mid)
    return lo


def theorem_sections(params: Params, results: Path, summ: pd.DataFrame, episodes: pd.DataFrame) -> tuple[dict, dict]:
    """The two theorems checked on the measurements: the template's context for their sections (empty when
    the inputs are missing) and their rows for ``theorems.json``."""
    from hnsdt.core.config import env_spec
    from hnsdt.evaluation.theorems import theorem1, theorem2
    from hnsdt.envs.oracle import optimum

    if not (results / "segments.csv").is_file() or "regret" not in summ or params.theorems is None:
        return {}, {}
    ts = params.theorems.model_dump()
    segments = pd.read_csv(results / "segments.csv")
    envs = {e: env_spec(params, e) for e in sorted(set(segments.env))}
    counts = pd.read_csv(results / "training_segments.csv")
    n_params = json.loads((results / "model_parameters.json").read_text())
    v_star = {(env, f): optimum(envs[env].layout, f, envs[env].max_steps, ts["gamma"]).ret
              for env, f in set(zip(segments.env, segments.fail_prob))}
    t1 = theorem1(segments, episodes, v_star, ts["gamma"], ts["B"])
    t2_parts = []
    for env in sorted(set(segments.env)):
        d = n_params.get(f"{env}/{PROPOSED}", float("nan")) if ts["vc_dimension"] == "parameters" else ts["vc_dimension"]
        part = theorem2(segments[segments.env == env], episodes, counts, float(d), ts["delta"])
        part["d_max_informative"] = [_largest_informative_d(r.m, r.K, ts["delta"]) for r in part.itertuples()]
        t2_parts.append(part)
    t2 = pd.concat(t2_parts, ignore_index=True) if t2_parts else pd.DataFrame()
    t1_lines = ["| env | fail_prob | ε_sym | ε_exec | ρ | bound | V*_γ | V^HNSDT_γ | measured regret | holds | "
                "bound / measured |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    t1_lines += [f"| {r.env} | {r.fail_prob:g} | {r.eps_sym:.3f} | {r.eps_exec:.4f} | {r.rho:.3f} | {r.bound:.2f} | "
                 f"{r.v_star:.4f} | {r.v_method:.4f} | {r.measured_regret:.4f} | {'yes' if r.holds else 'NO'} | "
                 f"{_fmt(r.looseness, '.0f')} |" for r in t1.itertuples()]
    t2_lines = ["| env | fail_prob | m | K | d | PAC lower bound | measured | holds | largest d with a bound > 0 |",
                "|---|---|---|---|---|---|---|---|---|"]
    t2_lines += [f"| {r.env} | {r.fail_prob:g} | {r.m} | {r.K} | {r.d:.0f} | {_fmt(r.bound)} | {r.measured:.3f} | "
                 f"{'yes' if r.holds else 'NO'} | {r.d_max_informative:.2f} |" for r in t2.itertuples()]
    context = {"gamma": f"{ts['gamma']:g}", "B": f"{ts['B']:g}", "delta": f"{ts['delta']:g}",
               "d_name": ("the number of HNSDT parameters" if ts["vc_dimension"] == "parameters"
                          else ts["vc_dimension"]),
               "theorem1": t1_lines, "theorem1_holds": int(t1.holds.sum()), "theorem1_cells": len(t1),
               "theorem2": t2_lines}
    data = {"theorem1": t1.to_dict(orient="records"), "theorem2": t2.to_dict(orient="records")}
    return context, data


SPLIT_LABELS = {"train": "training layouts", "heldout": "held-out layouts", "minigrid": "MiniGrid grids",
                "minigrid_16x16": "MiniGrid 16 × 16 grids", "drawn": "hand-drawn maps"}
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
    lines = ["| split | sub-goal | " + " | ".join(f"{h}: {_label(m)}" for m in pair
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
        ax.set_xticks(x + width * (len(splits) - 1) / 2, [_label(m) for m in methods], rotation=25, ha="right",
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
    methods = _methods(d)
    lines = ["| map | " + " | ".join(_label(m) for m in methods) + " | HNSDT steps / opt |",
             "|---|" + "---|" * (len(methods) + 1)]
    for layout, m in d.groupby("layout", sort=False):
        success = m.groupby("method").success.mean()
        won = m[(m.method == PROPOSED) & m.success]
        ratio = (won.steps / won.optimal_steps).mean() if len(won) else np.nan
        lines.append(f"| `{Path(layout).stem}` | " + " | ".join(_fmt(success.get(x)) for x in methods)
                     + f" | {_fmt(ratio, '.2f')} |")
    return "\n".join(lines)


def _split_table(table: pd.DataFrame) -> list[str]:
    """The markdown rows of :func:`generalisation_table`: per method, success ± std and steps / optimum on each
    split, and its held-out over its training success."""
    splits = list(dict.fromkeys(table.split))
    head = "| method | " + " | ".join(f"{SPLIT_LABELS.get(s, s)}: success | steps / opt" for s in splits)
    lines = [head + " | held-out / training success |", "|---" * (2 * len(splits) + 2) + "|"]
    for method in dict.fromkeys(table.method):
        d = table[table.method == method].set_index("split")
        cells = " | ".join(f"{_fmt(d.success.get(s))} ± {_fmt(d.success_std.get(s))} | {_fmt(d.steps_ratio.get(s), '.2f')}"
                           for s in splits)
        ratio = (d.success.get("heldout", np.nan) / d.success.get("train", np.nan)
                 if d.success.get("train", 0) > 0 else np.nan)
        lines.append(f"| {_label(method)} | {cells} | {_fmt(ratio, '.2f')} |")
    return lines


def experiment_contexts(params: Params, folder: Path) -> list[dict]:
    """The report's lines of each experiment of ``unseen_experiments``, from ``folder``/NAME/results: what it
    changes, its table (:func:`_split_table`) and HNSDT against the target (:func:`target_lines`); ``summary``
    holds its summary table (the headline's line)."""
    from hnsdt.core.config import layout_executor, unseen_experiment

    out = []
    for name, changes in params.unseen_experiments.items():
        results = Path(folder) / name / "results"
        if not (results / "summary.csv").is_file():
            raise FileNotFoundError(f"{results / 'summary.csv'}: no results of the unseen-layout experiment {name} "
                                    f"(run `dvc repro unseen_experiment@{name}`)")
        mine = unseen_experiment(params, name)
        summ = pd.read_csv(results / "summary.csv")
        written = {k: v if isinstance(v, str) else json.dumps(v) for k, v in changes.items()}  # as in YAML
        out.append({"name": name, "changes": ", ".join(f"`{k}: {v}`" for k, v in written.items()),
                    "family": mine.generalisation.family, "train": mine.generalisation.train_layouts,
                    "seeds": trained_seeds(summ), "operators": layout_executor(mine, PROPOSED).operators,
                    "results": str(results / "summary.csv"), "table": "\n".join(_split_table(generalisation_table(summ))),
                    "targets": target_lines(summ), "summary": summ})
    return out


def generalisation_context(params: Params, results: Path, figure: Path) -> dict:
    """The report's unseen-layout section: the figure, the table and per-fail_prob numbers."""
    from hnsdt.core.config import layout_executor

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
        detail.append(f"| {_label(method)} | {split} | " + " | ".join(
            f"{_fmt(d.success_mean.get(f))} ({_fmt(d.steps_ratio_mean.get(f), '.2f')}×)" for f in fps) + " |")
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


HEADLINE_SPLITS = ("heldout", "minigrid", "drawn")  # the unseen-layout splits in the headline (training maps:
#                                                     the report)


def headline_metrics(summ: pd.DataFrame, unseen: pd.DataFrame | None = None,
                     experiments: dict[str, pd.DataFrame] | None = None) -> dict:
    """The few numbers `dvc metrics show` and `dvc exp show` compare by default (the per-cell tables stay in
    ``results/`` and ``metrics/summary.csv``): per split (each paper env, each unseen-layout split) every method's
    success and HNSDT's steps / optimum, each the mean over the failure probabilities of the mean over seeds.
    The methods that learn nothing (the planners with hand-written controllers, at 1.000 in every cell here) are
    left to the report, so that the headline stays at about 40 numbers. Short keys (``keydoor.hnsdt``), so that
    `dvc exp show --only-changed` fits a terminal."""
    def mean(values: pd.Series) -> float | None:
        return None if values.isna().all() else round(float(values.mean()), 4)

    splits = [(env, summ[summ.env == env], "steps_ratio") for env in dict.fromkeys(summ.env)]
    if unseen is not None:
        splits += [(split, unseen[unseen.split == split], "steps_ratio_mean") for split in HEADLINE_SPLITS]
    for name, d in (experiments or {}).items():  # further experiments: their held-out maps
        splits.append((f"{name}.heldout", d[d.split == "heldout"], "steps_ratio_mean"))
    out = {}
    for name, d, ratio_column in splits:
        if len(d):
            out[name] = {m: mean(d[d.method == m].success_mean) for m in _methods(d) if METHODS[m].training != "none"}
            ratio = mean(d[d.method == PROPOSED][ratio_column]) if ratio_column in d else None
            if ratio is not None:
                out[name][f"{PROPOSED}_steps_ratio"] = ratio
    return out


def write_report(params: Params, results: Path, out: Path, lock_path: str | Path = "dvc.lock",
                 generalisation: Path | None = None, headline: Path | None = None,
                 ablations: Path | None = None, experiments: Path | None = None) -> Path:
    """``generalisation``: the unseen-layout experiment's results folder (its section is left out without one);
    ``experiments``: the folder of the further ones (``unseen_experiments``: each in ``experiments``/NAME);
    ``headline``: where to write :func:`headline_metrics` as JSON; ``ablations``: the measured variants of that
    experiment (:mod:`hnsdt.evaluation.ablations`; its table and scaling figure are left out without one)."""
    summary_path = results / "summary.csv"
    if not summary_path.is_file():
        raise FileNotFoundError(f"{summary_path}: no evaluation summary (run `dvc repro evaluate`)")
    summ = pd.read_csv(summary_path)
    episodes = pd.read_csv(results / "episodes.csv")
    episodes[["rrd", "mcap"]] = episodes[["rrd", "mcap"]].fillna("")  # recording paths: empty when not recorded
    with atomic_dir(out) as tmp:
        (tmp / "figures").mkdir(parents=True)
        from hnsdt.core.config import env_spec

        layouts = {e: env_spec(params, e) for e in dict.fromkeys(summ.env)}
        environment_figure(layouts, tmp / "figures" / "environments.png")
        comparison_figure(summ, tmp / "figures" / "comparison.png")
        heatmap_figure(summ, tmp / "figures" / "success_heatmap.png")
        paradigm_figure(summ, tmp / "figures" / "paradigms.png")
        view = seed_view(episodes)
        claims, claim_rows = claim_lines(summ, view)
        paper_claims_lines, paper_claim_rows = claim_lines(summ, view, arm="paper")
        arms = paper_arm_lines(summ, results)
        usage = usage_lines(results)
        has_optimum = "regret" in summ
        if has_optimum:
            regret_figure(summ, tmp / "figures" / "regret.png")
        outs = lock_outputs(lock_path)
        inputs = {p: md5 for p, md5 in sorted(outs.items())
                  if p.startswith(("data/", "models/", "generalisation/dataset", "generalisation/models/"))}
        unseen = {}
        if generalisation is not None:
            if not (generalisation / "summary.csv").is_file():
                raise FileNotFoundError(f"{generalisation / 'summary.csv'}: no results of the unseen-layout "
                                        "experiment (run `dvc repro evaluate_generalisation`)")
            unseen = generalisation_context(params, generalisation, tmp / "figures" / "generalisation.png")
        variants = {"ablations": ""}  # (a part of the unseen-layout section: shown with it)
        if ablations is not None and unseen:
            from hnsdt.evaluation.ablations import ablation_context

            if not ablations.is_file():
                raise FileNotFoundError(f"{ablations}: no measured variants (benchmarks/generalisation.py --record)")
            variants = ablation_context(ablations, tmp / "figures" / "scaling.png")
        further = experiment_contexts(params, experiments) if experiments is not None and unseen else []
        envs, methods = sorted(set(summ.env)), sorted(set(summ.method))
        rev, digest = git_revision(), params_digest(params)
        recorded = episodes[episodes.rrd != ""]
        theorem_text, theorem_data = theorem_sections(params, results, summ, episodes)
        paper_pure_dt = [m for m in PAPER_ARM.values() if m != PAPER_ARM[PROPOSED]]
        numbers = summ if has_optimum else summ.assign(success_ratio=np.nan, steps_ratio=np.nan, regret=np.nan)
        text = render_template(
            "report.md.j2", **({"theorem1": []} | theorem_text),
            methods=[_label(m) for m in methods], envs=envs, seeds=int(summ.seeds.max()),
            fail_probs=[f"{f:g}" for f in sorted(set(summ.fail_prob))],
            episodes_per_cell=int(episodes.groupby(["method", "env", "fail_prob", "seed"]).size().max()),
            revision=rev, digest=digest, inputs=inputs, paradigms=PARADIGMS,
            optimum=_optimum_table(summ) if has_optimum else "",
            target=_target_lines(summ) if has_optimum else [],
            claims=claims if len(claims) > 2 else [], within_std=paper_claims()["within_std"],
            arms=arms, paper_claims=paper_claims_lines, paper_hnsdt=_label(PAPER_ARM[PROPOSED]),
            paper_pure_dt=", ".join(_label(m) for m in paper_pure_dt),
            seeds_table=seed_lines(view), solved=f"{SOLVED:.0%}", bootstrap=f"{BOOTSTRAP:,}", usage=usage,
            numbers=_table(numbers), recorded=len(recorded),
            example_episode=recorded.episode_id.iloc[0] if len(recorded) else "",
            generalisation=bool(unseen), **unseen, **variants, experiments=further)
        (tmp / "report.md").write_text(text)
        theorem_data = {**theorem_data, "claims": claim_rows} if claim_rows else theorem_data
        if paper_claim_rows and arms:
            theorem_data["claims_paper_arm"] = paper_claim_rows
        if theorem_data:
            (tmp / "theorems.json").write_text(json.dumps(theorem_data, indent=2, sort_keys=True, default=float) + "\n")
        (tmp / "provenance.json").write_text(json.dumps(
            {"git_revision": rev, "params_digest": digest, "inputs": inputs}, indent=2, sort_keys=True) + "\n")
        if headline is not None:
            from hnsdt.core.fileio import atomic_file

            unseen_summary = pd.read_csv(generalisation / "summary.csv") if generalisation is not None else None
            further_summaries = {e["name"]: e["summary"] for e in further}
            with atomic_file(headline) as tmp_headline:
                tmp_headline.write_text(json.dumps(headline_metrics(summ, unseen_summary, further_summaries),
                                                   indent=2) + "\n")
    return out / "report.md"
