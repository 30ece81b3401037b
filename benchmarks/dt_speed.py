"""Our decision transformer against Hugging Face's ``DecisionTransformerModel``, side by side in one process.

Usage: python benchmarks/dt_speed.py [--repeats 3] [--steps 4] [--threads 2] [--device cpu|cuda] [--case case1]
Needs the benchmark-only extra: ``pip install -e .[bench]`` (transformers; never a runtime dependency).

At the paper's sizes (Case 1: L3/H4/d128/context 10, 100-step episodes; Case 2: L5/H4/d128/context 20,
250-step episodes) every contender learns the same batch of episodes (Case 1: 16 x 100 steps; Case 2:
8 x 250), each step's action predicted from its last h steps, and acts for 64 episodes at once:

* training -> supervised steps/s (forward + cross-entropy + backward + Adam over the batch, divided by its steps):
  - ``episode`` (ours): one pass over whole episodes, attention banded to h steps — each step computed once;
  - ``window`` (ours, the paper's formulation): one window of the last h steps per step (loss on its last);
  - HF, one window per step (3h tokens each, loss on its last step): what the paper's objective costs there;
  - HF, windows strided by h (every step of a window supervised, each step once but with 1..h steps of
    context): the cheapest HF can cover the batch;
* inference -> decisions/s, one greedy action per episode with h steps of history: ``episode`` steps one
  token through its key/value cache, the others recompute their window (eval mode, no grad). On a GPU, where
  64 decisions are bound by kernel launches, ours (episode) and HF's are also timed replayed from a CUDA
  graph, and "vs HF" divides by HF's faster way.

Rows alternate between the contenders, ``--repeats`` rounds, and the best round is kept (least disturbed).
HF's model interleaves three tokens per step (return, state, action: 3h tokens); ours puts one token per step
(state + previous action + the step's conditioning), the paper's "h + 1 tokens" (Appendix C). HF's model
reads float states and actions (one-hot actions, normalised row/col/flags), ours integer ones through
embeddings; its head is linear on the state token's output as ours.
"""

from __future__ import annotations

import argparse
import time

from hnsdt.core.reproducible import pin_process

pin_process()  # the pipeline's kernels and threads: the figures are what a stage sees

import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402

from hnsdt.models.dt import N_ACTIONS, NO_ACTION, DecisionTransformer, DTConfig  # noqa: E402

SIZES = {"case1": dict(n_layers=3, context=10, grid=5, flags=1, max_t=100, episodes=16),
         "case2": dict(n_layers=5, context=20, grid=9, flags=6, max_t=250, episodes=8)}
INFER = 64  # episodes acting at once
WINDOWS = 256  # a window per step: the windows timed, evenly spread over the batch (cost is linear in them)


def random_steps(size: dict, B: int, T: int, g: torch.Generator) -> dict:
    states = torch.cat([torch.randint(0, size["grid"], (B, T, 2), generator=g),
                        torch.randint(0, 2, (B, T, size["flags"]), generator=g)], dim=-1)
    return {"states": states, "actions": torch.randint(0, N_ACTIONS, (B, T), generator=g),
            "timesteps": torch.arange(T).repeat(B, 1), "subgoal_ids": torch.randint(1, 8, (B, T), generator=g),
            "subgoal_targets": torch.randint(0, size["grid"], (B, T, 2), generator=g),
            "returns": torch.rand(B, T, generator=g)}


def windows_of(ep: dict, h: int, stride: int, keep: int = 0) -> dict:
    """Windows of h steps ending at every ``stride``-th step (left-padded at the episode's start); ``keep`` > 0:
    only that many of them, evenly spread."""
    B, T = ep["actions"].shape
    ends = torch.arange(T - 1, -1, -stride).flip(0)
    idx = ends[:, None] - torch.arange(h - 1, -1, -1)[None]
    pad = idx < 0
    idx = idx.clamp(min=0)
    out = {k: v[:, idx].reshape(B * len(ends), h, *v.shape[2:]) for k, v in ep.items()}
    out["pad"] = pad.repeat(B, 1)
    if keep:
        pick = torch.linspace(0, len(out["pad"]) - 1, keep).long()
        out = {k: v[pick] for k, v in out.items()}
    return out


def ours(size: dict, condition: str, formulation: str, device):
    torch.manual_seed(0)
    return DecisionTransformer(DTConfig(condition, size["flags"], size["grid"], size["grid"],
                                        context=size["context"], n_layers=size["n_layers"],
                                        max_timestep=size["max_t"], formulation=formulation)).to(device)


