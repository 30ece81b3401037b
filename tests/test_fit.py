"""A training run stopped between epochs and continued elsewhere ends in the same bytes as one run in one go;
the executor queues a task's continuation behind the waiting tasks and returns results in task order."""

import contextlib
import pickle
from dataclasses import replace

import numpy as np
import pytest
import torch

from hnsdt.agents import SymbolicAgent, rollout
from hnsdt.baselines.recurrent import RecurrentTrainConfig, train_recurrent
from hnsdt.models.windows import frames_from_arrays
from hnsdt.envs import KeyDoorVectorEnv
from hnsdt.core.compute import Compute, Continue, run_tasks
from hnsdt.models.dt import DTConfig
from hnsdt.models.fit import FitState
from hnsdt.models.recurrent import RecurrentConfig
from hnsdt.models.train import TrainConfig, train_dt


@pytest.fixture(scope="module")
def frames(keydoor):
    eps = rollout(KeyDoorVectorEnv(24, keydoor, 0.2, 100), SymbolicAgent(keydoor), seed=3)
    cat = lambda f: np.concatenate([f(i, e) for i, e in enumerate(eps)])  # noqa: E731
    return frames_from_arrays(cat(lambda i, e: e.states[:-1]), cat(lambda i, e: e.actions),
                              cat(lambda i, e: e.rewards), cat(lambda i, e: e.subgoal_ids),
                              cat(lambda i, e: e.subgoal_targets), cat(lambda i, e: np.full(e.length, i)),
                              cat(lambda i, e: np.arange(e.length)))


def _dt(frames, keydoor, formulation="window", **kw):
    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, dropout=0.3,
                   max_timestep=100, formulation=formulation)  # dropout: the resumed half continues the stream
    return train_dt(frames, cfg, TrainConfig(epochs=3, batch_size=32, seed=2, log_every=3), progress=False, **kw)


def _episode_dt(frames, keydoor, **kw):
    return _dt(frames, keydoor, "episode", **kw)


def _rnn(frames, keydoor, **kw):
    cfg = RecurrentConfig(cell="lstm", hierarchical=True, n_flags=keydoor.n_flags, grid_h=keydoor.shape[0],
                          grid_w=keydoor.shape[1], n_layers=2, hidden=32, embed=16, dropout=0.2)
    out = train_recurrent(frames, cfg, RecurrentTrainConfig(epochs=3, batch_size=4, seed=2, log_every=3),
                          progress=False, **kw)
    return out[:2] if isinstance(out, tuple) else out


@pytest.mark.parametrize("train", [_dt, _episode_dt, _rnn], ids=["decision_transformer", "episodes", "lstm"])
def test_a_run_stopped_and_continued_elsewhere_is_the_run_in_one_go(frames, keydoor, train):
    whole, whole_curve = train(frames, keydoor)
    state = train(frames, keydoor, stop_after=1)
    assert isinstance(state, FitState) and state.epoch == 1 and 0 < state.step < whole_curve[-1]["step"]
    torch.manual_seed(123)  # another process: whatever its streams were, the state's replace them
    np.random.seed(123)
    part, part_curve = train(frames, keydoor, state=pickle.loads(pickle.dumps(state)))
    assert part_curve == whole_curve
    for (name, a), b in zip(whole.state_dict().items(), part.state_dict().values()):
        assert torch.equal(a, b), name
    assert not part.training
    for part_name, change in _STATE_PARTS.items():  # ... and it is the state's run: change a part, change the run
        other, other_curve = train(frames, keydoor, state=change(pickle.loads(pickle.dumps(state))))
        assert other_curve != whole_curve or not _same_weights(whole, other), f"{part_name} of the state unused"


def _same_weights(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values()))


def _nudged_moments(optimizer: dict) -> dict:
    return {**optimizer, "state": {i: {k: v * 1.5 if k == "exp_avg" else v for k, v in moments.items()}
                                   for i, moments in optimizer["state"].items()}}


