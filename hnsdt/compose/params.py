"""The schema of ``params.yaml``: every knob's type, range, default and meaning, in one place.

:func:`validate` checks a whole params file against it before any work starts: an unknown key, a wrong type or
an out-of-range value stops with one line naming the key. :mod:`hnsdt.compose.config` turns the validated sections into
the library's configs. The learned baselines' own knobs (``baselines.<method>``) are the training and network
config dataclasses their registry entries name (:mod:`hnsdt.core.methods`), checked by
:func:`hnsdt.compose.config.baseline_settings`.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import (BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, create_model, field_validator,
                      model_validator)

from hnsdt.data.collect import POLICIES, STARTS
from hnsdt.models.windows import FORMULATIONS, LOSS_STEPS
from hnsdt.envs.generate import FAMILIES
from hnsdt.core.compute import EXECUTORS
from hnsdt.core.methods import (BASELINES, DT_METHODS, LEARNED, METHODS, OFFLINE_BASELINES, ONLINE_BASELINES,
                                 MINIGRID_LEARNERS)
from hnsdt.symbolic.operators import OPERATOR_SETS
from hnsdt.symbolic.planner import PLAN_MODES

Probability = Annotated[float, Field(ge=0, le=1)]
PositiveInt = Annotated[int, Field(ge=1)]


class ParamsError(ValueError):
    """A malformed params file; the message names the file and the key."""


def config_schema(cls) -> type[BaseModel]:
    """The pydantic schema of a method's config dataclass (the registry's network and training configs, e.g.
    :class:`hnsdt.baselines.dqn.DQNConfig`): its fields with their types, strict (an ``int`` knob takes no
    ``"3"``, ``3.0`` or ``True``; a ``float`` one takes an ``int``), no other keys; a tuple field takes the YAML
    list. Every field is optional here: a knob left out keeps the dataclass's default, so the dataclass stays the
    one place a knob and its default are defined (:func:`hnsdt.compose.config.typed_config` checks a section)."""
    import dataclasses
    import typing

    if cls not in _CONFIG_SCHEMAS:
        hints = typing.get_type_hints(cls)
        fields = {}
        for f in dataclasses.fields(cls):
            kind = hints[f.name]
            if typing.get_origin(kind) is tuple:  # a YAML list: lax for the container, strict for its items
                kind = Annotated[kind, Field(strict=False)]
            fields[f.name] = (kind, None)
        _CONFIG_SCHEMAS[cls] = create_model(cls.__name__ + "Params", __config__=ConfigDict(
            strict=True, extra="forbid", frozen=True), **fields)
    return _CONFIG_SCHEMAS[cls]


_CONFIG_SCHEMAS: dict[type, type[BaseModel]] = {}


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class EnvParams(Section):
    id: str = Field(description="registered gymnasium id (hnsdt.envs.ENV_IDS)")
    layout: str = Field(description="layout: a built-in name, a layout file's path or the grid text")
    max_steps: PositiveInt = Field(description="episode step limit (truncation)")


class PaperPlannerParams(Section):
    """The paper's arm (``hnsdt_paper``, Appendix B): these keys override ``planner``'s."""

    mode: Literal[PLAN_MODES] = "bfs"
    operators: Literal[OPERATOR_SETS] = "move"
    allowance_factor: float | None = Field(None, gt=0)
    allowance_min: int | None = Field(None, ge=1)


class PlannerParams(Section):
    mode: Literal[PLAN_MODES] = Field("cost", description="bfs = fewest operators (the paper); cost = fewest steps")
    operators: Literal[OPERATOR_SETS] = Field("goto", description="goto = GoTo macro-operators; move = one-cell "
                                              "Move operators (the paper)")
    allowance_factor: float = Field(3.0, gt=0, description="an operator may take this x its nominal cost before "
                                    "a replan ...")
    allowance_min: PositiveInt = Field(6, description="... and at least this many steps")
    paper: PaperPlannerParams = PaperPlannerParams()


class BehaviourParams(Section):
    policy: Literal[POLICIES]
    episodes: int = Field(ge=0)
    start: Literal[STARTS] = "layout"
    epsilon: Probability = Field(0.0, description="noisy_planner: share of random actions")


class CollectParams(Section):
    seed: int = 0
    fps: PositiveInt = Field(10, description="LeRobot timestamps: frame t is at t / fps seconds")
    license: str = Field("apache-2.0", description="the dataset card's licence (a Hub licence identifier)")
    render: int = Field(0, ge=0, le=64, description="> 0: store each frame as video `observation.image`, this "
                        "many pixels per cell")
    fail_probs: list[Probability] = Field(min_length=1, description="each behaviour's episodes are split evenly")
    behaviours: list[BehaviourParams]


class ModelParams(Section):
    """A decision transformer's size (paper, Appendix C)."""

    n_layers: PositiveInt
    n_heads: PositiveInt
    d_model: PositiveInt
    context: PositiveInt = Field(description="timesteps in the model's window")
    tokens: str = Field("step", description="step = one token per step; interleaved = one per state/action/"
                        "return (hnsdt.models.dt checks it)")


