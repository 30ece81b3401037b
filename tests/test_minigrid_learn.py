"""The learners on MiniGrid's own worlds (hnsdt.models.minigrid_nets, hnsdt.agents.minigrid_play): the sub-goal
target as the agent sees it, the cached (transformer) and step-by-step (recurrent) acting against the whole-episode
pass, learning DoorKey from a small dataset, and bad inputs."""

from pathlib import Path

import numpy as np
import pytest
import torch

from hnsdt.agents.minigrid_play import Job, play
from hnsdt.minigrid import make_env, read_world, snapshot
from hnsdt.models.minigrid_nets import MiniGridDT, MiniGridDTConfig, egocentric


@pytest.mark.parametrize("seed", range(6))
def test_the_target_offset_is_where_minigrid_shows_the_object_in_its_own_view(seed):
    """For every object and door of a DoorKey world, at the start and after random turns and steps: the target's
    (ahead, aside) offset, read at MiniGrid's own view position of the agent (column 3 + aside, row 6 − ahead), is
    that object's type whenever it falls in the view and MiniGrid shows it (not hidden behind a wall); and MiniGrid's
    own ``dir_vec`` / ``right_vec`` are one cell ahead / aside."""
    from minigrid.core.constants import OBJECT_TO_IDX

    env = make_env("MiniGrid-DoorKey-6x6-v0")
    obs, _ = env.reset(seed=seed)
    world, live = read_world(env, "MiniGrid-DoorKey-6x6-v0", seed)
    rng = np.random.default_rng(seed)
    checked = 0
    for _ in range(30):
        s = snapshot(world, env, live)
        u = env.unwrapped
        at = torch.tensor(s.cell)
        d = torch.tensor(s.direction)
        for vec, want in ((u.dir_vec, (1, 0)), (u.right_vec, (0, 1))):
            cell = torch.tensor((s.cell[0] + int(vec[1]), s.cell[1] + int(vec[0])))  # (x, y) -> (row, col)
            assert tuple((egocentric(cell, at, d, 15) - 15).tolist()) == want
        things = [(o.kind, cell) for o, cell in zip(world.objects, s.objects)] + [("door", door.cell)
                                                                                  for door in world.doors]
        for kind, cell in things:
            if min(cell) < 0:
                continue
            ahead, aside = (egocentric(torch.tensor(cell), at, d, 15) - 15).tolist()
            x, y = 3 + aside, 6 - ahead
            if 0 <= x < 7 and 0 <= y < 7 and obs["image"][x, y, 0] != OBJECT_TO_IDX["unseen"]:
                assert obs["image"][x, y, 0] == OBJECT_TO_IDX[kind], (kind, cell, s)
                checked += 1
        obs, *_ = env.step(int(rng.choice([0, 1, 2, 2])))
    assert checked > 0
    assert egocentric(torch.tensor([-1, -1]), torch.tensor([2, 2]), torch.tensor(0), 15).tolist() == [-1, -1]


def test_the_networks_know_minigrids_own_ranges():
    """The networks' index ranges are MiniGrid's (they are written out so that loading any checkpoint does not
    import the MiniGrid world layer)."""
    from minigrid.core.constants import COLOR_TO_IDX, DIR_TO_VEC, OBJECT_TO_IDX, STATE_TO_IDX

    from hnsdt.minigrid.collect import SUBGOAL_NAMES
    from hnsdt.minigrid.world import Actions
    from hnsdt.models import minigrid_nets as nets

    assert (nets.N_ACTIONS, nets.N_OBJECTS, nets.N_COLORS, nets.N_DOOR_STATES, nets.N_DIRECTIONS, nets.N_KINDS) == (
        len(Actions), len(OBJECT_TO_IDX), len(COLOR_TO_IDX), len(STATE_TO_IDX), len(DIR_TO_VEC), len(SUBGOAL_NAMES))


def _random_states(T: int) -> torch.Tensor:
    """(1, T, 152) step-state vectors with every index in MiniGrid's ranges."""
    return torch.cat([torch.randint(0, 5, (1, T, 2)), torch.randint(0, 4, (1, T, 1)), torch.randint(0, 3, (1, T, 2)),
                      torch.stack([torch.randint(0, 11, (1, T, 49)), torch.randint(0, 6, (1, T, 49)),
                                   torch.randint(0, 3, (1, T, 49))], -1).flatten(-2)], -1)


