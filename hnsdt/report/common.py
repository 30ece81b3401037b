"""What every section of the report shares: method labels, line styles, number formats, the template and the
output md5s that ``dvc.lock`` records."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import yaml

from hnsdt.core.methods import METHODS


METHOD_LABELS = {name: m.label for name, m in METHODS.items()}


METRICS = [("success", "success rate"), ("steps", "steps (successful episodes)"), ("reward", "average reward")]


STYLES = [("o", "-"), ("s", "--"), ("^", ":"), ("D", "-."), ("v", "-"), ("P", "--"), ("X", ":")]


def line_style(i: int, n: int) -> dict:
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
    """A template of ``hnsdt/report/templates`` filled with ``context``; an unknown name in the template is
    an error, not an empty string."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).with_name("templates")),
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                             keep_trailing_newline=True, autoescape=False)
    return env.get_template(name).render(**context)


def label(method: str) -> str:
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
    other = [f"{n(int(k))} for {' and '.join(label(m) for m in ms.index)}" for k, ms in odd.groupby(odd, sort=False)]
    return ", ".join([*other, f"{usual} for the others"]) if other else n(usual)


def methods_in(summ: pd.DataFrame) -> list[str]:
    """Methods in the paper's order (by paradigm), unknown names last."""
    present = set(summ.method)
    return [m for m in METHODS if m in present] + sorted(present - set(METHODS))


def fmt(v, spec=".3f", dash="–"):
    return dash if pd.isna(v) else format(v, spec)


SPLIT_LABELS = {"train": "training layouts", "heldout": "held-out layouts", "minigrid": "MiniGrid grids",
                "minigrid_16x16": "MiniGrid 16 × 16 grids", "drawn": "hand-drawn maps"}