class ValidationParams(Section):
    """Training that stops on evidence (hnsdt.models.fit.Validation)."""

    share: float = Field(gt=0, lt=1, description="share of each behaviour's episodes held out")
    patience: PositiveInt = Field(2, description="epochs without a better measure before stopping")
    max_epochs: PositiveInt = Field(description="the cap")
    measure: Literal["loss", "steps"] = Field(
        "loss", description="loss: the loss on the held-out episodes; steps: mean steps to the exit from start "
        "states of the held-out episodes (fail_prob 0, the method's own agent; a failure counts the step limit)")
    starts: PositiveInt = Field(64, description="steps: how many held-out states to start from")


class TrainParams(Section):
    envs: list[str] = Field(min_length=1, description="keys of `envs`; every learned method trains on each")
    methods: list[Literal[DT_METHODS]] = Field(min_length=1, description="the decision transformers to train")
    seeds: list[int] = Field(min_length=1, description="shared by every learned method and the evaluation")
    behaviours: dict[Literal[DT_METHODS], list[Literal[POLICIES]]] = Field(
        default_factory=dict, description="which collected episodes each DT learns from (absent: all)")
    formulation: dict[Literal[DT_METHODS], Literal[FORMULATIONS]] = Field(
        default_factory=dict, description="each DT's examples: windows (absent) or whole episodes")
    loss: dict[Literal[DT_METHODS], Literal[LOSS_STEPS]] = Field(
        default_factory=dict, description="the window steps the loss counts (absent: window)")
    epochs: PositiveInt = Field(description="passes over each method's training examples (methods without "
                                "`validation`)")
    validation: dict[Literal[DT_METHODS], ValidationParams] = Field(
        default_factory=dict, description="per DT: train to the plateau of the loss on held-out episodes")
    max_steps: int = Field(0, ge=0, description="cap on gradient steps (0 = none)")
    batch_size: PositiveInt = 128
    lr: float = Field(1e-3, gt=0)
    dropout: Probability = 0.1
    device: str = Field("auto", description="auto = cuda if available, else cpu")


class BaselinesParams(BaseModel):
    """``offline`` / ``online``: which baselines train; ``<method>``: that method's knobs (its config
    dataclasses, checked by :func:`hnsdt.compose.config.baseline_settings`)."""

    model_config = ConfigDict(extra="allow", strict=True, frozen=True)

    offline: list[Literal[OFFLINE_BASELINES]] = Field(default_factory=list)
    online: list[Literal[ONLINE_BASELINES]] = Field(default_factory=list)

    @model_validator(mode="after")
    def _method_sections(self):
        for key, value in (self.model_extra or {}).items():
            if key not in BASELINES:
                raise ValueError(f"unknown key {key!r}: not a baseline of the registry ({', '.join(BASELINES)})")
            if not isinstance(value, dict):
                raise ValueError(f"{key} must be a mapping of that method's knobs")
        return self