def test_acting_step_by_step_gives_the_whole_episode_pass_numbers():
    """The key/value cache (one step a call, as play acts) and the packed whole-episode pass of training give the
    same logits, for HNSDT's per-step sub-goals and the pure DT's returns."""
    torch.manual_seed(0)
    T = 21
    states = _random_states(T)
    actions = torch.randint(0, 7, (1, T))
    times = torch.arange(T)[None]
    for condition in ("subgoal", "return"):
        model = MiniGridDT(MiniGridDTConfig(condition=condition, context=4, n_layers=2, d_model=32)).eval()
        ids = torch.randint(0, 7, (1, T)) if condition == "subgoal" else None
        targets = (torch.cat([torch.randint(-1, 5, (1, T, 2)), torch.randint(0, 6, (1, T, 2))], -1)
                   if condition == "subgoal" else None)
        returns = torch.rand(1, T) if condition == "return" else None
        with torch.no_grad():
            whole = model.forward_episode(states, actions, times, ids, targets, returns)
            cache = model.start(1)
            prev = torch.tensor([model.n_actions])
            for t in range(T):
                one = model.step(cache, torch.tensor([0]), states[:, t], prev, times[:, t],
                                 None if ids is None else ids[:, t], None if targets is None else targets[:, t],
                                 None if returns is None else returns[:, t])
                assert torch.allclose(one[0], whole[0, t], atol=1e-4), (condition, t)
                prev = actions[:, t]


@pytest.mark.parametrize("cell,hierarchical", [("lstm", True), ("gru", False)])
def test_the_recurrent_controllers_act_step_by_step_as_their_whole_episode_pass(cell, hierarchical):
    """Play's recurrent acting (one step a call, each episode's state a column of one batch, episodes dropping out)
    gives the training pass's logits; the hierarchical one reads its own sub-goal choice."""
    from hnsdt.agents.minigrid_play import _Recurrent
    from hnsdt.models.minigrid_nets import N_KINDS, MiniGridRecurrent, MiniGridRecurrentConfig

    torch.manual_seed(0)
    T = 9
    model = MiniGridRecurrent(MiniGridRecurrentConfig(cell=cell, hierarchical=hierarchical, n_layers=2, hidden=32,
                                                      embed=16)).eval()
    assert model.n_actions == 7 and (not hierarchical or model.subgoal_head.out_features == N_KINDS)
    episodes = [_random_states(T) for _ in range(3)]
    actor, chosen, stepped = _Recurrent(model, 3), [[], [], []], [[], [], []]
    step = model.step

    def recorded(states, prev, hidden):  # (what play's acting computed, per episode and step)
        out = step(states, prev, hidden)
        for k, i in enumerate(rows):
            stepped[i].append(out[0][k])
        return out
    model.step = recorded
    for t in range(T):
        rows = [0, 1, 2] if t < 4 else [0, 2]  # (episode 1 ends after 4 steps)
        got = actor.actions(rows, torch.cat([episodes[i][:, t] for i in rows]).numpy(), None, None, None)
        for k, i in enumerate(rows):
            chosen[i].append(int(got[k]))
    for i, ep in enumerate(episodes):
        n = len(chosen[i])
        prev = torch.tensor([[model.n_actions] + chosen[i][:-1]])
        with torch.no_grad():
            logits, sub_logits, _ = model(ep[:, :n], prev)
        assert torch.allclose(torch.stack(stepped[i]), logits[0], atol=1e-4), (cell, i)
        assert logits[0].argmax(-1).tolist() == chosen[i], (cell, i)
        assert (sub_logits is not None) == hierarchical


