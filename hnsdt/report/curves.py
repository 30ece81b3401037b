"""Learning curves: each learned method's validation measure against its training (env steps online, epochs
offline), every seed's evaluations as its checkpoint recorded them, so that a reader sees each row at its plateau.

A checkpoint trained to a validated plateau records its evaluations in its usage (``validation_<measure>``: a list
of ``{"step", "value"}`` online, ``{"epoch", "step", "value"}`` offline), the one it kept (``best_step`` /
``best_epoch``) and the measure's floor (the optimum's steps) when it has one. A method trained to a fixed budget
records none and has no curve.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from hnsdt.core.methods import METHODS  # noqa: E402
from hnsdt.report.common import label  # noqa: E402

MEASURES = {"steps": "steps to the exit", "loss": "validation loss"}  # validation_<name> -> the axis' name


def read_usages(checkpoints: dict[str, Path]) -> list[tuple[str, str, int, dict]]:
    """Per experiment (a name -> its folder of ``METHOD/seedN/config.json``), each learned method's checkpoints'
    usage, read once: (experiment, method, seed, usage)."""
    out = []
    for experiment, root in checkpoints.items():
        for config in sorted(Path(root).glob("*/seed*/config.json")):
            method = config.parent.parent.name
            if method in METHODS:
                out.append((experiment, method, int(config.parent.name[len("seed"):]),
                            json.loads(config.read_text()).get("usage", {})))
    return out


def trained_methods(usages: list[tuple]) -> dict[str, list[str]]:
    """Per experiment, the learned methods with checkpoints (:func:`read_usages`), in the registry's order."""
    present = {(experiment, method) for experiment, method, _, _ in usages}
    return {e: [m for m in METHODS if (e, m) in present] for e in dict.fromkeys(u[0] for u in usages)}


def histories(usages: list[tuple]) -> pd.DataFrame:
    """One row per recorded evaluation of the checkpoints (:func:`read_usages`): experiment, method, seed,
    measure, x (env steps online, the epoch offline), unit, value, kept (the evaluation whose weights the seed
    kept), floor, stopped (the seed stopped at its plateau before the cap)."""
    rows = []
    for experiment, method, seed, usage in usages:
        for name in MEASURES:
            for h in usage.get(f"validation_{name}", []):
                online = "epoch" not in h
                x = h["step"] if online else h["epoch"]
                kept = usage.get("best_step" if online else "best_epoch")
                rows.append({"experiment": experiment, "method": method, "seed": seed, "measure": name,
                             "x": x, "unit": "environment steps" if online else "epochs",
                             "value": float(h["value"]), "kept": x == kept,
                             "floor": usage.get("validation_floor", np.nan),
                             "stopped": bool(usage.get("stopped_early"))})
    return pd.DataFrame(rows, columns=["experiment", "method", "seed", "measure", "x", "unit", "value", "kept",
                                       "floor", "stopped"])


def curves_figure(h: pd.DataFrame, experiment: str, path: Path) -> None:
    """One panel per method of ``experiment``: each seed's evaluations (thin), the band from the lowest to the
    highest seed at every evaluation point a seed reached and the mean over them, each seed's kept evaluation
    (a dot) and the measure's floor (dashed)."""
    d = h[h.experiment == experiment]
    methods = [m for m in METHODS if m in set(d.method)]
    fig, axes = plt.subplots(1, len(methods), figsize=(2.9 * len(methods), 2.9), squeeze=False)
    for ax, method in zip(axes[0], methods):
        m = d[d.method == method]
        for _, seed in m.groupby("seed"):
            ax.plot(seed.x, seed.value, color="0.6", lw=0.7)
        at = m.groupby("x").value
        ax.fill_between(at.min().index, at.min(), at.max(), color="C0", alpha=0.25, lw=0)
        ax.plot(at.mean().index, at.mean(), color="C0", lw=1.5)
        kept = m[m.kept]
        ax.scatter(kept.x, kept.value, color="C3", s=14, zorder=3, label="kept")
        if m.floor.notna().any():
            ax.axhline(m.floor.dropna().iloc[0], color="k", ls="--", lw=0.8, label="floor (optimum)")
        ax.set_title(label(method), fontsize=9)
        ax.set_xlabel(m.unit.iloc[0], fontsize=8)
        if m.unit.iloc[0] == "environment steps":
            ax.xaxis.set_major_formatter(lambda v, _: f"{v / 1000:g}k")
        ax.set_ylabel(MEASURES[m.measure.iloc[0]], fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def training_exits(usages: list[tuple]) -> pd.DataFrame:
    """Per experiment, online method and seed (:func:`read_usages`): its training episodes, how many ended at the
    exit, its env steps."""
    rows = [{"experiment": e, "method": m, "episodes": u["episodes"], "exits": u["exits"], "env_steps": u["env_steps"]}
            for e, m, _, u in usages if "exits" in u]
    return pd.DataFrame(rows, columns=["experiment", "method", "episodes", "exits", "env_steps"])


def curve_lines(h: pd.DataFrame, trained: dict[str, list[str]], exits: pd.DataFrame | None = None) -> list[str]:
    """Per experiment (``trained``: experiment -> its learned methods): how many seeds of each method with a curve
    stopped at their plateau before the cap, and the methods trained to a fixed budget, which have none; each
    online learner whose seeds ended fewer than 5 % of their training episodes at the exit (``exits``, from
    :func:`training_exits`), with those counts: too few successes to learn the way from."""
    lines = []
    for experiment, methods in trained.items():
        d = h[h.experiment == experiment]
        seeds = d.groupby(["method", "seed"]).stopped.first().groupby("method")
        stopped = [f"{label(m)} {seeds.sum()[m]} of {seeds.size()[m]}" for m in methods if m in seeds.size()]
        fixed = [label(m) for m in methods if m not in set(d.method)]
        line = f"- {experiment}: seeds stopped at their plateau before the cap: {', '.join(stopped) or 'none'}"
        lines.append(line + (f"; trained to a fixed budget, with no validation measure (no curve): "
                             f"{', '.join(fixed)}." if fixed else "."))
        for method, e in ([] if exits is None else exits[exits.experiment == experiment].groupby("method", sort=False)):
            if (e.exits < 0.05 * e.episodes).all():
                lines.append(f"  - {label(method)}: {_span(e.exits, '')} of its {_span(e.episodes, ',')} training "
                             f"episodes a seed ended at the exit in up to {e.env_steps.max():,} environment steps: "
                             "too few successes to learn the way from within this cap.")
    return lines


def _span(values: pd.Series, spec: str) -> str:
    low, high = format(values.min(), spec), format(values.max(), spec)
    return low if low == high else f"{low}–{high}"
