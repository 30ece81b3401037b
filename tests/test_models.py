import numpy as np
import pytest
import torch

from hnsdt.agents import SymbolicAgent, rollout
from hnsdt.agents.dt_agents import History, HNSDTAgent, _greedy
from hnsdt.models.windows import frames_from_arrays, make_windows, window_ends
from hnsdt.envs import KeyDoorVectorEnv
from hnsdt.models.dt import NO_ACTION, DecisionTransformer, DTConfig
from hnsdt.models.train import TrainConfig, load_checkpoint, save_checkpoint, train_dt


def _cfg(condition, **kw):
    return DTConfig(condition, n_flags=2, grid_h=5, grid_w=5, **{"context": 4, "n_layers": 2, "n_heads": 4,
                    "d_model": 32, "dropout": 0.0, "max_timestep": 100} | kw)


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
    assert (b["subgoal_ids"] != torch.tensor([2, 28, 124])).all()
    moved = (a - other).abs().amax(dim=-1)  # (B, h): how far each prediction moved with the sub-goal
    assert (moved > 1e-4).all(), moved  # every step of every window, not only the first


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
def test_pure_dt_learns_to_reach_the_exit_an_untrained_one_does_not_reach(keydoor):
    """The pure DT (return-to-go, no sub-goal) trained on planner episodes reaches the exit of Case 1 in the
    optimal 14 steps from every start copy, asked for the dataset's best return; the same network untrained
    does not reach it."""
    from hnsdt.agents.dt_agents import PureDTAgent

    frames = _expert_frames(keydoor, n=48, fail_prob=0.1)
    cfg = DTConfig("return", keydoor.n_flags, *keydoor.shape, context=6, n_layers=2, d_model=64, dropout=0.0,
                   max_timestep=100, formulation="episode")
    best_return = max(frames.rewards[frames.episode == e].sum() for e in np.unique(frames.episode))
    torch.manual_seed(0)
    untrained = DecisionTransformer(cfg).eval()
    model, curve = train_dt(frames, cfg, TrainConfig(epochs=150, max_steps=150, batch_size=128, lr=1e-3, seed=0),
                            progress=False)
    assert curve[-1]["loss"] < 0.15 < curve[0]["loss"]
    trained, before = (rollout(KeyDoorVectorEnv(32, keydoor, 0.0, 100), PureDTAgent(m, best_return, keydoor), seed=1)
                       for m in (model, untrained))
    assert all(e.success for e in trained) and all(e.length == 14 for e in trained)
    assert not any(e.success for e in before)


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


# -- the episode formulation: banded attention over whole episodes, a key/value cache at inference ---------

def _episode(cfg, B=3, T=11, seed=0):
    g = torch.Generator().manual_seed(seed)
    states = torch.stack([torch.randint(0, 5, (B, T), generator=g), torch.randint(0, 5, (B, T), generator=g),
                          torch.randint(0, 2, (B, T), generator=g), torch.randint(0, 2, (B, T), generator=g)], -1)
    return {"states": states, "actions": torch.randint(0, 5, (B, T), generator=g),
            "timesteps": torch.arange(T).repeat(B, 1), "subgoal_ids": torch.randint(0, 30, (B, T), generator=g),
            "subgoal_targets": torch.randint(-1, 5, (B, T, 2), generator=g), "returns": torch.randn(B, T, generator=g)}


def _episode_cond(cfg, b, t=slice(None)):
    if cfg.condition == "subgoal":
        return {"subgoal_ids": b["subgoal_ids"][:, t], "subgoal_targets": b["subgoal_targets"][:, t]}
    return {"returns": b["returns"][:, t]} if cfg.condition == "return" else {}


@pytest.mark.parametrize("condition", ["subgoal", "return", "none"])
def test_cached_steps_compute_what_the_whole_episode_pass_computes(condition):
    """One token per step through the key/value cache gives every step's logits of the training pass (also past
    the context, where the ring of cached steps wraps round); rows advance independently."""
    cfg = _cfg(condition, formulation="episode")
    torch.manual_seed(0)
    model = DecisionTransformer(cfg).eval()
    b = _episode(cfg)
    with torch.no_grad():
        full = model(b["states"], b["actions"], b["timesteps"], None, **_episode_cond(cfg, b))
    assert full.shape == (3, 11, 5)
    cache = model.start(3)
    got = torch.zeros_like(full)
    for t in range(11):
        for rows in (torch.tensor([2]), torch.tensor([0, 1])):  # out of step within one time step
            prev = torch.full((len(rows),), NO_ACTION) if t == 0 else b["actions"][rows, t - 1]
            cond = {k: v[rows] for k, v in _episode_cond(cfg, b, t).items()}
            got[rows, t] = model.step(cache, rows, b["states"][rows, t], prev, b["timesteps"][rows, t], **cond)
    assert torch.allclose(got, full, atol=1e-5)