class EvaluateParams(Section):
    methods: list[Literal[tuple(METHODS)]] = Field(min_length=1)
    fail_probs: list[Probability] = Field(min_length=1)
    episodes: PositiveInt = Field(description="per method x env x fail_prob x seed, run as one batch")
    device: str = "cpu"


class MiniGridSource(Section):
    id: str = Field(description="a MiniGrid DoorKey id, e.g. MiniGrid-DoorKey-8x8-v0")
    layouts: PositiveInt = Field(description="its grids of seeds 0..layouts-1")
    max_steps: PositiveInt = Field(description="episode step limit on these grids")
    split: str = Field("minigrid", pattern=r"^minigrid(_[0-9a-z]+)?$",
                       description="the split's name in the tables: minigrid (in the headline) or minigrid_<name>, "
                                   "e.g. minigrid_16x16 for another size beside it")


class DrawnSource(Section):
    folder: str = Field(description="a folder of layout files (*.txt), e.g. hand-drawn maps, and those of the "
                                    "folders in it")
    max_steps: PositiveInt = Field(description="episode step limit on these maps")


class GeneralisationParams(Section):
    """The unseen-layout experiment (README, "Unseen layouts"): learners that read the grid around the agent,
    trained on generated layouts, evaluated on them, on held-out ones and on MiniGrid's grids."""

    family: Literal[FAMILIES] = Field("keydoor", description="generated family (hnsdt.envs.generate)")
    train_layouts: PositiveInt = Field(description="training layouts: the family's seeds 0..N-1")
    heldout_layouts: int = Field(ge=0, description="held-out layouts: seeds 100000.. (never in training)")
    evaluated_train_layouts: int = Field(ge=0, description="the first this many training layouts are evaluated")
    validation_layouts: int = Field(0, ge=0, description="validation layouts: seeds 200000.., never in training or "
                                    "evaluation; each DT with a train.validation entry trains to the plateau of its "
                                    "steps to the exit on them (0: the paper protocol's train.validation)")
    validation_families: list[Literal[FAMILIES]] = Field(
        default_factory=list, description="validation_layouts of each of these families (empty: the training "
        "family's): one split of several shapes, on which training families can be compared")
    validation_starts: PositiveInt | None = Field(None, description="every learner that trains to a plateau on the "
                                                  "validation layouts walks from about this many start states "
                                                  "over them (None: train.validation.<method>.starts, a "
                                                  "baseline's own starts)")
    minigrid: list[MiniGridSource] = Field(default_factory=list, description="MiniGrid grids, zero-shot")
    drawn: DrawnSource | None = Field(None, description="a folder of layout files (maps of any shape), zero-shot")
    max_offset: PositiveInt = Field(7, description="a sub-goal target further than this many cells along an axis "
                                    "reads as this far (its direction kept): fixed, so no network depends on the "
                                    "maps it is evaluated on")
    max_steps: PositiveInt = Field(description="episode step limit on generated layouts")
    view_radius: PositiveInt = Field(2, description="the learners see (2r+1) x (2r+1) cells around the agent")
    conv_layers: int = Field(0, ge=0, description="the view encoder of the decision transformers and the LSTM / "
                             "GRU: this many 3x3 convolutions before the projection (0: the cell embeddings "
                             "flattened)")
    value_iterations: int = Field(0, ge=0, description="the decision transformers' view encoder: > 0 plans over "
                                  "the view towards the sub-goal's target with a value-iteration module of this "
                                  "many backups (0: none)")
    whole_map: bool = Field(False, description="the decision transformers read the whole map too and plan over "
                            "it towards the sub-goal's target with a learned planning module "
                            "(hnsdt.models.plan.MapPlanner), once per sub-goal segment")
    operators: Literal[OPERATOR_SETS] | None = Field(None, description="the operators our arm's planner hands "
                                                      "its methods here (None: planner.operators); the "
                                                      "paper's arm keeps planner.paper's")
    symmetries: Literal[1, 4, 8] = Field(1, description="the decision transformers, the LSTM and the GRU train on "
                                         "each episode, every epoch anew, on its map turned at random: 4 = a "
                                         "quarter turn, 8 = a turn and a mirror image (1: as collected)")
    episodes_per_layout: PositiveInt = Field(description="noisy-planner episodes per training layout and start "
                                             "(the layout's start and random starts)")
    epsilon: Probability = Field(0.1, description="the noisy planner's share of random actions")
    random_episodes_per_layout: int = Field(0, ge=0, description="random-exploration episodes per training layout "
                                            "(random starts): what the paper's arm learns from")
    methods: list[Literal[DT_METHODS]] = Field(default_factory=list, description="decision transformers (knobs: "
                                               "train, models.<family>)")
    baselines: list[Literal[BASELINES]] = Field(default_factory=list, description="the other learned methods "
                                                "(knobs: baselines.<method>); the symbolic one is the reference")
    seeds: list[int] = Field(min_length=1, description="training seeds of every learned method (evaluation "
                             "episodes are drawn per seed; the symbolic reference runs these)")
    method_seeds: dict[Literal[LEARNED], list[int]] = Field(
        default_factory=dict, description="per method, training seeds that replace `seeds` (a method not run "
        "here is ignored; a further experiment that sets `seeds` drops them)")
    episodes: PositiveInt = Field(description="evaluation episodes per method x seed x layout x fail_prob")
    budgets: dict[Literal[LEARNED], dict[str, Any]] = Field(
        default_factory=dict, description="per method, training knobs that replace the paper protocol's here "
        "(the fields of its training config, e.g. epochs, max_steps, env_steps)")

    @field_validator("methods", "baselines", "seeds")
    @classmethod
    def _unique(cls, value):
        if len(set(value)) != len(value):
            raise ValueError(f"must not repeat an entry, got {value}")
        return value

    @field_validator("method_seeds")
    @classmethod
    def _distinct_seeds(cls, value):
        for method, seeds in value.items():
            if not seeds or len(set(seeds)) != len(seeds):
                raise ValueError(f"{method}: must list distinct seeds, got {seeds}")
        return value

    @property
    def learned(self) -> list[str]:
        return [*self.methods, *self.baselines]

    def seeds_of(self, method: str) -> list[int]:
        """The training seeds of ``method``: its ``method_seeds`` entry, else ``seeds``."""
        return list(self.method_seeds.get(method, self.seeds))


