"""Stage `report`: the figures, report.md and the headline metrics."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params


def report(params: Params, results: Path, out: Path, generalisation: Path | None = None,
           headline: Path | None = None, ablations: Path | None = None, experiments: Path | None = None,
           minigrid: Path | None = None, minigrid_learners: Path | None = None) -> Path:
    """Stage `report`: figures and report.md, and the headline metrics (``headline``)."""
    from hnsdt.report.write import write_report

    path = write_report(params, results, out, generalisation=generalisation, headline=headline, ablations=ablations,
                        experiments=experiments, minigrid=minigrid, minigrid_learners=minigrid_learners)
    print(f"wrote {path}")
    return path