# What a continued run must read from its state; a run that ignored it and redid the run from its seed would
# end in the same bytes as one run in one go, so each of these, changed, must change what it ends in.
_STATE_PARTS = {
    "weights": lambda s: replace(s, model={k: v + 0.01 if v.is_floating_point() else v for k, v in s.model.items()}),
    "optimiser moments": lambda s: replace(s, optimizer=_nudged_moments(s.optimizer)),
    "batch order's stream": lambda s: replace(s, rng=np.random.default_rng(999)),
    "dropout's stream": lambda s: replace(s, torch_rng=torch.Generator().manual_seed(999).get_state()),
    "epochs done": lambda s: replace(s, epoch=s.epoch + 1),
}


def _dqn(keydoor, **kw):
    from hnsdt.baselines.dqn import DQNConfig, train_dqn
    from hnsdt.models.qnetwork import QNetworkConfig

    return train_dqn(keydoor, 100, QNetworkConfig(keydoor.n_flags, *keydoor.shape, hidden=32),
                     DQNConfig(env_steps=1600, learning_starts=400, log_every=400, seed=3), progress=False, **kw)


def _options(keydoor, **kw):
    from hnsdt.baselines.options import OptionsConfig, train_options
    from hnsdt.models.qnetwork import OptionCriticConfig

    return train_options(keydoor, 100, OptionCriticConfig(keydoor.n_flags, *keydoor.shape, hidden=32),
                         OptionsConfig(env_steps=1600, learning_starts=400, log_every=400, seed=3), progress=False,
                         **kw)


def _weights_sum(net) -> float:
    return float(sum(p.double().sum() for p in net.parameters()))


def _dqn_validated(keydoor, **kw):
    """DQN trained to a plateau (of a measure that follows the weights): it keeps the weights of step 1,000 and
    stops at 1,400 of 1,600 steps."""
    from hnsdt.baselines.dqn import DQNConfig, train_dqn
    from hnsdt.models.qnetwork import QNetworkConfig

    return train_dqn(keydoor, 100, QNetworkConfig(keydoor.n_flags, *keydoor.shape, hidden=32),
                     DQNConfig(env_steps=1600, learning_starts=400, log_every=400, seed=7, patience=2,
                               validate_every=200), progress=False, measure=_weights_sum, **kw)


@pytest.mark.parametrize("train", [_dqn, _options, _dqn_validated], ids=["dqn", "option_critic", "dqn_validated"])
def test_an_online_run_paused_and_continued_elsewhere_is_the_run_in_one_go(keydoor, train):
    whole, whole_curve, whole_usage = train(keydoor)
    paused = train(keydoor, stop_after=800)
    assert not isinstance(paused, tuple) and paused.steps == 800 and paused.grad_steps > 0
    torch.manual_seed(123)
    part, part_curve, part_usage = train(keydoor, state=pickle.loads(pickle.dumps(paused)))
    assert part_usage == whole_usage
    if train is _dqn_validated:  # (its evaluations before the pause and after it, its plateau after it)
        assert whole_usage["stopped_early"] and (whole_usage["best_step"], whole_usage["env_steps"]) == (1000, 1400)
    np.testing.assert_equal(part_curve, whole_curve)  # (NaN losses before learning starts)
    for (name, a), b in zip(whole.state_dict().items(), part.state_dict().values()):
        assert torch.equal(a, b), name
    # ... and it is the paused run's: a run that ignored it and started again from its seed would end in the same
    # bytes, so its weights or its stream, changed, must change what it ends in
    changed = pickle.loads(pickle.dumps(paused))
    with torch.no_grad():
        for p in changed.net.parameters():
            p.add_(0.01)
    assert not _same_weights(whole, train(keydoor, state=changed)[0]), "the paused weights unused"
    changed = pickle.loads(pickle.dumps(paused))
    changed.rngs = [np.random.default_rng(999) for _ in changed.rngs]
    other, other_curve, _ = train(keydoor, state=changed)
    assert not _same_weights(whole, other), "the paused stream unused"


def _countdown(task: tuple[str, int]):
    """A task in ``parts`` parts: it hands back its remaining parts until the last one."""
    label, parts = task
    return Continue((label, parts - 1)) if parts > 1 else f"{label} done"


@pytest.mark.parametrize("workers", [1, 2])
def test_continued_tasks_come_back_in_task_order(workers):
    tasks = [("a", 3), ("b", 1), ("c", 2), ("d", 1), ("e", 2)]
    out = run_tasks(_countdown, tasks, Compute(workers=workers), progress=False)
    assert out == ["a done", "b done", "c done", "d done", "e done"]