class LogsParams(Section):
    episodes_per_cell: int = Field(1, ge=0, description="rerun + MCAP recordings per method x env x fail_prob "
                                   "(first seed)")


class ComputeParams(Section):
    executor: Literal[EXECUTORS] = Field("local", description="local = worker processes; ray = a Ray cluster")
    workers: int = Field(0, ge=0, description="local: runs at once (0 = one per core)")
    threads: PositiveInt = Field(1, description="torch CPU threads of each run; part of the bytes")


class MiniGridEnvParams(Section):
    id: str = Field(description="the gymnasium id of a MiniGrid key-door world (e.g. MiniGrid-DoorKey-8x8-v0), "
                    "stepped by MiniGrid itself")


class SeedRange(Section):
    first: int = Field(ge=0, description="the first of the seeds")
    count: PositiveInt = Field(description="how many seeds, from first on")

    @property
    def seeds(self) -> list[int]:
        return list(range(self.first, self.first + self.count))


class MiniGridCollectParams(Section):
    train_seeds: SeedRange = Field(description="MiniGrid's reset seeds of the training worlds (apart from test_seeds)")
    episodes_per_world: PositiveInt = Field(1, description="noisy symbolic-agent episodes per world and fail_prob")
    epsilon: Probability = Field(0.1, description="the share of random actions among the symbolic agent's")


