"""Before `dvc repro` (`make pipeline`): the two files DVC rewrites in place, not atomically, whole or cut short.

A run killed while DVC writes one of them leaves it cut short, and the next `dvc repro` stops on it with DVC's own
error. This says what to do instead, in one line, and exits 2:
- dvc.lock (the pipeline's record): the committed one back; stages finished since come back from DVC's run cache.
- .dvc/tmp/rwlock (which running DVC process holds which output): it only lists running processes, so with none
  running it may go (DVC itself drops the entries of killed processes from a whole one).
"""

import json
import sys
from pathlib import Path

import yaml
from dvc.schema import COMPILED_LOCKFILE_SCHEMA

LOCK, RWLOCK = Path("dvc.lock"), Path(".dvc/tmp/rwlock")


def main() -> int:
    if LOCK.exists():
        try:
            COMPILED_LOCKFILE_SCHEMA(yaml.safe_load(LOCK.read_text()))
        except Exception:  # not YAML, or YAML cut off before a stage's keys
            print("make: dvc.lock is damaged (a run killed while DVC rewrote it in place): git checkout dvc.lock, "
                  "then make pipeline again (stages finished since come back from DVC's run cache)", file=sys.stderr)
            return 2
    if RWLOCK.exists():
        try:
            json.loads(RWLOCK.read_text())
        except ValueError:
            print(f"make: {RWLOCK} is damaged (a run killed while DVC rewrote it in place): with no other dvc "
                  f"running, rm {RWLOCK}, then make pipeline again", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
