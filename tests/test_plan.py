"""The learned planning module over the whole map (hnsdt.models.plan.MapPlanner) and the data it reads: each
frame's whole map in the dataset, turned with its episode, planned once per sub-goal segment, on maps of any
side."""

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from hnsdt.compose.generalisation import VALIDATION_SEED
from hnsdt.envs.generate import FamilySizes, generate
from hnsdt.envs.layout import load_layout
from hnsdt.envs.observation import OUTSIDE, WALL, state_codes, view_states, whole_map
from hnsdt.evaluation.planning import shortest_way_shares, train_alone
from hnsdt.models.plan import LOWEST, MapPlanner
from hnsdt.models.view import ViewDecisionTransformer, turn_episodes, view_config
from test_generalisation import _turned_text

REPO = Path(__file__).resolve().parents[1]
STEPS = 600  # the module's training steps in the learning test (measured: docs/unseen-layouts-studies.md)


def _model(**sizes):
    cfg = view_config("subgoal", 2, 2, 7, whole_map=True, formulation="episode", context=4, n_layers=1, n_heads=2,
                      d_model=16, max_timestep=200, **sizes)
    torch.manual_seed(0)
    return ViewDecisionTransformer(cfg).eval()


def _episode(layout, T: int, seed: int = 0):
    """T random states of ``layout`` (free cells, flags 0 then 1 half way) and their view states with the map."""
    rng = np.random.default_rng(seed)
    free = np.argwhere(~layout.walls)
    cells = free[rng.integers(0, len(free), T)]
    flags = np.zeros((T, layout.n_flags), dtype=np.int64)
    flags[T // 2:, 0] = 1
    states = np.concatenate([cells, flags], axis=1)
    return states, view_states(layout, states, 2, max(layout.shape))


def test_the_whole_map_is_the_grid_in_each_state_on_a_square_of_any_side():
    layout = load_layout((REPO / "layouts/drawn/tall_16x4.txt").read_text())
    states, _ = _episode(layout, 6)
    grids = whole_map(layout, states, 20)
    assert grids.shape == (6, 20, 20)
    assert (grids[:, :16, :4] == state_codes(layout, states)).all() and (grids[:, :, 4:] == OUTSIDE).all()
    assert (grids[:, 16:] == OUTSIDE).all()
    with pytest.raises(ValueError, match="cannot hold"):
        whole_map(layout, states, 15)


def test_the_plan_is_made_once_per_segment_and_steps_as_the_episode_pass(monkeypatch):
    """A segment is a run of steps with the same map, flags and target: the episode pass plans once per segment
    (3 here), and stepping through the key/value cache plans each segment once and gives the same logits."""
    layout = load_layout((REPO / "layouts/drawn/rooms_10x10.txt").read_text())
    model = _model()
    T = 12
    _, states = _episode(layout, T)
    targets = np.array([[1, 1]] * 4 + [[2, 3]] * 2 + [[2, 3]] * 6)  # the flags change at step 6: 3 segments
    planned = []
    original = MapPlanner.plan
    monkeypatch.setattr(MapPlanner, "plan", lambda self, cells, *a: planned.append(len(cells)) or original(
        self, cells, *a))
    s = torch.from_numpy(states)[None]
    actions, steps = torch.randint(0, 5, (1, T), generator=torch.Generator().manual_seed(0)), torch.arange(T)[None]
    ids, tg = torch.ones(1, T, dtype=torch.long), torch.from_numpy(targets)[None]
    with torch.no_grad():
        full = model(s, actions, steps, None, subgoal_ids=ids, subgoal_targets=tg)
    assert planned == [3]
    planned.clear()
    model.eval()  # (empties the kept plans: the episode pass above kept its three)
    cache, rows = model.start(1), torch.arange(1)
    got = torch.stack([model.step(cache, rows, s[:, t], torch.full((1,), 5) if t == 0 else actions[:, t - 1],
                                  steps[:, t], ids[:, t], tg[:, t]) for t in range(T)], dim=1)
    assert planned == [1, 1, 1] and torch.allclose(got, full, atol=1e-5)


def test_the_target_and_the_map_change_what_the_module_reads():
    """The read-out follows the sub-goal's target and the map (fails when either is not read): a target beside
    the agent and one far off, the agent's neighbours as floor and as walls."""
    layout = load_layout((REPO / "layouts/drawn/rooms_10x10.txt").read_text())
    model = _model()
    _, states = _episode(layout, 1)
    s = torch.from_numpy(states)
    r, c = states[0, :2]
    free = {tuple(cell) for cell in np.argwhere(~layout.walls)}
    beside = next(n for n in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)) if n in free)
    far = max(free, key=lambda cell: abs(cell[0] - r) + abs(cell[1] - c))
    a, b = torch.tensor([beside]), torch.tensor([far])
    with torch.no_grad():
        base = model.view(s, a)
        assert not torch.allclose(base, model.view(s, b))
        walled = s.clone()
        walled[0, 2 + 25 + 2:] = torch.where(walled[0, 2 + 25 + 2:] == 2, 1, walled[0, 2 + 25 + 2:])  # floor→wall
        assert not torch.allclose(base, model.view(walled, a))


