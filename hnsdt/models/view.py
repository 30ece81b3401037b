"""The learned methods' networks on observations that show the world, for layouts they have not seen.

Each class here is its method's network (:mod:`hnsdt.models.dt`, :mod:`hnsdt.models.recurrent`,
:mod:`hnsdt.models.qnetwork`) with the state input changed so that nothing it reads is tied to one map:

* a step's state is the local view around the agent (:func:`hnsdt.envs.observation.local_view`, cell codes by
  identity: wall, floor, exit, key / door / item by letter, door open or closed) and the flags, never the
  absolute ``(row, col)``;
* the decision transformer's sub-goal token carries the operator's target *relative to the agent's current
  cell* (``target − (row, col)`` of the window's last step, or of each step in the episode formulation), not
  its absolute cell.

State vectors are ``row, col, view codes (row-major), flags`` (:func:`hnsdt.envs.observation.view_states`): the
datasets' own ``observation.state`` and ``observation.view`` side by side. Row and column are kept only to make the targets relative, and never embedded. The registry names these classes as each method's ``view_network``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.envs.layout import Layout
from hnsdt.envs.observation import N_CODES, view_states
from hnsdt.models.dt import DecisionTransformer, DTConfig
from hnsdt.models.qnetwork import OptionCritic, OptionCriticConfig, QNetwork, QNetworkConfig
from hnsdt.models.recurrent import RecurrentConfig, RecurrentPolicy


def split_states(states: torch.Tensor, radius: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(codes (…, cells) int64, flags (…, n_flags) float)`` of view state vectors."""
    cells = (2 * radius + 1) ** 2
    return states[..., 2:2 + cells], states[..., 2 + cells:].float()


class ViewEncoder(nn.Module):
    """A learned embedding of each cell's code, then (``conv_layers`` > 0) 3 × 3 convolutions over the view —
    features computed the same way wherever they sit, so a wall next to a corridor reads alike in any corner of
    the view — the result flattened and projected, plus a linear map of the flags: one ``width``-vector per
    state."""

    def __init__(self, radius: int, code_dim: int, n_flags: int, width: int, conv_layers: int = 0,
                 conv_channels: int = 32):
        super().__init__()
        self.radius = radius
        self.code_emb = nn.Embedding(N_CODES, code_dim)
        self.convs = None  # (no convolutions: the parameters, and so the bytes, of the flattened encoder)
        if conv_layers:
            widths = [code_dim] + [conv_channels] * conv_layers
            self.convs = nn.Sequential(*(layer for a, b in zip(widths, widths[1:])
                                         for layer in (nn.Conv2d(a, b, 3, padding=1), nn.ReLU())))
        self.view_proj = nn.Linear((2 * radius + 1) ** 2 * (conv_channels if conv_layers else code_dim), width)
        self.flag_proj = nn.Linear(max(n_flags, 1), width, bias=False)

    def forward(self, states: torch.Tensor) -> torch.Tensor:
        codes, flags = split_states(states, self.radius)
        if flags.shape[-1] == 0:
            flags = torch.zeros(*flags.shape[:-1], 1, device=flags.device)
        cells = self.code_emb(codes)  # (..., cells, code_dim)
        if self.convs is not None:
            side = 2 * self.radius + 1
            grid = cells.reshape(-1, side, side, cells.shape[-1]).permute(0, 3, 1, 2)
            cells = self.convs(grid).permute(0, 2, 3, 1).reshape(*codes.shape, -1)
        return self.view_proj(cells.flatten(-2)) + self.flag_proj(flags)


class ViewModel:
    """What every view network adds to its base: it reads view states made from the environment's
    observations and the layout."""

    cfg: object

    def model_states(self, layout: Layout, obs: np.ndarray) -> np.ndarray:
        return view_states(layout, obs, self.cfg.view_radius)


# -- decision transformer (HNSDT, pure DT) ---------------------------------------------------------------

@dataclass
class ViewDTConfig(DTConfig):
    """``grid_h`` / ``grid_w`` are the target-offset vocabularies: offsets ``-max_offset..max_offset`` with
    ``grid_h = grid_w = 2 * max_offset + 1`` (:func:`view_config`)."""

    view_radius: int = 2
    code_dim: int = 16  # embedding width of one cell code
    conv_layers: int = 0  # 3x3 convolutions over the view before its projection (0: the embeddings flattened)
    conv_channels: int = 32  # their width

    @property
    def max_offset(self) -> int:
        return (self.grid_h - 1) // 2


def view_config(condition: str, n_flags: int, view_radius: int, max_offset: int, conv_layers: int = 0,
                **sizes) -> ViewDTConfig:
    side = 2 * max_offset + 1
    return ViewDTConfig(condition=condition, n_flags=n_flags, grid_h=side, grid_w=side, view_radius=view_radius,
                        conv_layers=conv_layers, **sizes)


class ViewDecisionTransformer(ViewModel, DecisionTransformer, arch="view_decision_transformer",
                              config=ViewDTConfig):
    def build_state_encoder(self, width: int) -> None:  # the view, never the absolute cell
        cfg = self.cfg
        self.view = ViewEncoder(cfg.view_radius, cfg.code_dim, cfg.n_flags, width, cfg.conv_layers,
                                cfg.conv_channels)

    def embed_states(self, states: torch.Tensor) -> torch.Tensor:
        return self.view(states)

    def subgoal_targets(self, states: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """Absolute target -> offset from the agent's cell at that step (-1: none)."""
        m = self.cfg.max_offset
        rel = (targets - states[..., :2]).clamp(-m, m) + m
        return torch.where(targets < 0, -1, rel)


# -- recurrent controllers (LSTM hierarchical, GRU) -------------------------------------------------------

@dataclass
class ViewRecurrentConfig(RecurrentConfig):
    view_radius: int = 2
    code_dim: int = 16


class ViewRecurrentPolicy(ViewModel, RecurrentPolicy, arch="view_recurrent", config=ViewRecurrentConfig):
    def build_state_encoder(self, width: int) -> None:
        cfg = self.cfg
        self.view = ViewEncoder(cfg.view_radius, cfg.code_dim, cfg.n_flags, width)

    def embed_states(self, states: torch.Tensor) -> torch.Tensor:
        return self.view(states)


# -- value networks (DQN, option-critic): one-hot codes and flags into the MLP ---------------------------

def one_hot_view(states: torch.Tensor, radius: int) -> torch.Tensor:
    """(…, 2 + cells + flags) int64 → (…, cells · N_CODES + flags) float."""
    codes, flags = split_states(states, radius)
    return torch.cat([F.one_hot(codes, N_CODES).float().flatten(-2), flags], dim=-1)


@dataclass
class ViewQNetworkConfig(QNetworkConfig):
    view_radius: int = 2


class ViewQNetwork(ViewModel, QNetwork, arch="view_q_network", config=ViewQNetworkConfig):
    @staticmethod
    def n_inputs(cfg) -> int:
        return (2 * cfg.view_radius + 1) ** 2 * N_CODES + cfg.n_flags

    def features(self, states: torch.Tensor) -> torch.Tensor:
        return one_hot_view(states, self.cfg.view_radius)


@dataclass
class ViewOptionCriticConfig(OptionCriticConfig):
    view_radius: int = 2


class ViewOptionCritic(ViewModel, OptionCritic, arch="view_option_critic", config=ViewOptionCriticConfig):
    n_inputs = staticmethod(ViewQNetwork.n_inputs)

    def features(self, states: torch.Tensor) -> torch.Tensor:
        return one_hot_view(states, self.cfg.view_radius)
