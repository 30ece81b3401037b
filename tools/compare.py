"""The committed run and its experiments side by side, in a terminal: one row per params knob or metric that
differs between them, one column per row of `dvc exp show` (the workspace, the commit, each experiment;
``make compare``).

`dvc exp show` puts every knob and metric in a column of its own, hundreds of characters wide; this is its
transpose, restricted to what changed (as ``--only-changed``, without the dependencies' hashes): the knobs you
set with ``dvc exp run -S`` and the metrics that moved.

Usage: python tools/compare.py [--all] [--width N]
--all lists every experiment of every commit of the branch (default: the experiments of HEAD); --width the widest a
line may be (default: 200): with more experiments than fit, the newest that fit are shown and the rest counted.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import yaml

KEY_WIDTH = 44  # the row labels (a knob, evaluate.episodes, or a headline metric, heldout.hnsdt) are cut here
CELL_WIDTH = 14
METRICS = "metrics/headline/"  # the metrics of dvc.yaml (the report stage's): one file per split


def _label(key: str, knobs: set[str]) -> tuple[int, str] | None:
    """An ``exp_show`` column as (0, knob) or (1, ``split.metric``); None for the dependencies' and outputs'
    hashes. DVC names a column by its key alone (``evaluate.episodes``), or ``FILE:key`` where two files share a
    key (``params.yaml:...``; ``metrics/headline/keydoor.json:hnsdt``, the metrics being one file per split)."""
    file, _, name = key.rpartition(":")
    if file in ("", "params.yaml") and name in knobs:
        return 0, name
    if file.startswith(METRICS) and file.endswith(".json"):
        return 1, f"{Path(file).stem}.{name}"
    return None


def changed_rows(rows: list[dict], knobs: set[str]) -> dict[str, list]:
    """``label -> value per row`` for every knob (of ``knobs``) and headline metric whose values differ between
    ``rows`` (``dvc.api.exp_show`` rows), the knobs first."""
    labelled = sorted((label, key) for key in rows[0] if (label := _label(key, knobs)) is not None)
    out = {}
    for (kind, name), key in labelled:
        values = [r.get(key) for r in rows]
        if len({_cell(v) for v in values}) > 1:
            out[("knob " if kind == 0 else "") + name] = values
    return out


def _flat(tree: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out |= _flat(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


def _cell(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _fit(text: str, width: int) -> str:
    return text if len(text) <= width else text[:width - 1] + "…"


def render(rows: list[dict], width: int = 200) -> str:
    """The table of :func:`changed_rows`, no line over ``width`` characters."""
    names = [r.get("Experiment") or (r.get("rev") or "?")[:12] for r in rows]
    with open("params.yaml") as f:
        knobs = set(_flat(yaml.safe_load(f) or {}))
    fit = max(1, (width - KEY_WIDTH - 1) // (CELL_WIDTH + 1))
    keep = list(range(len(rows)))[:fit]  # the workspace and the commit first, then the newest experiments
    changed = changed_rows(rows, knobs)
    lines = [" ".join([f"{'':<{KEY_WIDTH}}"] + [f"{_fit(names[i], CELL_WIDTH):>{CELL_WIDTH}}" for i in keep])]
    for label, values in changed.items():
        lines.append(" ".join([f"{_fit(label, KEY_WIDTH):<{KEY_WIDTH}}"]
                              + [f"{_fit(_cell(values[i]), CELL_WIDTH):>{CELL_WIDTH}}" for i in keep]))
    if not changed:
        lines.append("(no knob or metric differs between these)")
    if len(rows) > len(keep):
        lines.append(f"({len(rows) - len(keep)} more experiments not shown: --width, or `dvc exp remove`)")
    return "\n".join(line.rstrip() for line in lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--all", action="store_true", help="every commit's experiments, not only HEAD's")
    parser.add_argument("--width", type=int, default=200)
    args = parser.parse_args()
    import dvc.api

    rows = dvc.api.exp_show(num=-1 if args.all else 1)
    if len(rows) < 2:
        print("no experiment to compare with: run one, e.g. `dvc exp run -S evaluate.episodes=50`", file=sys.stderr)
        return 1
    print(render(rows, args.width))
    return 0


if __name__ == "__main__":
    sys.exit(main())