def test_a_map_larger_than_any_training_map_runs_and_plans_over_all_of_it():
    """Nothing is tied to a map size: a 24 x 24 map (576 backups: its side squared, at least any path's length)
    and a 3 x 16 corridor step through the same model."""
    from hnsdt.agents.dt_agents import HNSDTAgent
    from hnsdt.agents.executor import ExecutorConfig
    from hnsdt.agents.rollout import rollout
    from hnsdt.envs.vector import KeyDoorVectorEnv

    rows = ["#" * 24] + ["#" + "." * 22 + "#"] * 22 + ["#" * 24]
    rows[1] = "#@" + "." * 21 + "#"
    rows[5] = "#" + "." * 10 + "a" + "." * 11 + "#"
    rows[12] = "#" * 11 + "A" + "#" * 12
    rows[22] = "#" + "." * 21 + "G#"
    big = load_layout("\n".join(rows))
    assert MapPlanner.iterations(24) == 576
    model = _model()
    for layout in (big, load_layout((REPO / "layouts/drawn/thin_3x16.txt").read_text())):
        agent = HNSDTAgent(layout, model, ExecutorConfig(operators="goto"))
        (ep,) = rollout(KeyDoorVectorEnv(1, layout, 0.0, 12), agent, seed=0)
        assert 1 <= ep.length <= 12


def test_a_turned_episode_turns_its_whole_map_with_it():
    """On a square map the turned episode's states, the whole map and the agent's cell included, are the states
    of the turned map (``generalisation.symmetries`` with ``whole_map``)."""
    from hnsdt.agents import SymbolicAgent, rollout
    from hnsdt.envs.vector import KeyDoorVectorEnv

    layout = load_layout((REPO / "layouts/drawn/spiral_9x9.txt").read_text())
    (ep,) = rollout(KeyDoorVectorEnv(1, layout, 0.0, 150), SymbolicAgent(layout), seed=0)
    T = ep.length
    batch = {"states": view_states(layout, ep.states[:T], 2, 9)[None], "actions": ep.actions[None],
             "subgoal_targets": ep.subgoal_targets[None]}
    for k in range(8):
        out = turn_episodes(batch, 2, np.array([k]), layout.n_flags)
        turned = load_layout(_turned_text(layout.text, k))
        cells = out["states"][0][:, :2]
        flags = out["states"][0][:, 2 + 25:2 + 25 + layout.n_flags]
        assert np.array_equal(out["states"][0], view_states(turned, np.concatenate([cells, flags], 1), 2, 9))
        has = ep.subgoal_targets[:, 0] >= 0
        codes = whole_map(turned, np.concatenate([cells, flags], 1), 9)
        target = out["subgoal_targets"][0][has]
        assert np.array_equal(codes[has, target[:, 0], target[:, 1]],
                              whole_map(layout, ep.states[:T], 9)[has, ep.subgoal_targets[has, 0],
                                                                     ep.subgoal_targets[has, 1]])


