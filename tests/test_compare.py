"""`make compare` (tools/compare.py): the changed knobs and headline metrics of `dvc exp show` rows, transposed
to fit a terminal. The real `dvc exp run` / compare round trip is in test_pipeline_use.py."""

from __future__ import annotations

import sys

from conftest import REPO

sys.path.insert(0, f"{REPO}/tools")

from compare import changed_rows, render  # noqa: E402


def _rows(n: int) -> list[dict]:
    """Rows as ``dvc.api.exp_show`` gives them: the workspace, the commit, then ``n`` experiments."""
    rows = []
    for i in range(n + 2):
        rows.append({"Experiment": None if i < 2 else f"exp-{i}", "rev": "workspace" if i == 0 else f"{i:040x}",
                     "evaluate.episodes": 100 if i == 1 else 50, "train.seeds": [0, 1],
                     "metrics/headline/keydoor.json:hnsdt": 1.0,
                     "metrics/headline/heldout.json:pure_dt": 0.48 + 0.01 * i,
                     "data/datasets/keydoor": f"md5-{i}"})  # a dependency's hash: never a row
    return rows


def test_only_what_changed_is_shown_the_knobs_first():
    changed = changed_rows(_rows(2), {"evaluate.episodes", "train.seeds"})
    assert list(changed) == ["knob evaluate.episodes", "heldout.pure_dt"]
    assert changed["knob evaluate.episodes"] == [50, 100, 50, 50]


def test_the_table_fits_the_width_and_says_what_it_left_out(monkeypatch, tmp_path):
    (tmp_path / "params.yaml").write_text("evaluate:\n  episodes: 100\ntrain:\n  seeds: [0, 1]\n")
    monkeypatch.chdir(tmp_path)
    text = render(_rows(30), width=120)
    assert max(map(len, text.splitlines())) <= 120
    assert "knob evaluate.episodes" in text and "heldout.pure_dt" in text and "more experiments not shown" in text
    assert "keydoor.hnsdt" not in text and "md5" not in text
    wide = render(_rows(30), width=1000)
    assert "more experiments not shown" not in wide and max(map(len, wide.splitlines())) > 120
