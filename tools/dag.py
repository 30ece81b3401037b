"""The pipeline's stages as a diagram that fits a page: `dvc dag --mermaid` with every foreach / matrix instance
folded into its stage (``train@keydoor-hnsdt`` → ``train``), for the README.

Usage: python tools/dag.py [--check]
Prints the Mermaid diagram, or with --check exits 1 (one line) when the README's (between the
``<!-- dag:begin -->`` / ``<!-- dag:end -->`` markers) differs from the pipeline's.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MARKERS = "<!-- dag:begin -->", "<!-- dag:end -->"


def fold(mermaid: str) -> str:
    """`dvc dag --mermaid` output with each stage's instances as one node, the edges between stages once each
    and none that a path through other stages already implies."""
    names = dict(re.findall(r'^\s*(node\d+)\["([^"]+)"\]', mermaid, re.M))
    stage = {node: name.split("@")[0] for node, name in names.items()}
    edges = {(stage[a], stage[b]) for a, b in re.findall(r"^\s*(node\d+)-->(node\d+)", mermaid, re.M)}
    edges = {(a, b) for a, b in edges if a != b}
    edges = {(a, b) for a, b in edges if not _reaches(edges - {(a, b)}, a, b)}  # an edge implied by others: left out
    order = list(dict.fromkeys(stage[n] for n in names))
    lines = ["flowchart LR"] + [f"  {a} --> {b}" for a, b in sorted(edges, key=lambda e: (order.index(e[0]),
                                                                                          order.index(e[1])))]
    return "\n".join(lines)


def _reaches(edges: set, a: str, b: str) -> bool:
    frontier, seen = [a], {a}
    while frontier:
        node = frontier.pop()
        for x, y in edges:
            if x == node and y not in seen:
                if y == b:
                    return True
                seen.add(y)
                frontier.append(y)
    return False


def diagram() -> str:
    out = subprocess.run(["dvc", "dag", "--mermaid"], cwd=ROOT, capture_output=True, text=True, check=True)
    return "```mermaid\n" + fold(out.stdout) + "\n```"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check the README's; exit 1 when it differs")
    args = parser.parse_args()
    if not args.check:
        print(diagram())
        return 0
    readme = (ROOT / "README.md").read_text()
    begin, end = MARKERS
    if readme.count(begin) != 1 or readme.count(end) != 1:
        print(f"README.md: needs exactly one {begin} and one {end}", file=sys.stderr)
        return 1
    shown = readme.split(begin)[1].split(end)[0].strip()
    if shown != diagram():
        print("README.md: the pipeline diagram differs from dvc.yaml's stages; paste `python tools/dag.py`",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
