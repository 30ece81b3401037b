"""A learned planning module over the whole map, the decision transformer's state encoder is composed with
(:class:`hnsdt.models.view.ViewEncoder`, ``whole_map``): given the map's cells, a mark on the sub-goal's target
cell (none for a DT without sub-goals) and the flags, it learns what each cell is, backs values up over the map
and is read out at the agent's cell into the state token.

Two backups (``backup``):

* ``moves`` (the default): value iteration over the grid's own four moves, the way Neural A* (Yonetani et al.
  2021) searches over a learned cost map. From its own code, the mark and the flags each cell learns a step cost;
  values start at the sub-goal's target cell (``goal="target"``, the default: the cell the planner's operator
  names, as VIN's and GPPN's goal map) and a cell's value is its best neighbour's less its step cost. The
  transition is the environment's (a move reaches one of four neighbours); what is learned is which cells are
  cheap to cross in this state (floor, a door the flags open). A cell whose learned cost is above ``LOWEST``
  (the read-out's wall) relays no value (``block``): it is a wall to the plan, whatever the detour round it
  costs — learned costs alone make a wall only as dear as the training maps' detours, so on a larger map a
  long way round lost to a way through the wall (docs/unseen-layouts-studies.md). A step without a target (a
  DT without sub-goals) starts from each cell's learned goal value instead — its log-probability of being the
  goal — as does every step with ``goal="learned"``. The read-out is the four neighbours' values less the
  agent's: no distance or direction is an input or a target, and with the backups cut the read-out points a
  shortest way from about a third of the cells.
* ``kernel``: VIN's (Tamar et al. 2016): ``channels`` action values per cell, each the cell's reward plus a
  learned 3 × 3 kernel's sum of the neighbours' values, the value their maximum; read out as the agent's action
  values and its neighbours' values. Measured not to learn to plan from our demonstrations (its actions a
  shortest way at 0.63 of held-out maze cells, 0.60 with the backups cut: docs/unseen-layouts-studies.md).

Both read out into the transformer and into the module's own action head on the neighbours' read-out
(:attr:`MapPlanner.act`, VIN's objective); both learn only from the collected episodes' actions.

How far it plans: a side × side map gets up to side² backups — at least the length of any path on it (a path
visits each cell at most once), so a value can reach every cell the target can be reached from, whatever the
map's shape; ``moves`` stops as soon as no value changes. The layers act per cell, so any map's side runs. With
a learned goal, how far a goal's value carries is learned too — until a cell that is not the goal outranks it
(their log-probabilities' gap over the floor's step cost), measured at about the training legs' length, so the
hand-drawn maps' long detours lay beyond it; from the target's cell nothing outranks a path, and what is left
learned is how much dearer a wall is than a detour (docs/unseen-layouts-studies.md).
``kernel``'s weights are scaled to an absolute sum of at most 1, so its values stay bounded over 576 backups.

The plan is computed once per sub-goal segment (a run of steps with the same map, flags and target) and read
out at every step of it; at inference (no gradient) plans are kept by segment, so a step costs one read-out.
"""

from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.envs.dynamics import N_ACTIONS
from hnsdt.envs.observation import N_CODES

BACKUPS = ("kernel", "moves")
GOALS = ("learned", "target")  # (moves) where values start: each cell's learned goal value, or the target's cell
LOWEST = 20.0  # (moves) a neighbour's read-out at most this far below the agent's cell: walls and the edge
CACHE = 4096  # plans kept at inference; the cache empties when full and whenever the weights may change


def taps(value: torch.Tensor) -> torch.Tensor:
    """(N, 1, S, S) → (N, 9, S, S): each cell's 3 × 3 neighbourhood (zero beyond the edge), row-major — a
    one-channel 3 × 3 convolution as a product with these, faster to train on CPU than ``conv2d``'s backward at
    this size."""
    side = value.shape[-1]
    padded = F.pad(value[:, 0], (1, 1, 1, 1))
    return torch.stack([padded[:, i:i + side, j:j + side] for i in range(3) for j in range(3)], dim=1)


