"""Does HNSDT transfer to layouts it has not seen? A first measurement of the generalisation experiment.

Trains the view decision transformer (:mod:`hnsdt.models.view_dt`: local view around the agent, sub-goal
targets relative to the agent) as HNSDT's low-level policy on noisy-planner episodes of ``--train-layouts``
generated layouts of a family, and the same DT with no conditioning token as a pure DT (the paper's build of
it, on the same episodes), then runs both (HNSDT: planner + executor + its DT) on the training layouts, on
``--test-layouts`` held-out generated layouts and, for the ``keydoor`` family, on MiniGrid-DoorKey-8x8 grids
(our dynamics). The symbolic baseline runs on the same layouts as the reference. Not yet part of
`dvc repro` (the issue on unseen layouts).

Run: python benchmarks/generalisation.py [--family keydoor] [--train-layouts 20] [--test-layouts 20]
     [--epochs 2] [--seeds 0] [--view-radius 2] [--episodes 20] [--fail-probs 0.1 0.3]
Prints a table: split x fail_prob -> success and steps / exact optimum for HNSDT (view DT) and the symbolic
baseline, mean over layouts (and seeds).
"""

import argparse
import time
from functools import lru_cache

import numpy as np

from hnsdt.reproducible import pin_process

pin_process()

from hnsdt.agents.dt_agents import HNSDTAgent, PureDTAgent  # noqa: E402
from hnsdt.agents.executor import ExecutorConfig  # noqa: E402
from hnsdt.agents.rollout import rollout  # noqa: E402
from hnsdt.agents.symbolic import SymbolicAgent  # noqa: E402
from hnsdt.data.collect import Behaviour, CollectConfig, collect_episodes  # noqa: E402
from hnsdt.data.windows import frames_from_arrays  # noqa: E402
from hnsdt.envs.generate import generate  # noqa: E402
from hnsdt.envs.minigrid_adapter import from_minigrid  # noqa: E402
from hnsdt.envs.vector import KeyDoorVectorEnv  # noqa: E402
from hnsdt.models.train import TrainConfig, train_dt  # noqa: E402
from hnsdt.models.view_dt import ViewDecisionTransformer, view_config, view_states  # noqa: E402
from hnsdt.oracle import optimum  # noqa: E402

MAX_STEPS = {"keydoor": 100, "multikeydoor": 250}
SIZES = {"keydoor": dict(n_layers=3, n_heads=4, d_model=128, context=10),
         "multikeydoor": dict(n_layers=5, n_heads=4, d_model=128, context=20)}  # params.yaml's `models`


def training_frames(layouts, max_steps: int, episodes: int, radius: int):
    """Noisy-planner episodes on every layout (from its start and from random states), as frames whose
    states are view states."""
    parts = {k: [] for k in ("states", "actions", "rewards", "subgoals", "targets", "episode", "timestep")}
    policy, n_ep = [], 0
    for i, layout in enumerate(layouts):
        cfg = CollectConfig(env_id="generated", layout=layout, max_steps=max_steps, fail_probs=[0.0, 0.1, 0.2, 0.3],
                            behaviours=[Behaviour("noisy_planner", episodes, "layout", 0.1),
                                        Behaviour("noisy_planner", episodes, "random", 0.1)], seed=i,
                            executor=ExecutorConfig(plan_mode="cost"))
        for rec in collect_episodes(cfg, progress=False):
            t = len(rec["actions"])
            parts["states"].append(view_states(layout, rec["states"][:t], radius))
            parts["actions"].append(rec["actions"])
            parts["rewards"].append(rec["rewards"])
            parts["subgoals"].append(rec["subgoal_ids"])
            parts["targets"].append(rec["subgoal_targets"])
            parts["episode"].append(np.full(t, n_ep))
            parts["timestep"].append(np.arange(t))
            policy += ["noisy_planner"] * t
            n_ep += 1
    return frames_from_arrays(*(np.concatenate(parts[k]) for k in parts), policy=np.array(policy, dtype=object))