@pytest.mark.parametrize("workers", [1, 2])
def test_costlier_tasks_start_first_and_results_keep_task_order(tmp_path, workers):
    """With ``cost``, the tasks start longest first (one worker: the log is the start order), equal costs in task
    order; the results still come back in task order. Fails when the cost is ignored or the results follow it."""
    log = tmp_path / "log"
    tasks = [(label, str(log), False) for label in "abcde"]
    cost = {"a": 1, "b": 3, "c": 2, "d": 3, "e": 0}
    out = run_tasks(_logged, tasks, Compute(workers=workers), progress=False, cost=lambda t: cost[t[0]])
    assert out == [f"{label} done" for label in "abcde"]
    if workers == 1:
        assert log.read_text().split() == ["b", "d", "c", "a", "e"]


def test_one_worker_runs_its_tasks_through_the_pickles_of_a_pool():
    """What one process runs is what a pool's worker would be handed: a task that cannot cross to a worker (a
    lambda here) fails in this process too, and a result comes back as a copy, not the object the task made."""
    with pytest.raises((pickle.PicklingError, AttributeError)):
        run_tasks(_countdown, [("a", 1), (lambda: 0, 1)], Compute(workers=1), progress=False)
    state = np.arange(3)
    (out,) = run_tasks(_same, [state], Compute(workers=1), progress=False)
    assert out is not state and (out == state).all()


def _same(task):
    return task


def _logged(task: tuple[str, str, bool]):
    """Appends its label to the file ``log`` (a count of the tasks that ran), then fails if told to."""
    label, log, fail = task
    with open(log, "a") as f:
        f.write(label + "\n")
    if fail:
        raise RuntimeError(f"{label} failed")
    return f"{label} done"


@pytest.mark.parametrize("workers", [1, 2])
def test_tasks_finished_before_a_run_stopped_are_not_run_again(tmp_path, workers, monkeypatch, capsys):
    """With ``keep``, each finished task's result is kept as it finishes: a run that stops part-way (here a
    task that fails; in a stage, a kill) and is started again runs only the tasks that had not finished, says
    so, and returns every result in task order. A kept result is taken only for the same task of the same code:
    another task, or the same task after the code changed, runs again. Fails when nothing is kept (every task
    runs twice) or a result is taken for another task."""
    from hnsdt.core import compute

    log, keep = tmp_path / "log", tmp_path / "kept"
    tasks = [(label, str(log), label == "c") for label in "abcd"]
    with pytest.raises(RuntimeError, match="c failed"):
        run_tasks(_logged, tasks, Compute(workers=workers), progress=False, keep=keep)
    kept = len(list(keep.glob("*.pkl")))  # a, b with one worker; with two, those done before c's failure came
    assert kept >= (2 if workers == 1 else 1)
    log.write_text("")
    tasks[2] = ("c", str(log), False)  # (mended: another task, which runs)
    out = run_tasks(_logged, tasks, Compute(workers=workers), progress=False, keep=keep)
    assert out == ["a done", "b done", "c done", "d done"]
    ran = log.read_text().split()
    assert "c" in ran and len(ran) == 4 - kept
    assert "runs finished before this one was stopped" in capsys.readouterr().out
    log.write_text("")
    assert run_tasks(_logged, tasks, Compute(workers=1), progress=False, keep=keep) == out
    assert log.read_text() == ""  # all four kept
    monkeypatch.setattr(compute, "_CODE_DIGEST", ["other code"])
    assert run_tasks(_logged, tasks[:1], Compute(workers=1), progress=False, keep=keep) == out[:1]
    assert log.read_text().split() == ["a"]  # another code: not taken


def test_a_stage_keeps_finished_tasks_only_while_killed(tmp_path):
    """The folder of kept results goes when the block ends, with the output written or with an error (which
    is an end, not a kill), and stays after an interrupt (Ctrl-C) for the next run."""
    from hnsdt.core.fileio import finished_tasks

    out = tmp_path / "models"
    for error in (None, RuntimeError):
        with contextlib.suppress(RuntimeError):
            with finished_tasks(out) as keep:
                keep.mkdir()
                if error:
                    raise error("stop")
        assert not keep.exists()
    with contextlib.suppress(KeyboardInterrupt):
        with finished_tasks(out) as keep:
            keep.mkdir()
            raise KeyboardInterrupt
    assert keep.is_dir() and keep.name.startswith(".hnsdt-tmp-models")


