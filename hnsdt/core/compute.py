"""Where the runs of a stage execute: worker processes on this machine, or a Ray cluster.

A stage hands over independent tasks (one training seed; one method × env × seed of the evaluation): a
module-level function and one frozen task object each, data included; the function returns a picklable result
and touches no file. The caller writes every output. Each task sets its own torch thread count (``compute.threads``) and
results come back in task order, so the outputs are the same bytes whichever executor runs the tasks and
however many workers share them (tested). A task may also return :class:`Continue` — the rest of its work
as a new task — which goes to the back of the queue: a training seed hands back its state part-way
(:func:`hnsdt.compose.training.pause_at`), so that 5 seeds on 2 workers take about 2.5 seed-times instead of 3.

* ``local`` (default): a pool of ``workers`` spawned processes (0 = one per core / threads); one worker runs
  the tasks in this process, each task and result through the same plain pickles as a pool's (so a task that
  would not cross to a worker fails here too).
* ``ray``: one Ray task per run, ``num_cpus = threads``. Connects to ``RAY_ADDRESS`` when it is set (a
  cluster whose nodes have this package installed at the same revision), otherwise starts a local Ray
  instance. The pinned CPU settings travel in the tasks' runtime environment.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import dataclass
from typing import Any, Callable

EXECUTORS = ("local", "ray")


@dataclass(frozen=True)
class Compute:
    executor: str = "local"  # local | ray
    workers: int = 0  # local: tasks at once (0 = one per available core / threads)
    threads: int = 1  # torch CPU threads per task; part of the bytes

    def __post_init__(self):
        if self.executor not in EXECUTORS:
            raise ValueError(f"compute.executor must be one of {EXECUTORS}, got {self.executor!r}")
        if self.workers < 0 or self.threads < 1:
            raise ValueError(f"compute: workers must be >= 0 and threads >= 1, got {self.workers}, {self.threads}")

    def local_workers(self, n_tasks: int) -> int:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        return max(1, min(n_tasks, self.workers or cores // self.threads))


@dataclass(frozen=True)
class Continue:
    """What a task returns when it has more to do: ``fn(task)`` is queued behind the waiting tasks, and its
    result (or further :class:`Continue`) stands for the first task's."""

    task: Any


def _call(fn: Callable, threads: int, task: Any) -> Any:
    import torch

    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)
    return fn(task)


def _dumps(obj: Any) -> bytes:
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def _call_pickled(fn: Callable, threads: int, task: bytes) -> bytes:
    # A task and its result cross to and from a worker process as one plain pickle each: the pool's own
    # pickler (torch's) would move every tensor of a model or a state through shared memory, a file descriptor
    # and a socket handshake apiece, about ten times the time of one pickle as bytes.
    return _dumps(_call(fn, threads, pickle.loads(task)))


def run_tasks(fn: Callable, tasks: list, compute: Compute = Compute(), desc: str = "runs",
              progress: bool = True) -> list:
    """``[fn(task) for task in tasks]``, computed by ``compute``'s executor; results in task order."""
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), desc=desc, unit="run", disable=not progress)
    try:
        if compute.executor == "ray":
            return _run_ray(fn, tasks, compute, bar)
        workers = compute.local_workers(len(tasks))
        if workers == 1:  # here, through the pickles a pool's tasks cross: what runs here would run there
            def call(task):
                return pickle.loads(_call_pickled(fn, compute.threads, _dumps(task)))

            out = []
            for task in tasks:
                result = call(task)
                while isinstance(result, Continue):
                    result = call(result.task)
                out.append(result)
                bar.update(1)
            return out
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        # spawn, not fork: a forked child would inherit torch's thread pools from this process.
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            def submit(task):
                return pool.submit(_call_pickled, fn, compute.threads, _dumps(task))

            running = {submit(task): i for i, task in enumerate(tasks)}
            out = [None] * len(tasks)
            while running:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in sorted(done, key=running.get):
                    i = running.pop(future)
                    result = pickle.loads(future.result())
                    if isinstance(result, Continue):
                        running[submit(result.task)] = i
                    else:
                        out[i] = result
                        bar.update(1)
            return out
    finally:
        bar.close()


def _run_ray(fn: Callable, tasks: list, compute: Compute, bar) -> list:
    try:
        import ray
    except ImportError:
        raise RuntimeError("compute.executor is ray but Ray is not installed: pip install -e '.[ray]'") from None
    from hnsdt.core.reproducible import pinned_environment

    if not ray.is_initialized():  # the workers of a cluster started by hand inherit none of the driver's pinned
        env = pinned_environment()  # variables: each task's runtime environment carries every one of them
        ray.init(address=os.environ.get("RAY_ADDRESS"), runtime_env={"env_vars": env},
                 include_dashboard=False, log_to_driver=False, configure_logging=False)
    remote = ray.remote(num_cpus=compute.threads)(_call)
    running = {remote.remote(fn, compute.threads, task): i for i, task in enumerate(tasks)}
    out = [None] * len(tasks)
    while running:
        done, _ = ray.wait(list(running), num_returns=1)
        i = running.pop(done[0])
        result = ray.get(done[0])
        if isinstance(result, Continue):
            running[remote.remote(fn, compute.threads, result.task)] = i
        else:
            out[i] = result
            bar.update(1)
    return out
