"""Environment steps per second: our single env, our numpy-batched env, and MiniGrid-DoorKey-5x5-v0.

Run: make bench   (or: python benchmarks/env_throughput.py [--seconds 2])
Random actions, fail_prob 0.1; finished copies of the batched env are reset in place.
"""

import argparse
import time

import gymnasium as gym
import minigrid  # noqa: F401  (registers MiniGrid ids)
import numpy as np

from hnsdt.envs import KeyDoorEnv, KeyDoorVectorEnv


def single(env, seconds):
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for a in rng.integers(0, env.action_space.n, 1000):
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
        n += 1000
    return n / (time.perf_counter() - t0)


def batched(num_envs, layout, seconds):
    venv = KeyDoorVectorEnv(num_envs, layout, 0.1, 100)
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        venv.step(rng.integers(0, 5, num_envs))
        if venv.done.any():
            venv.reset(options={"reset_mask": venv.done})
        n += num_envs
    return n / (time.perf_counter() - t0)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    rows = [
        ("MiniGrid-DoorKey-5x5-v0 (single)", single(gym.make("MiniGrid-DoorKey-5x5-v0").unwrapped, args.seconds)),
        ("hnsdt/KeyDoor-v0 (single)", single(KeyDoorEnv(fail_prob=0.1), args.seconds)),
        ("hnsdt/MultiKeyDoor-v0 (single)", single(KeyDoorEnv("multikeydoor_9x9", 0.1, 250), args.seconds)),
    ]
    for n in (64, 1024, 8192):
        rows.append((f"hnsdt/KeyDoor-v0 batched x{n}", batched(n, "keydoor_5x5", args.seconds)))
        rows.append((f"hnsdt/MultiKeyDoor-v0 batched x{n}", batched(n, "multikeydoor_9x9", args.seconds)))
    print(f"{'environment':<40} {'steps/s':>12}")
    for name, sps in rows:
        print(f"{name:<40} {sps:>12,.0f}")


if __name__ == "__main__":
    main()
