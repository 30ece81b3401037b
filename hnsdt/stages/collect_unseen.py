"""Stage `collect_generalisation`: the unseen-layout experiment's training layouts as one LeRobot dataset."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params


def collect_unseen(params: Params, out: Path, progress: bool = True) -> Path:
    """Stage `collect_generalisation`: noisy-planner episodes on every training layout of the unseen-layout
    experiment, one LeRobot dataset with local views at ``out``."""
    from hnsdt.compose import generalisation as gen
    from hnsdt.compose.config import layout_collect_config
    from hnsdt.data.collect import collect_on_layouts

    g, cfg = params.need("generalisation"), layout_collect_config(params)
    train = gen.training_layouts(params)
    gen.check_sources(train, max(cfg.fail_probs))
    root = collect_on_layouts(cfg, [s.layout for s in train], out, f"local/generated-{g.family}", g.view_radius,
                              g.family, progress)
    print(f"wrote LeRobot dataset {root} (card: {root / 'README.md'})")
    return root