def ours_train_batch(ep: dict, condition: str, formulation: str, h: int, device) -> dict:
    keep = ["states", "actions", "timesteps"] + (["subgoal_ids", "subgoal_targets"] if condition == "subgoal"
                                                 else ["returns"])
    if formulation == "episode":
        b = {k: ep[k] for k in keep}
        b["loss_mask"] = torch.ones_like(ep["actions"], dtype=torch.bool)
    else:  # one window per step, its sub-goal the last step's, loss on the last step (the paper's objective)
        w = windows_of(ep, h, 1, WINDOWS)
        b = {k: w[k] for k in keep + ["pad"]}
        if condition == "subgoal":
            b["subgoal_ids"], b["subgoal_targets"] = w["subgoal_ids"][:, -1], w["subgoal_targets"][:, -1]
        b["loss_mask"] = torch.zeros_like(w["actions"], dtype=torch.bool)
        b["loss_mask"][:, -1] = True
    return {k: v.to(device) for k, v in b.items()}


def hf_model(size: dict, device):
    from transformers import DecisionTransformerConfig, DecisionTransformerModel

    torch.manual_seed(0)
    cfg = DecisionTransformerConfig(state_dim=2 + size["flags"], act_dim=N_ACTIONS, hidden_size=128,
                                    max_ep_len=size["max_t"] + 1, n_layer=size["n_layers"], n_head=4,
                                    n_inner=512, activation_function="gelu", action_tanh=False,
                                    n_positions=3 * size["context"])
    return DecisionTransformerModel(cfg).to(device)


def hf_batch(w: dict, size: dict, last_only: bool, device) -> dict:
    return {"states": w["states"].float().to(device) / size["grid"],
            "actions": F.one_hot(w["actions"], N_ACTIONS).float().to(device),
            "returns_to_go": w["returns"][..., None].to(device), "timesteps": w["timesteps"].to(device),
            "attention_mask": (~w["pad"]).long().to(device), "targets": w["actions"].to(device),
            "last_only": last_only}


def hf_logits(model, b: dict) -> torch.Tensor:
    out = model(states=b["states"], actions=b["actions"], rewards=None, returns_to_go=b["returns_to_go"],
                timesteps=b["timesteps"], attention_mask=b["attention_mask"], return_dict=True)
    return out.action_preds


def sync(device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def best_time(step, n: int, device) -> float:
    step()  # warm-up (allocations, kernel choice)
    sync(device)
    t = time.perf_counter()
    for _ in range(n):
        step()
    sync(device)
    return (time.perf_counter() - t) / n


def train_step(model, b: dict, hf: bool):
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)

    def step():
        model.train()
        if hf:
            logits = hf_logits(model, b)
            if b["last_only"]:
                loss = F.cross_entropy(logits[:, -1], b["targets"][:, -1])
            else:
                real = b["attention_mask"].bool()
                loss = F.cross_entropy(logits[real], b["targets"][real])
        else:
            loss = model.loss(b)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return step


def contenders(size: dict, device) -> dict:
    """name -> (train step, supervised steps per train step, decide step): each on its own model and data."""
    h, B, T = size["context"], size["episodes"], size["max_t"]
    g = torch.Generator().manual_seed(0)
    episodes = random_steps(size, B, T, g)
    acting = random_steps(size, INFER, h, g)  # h steps of history, then one decision each
    out = {}
    for condition in ("subgoal", "return"):
        who = "hnsdt" if condition == "subgoal" else "pure DT"
        for formulation in ("episode", "window"):
            model = ours(size, condition, formulation, device)
            b = ours_train_batch(episodes, condition, formulation, h, device)
            out[f"ours {who}, {formulation}"] = (train_step(model, b, False),
                                                 B * T if formulation == "episode" else WINDOWS,
                                                 ours_decide(model, acting, condition, formulation, device))
    model = hf_model(size, device)
    per_step = windows_of({k: episodes[k] for k in ("states", "actions", "timesteps", "returns")}, h, 1, WINDOWS)
    strided = windows_of({k: episodes[k] for k in ("states", "actions", "timesteps", "returns")}, h, h)
    out["HF DT, a window per step"] = (train_step(model, hf_batch(per_step, size, True, device), True), WINDOWS,
                                      hf_decide(model, hf_batch(windows_of(acting, h, h), size, True, device)))
    model = hf_model(size, device)
    out["HF DT, windows strided by h"] = (train_step(model, hf_batch(strided, size, False, device), True), B * T,
                                         None)
    return out


