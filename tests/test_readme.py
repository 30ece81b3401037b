"""The README's generated parts: its headline table and docs/results.md's per-cell table are the committed
metrics' (tools/readme_results.py), and its pipeline diagram is dvc.yaml's (tools/dag.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from conftest import REPO

REPO = Path(REPO)
sys.path.insert(0, str(REPO / "tools"))

from readme_results import BEGIN, END, HEADLINE, RESULTS_PAGE, headline_table, render, results_table  # noqa: E402

from hnsdt.report.headline import read_headline  # noqa: E402


def test_the_readme_results_table_matches_the_committed_summary():
    out = subprocess.run([sys.executable, str(REPO / "tools/readme_results.py"), "--check"], capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr


def test_the_check_fails_when_a_number_changes():
    summary = pd.read_csv(REPO / "metrics/summary.csv")
    readme = (REPO / RESULTS_PAGE).read_text()  # the per-cell table's page
    assert render(readme, results_table(summary)) == readme
    changed = summary.copy()
    changed.loc[0, "success_mean"] = 0.123
    assert render(readme, results_table(changed)) != readme
    with pytest.raises(ValueError, match="marker"):
        render(readme.replace(BEGIN, ""), "")
    assert END in readme


def test_the_headline_table_follows_the_headline_metrics():
    headline = read_headline(REPO / "metrics/headline")
    readme = (REPO / "README.md").read_text()
    assert render(readme, headline_table(headline), HEADLINE) == readme
    method = next(m for m in headline["keydoor"] if m != "hnsdt_steps_ratio")
    headline["keydoor"][method] = 0.123
    table = headline_table(headline)
    assert "0.123" in table and render(readme, table, HEADLINE) != readme


def test_the_readme_pipeline_diagram_is_the_pipelines():
    from dag import fold

    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}  # dvc from the venv
    out = subprocess.run([sys.executable, str(REPO / "tools/dag.py"), "--check"], capture_output=True, text=True,
                         env=env)
    assert out.returncode == 0, out.stderr
    mermaid = """flowchart TD
	node1["collect@a"]
	node2["collect@b"]
	node3["train@a-x"]
	node4["evaluate"]
	node1-->node3
	node2-->node3
	node3-->node4
	node1-->node4
"""  # instances fold into their stage; collect --> evaluate is implied by collect --> train --> evaluate
    assert fold(mermaid).splitlines() == ["flowchart LR", "  collect --> train", "  train --> evaluate"]

