"""Where the steps of a plan-following agent go: each sub-goal segment of an episode against the shortest way to
its target (was the first action right, was it reached), and the segments of each operator in a training set."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from hnsdt.agents.navigation import step_towards
from hnsdt.agents.rollout import Episode
from hnsdt.envs.keydoor import PICK
from hnsdt.envs.layout import Layout


@lru_cache(maxsize=8)
def layout_navigator(layout: Layout):
    """The shortest-path tables of a layout (cached: a task runs its layouts one after another)."""
    from hnsdt.agents.navigation import Navigator

    return Navigator(layout)


_JUDGED_AS = {"Move": 1, "GoTo": 2}  # right_actions' kinds of operator; the others are judged as pick / open


def right_actions(episode: Episode, navigator) -> np.ndarray:
    """Per step of a plan-following episode: was its action one that achieves the operator being pursued
    fastest? A Move: the step onto its target cell; a GoTo: a move one closer along some shortest path; pick and
    open operators: pick/open. Steps with no operator are never right."""
    lay = navigator.layout
    T = episode.length
    right = np.zeros(T, dtype=bool)
    # per step: 0 no operator, 1 Move, 2 GoTo, 3 pick / open (a later segment's over an earlier one's); then
    # each kind's steps at once (the paper's Move operators make one segment per step)
    kind = np.zeros(T, dtype=np.int8)
    for seg in episode.segments:
        kind[seg.start:seg.end] = _JUDGED_AS.get(seg.operator.split("(")[0], 3)
    cells, actions, targets = episode.states[:T, :2], episode.actions[:T], episode.subgoal_targets[:T]
    move, go, other = kind == 1, kind == 2, kind == 3
    right[move] = step_towards(cells[move], targets[move]) == actions[move]
    if go.any():
        masks = episode.states[:T][go][:, lay.door_flags] @ (1 << np.arange(len(lay.doors)))
        idx = navigator.target_grid[targets[go, 0], targets[go, 1]]
        right[go] = navigator.on_shortest_path(idx, masks, cells[go], actions[go])
    right[other] = actions[other] == PICK
    return right


def _executed(episode: Episode) -> list[tuple]:
    """(segment, end step) of each sub-goal the episode acted on: its segments of at least one step (a plan
    replaced before its next operator's first step hands that operator to no one)."""
    ends = ((seg, seg.end if seg.end is not None else episode.length) for seg in episode.segments)
    return [(seg, end) for seg, end in ends if end > seg.start]


def executed_segments(episode: Episode) -> int:
    """How many sub-goals the episode acted on (the segments :func:`segment_facts` describes)."""
    return len(_executed(episode))


def segment_facts(episode: Episode, navigator, fail_prob: float) -> list[dict]:
    """One row per executed sub-goal segment of a plan-following episode, with the optimal expected steps to
    achieve its operator from the segment's first state: d / (1 − fail_prob) for a shortest path of d moves
    (d = 1 for a Move operator), 1 for pick/open; whether its first action was right (:func:`right_actions`), how
    many of its actions were, and how it ended (``outcome``: achieved, overran or broken — the replan's reason —,
    or ended with the episode). Both experiments add their own identity columns in front."""
    rows = []
    lay = navigator.layout
    right = right_actions(episode, navigator)
    for seg, end in _executed(episode):
        state = episode.states[seg.start]
        target = tuple(int(v) for v in episode.subgoal_targets[seg.start])
        if seg.operator.startswith("Move"):
            optimal = 1 / (1 - fail_prob)
        elif seg.operator.startswith("GoTo"):
            mask = navigator.door_mask({d for d, f in zip(lay.doors, state[lay.door_flags]) if f})
            dist = navigator.distance[navigator.target_index[target], mask, state[0], state[1]]
            optimal = dist / (1 - fail_prob) if dist >= 0 else np.nan
        else:
            optimal = 1.0
        rows.append({"operator": seg.operator, "subgoal_id": seg.subgoal_id, "start": seg.start, "end": end,
                     "steps": end - seg.start, "optimal_steps": optimal, "achieved": bool(seg.achieved),
                     "outcome": seg.outcome, "first_action_right": bool(right[seg.start]),
                     "right_actions": int(right[seg.start:end].sum())})
    return rows



def training_segment_counts(dataset_root: str | Path, env: str, behaviours) -> list[dict]:
    """Sub-goal segments per operator in a dataset, over the episodes of ``behaviours`` (Theorem 2's m)."""
    from hnsdt.data.segmentation import segments_of
    from hnsdt.data.frames import load_frames
    from hnsdt.symbolic.subgoals import ID_TO_NAME

    frames = load_frames(dataset_root)
    counts: dict[str, int] = {}
    for start in np.unique(frames.episode_start):
        idx = np.flatnonzero(frames.episode_start == start)
        if len(behaviours) and frames.policy[idx[0]] not in behaviours:
            continue
        for sid, _, _ in segments_of(frames.subgoals[idx]):
            if sid:
                counts[ID_TO_NAME[sid]] = counts.get(ID_TO_NAME[sid], 0) + 1
    return [{"env": env, "operator": op, "segments": n} for op, n in sorted(counts.items())]
