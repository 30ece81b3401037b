"""Same inputs, same bytes: run the whole DVC pipeline twice, in two fresh temporary copies of this repo with
the tiny params override of the end-to-end tests, and diff the two ``dvc.lock`` files.

Usage: python benchmarks/determinism.py [--keep]
Prints each run's time and every output whose md5 differs; exits 1 if any output other than the episode
recordings differs. The ``recordings`` output is listed but expected to differ: rerun stamps every row of an
``.rrd`` with a time-based id (its MCAP files and every table, dataset and model must match).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from tiny_repo import lock_outs, make_tiny_repo, run  # noqa: E402

EXPECTED_TO_DIFFER = {"evaluate:recordings"}


def _mcap_md5s(repo: Path) -> dict[str, str]:
    import hashlib

    return {str(p.relative_to(repo)): hashlib.md5(p.read_bytes()).hexdigest()
            for p in sorted((repo / "recordings").rglob("*.mcap"))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", action="store_true", help="keep the two temporary repos and print their paths")
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="hnsdt-determinism-"))
    locks, mcaps = [], []
    repos = {name: make_tiny_repo(root / name) for name in ("a", "b")}  # both copies before either run
    for name, repo in repos.items():
        t = time.perf_counter()
        run(["dvc", "repro", "--quiet"], repo)
        print(f"run {name}: dvc repro in {time.perf_counter() - t:.0f} s ({repo})", flush=True)
        locks.append(lock_outs(repo))
        mcaps.append(_mcap_md5s(repo))
    a, b = locks
    differ = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
    print(f"\n{len(a)} outputs in dvc.lock; {len(a) - len(differ)} identical, {len(differ)} differ")
    for k in differ:
        print(f"  differs: {k}  {a.get(k)} vs {b.get(k)}" + ("  (expected: rerun row ids)"
                                                              if k in EXPECTED_TO_DIFFER else ""))
    mcap_differ = [k for k in mcaps[0] if mcaps[0][k] != mcaps[1].get(k)]
    print(f"{len(mcaps[0])} MCAP recordings; {len(mcaps[0]) - len(mcap_differ)} identical")
    for k in mcap_differ:
        print(f"  differs: {k}")
    if not args.keep:
        import shutil

        shutil.rmtree(root, ignore_errors=True)
    unexpected = [k for k in differ if k not in EXPECTED_TO_DIFFER] + mcap_differ
    print("\nRESULT:", "identical" if not unexpected else f"{len(unexpected)} unexpected difference(s)")
    return 1 if unexpected else 0


if __name__ == "__main__":
    sys.exit(main())