def test_the_modules_own_loss_trains_its_head_only_when_weighted():
    """``plan_loss`` adds the module's own imitation loss (VIN's objective, read from its neighbours' values):
    its action head gets a gradient with it, none without it (the transformer never reads that head)."""
    layout = load_layout((REPO / "layouts/drawn/rooms_10x10.txt").read_text())
    _, states = _episode(layout, 8)
    batch = {"states": torch.from_numpy(states)[None], "actions": torch.arange(8)[None] % 5,
             "timesteps": torch.arange(8)[None], "subgoal_ids": torch.ones(1, 8, dtype=torch.long),
             "subgoal_targets": torch.tensor([[[1, 1]] * 8]), "loss_mask": torch.ones(1, 8, dtype=torch.bool)}
    for weight in (1.0, 0.0):
        model = _model(plan_loss=weight).train()
        model.loss(batch).backward()
        head = model.view.map_plan.act.weight.grad
        assert (head is not None and head.abs().sum() > 0) == (weight > 0)


def _values(module, grid: np.ndarray, flags, target) -> np.ndarray:
    """The module's value map of one whole map ``grid`` (S, S) of codes towards ``target`` (row, col)."""
    side = grid.shape[0]
    with torch.no_grad():
        _, value = module._plan_rows(torch.from_numpy(grid.reshape(1, -1)), torch.tensor([flags]),
                                     torch.tensor(np.array([target])), side)
    return value[0, 0].numpy()


def test_the_modules_values_turn_and_shift_with_the_map():
    """The backup over the four moves has the world's symmetries: a map turned a quarter, or mirrored, gives the
    values turned or mirrored; the map moved within a larger square of outside cells gives its cells the same
    values (everything per cell, no absolute position). Untrained weights: it holds for any."""
    layout = load_layout((REPO / "layouts/drawn/pocket_9x12.txt").read_text())
    states, _ = _episode(layout, 1)
    torch.manual_seed(3)
    module = MapPlanner(16, layout.n_flags).eval()
    grid = whole_map(layout, states, 12)[0]
    target = np.array(layout.goal)
    base = _values(module, grid, [0, 1], target)
    assert base[tuple(target)] == 0 and (np.delete(base.ravel(), target[0] * 12 + target[1]) < 0).all()  # from it
    turned = np.rot90(grid, k=-1).copy()  # clockwise: (r, c) -> (c, S-1-r)
    np.testing.assert_allclose(_values(module, turned, [0, 1], [target[1], 11 - target[0]]), np.rot90(base, k=-1),
                               rtol=1e-6, atol=1e-5)
    mirrored = grid[:, ::-1].copy()
    np.testing.assert_allclose(_values(module, mirrored, [0, 1], [target[0], 11 - target[1]]), base[:, ::-1],
                               rtol=1e-6, atol=1e-5)
    h, w = layout.shape
    placed = []
    for dr, dc in ((1, 1), (3, 2)):
        sea = np.full((17, 17), OUTSIDE, dtype=grid.dtype)
        sea[dr:dr + h, dc:dc + w] = grid[:h, :w]
        placed.append(_values(module, sea, [0, 1], target + [dr, dc])[dr:dr + h, dc:dc + w])
    np.testing.assert_allclose(placed[0], placed[1], rtol=1e-6, atol=1e-5)


def test_trained_on_a_handful_of_maps_it_plans_round_walls_on_maps_it_never_saw():
    """The module alone (hnsdt.evaluation.planning, as benchmarks/plan_module.py), trained on 8 generated braided
    mazes' demonstrations (at most 11 x 13 cells), picks a shortest way to the exit from most cells of 3
    validation mazes — also from the cells whose shortest way starts by walking away from the exit, which the
    cells around the agent cannot tell — and the same weights with the backups cut do not (breadth-first search
    scores here only; it never feeds the module). The long ways of larger mazes: below."""
    module = train_alone("keydoor_maze", 8, STEPS)
    layouts = [generate("keydoor_maze", seed) for seed in range(VALIDATION_SEED, VALIDATION_SEED + 3)]
    (planned, planned_away), (cut, cut_away) = shortest_way_shares(module, layouts), shortest_way_shares(module,
                                                                                                        layouts, 0)
    assert planned >= 0.9 and planned_away >= 0.8, (planned, planned_away)
    assert cut <= planned - 0.2 and cut_away <= planned_away - 0.1, (cut, cut_away)
    # Nothing depends on the longest leg it trained on (braided mazes: short detours): on perfect mazes of 21-24
    # cells a side, whose ways walk away from their target for dozens of steps, it picks a shortest way to the key
    # and to the exit from nearly every cell (measured: 1.000); the same weights with every cell relaying values
    # (``block`` off: a wall only as dear as its learned cost, which the short training detours never made dearer
    # than a long way round) do not (measured: 0.50-0.55).
    big = [generate("keydoor_perfect", seed, FamilySizes(rows=(21, 24), cols=(21, 24)))
           for seed in range(VALIDATION_SEED, VALIDATION_SEED + 2)]
    blocked = [shortest_way_shares(module, big, leg=leg)[0] for leg in ("key", "exit")]
    module.block = False
    relayed = [shortest_way_shares(module, big, leg=leg)[0] for leg in ("key", "exit")]
    assert min(blocked) >= 0.95 and max(relayed) <= 0.8, (blocked, relayed)


