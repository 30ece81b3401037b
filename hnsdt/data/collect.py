"""Collect exploration trajectories for one environment and write them as a LeRobot dataset.

Behaviours (each a list entry of ``collect.behaviours`` in params.yaml):

* ``random``: uniform random actions (the paper's exploration); sub-goals labelled in hindsight.
* ``noisy_planner``: the symbolic agent (plan + shortest-path controllers) with each action replaced by a
  uniform one with probability ``epsilon``; sub-goals are the operators it was executing.

Every episode also carries the paper's labelling (``move_subgoal``): its frames segmented in hindsight by the
Move / PickKey / OpenDoor / PickItem operators of Appendix B, whatever the behaviour.

``start: layout`` starts at ``@``; ``start: random`` starts on a random free cell (never a closed door or the
exit) with every key/door/item flag drawn at random, which covers sub-goals from many situations. Episodes of
each behaviour are split evenly over ``fail_probs``. Everything is seeded from ``seed``: same settings, same
files.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.rollout import Episode, RandomAgent, rollout
from hnsdt.agents.symbolic import SymbolicAgent
from hnsdt.data.segmentation import hindsight_labels
from hnsdt.envs.layout import Layout
from hnsdt.envs.vector import KeyDoorVectorEnv

POLICIES = ("random", "noisy_planner")
STARTS = ("layout", "random")


@dataclass
class Behaviour:
    policy: str
    episodes: int
    start: str = "layout"
    epsilon: float = 0.0

    def __post_init__(self):
        # Messages start with the field's name, so params errors read "collect.behaviours[i].<field> ...".
        if self.policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}, got {self.policy!r}")
        if self.start not in STARTS:
            raise ValueError(f"start must be one of {STARTS}, got {self.start!r}")
        if int(self.episodes) < 0:
            raise ValueError(f"episodes must be >= 0, got {self.episodes}")
        if not 0.0 <= float(self.epsilon) <= 1.0:
            raise ValueError(f"epsilon must be in [0, 1], got {self.epsilon}")

    @property
    def label(self) -> str:
        eps = f", epsilon={self.epsilon:g}" if self.policy == "noisy_planner" else ""
        return f"{self.policy}(start={self.start}{eps})"


@dataclass
class CollectConfig:
    env_id: str
    layout: Layout
    max_steps: int
    fail_probs: list[float]
    behaviours: list[Behaviour]
    seed: int = 0
    fps: int = 10
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)
    license: str = "apache-2.0"  # the dataset card's licence (a Hub licence identifier)
    render: int = 0  # pixels per grid cell of a rendered video feature `observation.image` (0 = none)


def random_start_states(layout: Layout, n: int, rng: np.random.Generator) -> np.ndarray:
    flags = rng.integers(0, 2, size=(n, layout.n_flags))
    door_cells = list(layout.doors.values())
    cells = [c for c in layout.free_cells() if c != layout.goal]
    states = np.zeros((n, layout.state_size), dtype=np.int64)
    states[:, 2:] = flags
    doors = states[:, layout.door_flags]
    for i in range(n):
        while True:
            cell = cells[rng.integers(len(cells))]
            if cell not in door_cells or doors[i, door_cells.index(cell)]:
                break  # a closed door cell would trap the agent from step 0
        states[i, :2] = cell
    return states


def _batch_seed(seed: int, *parts: int) -> int:
    return int(np.random.SeedSequence([seed, *parts]).generate_state(1)[0])


def collect_episodes(cfg: CollectConfig, progress: bool = True) -> list[dict]:
    """Run every behaviour × fail_prob batch; return episode dicts ready for :func:`write_dataset`."""
    out: list[dict] = []
    jobs = [(b, bi, f, fi) for bi, b in enumerate(cfg.behaviours) for fi, f in enumerate(cfg.fail_probs)]
    bar = tqdm(jobs, desc=f"collect {cfg.env_id}", disable=not progress, unit="batch")
    for b, bi, fail_prob, fi in bar:
        n = b.episodes // len(cfg.fail_probs) + (1 if fi < b.episodes % len(cfg.fail_probs) else 0)
        if n == 0:
            continue
        seed = _batch_seed(cfg.seed, bi, fi)
        rng = np.random.default_rng(seed)
        env = KeyDoorVectorEnv(n, cfg.layout, fail_prob, cfg.max_steps)
        starts = random_start_states(cfg.layout, n, rng) if b.start == "random" else None
        if b.policy == "random":
            episodes = rollout(env, RandomAgent(seed), seed, starts)
        else:
            episodes = rollout(env, SymbolicAgent(cfg.layout, cfg.executor), seed, starts, epsilon=b.epsilon)
        for i, ep in enumerate(episodes):
            out.append(_episode_record(cfg, b, fail_prob, seed, i, ep))
    return out


def _episode_record(cfg: CollectConfig, b: Behaviour, fail_prob: float, seed: int, i: int, ep: Episode) -> dict:
    if b.policy == "random":
        ids, targets = hindsight_labels(cfg.layout, ep.states)
    else:
        ids, targets = ep.subgoal_ids, ep.subgoal_targets
    move_ids, move_targets = hindsight_labels(cfg.layout, ep.states, "move")
    return {
        "states": ep.states, "actions": ep.actions, "rewards": ep.rewards, "success": ep.success,
        "subgoal_ids": ids, "subgoal_targets": targets, "move_subgoal_ids": move_ids,
        "move_subgoal_targets": move_targets,
        "meta": {
            "env_id": cfg.env_id, "layout": cfg.layout.name, "fail_prob": float(fail_prob), "seed": seed,
            "batch_index": i, "policy": b.policy, "behaviour": b.label, "start": b.start,
            "epsilon": float(b.epsilon), "success": bool(ep.success), "length": ep.length, "return": ep.ret,
        },
    }


MIN_VIDEO_WIDTH = 25  # pixels: SVT-AV1, LeRobot's video encoder, dies (SIGFPE) on narrower frames (measured)


def collect_dataset(cfg: CollectConfig, root: str | Path, repo_id: str, progress: bool = True) -> Path:
    """Collect and write the dataset with its card; nothing in it names the code revision or the run, so the same
    collection gives the same bytes."""
    width = cfg.layout.shape[1] * cfg.render
    if cfg.render and width < MIN_VIDEO_WIDTH:
        raise ValueError(f"collect.render: {cfg.render} pixels per cell draw layout {cfg.layout.name}'s "
                         f"{cfg.layout.shape[1]} columns {width} pixels wide; LeRobot's AV1 video encoder crashes on "
                         f"frames narrower than {MIN_VIDEO_WIDTH} (set collect.render to at least "
                         f"{-(-MIN_VIDEO_WIDTH // cfg.layout.shape[1])})")
    episodes = collect_episodes(cfg, progress)
    if not episodes:
        raise ValueError("collect: no episodes requested (every behaviour has episodes: 0)")
    meta = {
        "repo_id": repo_id, "env_id": cfg.env_id, "layout": cfg.layout.name, "max_steps": cfg.max_steps,
        "fps": cfg.fps, "seed": cfg.seed, "fail_probs": list(cfg.fail_probs),
        "behaviours": [vars(b) for b in cfg.behaviours], "executor": vars(cfg.executor), "render": cfg.render,
    }
    from hnsdt.data.card import card_arguments, coverage
    from hnsdt.data.lerobot_io import write_dataset  # lerobot takes seconds to import: only when writing

    card = card_arguments(cfg, [ep["meta"] for ep in episodes], coverage(episodes))
    return write_dataset(root, repo_id, cfg.layout, episodes, cfg.fps, meta, card, progress=progress,
                         render_px=cfg.render)


SHARD_LAYOUTS = 1_000  # layouts per shard of a dataset over more: each shard is collected and written by a worker
#                        process (its memory bounded by the shard, not the dataset), then they are joined one at a
#                        time (hnsdt.data.lerobot_io.join); the bytes depend on this number, not on the workers
#                        (docs/timings.md, "Ten times the data")


def collect_on_layouts(cfg: CollectConfig, layouts: list[Layout], root: str | Path, repo_id: str, view_radius: int,
                       family: str, progress: bool = True, compute=None) -> Path:
    """Collect ``cfg``'s behaviours on every layout of ``layouts`` (each its own batch seeds) and write one
    dataset whose frames also store the local view of ``view_radius`` and their layout's index. ``cfg.layout`` is
    ignored: the layouts' list takes its place. Over more than :data:`SHARD_LAYOUTS` layouts the collection runs
    shard by shard on ``compute``'s workers (:mod:`hnsdt.core.compute`), each shard a LeRobot dataset, joined one
    at a time by :func:`~hnsdt.data.lerobot_io.join`; the frames are the same as in one piece."""
    from hnsdt.data.card import card_arguments, coverage
    from hnsdt.data import lerobot_io

    meta = {"repo_id": repo_id, "env_id": cfg.env_id, "family": family, "layout": layouts[0].name,
            "layouts": [lay.name for lay in layouts], "max_steps": cfg.max_steps, "fps": cfg.fps, "seed": cfg.seed,
            "fail_probs": list(cfg.fail_probs), "behaviours": [vars(b) for b in cfg.behaviours],
            "executor": vars(cfg.executor)}
    first = replace(cfg, layout=layouts[0])
    if len(layouts) <= SHARD_LAYOUTS:
        episodes = _collect_layouts(cfg, layouts, 0, progress)
        card = card_arguments(first, [ep["meta"] for ep in episodes], coverage(episodes), layouts)
        return lerobot_io.write_dataset(root, repo_id, layouts, episodes, cfg.fps, meta, card, progress=progress,
                                        view_radius=view_radius)
    from hnsdt.core.compute import Compute, run_tasks
    from hnsdt.core.fileio import atomic_dir

    root, side = Path(root), lerobot_io.map_side(layouts)
    with atomic_dir(root) as staging:
        shards = [Shard(cfg, layouts[i:i + SHARD_LAYOUTS], i, side, repo_id, view_radius,
                        staging.parent / f"shard-{i // SHARD_LAYOUTS:05d}")
                  for i in range(0, len(layouts), SHARD_LAYOUTS)]
        parts = run_tasks(collect_shard, shards, compute or Compute(), desc=f"collect {cfg.env_id} by shards",
                          progress=progress)
        rows = [row for part_rows, _ in parts for row in part_rows]
        frames = {key: sum((counts[key] for _, counts in parts), Counter()) for key in parts[0][1]}
        info = lerobot_io.join(staging, repo_id, [s.folder for s in shards], progress)
        lerobot_io.finish_dataset(staging, repo_id, layouts, rows, meta, card_arguments(first, rows, frames, layouts),
                                  info, view_radius)
    return root


def _collect_layouts(cfg: CollectConfig, layouts: list[Layout], first: int, progress: bool) -> list[dict]:
    """The episodes on every layout of ``layouts``, the dataset's layouts ``first``, ``first + 1``, ...: each
    seeded by, and its episodes naming, its index in the dataset."""
    episodes = []
    for i, layout in enumerate(tqdm(layouts, desc=f"collect {cfg.env_id}", unit="layout", disable=not progress),
                               first):
        for ep in collect_episodes(replace(cfg, layout=layout, seed=_batch_seed(cfg.seed, 1_000_003, i)), False):
            ep["layout_index"] = i
            ep["meta"]["layout_index"] = i
            episodes.append(ep)
    return episodes


@dataclass(frozen=True)
class Shard:
    """One worker's part of a dataset over many layouts: its ``layouts``, the dataset's from index ``first`` on,
    written as a LeRobot dataset at ``folder``, the whole map drawn on the dataset's square ``side``."""

    cfg: CollectConfig
    layouts: list
    first: int
    side: int
    repo_id: str
    view_radius: int
    folder: Path


def collect_shard(shard: Shard) -> tuple[list[dict], dict]:
    """Collect and write one :class:`Shard`; its episodes' ``meta`` rows, in order, and their sub-goal
    :func:`~hnsdt.data.card.coverage`."""
    from hnsdt.data import lerobot_io
    from hnsdt.data.card import coverage

    episodes = _collect_layouts(shard.cfg, shard.layouts, shard.first, False)
    lerobot_io.write_frames(shard.folder, shard.repo_id, shard.layouts, episodes, shard.cfg.fps,
                            view_radius=shard.view_radius, side=shard.side, first=shard.first)
    return [ep["meta"] for ep in episodes], coverage(episodes)