@pytest.fixture(scope="module")
def doorkey5(tmp_path_factory):
    """Noisy symbolic-agent episodes on 40 DoorKey-5x5 worlds, as a LeRobot dataset, read back as frames."""
    from hnsdt.data.minigrid_dataset import load_minigrid_frames, write_minigrid_dataset
    from hnsdt.minigrid.collect import collect_episodes

    seeds, fail_probs = list(range(40)), [0.0, 0.2]
    episodes = collect_episodes("MiniGrid-DoorKey-5x5-v0", seeds, fail_probs, 1, 0.1, 0)
    root = write_minigrid_dataset(tmp_path_factory.mktemp("dk5") / "ds", "local/dk5", episodes, 10,
                                  dict(env_id="MiniGrid-DoorKey-5x5-v0", world_seeds=seeds, fail_probs=fail_probs,
                                       epsilon=0.1, seed=0, license="apache-2.0"))
    return root, load_minigrid_frames(root)


@pytest.mark.learning
def test_hnsdt_learns_to_act_on_unseen_doorkey_worlds_and_the_planner_token_is_what_it_follows(doorkey5):
    """HNSDT trained on 40 DoorKey-5x5 worlds finishes ≥ 0.9 of 20 unseen ones at fail_prob 0.1 (the untrained
    network: ≤ 0.3, so the threshold measures learning); with every sub-goal token replaced by the first
    operator's (GoTo the key), the trained one finishes ≤ 0.5: it reads the planner's token, not the view alone."""
    from hnsdt.models.train import TrainConfig, train_decision_transformer

    _, frames = doorkey5
    cfg = MiniGridDTConfig(condition="subgoal", context=8, n_layers=2, d_model=64)
    jobs = [Job(10_000 + s, 0.1, 0) for s in range(20)]
    untrained = MiniGridDT(cfg).eval()
    assert np.mean([e.success for e in play(untrained, "MiniGrid-DoorKey-5x5-v0", jobs, max_steps=60)]) <= 0.3
    model, _, usage = train_decision_transformer(frames, cfg, TrainConfig(epochs=12, batch_size=512, seed=0,
                                                                          device="cpu"), progress=False,
                                                 network=MiniGridDT)
    episodes = play(model, "MiniGrid-DoorKey-5x5-v0", jobs, max_steps=60)
    assert np.mean([e.success for e in episodes]) >= 0.9, [e.steps for e in episodes]
    assert usage["dataset_frames"] == len(frames)

    step = model.step
    def first_operator_only(cache, rows, states, prev, times, ids, targets, returns):
        return step(cache, rows, states, prev, times, torch.ones_like(ids), torch.cat(
            [targets[:, :2] * 0 - 1, targets[:, 2:] * 0 + torch.tensor([5, 4])], -1), returns)
    model.step = first_operator_only
    blind = play(model, "MiniGrid-DoorKey-5x5-v0", jobs, max_steps=60)
    assert np.mean([e.success for e in blind]) <= 0.5


@pytest.mark.learning
def test_the_gru_learns_doorkey_from_the_same_dataset(doorkey5):
    """The GRU controller (behaviour cloning on whole episodes) trained on the 40 DoorKey-5x5 worlds finishes ≥ 0.8
    of 20 unseen ones at fail_prob 0.1; the untrained one none of them."""
    from hnsdt.baselines.recurrent import RecurrentTrainConfig, train_recurrent
    from hnsdt.models.minigrid_nets import MiniGridRecurrent, MiniGridRecurrentConfig

    _, frames = doorkey5
    cfg = MiniGridRecurrentConfig(cell="gru", n_layers=2, hidden=64, embed=32)
    jobs = [Job(10_000 + s, 0.1, 0) for s in range(20)]
    untrained = MiniGridRecurrent(cfg).eval()
    assert np.mean([e.success for e in play(untrained, "MiniGrid-DoorKey-5x5-v0", jobs, max_steps=60)]) <= 0.1
    model, _, usage = train_recurrent(frames, cfg, RecurrentTrainConfig(epochs=20, batch_size=16, seed=0),
                                      progress=False, network=MiniGridRecurrent)
    episodes = play(model, "MiniGrid-DoorKey-5x5-v0", jobs, max_steps=60)
    assert np.mean([e.success for e in episodes]) >= 0.8, [e.steps for e in episodes]
    assert usage["dataset_frames"] == len(frames)


