"""What both experiments' evaluations run on: a trained model loaded as its method's agent, and :class:`EvalTask`
(one method and training seed, every :class:`Batch` it rolls out), which :func:`evaluate_run` runs touching no
file, so any executor (:mod:`hnsdt.core.compute`) can run it. Both experiments evaluate through
:func:`evaluate` (an :class:`Evaluation`: tasks, and how their rows become tables), make an episode again
through :func:`rerun`, and name an episode by :func:`episode_id`; the paper protocol (:mod:`.paper`) and the
unseen layouts (:mod:`.layouts`) differ only in the batches they plan and the rows they write.

Metrics follow the paper: success rate, mean steps of the successful episodes, mean reward (episode return);
each is computed per seed and then reported as mean ± std over seeds."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.rollout import Agent, Episode, rollout
from hnsdt.core.methods import method as lookup_method
from hnsdt.implementations import code_of, resolve
from hnsdt.envs.layout import Layout
from hnsdt.envs.vector import KeyDoorVectorEnv, Streams


def episode_id(method: str, layout: str, fail_prob: float, seed: int, episode: int) -> str:
    """An evaluated episode's id, in both experiments: ``METHOD/LAYOUT/fpP/seedK/epI`` (LAYOUT: a paper map's
    env name, or an unseen layout's name, e.g. a drawn map's file name)."""
    return f"{method}/{layout}/fp{fail_prob:g}/seed{seed}/ep{episode}"


def checkpoint_dir(models_root: str | Path, env: str, method: str, seed: int) -> Path:
    return Path(models_root) / env / method / f"seed{seed}"


def load_model(path: str | Path, method: str, device: str = "cpu", view: bool = False):
    """``(model, checkpoint meta)`` of a learned method's checkpoint folder ``path``; ``(None, {})`` for a method
    that does not learn. ``view``: the checkpoint must hold the method's view network (unseen layouts)."""
    entry = lookup_method(method)
    if entry.training == "none":
        return None, {}
    from hnsdt.models.checkpoint import load_checkpoint

    model, meta = load_checkpoint(path, device)
    if meta.get("method", method) != method:
        raise ValueError(f"{path} holds a {meta['method']} model")
    if view and meta.get("arch") != resolve(code_of(method).view_network).arch:
        raise ValueError(f"{path} is not a view model (train it with `python pipeline/generalisation.py train "
                         f"--method {method}`)")
    return model, meta


def build_agent(method: str, layout: Layout, executor: ExecutorConfig, model=None, meta: dict | None = None,
                epsilon: float = 0.0, agent_seed: int = 0) -> Agent:
    """The batched agent of ``method`` around its trained ``model``. ``epsilon`` and ``agent_seed`` only
    matter to the online baselines (ε-greedy noise, sampled options)."""
    return resolve(code_of(method).agent)(model, meta or {}, layout, executor, epsilon, agent_seed)


def training_usage(models_root: str | Path, env: str, method: str, seed: int) -> dict:
    """What a learned model was trained on, from its checkpoint: env steps (online) or dataset frames."""
    import json

    meta = json.loads((checkpoint_dir(models_root, env, method, seed) / "config.json").read_text())
    usage = meta.get("usage", {})
    return {"method": method, "env": env, "seed": seed, "training": lookup_method(method).training,
            "env_steps": usage.get("env_steps"), "dataset_frames": usage.get("dataset_frames"),
            "epochs": usage.get("epochs"), "gradient_steps": usage.get("gradient_steps"),
            "epoch_kept": usage.get("best_epoch"),  # trained to a validation plateau: the epoch whose weights it
            "env_steps_kept": usage.get("best_step"),  # kept (offline), or the env step (online)
            "training_exits": usage.get("exits")}  # online: training episodes that ended at the exit


