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
from hnsdt.models.kernels import Linear
from hnsdt.models.plan import MapPlanner, taps
from hnsdt.models.qnetwork import (ActorCritic, ActorCriticConfig, OptionCritic, OptionCriticConfig, QNetwork,
                                   QNetworkConfig)
from hnsdt.models.recurrent import RecurrentConfig, RecurrentPolicy


def split_states(states: torch.Tensor, radius: int, n_flags: int | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """``(codes (…, cells) int64, flags (…, n_flags) float)`` of view state vectors (``n_flags``: where the
    whole map follows them; None: the flags run to the end)."""
    cells = (2 * radius + 1) ** 2
    end = None if n_flags is None else 2 + cells + n_flags
    return states[..., 2:2 + cells], states[..., 2 + cells:end].float()


class ValueIteration(nn.Module):
    """A value-iteration network's planning module (Tamar et al. 2016) over the view, towards a marked target
    cell: a reward map from each cell's features and the mark, then ``iterations`` Bellman backups — a 3 × 3
    convolution of reward and value into ``channels`` action values, the value their maximum — with weights
    shared across iterations, so a value spreads ``iterations`` cells around walls. Read out at the agent's
    (centre) cell: its action values and its four neighbours' values."""

    def __init__(self, in_channels: int, iterations: int, channels: int, hidden: int = 32):
        super().__init__()
        self.iterations = iterations
        self.reward = nn.Sequential(nn.Conv2d(in_channels + 1, hidden, 3, padding=1), nn.ReLU(),
                                    nn.Conv2d(hidden, 1, 1))
        self.q_from_reward = nn.Conv2d(1, channels, 3, padding=1, bias=False)
        self.q_from_value = nn.Conv2d(1, channels, 3, padding=1, bias=False)  # its weight, applied via _taps
        self.out_features = channels + 4

    def forward(self, grid: torch.Tensor, mark: torch.Tensor) -> torch.Tensor:
        """grid (N, C, S, S), mark (N, 1, S, S) → (N, channels + 4)."""
        q_reward = self.q_from_reward(self.reward(torch.cat([grid, mark], dim=1)))
        weight = self.q_from_value.weight.reshape(-1, 9)
        backup = lambda value: q_reward + torch.einsum("ck,nkhw->nchw", weight, taps(value))  # noqa: E731
        value = q_reward.max(dim=1, keepdim=True).values
        for _ in range(self.iterations):
            value = backup(value).max(dim=1, keepdim=True).values
        q = backup(value)
        c = grid.shape[-1] // 2
        near = value[:, 0, [c - 1, c + 1, c, c], [c, c, c - 1, c + 1]]  # up, down, left, right of the agent
        return torch.cat([q[:, :, c, c], near], dim=-1)


class ViewEncoder(nn.Module):
    """A learned embedding of each cell's code, then (``conv_layers`` > 0) 3 × 3 convolutions over the view —
    features computed the same way wherever they sit, so a wall next to a corridor reads alike in any corner of
    the view — the result flattened and projected, plus a linear map of the flags: one ``width``-vector per
    state. With ``value_iterations`` > 0 the view is planned over instead (:class:`ValueIteration`, the
    target marked): the agent's 3 × 3 neighbourhood and the plan's read-out are projected. With ``whole_map``
    the state vectors end with the whole map (:func:`hnsdt.envs.observation.view_states`' ``map_side``) and a
    planning module over it (:class:`hnsdt.models.plan.MapPlanner`) adds its read-out, projected."""

    def __init__(self, radius: int, code_dim: int, n_flags: int, width: int, conv_layers: int = 0,
                 conv_channels: int = 32, value_iterations: int = 0, value_channels: int = 8,
                 whole_map: bool = False, plan_channels: int = 8, plan_backup: str = "moves",
                 plan_goal: str = "target", plan_block: bool = True):
        super().__init__()
        self.radius, self.n_flags = radius, n_flags
        self.code_emb = nn.Embedding(N_CODES, code_dim)
        self.convs = None  # (no convolutions: the parameters, and so the bytes, of the flattened encoder)
        if conv_layers:
            widths = [code_dim] + [conv_channels] * conv_layers
            self.convs = nn.Sequential(*(layer for a, b in zip(widths, widths[1:])
                                         for layer in (nn.Conv2d(a, b, 3, padding=1), nn.ReLU())))
        channels = conv_channels if conv_layers else code_dim
        self.plan = None
        if value_iterations:
            self.plan = ValueIteration(channels, value_iterations, value_channels)
            self.view_proj = Linear(9 * channels + self.plan.out_features, width)
        else:
            self.view_proj = Linear((2 * radius + 1) ** 2 * channels, width)
        self.flag_proj = Linear(max(n_flags, 1), width, bias=False)
        self.map_plan = None
        if whole_map:
            self.map_plan = MapPlanner(code_dim, n_flags, plan_channels, backup=plan_backup, goal=plan_goal,
                                       block=plan_block)
            self.plan_proj = Linear(self.map_plan.out_features, width, bias=False)

    def forward(self, states: torch.Tensor, targets: torch.Tensor | None = None) -> torch.Tensor:
        """``targets`` (…, 2), read only by a planning module: each step's sub-goal target cell (-1: none;
        ``None``: none anywhere)."""
        out = self.embed_view(states, None if targets is None or self.plan is None else self.offsets(states, targets))
        if self.map_plan is None:
            return out
        cells = 2 + (2 * self.radius + 1) ** 2
        flat = states.reshape(-1, states.shape[-1])
        plan = self.map_plan(flat[:, cells + self.n_flags:], flat[:, cells:cells + self.n_flags],
                             None if targets is None else targets.reshape(-1, 2), flat[:, :2])
        # the neighbours' read-out of these steps, from which the model's loss takes the module's own action logits
        # (kept with or without a gradient: a held-out loss is measured under no_grad; acting never reads it)
        self.plan_read = plan[:, -4:]  # (steps, 4)
        return out + self.plan_proj(plan).reshape(*out.shape)

    @staticmethod
    def offsets(states: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """(…, 3): the target's row and column offset from the agent, and 1 where there is a target (0: none)."""
        present = (targets[..., :1] >= 0).long()
        return torch.cat([(targets - states[..., :2]) * present, present], dim=-1)

    def embed_view(self, states: torch.Tensor, targets: torch.Tensor | None = None) -> torch.Tensor:
        """The view and flags; ``targets`` (…, 3), read only with value iterations over the view
        (:meth:`offsets`)."""
        codes, flags = split_states(states, self.radius, self.n_flags)
        if flags.shape[-1] == 0:
            flags = torch.zeros(*flags.shape[:-1], 1, device=flags.device)
        cells = self.code_emb(codes)  # (..., cells, code_dim)
        if self.convs is None and self.plan is None:
            features = cells.flatten(-2)
        else:
            side, r = 2 * self.radius + 1, self.radius
            grid = cells.reshape(-1, side, side, cells.shape[-1]).permute(0, 3, 1, 2)
            if self.convs is not None:
                grid = self.convs(grid)
            if self.plan is None:
                features = grid.permute(0, 2, 3, 1).flatten(1)
            else:
                around = grid[:, :, r - 1:r + 2, r - 1:r + 2].flatten(1)  # the agent's 3 x 3 cells
                plan = self.plan(grid, self.target_mark(targets, grid.shape[0], grid.device))
                features = torch.cat([around, plan], dim=-1)
            features = features.reshape(*codes.shape[:-1], -1)
        return self.view_proj(features) + self.flag_proj(flags)

    def target_mark(self, targets: torch.Tensor | None, n: int, device) -> torch.Tensor:
        """(n, 1, side, side): 1 at the target's cell of the view (a target beyond the view at its edge, the
        direction kept), all 0 where there is none."""
        side, r = 2 * self.radius + 1, self.radius
        mark = torch.zeros(n, side * side, device=device)
        if targets is not None:
            targets = targets.reshape(n, 3)
            cell = (targets[:, 0].clamp(-r, r) + r) * side + targets[:, 1].clamp(-r, r) + r
            mark[torch.arange(n, device=device), cell] = targets[:, 2].float()
        return mark.reshape(n, 1, side, side)


class ViewModel:
    """What every view network adds to its base: it reads view states made from the environment's
    observations and the layout."""

    cfg: object

    def model_states(self, layout: Layout, obs: np.ndarray) -> np.ndarray:
        side = 0
        if getattr(self.cfg, "whole_map", False):  # (several layouts: one square that holds each)
            side = max(max(lay.shape) for lay in ((layout,) if isinstance(layout, Layout) else layout))
        return view_states(layout, obs, self.cfg.view_radius, side)


# -- symmetries: the same episodes on the map turned and mirrored ----------------------------------------

SYMMETRIES = (1, 4, 8)  # none; the four quarter turns; those and their mirror images
FAR = 4096  # turned cells are (col, FAR - row): never negative (-1 means "no target"), offsets between them exact


def turn_episodes(batch: dict[str, np.ndarray], radius: int, k: np.ndarray, n_flags: int | None = None
                  ) -> dict[str, np.ndarray]:
    """Episodes of view states (:func:`hnsdt.models.windows.make_episodes`) as they would have run on their map
    turned ``k % 4`` quarter turns clockwise, then mirrored left to right when ``k >= 4`` (``k``: one per
    episode): the world's rules are the same in every direction, so each is an episode of that map. The views
    turn with the map, the moves turn with it (up becomes right), the agent's cell and the sub-goal targets turn
    about a far origin, so the offsets between them — all a view network reads of them — are the turned ones.
    Flags, picks, timesteps and the conditioning's ids and returns stay; so do the markers of "no action yet"
    (``prev_actions`` of the recurrent controllers). States that end with the whole map (after ``n_flags``
    flags) turn it too, and their cells turn within its square, so they stay its cells."""
    out = dict(batch)
    side = 2 * radius + 1
    states = batch["states"].copy()
    codes = states[..., 2:2 + side * side].reshape(*states.shape[:-1], side, side)
    start = 2 + side * side + (n_flags or 0)
    map_side = int(round((states.shape[-1] - start) ** 0.5)) if n_flags is not None else 0
    grids = states[..., start:].reshape(*states.shape[:-1], map_side, map_side) if map_side else None
    far = map_side - 1 if map_side else FAR
    cells = states[..., :2]
    actions = {key: batch[key].copy() for key in ("actions", "prev_actions") if key in batch}
    targets = batch["subgoal_targets"].copy() if "subgoal_targets" in batch else None
    for i, ki in enumerate(np.asarray(k)):
        turns, mirror = int(ki) % 4, int(ki) >= 4
        view = np.rot90(codes[i], k=-turns, axes=(-2, -1))
        codes[i] = view[..., ::-1] if mirror else view
        if grids is not None:
            grid = np.rot90(grids[i], k=-turns, axes=(-2, -1))
            grids[i] = grid[..., ::-1] if mirror else grid
        for a in actions.values():
            turned = (a[i] + turns) % 4
            a[i] = np.where(a[i] < 4, (4 - turned) % 4 if mirror else turned, a[i])  # moves; pick and markers stay
        cells[i] = _turn_cells(cells[i], turns, mirror, far)
        if targets is not None:
            targets[i] = np.where(targets[i] >= 0, _turn_cells(targets[i], turns, mirror, far), targets[i])
    states[..., 2:2 + side * side] = codes.reshape(*states.shape[:-1], side * side)  # (cells: a view of states)
    if grids is not None:
        states[..., start:] = grids.reshape(*states.shape[:-1], map_side * map_side)
    out.update(states=states, **actions)
    if targets is not None:
        out["subgoal_targets"] = targets
    return out


def turned_maps(model_cfg, symmetries: int, seed: int):
    """The training augmentation of ``symmetries`` > 1 (:class:`hnsdt.models.fit.Objective`'s ``augment``): each
    episode of a batch on its map turned (and mirrored) at random (:func:`turn_episodes`), drawn from the seed,
    the epoch and the batch's first episode; None for 1."""
    if symmetries == 1:
        return None
    if symmetries not in SYMMETRIES:
        raise ValueError(f"symmetries must be one of {SYMMETRIES}, got {symmetries}")
    radius = getattr(model_cfg, "view_radius", None)
    if radius is None or getattr(model_cfg, "formulation", "episode") != "episode":
        raise ValueError("symmetries > 1 turns maps: it needs a network that reads views (no absolute cells) and "
                         "whole episodes (the episode formulation)")

    def augment(arrays: dict, rows: np.ndarray, epoch: int) -> dict:
        k = np.random.default_rng([seed, epoch, 4099, int(rows[0])]).integers(0, symmetries, len(rows))
        return turn_episodes(arrays, radius, k, model_cfg.n_flags if getattr(model_cfg, "whole_map", False) else None)
    return augment


def _turn_cells(cells: np.ndarray, turns: int, mirror: bool, far: int = FAR) -> np.ndarray:
    """(…, 2) (row, col) after ``turns`` clockwise quarter turns, (r, c) -> (c, far - r), then the mirror
    (r, c) -> (r, far - c): cells of a square of side ``far`` + 1 stay in it."""
    r, c = cells[..., 0], cells[..., 1]
    for _ in range(turns):
        r, c = c, far - r
    if mirror:
        c = far - c
    return np.stack([r, c], axis=-1)


# -- decision transformer (HNSDT, pure DT) ---------------------------------------------------------------

@dataclass
class ViewDTConfig(DTConfig):
    """``grid_h`` / ``grid_w`` are the target-offset vocabularies: offsets ``-max_offset..max_offset`` with
    ``grid_h = grid_w = 2 * max_offset + 1`` (:func:`view_config`)."""

    view_radius: int = 2
    code_dim: int = 16  # embedding width of one cell code
    conv_layers: int = 0  # 3x3 convolutions over the view before its projection (0: the embeddings flattened)
    conv_channels: int = 32  # their width
    value_iterations: int = 0  # > 0: a value-iteration module plans over the view towards the sub-goal's target
    #                            (ValueIteration), that many backups; needs the episode formulation
    value_channels: int = 8  # its action values per cell
    whole_map: bool = False  # the states end with the whole map and a planning module plans over it towards the
    #                          sub-goal's target (hnsdt.models.plan.MapPlanner); needs the episode formulation
    plan_backup: str = "moves"  # its backup: "moves" (the four moves, each cell's step cost and goal value
    #                             learned) or "kernel" (VIN's learned 3 x 3 kernel; hnsdt.models.plan)
    plan_goal: str = "target"  # (moves) where its values start: the sub-goal's target cell ("target"; a step
    #                            without one, or a DT without sub-goals: each cell's learned goal value) or always
    #                            each cell's learned goal value ("learned")
    plan_block: bool = True  # (moves) a cell whose learned step cost is above the read-out's wall relays no value
    #                          (False: every cell relays, a wall only as dear as its learned cost)
    plan_channels: int = 8  # (kernel) its action values per cell
    plan_loss: float = 1.0  # weight of the module's own imitation loss beside the transformer's (0: end to end
    #                         through the transformer only)
    plan_lr: float = 10.0  # the module's learning rate as a multiple of the transformer's

    def __post_init__(self):
        super().__post_init__()
        if self.value_iterations and self.formulation != "episode":
            raise ValueError("value_iterations > 0 needs formulation 'episode' (each step's own target)")
        if self.whole_map and self.formulation != "episode":
            raise ValueError("whole_map needs formulation 'episode' (each step's own target and map)")

    @property
    def max_offset(self) -> int:
        return (self.grid_h - 1) // 2


def view_config(condition: str, n_flags: int, view_radius: int, max_offset: int, conv_layers: int = 0,
                value_iterations: int = 0, whole_map: bool = False, **sizes) -> ViewDTConfig:
    side = 2 * max_offset + 1
    return ViewDTConfig(condition=condition, n_flags=n_flags, grid_h=side, grid_w=side, view_radius=view_radius,
                        conv_layers=conv_layers, value_iterations=value_iterations, whole_map=whole_map, **sizes)


class ViewDecisionTransformer(ViewModel, DecisionTransformer, arch="view_decision_transformer",
                              config=ViewDTConfig):
    def build_state_encoder(self, width: int) -> None:  # the view, never the absolute cell
        cfg = self.cfg
        self.view = ViewEncoder(cfg.view_radius, cfg.code_dim, cfg.n_flags, width, cfg.conv_layers,
                                cfg.conv_channels, cfg.value_iterations, cfg.value_channels, cfg.whole_map,
                                cfg.plan_channels, cfg.plan_backup, cfg.plan_goal, cfg.plan_block)

    def embed_states(self, states: torch.Tensor, targets: torch.Tensor | None = None) -> torch.Tensor:
        return self.view(states, targets)

    def param_groups(self, lr: float) -> list[dict]:
        """Adam's groups: the planning module (``whole_map``) at ``plan_lr`` × ``lr``, the rest at ``lr``."""
        planner = list(self.view.map_plan.parameters()) if self.view.map_plan is not None else []
        ids = {id(p) for p in planner}
        rest = [p for p in self.parameters() if id(p) not in ids]
        return [{"params": rest}] + ([{"params": planner, "lr": lr * self.cfg.plan_lr}] if planner else [])

    def loss(self, batch: dict) -> torch.Tensor:
        """The transformer's loss, plus (``whole_map``) ``plan_loss`` × the planning module's own cross-entropy
        on the same steps, from the read-out the forward pass made (packed in its order)."""
        loss = super().loss(batch)
        if self.view.map_plan is None or not self.cfg.plan_loss:
            return loss
        actions, mask, steps = batch["actions"], batch["loss_mask"], batch.get("steps")
        if steps is not None:
            actions, mask = actions[steps], mask[steps]
        nll = F.cross_entropy(self.view.map_plan.act(self.view.plan_read), actions.reshape(-1), reduction="none")
        mask = mask.reshape(-1).float()
        return loss + self.cfg.plan_loss * (nll * mask).sum() / mask.sum().clamp(min=1.0)

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
    conv_layers: int = 0  # 3x3 convolutions over the view first: the decision transformers' encoder (no value
    #                       iterations: those plan towards a sub-goal's target, which these controllers never read)


class ViewRecurrentPolicy(ViewModel, RecurrentPolicy, arch="view_recurrent", config=ViewRecurrentConfig):
    def build_state_encoder(self, width: int) -> None:
        cfg = self.cfg
        self.view = ViewEncoder(cfg.view_radius, cfg.code_dim, cfg.n_flags, width, cfg.conv_layers)

    def embed_states(self, states: torch.Tensor) -> torch.Tensor:
        return self.view(states)


# -- value networks (DQN, option-critic): one-hot codes and flags into the MLP ---------------------------

def one_hot_view(states: torch.Tensor, radius: int) -> torch.Tensor:
    """(…, 2 + cells + flags) int64 → (…, cells · N_CODES + flags) float."""
    codes, flags = split_states(states, radius)
    return torch.cat([F.one_hot(codes, N_CODES).float().flatten(-2), flags], dim=-1)


class ViewFeatures:
    """The value networks' MLP input on views, in place of :class:`~hnsdt.models.qnetwork.StateFeatures`: the
    one-hot cell codes of the view and the flags."""

    cfg: object

    @staticmethod
    def n_inputs(cfg) -> int:
        return (2 * cfg.view_radius + 1) ** 2 * N_CODES + cfg.n_flags

    def features(self, states: torch.Tensor) -> torch.Tensor:
        return one_hot_view(states, self.cfg.view_radius)


@dataclass
class ViewQNetworkConfig(QNetworkConfig):
    view_radius: int = 2


class ViewQNetwork(ViewModel, ViewFeatures, QNetwork, arch="view_q_network", config=ViewQNetworkConfig):
    pass


@dataclass
class ViewOptionCriticConfig(OptionCriticConfig):
    view_radius: int = 2


class ViewOptionCritic(ViewModel, ViewFeatures, OptionCritic, arch="view_option_critic",
                       config=ViewOptionCriticConfig):
    pass


@dataclass
class ViewActorCriticConfig(ActorCriticConfig):
    view_radius: int = 2


class ViewActorCritic(ViewModel, ViewFeatures, ActorCritic, arch="view_actor_critic", config=ViewActorCriticConfig):
    pass
