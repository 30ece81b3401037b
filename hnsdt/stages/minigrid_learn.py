"""Stage `minigrid_learn`: the learners on one of MiniGrid's own worlds (``minigrid.envs.<name>``) — the decision
transformers (HNSDT, the pure DT) and the RNNs (the LSTM, the GRU) trained on its dataset, PPO in its training
worlds — played on every test world and fail_prob."""

from __future__ import annotations

import json
from pathlib import Path

from hnsdt.compose.config import Params, compute_settings
from hnsdt.stages.common import provenance


def minigrid_learn(params: Params, env: str, dataset: Path, out: Path, recorded: Path | None = None,
                   compute=None, progress: bool = True) -> Path:
    """``out``: ``models/<method>/seed<k>/`` (checkpoints, with what the training used and its validation
    measure), ``curves/<method>-seed<k>.json`` (loss every 10 steps, the validation steps every epoch),
    ``learned.csv`` (per world, fail_prob, method and training seed), ``summary.csv`` (over worlds and seeds) and
    ``provenance.json`` (PPO's curve: a row per iteration, its validation steps every ``eval_every`` frames);
    ``recorded``: one rerun and one MCAP recording per method and fail_prob (training seed
    0, the first test world; their own output, as rerun's bytes vary from run to run)."""
    from hnsdt.compose.minigrid import learn, learn_runs, start_order
    from hnsdt.core.compute import run_tasks
    from hnsdt.core.fileio import atomic_dir, finished_tasks, write_folder
    from hnsdt.evaluation.minigrid import (LEARNED_COLUMNS, ROW_COLUMNS, learned_recordings, played_rows,
                                           summarise_seeds, to_csv)
    from hnsdt.models.checkpoint import save_checkpoint

    section = params.need("minigrid")
    if env not in section.envs:
        raise params.error(f"minigrid.envs has no {env!r} (it has {', '.join(section.envs)})")
    runs = learn_runs(params, env, str(dataset))
    with finished_tasks(out) as keep:  # (runs finished before a kill are not run again)
        results = run_tasks(learn, runs, compute or compute_settings(params), desc=f"learn {env}", progress=progress,
                            keep=keep, cost=start_order)
        rows, models = [], {}
        with atomic_dir(out) as work:
            (work / "curves").mkdir(parents=True)
            for run, result in zip(runs, results):
                model = result["network"](result["config"])
                model.load_state_dict(result["state"])
                models[(run.method, run.seed)] = model
                name = f"{run.method}/seed{run.seed}"
                save_checkpoint(model, work / "models" / name, {"method": run.method, "seed": run.seed,
                                                               "env_id": run.env_id, "dataset_md5": run.data_md5,
                                                               "usage": result["usage"]})
                (work / "curves" / f"{run.method}-seed{run.seed}.json").write_text(
                    json.dumps({"curve": result["curve"], "usage": result["usage"]}, indent=1) + "\n")
                rows += played_rows(run.env_id, run.method, run.seed, run.test, result["episodes"])
            (work / "learned.csv").write_text(to_csv(rows, ROW_COLUMNS + ("train_seed",)))
            (work / "summary.csv").write_text(to_csv(summarise_seeds(rows), LEARNED_COLUMNS))
            (work / "provenance.json").write_text(json.dumps({"env": env, "id": section.envs[env].id,
                                                              **provenance(params)}, indent=1) + "\n")
    if recorded is not None:
        seed = min(r.seed for r in runs)
        first = {m: model for (m, s), model in models.items() if s == seed}
        files = learned_recordings(section.envs[env].id, first, section.test_seeds.first, section.fail_probs,
                                   section.learn.target_return, provenance(params))
        write_folder(recorded, files)
        print(f"wrote {len(files)} recordings to {recorded}")
    print(f"wrote {out}")
    return Path(out)
