"""Same seed, same bytes, however the runs are grouped and wherever they execute: one process or a pool of
workers, alone or beside other seeds, the local executor or a real (local) Ray instance."""

import pytest

from test_bad_input import hnsdt, workdir  # noqa: F401  (the module fixture: small params and a dataset)


def test_a_seed_trains_to_the_same_bytes_alone_or_after_another(workdir, tmp_path):  # noqa: F811
    common = ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet", "--dataset",
              workdir / "data/datasets/keydoor"]
    together = hnsdt(*common, "--seed", "0", "1", "--workers", "1", "--out", tmp_path / "together", "--curves",
                     tmp_path / "c1", cwd=workdir)
    alone = hnsdt(*common, "--seed", "1", "--out", tmp_path / "alone", "--curves", tmp_path / "c2", cwd=workdir)
    assert together.returncode == 0 and alone.returncode == 0, together.stderr + alone.stderr
    assert sorted(p.name for p in (tmp_path / "together").iterdir()) == ["seed0", "seed1"]
    weights = [(tmp_path / d / "seed1/model.safetensors").read_bytes() for d in ("together", "alone")]
    assert weights[0] == weights[1]
    assert (tmp_path / "c1/seed1.csv").read_text() == (tmp_path / "c2/seed1.csv").read_text()
    assert (tmp_path / "together/seed0/model.safetensors").read_bytes() != weights[0]  # seeds do differ


def _files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_executors_and_worker_counts_give_the_same_bytes(workdir, tmp_path):  # noqa: F811
    """Training (two seeds) and evaluation, each run in this process, by two local workers and on a local
    Ray instance: every checkpoint, curve and results table is identical."""
    train = ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet", "--seed", "0", "1",
             "--dataset", workdir / "data/datasets/keydoor"]
    evaluate = ["evaluate", "--models", workdir / "models", "--quiet"]
    runs = {"inline": ["--workers", "1"], "pool": ["--workers", "2"], "ray": ["--executor", "ray"]}
    for name, how in runs.items():
        for args in ([*train, "--out", tmp_path / name / "models", "--curves", tmp_path / name / "curves"],
                     [*evaluate, "--out", tmp_path / name / "results", "--recordings", tmp_path / name / "rec"]):
            out = hnsdt(*args, *how, cwd=workdir)
            assert out.returncode == 0, f"{name}: {out.stderr[-3000:]}"
    reference = {sub: _files(tmp_path / "inline" / sub) for sub in ("models", "curves", "results")}
    assert len(reference["models"]) == 4 and "metrics.json" in reference["results"]
    for name in ("pool", "ray"):
        for sub in ("models", "curves", "results"):
            assert _files(tmp_path / name / sub) == reference[sub], f"{name} {sub} differ from one process"
