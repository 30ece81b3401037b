"""Stage `minigrid_collect`: the learners' LeRobot dataset on one of MiniGrid's own worlds (``minigrid.envs.<name>``):
noisy symbolic-agent episodes on the training worlds, every fail_prob, each frame labelled with its operator."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params


def minigrid_collect(params: Params, env: str, out: Path, progress: bool = True) -> Path:
    from hnsdt.data.minigrid_dataset import write_minigrid_dataset
    from hnsdt.minigrid.collect import collect_episodes
    from hnsdt.minigrid.live import check_id

    section = params.need("minigrid")
    if env not in section.envs:
        raise params.error(f"minigrid.envs has no {env!r} (it has {', '.join(section.envs)})")
    if section.collect is None:
        raise params.error("missing key minigrid.collect")
    collect = params.need("collect")
    env_id, c = section.envs[env].id, section.collect
    check_id(env_id)
    seeds = c.train_seeds.seeds
    episodes = collect_episodes(env_id, seeds, section.fail_probs, c.episodes_per_world, c.epsilon, collect.seed,
                                progress)
    meta = dict(env_id=env_id, world_seeds=seeds, fail_probs=list(section.fail_probs), epsilon=c.epsilon,
                seed=collect.seed, episodes_per_world=c.episodes_per_world, license=collect.license)
    write_minigrid_dataset(out, f"local/minigrid-{env}", episodes, collect.fps, meta, progress)
    print(f"wrote LeRobot dataset {out} ({len(episodes)} episodes)")
    return Path(out)
