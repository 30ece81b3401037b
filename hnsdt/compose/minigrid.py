"""The learners on MiniGrid's own worlds, one run per method and training seed: the decision transformers and the
RNN baselines trained on the world's dataset (:mod:`hnsdt.data.minigrid_dataset`), the online learners (PPO, DQN,
option-critic: :data:`ONLINE`) in its training worlds, each to the plateau of its steps on validation worlds; then every test world and fail_prob played
(:func:`hnsdt.agents.minigrid_play.play`).

A run is a frozen :class:`LearnRun` (the dataset by path and md5, the knobs, the worlds) handed to :func:`learn` on
the stage's executor (:mod:`hnsdt.core.compute`); it returns the weights, the curve, what the training used and
the played episodes, and touches no file.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

from hnsdt.agents.minigrid_play import Job, play
from hnsdt.baselines.minigrid_dqn import MiniGridDQNConfig, train_minigrid_dqn
from hnsdt.baselines.minigrid_options import MiniGridOptionsConfig, train_minigrid_options
from hnsdt.baselines.minigrid_ppo import MiniGridPPOConfig, train_minigrid_ppo
from hnsdt.compose.params import Params
from hnsdt.baselines.recurrent import RecurrentTrainConfig, train_recurrent
from hnsdt.core.methods import OFFLINE_BASELINES, OUR_DTS, method
from hnsdt.data.format import DatasetError
from hnsdt.data.minigrid_dataset import check_minigrid_dataset, load_minigrid_frames
from hnsdt.evaluation.minigrid import StepsOnWorlds
from hnsdt.models.minigrid_nets import (MiniGridActorCriticConfig, MiniGridDT, MiniGridDTConfig,
                                        MiniGridOptionCriticConfig, MiniGridQNetworkConfig, MiniGridRecurrent,
                                        MiniGridRecurrentConfig)
from hnsdt.models.train import TrainConfig, train_decision_transformer


@dataclass(frozen=True)
class LearnRun:
    env_id: str
    dataset: str  # the world's LeRobot dataset
    data_md5: str  # ... whose bytes the run was planned on
    method: str  # a MiniGrid learner of the registry (hnsdt.core.methods.MINIGRID_LEARNERS)
    seed: int
    model: tuple  # the network's config fields (MiniGridDTConfig's, MiniGridRecurrentConfig's, or an online
    #               learner's: ONLINE's) as (name, value)
    train: tuple  # the trainer's (TrainConfig's, RecurrentTrainConfig's, ONLINE's)
    validation: tuple[Job, ...]
    validation_max_steps: int
    test: tuple[Job, ...]
    target_return: float
    train_seeds: tuple[int, ...]  # the online learners' worlds (the dataset's)
    fail_probs: tuple[float, ...]


def learn_runs(params: Params, env: str, dataset: str) -> list[LearnRun]:
    """Every method × seed of ``minigrid.learn`` on world ``env`` (a key of ``minigrid.envs``)."""
    section = params.need("minigrid")
    learn = section.learn
    if learn is None:
        raise params.error("minigrid.learn is missing: the decision transformers' knobs on MiniGrid's worlds")
    md5 = check_minigrid_dataset(dataset).get("data_md5", "")
    validation = tuple(Job(s, p, 0) for s in learn.validation_seeds.seeds for p in section.fail_probs)
    test = tuple(Job(s, p, k) for s in section.test_seeds.seeds for p in section.fail_probs
                 for k in range(section.episodes))
    runs = []
    for name in learn.methods:
        if name in OUR_DTS:
            model = MiniGridDTConfig(condition=method(name).condition, **learn.model.model_dump())
            train = TrainConfig(epochs=learn.max_epochs, batch_size=learn.batch_size, lr=learn.lr, seed=0,
                                device="cpu", patience=learn.patience, log_every=10)
        elif name in OFFLINE_BASELINES:  # the network and its batches as in the paper's worlds (baselines.<name>)
            model, train = _recurrent_settings(params, name, learn)
        else:  # an online learner: its knobs in minigrid.learn.<name> (the network's among them: options')
            network, trainer, _ = ONLINE[method(name).code]
            knobs = getattr(learn, name).model_dump()
            net_fields = {f for f in network.__dataclass_fields__ if f in knobs}
            model = network(**{k: knobs.pop(k) for k in net_fields})
            train = trainer(**knobs)
        for seed in learn.seeds:
            runs.append(LearnRun(section.envs[env].id, str(dataset), md5, name, int(seed),
                                 tuple(asdict(model).items()), tuple({**asdict(train), "seed": int(seed)}.items()),
                                 validation, learn.validation_max_steps, test, learn.target_return,
                                 tuple(section.collect.train_seeds.seeds), tuple(section.fail_probs)))
    return runs


def start_order(run: LearnRun) -> int:
    """Which runs the stage starts first (:func:`hnsdt.core.compute.run_tasks`' ``cost``), longest first: the
    online learners (every frame a step of MiniGrid, and a policy that never reaches the goal plays every test
    episode to MiniGrid's step limit), then the RNNs, then the transformers (one run each on the Zen 4: 69–225,
    28–62 and 16–30 s, ``benchmarks/minigrid_learn_runs.py``). Only the order runs start in."""
    return 2 if method(run.method).training == "online" else 1 if run.method in OFFLINE_BASELINES else 0


# The online learners by the registry's code: their network's config, their trainer's config and their training
ONLINE = {"policy_gradient": (MiniGridActorCriticConfig, MiniGridPPOConfig, train_minigrid_ppo),
          "q_learning": (MiniGridQNetworkConfig, MiniGridDQNConfig, train_minigrid_dqn),
          "option_critic": (MiniGridOptionCriticConfig, MiniGridOptionsConfig, train_minigrid_options)}

RECURRENT_KNOBS = ("n_layers", "hidden", "embed", "batch_size", "lr")  # read from baselines.<name>


def _recurrent_settings(params: Params, name: str, learn) -> tuple[MiniGridRecurrentConfig, RecurrentTrainConfig]:
    """An RNN baseline's network and trainer on MiniGrid: its size, batch (whole episodes) and learning rate from
    ``baselines.<name>`` (one place for them), the epoch cap and patience of ``minigrid.learn``."""
    section = (params.need("baselines").model_extra or {}).get(name)
    missing = [k for k in RECURRENT_KNOBS if k not in (section or {})]
    if missing:
        raise params.error(f"baselines.{name} lacks {', '.join(missing)}: {name}'s network and batches on "
                           "MiniGrid's worlds")
    model = MiniGridRecurrentConfig(**method(name).fixed, n_layers=int(section["n_layers"]),
                                    hidden=int(section["hidden"]), embed=int(section["embed"]),
                                    cell_dim=learn.model.cell_dim)
    train = RecurrentTrainConfig(epochs=learn.max_epochs, batch_size=int(section["batch_size"]),
                                 lr=float(section["lr"]), seed=0, device="cpu", patience=learn.patience)
    return model, train


@lru_cache(maxsize=1)
def _frames(dataset: str, md5: str):
    """The dataset's frames, read once per process; refused when its bytes are not those the stage planned on."""
    frames, found = load_minigrid_frames(dataset, with_md5=True)
    if found != md5:
        raise DatasetError(f"dataset {dataset}: changed since the stage read it (data md5 {found}, was {md5}); "
                           "run the stage again")
    return frames


def train(run: LearnRun) -> tuple:
    """Train ``run``'s model to its plateau on the validation worlds: ``(model, config, curve, usage)``."""
    measure = StepsOnWorlds(run.env_id, list(run.validation), run.validation_max_steps, run.target_return)
    if run.method in OUR_DTS:
        cfg = MiniGridDTConfig(**dict(run.model))
        model, curve, usage = train_decision_transformer(_frames(run.dataset, run.data_md5), cfg,
                                                         TrainConfig(**dict(run.train)), progress=False,
                                                         network=MiniGridDT, measure=measure)
    elif run.method in OFFLINE_BASELINES:
        cfg = MiniGridRecurrentConfig(**dict(run.model))
        model, curve, usage = train_recurrent(_frames(run.dataset, run.data_md5), cfg, RecurrentTrainConfig(
            **dict(run.train)), progress=False, network=MiniGridRecurrent, measure=measure)
    else:
        network, trainer, train_online = ONLINE[method(run.method).code]
        cfg = network(**dict(run.model))
        model, curve, usage = train_online(run.env_id, list(run.train_seeds), list(run.fail_probs), cfg,
                                           trainer(**dict(run.train)), measure, progress=False)
    return model, cfg, curve, usage


def learn(run: LearnRun) -> dict:
    """Train ``run``'s model (:func:`train`), then play the test worlds: ``{"state": weights, "config", "curve",
    "usage", "episodes": [Episode per test job]}``."""
    model, cfg, curve, usage = train(run)
    episodes = play(model, run.env_id, list(run.test), run.target_return)
    return {"network": type(model), "state": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
            "config": cfg, "curve": curve, "usage": usage, "episodes": episodes}
