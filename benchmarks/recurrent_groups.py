"""What computing a batch's episodes in groups of like length buys the LSTM's and GRU's training, per step.

Usage: python benchmarks/recurrent_groups.py [--envs keydoor multikeydoor unseen] [--methods lstm_hier gru]
                                            [--batches 40] [--rounds 3] [--costs STEP GROUP]
Reads the pipeline's datasets (data/datasets/ENV; `unseen`: generalisation/dataset; run `dvc repro` first) and
each method's training episodes as its stage reads them (params.yaml), takes the first --batches batches of one
shuffled epoch and times the loss and its gradient on each, padded (every episode padded to the batch's longest in
one pass, as until 2026-12-03) and grouped (`RecurrentPolicy.loss`: hnsdt.models.recurrent.length_groups),
--rounds times alternately, on one thread as in the pipeline. Prints the padded steps per real step, the
milliseconds per batch of both (the fastest round) and the largest difference of the two losses (same weights).
--costs: group either cell with these costs instead of `GROUP_COSTS` (how they were chosen).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hnsdt.core.reproducible import pin_process

pin_process()

import numpy as np  # noqa: E402
import torch  # noqa: E402
from packed_episodes import fastest_ms  # noqa: E402  (benchmarks/, beside this script)


def padded_loss(model, batch: dict) -> torch.Tensor:
    """The loss as one padded pass computed it."""
    return model._nll_sum(batch) / batch["mask"].sum().clamp(min=1).float()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["keydoor", "multikeydoor", "unseen"])
    parser.add_argument("--methods", nargs="+", default=["lstm_hier", "gru"])
    parser.add_argument("--batches", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--costs", type=float, nargs=2, metavar=("STEP", "GROUP"))
    args = parser.parse_args()

    from hnsdt.compose import training
    from hnsdt.implementations import network_for
    from hnsdt.baselines.recurrent import episode_batch, training_episodes
    from hnsdt.stages.train_unseen import plan_unseen
    from hnsdt.compose.config import load_params
    from hnsdt.models import recurrent
    from hnsdt.models.fit import to_device

    if args.costs:
        recurrent.GROUP_COSTS.update(lstm=tuple(args.costs), gru=tuple(args.costs))

    torch.set_num_threads(1)
    params = load_params("params.yaml")
    print(f"{'env':<13} {'method':<10} {'padded/real':>11} {'padded ms':>10} {'grouped ms':>10} {'speed-up':>8} "
          f"{'loss diff':>9}")
    for env in args.envs:
        for method in args.methods:
            if env == "unseen":
                task = plan_unseen(params, method, Path("generalisation/dataset"))[0]
            else:
                task = training.plan_runs(params, env, method, [0], Path("data/datasets") / env)[0]
            starts, lengths = training_episodes(task.frames(), task.train_cfg.behaviours)
            order = np.random.default_rng(0).permutation(len(starts))
            size = task.train_cfg.batch_size
            rows = [order[b:b + size] for b in range(0, len(order), size)][:args.batches]
            batches = [to_device(episode_batch(task.frames(), starts[r], lengths[r]), torch.device("cpu")) for r in rows]
            padded_steps = sum(b["mask"].numel() for b in batches) / sum(int(b["mask"].sum()) for b in batches)
            torch.manual_seed(0)
            model = network_for(method, task.model_cfg)(task.model_cfg).train()
            with torch.no_grad():
                diff = max(abs(float(model.loss(b)) - float(padded_loss(model, b))) for b in batches)
            padded, grouped = fastest_ms(model, args.rounds, (batches, lambda b: padded_loss(model, b)),
                                         (batches, model.loss))
            print(f"{env:<13} {method:<10} {padded_steps:>11.2f} {padded:>10.1f} {grouped:>10.1f} "
                  f"{padded / grouped:>7.2f}x {diff:>9.1e}", flush=True)


if __name__ == "__main__":
    main()