@dataclass(frozen=True)
class Batch:
    """One rollout of a method: ``copies`` copies of one layout (or of several, one per equal run of copies), with
    one failure probability for all or one per copy, from one environment seed — or one per equal run of copies
    (a tuple: the paper protocol's cells or a split's maps, each drawing what it would alone,
    :class:`hnsdt.envs.vector.Streams`); the agent draws from each ``seed + 1``.
    ``key`` is what the experiment's rows need to know about the batch (the paper protocol: its cells, :class:`Cell`;
    unseen layouts: the sources of its maps and the episodes per fail_prob)."""

    layout: Layout | tuple[Layout, ...]  # one, or one per equal run of copies (unseen layouts: a split's maps)
    max_steps: int
    copies: int
    fail_prob: float | tuple[float, ...]
    seed: int | tuple[int, ...]
    key: Any


@dataclass(frozen=True)
class EvalTask:
    """One method and training seed of an evaluation: its trained model and every batch it runs. ``rows`` (a
    module-level function, so any executor can ship it) turns a batch's episodes into the experiment's rows:
    ``rows(task, batch, episodes)``. Both experiments run through :func:`evaluate_run`; they differ in the
    batches they plan and the rows they write."""

    method: str
    seed: int
    executor: ExecutorConfig  # its arm's planner
    model: Any  # None for the symbolic method
    meta: dict  # the checkpoint's facts
    epsilon: float  # online methods' exploration
    batches: tuple[Batch, ...]
    rows: Callable[..., Any]
    log_episodes: int = 0  # the paper protocol: the first this many episodes of each cell come back recorded
    provenance: dict | None = None  # ... with these facts in each recording (revision, params digest)


def run_batch(task: EvalTask, batch: Batch) -> list[Episode]:
    agent_seed = batch.seed + 1 if np.ndim(batch.seed) == 0 else Streams([s + 1 for s in batch.seed], batch.copies)
    agent = build_agent(task.method, batch.layout, task.executor, task.model, task.meta, task.epsilon, agent_seed)
    fail_prob = np.asarray(batch.fail_prob, dtype=np.float64) if isinstance(batch.fail_prob, tuple) else batch.fail_prob
    return rollout(KeyDoorVectorEnv(batch.copies, batch.layout, fail_prob, batch.max_steps), agent, seed=batch.seed)


def evaluate_run(task: EvalTask) -> list:
    """Every batch of the task, in order: ``task.rows`` of each."""
    return [task.rows(task, batch, run_batch(task, batch)) for batch in task.batches]


@dataclass(frozen=True)
class Evaluation:
    """One experiment's evaluation: its tasks, and how their results become its tables (``write(folder,
    results)``: ``results`` holds each task's rows of each batch; returns the episode table)."""

    tasks: list[EvalTask]
    write: Callable[[Path, list], Any]
    desc: str = "evaluate"


def evaluate(evaluation: Evaluation, out: str | Path, compute=None, progress: bool = True):
    """Every task of ``evaluation`` on ``compute``'s executor, its tables written into ``out``, which is whole or
    absent (built in a temporary folder and moved into place); the episode table. Cells finished by a run that
    was killed are taken from what it kept (:func:`hnsdt.core.fileio.finished_tasks`)."""
    from hnsdt.core.compute import Compute, run_tasks
    from hnsdt.core.fileio import atomic_dir, finished_tasks

    with finished_tasks(out) as keep:  # (cells finished before a kill are not run again)
        results = run_tasks(evaluate_run, evaluation.tasks, compute or Compute(), desc=evaluation.desc,
                            progress=progress, keep=keep)
        with atomic_dir(Path(out)) as tmp:
            tmp.mkdir()
            return evaluation.write(tmp, results)


def rerun(task: EvalTask, threads: int) -> tuple[dict, dict]:
    """An evaluated episode made again: its task (its batch alone, ``rows`` picking the episode) in this process,
    through the pickles and thread count a worker's runs have: the ``(outcome, files)`` of that episode."""
    from hnsdt.core.compute import Compute, run_tasks

    ((outcome, files),), = run_tasks(evaluate_run, [task], Compute(workers=1, threads=threads), progress=False)
    return outcome, files