def test_copies_with_one_history_are_computed_once_and_act_as_if_alone():
    """Acting with the cache, copies whose histories are identical so far share one computation (a cell's
    copies at fail_prob 0; at others until an action fails): the model sees one row per distinct history, and
    every copy acts as it does alone — when copies part ways, a copy dies and its row is reused."""
    from hnsdt.agents.dt_agents import CachedContext

    cfg = _cfg("none", formulation="episode")
    torch.manual_seed(0)
    model = DecisionTransformer(cfg).eval()
    T, base = 11, _episode(cfg, B=1, T=11)["states"][0].numpy()
    other = _episode(cfg, B=3, T=11, seed=1)["states"].numpy()
    parts = {0: None, 1: (3, 0), 2: (6, 1), 3: (0, 2), 4: None, 5: (3, 0)}  # copy: (step it parts at, its way)
    states = np.stack([base if way is None else np.concatenate([base[:way[0]], other[way[1], way[0]:]])
                       for way in parts.values()])  # (6, T, 4): 1 and 5 part together, 3 from the start
    lives = np.array([T, T, T, T, 5, T])  # copy 4 ends after 5 steps
    seen = []  # (cache rows, logits) of every call of the model
    step = model.step
    model.step = lambda cache, rows, *a, **k: seen.append((rows, step(cache, rows, *a, **k))) or seen[-1][1]
    together, alone = CachedContext(model, states[:, 0]), [CachedContext(model, states[i:i + 1, 0]) for i in range(6)]
    for t in range(T):
        rows = np.flatnonzero(lives > t)
        got = together.decide(rows)
        cache_rows, logits = seen[-1]
        assert len(cache_rows) == len({states[i, :t + 1].tobytes() for i in rows})  # one per distinct history
        for i, a in zip(rows, got):
            mine = logits[int(torch.searchsorted(cache_rows, int(together.row[i])))]
            assert a == alone[i].decide(np.array([0]))[0], f"copy {i} at step {t}"
            assert torch.allclose(mine, seen[-1][1][0], atol=1e-6), f"copy {i} at step {t}"
            alone[i].observe(np.array([0]), np.array([a]), states[i:i + 1, min(t + 1, T - 1)])
        actions = np.zeros(6, dtype=np.int64)
        actions[rows] = got
        together.observe(rows, actions, states[:, min(t + 1, T - 1)])


@pytest.mark.parametrize("T", [1, 4, 7, 8, 23, 24])
def test_banded_attention_block_by_block_is_the_band_masked_attention(T):
    """Attention cut into blocks of h (each block's queries against its own and the previous block's keys)
    gives the whole-sequence attention under the band mask — for episodes shorter than, equal to, and not a
    multiple of h — and so does one encoder layer built on it."""
    from hnsdt.models.dt import band_mask, banded_attention, banded_layer

    g = torch.Generator().manual_seed(T)
    q, k, v = (torch.randn(2, 4, T, 8, generator=g) for _ in range(3))
    full = torch.nn.functional.scaled_dot_product_attention(q, k, v, attn_mask=band_mask(T, 8))
    assert torch.allclose(banded_attention(q, k, v, 8), full, atol=1e-6)
    layer = DecisionTransformer(_cfg("none", formulation="episode", context=8)).blocks.layers[0].eval()
    x = torch.randn(2, T, layer.linear1.in_features, generator=g)
    with torch.no_grad():
        assert torch.allclose(banded_layer(layer, x, 8), layer(x, src_mask=band_mask(T, 8)), atol=1e-5)


@pytest.mark.parametrize("condition", ["subgoal", "return", "none"])
def test_episodes_packed_end_to_end_compute_what_they_compute_padded(condition):
    """Training packs a batch's real steps into one sequence (no padding computed), attention kept within each
    episode: the logits of the real steps are the padded batch's, episodes of 1 step, shorter than h and
    crossing blocks included, and a pad's logits are 0; so does the loss."""
    cfg = _cfg(condition, formulation="episode", context=4)
    torch.manual_seed(0)
    model = DecisionTransformer(cfg).eval()
    b = _episode(cfg, B=5, T=11)
    lengths = torch.tensor([3, 11, 1, 7, 9])
    steps = torch.arange(11)[None] < lengths[:, None]
    with torch.no_grad():
        padded = model(b["states"], b["actions"], b["timesteps"], None, **_episode_cond(cfg, b))
        packed = model(b["states"], b["actions"], b["timesteps"], None, **_episode_cond(cfg, b), steps=steps)
        assert torch.allclose(packed[steps], padded[steps], atol=1e-5)
        assert not packed[~steps].any()
        batch = {**b, **_episode_cond(cfg, b), "loss_mask": steps}
        assert torch.allclose(model.loss({**batch, "steps": steps}), model.loss(batch), atol=1e-6)


