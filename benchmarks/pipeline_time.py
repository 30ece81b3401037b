"""How long the whole default pipeline takes, stage by stage: `dvc repro` in a fresh temporary copy of this repo
(no datasets, models or lock file; this venv), timing each stage from DVC's own "Running stage" lines.

Usage: python benchmarks/pipeline_time.py [--tiny] [--keep] [--cache DIR] [--imports]
--tiny uses the end-to-end test's tiny params instead of params.yaml; --imports also prints how long each stage's
processes spent importing (Python's -X importtime, which itself slows the imports a little); --cache points the
copy's DVC cache at DIR (e.g. this repo's .dvc/cache, so a later `dvc repro` here restores the timed run's outputs
from DVC's run cache instead of computing them again). Prints the total and a table of stages,
grouped by kind (collect, train, train_offline, train_online, evaluate, report), slowest first, and how many of
the machine's cores each stage kept busy (from /proc/stat, so only meaningful with nothing else running): a stage
that leaves a core idle is where parallelism, not faster code, would save time.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from tiny_repo import BIN, make_tiny_repo  # noqa: E402


def cpu_times() -> tuple[int, int] | None:
    """(busy, all) clock ticks of every core since boot, from /proc/stat (None where there is none). Busy is
    user, nice, system, irq and softirq; all adds idle, iowait and the time the hypervisor stole."""
    try:
        with open("/proc/stat") as f:
            ticks = [int(v) for v in f.readline().split()[1:9]]
    except OSError:
        return None
    busy = ticks[0] + ticks[1] + ticks[2] + ticks[5] + ticks[6]
    return busy, sum(ticks)


def busy_cores(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float:
    """How many cores were busy on average between two :func:`cpu_times` readings (nan without them)."""
    if before is None or after is None or after[1] == before[1]:
        return float("nan")
    return (after[0] - before[0]) / (after[1] - before[1]) * (os.cpu_count() or 1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="the end-to-end test's tiny params")
    parser.add_argument("--keep", action="store_true", help="keep the temporary copy")
    parser.add_argument("--cache", type=Path, help="DVC cache folder for the copy (default: its own)")
    parser.add_argument("--imports", action="store_true", help="each stage's import time (PYTHONPROFILEIMPORTTIME)")
    args = parser.parse_args()
    repo = make_tiny_repo(Path(tempfile.mkdtemp(prefix="hnsdt-pipeline-time-")) / "repo", tiny=args.tiny)
    env = dict(os.environ, PATH=f"{BIN}:{os.environ['PATH']}", PYTHONUNBUFFERED="1")
    if args.imports:
        env["PYTHONPROFILEIMPORTTIME"] = "1"  # every stage process lists its imports on stderr, which DVC relays
    if args.cache:
        subprocess.run(["dvc", "cache", "dir", str(args.cache.resolve())], cwd=repo, env=env, check=True)
    start = time.perf_counter()
    marks: list[tuple[float, str]] = []
    ticks: list[tuple[int, int] | None] = []  # cpu_times() at each mark
    proc = subprocess.Popen(["dvc", "repro"], cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, bufsize=1)
    tail: list[str] = []
    imports: dict[str, float] = defaultdict(float)  # stage -> seconds of its processes' top-level imports
    for line in proc.stdout:
        m = re.match(r"Running stage '([^']+)'", line)
        if m:
            marks.append((time.perf_counter() - start, m.group(1)))
            ticks.append(cpu_times())
            print(f"[{marks[-1][0]:7.1f} s] {m.group(1)}", flush=True)
        if line.startswith("import time:"):  # (--imports; kept out of the failure tail)
            top = re.match(r"import time:\s+\d+ \|\s+(\d+) \| \S", line)  # one space: imported by the script
            if top and marks:
                imports[marks[-1][1]] += int(top.group(1)) / 1e6
            continue
        tail = (tail + [line])[-20:]
    total, end_ticks = time.perf_counter() - start, cpu_times()
    if proc.wait() != 0:
        print("".join(tail), file=sys.stderr)
        return 1
    ends = [t for t, _ in marks[1:]] + [total]
    per_stage = [(name, end - t) for (t, name), end in zip(marks, ends)]
    cores = dict(zip((name for _, name in marks), map(busy_cores, ticks, ticks[1:] + [end_ticks])))
    kinds: dict[str, list[float]] = defaultdict(list)
    for name, secs in per_stage:
        kinds[name.split("@")[0]].append(secs)
    print(f"\ntotal: {total:.0f} s ({total / 60:.1f} min), {len(per_stage)} stages, {os.cpu_count()} cores")
    print(f"{'stage kind':<14} {'instances':>9} {'seconds':>8} {'share':>6}")
    for kind, secs in sorted(kinds.items(), key=lambda kv: -sum(kv[1])):
        print(f"{kind:<14} {len(secs):>9} {sum(secs):>8.0f} {sum(secs) / total:>6.0%}")
    n = os.cpu_count() or 1
    print(f"cores busy on average: {busy_cores(ticks[0] if ticks else None, end_ticks):.2f} of {n}")
    print("\nslowest instances (seconds, cores busy):")
    for name, secs in sorted(per_stage, key=lambda x: -x[1])[:12]:
        print(f"  {secs:7.1f} s  {cores[name]:4.2f}  {name}")
    print("\nevery stage by idle core-seconds (seconds × cores left idle; the cores busy):")
    for name, secs in sorted(per_stage, key=lambda x: -(n - cores[x[0]]) * x[1]):
        print(f"  {(n - cores[name]) * secs:7.1f}  {cores[name]:4.2f}  {name}")
    if args.imports:
        print(f"\nimports: {sum(imports.values()):.1f} s of the {total:.0f} s, per stage (its processes' imports, "
              "seconds of the stage):")
        for name, secs in per_stage:
            print(f"  {imports[name]:6.1f} of {secs:6.1f} s  {name}")
    if args.keep:
        print(f"\nkept {repo}")
    else:
        shutil.rmtree(repo.parent, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