@lru_cache(maxsize=None)
def optimal_steps(layout, fail_prob: float, max_steps: int) -> float:
    """The exact optimum's expected steps (one value iteration per layout and fail_prob, shared by the methods)."""
    return optimum(layout, fail_prob, max_steps).steps


def run(layouts, max_steps, fail_prob, episodes, make_agent, seed):
    success, ratio = [], []
    for i, layout in enumerate(layouts):
        eps = rollout(KeyDoorVectorEnv(episodes, layout, fail_prob, max_steps), make_agent(layout), seed=seed + i)
        ok = [e.length for e in eps if e.success]
        success.append(len(ok) / len(eps))
        if ok:
            ratio.append(np.mean(ok) / optimal_steps(layout, fail_prob, max_steps))
    return float(np.mean(success)), float(np.mean(ratio)) if ratio else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", choices=list(MAX_STEPS), default="keydoor")
    ap.add_argument("--train-layouts", type=int, default=20)
    ap.add_argument("--test-layouts", type=int, default=20)
    ap.add_argument("--episodes-per-layout", type=int, default=16, help="per behaviour, per training layout")
    ap.add_argument("--epochs", type=int, default=2)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--view-radius", type=int, default=2)
    ap.add_argument("--episodes", type=int, default=20, help="evaluation episodes per layout and fail_prob")
    ap.add_argument("--fail-probs", type=float, nargs="+", default=[0.1, 0.3])
    args = ap.parse_args()
    max_steps = MAX_STEPS[args.family]
    splits = {"train": [generate(args.family, s) for s in range(args.train_layouts)],
              "heldout": [generate(args.family, 100_000 + s) for s in range(args.test_layouts)]}
    if args.family == "keydoor":
        splits["minigrid"] = [from_minigrid("MiniGrid-DoorKey-8x8-v0", s) for s in range(args.test_layouts)]
    t0 = time.perf_counter()
    frames = training_frames(splits["train"], max_steps, args.episodes_per_layout, args.view_radius)
    print(f"training frames: {len(frames):,} from {args.train_layouts} layouts ({time.perf_counter() - t0:.0f} s)")
    n_flags = splits["train"][0].n_flags
    max_offset = max(max(lay.shape) for layouts in splits.values() for lay in layouts) - 1
    executor = ExecutorConfig(plan_mode="cost")
    rows = {}
    for seed in args.seeds:
        models = {}
        for condition in ("subgoal", "none"):
            t1 = time.perf_counter()
            cfg = view_config(condition, n_flags, args.view_radius, max_offset, max_timestep=max_steps, dropout=0.1,
                              **SIZES[args.family])
            models[condition], curve = train_dt(frames, cfg, TrainConfig(
                epochs=args.epochs, batch_size=128, lr=1e-3, seed=seed, behaviours=("noisy_planner",)),
                progress=False, network=ViewDecisionTransformer)
            print(f"seed {seed}, {condition}: {curve[-1]['step']} gradient steps, final loss {curve[-1]['loss']:.3f} "
                  f"({time.perf_counter() - t1:.0f} s)", flush=True)
        for split, layouts in splits.items():
            for fp in args.fail_probs:
                for name, make in (("HNSDT (view DT)", lambda lay: HNSDTAgent(lay, models["subgoal"], executor)),
                                   ("pure DT (view, no token)", lambda lay: PureDTAgent(models["none"], None, lay)),
                                   ("symbolic", lambda lay: SymbolicAgent(lay, executor))):
                    rows.setdefault((split, fp, name), []).append(
                        run(layouts, max_steps, fp, args.episodes, make, seed=1000 * seed))
    print(f"\n{args.family}: {args.train_layouts} training layouts, {args.test_layouts} per test split, "
          f"{args.episodes} episodes per layout, seeds {args.seeds}, {args.epochs} epochs\n")
    print("| split | fail_prob | method | success | steps / optimal |")
    print("|---|---|---|---|---|")
    for (split, fp, name), vals in rows.items():
        s, r = np.mean([v[0] for v in vals]), np.nanmean([v[1] for v in vals])
        print(f"| {split} | {fp:g} | {name} | {s:.3f} | {r:.3f} |")
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
