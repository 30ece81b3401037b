"""Our decision transformer against Hugging Face's ``DecisionTransformerModel``, side by side in one process.

Usage: python benchmarks/dt_speed.py [--repeats 3] [--steps 8] [--threads 2] [--device cpu|cuda]
Needs the benchmark-only extra: ``pip install -e .[bench]`` (transformers; never a runtime dependency).

At the paper's sizes (Case 1: L3/H4/d128/context 10; Case 2: L5/H4/d128/context 20) it times
* training: batch 128, forward + cross-entropy over the 5 actions + backward + Adam step -> windows/s;
* inference: batch 64, one greedy decision per window (eval mode, no grad) -> decisions/s.
Rows alternate between the models, ``--repeats`` rounds, and the best round is kept (least disturbed).

What differs, by design: HF's model interleaves three tokens per step (return, state, action: 3h tokens);
ours puts one token per step (state + previous action, plus the return for the pure DT: h tokens; plus one
sub-goal token for HNSDT: h + 1), the paper's "h + 1 tokens" (Appendix C). Each window carries the same
information and the same h supervised actions. Our ``tokens: interleaved`` layout is timed as well, to show
what the layout alone buys. HF's model reads float states and actions (here: one-hot actions, normalised
row/col/flags), ours integer ones through embeddings; its head is linear on the state token's output as ours.
"""

from __future__ import annotations

import argparse
import time

from hnsdt.reproducible import pin_process

pin_process()  # the pipeline's kernels and threads: the figures are what a stage sees

import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402

from hnsdt.models.dt import N_ACTIONS, DecisionTransformer, DTConfig  # noqa: E402

SIZES = {"case1": dict(n_layers=3, context=10, grid=5, flags=1, max_t=100),
         "case2": dict(n_layers=5, context=20, grid=9, flags=6, max_t=250)}


def ours_batch(size: dict, B: int, condition: str, device) -> dict:
    g = torch.Generator().manual_seed(0)
    h, grid = size["context"], size["grid"]
    states = torch.cat([torch.randint(0, grid, (B, h, 2), generator=g),
                        torch.randint(0, 2, (B, h, size["flags"]), generator=g)], dim=-1)
    batch = {"states": states, "actions": torch.randint(0, N_ACTIONS, (B, h), generator=g),
             "timesteps": torch.arange(h).repeat(B, 1), "pad": torch.zeros(B, h, dtype=torch.bool),
             "loss_mask": torch.ones(B, h, dtype=torch.bool)}
    if condition == "subgoal":
        batch["subgoal_ids"] = torch.randint(1, 8, (B,), generator=g)
        batch["subgoal_targets"] = torch.randint(0, grid, (B, 2), generator=g)
    else:
        batch["returns"] = torch.rand(B, h, generator=g)
    return {k: v.to(device) for k, v in batch.items()}


def hf_model(size: dict, device):
    from transformers import DecisionTransformerConfig, DecisionTransformerModel

    cfg = DecisionTransformerConfig(state_dim=2 + size["flags"], act_dim=N_ACTIONS, hidden_size=128,
                                    max_ep_len=size["max_t"] + 1, n_layer=size["n_layers"], n_head=4,
                                    n_inner=512, activation_function="gelu", action_tanh=False,
                                    n_positions=3 * size["context"])
    return DecisionTransformerModel(cfg).to(device)


def hf_batch(size: dict, B: int, device) -> dict:
    b = ours_batch(size, B, "return", "cpu")
    return {"states": b["states"].float().to(device) / size["grid"],
            "actions": F.one_hot(b["actions"], N_ACTIONS).float().to(device),
            "returns_to_go": b["returns"][..., None].to(device), "timesteps": b["timesteps"].to(device),
            "attention_mask": torch.ones(B, size["context"], dtype=torch.long, device=device),
            "targets": b["actions"].to(device)}


def hf_logits(model, b: dict) -> torch.Tensor:
    out = model(states=b["states"], actions=b["actions"], rewards=None, returns_to_go=b["returns_to_go"],
                timesteps=b["timesteps"], attention_mask=b["attention_mask"], return_dict=True)
    return out.action_preds


def sync(device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def time_train(step, steps: int, device) -> float:
    step()  # warm-up (allocations, kernel choice)
    sync(device)
    t = time.perf_counter()
    for _ in range(steps):
        step()
    sync(device)
    return (time.perf_counter() - t) / steps


def contenders(size: dict, device) -> dict:
    """name -> (train_step, infer_step) closures, each on its own model and batches."""
    out = {}
    for name, cond, tokens in (("ours hnsdt (step tokens, h+1)", "subgoal", "step"),
                               ("ours pure DT (step tokens, h)", "return", "step"),
                               ("ours pure DT (interleaved, 3h-1)", "return", "interleaved")):
        torch.manual_seed(0)
        model = DecisionTransformer(DTConfig(cond, size["flags"], size["grid"], size["grid"],
                                             context=size["context"], n_layers=size["n_layers"],
                                             max_timestep=size["max_t"], tokens=tokens)).to(device)
        out[name] = (model, ours_batch(size, 128, cond, device), ours_batch(size, 64, cond, device))
    torch.manual_seed(0)
    out["HF DecisionTransformerModel (3h)"] = (hf_model(size, device), hf_batch(size, 128, device),
                                               hf_batch(size, 64, device))
    steps = {}
    for name, (model, train_b, infer_b) in out.items():
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)
        hf = name.startswith("HF")

        def train_step(model=model, b=train_b, opt=opt, hf=hf):
            model.train()
            if hf:
                logits = hf_logits(model, b)
                loss = F.cross_entropy(logits.reshape(-1, N_ACTIONS), b["targets"].reshape(-1))
            else:
                loss = model.loss(b)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()

        def infer_step(model=model, b=infer_b, hf=hf):
            model.eval()
            with torch.inference_mode():
                if hf:
                    logits = hf_logits(model, b)
                else:
                    logits = model(b["states"], b["actions"], b["timesteps"], b["pad"], b.get("subgoal_ids"),
                                   b.get("subgoal_targets"), b.get("returns"))
                return logits[:, -1].argmax(-1)

        steps[name] = (train_step, infer_step)
    return steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=8, help="timed training steps (inference: 4x as many)")
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
        best = {name: [np.inf, np.inf] for name in steps}
        for _ in range(args.repeats):
            for name, (train_step, infer_step) in steps.items():
                best[name][0] = min(best[name][0], time_train(train_step, args.steps, device))
                best[name][1] = min(best[name][1], time_train(infer_step, 4 * args.steps, device))
        hf_train, hf_infer = best["HF DecisionTransformerModel (3h)"]
        print(f"\n{case}: L{size['n_layers']}/H4/d128/context {size['context']}; train batch 128, infer batch 64")
        print(f"{'model':36s} {'train windows/s':>16s} {'vs HF':>7s} {'decisions/s':>12s} {'vs HF':>7s}")
        for name, (tr, inf) in best.items():
            print(f"{name:36s} {128 / tr:16,.0f} {hf_train / tr:6.2f}x {64 / inf:12,.0f} {hf_infer / inf:6.2f}x")


if __name__ == "__main__":
    main()
