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

A stage that passes ``keep`` (:func:`hnsdt.core.fileio.finished_tasks`: a hidden folder beside its output) has
each finished task's result kept there until its output is written: killed and started again, it computes only
the tasks that had not finished (training seeds, evaluation cells), with the same bytes.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import dataclass
from pathlib import Path
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
              progress: bool = True, keep: Path | None = None, cost: Callable[[Any], float] | None = None) -> list:
    """``[fn(task) for task in tasks]``, computed by ``compute``'s executor; results in task order. ``keep``: a
    folder where each task's result is kept as soon as it is finished (:class:`Kept`), so that a run killed
    part-way and started again computes only the tasks that had not finished; the caller removes it once the
    results are written. ``cost``: a task's expected time (any unit); the tasks start longest first, so that
    workers do not sit idle at the end behind one long task (only the order they start in: not the results)."""
    from tqdm import tqdm

    kept = Kept(keep, fn) if keep is not None else None
    paths = [kept.path(task) for task in tasks] if kept else [None] * len(tasks)  # (each task pickled once here)
    out = [kept.result(path) if kept else _MISSING for path in paths]
    todo = [i for i, result in enumerate(out) if result is _MISSING]
    if cost is not None:
        todo.sort(key=lambda i: -cost(tasks[i]))  # (stable: equal costs keep task order)
    if len(todo) < len(tasks):
        print(f"{desc}: {len(tasks) - len(todo)} of {len(tasks)} runs finished before this one was stopped; "
              f"taken from {keep}", flush=True)
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc=desc, unit="run", disable=not progress)

    def finished(i: int, result: Any) -> None:
        if kept:
            kept.add(paths[todo[i]], result)
        out[todo[i]] = result
        bar.update(1)

    try:
        if todo:
            (_run_ray if compute.executor == "ray" else _run_local)(fn, [tasks[i] for i in todo], compute, finished)
        return out
    finally:
        bar.close()


_MISSING = object()  # no kept result (a kept result may itself be None)


class Kept:
    """Finished tasks' results in a folder, one pickle each, named by a digest of the function, the task's pickle
    and the code and library versions that computed it (:func:`code_digest`): a result is only ever taken
    for the same task of the same code."""

    def __init__(self, folder: Path, fn: Callable):
        self.folder, self.fn = Path(folder), f"{fn.__module__}.{fn.__qualname__}"

    def path(self, task: Any) -> Path:
        """Where ``task``'s result is kept."""
        import hashlib

        digest = hashlib.sha256(f"{code_digest()}\0{self.fn}\0".encode() + _dumps(task)).hexdigest()[:32]
        return self.folder / f"{digest}.pkl"

    @staticmethod
    def result(path: Path) -> Any:
        """The result kept at ``path``, or ``_MISSING`` when there is none (or a damaged one: computed again)."""
        try:
            return pickle.loads(path.read_bytes())
        except Exception:  # noqa: BLE001  (none there, or damaged)
            return _MISSING

    @staticmethod
    def add(path: Path, result: Any) -> None:
        """Keep ``result`` at ``path``; where it cannot be kept (a full disk) the run goes on without it."""
        from hnsdt.core.fileio import atomic_file

        try:
            with atomic_file(path) as tmp:
                tmp.write_bytes(_dumps(result))
        except OSError:
            pass


_CODE_DIGEST: list[str] = []


def code_digest() -> str:
    """sha256 over this package's source files (path and bytes), the versions of the libraries that compute
    results, and the pinned environment: what a kept result must have been computed with."""
    if not _CODE_DIGEST:
        import hashlib
        from importlib.metadata import version

        from hnsdt.core.reproducible import pinned_environment

        package = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for f in sorted(package.rglob("*.py")):
            h.update(f.relative_to(package).as_posix().encode() + b"\0" + f.read_bytes())
        for lib in ("torch", "numpy", "lerobot", "gymnasium", "minigrid"):
            h.update(f"{lib}=={version(lib)}".encode())
        h.update(repr(sorted(pinned_environment().items())).encode())
        _CODE_DIGEST.append(h.hexdigest())
    return _CODE_DIGEST[0]


def _run_local(fn: Callable, tasks: list, compute: Compute, finished: Callable[[int, Any], None]) -> None:
    workers = compute.local_workers(len(tasks))
    if workers == 1:  # here, through the pickles a pool's tasks cross: what runs here would run there
        def call(task):
            return pickle.loads(_call_pickled(fn, compute.threads, _dumps(task)))

        for i, task in enumerate(tasks):
            result = call(task)
            while isinstance(result, Continue):
                result = call(result.task)
            finished(i, result)
        return
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    # spawn, not fork: a forked child would inherit torch's thread pools from this process.
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        def submit(task):
            return pool.submit(_call_pickled, fn, compute.threads, _dumps(task))

        running = {submit(task): i for i, task in enumerate(tasks)}
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in sorted(done, key=running.get):
                i = running.pop(future)
                result = pickle.loads(future.result())
                if isinstance(result, Continue):
                    running[submit(result.task)] = i
                else:
                    finished(i, result)


def _run_ray(fn: Callable, tasks: list, compute: Compute, finished: Callable[[int, Any], None]) -> None:
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
    while running:
        done, _ = ray.wait(list(running), num_returns=1)
        i = running.pop(done[0])
        result = ray.get(done[0])
        if isinstance(result, Continue):
            running[remote.remote(fn, compute.threads, result.task)] = i
        else:
            finished(i, result)
