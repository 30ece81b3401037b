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

Two formulations (``formulation``) of what one training example and one decision are:

* ``"window"`` (the paper's, Appendix C): an example is a window of the last h steps ending at a frame, cut
  anew for every frame, so a step is recomputed in up to h windows; each decision recomputes the whole window.
  The sub-goal token leads the window and conditions every step in it.
* ``"episode"``: an example is a whole episode, attention limited to the last h steps (sliding-window
  attention, computed block by block: :func:`banded_attention`), so every step's prediction comes out of one
  pass and each step is computed once (a training batch's episodes packed end to end, so no padding is
  computed: :meth:`DecisionTransformer.forward_episode`); at inference a key/value cache of the last h steps makes a decision one new token
  (:meth:`DecisionTransformer.step`). Each step token carries its own conditioning (its sub-goal and target,
  or its return-to-go) instead of one leading token; a step sees h steps back per layer, so through L layers
  information reaches L·(h − 1) steps back, where a window cuts it at h. ``"step"`` tokens only.

States are integer vectors (row, col, flags): row and column have embedding tables, flags a linear map. Every
token of step k also gets the embedding of its episode timestep. The action head is a categorical over the 5
actions; training minimises its negative log-likelihood.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.envs.dynamics import N_ACTIONS  # the world's actions (the Actions enum), the head's outputs
from hnsdt.models.kernels import Linear, attention, gelu, linear
from hnsdt.models.network import Network
from hnsdt.models.windows import FORMULATIONS
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
    formulation: str = "window"  # "window" = an example per frame (its last h steps); "episode" = whole episodes,
    #                              attention banded to h steps, a key/value cache at inference

    def __post_init__(self):
        if self.condition not in CONDITIONS:
            raise ValueError(f"condition must be one of {CONDITIONS}, got {self.condition!r}")
        if self.tokens not in TOKEN_LAYOUTS:
            raise ValueError(f"tokens must be one of {TOKEN_LAYOUTS}, got {self.tokens!r}")
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, got {self.formulation!r}")
        if self.formulation == "episode" and self.tokens != "step":
            raise ValueError("formulation 'episode' needs tokens 'step' (one token per step)")
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
    n_actions = N_ACTIONS  # the head's outputs; NO_ACTION (the "none" previous action) is this index. A network for
    #                        a world with other actions (MiniGrid's 7: hnsdt.models.minigrid_nets) sets its own

    def __init__(self, cfg: DTConfig):
        super().__init__(cfg)
        d = cfg.d_model
        self.build_state_encoder(d)
        self.action_emb = nn.Embedding(self.n_actions + (cfg.tokens == "step"), d)  # + NO_ACTION
        self.time_emb = nn.Embedding(cfg.max_timestep + 1, d)
        if cfg.condition == "subgoal":
            self.build_subgoal_encoder(d)
        elif cfg.condition == "return":
            self.return_proj = Linear(1, d)
        self.type_emb = nn.Embedding(3, d)  # state, action, condition: the model tells token kinds apart
        self.pad_emb = nn.Parameter(torch.zeros(d))
        layer = nn.TransformerEncoderLayer(d, cfg.n_heads, 4 * d, cfg.dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, cfg.n_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(d)
        self.head = Linear(d, self.n_actions)
        self.drop = nn.Dropout(cfg.dropout)
        self.register_buffer("causal_mask", nn.Transformer.generate_square_subsequent_mask(cfg.seq_len),
                             persistent=False)

    def build_state_encoder(self, width: int) -> None:
        """The part that turns a state into a ``width``-vector (:meth:`embed_states`), built first: here the
        paper's state, ``(row, col)`` embeddings plus a linear map of the flags. A network that reads states
        another way builds its own part here (:mod:`hnsdt.models.view`)."""
        cfg = self.cfg
        self.row_emb = nn.Embedding(cfg.grid_h, width)
        self.col_emb = nn.Embedding(cfg.grid_w, width)
        self.flag_proj = Linear(max(cfg.n_flags, 1), width, bias=False)

    def build_subgoal_encoder(self, width: int) -> None:
        """The sub-goal token's embeddings (:meth:`embed_subgoals`): the operator id and its target cell."""
        cfg = self.cfg
        self.subgoal_emb = nn.Embedding(VOCAB_SIZE, width)
        self.target_row_emb = nn.Embedding(cfg.grid_h + 1, width)  # index 0 = no target
        self.target_col_emb = nn.Embedding(cfg.grid_w + 1, width)

    def embed_states(self, states: torch.Tensor, targets: torch.Tensor | None = None) -> torch.Tensor:
        """(…, d_model) of states; ``targets`` (each step's absolute sub-goal target, -1: none) is there for a
        state encoder that plans towards it (:mod:`hnsdt.models.view`); this one does not read it."""
        flags = states[..., 2:].float() if self.cfg.n_flags else states[..., :1].float() * 0
        return self.row_emb(states[..., 0]) + self.col_emb(states[..., 1]) + self.flag_proj(flags)

    def subgoal_targets(self, states: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """The target cells the sub-goal embedding reads, given the agent's states at the same steps (here: the
        absolute cells; the view networks make them relative to the agent)."""
        return targets

    def embed_subgoals(self, ids: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        tgt = targets + 1  # -1 (none) -> 0
        return self.subgoal_emb(ids) + self.target_row_emb(tgt[..., 0]) + self.target_col_emb(tgt[..., 1])

    def step_tokens(self, states, prev_actions, timesteps, subgoal_ids=None, subgoal_targets=None, returns=None):
        """The episode formulation's token of each step: state + previous action + timestep + its own
        conditioning (sub-goal and target, or return-to-go)."""
        cfg = self.cfg
        x = (self.embed_states(states, subgoal_targets if cfg.condition == "subgoal" else None)
             + self.action_emb(prev_actions)
             + self.time_emb(timesteps.clamp(0, cfg.max_timestep)) + self.type_emb.weight[0])
        if cfg.condition == "subgoal":
            x = x + self.embed_subgoals(subgoal_ids, self.subgoal_targets(states, subgoal_targets))
        elif cfg.condition == "return":
            x = x + self.return_proj(returns[..., None] / cfg.return_scale)
        return x

    def forward_episode(self, states, actions, timesteps, subgoal_ids=None, subgoal_targets=None, returns=None,
                        steps=None):
        """Action logits (B, T, 5) of whole episodes (right-padded: causal attention never reads a later pad);
        subgoal_ids (B, T), subgoal_targets (B, T, 2), returns (B, T): each step's own. ``steps`` (B, T) bool,
        the real steps: the episodes are packed end to end into one sequence first, attention kept within
        each, so no padding is computed (the logits of pads are then 0)."""
        prev = torch.full_like(actions, self.n_actions)  # (NO_ACTION)
        prev[:, 1:] = actions[:, :-1]
        inputs, segments = (states, prev, timesteps, subgoal_ids, subgoal_targets, returns), None
        if steps is not None:
            segments = torch.arange(len(steps), device=steps.device)[:, None].expand_as(steps)[steps][None]
            inputs = [None if t is None else t[steps][None] for t in inputs]
        x = self.drop(self.step_tokens(*inputs))
        for layer in self.blocks.layers:
            x = banded_layer(layer, x, self.cfg.context, segments)
        logits = _head(self, x)
        if steps is None:
            return logits
        return logits.new_zeros(*steps.shape, logits.shape[-1]).masked_scatter(steps[..., None], logits[0])

    def start(self, n: int) -> "StepCache":
        """An empty key/value cache for ``n`` episodes (episode formulation, eval mode)."""
        return StepCache(self, n)

    @torch.no_grad()
    def step(self, cache: "StepCache", rows, states, prev_actions, timesteps, subgoal_ids=None,
             subgoal_targets=None, returns=None) -> torch.Tensor:
        """Action logits (len(rows), 5) of the next step of episodes ``rows``: one token each through every
        layer, attending to the cached keys and values of their last h − 1 steps; the same numbers as
        :meth:`forward_episode` on the whole episode (tested)."""
        x = self.step_tokens(states, prev_actions, timesteps, subgoal_ids, subgoal_targets, returns)
        slot, valid = cache.advance(rows)
        if int(rows[-1]) == len(rows) - 1 and bool((slot == slot[0]).all()):  # rows 0 … n − 1 at one step (as
            slot = int(slot[0])  # CachedContext steps them): every layer writes and reads its cache as views
        mask = torch.zeros(valid.shape, device=x.device).masked_fill(~valid, float("-inf"))[:, None, None, :]
        for i, layer in enumerate(self.blocks.layers):
            x = cached_layer(layer, x, cache.keys[i], cache.values[i], rows, slot, mask)
        return _head(self, x)

    def forward(self, states, actions, timesteps, pad, subgoal_ids=None, subgoal_targets=None, returns=None,
                steps=None):
        """Action logits (B, h, 5), one per state of the window (episode formulation: per step of the episode,
        each conditioning argument per step, ``pad`` unused).

        states (B, h, d) int64; actions (B, h) int64 (the last one is never read); timesteps (B, h) int64;
        pad (B, h) bool marks steps before the episode began (windows are left-padded); subgoal_ids (B,) and
        subgoal_targets (B, 2) for ``subgoal``; returns (B, h) float for ``return``; neither for ``none``.
        Padded steps become a learned pad token, identically in training and at inference, so no attention mask
        is needed. ``steps``: the episode formulation's real steps, packed (:meth:`forward_episode`)."""
        cfg = self.cfg
        if cfg.formulation == "episode":
            return self.forward_episode(states, actions, timesteps, subgoal_ids, subgoal_targets, returns, steps)
        B, h = actions.shape
        time = self.time_emb(timesteps.clamp(0, cfg.max_timestep))
        keep = (~pad)[..., None].float()
        if cfg.condition == "subgoal":
            g = self.embed_subgoals(subgoal_ids, self.subgoal_targets(states[:, -1], subgoal_targets))
            g = g + self.type_emb.weight[2]
        if cfg.tokens == "step":
            prev = torch.full_like(actions, self.n_actions)  # (NO_ACTION)
            prev[:, 1:] = torch.where(pad[:, :-1], self.n_actions, actions[:, :-1])
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
        logits = self(batch["states"], batch["actions"], batch["timesteps"], batch.get("pad"), batch.get("subgoal_ids"),
                      batch.get("subgoal_targets"), batch.get("returns"), batch.get("steps"))
        nll = F.cross_entropy(logits.reshape(-1, self.n_actions), batch["actions"].reshape(-1), reduction="none")
        mask = batch["loss_mask"].reshape(-1).float()
        return (nll * mask).sum() / mask.sum().clamp(min=1.0)


def band_mask(n: int, context: int, device=None) -> torch.Tensor:
    """(n, n) additive mask: step j attends to steps j − context < i ≤ j."""
    i = torch.arange(n, device=device)
    d = i[:, None] - i[None, :]
    return torch.zeros(n, n, device=device).masked_fill((d < 0) | (d >= context), float("-inf"))


@lru_cache(maxsize=64)  # built once per episode length, not per layer and batch; SDPA only reads it
def _block_mask(blocks: int, context: int, device) -> torch.Tensor:
    """(blocks, h, 2h) additive mask of :func:`banded_attention`: query a of a block attends to keys a + 1 …
    a + h of its previous block and itself (the last h steps up to its own); block 0 has no previous block."""
    a, b = torch.arange(context, device=device)[:, None], torch.arange(2 * context, device=device)[None, :]
    mask = torch.zeros(blocks, context, 2 * context, device=device).masked_fill((b <= a) | (b > a + context),
                                                                                 float("-inf"))
    mask[0, :, :context] = float("-inf")
    return mask


def banded_attention(q, k, v, context: int, dropout_p: float = 0.0, segments=None) -> torch.Tensor:
    """Causal attention to the last ``context`` steps of (B, heads, T, d) queries, keys and values, computed
    block by block: the steps are cut into blocks of h, and each block's queries attend to the keys of that
    block and the one before (2h keys, masked to each query's own h) — 2h·T scores instead of the T² that
    :func:`band_mask` over the whole episode computes and mostly masks away. The same numbers up to rounding
    (tested). ``segments`` (B, T): each step's episode, when several lie end to end in a row; a step attends to
    its own episode's only."""
    B, H, T, d = q.shape
    blocks = -(-T // context)
    if blocks * context != T:  # right-pad to whole blocks: the pad comes after every real step, never read
        q, k, v = (F.pad(t, (0, 0, 0, blocks * context - T)) for t in (q, k, v))
    q, k, v = (t.view(B, H, blocks, context, d) for t in (q, k, v))
    k, v = (_previous_and_own(t, dim=3) for t in (k, v))
    mask = _block_mask(blocks, context, q.device)
    if segments is not None:  # (pads: segment -1, their own, so that no row of scores is all masked)
        own = F.pad(segments, (0, blocks * context - T), value=-1).view(B, blocks, context)
        other = own[..., :, None] != _previous_and_own(own[..., None], dim=2)[..., 0][..., None, :]
        mask = (torch.zeros(other.shape, device=q.device).masked_fill(other, float("-inf")) + mask)[:, None]
    out = attention(q, k, v, mask, dropout_p)
    return out.reshape(B, H, blocks * context, d)[:, :, :T]


def _previous_and_own(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Blocks (along ``dim - 1``) of ``t`` each joined along ``dim`` to the block before (zeros before block 0)."""
    before = [0, 0] * (t.dim() - dim) + [1, 0]  # F.pad's (last dim first) pairs: one block in front along dim - 1
    return torch.cat([F.pad(t.narrow(dim - 1, 0, t.shape[dim - 1] - 1), before), t], dim=dim)


def banded_layer(layer: nn.TransformerEncoderLayer, x, context: int, segments=None) -> torch.Tensor:
    """One pre-norm encoder layer on whole (B, T, d) episodes, attention limited to the last ``context`` steps
    (:func:`banded_attention`, within each episode of ``segments``); dropout where ``layer`` applies it, in
    training mode."""
    B, T, d = x.shape
    q, k, v = _qkv(layer, x).permute(2, 0, 3, 1, 4)  # (B, heads, T, d / heads) each
    out = banded_attention(q, k, v, context, layer.self_attn.dropout if layer.training else 0.0, segments)
    out = _apply(layer.self_attn.out_proj, out.transpose(1, 2).reshape(B, T, d))
    return _feed_forward(layer, x + layer.dropout1(out))


def _qkv(layer: nn.TransformerEncoderLayer, x) -> torch.Tensor:
    """The pre-norm layer's queries, keys and values of ``x`` (…, d), as (…, 3, heads, d / heads)."""
    attn = layer.self_attn
    d = x.shape[-1]
    return linear(layer.norm1(x), attn.in_proj_weight, attn.in_proj_bias).unflatten(-1, (3, attn.num_heads,
                                                                                          d // attn.num_heads))


def _feed_forward(layer: nn.TransformerEncoderLayer, x) -> torch.Tensor:
    """The pre-norm layer's second half, residual included (its dropouts act in training mode only)."""
    hidden = layer.dropout(gelu(_apply(layer.linear1, layer.norm2(x))))  # the layer's activation
    return x + layer.dropout2(_apply(layer.linear2, hidden))


def _apply(module: nn.Linear, x) -> torch.Tensor:
    """``module(x)`` on the pinned BLAS kernel (:mod:`hnsdt.models.kernels`)."""
    return linear(x, module.weight, module.bias)


def _head(model: DecisionTransformer, x) -> torch.Tensor:
    """The episode formulation's action logits of the last layer's tokens."""
    return _apply(model.head, model.norm(x))


class StepCache:
    """Keys and values of each episode's last h steps, per layer, in a ring of h slots (attention does not care
    about slot order: a step's position is in its own token, through the timestep embedding)."""

    def __init__(self, model: DecisionTransformer, n: int):
        cfg = model.cfg
        device = next(model.parameters()).device
        shape = (n, cfg.n_heads, cfg.context, cfg.d_model // cfg.n_heads)
        transposed = (n, cfg.n_heads, cfg.d_model // cfg.n_heads, cfg.context)  # keys as the product reads them
        self.keys = [torch.zeros(transposed, device=device) for _ in range(cfg.n_layers)]
        self.values = [torch.zeros(shape, device=device) for _ in range(cfg.n_layers)]
        self.seen = torch.zeros(n, dtype=torch.long, device=device)  # steps each episode has put in the cache
        self.context = cfg.context

    def advance(self, rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The slot of each row's new step and which slots it attends to ((len(rows), h) bool)."""
        t = self.seen[rows]
        self.seen[rows] = t + 1
        valid = torch.arange(self.context, device=t.device)[None, :] <= t[:, None]  # filled slots, this one too
        return t % self.context, valid

    def copy_rows(self, src: torch.Tensor, dst: torch.Tensor) -> None:
        """Rows ``dst`` become copies of rows ``src``: episodes that shared a history part ways."""
        for cached in (*self.keys, *self.values):
            cached[dst] = cached[src]
        self.seen[dst] = self.seen[src]


def cached_layer(layer: nn.TransformerEncoderLayer, x, keys, values, rows, slot, mask) -> torch.Tensor:
    """One pre-norm encoder layer (eval mode) on one new token per row, its key and value written into the
    cache: the same computation as ``layer`` on the whole sequence under :func:`band_mask`. ``rows``: the
    cache rows of ``x``, sorted and distinct; ``mask``: additive, (n, 1, 1, h); ``keys`` transposed
    ((N, heads, d / heads, h): the attention's product reads them so, without a copy); ``slot``: each row's
    slot, or one for all when ``rows`` are 0 … n − 1."""
    n, d = x.shape
    q, k, v = _qkv(layer, x).unbind(1)  # (n, heads, d / heads) each
    if isinstance(slot, int):
        keys, values = keys[:n], values[:n]
        keys[..., slot], values[:, :, slot] = k, v
    else:
        keys[rows, :, :, slot], values[rows, :, slot] = k, v
        if n < len(keys):  # some rows are idle: read the first n if they are the live ones, else gather them
            keys, values = (keys[:n], values[:n]) if int(rows[-1]) == n - 1 else (keys[rows], values[rows])
    out = attention(q[:, :, None], keys.transpose(-1, -2), values, mask)
    return _feed_forward(layer, x + _apply(layer.self_attn.out_proj, out.reshape(n, d)))
