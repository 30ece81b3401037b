"""A learned planning module over the whole map: a value-iteration network (Tamar et al. 2016) the decision
transformer's state encoder is composed with (:class:`hnsdt.models.view.ViewEncoder`, ``whole_map``).

Given the map's cells (their learned embeddings), a mark on the sub-goal's target cell (none for a DT without
sub-goals) and the flags, it learns a reward per cell from that cell alone, then runs Bellman backups —
``channels`` action values per cell, each its reward plus a learned 3 × 3 kernel's sum of the neighbours'
values (VIN's transition kernel), the value their maximum, the weights shared by every backup — and is read out
at the agent's cell: its action values and its four neighbours' values, relative to the best action's and its
own. Nothing in it is a distance or a direction: reward, backup and read-out are learned from the collected
episodes' actions, through the transformer, end to end — and through its own action head
(:attr:`MapPlanner.act`, VIN's objective), which reads only the neighbours' values. Both choices close a
shortcut measured to stop it planning: trained through the transformer alone (which also reads the view and
the target's offset), or with VIN's 3 × 3 reward and a head on the agent's own action values, it learned to
predict the demonstrations' actions from the cells around the agent, and its values pointed a shortest way
from barely more cells than chance (docs/unseen-layouts-studies.md).

How far it plans: a side × side map gets side² backups — at least the length of any path on it (a path visits
each cell at most once), so a value reaches every cell the target can be reached from, whatever the map's
shape or the leg's detour; nothing depends on the maps trained on (the convolutions are the same on any side).
Each kernel's weights are scaled to an absolute sum of at most 1, so a backup never expands the values: they
stay bounded however many backups run (a value moves by at most the largest reward per backup), where VIN's
free kernel can grow them geometrically, to overflow in the 576 backups of a 24 × 24 map. (A kernel that is a
probability over the neighbourhood, tried first, learned the demonstrations' actions far more slowly: 0.45
against 0.82 of them after 300 steps; so did a read-out scaled by the best neighbour's gain.)

The plan is computed once per sub-goal segment (a run of steps with the same map, flags and target) and read
out at every step of it; at inference (no gradient) plans are kept by segment, so a step costs one read-out.
"""

from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from hnsdt.envs.dynamics import N_ACTIONS

CACHE = 4096  # plans kept at inference; the cache empties when full and whenever the weights may change


def taps(value: torch.Tensor) -> torch.Tensor:
    """(N, 1, S, S) → (N, 9, S, S): each cell's 3 × 3 neighbourhood (zero beyond the edge), row-major — a
    one-channel 3 × 3 convolution as a product with these, faster to train on CPU than ``conv2d``'s backward at
    this size."""
    side = value.shape[-1]
    padded = F.pad(value[:, 0], (1, 1, 1, 1))
    return torch.stack([padded[:, i:i + side, j:j + side] for i in range(3) for j in range(3)], dim=1)


class MapPlanner(nn.Module):
    """Reward map → side² backups → the read-out at the agent's cell (``out_features`` numbers)."""

    def __init__(self, code_dim: int, n_flags: int, channels: int = 8, hidden: int = 32):
        super().__init__()
        self.n_flags = n_flags
        self.reward = nn.Sequential(nn.Conv2d(code_dim + 1 + n_flags, hidden, 1), nn.ReLU(),
                                    nn.Conv2d(hidden, 1, 1))  # each cell's own: no view of its neighbours
        self.q_from_reward = nn.Conv2d(1, channels, 1, bias=False)
        self.transition = nn.Parameter(0.1 * torch.randn(channels, 9))  # each action's kernel over the 3 x 3
        self.out_features = channels + 4
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

    def plan(self, cells: torch.Tensor, mark: torch.Tensor, flags: torch.Tensor
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """cells (N, code_dim, S, S), mark (N, 1, S, S), flags (N, n_flags) → the action values the reward
        gives (N, channels, S, S) and the value after side² backups (N, 1, S, S)."""
        side = cells.shape[-1]
        spread = flags[:, :self.n_flags, None, None].expand(-1, -1, side, side)
        q_reward = self.q_from_reward(self.reward(torch.cat([cells, mark, spread], dim=1)))
        weight = self.kernel()
        value = q_reward.max(dim=1, keepdim=True).values
        for _ in range(self.iterations(side)):
            value = (q_reward + torch.einsum("ck,nkhw->nchw", weight, taps(value))).max(dim=1, keepdim=True).values
        return q_reward, value

    def read(self, q_reward: torch.Tensor, value: torch.Tensor, segment: torch.Tensor, cells: torch.Tensor
             ) -> torch.Tensor:
        """The read-out (M, channels + 4) of M steps, each in plan ``segment[i]`` at ``cells[i]`` (row, col)."""
        r, c = cells[:, 0], cells[:, 1]
        padded = F.pad(value[:, 0], (1, 1, 1, 1))
        around = torch.stack([padded[segment, r + i, c + j] for i in range(3) for j in range(3)], dim=-1)  # (M, 9)
        q = q_reward[segment, :, r, c] + around @ self.kernel().T
        near = around[:, [1, 7, 3, 5]] - around[:, 4:5]  # up, down, left, right, relative to the agent's cell
        return torch.cat([q - q.max(dim=-1, keepdim=True).values, near], dim=-1)

    def forward(self, embed, grid: torch.Tensor, flags: torch.Tensor, targets: torch.Tensor | None,
                cells: torch.Tensor) -> torch.Tensor:
        """The read-out (M, out_features) of M steps: ``grid`` (M, S²) codes of each step's map, ``flags``
        (M, n_flags), ``targets`` (M, 2) the sub-goal's cell (-1: none; None: no sub-goals), ``cells`` (M, 2)
        the agent's; ``embed`` maps codes to (…, code_dim). One plan per run of equal map, flags and target."""
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
            q_reward, value = self._plan_rows(embed, grid[first], flags[first], targets[first], side)
        else:
            q_reward, value = self._kept_plans(embed, key[first], grid[first], flags[first], targets[first], side)
        return self.read(q_reward, value, segment, cells)

    def _plan_rows(self, embed, grid, flags, targets, side):
        n = grid.shape[0]
        cells = embed(grid).reshape(n, side, side, -1).permute(0, 3, 1, 2)
        mark = torch.zeros(n, side * side, device=grid.device)
        present = (targets[:, 0] >= 0) & (targets[:, 0] < side) & (targets[:, 1] >= 0) & (targets[:, 1] < side)
        rows = torch.nonzero(present).flatten()
        mark[rows, targets[rows, 0] * side + targets[rows, 1]] = 1.0
        return self.plan(cells, mark.reshape(n, 1, side, side), flags.float())

    def _kept_plans(self, embed, keys, grid, flags, targets, side):
        names = [k.cpu().numpy().tobytes() for k in keys]
        plans = {name: self._plans[name] for name in names if name in self._plans}
        first_of = {name: i for i, name in reversed(list(enumerate(names)))}  # each name's first row
        missing = [i for name, i in first_of.items() if name not in plans]
        if missing:
            rows = torch.tensor(missing, device=grid.device)
            q_reward, value = self._plan_rows(embed, grid[rows], flags[rows], targets[rows], side)
            made = {names[i]: (q_reward[j], value[j]) for j, i in enumerate(missing)}
            plans.update(made)
            if len(self._plans) + len(made) > CACHE:
                self._plans.clear()
            self._plans.update(made)
        return torch.stack([plans[name][0] for name in names]), torch.stack([plans[name][1] for name in names])
