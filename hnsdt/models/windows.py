"""What the offline learners train on: a dataset's :class:`Frames` as numpy arrays, and the decision
transformer's examples cut from them: context windows (the window formulation) or whole episodes (the episode
formulation, :func:`make_episodes`).

Windows are cut with numpy indexing: the same windows LeRobot's ``delta_timestamps`` gives, left-padded at
episode starts, but built in milliseconds for a whole epoch instead of one ``__getitem__`` call per sample.
:func:`hnsdt.data.frames.load_frames` reads the frames of a LeRobot dataset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Frames:
    states: np.ndarray  # (N, d) int64
    actions: np.ndarray  # (N,) int64
    rewards: np.ndarray  # (N,) float32
    subgoals: np.ndarray  # (N,) int64
    targets: np.ndarray  # (N, 2) int64
    episode: np.ndarray  # (N,) int64
    timestep: np.ndarray  # (N,) int64, frame index within its episode
    episode_start: np.ndarray  # (N,) int64, global index of the episode's first frame
    returns_to_go: np.ndarray  # (N,) float32, undiscounted sum of this and later rewards of the episode
    policy: np.ndarray  # (N,) str, the behaviour policy of the frame's episode ("" when unknown)

    def __len__(self) -> int:
        return len(self.actions)


def frames_from_arrays(states, actions, rewards, subgoals, targets, episode, timestep, policy=None) -> Frames:
    episode = np.asarray(episode, dtype=np.int64)
    n = len(episode)
    starts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]])
    lengths = np.diff(np.r_[starts, n])
    episode_start = np.repeat(starts, lengths)
    rewards = np.asarray(rewards, dtype=np.float32)
    # Returns-to-go: reverse cumulative sum inside each episode.
    rtg = np.zeros(n, dtype=np.float32)
    for s, ln in zip(starts, lengths):
        rtg[s : s + ln] = np.cumsum(rewards[s : s + ln][::-1])[::-1]
    return Frames(np.asarray(states, np.int64), np.asarray(actions, np.int64).reshape(n), rewards,
                  np.asarray(subgoals, np.int64).reshape(n), np.asarray(targets, np.int64).reshape(n, 2),
                  episode, np.asarray(timestep, np.int64).reshape(n), episode_start, rtg,
                  np.asarray(policy if policy is not None else [""] * n, dtype=object))


def achieving_frames(frames: Frames) -> np.ndarray:
    """Per frame: did its action achieve its sub-goal? The last frame of each run of one sub-goal (id and target)
    within an episode. In a hindsight-labelled random walk the run's earlier frames are the actions that did not
    (wall bumps, picks on nothing); in a planner's segment, failed attempts of the right action."""
    g = frames.subgoals
    nxt = np.r_[1:len(frames), len(frames) - 1]
    ends = ((frames.episode[nxt] != frames.episode) | (g[nxt] != g) | (frames.targets[nxt] != frames.targets).any(-1)
            | (np.arange(len(frames)) == len(frames) - 1))
    return ends & (g != 0)


def window_ends(frames: Frames, condition: str, behaviours=(), loss: str = "window") -> np.ndarray:
    """Frames that end a training window: every frame with a sub-goal (HNSDT; with ``loss="achieving"`` only
    those that achieved it) or every frame (pure DTs), of episodes collected by one of ``behaviours`` (all
    episodes when empty). Context reaches into any frame."""
    keep = frames.subgoals != 0 if condition == "subgoal" else np.ones(len(frames), dtype=bool)
    if loss == "achieving":
        keep &= _achieving(frames, condition)
    if len(behaviours):
        keep &= np.isin(frames.policy, list(behaviours))
    return np.flatnonzero(keep)


FORMULATIONS = ("window", "episode")  # a decision transformer's examples: windows, or whole episodes
LOSS_STEPS = ("window", "last", "achieving")


def supervised_frames(frames: Frames, condition: str, loss: str) -> np.ndarray | None:
    """The frames whose actions the loss ``achieving`` counts (:func:`achieving_frames`); None for the others."""
    return _achieving(frames, condition) if loss == "achieving" else None


