"""The decision transformer of Appendix C: a decoder-only causal transformer over a window of h steps.

Two conditionings share one network:

* ``condition="subgoal"`` (HNSDT): one sub-goal token ``g = ψ(o)`` (operator id + target cell, its own
  embeddings) leads the window. The loss only counts steps whose own sub-goal is ``g`` (a window that starts
  in an earlier operator's segment still gives its history as context).
* ``condition="return"`` (our pure DT baseline, as in the original decision transformer): each step also
  carries its return-to-go ``R_k``; no sub-goals.
* ``condition="none"`` (the paper's pure DT, Appendix C: "g≤t remains empty"): states and actions only.

Two token layouts (``tokens``):

* ``"step"`` (default): one token per step, ``x_k = s_k + a_{k-1} (+ R_k)``, so a window is the paper's
  "h + 1 tokens if one counts sub-goal embeddings" (Appendix C) — ``[g, x_1, ..., x_h]`` — and each ``x_k``
  predicts ``a_k``. The previous action of a window's first step, and of an episode's first step, is a
  learned "none" action. 2× (sub-goal) to 3× (return) fewer tokens than interleaving, which is where the
  training and acting speed comes from (``benchmarks/dt_speed.py``).
* ``"interleaved"``: Chen et al.'s layout, one token per element: ``[g, s_1, a_1, ..., s_h]`` or
  ``[R_1, s_1, a_1, ..., R_h, s_h]``; every state token predicts its action.

States are integer vectors (row, col, flags): row and column have embedding tables, flags a linear map. Every
token of step k also gets the embedding of its episode timestep. The action head is a categorical over the 5
actions; training minimises its negative log-likelihood.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.envs.dynamics import N_ACTIONS  # the world's actions (the Actions enum), the head's outputs
from hnsdt.models.network import Network
from hnsdt.symbolic.subgoals import VOCAB_SIZE

CONDITIONS = ("subgoal", "return", "none")
TOKEN_LAYOUTS = ("step", "interleaved")
NO_ACTION = N_ACTIONS  # "step" layout: the previous action of a window's or an episode's first step


@dataclass
class DTConfig:
    condition: str  # "subgoal" (HNSDT), "return" (our pure DT) or "none" (the paper's pure DT)
    n_flags: int
    grid_h: int
    grid_w: int
    context: int = 10  # h: steps of (state, action) history in a window
    n_layers: int = 3
    n_heads: int = 4
    d_model: int = 128
    dropout: float = 0.1
    max_timestep: int = 256
    return_scale: float = 10.0  # returns-to-go are divided by this before embedding
    tokens: str = "step"  # "step" = one token per step (state + previous action); "interleaved" = one per element

    def __post_init__(self):
        if self.condition not in CONDITIONS:
            raise ValueError(f"condition must be one of {CONDITIONS}, got {self.condition!r}")
        if self.tokens not in TOKEN_LAYOUTS:
            raise ValueError(f"tokens must be one of {TOKEN_LAYOUTS}, got {self.tokens!r}")
        if self.d_model % self.n_heads:
            raise ValueError(f"d_model {self.d_model} is not divisible by n_heads {self.n_heads}")

    @property
    def tokens_per_step(self) -> int:
        if self.tokens == "step":
            return 1
        return 3 if self.condition == "return" else 2

    @property
    def seq_len(self) -> int:
        """Tokens in a window, without the final action (which is what is predicted)."""
        extra = 1 if self.condition == "subgoal" else 0
        last = 0 if self.tokens == "step" else 1  # interleaved windows drop the final action token
        return extra + self.tokens_per_step * self.context - last

    def to_dict(self) -> dict:
        return asdict(self)


class DecisionTransformer(Network, arch="decision_transformer", config=DTConfig):
    def __init__(self, cfg: DTConfig):
        super().__init__(cfg)
        d = cfg.d_model
        self.row_emb = nn.Embedding(cfg.grid_h, d)
        self.col_emb = nn.Embedding(cfg.grid_w, d)
        self.flag_proj = nn.Linear(max(cfg.n_flags, 1), d, bias=False)
        self.action_emb = nn.Embedding(N_ACTIONS + (cfg.tokens == "step"), d)  # + NO_ACTION
        self.time_emb = nn.Embedding(cfg.max_timestep + 1, d)
        if cfg.condition == "subgoal":
            self.subgoal_emb = nn.Embedding(VOCAB_SIZE, d)
            self.target_row_emb = nn.Embedding(cfg.grid_h + 1, d)  # index 0 = no target
            self.target_col_emb = nn.Embedding(cfg.grid_w + 1, d)
        elif cfg.condition == "return":
            self.return_proj = nn.Linear(1, d)
        self.type_emb = nn.Embedding(3, d)  # state, action, condition: the model tells token kinds apart
        self.pad_emb = nn.Parameter(torch.zeros(d))
        layer = nn.TransformerEncoderLayer(d, cfg.n_heads, 4 * d, cfg.dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, cfg.n_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(d)
        self.head = nn.Linear(d, N_ACTIONS)
        self.drop = nn.Dropout(cfg.dropout)
        self.register_buffer("causal_mask", nn.Transformer.generate_square_subsequent_mask(cfg.seq_len),
                             persistent=False)

    def embed_states(self, states: torch.Tensor) -> torch.Tensor:
        flags = states[..., 2:].float() if self.cfg.n_flags else states[..., :1].float() * 0
        return self.row_emb(states[..., 0]) + self.col_emb(states[..., 1]) + self.flag_proj(flags)

    def forward(self, states, actions, timesteps, pad, subgoal_ids=None, subgoal_targets=None, returns=None):
        """Action logits (B, h, 5), one per state of the window.

        states (B, h, d) int64; actions (B, h) int64 (the last one is never read); timesteps (B, h) int64;
        pad (B, h) bool marks steps before the episode began (windows are left-padded); subgoal_ids (B,) and
        subgoal_targets (B, 2) for ``subgoal``; returns (B, h) float for ``return``; neither for ``none``.
        Padded steps become a learned pad token, identically in training and at inference, so no attention mask
        is needed."""
        cfg = self.cfg
        B, h = actions.shape
        time = self.time_emb(timesteps.clamp(0, cfg.max_timestep))
        keep = (~pad)[..., None].float()
        if cfg.condition == "subgoal":
            tgt = subgoal_targets + 1  # -1 (none) -> 0
            g = (self.subgoal_emb(subgoal_ids) + self.target_row_emb(tgt[:, 0]) + self.target_col_emb(tgt[:, 1])
                 + self.type_emb.weight[2])
        if cfg.tokens == "step":
            prev = torch.full_like(actions, NO_ACTION)
            prev[:, 1:] = torch.where(pad[:, :-1], NO_ACTION, actions[:, :-1])
            x = self.embed_states(states) + self.action_emb(prev) + time + self.type_emb.weight[0]
            if cfg.condition == "return":
                x = x + self.return_proj(returns[..., None] / cfg.return_scale)
            seq = x * keep + self.pad_emb * (1 - keep)
            if cfg.condition == "subgoal":
                seq = torch.cat([g[:, None], seq], dim=1)
            x = self.blocks(self.drop(seq), mask=self.causal_mask, is_causal=True)
            return self.head(self.norm(x[:, seq.shape[1] - h:]))
        s_tok = (self.embed_states(states) + time + self.type_emb.weight[0]) * keep + self.pad_emb * (1 - keep)
        a_tok = (self.action_emb(actions) + time + self.type_emb.weight[1]) * keep + self.pad_emb * (1 - keep)
        if cfg.condition != "return":
            steps = torch.stack([s_tok, a_tok], dim=2).reshape(B, 2 * h, -1)[:, :-1]  # the last action is the target
            lead = int(cfg.condition == "subgoal")
            seq = torch.cat([g[:, None], steps], dim=1) if lead else steps
            state_pos = lead + 2 * torch.arange(h, device=seq.device)
        else:
            r_tok = self.return_proj(returns[..., None] / cfg.return_scale) + time + self.type_emb.weight[2]
            r_tok = r_tok * keep + self.pad_emb * (1 - keep)
            steps = torch.stack([r_tok, s_tok, a_tok], dim=2).reshape(B, 3 * h, -1)
            seq = steps[:, :-1]
            state_pos = 1 + 3 * torch.arange(h, device=seq.device)
        x = self.blocks(self.drop(seq), mask=self.causal_mask, is_causal=True)
        return self.head(self.norm(x[:, state_pos]))

    def loss(self, batch: dict) -> torch.Tensor:
        logits = self(batch["states"], batch["actions"], batch["timesteps"], batch["pad"], batch.get("subgoal_ids"),
                      batch.get("subgoal_targets"), batch.get("returns"))
        nll = F.cross_entropy(logits.reshape(-1, N_ACTIONS), batch["actions"].reshape(-1), reduction="none")
        mask = batch["loss_mask"].reshape(-1).float()
        return (nll * mask).sum() / mask.sum().clamp(min=1.0)