class MapPlanner(nn.Module):
    """Each cell's own layers → backups (at most side²) → the read-out at the agent's cell (``out_features``
    numbers)."""

    def __init__(self, code_dim: int, n_flags: int, channels: int = 8, hidden: int = 32, backup: str = "moves",
                 goal: str = "target", block: bool = True):
        super().__init__()
        for name, value, allowed in (("backup", backup, BACKUPS), ("goal", goal, GOALS)):
            if value not in allowed:
                raise ValueError(f"{name} {value!r} is not one of {', '.join(allowed)}")
        self.n_flags, self.backup, self.goal, self.block = n_flags, backup, goal, block
        self.code_emb = nn.Embedding(N_CODES, code_dim)  # its own: the view's embedding learns at another pace
        outputs = 1 if backup == "kernel" else 2  # (moves: a step's cost and the goal's log-value per cell)
        self.reward = nn.Sequential(nn.Conv2d(code_dim + 1 + n_flags, hidden, 1), nn.ReLU(),
                                    nn.Conv2d(hidden, outputs, 1))  # each cell's own: no view of its neighbours
        if backup == "kernel":
            self.q_from_reward = nn.Conv2d(1, channels, 1, bias=False)
            self.transition = nn.Parameter(0.1 * torch.randn(channels, 9))  # each action's kernel over the 3 x 3
        self.out_features = channels + 4 if backup == "kernel" else 4
        self.act = nn.Linear(4, N_ACTIONS)  # the module's own action logits from its neighbours' values (its loss)
        self._plans: dict[bytes, tuple[torch.Tensor, torch.Tensor]] = {}

    def kernel(self) -> torch.Tensor:
        """(channels, 9): each action's weights over the 3 x 3 neighbourhood (row-major), absolute sum <= 1."""
        return self.transition / self.transition.abs().sum(dim=-1, keepdim=True).clamp(min=1.0)

    @staticmethod
    def iterations(side: int) -> int:
        return side * side

    def train(self, mode: bool = True):
        self._plans.clear()  # (training changes the weights the kept plans were made with)
        return super().train(mode)

    def plan(self, cells: torch.Tensor, mark: torch.Tensor, flags: torch.Tensor, backups: int | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """cells (N, code_dim, S, S), mark (N, 1, S, S), flags (N, n_flags) → what the read-out needs besides
        the values — ``moves``: each cell's goal value and, where it relays nothing, its step cost (N, 2, S, S);
        ``kernel``: the action values its reward gives (N, channels, S, S) — and the values after the backups
        (N, 1, S, S). ``backups``: at most that many instead of side² (0: each cell's own values, nothing
        planned)."""
        side = cells.shape[-1]
        backups = self.iterations(side) if backups is None else backups
        spread = flags[:, :self.n_flags, None, None].expand(-1, -1, side, side)
        reward = self.reward(torch.cat([cells, mark, spread], dim=1))
        if self.backup == "moves":
            return self._plan_moves(reward, mark, backups)
        q_reward = self.q_from_reward(reward)
        weight = self.kernel()
        value = q_reward.max(dim=1, keepdim=True).values
        for _ in range(backups):
            value = (q_reward + torch.einsum("ck,nkhw->nchw", weight, taps(value))).max(dim=1, keepdim=True).values
        return q_reward, value

    def _plan_moves(self, reward: torch.Tensor, mark: torch.Tensor, backups: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Backups over the four moves: a cell's value is the larger of its goal value (``goal="target"`` and a
        marked cell: 0 there, -1e9 elsewhere; else its learned log-probability of being the goal) and its best
        neighbour's less the cell's learned step cost (> 0), none through a cell dearer than ``LOWEST`` (``block``);
        stops once nothing changes (at most ``backups``)."""
        cost = F.softplus(reward[:, :1])
        goal = F.logsigmoid(reward[:, 1:])
        if self.goal == "target":
            marked = mark.flatten(1).amax(dim=1)[:, None, None, None] > 0
            goal = torch.where(marked, torch.where(mark > 0, 0.0, -1e9), goal)
        walls = cost > LOWEST if self.block else torch.zeros_like(cost, dtype=torch.bool)
        value = goal
        for _ in range(backups):
            padded = F.pad(value[:, 0], (1, 1, 1, 1), value=-1e9)
            best = torch.stack([padded[:, :-2, 1:-1], padded[:, 2:, 1:-1], padded[:, 1:-1, :-2],
                                padded[:, 1:-1, 2:]]).max(dim=0).values
            new = torch.maximum(goal, torch.where(walls, -1e9, best[:, None] - cost))
            if torch.equal(new, value):
                break
            value = new
        return torch.cat([goal, cost.masked_fill(~walls, 0.0)], dim=1), value

    def read(self, q_reward: torch.Tensor, value: torch.Tensor, segment: torch.Tensor, cells: torch.Tensor
             ) -> torch.Tensor:
        """The read-out (M, out_features) of M steps, each in plan ``segment[i]`` at ``cells[i]`` (row, col)."""
        r, c = cells[:, 0], cells[:, 1]
        padded = F.pad(value[:, 0], (1, 1, 1, 1), value=-1e9 if self.backup == "moves" else 0.0)
        around = torch.stack([padded[segment, r + i, c + j] for i in range(3) for j in range(3)], dim=-1)  # (M, 9)
        if self.backup == "moves":  # (beyond the edge: a wall's lowest value, not -1e9)
            near = around[:, [1, 7, 3, 5]]
            here = around[:, 4:5]
            wall = q_reward[segment, 1, r, c][:, None]  # (> 0: the agent's cell relays nothing, -1e9 in the plan)
            own = torch.maximum(q_reward[segment, 0, r, c][:, None], near.max(dim=-1, keepdim=True).values - wall)
            return (near - torch.where(wall > 0, own, here)).clamp(min=-LOWEST)  # (its own value as a cell's)
        q = q_reward[segment, :, r, c] + around @ self.kernel().T
        near = around[:, [1, 7, 3, 5]] - around[:, 4:5]  # up, down, left, right, relative to the agent's cell
        return torch.cat([q - q.max(dim=-1, keepdim=True).values, near], dim=-1)

    def forward(self, grid: torch.Tensor, flags: torch.Tensor, targets: torch.Tensor | None,
                cells: torch.Tensor) -> torch.Tensor:
        """The read-out (M, out_features) of M steps: ``grid`` (M, S²) codes of each step's map, ``flags``
        (M, n_flags), ``targets`` (M, 2) the sub-goal's cell (-1: none; None: no sub-goals), ``cells`` (M, 2)
        the agent's. One plan per run of equal map, flags and target."""
        m = grid.shape[0]
        side = int(round(grid.shape[1] ** 0.5))
        if side * side != grid.shape[1]:
            raise ValueError(f"a whole map of {grid.shape[1]} cells is not a square")
        if targets is None:
            targets = torch.full((m, 2), -1, dtype=torch.long, device=grid.device)
        key = torch.cat([grid, flags.long(), targets], dim=-1)
        new = torch.ones(m, dtype=torch.bool, device=grid.device)
        new[1:] = (key[1:] != key[:-1]).any(-1)
        segment = new.cumsum(0) - 1
        first = torch.nonzero(new).flatten()
        if self.training or torch.is_grad_enabled():  # (plans are kept only where the weights cannot change)
            q_reward, value = self._plan_rows(grid[first], flags[first], targets[first], side)
        else:
            q_reward, value = self._kept_plans(key[first], grid[first], flags[first], targets[first], side)
        return self.read(q_reward, value, segment, cells)

    def _plan_rows(self, grid, flags, targets, side, backups: int | None = None):
        n = grid.shape[0]
        cells = self.code_emb(grid).reshape(n, side, side, -1).permute(0, 3, 1, 2)
        mark = torch.zeros(n, side * side, device=grid.device)
        present = (targets[:, 0] >= 0) & (targets[:, 0] < side) & (targets[:, 1] >= 0) & (targets[:, 1] < side)
        rows = torch.nonzero(present).flatten()
        mark[rows, targets[rows, 0] * side + targets[rows, 1]] = 1.0
        return self.plan(cells, mark.reshape(n, 1, side, side), flags.float(), backups)

    def _kept_plans(self, keys, grid, flags, targets, side):
        names = [k.cpu().numpy().tobytes() for k in keys]
        plans = {name: self._plans[name] for name in names if name in self._plans}
        first_of = {name: i for i, name in reversed(list(enumerate(names)))}  # each name's first row
        missing = [i for name, i in first_of.items() if name not in plans]
        if missing:
            rows = torch.tensor(missing, device=grid.device)
            q_reward, value = self._plan_rows(grid[rows], flags[rows], targets[rows], side)
            made = {names[i]: (q_reward[j], value[j]) for j, i in enumerate(missing)}
            plans.update(made)
            if len(self._plans) + len(made) > CACHE:
                self._plans.clear()
            self._plans.update(made)
        return torch.stack([plans[name][0] for name in names]), torch.stack([plans[name][1] for name in names])
