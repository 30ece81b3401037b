"""Writing a LeRobot dataset faster changes none of its bytes: the episode statistics computed on whole arrays are
lerobot's own, and lerobot's metadata written once is what it writes after every episode."""

import contextlib

import numpy as np
import pytest
from lerobot.datasets import compute_stats

from hnsdt.data import lerobot_io
from hnsdt.data.collect import Behaviour, CollectConfig, collect_on_layouts
from hnsdt.data.episode_stats import feature_stats
from hnsdt.envs.generate import generate


def _awkward_arrays():
    rng = np.random.default_rng(7)
    yield rng.integers(0, 14, (37, 169))                       # a whole map: int codes, constant walls
    yield rng.integers(0, 3, (2, 5))                           # two frames
    yield np.full((20, 3), 7)                                  # every element constant
    yield rng.normal(size=(50, 4)).astype(np.float32)
    yield np.full((9,), -0.1, np.float32)                      # float32: the 1e-10 padding vanishes, a zero step
    yield np.array([1000.0, 1000.001, 1000.0005], np.float32)  # float32 edges that repeat
    yield rng.integers(0, 2, (300,)).astype(bool)
    yield np.concatenate([np.zeros(99), [1e6]])                # a value on the last edge, the rest in the first bin
    yield rng.integers(-5, 5, (120, 1))
    yield rng.random((17, 6)).astype(np.float32) * 1e-30
    for n in (3, 10, 31, 100, 257):                            # quantile targets q * n on and off whole counts
        yield rng.integers(0, 4, (n, 3)) * rng.integers(1, 9, 3)


@pytest.mark.parametrize("array", list(_awkward_arrays()), ids=lambda a: f"{a.dtype}{a.shape}")
def test_the_vectorised_episode_stats_are_lerobots_bit_for_bit(array):
    keepdims = array.ndim == 1  # (compute_episode_stats' own choice)
    want = compute_stats.get_feature_stats(array, axis=0, keepdims=keepdims)
    got = feature_stats(array, axis=0, keepdims=keepdims)
    assert list(got) == list(want)
    for key in want:
        assert (got[key].dtype, got[key].shape) == (want[key].dtype, want[key].shape), key
        assert got[key].tobytes() == want[key].tobytes(), (key, got[key], want[key])


def test_a_dataset_written_faster_is_the_bytes_lerobot_writes_alone(tmp_path, monkeypatch):
    """A dataset over two generated maps, with local views and whole maps, written as the stages write it and
    again with lerobot's own statistics and its metadata rewritten after every episode: every file the same."""
    layouts = [generate("keydoor_maze", seed) for seed in (0, 1)]
    cfg = CollectConfig("hnsdt/KeyDoor-v0", layouts[0], 80, [0.0, 0.2],
                        [Behaviour("noisy_planner", 4, "layout", 0.1), Behaviour("noisy_planner", 4, "random", 0.1)])
    fast = collect_on_layouts(cfg, layouts, tmp_path / "fast", "local/t", 2, "keydoor_maze", progress=False)
    monkeypatch.setattr(lerobot_io, "vectorised_episode_stats", contextlib.nullcontext)
    monkeypatch.setattr(lerobot_io, "_metadata_written_once", lambda ds: contextlib.nullcontext())
    plain = collect_on_layouts(cfg, layouts, tmp_path / "plain", "local/t", 2, "keydoor_maze", progress=False)
    files = sorted(p.relative_to(plain) for p in plain.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(fast) for p in fast.rglob("*") if p.is_file())
    assert any(f.name == "stats.json" for f in files) and any(f.name == "info.json" for f in files)
    assert [f for f in files if (fast / f).read_bytes() != (plain / f).read_bytes()] == []