def _achieving(frames: Frames, condition: str) -> np.ndarray:
    if condition != "subgoal":
        raise ValueError(f"loss 'achieving' needs sub-goal labels; a {condition!r}-conditioned DT has none")
    return achieving_frames(frames)


def make_windows(frames: Frames, ends: np.ndarray, h: int, condition: str, loss: str = "window"
                 ) -> dict[str, np.ndarray]:
    """Windows of ``h`` steps ending at ``ends``, with the arrays the model's forward and loss read.

    ``loss`` picks the steps the loss counts: ``window`` = every step of the window that serves its sub-goal
    (every real step for the pure DTs), more signal per window; ``last`` = only the window's last step, so each
    frame counts once (the paper's objective); ``achieving`` = the last step too, of windows that end where a
    sub-goal was achieved (:func:`window_ends`; a deviation from the paper, docs/paper-arm.md). With ``window`` a
    segment's early steps count in several windows and its last step in one: harmless when every action of a
    segment leads to its sub-goal, biased towards the non-achieving actions of hindsight-labelled random walks
    (docs/paper-arm.md)."""
    if loss not in LOSS_STEPS:
        raise ValueError(f"loss must be one of {LOSS_STEPS}, got {loss!r}")
    offsets = np.arange(h - 1, -1, -1)
    idx = ends[:, None] - offsets[None, :]
    pad = idx < frames.episode_start[ends][:, None]
    idx = np.where(pad, ends[:, None], idx)  # padded slots read any real frame; the model replaces them
    batch = {
        "states": frames.states[idx], "actions": frames.actions[idx], "timesteps": frames.timestep[idx],
        "pad": pad,
    }
    if condition == "subgoal":
        g = frames.subgoals[ends]
        batch["subgoal_ids"] = g
        batch["subgoal_targets"] = frames.targets[ends]
        # the steps that serve this window's sub-goal: same operator id and target (all Move operators share
        # one id, so the target tells a window's own move from the moves before it)
        same = (frames.subgoals[idx] == g[:, None]) & (frames.targets[idx] == frames.targets[ends][:, None]).all(-1)
        batch["loss_mask"] = same & ~pad
    else:
        if condition == "return":
            batch["returns"] = frames.returns_to_go[idx]
        batch["loss_mask"] = ~pad
    if loss in ("last", "achieving"):
        batch["loss_mask"][:, :-1] = False
    return batch


def episode_spans(frames: Frames, behaviours=()) -> tuple[np.ndarray, np.ndarray]:
    """``(first frame, length)`` of every episode collected by one of ``behaviours`` (all when empty)."""
    starts = np.flatnonzero(np.r_[True, frames.episode[1:] != frames.episode[:-1]])
    lengths = np.diff(np.r_[starts, len(frames)])
    if len(behaviours):
        keep = np.isin(frames.policy[starts], list(behaviours))
        starts, lengths = starts[keep], lengths[keep]
    return starts, lengths


def make_episodes(frames: Frames, starts: np.ndarray, lengths: np.ndarray, condition: str,
                  supervised: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Whole episodes, right-padded to the longest, with each step's own conditioning; the loss counts every
    real step once (HNSDT: every step with a sub-goal; of those, only the frames ``supervised`` marks when given,
    e.g. :func:`achieving_frames` for the loss ``achieving``)."""
    steps = np.arange(lengths.max())
    real = steps[None, :] < lengths[:, None]
    idx = np.where(real, starts[:, None] + steps[None, :], starts[:, None])  # pads read the first frame
    batch = {"states": frames.states[idx], "actions": frames.actions[idx], "timesteps": frames.timestep[idx],
             "loss_mask": real, "steps": real}  # steps: the real ones, which the model packs (DecisionTransformer)
    if condition == "subgoal":
        batch["subgoal_ids"] = frames.subgoals[idx]
        batch["subgoal_targets"] = frames.targets[idx]
        batch["loss_mask"] = real & (batch["subgoal_ids"] != 0)
        if supervised is not None:
            batch["loss_mask"] &= supervised[idx]
    elif condition == "return":
        batch["returns"] = frames.returns_to_go[idx]
    return batch
