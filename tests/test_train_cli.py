"""`hnsdt train` runs every seed of a method in one process; grouping must not change any seed's bytes."""

from test_bad_input import hnsdt, workdir  # noqa: F401  (the module fixture: small params and a dataset)


def test_a_seed_trains_to_the_same_bytes_alone_or_after_another(workdir, tmp_path):  # noqa: F811
    common = ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet", "--dataset",
              workdir / "data/datasets/keydoor"]
    together = hnsdt(*common, "--seed", "0", "1", "--out", tmp_path / "together", "--curves", tmp_path / "c1",
                     cwd=workdir)
    alone = hnsdt(*common, "--seed", "1", "--out", tmp_path / "alone", "--curves", tmp_path / "c2", cwd=workdir)
    assert together.returncode == 0 and alone.returncode == 0, together.stderr + alone.stderr
    assert sorted(p.name for p in (tmp_path / "together").iterdir()) == ["seed0", "seed1"]
    weights = [(tmp_path / d / "seed1/model.safetensors").read_bytes() for d in ("together", "alone")]
    assert weights[0] == weights[1]
    assert (tmp_path / "c1/seed1.csv").read_text() == (tmp_path / "c2/seed1.csv").read_text()
    assert (tmp_path / "together/seed0/model.safetensors").read_bytes() != weights[0]  # seeds do differ
