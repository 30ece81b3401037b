"""The dataset card, in the Hugging Face Hub / LeRobot convention, and the push to the Hub.

The card is LeRobot's own (``create_lerobot_dataset_card``: YAML front matter with the licence, the
``robotics`` task category, the ``LeRobot`` tag and the parquet ``configs``; the ``meta/info.json`` structure)
filled with what a user of these data needs: features and their meaning, the behaviours and how often they
succeed, sub-goal coverage under both labellings, the layout, the paper's BibTeX and the provenance (md5
of the data files, and where to find the revision that made them: no file names it, so the same collection gives
the same bytes). The arguments are kept in ``meta/hnsdt.json``, so
``hnsdt dataset push`` gives the Hub the same card LeRobot's ``push_to_hub`` would write from them.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from pathlib import Path

import numpy as np

from hnsdt.data.features import card_rows
from hnsdt.symbolic.subgoals import ID_TO_NAME

BIBTEX = """@inproceedings{baheri2025hnsdt,
  title     = {Hierarchical Neuro-Symbolic Decision Transformer},
  author    = {Baheri, Ali and Alm, Cecilia O.},
  booktitle = {Neural-Symbolic Learning and Reasoning (NeSy)},
  year      = {2025}
}"""


def coverage(episodes: list[dict]) -> dict[str, Counter]:
    """Frames per sub-goal id of each labelling (``subgoal_ids``, ``move_subgoal_ids``): the card's coverage
    tables; the counts of two parts of a dataset add up."""
    return {key: Counter(int(i) for ep in episodes for i in ep[key]) for key in ("subgoal_ids", "move_subgoal_ids")}


def description(cfg, rows: list[dict], frames: dict[str, Counter], layouts=None) -> str:
    """The card's body: what the data are, how they were made, what they cover (``rows``: the episodes' ``meta``
    rows; ``frames``: their :func:`coverage`). ``layouts``: a dataset over many layouts (``cfg.layout`` is then the first), which stores views."""
    total = sum(m["length"] for m in rows)
    by_behaviour: dict[tuple[str, float], list[bool]] = {}
    for m in rows:
        by_behaviour.setdefault((m["behaviour"], m["fail_prob"]), []).append(m["success"])
    where = f"on layout `{cfg.layout.name}`" if not layouts else (
        f"on {len(layouts)} generated layouts (`{layouts[0].name}` … `{layouts[-1].name}`; the first shown below, "
        "all in `layout_texts` of meta/hnsdt.json)")
    lines = [
        f"Exploration data for `{cfg.env_id}` {where}, written by hnsdt, a "
        "reproduction of *Hierarchical Neuro-Symbolic Decision "
        "Transformer* (NeSy 2025): a stochastic key–door grid world where each move fails (the agent stays) "
        "with probability `fail_prob`.", "",
        "```", cfg.layout.text.rstrip(), "```", "",
        "`@` start, `G` exit, `#` wall, `a`–`z` keys, `A`–`Z` the doors they open, `0`–`9` items to collect.", "",
        f"- episodes: {len(rows)}, frames: {total}, fps: {cfg.fps}, max_steps: {cfg.max_steps}, "
        f"seed: {cfg.seed}",
        f"- fail_probs: {', '.join(f'{f:g}' for f in cfg.fail_probs)}",
        "- load offline: `LeRobotDataset(repo_id, root=<this folder>)`", "",
        "### Features", "", "| feature | meaning |", "|---|---|",
        *[f"| `{name}` | {meaning} |" for name, meaning in card_rows(image=bool(cfg.render), view=bool(layouts))], "",
        "### Behaviours and their success rate", "",
        "`random`: uniform random actions (the paper's exploration); `noisy_planner`: the symbolic planner's "
        "shortest-path controllers with each action replaced by a random one with probability epsilon. "
        "`start=random` starts on a random free cell with random key / door / item flags.", "",
        "| behaviour | fail_prob | episodes | success |", "|---|---|---|---|",
        *[f"| {label} | {f:g} | {len(s)} | {np.mean(s):.3f} |" for (label, f), s in sorted(by_behaviour.items())],
    ]
    for key, title in (("subgoal_ids", "Sub-goal coverage (`subgoal`, GoTo operators)"),
                       ("move_subgoal_ids", "Sub-goal coverage of the paper's labelling (`move_subgoal`)")):
        lines += ["", f"### {title}", "", "| sub-goal | frames | share |", "|---|---|---|"]
        for i, count in sorted(frames[key].items()):
            name = ID_TO_NAME[i]
            lines.append(f"| {name} | {count} | {count / total:.3f} |")
    lines += ["", "The sub-goal vocabulary (ids → names) is `subgoal_vocabulary` in `meta/hnsdt.json`; per-episode "
              "metadata (behaviour, fail_prob, seed, outcome) is `meta/hnsdt_episodes.parquet`.", "",
              "### Provenance", "",
              "- md5 of the data files (`data/**/*.parquet`, in path order): `{data_md5}`",
              "- made by the collection settings in `meta/hnsdt.json`; the files name no code revision or run, so "
              "the same collection gives the same bytes. The git revision that made them is the commit whose "
              "`dvc.lock` lists this folder's md5 (the pipeline's report cites both){pushed_from}"]
    return "\n".join(lines) + "\n"


def card_arguments(cfg, rows: list[dict], frames: dict[str, Counter], layouts=None) -> dict:
    """``create_lerobot_dataset_card`` / ``push_to_hub`` arguments (kept in meta/hnsdt.json); ``rows``: the
    episodes' ``meta`` rows, ``frames``: their :func:`coverage`."""
    env = cfg.env_id.split("/")[-1]
    return {"tags": ["hnsdt", "gridworld", "key-door", "neuro-symbolic", "decision-transformer", env],
            "license": cfg.license, "dataset_description": description(cfg, rows, frames, layouts),
            "paper": "Baheri and Alm, *Hierarchical Neuro-Symbolic Decision Transformer*, NeSy 2025",
            "citation_bibtex": BIBTEX}


def data_md5(root: str | Path) -> str:
    h = hashlib.md5()
    for path in sorted(Path(root).glob("data/**/*.parquet")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def template_values(arguments: dict, md5: str, pushed_from: str | None = None) -> dict:
    """The card template's values beside ``tags`` and ``license``, the data md5 filled in, and (a card that goes
    to the Hub) the git revision it was pushed from."""
    values = {k: v for k, v in arguments.items() if k not in ("tags", "license")}
    pushed = f"; pushed from hnsdt revision `{pushed_from}`" if pushed_from else ""
    values["dataset_description"] = (values["dataset_description"].replace("{data_md5}", md5)
                                     .replace("{pushed_from}", pushed))
    return values


def render_card(arguments: dict, info, repo_id: str, md5: str, pushed_from: str | None = None) -> str:
    """The card text: LeRobot's template filled with ``arguments`` (``info`` = the dataset's meta.info)."""
    from lerobot.datasets.utils import create_lerobot_dataset_card

    card = create_lerobot_dataset_card(tags=arguments["tags"], dataset_info=info, license=arguments["license"],
                                       repo_id=repo_id, **template_values(arguments, md5, pushed_from))
    return str(card).rstrip() + "\n"
