"""What packing a batch's episodes end to end buys the decision transformers' training, per gradient step.

Usage: python benchmarks/packed_episodes.py [--envs keydoor multikeydoor] [--methods hnsdt pure_dt hnsdt_paper]
                                            [--batches 40] [--rounds 2]
Reads the pipeline's datasets (data/datasets/ENV; run `dvc repro` first) and each method's training examples
as the `train` stage builds them (params.yaml), takes the first --batches batches of one shuffled epoch and
times the loss and its gradient on each, padded (every episode padded to the batch's longest, as until
993b555) and packed (the real steps end to end, attention kept within each episode: what training does now),
--rounds times alternately, on one thread as in the pipeline. Prints the padded steps per real step and the
milliseconds per batch of both, and checks that both give the same loss up to rounding (eval mode, no dropout).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hnsdt.core.reproducible import pin_process

pin_process()

import numpy as np  # noqa: E402
import torch  # noqa: E402


def gradient_ms(model, batches: list[dict], loss_of) -> float:
    """Milliseconds per batch of ``loss_of(batch)`` and its gradient."""
    start = time.perf_counter()
    for batch in batches:
        loss = loss_of(batch)
        model.zero_grad()
        loss.backward()
    return (time.perf_counter() - start) / len(batches) * 1000


def fastest_ms(model, rounds: int, *runs) -> list[float]:
    """The fastest of ``rounds`` timings of each run ``(batches, loss_of)``, the runs taking turns."""
    ms = [[gradient_ms(model, batches, loss_of) for batches, loss_of in runs] for _ in range(rounds)]
    return [min(column) for column in zip(*ms)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["keydoor", "multikeydoor"])
    parser.add_argument("--methods", nargs="+", default=["hnsdt", "pure_dt", "hnsdt_paper"])
    parser.add_argument("--batches", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()

    from hnsdt.compose import training
    from hnsdt.compose.config import load_params
    from hnsdt.models.dt import DecisionTransformer
    from hnsdt.models.fit import to_device
    from hnsdt.models.train import objective_for

    torch.set_num_threads(1)
    params = load_params("params.yaml")
    print(f"{'env':<13} {'method':<12} {'padded/real':>11} {'padded ms':>10} {'packed ms':>10} {'speed-up':>8}")
    for env in args.envs:
        for method in args.methods:
            task = training.plan_runs(params, env, method, [0], Path("data/datasets") / env)[0]
            if task.model_cfg.formulation != "episode":
                print(f"{env:<13} {method:<12} (window formulation: nothing padded to pack)")
                continue
            objective = objective_for(task.frames(), task.model_cfg, task.train_cfg)
            order = np.random.default_rng(0).permutation(objective.examples)
            rows = objective.batches(order, task.train_cfg.batch_size)
            batches = [to_device(objective.batch(r), torch.device("cpu")) for r in rows[:args.batches]]
            padded_steps = sum(b["steps"].numel() for b in batches) / sum(int(b["steps"].sum()) for b in batches)
            torch.manual_seed(0)
            model = DecisionTransformer(task.model_cfg)
            with torch.no_grad():
                model.eval()
                for b in batches:
                    plain = {k: v for k, v in b.items() if k != "steps"}
                    assert torch.allclose(model.loss(b), model.loss(plain), atol=1e-5), "packed loss differs"
            model.train()
            unpacked = [{k: v for k, v in b.items() if k != "steps"} for b in batches]
            padded, packed = fastest_ms(model, args.rounds, (unpacked, model.loss), (batches, model.loss))
            print(f"{env:<13} {method:<12} {padded_steps:>11.2f} {padded:>10.1f} {packed:>10.1f} "
                  f"{padded / packed:>7.2f}x", flush=True)


if __name__ == "__main__":
    main()