def test_episode_attention_reaches_back_context_steps_per_layer():
    """With one layer, step t reads steps t - h + 1 .. t: a change h steps back is invisible, h - 1 back is not."""
    cfg = _cfg("return", formulation="episode", n_layers=1)
    model = DecisionTransformer(cfg).eval()
    b = _episode(cfg)
    run = lambda b: model(b["states"], b["actions"], b["timesteps"], None, returns=b["returns"])  # noqa: E731
    with torch.no_grad():
        base = run(b)
        for back, visible in ((cfg.context, False), (cfg.context - 1, True)):
            changed = {k: v.clone() for k, v in b.items()}
            changed["returns"][:, 9 - back] += 5.0
            out = run(changed)
            assert torch.allclose(out[:, 9], base[:, 9], atol=1e-6) != visible
            assert torch.allclose(out[:, :9 - back], base[:, :9 - back], atol=1e-6)  # causal


def test_episode_batches_supervise_every_labelled_step_once(keydoor):
    from hnsdt.models.windows import episode_spans, make_episodes

    frames = _expert_frames(keydoor, n=5)
    frames.subgoals[:2] = 0
    starts, lengths = episode_spans(frames)
    batch = make_episodes(frames, starts, lengths, "subgoal")
    assert batch["states"].shape[:2] == (5, lengths.max())
    assert batch["loss_mask"].sum() == (frames.subgoals != 0).sum()
    real = np.arange(lengths.max())[None] < lengths[:, None]
    assert np.array_equal(batch["actions"][real], frames.actions)  # episodes in order, right-padded
    assert np.array_equal(batch["subgoal_targets"][real], frames.targets)


@pytest.mark.parametrize("condition", ["subgoal", "return"])
def test_cached_agents_act_as_the_episode_pass_predicts(keydoor, condition):
    """An agent's cached decisions are the argmax of the training pass over the episode it produced: states,
    previous actions, timesteps and each step's own sub-goal / return-to-go reach the model as in training."""
    from hnsdt.agents.dt_agents import make_agent

    torch.manual_seed(1)
    model = DecisionTransformer(DTConfig(condition, keydoor.n_flags, *keydoor.shape, context=3, n_layers=2,
                                         d_model=32, max_timestep=100, formulation="episode")).eval()
    agent = make_agent(model, {"target_return": 0.5}, keydoor, None)
    eps = rollout(KeyDoorVectorEnv(4, keydoor, 0.3, 30), agent, seed=2)
    for e in eps:
        T = e.length
        b = {"states": torch.from_numpy(e.states[None, :T]), "actions": torch.from_numpy(e.actions[None]),
             "timesteps": torch.arange(T)[None]}
        if condition == "subgoal":
            b |= {"subgoal_ids": torch.from_numpy(e.subgoal_ids[None]),
                  "subgoal_targets": torch.from_numpy(e.subgoal_targets[None])}
        else:
            b["returns"] = torch.from_numpy((0.5 - np.r_[0, np.cumsum(e.rewards)[:-1]])[None]).float()
        with torch.no_grad():
            predicted = model(b.pop("states"), b.pop("actions"), b.pop("timesteps"), None, **b)[0].argmax(-1).numpy()
        acted = e.subgoal_ids > 0 if condition == "subgoal" else np.ones(T, bool)
        assert acted.any() and np.array_equal(predicted[acted], e.actions[acted])


@pytest.mark.learning
def test_episode_hnsdt_overfits_a_tiny_dataset_and_then_acts_optimally(keydoor):
    frames = _expert_frames(keydoor, n=48, fail_prob=0.1)
    cfg = DTConfig("subgoal", keydoor.n_flags, *keydoor.shape, context=6, n_layers=2, d_model=64, dropout=0.0,
                   max_timestep=100, formulation="episode")
    model, curve = train_dt(frames, cfg, TrainConfig(epochs=150, max_steps=150, batch_size=128, lr=1e-3, seed=0),
                            progress=False)
    assert curve[-1]["loss"] < 0.15 < curve[0]["loss"] and curve[-1]["step"] == 150
    eps = rollout(KeyDoorVectorEnv(32, keydoor, 0.0, 100), HNSDTAgent(keydoor, model), seed=1)
    assert all(e.success for e in eps) and all(e.length == 14 for e in eps)
