"""Stage `collect_generalisation`: the unseen-layout experiment's training layouts as one LeRobot dataset."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params, compute_settings


def collect_unseen(params: Params, out: Path, progress: bool = True, compute=None) -> Path:
    """Stage `collect_generalisation`: noisy-planner episodes on every training layout of the unseen-layout
    experiment, one LeRobot dataset with local views at ``out`` (over many layouts, shard by shard on ``compute``'s
    workers: :func:`hnsdt.data.collect.collect_on_layouts`)."""
    from hnsdt.compose import generalisation as gen
    from hnsdt.compose.config import layout_collect_config
    from hnsdt.data.collect import collect_on_layouts

    g, cfg = params.need("generalisation"), layout_collect_config(params)
    train = gen.training_layouts(params)
    gen.check_sources(train, max(cfg.fail_probs), yardsticks=g.evaluated_train_layouts)  # (the rest: data)
    root = collect_on_layouts(cfg, [s.layout for s in train], out, f"local/generated-{g.family}", g.view_radius,
                              g.family, progress, compute or compute_settings(params))
    print(f"wrote LeRobot dataset {root} (card: {root / 'README.md'})")
    return root
