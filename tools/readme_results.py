"""The README's results table, generated from the evaluation summary that git keeps (`metrics/summary.csv`).

Usage: python tools/readme_results.py [--check]
Rewrites the table between the `<!-- results:begin -->` and `<!-- results:end -->` markers of README.md, or
with --check exits 1 (one line) when the README's table is not the one the committed summary gives.
``tests/test_readme.py`` runs the check, so the README cannot silently disagree with the run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hnsdt.methods import METHODS  # noqa: E402

BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
CASES = {"keydoor": "Case 1 keydoor", "multikeydoor": "Case 2 multikeydoor"}


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


def render(readme: str, table: str) -> str:
    if readme.count(BEGIN) != 1 or readme.count(END) != 1:
        raise ValueError(f"README.md needs exactly one {BEGIN} and one {END} marker")
    head, rest = readme.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{table}\n{END}{tail}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check; exit 1 when the README differs")
    args = parser.parse_args()
    readme_path, summary_path = ROOT / "README.md", ROOT / "metrics/summary.csv"
    readme = readme_path.read_text()
    wanted = render(readme, results_table(pd.read_csv(summary_path)))
    if args.check:
        if wanted != readme:
            print(f"README.md: the results table differs from {summary_path.relative_to(ROOT)}; run "
                  "`python tools/readme_results.py`", file=sys.stderr)
            return 1
        return 0
    readme_path.write_text(wanted)
    return 0


if __name__ == "__main__":
    sys.exit(main())
