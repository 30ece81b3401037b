"""How many training worlds MiniGrid's HNSDT needs, chosen on the validation worlds (never the test worlds).

Usage: python benchmarks/minigrid_data_size.py [--world doorkey8] [--sizes 25 50 100 200] [--seeds 0 1]
Trains HNSDT as `minigrid_learn` does (the knobs of params.yaml's `minigrid.learn`, to the plateau of its steps on
the validation worlds) on the episodes of the first N training worlds of `minigrid/<world>/dataset` (the stage's
dataset; sizes beyond it are collected here with the stage's collection settings on the next training seeds, into
a temporary folder), and prints per size and seed: the frames, the epochs, and the validation measure (mean steps,
a failure counting as the limit) with the validation success rate. Run `dvc repro minigrid_collect@<world>` first.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd


def subset(frames, keep: np.ndarray):
    """The frames ``keep`` marks (whole episodes), as a Frames of their own."""
    from hnsdt.models.windows import frames_from_arrays

    part = frames_from_arrays(frames.states[keep], frames.actions[keep], frames.rewards[keep], frames.subgoals[keep],
                              frames.targets[keep][:, :2], frames.episode[keep], frames.timestep[keep])
    return dataclasses.replace(part, targets=frames.targets[keep])


def first_worlds(frames, table: pd.DataFrame, worlds: int) -> np.ndarray:
    """Per frame: is its episode on one of the first ``worlds`` training worlds of the dataset?"""
    chosen = sorted(table.world_seed.unique())[:worlds]
    return np.isin(frames.episode, table.episode_index[table.world_seed.isin(chosen)].to_numpy())


def main() -> None:
    import torch

    from hnsdt.agents.minigrid_play import Job, play
    from hnsdt.compose.config import load_params
    from hnsdt.core.methods import PROPOSED, method
    from hnsdt.data.format import EPISODES_TABLE
    from hnsdt.data.minigrid_dataset import load_minigrid_frames, write_minigrid_dataset
    from hnsdt.minigrid.collect import collect_episodes
    from hnsdt.models.minigrid_nets import MiniGridDT, MiniGridDTConfig
    from hnsdt.models.train import TrainConfig, train_decision_transformer
    from hnsdt.evaluation.minigrid import StepsOnWorlds

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="doorkey8")
    parser.add_argument("--sizes", type=int, nargs="+", default=[25, 50, 100, 200])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    args = parser.parse_args()
    torch.set_num_threads(1)
    params = load_params("params.yaml")
    section, learn = params.minigrid, params.minigrid.learn
    env_id = section.envs[args.world].id
    root = Path("minigrid") / args.world / "dataset"
    frames, table = load_minigrid_frames(root), pd.read_parquet(root / EPISODES_TABLE)
    have = table.world_seed.nunique()
    extra = None
    if max(args.sizes) > have:  # the next training seeds, collected as the stage collects
        c = section.collect
        first = c.train_seeds.first + c.train_seeds.count
        seeds = list(range(first, first + max(args.sizes) - have))
        episodes = collect_episodes(env_id, seeds, section.fail_probs, c.episodes_per_world, c.epsilon,
                                    params.collect.seed, progress=True)
        with tempfile.TemporaryDirectory() as tmp:
            more = write_minigrid_dataset(Path(tmp) / "more", "local/more", episodes, params.collect.fps,
                                          dict(env_id=env_id, world_seeds=seeds, fail_probs=section.fail_probs,
                                               epsilon=c.epsilon, seed=params.collect.seed, license="apache-2.0"))
            extra = (load_minigrid_frames(more), pd.read_parquet(more / EPISODES_TABLE))
    measure = StepsOnWorlds(env_id, [Job(s, p, 0) for s in learn.validation_seeds.seeds for p in section.fail_probs],
                            learn.validation_max_steps)
    cfg = MiniGridDTConfig(condition=method(PROPOSED).condition, **learn.model.model_dump())
    print(f"{env_id}: HNSDT, validation worlds {learn.validation_seeds.first}–{learn.validation_seeds.seeds[-1]}")
    print("worlds  seed  frames  epochs  best_epoch  validation_steps  validation_success")
    for size in args.sizes:
        part = subset(frames, first_worlds(frames, table, min(size, have)))
        if size > have:  # and the collected ones after them, numbered on
            more_frames, more_table = extra
            add = subset(more_frames, first_worlds(more_frames, more_table, size - have))
            both = {f.name: np.concatenate([getattr(part, f.name), getattr(add, f.name)])
                    for f in dataclasses.fields(part)}
            both["episode"][len(part):] += part.episode.max() + 1
            part = subset(dataclasses.replace(part, **both), np.ones(len(both["episode"]), bool))  # (starts anew)
        for seed in args.seeds:
            train = TrainConfig(epochs=learn.max_epochs, batch_size=learn.batch_size, lr=learn.lr, seed=seed,
                                device="cpu", patience=learn.patience)
            model, _, usage = train_decision_transformer(part, cfg, train, progress=False, network=MiniGridDT,
                                                         measure=measure)
            eps = play(model, env_id, measure.jobs, max_steps=learn.validation_max_steps)
            print(f"{size:6d}  {seed:4d}  {usage['dataset_frames']:6d}  {usage['epochs']:6.0f}  "
                  f"{usage['best_epoch']:10d}  {min(v['value'] for v in usage['validation_steps']):16.2f}  "
                  f"{np.mean([e.success for e in eps]):18.3f}", flush=True)


if __name__ == "__main__":
    main()