def test_a_dataset_that_is_not_minigrids_is_one_clear_line(tmp_path, doorkey5):
    from hnsdt.data.format import DatasetError
    from hnsdt.data.minigrid_dataset import load_minigrid_frames

    with pytest.raises(DatasetError, match="no such folder"):
        load_minigrid_frames(tmp_path / "nowhere")
    root, _ = doorkey5
    import json
    import shutil
    copy = shutil.copytree(root, tmp_path / "copy")
    meta = json.loads((copy / "meta/hnsdt.json").read_text())
    meta["subgoal_kinds"] = ["none", "move"]
    (copy / "meta/hnsdt.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="not a MiniGrid dataset") as err:
        load_minigrid_frames(copy)
    assert "\n" not in str(err.value)


def test_learn_params_refuse_validation_worlds_that_are_trained_or_tested_on():
    import yaml

    from conftest import REPO
    from hnsdt.compose.params import MiniGridParams

    section = yaml.safe_load((Path(REPO) / "params.yaml").read_text())["minigrid"]
    assert MiniGridParams(**section).learn.validation_seeds.first == 50000
    for first in (section["test_seeds"]["first"], 0):
        bad = dict(section, learn=dict(section["learn"], validation_seeds={"first": first, "count": 5}))
        with pytest.raises(ValueError, match="validation_seeds overlaps"):
            MiniGridParams(**bad)
    with pytest.raises(ValueError, match="learn needs collect"):
        MiniGridParams(**{k: v for k, v in section.items() if k != "collect"})


def test_an_rnn_baseline_without_its_network_knobs_is_one_clear_line(tmp_path):
    """The RNN baselines on MiniGrid take their size, batch and learning rate from ``baselines.<name>``; a missing
    one is named."""
    import yaml

    from conftest import REPO
    from hnsdt.compose.config import load_params
    from hnsdt.compose.minigrid import _recurrent_settings
    from hnsdt.compose.params import ParamsError

    raw = yaml.safe_load((Path(REPO) / "params.yaml").read_text())
    params = load_params(Path(REPO) / "params.yaml")
    model, train = _recurrent_settings(params, "lstm_hier", params.minigrid.learn)
    assert (model.cell, model.hierarchical, model.hidden, train.batch_size) == (
        "lstm", True, raw["baselines"]["lstm_hier"]["hidden"], raw["baselines"]["lstm_hier"]["batch_size"])
    del raw["baselines"]["gru"]["hidden"]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(raw))
    params = load_params(tmp_path / "params.yaml")
    with pytest.raises(ParamsError, match="baselines.gru lacks hidden") as err:
        _recurrent_settings(params, "gru", params.minigrid.learn)
    assert "\n" not in str(err.value)


@pytest.mark.learning
def test_ppo_learns_doorkey_5x5_within_the_rl_zoo_budget():
    """PPO (rl-starter-files' defaults) in 40 DoorKey-5x5 training worlds under fail_probs 0 and 0.2, 100k frames (RL
    Baselines3 Zoo's budget on DoorKey-5x5): ≥ 0.8 of 20 unseen worlds at fail_prob 0.1 greedily, where its first
    measurement (after 25k frames) reached none of the validation worlds' goals — learned, not given."""
    from hnsdt.baselines.minigrid_ppo import MiniGridPPOConfig, train_minigrid_ppo
    from hnsdt.evaluation.minigrid import StepsOnWorlds
    from hnsdt.models.minigrid_nets import MiniGridActorCriticConfig

    env = "MiniGrid-DoorKey-5x5-v0"
    measure = StepsOnWorlds(env, [Job(50_000 + s, 0.1, 0) for s in range(10)], 60)
    model, curve, usage = train_minigrid_ppo(env, list(range(40)), [0.0, 0.2], MiniGridActorCriticConfig(),
                                             MiniGridPPOConfig(max_frames=100_000, eval_every=25_000), measure,
                                             progress=False)
    assert usage["validation_steps"][0]["value"] == 60.0
    episodes = play(model, env, [Job(10_000 + s, 0.1, 0) for s in range(20)], max_steps=100)
    assert np.mean([e.success for e in episodes]) >= 0.8, usage["validation_steps"]
    assert curve[-1]["frames"] >= 100_000 or usage["stopped_early"]


