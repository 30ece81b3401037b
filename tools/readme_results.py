"""The results tables of the README and docs/results.md, generated from the files of the run that git keeps: the
README's headline from `metrics/headline/` (a file per split), the per-cell table of docs/results.md from the
evaluation summary (`metrics/summary.csv`).

Usage: python tools/readme_results.py [--check]
Rewrites the tables between the `<!-- headline:begin -->` / `<!-- headline:end -->` markers of README.md and the
`<!-- results:begin -->` / `<!-- results:end -->` markers of docs/results.md, or with --check exits 1 (one line)
when a table is not the one the committed files give. ``tests/test_readme.py`` runs the check, so neither page
can silently disagree with the run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hnsdt.core.methods import METHODS  # noqa: E402
from hnsdt.report.headline import read_headline  # noqa: E402

BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
HEADLINE = "<!-- headline:begin -->", "<!-- headline:end -->"
RESULTS_PAGE = "docs/results.md"  # the per-cell table's page (the README holds the headline)
CASES = {"keydoor": "Case 1 keydoor", "multikeydoor": "Case 2 multikeydoor"}
SPLITS = {"heldout": "held-out maps", "minigrid": "MiniGrid grids", "drawn": "hand-drawn maps"}


def _rate(mean: float, std: float) -> str:
    if mean == 0 and std == 0:
        return "0"
    return f"{mean:.3f} ± " + ("0" if std == 0 else f"{std:.3f}")


def results_table(summary: pd.DataFrame) -> str:
    """Success (mean ± std over seeds) per fail_prob and the range of steps / optimal, per env × method."""
    fail_probs = sorted(set(summary.fail_prob))
    lines = ["| env | method | " + " | ".join(f"fail {f:g}" for f in fail_probs) + " | steps / optimal |",
             "|---|---|" + "---|" * len(fail_probs) + "---|"]
    order = {m: i for i, m in enumerate(METHODS)}
    envs = sorted(set(summary.env), key=lambda e: (e not in CASES, list(CASES).index(e) if e in CASES else e))
    for env in envs:
        rows = summary[summary.env == env]
        for method in sorted(set(rows.method), key=lambda m: (order.get(m, len(order)), m)):
            r = rows[rows.method == method].sort_values("fail_prob")
            rates = [_rate(x.success_mean, x.success_std) for x in r.itertuples()]
            ratio = r.steps_ratio.dropna()
            span = f"{ratio.min():.3f} – {ratio.max():.3f}" if len(ratio) else "–"
            label = METHODS[method].label if method in METHODS else method
            lines.append(f"| {CASES.get(env, env)} | {label} | " + " | ".join(rates) + f" | {span} |")
    return "\n".join(lines)


def _split_label(split: str) -> str:
    """A headline key's column title: a paper env, an unseen-layout split, or ``<experiment>.<split>``."""
    if "." in split:  # a further unseen-layout experiment's (unseen_experiments.<name>)
        name, split = split.split(".", 1)
        return f"{SPLITS.get(split, split)} ({name})"
    return CASES.get(split, SPLITS.get(split, split))


def headline_table(headline: dict) -> str:
    """Success per method (rows) and split (columns), and HNSDT's steps / optimum, from the headline metrics."""
    splits = list(headline)
    methods = [m for m in METHODS if any(m in headline[s] for s in splits)]
    lines = ["| method | " + " | ".join(_split_label(s) for s in splits) + " |",
             "|---|" + "---|" * len(splits)]
    for method in methods:
        cells = [f"{headline[s][method]:.3f}" if headline[s].get(method) is not None else "–" for s in splits]
        lines.append(f"| {METHODS[method].label} | " + " | ".join(cells) + " |")
    ratios = [headline[s].get("hnsdt_steps_ratio") for s in splits]
    lines.append("| HNSDT steps / optimum | " + " | ".join("–" if r is None else f"{r:.2f}×" for r in ratios) + " |")
    return "\n".join(lines)


def render(readme: str, table: str, markers: tuple[str, str] = (BEGIN, END)) -> str:
    begin, end = markers
    if readme.count(begin) != 1 or readme.count(end) != 1:
        raise ValueError(f"README.md needs exactly one {begin} and one {end} marker")
    head, rest = readme.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{table}\n{end}{tail}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check; exit 1 when the README differs")
    args = parser.parse_args()
    pages = {ROOT / "README.md": lambda text: render(text, headline_table(read_headline(ROOT / "metrics/headline")),
                                                     HEADLINE),
             ROOT / RESULTS_PAGE: lambda text: render(text, results_table(pd.read_csv(ROOT / "metrics/summary.csv")))}
    for path, rendered in pages.items():
        text = path.read_text()
        wanted = rendered(text)
        if args.check and wanted != text:
            print(f"{path.relative_to(ROOT)}: its table differs from metrics/ (summary.csv or headline/); run "
                  "`python tools/readme_results.py`", file=sys.stderr)
            return 1
        if not args.check:
            path.write_text(wanted)
    return 0


if __name__ == "__main__":
    sys.exit(main())