class MiniGridModelParams(Section):
    context: PositiveInt = Field(16, description="h: the steps each step attends to (banded attention)")
    n_layers: PositiveInt = Field(3, description="transformer layers")
    n_heads: PositiveInt = Field(4, description="attention heads")
    d_model: PositiveInt = Field(128, description="token width")
    dropout: float = Field(0.1, ge=0, lt=1, description="dropout in training")
    cell_dim: PositiveInt = Field(16, description="each view cell's embedding before the 49 are projected")


class MiniGridOnlineParams(Section):
    """What every online learner on MiniGrid's worlds has (hnsdt.baselines.minigrid_copies)."""
    max_frames: PositiveInt = Field(250_000, description="the cap on env steps; it stops at its plateau before")
    num_envs: PositiveInt = Field(16, description="copies of the env stepped together")
    eval_every: PositiveInt = Field(50_000, description="frames between validation measurements")
    patience: PositiveInt = Field(4, description="measurements without fewer validation steps before stopping")


class MiniGridPPOParams(MiniGridOnlineParams):
    rollout_steps: PositiveInt = Field(128, description="steps of every copy per iteration")
    lr: float = Field(1e-3, gt=0, description="Adam's learning rate")
    batch_size: PositiveInt = Field(256, description="steps per minibatch")
    update_epochs: PositiveInt = Field(4, description="passes over each rollout")
    ent_coef: float = Field(0.01, ge=0, description="entropy bonus")


class MiniGridDQNParams(MiniGridOnlineParams):
    lr: float = Field(2.5e-4, gt=0, description="Adam's learning rate")
    buffer_size: PositiveInt = Field(10_000, description="replay capacity, in transitions")
    batch_size: PositiveInt = Field(128, description="replayed transitions per gradient step")
    learning_starts: PositiveInt = Field(10_000, description="frames of exploration before learning")
    train_every: PositiveInt = Field(10, description="frames per gradient step")
    target_period: PositiveInt = Field(50, description="gradient steps between target-network copies")
    exploration_fraction: float = Field(0.5, gt=0, le=1, description="of max_frames, over which epsilon decays")


class MiniGridOptionsParams(MiniGridOnlineParams):
    lr: float = Field(5e-4, gt=0, description="Adam's learning rate")
    n_options: PositiveInt = Field(8, description="the options")
    termination_reg: float = Field(0.01, ge=0, description="the margin that keeps options from ending every step")
    entropy_reg: float = Field(0.01, ge=0, description="the intra-option policies' entropy bonus")
    exploration_fraction: float = Field(0.5, gt=0, le=1, description="of max_frames, over which epsilon decays")


class MiniGridLearnParams(Section):
    methods: list[Literal[MINIGRID_LEARNERS]] = Field(
        min_length=1, description="the learners: the decision transformers and the RNNs on each world's dataset, "
                                  "the online learners (PPO, DQN, option-critic) in its worlds")
    seeds: list[int] = Field(min_length=1, description="training seeds, each evaluated on every test world")
    model: MiniGridModelParams = Field(default_factory=MiniGridModelParams)
    batch_size: PositiveInt = Field(1024, description="steps per gradient step (whole episodes)")
    lr: float = Field(1e-3, gt=0, description="Adam's learning rate")
    max_epochs: PositiveInt = Field(30, description="the cap on passes over the dataset")
    patience: PositiveInt = Field(3, description="epochs without a better validation measure before stopping")
    validation_seeds: SeedRange = Field(description="MiniGrid's reset seeds of the validation worlds, where the "
                                        "plateau is measured (apart from the training and test worlds)")
    validation_max_steps: PositiveInt = Field(100, description="a validation episode not done by then is a "
                                              "failure, counted as this many steps")
    target_return: float = Field(1.0, description="the pure DT's return-to-go at the start of an episode")
    ppo: MiniGridPPOParams = Field(default_factory=lambda: MiniGridPPOParams(),
                                   description="PPO's knobs (hnsdt.baselines.minigrid_ppo)")
    dqn: MiniGridDQNParams = Field(default_factory=lambda: MiniGridDQNParams(),
                                   description="DQN's knobs (hnsdt.baselines.minigrid_dqn)")
    options: MiniGridOptionsParams = Field(default_factory=lambda: MiniGridOptionsParams(),
                                           description="option-critic's knobs (hnsdt.baselines.minigrid_options)")


