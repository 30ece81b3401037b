"""LeRobot's per-episode feature statistics, computed for all of a feature's elements at once: the same numbers.

Writing an episode, ``lerobot`` computes each feature's min, max, mean, std and five quantiles per element
(``compute_stats.get_feature_stats``: one ``RunningQuantileStats`` update, a 5,000-bin histogram per element, a
cumulative sum per element and quantile). Over a dataset whose frames carry the whole map (169 elements) that
per-element Python loop was 60 % of the write (11.7 of 18.9 s for 256 episodes, profiled). :func:`feature_stats`
does the same arithmetic on arrays of every element: the same bin edges (``np.linspace``), each value's bin by
``np.histogram``'s rule (``edges[k] <= v < edges[k + 1]``, the last bin closed), each quantile's bin read off the
sorted bins instead of a cumulative histogram, the same interpolation — the same values and dtypes bit for bit
(``tests/test_episode_stats.py`` compares them with ``lerobot``'s own on awkward arrays), so a dataset is the same
bytes, written faster. Anything else (images, other axes or quantiles, fewer than two frames) goes to ``lerobot``'s
own function.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
from lerobot.datasets import compute_stats as lerobot_stats

BINS = 5000  # RunningQuantileStats' default num_quantile_bins, which get_feature_stats uses


def feature_stats(array: np.ndarray, axis, keepdims: bool, quantile_list: list[float] | None = None) -> dict:
    """``lerobot.datasets.compute_stats.get_feature_stats``, its vector case (``axis`` 0) vectorised."""
    quantiles = lerobot_stats.DEFAULT_QUANTILES if quantile_list is None else quantile_list
    if axis not in (0, (0,)) or array.shape[0] < 2 or list(quantiles) != lerobot_stats.DEFAULT_QUANTILES:
        return _lerobot_feature_stats(array, axis, keepdims, quantile_list)
    reshaped, count = lerobot_stats._prepare_array_for_stats(array, axis)
    stats = _running_stats(reshaped, quantiles)
    stats["count"] = np.array([count])
    return lerobot_stats._reshape_stats_by_axis(stats, axis, keepdims, array.shape)


def _running_stats(batch: np.ndarray, quantiles: list[float]) -> dict:
    """One ``RunningQuantileStats().update(batch)`` then ``get_statistics()``, every element at once."""
    batch = batch.reshape(-1, batch.shape[-1])
    batch = batch.astype(np.result_type(batch.dtype, np.float32), copy=False)
    n = batch.shape[0]
    mean, mean_sq = np.mean(batch, axis=0), np.mean(batch**2, axis=0)
    low, high = np.min(batch, axis=0), np.max(batch, axis=0)
    edges = _bin_edges(low - 1e-10, high + 1e-10)
    # (update's running mean after its first batch: the same operations, whose result is the batch's mean)
    mean += (np.mean(batch, axis=0) - mean) * (n / n)
    mean_sq += (np.mean(batch**2, axis=0) - mean_sq) * (n / n)
    bins = _bins(batch, edges)
    stats = {"min": low.copy(), "max": high.copy(), "mean": mean.copy(),
             "std": np.sqrt(np.maximum(0, mean_sq - mean**2)), "count": np.array([n])}
    for q in quantiles:
        stats[f"q{int(q * 100):02d}"] = _quantile(bins, edges, q * n)
    return stats


def _bin_edges(start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Row i: ``np.linspace(start[i], stop[i], BINS + 1)``. (numpy takes another branch for a zero step, and over
    an array for every row as soon as one row has one: then the rows go one at a time.)"""
    if not ((stop - start) / BINS == 0).any():
        return np.linspace(start, stop, BINS + 1, axis=1)
    return np.stack([np.linspace(a, b, BINS + 1) for a, b in zip(start, stop)])


def _bins(batch: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Each value's histogram bin, each column sorted: ``np.histogram``'s rule, ``edges[k] <= v < edges[k + 1]``
    and the last bin closed. (Every value lies within its row's edges: they run from min - 1e-10 to max + 1e-10.)"""
    index = np.empty(batch.shape[::-1], dtype=np.int64)
    for i, row in enumerate(edges):
        index[i] = np.searchsorted(row, batch[:, i], side="right") - 1
    return np.sort(np.minimum(index, BINS - 1), axis=1)


def _quantile(bins: np.ndarray, edges: np.ndarray, target: float) -> np.ndarray:
    """``RunningQuantileStats._compute_single_quantile`` of every row, gathered as its ``np.array`` would be. Its
    cumulative histogram is the count of values in bins up to each: the first bin where it reaches ``target``
    is that of the ceil(target)-th smallest value (none beyond the count: the last edge)."""
    rows, n = np.arange(len(bins)), bins.shape[1]
    need = math.ceil(target)
    idx = np.zeros(len(bins), dtype=np.int64) if need <= 0 else (
        np.full(len(bins), BINS) if need > n else bins[:, need - 1])
    inner = np.clip(idx, 1, BINS - 1)
    before = (bins < inner[:, None]).sum(axis=1).astype(np.float64)  # the cumulative histogram at inner - 1
    in_bin = (bins == inner[:, None]).sum(axis=1).astype(np.float64)
    at_edge = (idx == 0) | (idx >= BINS) | (in_bin == 0)
    edge = edges[rows, np.minimum(idx, BINS)]  # edges[0], edges[-1] or edges[idx]
    low, high = edges[rows, inner], edges[rows, inner + 1]
    value = low + ((target - before) / np.where(at_edge, 1.0, in_bin)) * (high - low)
    if at_edge.all():  # (a list of the edges' own scalars: their dtype)
        return edge
    return np.where(at_edge, edge, value)


_lerobot_feature_stats = lerobot_stats.get_feature_stats


@contextlib.contextmanager
def vectorised_episode_stats():
    """While writing: ``lerobot``'s episode statistics computed by :func:`feature_stats` (the same numbers)."""
    lerobot_stats.get_feature_stats = feature_stats
    try:
        yield
    finally:
        lerobot_stats.get_feature_stats = _lerobot_feature_stats
