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
                rows.append(_row(env_id, seed, p, method, eps, len(mdp)))
    return rows


class StepsOnWorlds:
    """A validation measure for a MiniGrid learner (any model :func:`hnsdt.agents.minigrid_play.play` acts with;
    lower is better): the mean steps of its episodes on ``jobs`` (validation worlds × fail_probs), an episode not
    done within ``max_steps`` counting as ``max_steps`` — which is then the ``ceiling``, the value of a model that
    never reaches its goal (:class:`hnsdt.models.fit.Validation`). Plays greedily from fixed worlds and failure streams: it draws no
    random numbers of the training's."""

    name = "steps"

    def __init__(self, env_id: str, jobs: list, max_steps: int, target_return: float = 1.0):
        self.env_id, self.jobs, self.max_steps, self.target_return = env_id, jobs, max_steps, target_return
        self.ceiling = float(max_steps)

    def __call__(self, model) -> float:
        from hnsdt.agents.minigrid_play import play

        episodes = play(model, self.env_id, self.jobs, self.target_return, self.max_steps)
        return float(np.mean([e.steps if e.success else self.max_steps for e in episodes]))


def played_rows(env_id: str, method: str, train_seed: int, jobs: list, episodes: list) -> list[dict]:
    """A learner's rows, one per (world, fail_prob) as the references' (means of its episodes there), with the
    training seed that made it."""
    groups: dict[tuple, list] = {}
    for job, ep in zip(jobs, episodes):
        groups.setdefault((job.seed, job.fail_prob), []).append(ep)
    return [_row(env_id, seed, p, method, eps, 0) | {"train_seed": int(train_seed)}
            for (seed, p), eps in groups.items()]


def _row(env_id: str, seed: int, p: float, method: str, eps: list, states: int) -> dict:
    """The row of ``eps``, the episodes of ``method`` on one world and fail_prob."""
    won = [e.steps for e in eps if e.success]
    return dict(env=env_id, seed=int(seed), fail_prob=float(p), method=method, episodes=len(eps),
                success=float(np.mean([e.success for e in eps])), reward=float(np.mean([e.reward for e in eps])),
                steps=float(np.mean(won)) if won else float("nan"), plans=float(np.mean([e.plans for e in eps])),
                gave_up=sum(bool(e.error) for e in eps), states=states)


def recordings(env_id: str, seed: int, fail_probs: Iterable[float], meta: dict | None = None) -> dict[str, bytes]:
    """One recorded episode (failure stream 0) of each played reference on world ``seed`` per fail_prob, as
    ``{file name: bytes}``: ``<method>_fp<p>.rrd`` and ``.mcap``."""
    from hnsdt.minigrid.bot import BotPolicy
    from hnsdt.minigrid.controllers import SymbolicAgent
    from hnsdt.minigrid.live import run_episode

    policies = {SYMBOLIC: lambda world, env: SymbolicAgent(world), BOT: BotPolicy}
    files = {}
    for p in fail_probs:
        for method, make in policies.items():
            trace: list = []
            ep = run_episode(env_id, seed, p, 0, make, trace)
            files |= _recorded(method, env_id, seed, p, trace, ep.success, meta)
    return files


def learned_recordings(env_id: str, models: dict, seed: int, fail_probs: Iterable[float], target_return: float,
                       meta: dict | None = None) -> dict[str, bytes]:
    """One recorded episode (failure stream 0) of each learner in ``models`` (method -> model) on world ``seed`` per
    fail_prob: ``<method>_fp<p>.rrd`` and ``.mcap``, as :func:`recordings`."""
    from hnsdt.agents.minigrid_play import Job, play

    files = {}
    for p in fail_probs:
        for method, model in models.items():
            trace: list = []
            ep, = play(model, env_id, [Job(seed, p, 0)], target_return, traces={0: trace})
            files |= _recorded(method, env_id, seed, p, trace, ep.success, meta)
    return files


def _recorded(method: str, env_id: str, seed: int, p: float, trace: list, success: bool, meta: dict | None
              ) -> dict[str, bytes]:
    """The ``.rrd`` and ``.mcap`` of one traced episode, by file name."""
    from hnsdt.logs.minigrid_log import MiniGridRecord, recording_files

    rec = MiniGridRecord(f"{method}/{env_id}@{seed}/fp{p:g}/ep0", trace, success,
                         dict(meta or {}, method=method, env=env_id, world_seed=int(seed), fail_prob=float(p)))
    return {f"{method}_fp{p:g}{suffix}": data for suffix, data in recording_files(rec).items()}


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


LEARNED_COLUMNS = ("env", "fail_prob", "method", "seeds", "worlds", "success_mean", "success_std", "reward_mean",
                   "reward_std", "steps_mean", "steps_std", "gave_up")


def summarise_seeds(rows: list[dict]) -> list[dict]:
    """Per (env, fail_prob, method) of a learner's rows: the mean over its training seeds of each seed's mean over
    the worlds (:func:`summarise`), and the std over the seeds."""
    per_seed: dict[tuple, list[dict]] = {}
    for seed in sorted({r["train_seed"] for r in rows}):
        for s in summarise([r for r in rows if r["train_seed"] == seed]):
            per_seed.setdefault((s["env"], s["fail_prob"], s["method"]), []).append(s)
    out = []
    for (env, p, method), ss in per_seed.items():
        stats = {}
        for key in ("success", "reward", "steps"):
            values = np.array([s[f"{key}_mean"] for s in ss], dtype=float)
            values = values[~np.isnan(values)]
            stats[f"{key}_mean"] = float(values.mean()) if len(values) else float("nan")
            stats[f"{key}_std"] = float(values.std()) if len(values) else float("nan")
        out.append(dict(env=env, fail_prob=p, method=method, seeds=len(ss), worlds=ss[0]["worlds"], **stats,
                        gave_up=sum(s["gave_up"] for s in ss)))
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