class MiniGridParams(Section):
    envs: dict[str, MiniGridEnvParams] = Field(min_length=1, description="MiniGrid's own worlds, one stage per "
                                               "name (minigrid_reference@<name>, outputs under minigrid/<name>)")
    test_seeds: SeedRange = Field(description="the worlds evaluated: MiniGrid's reset seeds, never trained on")
    fail_probs: list[Probability] = Field(min_length=1, description="the paper's action-failure probabilities")
    episodes: PositiveInt = Field(5, description="episodes of the BabyAI bot and of the symbolic agent per world "
                                  "and fail_prob, each with its own failure draws")
    collect: MiniGridCollectParams | None = Field(None, description="the learners' datasets, one per world "
                                                  "(minigrid_collect@<name>, minigrid/<name>/dataset)")
    learn: MiniGridLearnParams | None = Field(None, description="the decision transformers trained on those "
                                              "datasets and evaluated beside the references "
                                              "(minigrid_learn@<name>, minigrid/<name>/learned)")

    @model_validator(mode="after")
    def _apart(self):
        test = set(self.test_seeds.seeds)
        train = set(self.collect.train_seeds.seeds) if self.collect is not None else set()
        if train & test:
            raise ValueError("collect.train_seeds overlaps test_seeds: a world trained on would be evaluated")
        if self.learn is not None:
            if self.collect is None:
                raise ValueError("learn needs collect: the decision transformers train on its datasets")
            if set(self.learn.validation_seeds.seeds) & (train | test):
                raise ValueError("learn.validation_seeds overlaps collect.train_seeds or test_seeds: the plateau "
                                 "must be measured on worlds of its own")
        return self

    @field_validator("envs")
    @classmethod
    def _names(cls, value):
        for name in value:
            if not re.fullmatch(r"[a-z][a-z0-9_]*", name):  # (a DVC stage name and a folder name)
                raise ValueError(f"{name!r}: a world's name is lower-case letters, digits and _")
        return value


class TheoremsParams(Section):
    gamma: float = Field(gt=0, lt=1, description="discount in Theorem 1's bound")
    B: float = Field(ge=0, description="extra cost of one failed operator step")
    delta: float = Field(gt=0, lt=1, description="Theorem 2's confidence")
    vc_dimension: float | str = Field("parameters", description="Theorem 2's VC-dimension proxy: a number, or "
                                      "`parameters` (HNSDT's count)")

    @field_validator("vc_dimension")
    @classmethod
    def _vc(cls, value):
        if value != "parameters" and (isinstance(value, str) or value <= 0):
            raise ValueError(f"must be a positive number or 'parameters', got {value!r}")
        return value