def test_episode_batches_hold_each_episode_once_and_close_at_the_batch_size():
    from hnsdt.models.fit import Objective

    sizes = np.array([5, 30, 2, 2, 9, 14, 1, 40])
    objective = Objective(np.arange(8), None, None, None, sizes=sizes)
    order = np.random.default_rng(0).permutation(8)
    batches = objective.batches(order, 16)
    assert np.array_equal(np.concatenate(batches), order)
    assert all(sizes[b].sum() >= 16 for b in batches[:-1])  # each closes once it reaches the batch size ...
    assert all(sizes[b[:-1]].sum() < 16 for b in batches)  # ... and not later
    assert objective.steps_per_epoch(16) == 7


def test_validation_stops_at_the_plateau_and_keeps_the_best_epoch(frames, keydoor):
    """Measured after each epoch: 3.0, 2.0, 2.5, 2.4 with patience 2 -> stops after epoch 4 of 10, weights of 2."""
    from hnsdt.models.fit import Validation

    values = iter([3.0, 2.0, 2.5, 2.4, 1.0, 1.0])
    snapshots = {}
    validation = Validation(lambda model: next(values), patience=2)
    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, max_timestep=100,
                   formulation="episode")
    model, curve = train_dt(frames, cfg, TrainConfig(epochs=10, batch_size=32, seed=2), progress=False,
                            validation=validation, on_epoch=lambda e, step, m: snapshots.__setitem__(
                                e, {k: v.clone() for k, v in m.state_dict().items()}))
    assert [h["epoch"] for h in validation.history] == [1, 2, 3, 4] and validation.stopped_early
    assert validation.best_epoch == 2 and curve[-1]["epoch"] == 4 and not model.training
    for name, value in model.state_dict().items():
        assert torch.equal(value, snapshots[2][name]), name


def test_a_recurrent_learner_holds_out_episodes_and_keeps_the_epoch_of_their_lowest_loss(frames, keydoor):
    """With ``validation`` a share of the episodes trains nothing and their loss per action is the measure: the
    model kept is the epoch whose held-out loss was the lowest (measured again here on those episodes), and the
    data used counts the rest. Fails when the held-out episodes train too or another epoch's weights are kept."""
    from hnsdt.baselines.recurrent import held_out_loss, training_episodes
    from hnsdt.models.train import validation_episodes

    cfg = RecurrentConfig(cell="gru", hierarchical=False, n_flags=keydoor.n_flags, grid_h=keydoor.shape[0],
                          grid_w=keydoor.shape[1], n_layers=1, hidden=16, embed=8)
    train_cfg = RecurrentTrainConfig(epochs=6, batch_size=4, lr=0.02, seed=1, validation=0.25, patience=2)
    model, curve, usage = train_recurrent(frames, cfg, train_cfg, progress=False)
    starts, lengths = training_episodes(frames)
    held = validation_episodes(frames, 0.25)[starts]
    assert held.sum() == 6 and usage["dataset_episodes"] == 24 - 6 and usage["dataset_frames"] == lengths[~held].sum()
    values = [h["value"] for h in usage["validation_loss"]]
    assert usage["best_epoch"] == 1 + int(np.argmin(values)) and len(values) == curve[-1]["epoch"]
    assert held_out_loss(frames, starts[held], lengths[held], 4)(model) == min(values)
    with pytest.raises(ValueError, match="set patience"):
        train_recurrent(frames, cfg, replace(train_cfg, patience=0), progress=False)


def test_a_learner_that_never_reached_the_exit_is_at_no_plateau(frames, keydoor):
    """A measure at its ceiling (every validation start failed: the step limit) in every epoch so far does not
    stop training on patience: 100, 100, 100, then 60, 70, 80 with patience 2 runs on past epoch 3 and stops
    after epoch 6 (the weights of 4). Fails when the ceiling rule is cut (it stops after epoch 3)."""
    from hnsdt.models.fit import Validation

    class Steps:
        ceiling = 100.0

        def __init__(self):
            self.values = iter([100.0, 100.0, 100.0, 60.0, 70.0, 80.0, 50.0])

        def __call__(self, model):
            return next(self.values)

    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, max_timestep=100,
                   formulation="episode")
    validation = Validation(Steps(), patience=2)
    train_dt(frames, cfg, TrainConfig(epochs=10, batch_size=32, seed=2), progress=False, validation=validation)
    assert [h["epoch"] for h in validation.history] == [1, 2, 3, 4, 5, 6] and validation.best_epoch == 4
    # ... and at its ceiling throughout, it trains to the cap
    always = Steps()
    always.values = iter([100.0] * 5)
    validation = Validation(always, patience=2)
    train_dt(frames, cfg, TrainConfig(epochs=5, batch_size=32, seed=2), progress=False, validation=validation)
    assert len(validation.history) == 5 and not validation.stopped_early