def test_a_held_out_loss_without_a_gradient_reads_its_own_steps():
    """A held-out loss is measured under ``no_grad``: the module's own loss there reads that batch's read-out,
    not the last training batch's (which has another number of steps)."""
    layout = load_layout((REPO / "layouts/drawn/rooms_10x10.txt").read_text())

    def batch(t: int, seed: int) -> dict:
        _, states = _episode(layout, t, seed)
        return {"states": torch.from_numpy(states)[None], "actions": torch.arange(t)[None] % 5,
                "timesteps": torch.arange(t)[None], "subgoal_ids": torch.ones(1, t, dtype=torch.long),
                "subgoal_targets": torch.tensor([[[1, 1]] * t]), "loss_mask": torch.ones(1, t, dtype=torch.bool)}

    model = _model()
    held_out = batch(6, 1)
    with_grad = model.loss(held_out).item()
    model.loss(batch(8, 0))  # a training batch of another length
    with torch.no_grad():
        assert model.loss(held_out).item() == pytest.approx(with_grad, rel=1e-6)


def _wall_costs_more_than_a_wall_reads(module: MapPlanner, wall_cost: float) -> None:
    """Hand-set weights: a floor-like cell's step cost 1, a wall's ``wall_cost`` (above LOWEST)."""
    with torch.no_grad():
        for p in module.parameters():
            p.zero_()
        module.code_emb.weight[WALL, 0] = 1.0
        first, last = module.reward[0], module.reward[2]
        first.weight[0, 0] = 1.0
        last.weight[0, 0] = wall_cost
        last.bias[0] = math.log(math.e - 1)  # softplus: 1


def test_a_cell_dearer_than_the_read_outs_wall_relays_nothing_however_long_the_way_round():
    """``block``: a cell whose learned step cost is above LOWEST is a wall to the plan. Beside a wall that costs
    30 floor steps, with the target behind it and a way round of 40, the read-out at the agent's cell points
    round; without ``block`` it points through the wall. The agent on such a cell still reads its neighbours'
    values, bounded (a value of -1e9 there would read +1e9)."""
    layout = load_layout("@a" + "." * 19 + "\n" + "#" * 19 + "A.\n" + "G" + "." * 20 + "\n")
    side = max(layout.shape)
    grid = torch.from_numpy(whole_map(layout, np.array([[0, 0] + [0] * layout.n_flags]), side).reshape(1, -1))
    flags, target = torch.zeros(1, layout.n_flags), torch.tensor([list(layout.goal)])
    reads = {}
    for block in (True, False):
        module = MapPlanner(4, layout.n_flags, hidden=2, block=block).eval()
        _wall_costs_more_than_a_wall_reads(module, 30.0)
        with torch.no_grad():
            reads[block] = module(grid, flags, target, torch.tensor([[0, 0], [1, 0]]))  # (up, down, left, right)
    assert 30.0 > LOWEST
    assert reads[True][0].argmax().item() == 3 and reads[False][0].argmax().item() == 1, reads
    on_wall = reads[True][1]  # the agent on the wall below its start: down, the target, is best
    assert on_wall.abs().max() < 2 * LOWEST and on_wall.argmax().item() == 1, on_wall