class Params(Section):
    """The whole file, validated once (:func:`validate`); every stage takes this object. A section without
    defaults may be left out of a file that only some commands read (``hnsdt plan`` needs ``envs`` alone):
    :meth:`need` stops the command that needs it with "missing key <section>"."""

    _source: str = PrivateAttr("params")  # where it came from: every error names it
    _raw: dict = PrivateAttr(default_factory=dict)  # the mapping as written (the provenance digest hashes it)

    envs: dict[str, EnvParams] = Field(min_length=1)
    planner: PlannerParams = PlannerParams()
    collect: CollectParams | None = None
    models: dict[str, ModelParams] = Field(default_factory=dict)
    train: TrainParams | None = None
    baselines: BaselinesParams = BaselinesParams()
    evaluate: EvaluateParams | None = None
    logs: LogsParams = LogsParams()
    compute: ComputeParams = ComputeParams()
    theorems: TheoremsParams | None = None
    generalisation: GeneralisationParams | None = None
    minigrid: MiniGridParams | None = None
    unseen_experiments: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="further unseen-layout experiments: per name, the `generalisation` keys "
        "it changes (each one stage, unseen_experiment@<name>, outputs under generalisation/experiments/<name>; "
        "its decision transformers beside the symbolic reference, no baselines)")

    @field_validator("unseen_experiments")
    @classmethod
    def _experiments(cls, value, info):
        base = info.data.get("generalisation")
        if value and base is None:
            raise ValueError("needs the generalisation section (each experiment changes some of its keys)")
        for name, changes in value.items():
            if not re.fullmatch(r"[a-z][a-z0-9_]*", name):  # (a DVC stage name and a folder name)
                raise ValueError(f"{name!r}: an experiment's name is lower-case letters, digits and _")
            merged_experiment(base, name, changes)
        return value

    @property
    def source(self) -> str:
        return self._source

    @property
    def raw(self) -> dict:
        """The file's mapping as written, before defaults: what :func:`hnsdt.core.provenance.params_digest` hashes."""
        return self._raw

    def error(self, msg: str) -> ParamsError:
        """One line naming the params file: ``<source>: msg``."""
        return ParamsError(f"{self._source}: {msg}")

    def need(self, name: str):
        """A section that the running command needs (and a partial params file may lack)."""
        section = getattr(self, name)
        if section is None:
            raise self.error(f"missing key {name}")
        return section


SECTIONS = tuple(Params.model_fields)


def merged_experiment(base: GeneralisationParams, name: str, changes: dict) -> GeneralisationParams:
    """The section of the unseen-layout experiment ``name``: ``base`` with ``changes`` (its keys) in place, and no
    baselines — a further experiment runs its decision transformers beside the symbolic reference, so that its stage
    depends on their knobs alone (a baseline's knob never reruns it); a bad key or value is one line naming
    ``<name>.<key>``."""
    if changes.get("baselines"):
        raise ValueError(f"{name}.baselines: a further experiment runs decision transformers only (`methods`); "
                         "the baselines run in the generalisation section's experiment")
    try:
        dropped = {"method_seeds": {}} if "seeds" in changes else {}  # (its seeds are every method's)
        return GeneralisationParams.model_validate({**base.model_dump(), **dropped, **changes, "baselines": []})
    except ValidationError as e:
        err = e.errors()[0]
        key = ".".join(str(part) for part in (name, *err["loc"]))
        if err["type"] == "extra_forbidden":
            raise ValueError(f"{key}: not a generalisation key") from None
        raise ValueError(f"{key}: {err['msg'].removeprefix('Value error, ')}") from None


def validate(raw: Any, source: str = "params") -> Params:
    """The typed params, or a :class:`ParamsError` of one line naming ``source`` and the first offending key."""
    import copy

    try:
        params = Params.model_validate(raw)
    except ValidationError as e:
        err = e.errors()[0]
        key = ".".join(str(part) for part in err["loc"])
        if err["type"] == "extra_forbidden":
            raise ParamsError(f"{source}: unknown key {key}") from None
        if err["type"] == "missing":
            raise ParamsError(f"{source}: missing key {key}") from None
        message = err["msg"].removeprefix("Value error, ")
        got = "" if err["type"] == "value_error" else f", got {err['input']!r}"  # (its message says it)
        raise ParamsError(f"{source}: {key}: {message}{got}") from None
    params._source, params._raw = source, copy.deepcopy(raw)
    return params