def test_a_measure_at_its_floor_ends_training_at_once_with_the_weights_a_longer_run_keeps(frames, keydoor):
    """A measure that reaches its floor (no model can do better: the optimum's steps) stops after that epoch,
    keeping the weights the patience rule would have kept after more epochs."""
    from hnsdt.models.fit import Validation

    class Steps:  # measured after each epoch: 5.0, 4.0 (= the floor), then 4.0 again
        floor = 4.0

        def __init__(self):
            self.values = iter([5.0, 4.0, 4.0, 4.0])

        def __call__(self, model):
            return next(self.values)

    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, max_timestep=100,
                   formulation="episode")
    runs = {}
    for floor in (True, False):
        measure = Steps()
        if not floor:
            measure.floor = float("-inf")
        validation = Validation(measure, patience=2)
        runs[floor] = validation, train_dt(frames, cfg, TrainConfig(epochs=10, batch_size=32, seed=2), progress=False,
                                           validation=validation)[0]
    (at_floor, short), (patient, long) = runs[True], runs[False]
    assert [h["epoch"] for h in at_floor.history] == [1, 2] and at_floor.stopped_early
    assert [h["epoch"] for h in patient.history] == [1, 2, 3, 4]
    assert at_floor.best_epoch == patient.best_epoch == 2
    assert at_floor.record("steps")["validation_floor"] == 4.0 and "validation_floor" not in patient.record("steps")
    for (name, a), b in zip(short.state_dict().items(), long.state_dict().values()):
        assert torch.equal(a, b), name


def test_a_validated_run_stopped_and_continued_elsewhere_is_the_run_in_one_go(frames, keydoor):
    """The validation record and the best epoch's weights travel in the state too."""
    from hnsdt.models.train import train_decision_transformer

    cfg = DTConfig("subgoal", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, dropout=0.3,
                   max_timestep=100, formulation="episode")
    tc = TrainConfig(epochs=6, batch_size=32, seed=2, log_every=3, validation=0.25, patience=1, lr=0.02)
    whole, curve, usage = train_decision_transformer(frames, cfg, tc, progress=False)
    state = train_decision_transformer(frames, cfg, tc, progress=False, stop_after=1)
    assert isinstance(state, FitState) and len(state.validated) == 1 and state.best is not None
    torch.manual_seed(123)
    part, part_curve, part_usage = train_decision_transformer(frames, cfg, tc, progress=False,
                                                              state=pickle.loads(pickle.dumps(state)))
    assert part_curve == curve and part_usage == usage and usage["validation_frames"] > 0
    assert usage["best_epoch"] == min(usage["validation_loss"], key=lambda h: h["value"])["epoch"]
    for (name, a), b in zip(whole.state_dict().items(), part.state_dict().values()):
        assert torch.equal(a, b), name
    # the best epoch so far travels too: one no later epoch can beat is the one the continued run keeps
    kept = {k: v + 0.01 if v.is_floating_point() else v for k, v in state.best[2].items()}
    unbeaten, _, unbeaten_usage = train_decision_transformer(
        frames, cfg, tc, progress=False, state=replace(state, best=(float("-inf"), state.best[1], kept)))
    assert unbeaten_usage["best_epoch"] == state.best[1]
    assert all(torch.equal(kept[k], v) for k, v in unbeaten.state_dict().items())


