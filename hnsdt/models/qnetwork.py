"""Networks of the traditional-RL baselines: DQN's Q-network, the option-critic network and PPO's actor-critic.

States are small integer vectors (row, col, flags), so each reads a one-hot encoding of row and column next to
the flags and pass it through an MLP of ``n_layers`` × ``hidden`` ReLU units.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.envs.dynamics import N_ACTIONS
from hnsdt.models.kernels import Linear
from hnsdt.models.network import Network


def encode_states(states: torch.Tensor, grid_h: int, grid_w: int) -> torch.Tensor:
    """(…, 2 + flags) int64 → (…, grid_h + grid_w + flags) float: one-hot row, one-hot column, flags."""
    return torch.cat([F.one_hot(states[..., 0], grid_h).float(), F.one_hot(states[..., 1], grid_w).float(),
                      states[..., 2:].float()], dim=-1)


def mlp(n_in: int, hidden: int, n_layers: int) -> nn.Sequential:
    layers, width = [], n_in
    for _ in range(n_layers):
        layers += [Linear(width, hidden), nn.ReLU()]
        width = hidden
    return nn.Sequential(*layers)


class StateFeatures:
    """The MLP input of both value networks (:mod:`hnsdt.models.view` swaps it for the view's)."""

    cfg: object

    @staticmethod
    def n_inputs(cfg) -> int:
        return cfg.grid_h + cfg.grid_w + cfg.n_flags

    def features(self, states: torch.Tensor) -> torch.Tensor:
        return encode_states(states, self.cfg.grid_h, self.cfg.grid_w)


@dataclass
class QNetworkConfig:
    n_flags: int
    grid_h: int
    grid_w: int
    hidden: int = 128
    n_layers: int = 2


class QNetwork(StateFeatures, Network, arch="q_network", config=QNetworkConfig):
    def __init__(self, cfg: QNetworkConfig):
        super().__init__(cfg)
        self.body = mlp(self.n_inputs(cfg), cfg.hidden, cfg.n_layers)
        self.head = Linear(cfg.hidden, N_ACTIONS)

    def forward(self, states: torch.Tensor) -> torch.Tensor:
        """Q-values (B, 5)."""
        return self.head(self.body(self.features(states)))


@dataclass
class OptionCriticConfig:
    n_flags: int
    grid_h: int
    grid_w: int
    n_options: int = 8
    hidden: int = 128
    n_layers: int = 2


class OptionCritic(StateFeatures, Network, arch="option_critic", config=OptionCriticConfig):
    """Shared features; heads for Q_Ω(s, ω), the termination probabilities β_ω(s) and the intra-option
    policies π_ω(a | s) of every option (Bacon et al., 2017)."""

    def __init__(self, cfg: OptionCriticConfig):
        super().__init__(cfg)
        self.body = mlp(self.n_inputs(cfg), cfg.hidden, cfg.n_layers)
        self.q_head = Linear(cfg.hidden, cfg.n_options)
        self.termination_head = Linear(cfg.hidden, cfg.n_options)
        self.policy_head = Linear(cfg.hidden, cfg.n_options * N_ACTIONS)

    def forward(self, states: torch.Tensor):
        """Q_Ω (B, K), β (B, K) in (0, 1), policy logits (B, K, 5)."""
        x = self.body(self.features(states))
        logits = self.policy_head(x).view(*x.shape[:-1], self.cfg.n_options, N_ACTIONS)
        return self.q_head(x), _sigmoid(self.termination_head(x), self.stack_size), logits


def _sigmoid(x: torch.Tensor, stack_size: int) -> torch.Tensor:
    """``torch.sigmoid``; in a stack of networks (:func:`hnsdt.baselines.online.stack_networks`), one call per
    network: torch computes a tensor's last few elements on another code path than the rest, with other last bits,
    and each network must get the bytes it gets alone."""
    return torch.stack([torch.sigmoid(part) for part in x]) if stack_size else torch.sigmoid(x)


@dataclass
class ActorCriticConfig(QNetworkConfig):
    """The Q-network's knobs, for each of the actor's and the critic's MLPs."""


class ActorCritic(StateFeatures, Network, arch="actor_critic", config=ActorCriticConfig):
    """PPO's network, after CleanRL's ``ppo.py``: separate actor and critic MLPs over the same features, their
    layers initialised orthogonally (gain √2; the policy head 0.01, so that the first policy is near uniform; the
    value head 1)."""

    def __init__(self, cfg: ActorCriticConfig):
        super().__init__(cfg)
        self.actor = mlp(self.n_inputs(cfg), cfg.hidden, cfg.n_layers)
        self.policy_head = Linear(cfg.hidden, N_ACTIONS)
        self.critic = mlp(self.n_inputs(cfg), cfg.hidden, cfg.n_layers)
        self.value_head = Linear(cfg.hidden, 1)
        for module in self.modules():
            if isinstance(module, Linear):
                gain = 0.01 if module is self.policy_head else 1.0 if module is self.value_head else 2 ** 0.5
                nn.init.orthogonal_(module.weight, gain)
                nn.init.zeros_(module.bias)

    def forward(self, states: torch.Tensor):
        """Policy logits (B, 5), state values (B,)."""
        x = self.features(states)
        return self.policy_head(self.actor(x)), self.value_head(self.critic(x)).squeeze(-1)
