"""Stage `minigrid_reference`: the exact optimum, the BabyAI bot and the symbolic agent on one of MiniGrid's own
worlds (``minigrid.envs.<name>``), every test seed and fail_prob."""

from __future__ import annotations

import json
from pathlib import Path

from hnsdt.compose.config import Params
from hnsdt.core.fileio import atomic_dir, write_folder
from hnsdt.stages.common import provenance


def minigrid_reference(params: Params, env: str, out: Path, recorded: Path | None = None) -> Path:
    """``out``: ``reference.csv`` (per world, fail_prob and reference), ``summary.csv`` (mean over the worlds)
    and ``provenance.json``; ``recorded``: a folder of one rerun and one MCAP recording per played reference and
    fail_prob, on the first test world (their own output: rerun's bytes vary from run to run)."""
    from hnsdt.evaluation.minigrid import (ROW_COLUMNS, SUMMARY_COLUMNS, recordings, reference_rows, summarise,
                                           to_csv)
    from hnsdt.minigrid.live import check_id

    section = params.need("minigrid")
    if env not in section.envs:
        raise params.error(f"minigrid.envs has no {env!r} (it has {', '.join(section.envs)})")
    env_id = section.envs[env].id
    check_id(env_id)
    rows = reference_rows(env_id, section.test_seeds.seeds, section.fail_probs, section.episodes)
    with atomic_dir(out) as work:
        work.mkdir(parents=True)
        (work / "reference.csv").write_text(to_csv(rows, ROW_COLUMNS))
        (work / "summary.csv").write_text(to_csv(summarise(rows), SUMMARY_COLUMNS))
        (work / "provenance.json").write_text(json.dumps({"env": env, "id": env_id, **provenance(params)},
                                                         indent=1) + "\n")
    if recorded is not None:
        files = recordings(env_id, section.test_seeds.first, section.fail_probs, provenance(params))
        write_folder(recorded, files)
        print(f"wrote {len(files)} recordings to {recorded}")
    print(f"wrote {out}")
    return Path(out)
