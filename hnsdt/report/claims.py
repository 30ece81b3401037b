"""Agreement with the paper's claims (``paper_claims.yaml``): each claim checked against our measurements, with
bootstrap intervals over the seeds."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from hnsdt.core.methods import METHODS, PAPER_ARM
from hnsdt.report.common import METHOD_LABELS, label
from hnsdt.report.figures import paradigm_table


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
    lines += [f"| {r.env} | {label(r.method)} | {r.solved} of {r.seeds} | {r.success:.3f} | "
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

    def label(method: str) -> str:
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
        rows.append({"claim": f"{label(p['method'])} {p['metric']} on {p['env']} at fail_prob {p['fail_prob']:g}",
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
            rows.append({"claim": f"{label(method)} collapses to near-zero success on {col['env']} at fail_prob "
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
            rows.append({"claim": f"{label(method)} is intermediate on {env} at fail_prob {fp:g} (between "
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
