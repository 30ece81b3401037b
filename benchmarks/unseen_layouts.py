"""The symbolic baseline and the exact optimum on layouts nobody tuned for: generated families and MiniGrid's
DoorKey grids (our dynamics). A check of the generator, the MiniGrid adapter and the planner on many worlds,
and the reference line of the generalisation experiment (the planner reads the layout, so it cannot fail to
transfer; the learners are what the experiment is about).

Run: python benchmarks/unseen_layouts.py [--layouts 20] [--episodes 100] [--fail-probs 0 0.1 0.2 0.3]
Prints, per source x fail_prob: the symbolic baseline's success and its steps relative to the exact optimum
(mean over layouts), and the optimum's own success.
"""

import argparse
import time

import numpy as np

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.symbolic import SymbolicAgent
from hnsdt.agents.rollout import rollout
from hnsdt.envs.generate import check_usable, generate
from hnsdt.envs.minigrid_adapter import from_minigrid
from hnsdt.envs.vector import KeyDoorVectorEnv
from hnsdt.envs.oracle import optimum

SOURCES = {  # name -> (layout of seed s, max_steps)
    "generated keydoor": (lambda s: generate("keydoor", s), 100),
    "generated multikeydoor": (lambda s: generate("multikeydoor", s), 250),
    "MiniGrid-DoorKey-8x8": (lambda s: from_minigrid("MiniGrid-DoorKey-8x8-v0", s), 100),
    "MiniGrid-DoorKey-16x16": (lambda s: from_minigrid("MiniGrid-DoorKey-16x16-v0", s), 250),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--layouts", type=int, default=20, help="seeds 1000.. of each source (default 20)")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--fail-probs", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3])
    args = ap.parse_args()
    print("| source | layouts | distinct | fail_prob | symbolic success | optimal success | steps / optimal |")
    print("|---|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    for name, (make, max_steps) in SOURCES.items():
        layouts = [make(1000 + s) for s in range(args.layouts)]
        for layout in layouts:
            check_usable(layout, max_steps, max(args.fail_probs))
        for fp in args.fail_probs:
            success, ratio, opt_success = [], [], []
            for i, layout in enumerate(layouts):
                env = KeyDoorVectorEnv(args.episodes, layout, fp, max_steps)
                eps = rollout(env, SymbolicAgent(layout, ExecutorConfig(plan_mode="cost")), seed=i)
                best = optimum(layout, fp, max_steps)
                ok = [e.length for e in eps if e.success]
                success.append(len(ok) / len(eps))
                opt_success.append(best.success)
                if ok:
                    ratio.append(np.mean(ok) / best.steps)
            print(f"| {name} | {len(layouts)} | {len({l.text for l in layouts})} | {fp:g} | {np.mean(success):.3f} | "
                  f"{np.mean(opt_success):.3f} | {np.mean(ratio):.3f} |", flush=True)
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
