"""The references on MiniGrid's own worlds, per world and fail_prob: the exact optimum, MiniGrid's BabyAI bot and
the symbolic agent (our planner with hand-written controllers).

One row per (world, fail_prob, reference): ``optimum`` is exact (:class:`hnsdt.minigrid.WorldMDP`: success
probability, expected MiniGrid reward, expected steps of the successful episodes); ``babyai_bot`` and ``symbolic``
are means of ``episodes`` episodes in MiniGrid's own env, each with its own failure draws (``plans``: the
symbolic agent's planner calls per episode). The summary averages the worlds: success and reward over every world,
steps over the worlds with a success.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable

import numpy as np
from tqdm import tqdm

from hnsdt.core.methods import REFERENCE
from hnsdt.minigrid import WorldMDP, world_of
from hnsdt.minigrid.bot import bot_episode
from hnsdt.minigrid.controllers import symbolic_episode

OPTIMUM, BOT, SYMBOLIC = "optimum", "babyai_bot", REFERENCE  # (the registry's symbolic method, on MiniGrid)
POLICIES = {BOT: bot_episode, SYMBOLIC: symbolic_episode}  # the references played in MiniGrid's env
ROW_COLUMNS = ("env", "seed", "fail_prob", "method", "episodes", "success", "reward", "steps", "plans", "gave_up",
               "states")
SUMMARY_COLUMNS = ("env", "fail_prob", "method", "worlds", "success_mean", "reward_mean", "steps_mean",
                   "plans_mean", "gave_up")


def reference_rows(env_id: str, seeds: Iterable[int], fail_probs: Iterable[float], episodes: int,
                   progress: bool = True) -> list[dict]:
    """The references' rows for every world ``seeds`` generates and every fail_prob."""
    seeds, fail_probs = [int(s) for s in seeds], [float(p) for p in fail_probs]
    rows = []
    for seed in tqdm(seeds, desc=f"{env_id} references", unit="world", disable=not progress):
        world = world_of(env_id, seed)
        mdp = WorldMDP(world)
        for p in fail_probs:
            opt, _ = mdp.solve(p)
            rows.append(dict(env=env_id, seed=seed, fail_prob=p, method=OPTIMUM, episodes=0, success=opt.success,
                             reward=opt.ret, steps=opt.steps, plans=0.0, gave_up=0, states=len(mdp)))
            for method, play in POLICIES.items():
                eps = [play(env_id, seed, p, failure_seed=k) for k in range(episodes)]
                won = [e.steps for e in eps if e.success]
                rows.append(dict(env=env_id, seed=seed, fail_prob=p, method=method, episodes=len(eps),
                                 success=float(np.mean([e.success for e in eps])),
                                 reward=float(np.mean([e.reward for e in eps])),
                                 steps=float(np.mean(won)) if won else float("nan"),
                                 plans=float(np.mean([e.plans for e in eps])),
                                 gave_up=sum(bool(e.error) for e in eps), states=len(mdp)))
    return rows


def recordings(env_id: str, seed: int, fail_probs: Iterable[float], meta: dict | None = None) -> dict[str, bytes]:
    """One recorded episode (failure stream 0) of each played reference on world ``seed`` per fail_prob, as
    ``{file name: bytes}``: ``<method>_fp<p>.rrd`` and ``.mcap``."""
    from hnsdt.logs.minigrid_log import MiniGridRecord, recording_files
    from hnsdt.minigrid.bot import BotPolicy
    from hnsdt.minigrid.controllers import SymbolicAgent
    from hnsdt.minigrid.live import run_episode

    policies = {SYMBOLIC: lambda world, env: SymbolicAgent(world), BOT: BotPolicy}
    files = {}
    for p in fail_probs:
        for method, make in policies.items():
            trace: list = []
            ep = run_episode(env_id, seed, p, 0, make, trace)
            rec = MiniGridRecord(f"{method}/{env_id}@{seed}/fp{p:g}/ep0", trace, ep.success,
                                 dict(meta or {}, method=method, env=env_id, world_seed=int(seed), fail_prob=float(p)))
            for suffix, data in recording_files(rec).items():
                files[f"{method}_fp{p:g}{suffix}"] = data
    return files


def summarise(rows: list[dict]) -> list[dict]:
    """Per (env, fail_prob, method): the mean over its worlds."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["env"], r["fail_prob"], r["method"]), []).append(r)
    out = []
    for (env, p, method), rs in groups.items():
        steps = [r["steps"] for r in rs if r["success"] > 0]
        out.append(dict(env=env, fail_prob=p, method=method, worlds=len(rs),
                        success_mean=float(np.mean([r["success"] for r in rs])),
                        reward_mean=float(np.mean([r["reward"] for r in rs])),
                        steps_mean=float(np.mean(steps)) if steps else float("nan"),
                        plans_mean=float(np.mean([r["plans"] for r in rs])),
                        gave_up=sum(r["gave_up"] for r in rs)))
    return out


def to_csv(rows: list[dict], columns: tuple[str, ...]) -> str:
    """Rows as CSV text, floats to 6 decimals (the same bytes for the same numbers)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: (f"{v:.6f}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def read_csv(text: str) -> list[dict]:
    """:func:`to_csv`'s rows back, numbers as numbers."""
    rows = []
    for r in csv.DictReader(io.StringIO(text)):
        rows.append({k: (v if k in ("env", "method") else float(v) if "." in v or v == "nan" else int(v))
                     for k, v in r.items()})
    return rows