@pytest.mark.parametrize("code", ["policy_gradient", "q_learning", "option_critic"])
def test_online_runs_are_the_same_bytes_for_the_same_seed_and_differ_for_another(code):
    """PPO, DQN and option-critic on MiniGrid (hnsdt.compose.minigrid.ONLINE): a run is its seed's bytes, and
    another seed's differ (each learns here: the replay learners start learning within the 1,024 frames)."""
    from hnsdt.compose.minigrid import ONLINE
    from hnsdt.evaluation.minigrid import StepsOnWorlds

    network, trainer, train = ONLINE[code]
    env = "MiniGrid-DoorKey-5x5-v0"
    measure = StepsOnWorlds(env, [Job(50_000, 0.1, 0)], 20)
    knobs = {k: v for k, v in dict(rollout_steps=128, learning_starts=256).items() if k in trainer.__dataclass_fields__}
    weights = []
    for seed in (0, 0, 1):
        model, curve, usage = train(env, [0, 1, 2], [0.0, 0.3], network(),
                                    trainer(seed=seed, max_frames=1024, num_envs=4, eval_every=512, **knobs), measure,
                                    progress=False)
        weights.append(torch.cat([p.flatten() for p in model.state_dict().values()]))
        assert curve[-1]["frames"] == 1024 and usage["gradient_steps"] > 0
    assert torch.equal(weights[0], weights[1]) and not torch.equal(weights[0], weights[2])


def test_option_critic_plays_each_episode_with_its_own_draws():
    """Option-critic's options and actions are drawn in play (call-and-return): each episode from a generator of its
    own, so an episode is the same played alone or beside others. Fails with one generator shared by the batch."""
    from hnsdt.models.minigrid_nets import MiniGridOptionCritic, MiniGridOptionCriticConfig

    torch.manual_seed(0)
    model = MiniGridOptionCritic(MiniGridOptionCriticConfig()).eval()
    env = "MiniGrid-DoorKey-5x5-v0"
    jobs = [Job(10_000 + s, 0.0, k) for s in range(2) for k in range(2)]  # (no failures: only the draws differ)
    together = {i: [] for i in range(len(jobs))}
    play(model, env, jobs, max_steps=30, traces=together)
    actions = {i: [step.action for step in trace] for i, trace in together.items()}
    for i in (1, 2):
        alone = {0: []}
        play(model, env, [jobs[i]], max_steps=30, traces=alone)
        assert [step.action for step in alone[0]] == actions[i]
    assert actions[0] != actions[1]  # (the same world twice: another episode's own draws)


def test_a_worlds_episodes_at_fail_prob_0_are_played_once_each_the_one_it_plays_alone(monkeypatch):
    """At fail_prob 0 no action fails, so a greedy learner's episodes of one world are one episode: play makes one
    game per world there (and one per job at other fail_probs), and each job gets the episode it plays alone. Fails
    when worlds or failure probabilities are merged, or an episode lands on another job."""
    import hnsdt.agents.minigrid_play as minigrid_play
    from hnsdt.models.minigrid_nets import MiniGridRecurrent, MiniGridRecurrentConfig

    torch.manual_seed(0)
    model = MiniGridRecurrent(MiniGridRecurrentConfig(cell="gru", n_layers=1, hidden=32, embed=16)).eval()
    env = "MiniGrid-DoorKey-5x5-v0"
    jobs = [Job(10_000 + s, p, k) for s in range(3) for p in (0.0, 0.5) for k in range(3)]
    made = []
    game = minigrid_play._Game.__init__
    monkeypatch.setattr(minigrid_play._Game, "__init__", lambda self, env_id, job, *rest: (
        made.append(job), game(self, env_id, job, *rest))[1])
    together = play(model, env, jobs, max_steps=25)
    expected = [Job(10_000 + s, 0.0, 0) for s in range(3)] + [job for job in jobs if job.fail_prob == 0.5]
    assert len(made) == len(expected) and set(made) == set(expected)
    alone = [play(model, env, [job], max_steps=25)[0] for job in jobs]
    assert together == alone
