"""The networks on MiniGrid's own worlds (:mod:`hnsdt.minigrid`), reading what a MiniGrid agent sees and acting with
MiniGrid's seven actions: the decision transformer of :mod:`hnsdt.models.dt` (episode formulation, one token per
step; :class:`MiniGridDT`), the RNN baselines' controllers of :mod:`hnsdt.models.recurrent`
(:class:`MiniGridRecurrent`), and the online learners' networks over the current step (:class:`ViewConv`: PPO's
actor-critic, DQN's Q-network, option-critic's).

A step's state vector (:func:`step_states`) is ``row, col, direction, carried type, carried colour`` and then
MiniGrid's own observation ``image``, the 7 × 7 cells ahead of the agent (egocentric, each cell's object, colour
and state indices, flattened): the datasets' ``observation.state`` and ``observation.view`` side by side. The
transformer and the recurrent controllers embed each cell's three indices (summed, then the 49 cells flattened and
projected), the direction and what is carried (:class:`ViewStates`) — never the absolute cell, which is there only
to place the sub-goal's target.

HNSDT's sub-goal token (each step's own, ``condition="subgoal"``) is the operator's kind (goto_object, goto_door,
goto_goal, pickup, open, drop), what it is about (MiniGrid's type and colour of its object, door or goal) and its
target cell as the agent would say it: so many cells ahead and so many to the right (:meth:`MiniGridDT
.subgoal_targets`), a turn of the offset into the agent's frame, as MiniGrid's own view is egocentric. A target
is the operator's argument — the planner names the object and knows its cell, as on our maps — never a path or a
distance to walk. The pure DT (``condition="return"``) reads the return-to-go instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn

from hnsdt.models.dt import DecisionTransformer, DTConfig
from hnsdt.models.kernels import Linear
from hnsdt.models.network import Network
from hnsdt.models.recurrent import RecurrentConfig, RecurrentPolicy

N_ACTIONS = 7  # MiniGrid's actions (hnsdt.minigrid.world.Actions: left … done; tested equal). Not imported: every
#               checkpoint load imports this module, and the paper's stages do not depend on hnsdt.minigrid
VIEW = 7  # MiniGrid's agent_view_size
N_STATE = 5  # row, col, direction, carried type, carried colour
N_OBJECTS, N_COLORS, N_DOOR_STATES, N_DIRECTIONS = 11, 6, 3, 4  # minigrid.core.constants' index ranges
N_KINDS = 7  # none and hnsdt.minigrid.operators.KINDS: hnsdt.minigrid.collect.SUBGOAL_NAMES


@dataclass
class MiniGridDTConfig(DTConfig):
    n_flags: int = 0  # (unused here: the state is the view, the direction and what is carried)
    grid_h: int = 0
    grid_w: int = 0
    formulation: str = "episode"  # (the only one: each step carries its own sub-goal)
    return_scale: float = 1.0  # MiniGrid's returns are at most 1
    max_timestep: int = 640  # DoorKey-8x8's own step limit; later steps share the last embedding
    cell_dim: int = 16  # each view cell's embedding (object + colour + state), before the 49 are projected
    max_offset: int = 15  # a target further than this many cells ahead or aside reads as this far (16x16 grids)

    def __post_init__(self):
        super().__post_init__()
        if self.formulation != "episode":
            raise ValueError("the MiniGrid decision transformer needs formulation 'episode'")
        if self.condition == "none":
            raise ValueError("the MiniGrid decision transformer is conditioned on sub-goals or returns, not 'none'")


class ViewStates:
    """How a MiniGrid network reads a :func:`step_states` vector (a mixin before the network's base class): each of
    the 49 view cells' three indices embedded and summed, the cells flattened and projected, plus the direction's
    and the carried object's embeddings — never the absolute cell."""

    def build_state_encoder(self, width: int) -> None:
        c = self.cfg.cell_dim
        self.object_emb = nn.Embedding(N_OBJECTS, c)
        self.color_emb = nn.Embedding(N_COLORS, c)
        self.door_state_emb = nn.Embedding(N_DOOR_STATES, c)
        self.view_proj = Linear(VIEW * VIEW * c, width)
        self.direction_emb = nn.Embedding(N_DIRECTIONS, width)
        self.carried_type_emb = nn.Embedding(N_OBJECTS, width)
        self.carried_color_emb = nn.Embedding(N_COLORS, width)

    def embed_states(self, states: torch.Tensor, targets: torch.Tensor | None = None) -> torch.Tensor:
        cells = states[..., N_STATE:].unflatten(-1, (VIEW * VIEW, 3))
        view = self.object_emb(cells[..., 0]) + self.color_emb(cells[..., 1]) + self.door_state_emb(cells[..., 2])
        return (self.view_proj(view.flatten(-2)) + self.direction_emb(states[..., 2])
                + self.carried_type_emb(states[..., 3]) + self.carried_color_emb(states[..., 4]))


class MiniGridDT(ViewStates, DecisionTransformer, arch="minigrid_decision_transformer", config=MiniGridDTConfig):
    n_actions = N_ACTIONS

    def build_subgoal_encoder(self, width: int) -> None:
        span = 2 * self.cfg.max_offset + 2  # offsets -m … m, and 0 = no target
        self.subgoal_emb = nn.Embedding(N_KINDS, width)
        self.ahead_emb = nn.Embedding(span, width)
        self.aside_emb = nn.Embedding(span, width)
        self.about_type_emb = nn.Embedding(N_OBJECTS, width)
        self.about_color_emb = nn.Embedding(N_COLORS, width)

    def subgoal_targets(self, states: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """Each step's sub-goal ``(row, col, type, colour)`` -> ``(ahead, aside, type, colour)``: the target's
        offset from the agent turned into its frame (cells ahead, cells to the right; each shifted to an index,
        -1 for no target)."""
        return torch.cat([egocentric(targets[..., :2], states[..., :2], states[..., 2], self.cfg.max_offset),
                          targets[..., 2:]], dim=-1)

    def embed_subgoals(self, ids: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        return (self.subgoal_emb(ids) + self.ahead_emb(targets[..., 0] + 1) + self.aside_emb(targets[..., 1] + 1)
                + self.about_type_emb(targets[..., 2]) + self.about_color_emb(targets[..., 3]))


def egocentric(target: torch.Tensor, cell: torch.Tensor, direction: torch.Tensor, limit: int) -> torch.Tensor:
    """(…, 2) ``(ahead, aside)`` indices 0 … 2·limit of ``target − cell`` (row, col) seen from an agent facing
    ``direction`` (MiniGrid's: 0 east, 1 south, 2 west, 3 north), clamped to ``limit``; -1 where there is no target
    (a negative row)."""
    dr, dc = (target - cell).unbind(-1)
    ahead = torch.stack([dc, dr, -dc, -dr], -1).gather(-1, direction[..., None])[..., 0]
    aside = torch.stack([dr, -dc, -dr, dc], -1).gather(-1, direction[..., None])[..., 0]
    out = torch.stack([ahead, aside], -1).clamp(-limit, limit) + limit
    return torch.where(target[..., :1] < 0, -1, out)


def step_states(state: np.ndarray, view: np.ndarray) -> np.ndarray:
    """The network's state vectors: ``observation.state`` (…, 5) and ``observation.view`` (…, 147) side by side."""
    return np.concatenate([np.asarray(state, np.int64), np.asarray(view, np.int64).reshape(*np.shape(state)[:-1],
                                                                                            -1)], axis=-1)


@dataclass
class MiniGridRecurrentConfig(RecurrentConfig):
    n_flags: int = 0  # (unused here, as the transformer's)
    grid_h: int = 0
    grid_w: int = 0
    cell_dim: int = 16  # each view cell's embedding, as the transformer's


class MiniGridRecurrent(ViewStates, RecurrentPolicy, arch="minigrid_recurrent", config=MiniGridRecurrentConfig):
    """The RNN baselines on MiniGrid (:class:`hnsdt.models.recurrent.RecurrentPolicy`: the LSTM hierarchical
    controller, the GRU sequential one) reading MiniGrid's view; the hierarchical one's sub-goal head predicts the
    operator's kind (the dataset's ``subgoal``), which its action head then reads — no planner when it acts."""

    n_actions = N_ACTIONS
    n_subgoals = N_KINDS


class ViewConv:
    """Reading the current step alone as MiniGrid's own starter code does (``rl-starter-files``' ACModel): three
    2 × 2 convolutions with a max-pool over the 7 × 7 view's (object, colour, state) indices, plus the direction,
    into 64 features. States are :func:`step_states` vectors, of which it reads the direction and the view (the
    agent's cell, and what it carries but through the view, never). Shared by the online learners' networks."""

    def build_view_conv(self) -> None:
        self.image = nn.Sequential(nn.Conv2d(3, 16, 2), nn.ReLU(), nn.MaxPool2d(2), nn.Conv2d(16, 32, 2), nn.ReLU(),
                                   nn.Conv2d(32, 64, 2), nn.ReLU(), nn.Flatten())
        self.direction_emb = nn.Embedding(N_DIRECTIONS, 64)

    def view_features(self, states: torch.Tensor) -> torch.Tensor:
        """(N, 64) of (N, 152) state vectors."""
        view = states[:, N_STATE:].unflatten(-1, (VIEW, VIEW, 3)).permute(0, 3, 2, 1).float()  # (N, 3, y, x)
        return self.image(view) + self.direction_emb(states[:, 2])


def _head(hidden: int, outputs: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(64, hidden), nn.Tanh(), nn.Linear(hidden, outputs))


@dataclass
class MiniGridActorCriticConfig:
    hidden: int = 64  # the actor's and the critic's hidden layer


class MiniGridActorCritic(ViewConv, Network, arch="minigrid_actor_critic", config=MiniGridActorCriticConfig):
    """PPO's network on MiniGrid (the actor-critic of ``rl-starter-files``): :class:`ViewConv` into an actor
    (logits over the 7 actions) and a critic (the state's value). No memory."""

    n_actions = N_ACTIONS

    def __init__(self, cfg: MiniGridActorCriticConfig):
        super().__init__(cfg)
        self.build_view_conv()
        self.actor, self.critic = _head(cfg.hidden, N_ACTIONS), _head(cfg.hidden, 1)

    def forward(self, states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(logits (N, 7), values (N,)) of (N, 152) state vectors."""
        x = self.view_features(states)
        return self.actor(x), self.critic(x)[:, 0]


@dataclass
class MiniGridQNetworkConfig:
    hidden: int = 64  # the Q head's hidden layer


class MiniGridQNetwork(ViewConv, Network, arch="minigrid_q_network", config=MiniGridQNetworkConfig):
    """DQN's network on MiniGrid: :class:`ViewConv` into the 7 actions' values. No memory."""

    n_actions = N_ACTIONS

    def __init__(self, cfg: MiniGridQNetworkConfig):
        super().__init__(cfg)
        self.build_view_conv()
        self.q = _head(cfg.hidden, N_ACTIONS)

    def forward(self, states: torch.Tensor) -> torch.Tensor:
        """Q-values (N, 7) of (N, 152) state vectors."""
        return self.q(self.view_features(states))


@dataclass
class MiniGridOptionCriticConfig:
    n_options: int = 8  # as on our maps (hnsdt.models.qnetwork.OptionCriticConfig)
    hidden: int = 64  # each head's hidden layer


class MiniGridOptionCritic(ViewConv, Network, arch="minigrid_option_critic", config=MiniGridOptionCriticConfig):
    """Option-critic's network on MiniGrid (Bacon et al., 2017): :class:`ViewConv` into Q_Ω(s, ω), the
    termination probabilities β_ω(s) and the intra-option policies π_ω(a | s) of every option. No memory."""

    n_actions = N_ACTIONS

    def __init__(self, cfg: MiniGridOptionCriticConfig):
        super().__init__(cfg)
        self.build_view_conv()
        k = cfg.n_options
        self.q, self.termination, self.policy = _head(cfg.hidden, k), _head(cfg.hidden, k), _head(cfg.hidden,
                                                                                                  k * N_ACTIONS)

    def forward(self, states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Q_Ω (N, K), β (N, K) in (0, 1), policy logits (N, K, 7)."""
        x = self.view_features(states)
        return self.q(x), torch.sigmoid(self.termination(x)), self.policy(x).unflatten(-1, (self.cfg.n_options,
                                                                                              N_ACTIONS))
