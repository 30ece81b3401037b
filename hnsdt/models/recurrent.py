"""Recurrent controllers of the RNN baselines (paper, Section 5): the LSTM hierarchical controller (3 × 256) and
the GRU sequential controller (2 × 128).

Each step's input is the state (row and column embeddings plus a linear map of the flags) plus the embedding of
the previous action (a start token at t = 0). The flat controller reads an action from the recurrent state.
The hierarchical one has two heads: a high-level head predicts the current sub-goal id (ψ's vocabulary) from
the history, and a low-level head predicts the action from the history and that sub-goal's embedding. Training
feeds the labelled sub-goal (teacher forcing); acting feeds the high-level head's own choice, so no planner is
needed at test time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.models.dt import N_ACTIONS
from hnsdt.models.kernels import linear, tanh
from hnsdt.models.network import Network
from hnsdt.symbolic.subgoals import VOCAB_SIZE

CELLS = ("lstm", "gru")
START_ACTION = N_ACTIONS  # the "previous action" of an episode's first step (RecurrentPolicy's; a subclass's: its
#                          n_actions)


@dataclass
class RecurrentConfig:
    cell: str  # "lstm" or "gru"
    n_flags: int
    grid_h: int
    grid_w: int
    n_layers: int = 2
    hidden: int = 128
    hierarchical: bool = False  # sub-goal head + sub-goal-conditioned action head
    embed: int = 64
    dropout: float = 0.0

    def __post_init__(self):
        if self.cell not in CELLS:
            raise ValueError(f"cell must be one of {CELLS}, got {self.cell!r}")
        if min(self.n_layers, self.hidden, self.embed) < 1:
            raise ValueError("n_layers, hidden and embed must be positive")


class RecurrentPolicy(Network, arch="recurrent", config=RecurrentConfig):
    n_actions = N_ACTIONS  # the action head's outputs; this index is the start token (START_ACTION). A network for
    #                        another world's actions sets its own (hnsdt.models.minigrid_nets)
    n_subgoals = VOCAB_SIZE  # the hierarchical sub-goal head's outputs: the dataset's sub-goal ids

    def __init__(self, cfg: RecurrentConfig):
        super().__init__(cfg)
        d, h = cfg.embed, cfg.hidden
        self.build_state_encoder(d)
        self.prev_action_emb = nn.Embedding(self.n_actions + 1, d)
        rnn = nn.LSTM if cfg.cell == "lstm" else nn.GRU
        self.rnn = rnn(d, h, cfg.n_layers, batch_first=True, dropout=cfg.dropout if cfg.n_layers > 1 else 0.0)
        if cfg.hierarchical:
            self.subgoal_head = nn.Linear(h, self.n_subgoals)
            self.subgoal_emb = nn.Embedding(self.n_subgoals, h)
            self.action_head = nn.Sequential(nn.Linear(2 * h, h), nn.ReLU(), nn.Linear(h, self.n_actions))
        else:
            self.action_head = nn.Linear(h, self.n_actions)

    def build_state_encoder(self, width: int) -> None:
        """The state's part, built first: ``(row, col)`` embeddings plus a linear map of the flags (a network
        that reads states another way builds its own here, :mod:`hnsdt.models.view`)."""
        cfg = self.cfg
        self.row_emb = nn.Embedding(cfg.grid_h, width)
        self.col_emb = nn.Embedding(cfg.grid_w, width)
        self.flag_proj = nn.Linear(max(cfg.n_flags, 1), width, bias=False)

    def embed_states(self, states: torch.Tensor) -> torch.Tensor:
        flags = states[..., 2:].float() if self.cfg.n_flags else states[..., :1].float() * 0
        return self.row_emb(states[..., 0]) + self.col_emb(states[..., 1]) + self.flag_proj(flags)

    def forward(self, states, prev_actions, subgoals=None, hidden=None):
        """states (B, T, d) int64, prev_actions (B, T) int64; ``subgoals`` (B, T) feeds the hierarchical action
        head (None: its own argmax). Returns action logits (B, T, n_actions), sub-goal logits (B, T, V) or None, and
        the recurrent state to continue from."""
        x = self.embed_states(states) + self.prev_action_emb(prev_actions)
        out, hidden = self.rnn(x, hidden)
        if not self.cfg.hierarchical:
            return self.action_head(out), None, hidden
        subgoal_logits = self.subgoal_head(out)
        if subgoals is None:
            subgoals = subgoal_logits.argmax(-1)
        actions = self.action_head(torch.cat([out, self.subgoal_emb(subgoals)], dim=-1))
        return actions, subgoal_logits, hidden

    @torch.no_grad()
    def step(self, states, prev_actions, hidden=None):
        """Acting: one step of N episodes, states (N, d), prev_actions (N,); returns action logits (N, n_actions),
        sub-goal logits (N, V) or None, and the recurrent state (as :meth:`forward`'s). The same numbers as
        :meth:`forward` up to rounding (tested), every product on OpenBLAS (:func:`recurrent_step`): torch's fused
        LSTM runs oneDNN's RNN code, whose bytes follow the CPU and which takes about 2 ms a step at a few
        episodes."""
        x = self.embed_states(states) + self.prev_action_emb(prev_actions)
        out, hidden = recurrent_step(self.rnn, x, hidden)
        if not self.cfg.hierarchical:
            return _dense(self.action_head, out), None, hidden
        subgoal_logits = _dense(self.subgoal_head, out)
        subgoals = subgoal_logits.argmax(-1)
        return _dense(self.action_head, torch.cat([out, self.subgoal_emb(subgoals)], dim=-1)), subgoal_logits, hidden

    def loss(self, batch: dict) -> torch.Tensor:
        """Masked cross-entropy of the actions, plus that of the sub-goals for the hierarchical controller, over a
        batch of right-padded episodes. An LSTM's batch goes through the network in groups of like length where
        that costs less (:func:`length_groups`), each group cut to its longest: a step never reads the padding
        after it, so this is the one padded pass's loss and gradient up to rounding (tested), without most of the
        padding's work. (A GRU's cost is mostly its per-step work, which groups only repeat: one pass.)"""
        mask = batch["mask"]
        total = mask.reshape(-1).float().sum().clamp(min=1.0)
        costs = GROUP_COSTS[self.cfg.cell]
        lengths = mask.sum(1).cpu().numpy() if costs else None
        groups = length_groups(lengths, *costs) if costs else []
        if len(groups) <= 1:
            return self._nll_sum(batch) / total
        parts = ({k: v[torch.from_numpy(rows).to(mask.device), :lengths[rows[0]]] for k, v in batch.items()}
                 for rows in groups)  # (each group's rows longest first)
        return sum(self._nll_sum(part) for part in parts) / total

    def _nll_sum(self, batch: dict) -> torch.Tensor:
        logits, sub_logits, _ = self(batch["states"], batch["prev_actions"], batch.get("subgoals"))
        nll = F.cross_entropy(logits.reshape(-1, self.n_actions), batch["actions"].reshape(-1), reduction="none")
        if sub_logits is not None:
            nll = nll + F.cross_entropy(sub_logits.reshape(-1, self.n_subgoals), batch["subgoals"].reshape(-1),
                                        reduction="none")
        return (nll * batch["mask"].reshape(-1).float()).sum()


# What a group of episodes costs a cell's recurrent layers, in episode-steps (:func:`length_groups`): its rows times
# its longest length, plus (per time step, rows' worth; per group, episode-steps' worth) the fixed work of oneDNN's
# calls. None: one padded pass. Chosen with `python benchmarks/recurrent_groups.py` on the pipeline's batches: they
# decide only how a batch is split — the speed and the gradient's rounding —, so they are constants, the same on
# every machine.
GROUP_COSTS = {"lstm": (4, 150), "gru": None}


def length_groups(lengths: np.ndarray, step_cost: float, group_cost: float) -> list[np.ndarray]:
    """A batch's rows (episodes of ``lengths``) split into groups of like length, longest first, each group's
    rows longest first: of the splits of the rows sorted by length, the one that costs least — a group
    ``longest * (rows + step_cost) + group_cost`` — by dynamic programming over where groups end."""
    order = np.argsort(-np.asarray(lengths), kind="stable")
    longest = np.asarray(lengths)[order]  # a group starting at i is padded to longest[i]
    n = len(order)
    cost, start = np.full(n + 1, np.inf), np.zeros(n + 1, dtype=np.int64)
    cost[0] = 0.0
    for end in range(1, n + 1):
        for i in range(end):
            c = cost[i] + float(longest[i]) * (end - i + step_cost) + group_cost
            if c < cost[end]:
                cost[end], start[end] = c, i
    groups, end = [], n
    while end:
        groups.append(order[start[end]:end])
        end = start[end]
    return groups[::-1]


def _dense(head: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """A head (a Linear, or a Sequential of Linear and ReLU) on :func:`kernels.linear`."""
    for layer in (head if isinstance(head, nn.Sequential) else [head]):
        x = linear(x, layer.weight, layer.bias) if isinstance(layer, nn.Linear) else layer(x)
    return x


def recurrent_step(rnn: nn.LSTM | nn.GRU, x: torch.Tensor, hidden=None):
    """One time step of ``rnn`` (eval mode, ``batch_first``) on inputs x (N, d): ``(out (N, h), hidden)``, hidden as
    torch's (``(h, c)`` of (layers, N, h) each for an LSTM, (layers, N, h) for a GRU; None = zeros). The gate
    equations of torch's documentation, each product on :func:`kernels.linear`, tanh on :func:`kernels.tanh`."""
    n, lstm = len(x), isinstance(rnn, nn.LSTM)
    zeros = torch.zeros(rnn.num_layers, n, rnn.hidden_size, dtype=x.dtype, device=x.device)
    if hidden is None:
        hidden = (zeros, zeros.clone()) if lstm else zeros
    hs, cs = [], []
    for k in range(rnn.num_layers):
        w_ih, w_hh, b_ih, b_hh = (getattr(rnn, f"{name}_l{k}") for name in ("weight_ih", "weight_hh", "bias_ih",
                                                                             "bias_hh"))
        h = hidden[0][k] if lstm else hidden[k]
        gi, gh = linear(x, w_ih, b_ih), linear(h, w_hh, b_hh)
        if lstm:
            i, f, g, o = (gi + gh).chunk(4, dim=1)
            c = torch.sigmoid(f) * hidden[1][k] + torch.sigmoid(i) * tanh(g)
            x = torch.sigmoid(o) * tanh(c)
            cs.append(c)
        else:
            i_r, i_z, i_n = gi.chunk(3, dim=1)
            h_r, h_z, h_n = gh.chunk(3, dim=1)
            r, z = torch.sigmoid(i_r + h_r), torch.sigmoid(i_z + h_z)
            x = (1 - z) * tanh(i_n + r * h_n) + z * h
        hs.append(x)  # (no dropout between layers: eval mode)
    return x, ((torch.stack(hs), torch.stack(cs)) if lstm else torch.stack(hs))
