"""Time and peak memory of the unseen-layout experiment's collection and HNSDT training as the training maps grow.

For each number of maps: `hnsdt generalisation collect` and `hnsdt generalisation train --method hnsdt` (one
seed) run as fresh processes on params.yaml with `generalisation.train_layouts` set, under `/usr/bin/time -v`
(its "Maximum resident set size": the largest single process) while a sampler adds up the resident memory of
the command's whole process tree every 0.2 s (workers included). Prints one row per number of maps and stage:
frames, seconds, seconds per 1,000 maps, CPU-seconds (user + system, every process: the figure to compare when
other work shares the cores), peak RSS of one process and of the tree. The issue's scale study runs
`--maps 400 4000 40000` with `--set episodes_per_layout=1` (2 episodes a map, as the scaling figure's 4,000-map
point); the figure is in docs/timings.md.

Run: python benchmarks/data_scale.py --maps 400 4000 [--seed 0] [--set KEY=VALUE ...] [--keep DIR] [--epochs E]
     [--stages collect train]
(`--set` takes a `generalisation` key as YAML; `--epochs E` caps HNSDT's epochs, its validated plateau otherwise;
`--keep DIR` keeps each dataset and model in DIR/maps<N>, where `--stages train` finds the dataset again.)
"""

import argparse
import copy
import json
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil
import yaml

ROOT = Path(__file__).resolve().parents[1]


def tree_rss(proc: psutil.Process) -> int:
    """Resident bytes of ``proc`` and every process below it (0 for any that ended meanwhile)."""
    total = 0
    for p in [proc, *proc.children(recursive=True)]:
        try:
            total += p.memory_info().rss
        except psutil.Error:
            pass
    return total


def measured(cmd: list[str], log: Path) -> dict:
    """Run ``cmd`` under ``/usr/bin/time -v``; its wall seconds, the largest process's peak RSS and the process
    tree's peak summed RSS (bytes). A failed command stops the benchmark with its log's tail."""
    with open(log, "w") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(["/usr/bin/time", "-v", *cmd], stdout=out, stderr=subprocess.STDOUT, cwd=ROOT)
        peak, ps = 0, psutil.Process(proc.pid)
        done = threading.Event()

        def sample():
            nonlocal peak
            while not done.wait(0.2):
                peak = max(peak, tree_rss(ps))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        rc = proc.wait()
        done.set()
        sampler.join()
        seconds = time.perf_counter() - t0
    text = log.read_text()
    if rc:
        sys.exit(f"{' '.join(cmd)} failed ({rc}):\n" + "\n".join(text.splitlines()[-20:]))
    largest = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1)) * 1024
    cpu = sum(float(re.search(rf"{kind} time \(seconds\): ([\d.]+)", text).group(1)) for kind in ("User", "System"))
    return {"seconds": seconds, "cpu": cpu, "rss": largest, "tree_rss": peak}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--maps", type=int, nargs="+", required=True)
    ap.add_argument("--params", default="params.yaml")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--epochs", type=int, help="cap HNSDT's epochs (default: its validated plateau)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--keep", type=Path, metavar="DIR")
    ap.add_argument("--stages", nargs="+", choices=["collect", "train"], default=["collect", "train"],
                    help="train alone: on the dataset a run with --keep DIR left in DIR/maps<N>")
    args = ap.parse_args()
    raw = yaml.safe_load((ROOT / args.params).read_text())
    hnsdt = str(Path(sys.executable).with_name("hnsdt"))
    gib = 2 ** 30
    from hnsdt.core.provenance import cpu_name

    print(f"CPU: {cpu_name()}; params {args.params} with {args.set or 'no changes'}; HNSDT seed {args.seed}\n")
    print("| maps | stage | frames | seconds | s / 1,000 maps | CPU-s | peak RSS, largest process | peak RSS, all "
          "processes |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.maps:
            folder = (args.keep / f"maps{n}") if args.keep else Path(tmp) / f"maps{n}"
            folder.mkdir(parents=True, exist_ok="collect" not in args.stages)
            cfg = copy.deepcopy(raw)
            g = cfg["generalisation"]
            g.update(train_layouts=n, method_seeds={"hnsdt": [args.seed]})
            for item in args.set:
                key, _, value = item.partition("=")
                g[key] = yaml.safe_load(value)
            if args.epochs:
                cfg["train"]["validation"]["hnsdt"]["max_epochs"] = args.epochs
            params = folder / "params.yaml"
            params.write_text(yaml.safe_dump(cfg, sort_keys=False))
            base = [hnsdt, "--params", str(params), "generalisation"]
            dataset = folder / "dataset"
            runs = {
                "collect": base + ["collect", "--out", str(dataset), "--quiet"],
                "train hnsdt": base + ["train", "--method", "hnsdt", "--dataset", str(dataset), "--out",
                                       str(folder / "models/hnsdt"), "--curves", str(folder / "curves"), "--quiet"],
            }
            for stage, cmd in runs.items():
                if stage.split()[0] not in args.stages:
                    continue
                m = measured(cmd, folder / f"{stage.replace(' ', '_')}.log")
                frames = json.loads((dataset / "meta/info.json").read_text())["total_frames"]
                extra = ""
                if stage.startswith("train"):
                    usage = json.loads((folder / f"models/hnsdt/seed{args.seed}/config.json").read_text())
                    usage = usage.get("facts", usage).get("usage", {})
                    extra = f" ({usage.get('epochs', '?')} epochs, {usage.get('gradient_steps', '?')} steps)"
                print(f"| {n:,} | {stage}{extra} | {frames:,} | {m['seconds']:.0f} | {1000 * m['seconds'] / n:.0f} | "
                      f"{m['cpu']:.0f} | {m['rss'] / gib:.2f} GiB | {m['tree_rss'] / gib:.2f} GiB |", flush=True)


if __name__ == "__main__":
    main()