@pytest.mark.parametrize("validated", [True, False], ids=["plateau", "fixed_budget"])
def test_a_seed_sharing_workers_pauses_after_every_epoch_when_a_plateau_ends_it(frames, keydoor, validated):
    """Where seeds share workers (train_all), a run that a validation plateau ends — after an epoch no one knows
    beforehand — hands back its state after every epoch, so the seeds take turns epoch by epoch; a fixed budget
    pauses once, half-way. Chained through pickles (as between processes), each ends in the run's bytes."""
    from hnsdt.compose.training import TrainTask, train_run

    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, dropout=0.3,
                   max_timestep=100, formulation="episode")
    tc = (TrainConfig(epochs=8, batch_size=32, seed=2, log_every=3, validation=0.25, patience=1, lr=0.02)
          if validated else TrainConfig(epochs=4, batch_size=32, seed=2, log_every=3))
    task = TrainTask("pure_dt", 2, cfg, tc, frames, {"dataset": "d"})
    whole, facts, curve = train_run(task)
    epochs = facts["usage"]["epochs"]
    assert not validated or 2 < epochs < 8  # (the plateau ended it before the cap, after a few epochs)
    out, pauses = train_run(pickle.loads(pickle.dumps(replace(task, split=True)))), []
    while isinstance(out, Continue):
        pauses.append(out.task.state.epoch)
        out = train_run(pickle.loads(pickle.dumps(out.task)))
    assert pauses == (list(range(1, int(epochs))) if validated else [2])
    part, part_facts, part_curve = out
    assert part_facts == facts and part_curve == curve
    for (name, a), b in zip(whole.state_dict().items(), part.state_dict().values()):
        assert torch.equal(a, b), name


def test_validation_episodes_are_a_share_of_each_behaviour_never_trained_on(frames, keydoor):
    from hnsdt.models.train import objective_for, validation_episodes
    from hnsdt.models.windows import episode_spans

    mixed = frames_from_arrays(frames.states, frames.actions, frames.rewards, frames.subgoals, frames.targets,
                               frames.episode, frames.timestep,
                               np.where(frames.episode % 3 == 0, "random", "noisy_planner"))
    held = validation_episodes(mixed, 0.25)
    starts, _ = episode_spans(mixed)
    for policy in ("random", "noisy_planner"):
        mine = mixed.policy[starts] == policy
        assert held[starts][mine].sum() == round(0.25 * mine.sum())
    assert np.array_equal(held, validation_episodes(mixed, 0.25)) and not validation_episodes(mixed, 0.0).any()
    for formulation in ("window", "episode"):
        cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, formulation=formulation)
        tc = TrainConfig(validation=0.25)
        train, val = objective_for(mixed, cfg, tc), objective_for(mixed, cfg, tc, "validation")
        if formulation == "window":  # examples: the frames windows end at
            assert not held[train.examples].any() and held[val.examples].all()
            assert len(train.examples) + len(val.examples) == len(mixed)
        else:  # examples: episodes, their sizes their steps
            assert train.sizes.sum() == (~held).sum() and val.sizes.sum() == held.sum()


def test_our_adam_steps_torchs_update():
    """hnsdt.models.optim.Adam is torch's update with a correctly rounded square root (torch's is MKL's, whose
    roots differ in the last bit by MKL's mode), state-dict round trip included, and refuses the options it does
    not step (that it imports no torch._dynamo: test_kernels' child process, which starts without it)."""
    from hnsdt.models.optim import Adam

    def train(cls):
        torch.manual_seed(0)
        net = torch.nn.Sequential(torch.nn.Linear(3, 8), torch.nn.ReLU(), torch.nn.Linear(8, 2))
        opt = cls(net.parameters(), lr=1e-2)
        for i in range(12):
            opt.zero_grad()
            (net(torch.randn(4, 3)) ** 2).sum().backward()
            opt.step()
            if i == 5:
                state = opt.state_dict()
                opt = cls(net.parameters(), lr=1e-2)
                opt.load_state_dict(state)
        return torch.cat([p.detach().flatten() for p in net.parameters()])

    ours, torchs = train(Adam), train(torch.optim.Adam)
    torch.testing.assert_close(ours, torchs, rtol=1e-5, atol=1e-6)
    assert not torch.equal(ours, train(lambda params, lr: Adam(params, lr=lr, eps=1e-3)))  # (the test can fail)
    net = torch.nn.Linear(2, 1)
    net(torch.ones(1, 2)).sum().backward()
    with pytest.raises(ValueError, match="amsgrad"):
        Adam(net.parameters(), amsgrad=True).step()
