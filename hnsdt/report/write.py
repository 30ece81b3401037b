"""The report stage's entry point: every section written into ``report.md`` and its figures, traced to the git
revision, the params digest and the md5 of every dataset and model they came from."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from hnsdt.compose.params import Params
from hnsdt.core.fileio import atomic_dir
from hnsdt.core.methods import PAPER_ARM, PARADIGMS, PROPOSED
from hnsdt.core.provenance import git_revision, params_digest
from hnsdt.report.claims import BOOTSTRAP, SOLVED, claim_lines, paper_claims, seed_lines, seed_view
from hnsdt.report.common import label, lock_outputs, render_template
from hnsdt.report.curves import curve_lines, curves_figure, histories, read_usages, trained_methods, training_exits
from hnsdt.report.figures import comparison_figure, environment_figure, heatmap_figure, paradigm_figure, regret_figure
from hnsdt.report.headline import headline_metrics, write_headline
from hnsdt.report.minigrid import minigrid_context
from hnsdt.report.paper_arm import paper_arm_lines
from hnsdt.report.tables import optimum_table, results_table, paper_target_lines, usage_lines
from hnsdt.report.theorems import theorem_sections
from hnsdt.report.unseen import executors_table, experiment_contexts, generalisation_context


def write_report(params: Params, results: Path, out: Path, lock_path: str | Path = "dvc.lock",
                 generalisation: Path | None = None, headline: Path | None = None,
                 ablations: Path | None = None, experiments: Path | None = None,
                 minigrid: Path | None = None, minigrid_learners: Path | None = None) -> Path:
    """``minigrid``: the folder of MiniGrid's own worlds (``minigrid``/NAME/reference; its section is left out
    without one); ``minigrid_learners``: the MiniGrid learners measured outside the default run
    (:mod:`hnsdt.evaluation.minigrid_learners`; their rows are left out without one); ``generalisation``: the unseen-layout experiment's results folder (its section is left out without one);
    ``experiments``: the folder of the further ones (``unseen_experiments``: each in ``experiments``/NAME);
    ``headline``: the folder to write :func:`headline_metrics` into (one JSON file per split); ``ablations``: the
    measured variants of that experiment (:mod:`hnsdt.evaluation.ablations`; its table and scaling figure are left
    out without one)."""
    summary_path = results / "summary.csv"
    if not summary_path.is_file():
        raise FileNotFoundError(f"{summary_path}: no evaluation summary (run `dvc repro evaluate`)")
    summ = pd.read_csv(summary_path)
    episodes = pd.read_csv(results / "episodes.csv")
    episodes[["rrd", "mcap"]] = episodes[["rrd", "mcap"]].fillna("")  # recording paths: empty when not recorded
    with atomic_dir(out) as tmp:
        (tmp / "figures").mkdir(parents=True)
        from hnsdt.compose.config import env_spec

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
        curves, curve_figures = learning_curves(outs, Path(lock_path).parent, tmp / "figures")
        inputs = {p: md5 for p, md5 in sorted(outs.items())  # (not the recordings: their bytes vary run to run)
                  if p.startswith(("data/", "models/", "generalisation/dataset", "generalisation/models/",
                                   "minigrid/")) and not p.endswith("recordings")}
        unseen, unseen_summary = {}, None
        if generalisation is not None:
            if not (generalisation / "summary.csv").is_file():
                raise FileNotFoundError(f"{generalisation / 'summary.csv'}: no results of the unseen-layout "
                                        "experiment (run `dvc repro evaluate_generalisation`)")
            unseen_summary = pd.read_csv(generalisation / "summary.csv")
            unseen = generalisation_context(params, generalisation, tmp / "figures" / "generalisation.png")
        variants = {"ablations": ""}  # (a part of the unseen-layout section: shown with it)
        if ablations is not None and unseen:
            from hnsdt.evaluation.ablations import ablation_context

            if not ablations.is_file():
                raise FileNotFoundError(f"{ablations}: no measured variants (benchmarks/generalisation.py --record)")
            variants = ablation_context(ablations, tmp / "figures" / "scaling.png")
        further = experiment_contexts(params, experiments, generalisation) if experiments is not None and unseen else []
        executors = executors_table(params, unseen_summary, further) if further else ""
        envs, methods = sorted(set(summ.env)), sorted(set(summ.method))
        rev, digest = git_revision(), params_digest(params)
        recorded = episodes[episodes.rrd != ""]
        theorem_text, theorem_data = theorem_sections(params, results, summ, episodes)
        paper_pure_dt = [m for m in PAPER_ARM.values() if m != PAPER_ARM[PROPOSED]]
        numbers = summ if has_optimum else summ.assign(success_ratio=np.nan, steps_ratio=np.nan, regret=np.nan)
        text = render_template(
            "report.md.j2", **({"theorem1": []} | theorem_text),
            methods=[label(m) for m in methods], envs=envs, seeds=int(summ.seeds.max()),
            fail_probs=[f"{f:g}" for f in sorted(set(summ.fail_prob))],
            episodes_per_cell=int(episodes.groupby(["method", "env", "fail_prob", "seed"]).size().max()),
            revision=rev, digest=digest, inputs=inputs, paradigms=PARADIGMS,
            optimum=optimum_table(summ) if has_optimum else "",
            target=paper_target_lines(summ) if has_optimum else [],
            claims=claims if len(claims) > 2 else [], within_std=paper_claims()["within_std"],
            arms=arms, paper_claims=paper_claims_lines, paper_hnsdt=label(PAPER_ARM[PROPOSED]),
            paper_pure_dt=", ".join(label(m) for m in paper_pure_dt),
            seeds_table=seed_lines(view), solved=f"{SOLVED:.0%}", bootstrap=f"{BOOTSTRAP:,}", usage=usage,
            curves=curves, curve_figures=curve_figures,
            numbers=results_table(numbers), recorded=len(recorded),
            example_episode=recorded.episode_id.iloc[0] if len(recorded) else "",
            generalisation=bool(unseen), **unseen, **variants, experiments=further, executors=executors,
            **({"minigrid_lines": []} | (minigrid_context(params, minigrid, minigrid_learners)
                                         if minigrid is not None else {})))
        (tmp / "report.md").write_text(text)
        theorem_data = {**theorem_data, "claims": claim_rows} if claim_rows else theorem_data
        if paper_claim_rows and arms:
            theorem_data["claims_paper_arm"] = paper_claim_rows
        if theorem_data:
            (tmp / "theorems.json").write_text(json.dumps(theorem_data, indent=2, sort_keys=True, default=float) + "\n")
        (tmp / "provenance.json").write_text(json.dumps(
            {"git_revision": rev, "params_digest": digest, "inputs": inputs}, indent=2, sort_keys=True) + "\n")
        if headline is not None:
            further_summaries = {e["name"]: e["summary"] for e in further}
            write_headline(headline_metrics(summ, unseen_summary, further_summaries), headline)
    return out / "report.md"


def learning_curves(outs: dict[str, str], root: Path, figures: Path) -> tuple[list[str], list[tuple[str, str]]]:
    """The learned methods' validation curves from their checkpoints — the paper protocol's per env
    (``models/ENV``), the unseen layouts' (``generalisation/models``), as the lock lists them: the lines under the
    figures and (experiment, figure file) per experiment with a curve."""
    folders = dict.fromkeys(str(Path(p).parent) for p in sorted(outs) if p.startswith("models/"))
    checkpoints = {Path(f).name: root / f for f in folders}
    if any(p.startswith("generalisation/models/") for p in outs):
        checkpoints["unseen layouts"] = root / "generalisation/models"
    usages = read_usages(checkpoints)
    h = histories(usages)
    made = []
    for experiment in dict.fromkeys(h.experiment):
        name = f"learning_{experiment.replace(' ', '_')}.png"
        curves_figure(h, experiment, figures / name)
        made.append((experiment, name))
    return curve_lines(h, trained_methods(usages), training_exits(usages)), made
