"""The decision transformer on observations that show the world, for layouts it has not seen.

:class:`ViewDecisionTransformer` is :class:`~hnsdt.models.dt.DecisionTransformer` with two inputs changed so
that nothing it reads is tied to one map:

* a step's state is the local view around the agent (:func:`hnsdt.envs.observation.local_view`, cell codes by
  identity) and the flags, not the absolute ``(row, col)``;
* the sub-goal token carries the operator's target *relative to the agent's current cell* (``target − (row,
  col)`` of the window's last step), not its absolute cell.

Its state vectors are ``row, col, view codes (row-major), flags`` (:func:`view_states`): row and column are kept
only to make the targets relative, and never embedded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn

from hnsdt.envs.layout import Layout
from hnsdt.envs.observation import N_CODES, local_view
from hnsdt.models.dt import DecisionTransformer, DTConfig


@dataclass
class ViewDTConfig(DTConfig):
    """``grid_h`` / ``grid_w`` are the target-offset vocabularies: offsets ``-max_offset..max_offset`` with
    ``grid_h = grid_w = 2 * max_offset + 1`` (:func:`view_config`)."""

    view_radius: int = 2
    code_dim: int = 16  # embedding width of one cell code

    @property
    def max_offset(self) -> int:
        return (self.grid_h - 1) // 2


def view_config(condition: str, n_flags: int, view_radius: int, max_offset: int, **sizes) -> ViewDTConfig:
    side = 2 * max_offset + 1
    return ViewDTConfig(condition=condition, n_flags=n_flags, grid_h=side, grid_w=side, view_radius=view_radius,
                        **sizes)


def view_states(layout: Layout, states: np.ndarray, radius: int) -> np.ndarray:
    """``row, col, view codes, flags`` per state: what :class:`ViewDecisionTransformer` reads."""
    states = np.asarray(states, dtype=np.int64).reshape(-1, 2 + layout.n_flags)
    views = local_view(layout, states, radius).reshape(len(states), -1)
    return np.concatenate([states[:, :2], views, states[:, 2:]], axis=1)


class ViewDecisionTransformer(DecisionTransformer, arch="view_decision_transformer", config=ViewDTConfig):
    def __init__(self, cfg: ViewDTConfig):
        super().__init__(cfg)
        del self.row_emb, self.col_emb  # absolute positions are never read
        side = 2 * cfg.view_radius + 1
        self.code_emb = nn.Embedding(N_CODES, cfg.code_dim)
        self.view_proj = nn.Linear(side * side * cfg.code_dim, cfg.d_model)

    def model_states(self, layout: Layout, obs: np.ndarray) -> np.ndarray:
        return view_states(layout, obs, self.cfg.view_radius)

    def embed_states(self, states: torch.Tensor) -> torch.Tensor:
        cells = (2 * self.cfg.view_radius + 1) ** 2
        codes = states[..., 2:2 + cells]
        flags = states[..., 2 + cells:].float() if self.cfg.n_flags else states[..., :1].float() * 0
        return self.view_proj(self.code_emb(codes).flatten(-2)) + self.flag_proj(flags)

    def forward(self, states, actions, timesteps, pad, subgoal_ids=None, subgoal_targets=None, returns=None):
        if subgoal_targets is not None:  # absolute target -> offset from the agent's current cell (-1: none)
            m = self.cfg.max_offset
            rel = (subgoal_targets - states[:, -1, :2]).clamp(-m, m) + m
            subgoal_targets = torch.where(subgoal_targets < 0, -1, rel)
        return super().forward(states, actions, timesteps, pad, subgoal_ids, subgoal_targets, returns)
