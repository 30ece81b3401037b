import numpy as np
import pytest
import torch

from hnsdt.agents import SymbolicAgent, rollout
from hnsdt.agents.dt_agents import History, HNSDTAgent, _greedy
from hnsdt.models.windows import frames_from_arrays, make_windows, window_ends
from hnsdt.envs import KeyDoorVectorEnv
from hnsdt.models.dt import DecisionTransformer, DTConfig
from hnsdt.models.train import TrainConfig, load_checkpoint, save_checkpoint, train_dt


def _cfg(condition, **kw):
    return DTConfig(condition, n_flags=2, grid_h=5, grid_w=5, context=4, n_layers=2, n_heads=4, d_model=32,
                    dropout=0.0, max_timestep=100, **kw)


def _batch(cfg, B=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    h = cfg.context
    states = torch.stack([torch.randint(0, 5, (B, h), generator=g), torch.randint(0, 5, (B, h), generator=g),
                          torch.randint(0, 2, (B, h), generator=g), torch.randint(0, 2, (B, h), generator=g)], -1)
    return {"states": states, "actions": torch.randint(0, 5, (B, h), generator=g),
            "timesteps": torch.arange(h).repeat(B, 1), "pad": torch.zeros(B, h, dtype=torch.bool),
            "subgoal_ids": torch.tensor([1, 27, 125])[:B], "subgoal_targets": torch.tensor([[4, 0], [4, 0], [0, 4]])[:B],
            "returns": torch.randn(B, h, generator=g)}


@pytest.mark.parametrize("tokens", ["step", "interleaved"])
@pytest.mark.parametrize("condition", ["subgoal", "return"])
def test_shapes_and_sequence_length(condition, tokens):
    cfg = _cfg(condition, tokens=tokens)
    model = DecisionTransformer(cfg).eval()
    b = _batch(cfg)
    logits = model(b["states"], b["actions"], b["timesteps"], b["pad"], **_cond(condition, b))
    assert logits.shape == (3, cfg.context, 5)
    expected = {("subgoal", "interleaved"): 2 * 4, ("return", "interleaved"): 3 * 4 - 1,
                ("subgoal", "step"): 4 + 1, ("return", "step"): 4}  # step: the paper's h + 1 with the sub-goal
    assert cfg.seq_len == expected[(condition, tokens)]


def _cond(condition, b):
    if condition == "subgoal":
        return {"subgoal_ids": b["subgoal_ids"], "subgoal_targets": b["subgoal_targets"]}
    return {"returns": b["returns"]}


@pytest.mark.parametrize("tokens", ["step", "interleaved"])
@pytest.mark.parametrize("condition", ["subgoal", "return"])
def test_causal_masking_future_steps_do_not_change_past_predictions(condition, tokens):
    cfg = _cfg(condition, tokens=tokens)
    model = DecisionTransformer(cfg).eval()
    b = _batch(cfg)
    before = model(b["states"], b["actions"], b["timesteps"], b["pad"], **_cond(condition, b))
    b2 = {k: v.clone() for k, v in b.items()}
    b2["states"][:, -1] = (b2["states"][:, -1] + 1) % 2  # change only the last step's state and action
    b2["actions"][:, -2] = (b2["actions"][:, -2] + 1) % 5
    after = model(b2["states"], b2["actions"], b2["timesteps"], b2["pad"], **_cond(condition, b2))
    # no step sees its own action (the label) or anything later: every step but the last is unchanged
    assert torch.allclose(before[:, :-1], after[:, :-1], atol=1e-6)
    assert not torch.allclose(before[:, -1], after[:, -1])  # the changed step's prediction does move


def test_subgoal_token_conditions_every_prediction():
    cfg = _cfg("subgoal")
    model = DecisionTransformer(cfg).eval()
    b = _batch(cfg)
    a = model(b["states"], b["actions"], b["timesteps"], b["pad"], b["subgoal_ids"], b["subgoal_targets"])
    other = model(b["states"], b["actions"], b["timesteps"], b["pad"], torch.tensor([2, 28, 124]), b["subgoal_targets"])
    assert not torch.allclose(a[:, 0], other[:, 0])


@pytest.mark.parametrize("tokens", ["step", "interleaved"])
def test_padded_steps_are_ignored_whatever_they_hold(tokens):
    cfg = _cfg("subgoal", tokens=tokens)
    model = DecisionTransformer(cfg).eval()
    b = _batch(cfg)
    b["pad"][:, :2] = True
    a = model(b["states"], b["actions"], b["timesteps"], b["pad"], b["subgoal_ids"], b["subgoal_targets"])
    b["states"][:, :2] = (b["states"][:, :2] + 1) % 2
    b["actions"][:, :2] = (b["actions"][:, :2] + 3) % 5
    c = model(b["states"], b["actions"], b["timesteps"], b["pad"], b["subgoal_ids"], b["subgoal_targets"])
    assert torch.allclose(a[:, 2:], c[:, 2:], atol=1e-6)


def _expert_frames(layout, n=64, fail_prob=0.1, seed=0):
    eps = rollout(KeyDoorVectorEnv(n, layout, fail_prob, 100), SymbolicAgent(layout), seed=seed)
    cols = {k: [] for k in ("states", "actions", "rewards", "subgoals", "targets", "episode", "timestep")}
    for i, e in enumerate(eps):
        cols["states"].append(e.states[:-1]), cols["actions"].append(e.actions), cols["rewards"].append(e.rewards)
        cols["subgoals"].append(e.subgoal_ids), cols["targets"].append(e.subgoal_targets)
        cols["episode"].append(np.full(e.length, i)), cols["timestep"].append(np.arange(e.length))
    return frames_from_arrays(*(np.concatenate(cols[k]) for k in cols))


def test_history_windows_equal_training_windows(keydoor):
    """What the agent feeds the model at step t is exactly the training window ending at frame t."""
    frames = _expert_frames(keydoor, n=1)
    T = len(frames)
    hist = History(frames.states[:1], h=4)
    for t in range(T):
        w = make_windows(frames, np.array([t]), 4, "subgoal")
        for key in ("states", "timesteps", "pad"):
            got = getattr(hist, key)[0]
            want = w[key][0]
            real = ~w["pad"][0]
            assert np.array_equal(got[real], want[real]) if key != "pad" else np.array_equal(got, want)
        assert np.array_equal(hist.actions[0][~w["pad"][0]][:-1], w["actions"][0][~w["pad"][0]][:-1])
        hist.record_action(np.array([0]), frames.actions[t : t + 1])
        if t + 1 < T:
            hist.push(np.array([0]), frames.states[t + 1 : t + 2])


@pytest.mark.parametrize("condition", ["subgoal", "return"])
def test_acting_runs_each_distinct_window_once_with_the_same_actions(condition):
    """Agents send identical windows through the model once; every row gets the action of its own window."""
    torch.manual_seed(0)
    model = DecisionTransformer(_cfg(condition)).eval()
    batch = _batch(model.cfg)
    keys = ["states", "actions", "timesteps", "pad"] + (
        ["subgoal_ids", "subgoal_targets"] if condition == "subgoal" else ["returns"])
    order = [2, 0, 2, 1, 0, 2]  # duplicates, out of order
    inputs = {k: batch[k].numpy()[order] for k in keys}
    calls = []
    hook = model.register_forward_hook(lambda module, args, logits: calls.append(len(logits)))
    actions = _greedy(model, inputs)
    hook.remove()
    with torch.no_grad():
        one_by_one = [model(**{k: torch.from_numpy(v[i : i + 1]) for k, v in inputs.items()})[0, -1].argmax().item()
                      for i in range(len(order))]
    assert actions.tolist() == one_by_one
    assert calls == [3]  # one forward over the 3 distinct windows


@pytest.mark.learning
def test_hnsdt_overfits_a_tiny_dataset_and_then_acts_optimally(keydoor):
    frames = _expert_frames(keydoor, n=48, fail_prob=0.1)
    cfg = DTConfig("subgoal", keydoor.n_flags, *keydoor.shape, context=6, n_layers=2, d_model=64, dropout=0.0,
                   max_timestep=100)
    model, curve = train_dt(frames, cfg, TrainConfig(epochs=60, max_steps=150, batch_size=128, lr=1e-3, seed=0),
                            progress=False)
    assert curve[-1]["loss"] < 0.15 < curve[0]["loss"]
    eps = rollout(KeyDoorVectorEnv(32, keydoor, 0.0, 100), HNSDTAgent(keydoor, model), seed=1)
    assert all(e.success for e in eps) and all(e.length == 14 for e in eps)


def test_same_seed_same_weights_and_checkpoint_round_trip(tmp_path, keydoor):
    frames = _expert_frames(keydoor, n=8)
    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, max_timestep=100)
    tc = TrainConfig(epochs=1, max_steps=3, batch_size=16, seed=5)
    a, _ = train_dt(frames, cfg, tc, progress=False)
    b, _ = train_dt(frames, cfg, tc, progress=False)
    for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(va, vb), k
    save_checkpoint(a, tmp_path / "ckpt", {"target_return": -0.4})
    c, meta = load_checkpoint(tmp_path / "ckpt")
    assert meta["target_return"] == -0.4 and meta["model"]["condition"] == "return"
    for va, vc in zip(a.state_dict().values(), c.state_dict().values()):
        assert torch.equal(va, vc)
    with pytest.raises(FileNotFoundError, match="missing model.safetensors"):
        load_checkpoint(tmp_path / "nothing")


def test_training_windows_cover_labelled_frames_only_for_hnsdt(keydoor):
    frames = _expert_frames(keydoor, n=4)
    frames.subgoals[:3] = 0
    assert 0 not in frames.subgoals[window_ends(frames, "subgoal")]
    assert len(window_ends(frames, "return")) == len(frames)