def ours_decide(model, acting: dict, condition: str, formulation: str, device):
    cond = ["subgoal_ids", "subgoal_targets"] if condition == "subgoal" else ["returns"]
    h = acting["actions"].shape[1]
    if formulation == "episode":  # a cache holding h - 1 steps; each call adds one and decides
        model.eval()
        rows = torch.arange(INFER, device=device)
        cache = model.start(INFER)
        d = {k: v.to(device) for k, v in acting.items()}
        for t in range(h - 1):
            model.step(cache, rows, d["states"][:, t], d["actions"][:, t - 1] if t else torch.full_like(rows, NO_ACTION),
                       d["timesteps"][:, t], **{k: d[k][:, t] for k in cond})
        last = {k: d[k][:, -1] for k in ["states", "timesteps"] + cond}
        prev = d["actions"][:, -2]

        def decide():
            cache.seen -= 1  # the same step again: its slot rewritten, the window unchanged
            with torch.inference_mode():
                return model.step(cache, rows, last["states"], prev, last["timesteps"],
                                  **{k: last[k] for k in cond}).argmax(-1)
        return decide
    w = windows_of(acting, h, h)
    b = {k: w[k].to(device) for k in ["states", "actions", "timesteps", "pad"] + cond}
    if condition == "subgoal":
        b["subgoal_ids"], b["subgoal_targets"] = b["subgoal_ids"][:, -1], b["subgoal_targets"][:, -1]

    def decide():
        model.eval()
        with torch.inference_mode():
            return model(b["states"], b["actions"], b["timesteps"], b["pad"], b.get("subgoal_ids"),
                         b.get("subgoal_targets"), b.get("returns"))[:, -1].argmax(-1)
    return decide


def hf_decide(model, b: dict):
    def decide():
        model.eval()
        with torch.inference_mode():
            return hf_logits(model, b)[:, -1].argmax(-1)
    return decide


def graphed(decide):
    """``decide`` captured once in a CUDA graph and replayed (no per-kernel launch cost), or None if it cannot be
    captured."""
    try:
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            for _ in range(3):
                decide()
        torch.cuda.current_stream().wait_stream(side)
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            out = decide()
    except RuntimeError as e:
        print(f"(no CUDA graph: {e})")
        return None

    def replay():
        graph.replay()
        return out
    return replay


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=4, help="timed training steps (inference: 8x as many)")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0 = the pinned default)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--case", choices=sorted(SIZES), action="append")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    print(f"device {device}, torch {torch.__version__}, threads {torch.get_num_threads()}")
    for case in args.case or sorted(SIZES):
        size = SIZES[case]
        steps = contenders(size, device)
        if device.type == "cuda":  # acting is launch-bound at this batch on a GPU: the same, kernels graphed
            for name in ("ours hnsdt, episode", "HF DT, a window per step"):
                replay = graphed(steps[name][2])
                if replay is not None:
                    steps[f"{name.split(',')[0]}, CUDA graph"] = (None, steps[name][1], replay)
        best = {name: [np.inf, np.inf] for name in steps}
        for _ in range(args.repeats):
            for name, (train, _, decide) in steps.items():
                if train is not None:
                    best[name][0] = min(best[name][0], best_time(train, args.steps, device))
                if decide is not None:
                    best[name][1] = min(best[name][1], best_time(decide, 8 * args.steps, device))
        rate = {name: steps[name][1] / tr for name, (tr, _) in best.items()}  # supervised steps/s
        hf_infer = best["HF DT, a window per step"][1]
        if "HF DT, CUDA graph" in best:
            hf_infer = min(hf_infer, best["HF DT, CUDA graph"][1])
        print(f"\n{case}: L{size['n_layers']}/H4/d128/context {size['context']}; train {size['episodes']} episodes x "
              f"{size['max_t']} steps; {INFER} episodes acting")
        print(f"{'model':30s} {'supervised steps/s':>19s} {'vs HF':>7s} {'vs HF strided':>14s} "
              f"{'decisions/s':>12s} {'vs HF':>7s}")
        for name, (tr, inf) in best.items():
            acting = f"{INFER / inf:12,.0f} {hf_infer / inf:6.2f}x" if np.isfinite(inf) else f"{'-':>12s} {'':7s}"
            training = (f"{rate[name]:19,.0f} {rate[name] / rate['HF DT, a window per step']:6.2f}x "
                        f"{rate[name] / rate['HF DT, windows strided by h']:13.2f}x" if np.isfinite(tr)
                        else f"{'-':>19s} {'':7s} {'':14s}")
            print(f"{name:30s} {training} {acting}")


if __name__ == "__main__":
    main()
