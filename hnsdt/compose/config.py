"""params.yaml -> the library's typed settings.

The schema of the file (every knob's type, range, default and meaning) is :mod:`hnsdt.compose.params`. This module
loads a params file and validates it there once (bad input stops with one line naming the file and the key):
:func:`load_params` returns the :class:`~hnsdt.compose.params.Params` model that every stage takes, and the functions
below turn its sections into the frozen settings each stage runs with (an :class:`EnvSpec`, the planner's
:class:`~hnsdt.agents.executor.ExecutorConfig`, :class:`TrainSettings`, :class:`BaselineSettings`,
:class:`EvaluateSettings`). Nothing below the command line reads a params mapping.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.core.methods import BASELINES, DT_METHODS, METHODS, PROPOSED
from hnsdt.implementations import code_of, resolve
from hnsdt.compose.params import SECTIONS, Params, ParamsError, config_schema, validate
from hnsdt.data.collect import POLICIES, Behaviour, CollectConfig
from hnsdt.envs import ENV_IDS, LayoutError, load_layout
from hnsdt.envs.layout import Layout

__all__ = ["ParamsError", "Params", "load_params", "EnvSpec", "env_spec", "executor_config", "method_executor",
           "collect_config", "layout_collect_config", "model_config", "TrainSettings", "train_settings",
           "BaselineSettings", "baseline_settings", "typed_config", "compute_settings", "EvaluateSettings", "evaluate_settings"]


def load_params(path: str | Path = "params.yaml", overrides=()) -> Params:
    """The params file, validated whole before any work starts. ``overrides``: ``"dotted.key=value"`` strings (the
    value read as YAML) applied first, as ``dvc exp run -S`` would (benchmarks' ``--set``)."""
    path = Path(path)
    if not path.is_file():
        raise ParamsError(f"{path}: no such params file")
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ParamsError(f"{path}: not valid YAML{where}") from None
    if not isinstance(raw, dict):
        raise ParamsError(f"{path}: expected a mapping of sections at the top level")
    for override in overrides:
        key, sep, value = override.partition("=")
        *parents, last = key.split(".")
        node = raw
        for part in parents:
            node = node.get(part) if isinstance(node, dict) else None
        if not sep or not isinstance(node, dict):
            raise ParamsError(f"{path}: cannot set {override!r}: expected KEY=VALUE with KEY a dotted path into "
                              "a mapping of params.yaml")
        node[last] = yaml.safe_load(value)
    unknown = sorted(set(raw) - set(SECTIONS))
    if unknown:
        raise ParamsError(f"{path}: unknown section(s) {unknown}; params.yaml has {', '.join(SECTIONS)}")
    return validate(raw, str(path))


@dataclass(frozen=True)
class EnvSpec:
    """One environment to run on: a key of ``envs``, or a generated family of the unseen-layout experiment."""

    name: str
    id: str  # gymnasium id
    layout: Layout | None  # None: many layouts (a generated family)
    max_steps: int


def env_spec(params: Params, name: str) -> EnvSpec:
    """``envs.<name>`` with its layout loaded."""
    if name not in params.envs:
        raise params.error(f"unknown env {name!r}; params defines {', '.join(params.envs) or 'none'}")
    env = params.envs[name]
    if env.id not in ENV_IDS:
        raise params.error(f"envs.{name}.id {env.id!r} is not a registered id ({', '.join(ENV_IDS)})")
    try:
        layout = load_layout(env.layout)
    except LayoutError as e:
        raise params.error(f"envs.{name}.layout: {e}") from None
    return EnvSpec(name, env.id, layout, env.max_steps)


def executor_config(params: Params, arm: str = "ours") -> ExecutorConfig:
    """The planner and executor settings of an arm: ``planner`` (ours) or ``planner.paper`` over it (the
    paper's arm; its mode and operators default to the paper's BFS over Move operators)."""
    planner = params.planner
    mode, operators = planner.mode, planner.operators
    factor, minimum = planner.allowance_factor, planner.allowance_min
    if arm == "paper":
        paper = planner.paper
        mode, operators = paper.mode, paper.operators
        factor = paper.allowance_factor if paper.allowance_factor is not None else factor
        minimum = paper.allowance_min if paper.allowance_min is not None else minimum
    return ExecutorConfig(plan_mode=mode, operators=operators, allowance_factor=float(factor),
                          allowance_min=minimum)


def method_executor(params: Params, method: str) -> ExecutorConfig:
    """The executor settings a plan-following method runs with (its arm's planner)."""
    return executor_config(params, METHODS[method].arm)


def layout_executor(params: Params, method: str) -> ExecutorConfig:
    """The executor settings of a method in the unseen-layout experiment: its arm's, our arm's operators replaced
    by ``generalisation.operators`` where set (the labels it learns from and the sub-goals it is given)."""
    executor, operators = method_executor(params, method), params.need("generalisation").operators
    if operators is None or METHODS[method].arm != "ours":
        return executor
    return replace(executor, operators=operators)


def unseen_experiment(params: Params, name: str | None) -> Params:
    """``params`` as the unseen-layout experiment ``name`` of ``unseen_experiments`` sees them: its changes in
    the ``generalisation`` section (None: the section as it is), so every stage of that experiment runs on it."""
    from hnsdt.compose.params import merged_experiment

    if name is None:
        return params
    if name not in params.unseen_experiments:
        raise params.error(f"unseen_experiments: no experiment {name!r}; expected one of "
                           f"{sorted(params.unseen_experiments)}")
    section = merged_experiment(params.need("generalisation"), name, params.unseen_experiments[name])
    derived = params.model_copy(update={"generalisation": section})
    derived._source, derived._raw = f"{params.source} (unseen_experiments.{name})", params.raw
    return derived


def collect_config(params: Params, name: str) -> CollectConfig:
    env = env_spec(params, name)
    collect = params.need("collect")
    behaviours = [Behaviour(b.policy, b.episodes, b.start, float(b.epsilon)) for b in collect.behaviours]
    return CollectConfig(
        env_id=env.id, layout=env.layout, max_steps=env.max_steps,
        fail_probs=[float(f) for f in collect.fail_probs], behaviours=behaviours, seed=collect.seed, fps=collect.fps,
        executor=executor_config(params), license=collect.license, render=collect.render,
    )


def layout_collect_config(params: Params) -> CollectConfig:
    """The unseen-layout experiment's collection on its training layouts (``layout`` is left None):
    ``collect``'s seed, fps, licence and fail_probs, the noisy planner of ``planner``,
    ``generalisation.episodes_per_layout`` per start, and ``generalisation.random_episodes_per_layout`` random walks
    (the paper's arm's data)."""
    g, collect = params.need("generalisation"), params.need("collect")
    behaviours = [Behaviour("noisy_planner", g.episodes_per_layout, start, g.epsilon) for start in ("layout", "random")]
    if g.random_episodes_per_layout:
        behaviours.append(Behaviour("random", g.random_episodes_per_layout, "random"))
    return CollectConfig(env_id=f"hnsdt/generated-{g.family}", layout=None, max_steps=g.max_steps,
                         fail_probs=[float(f) for f in collect.fail_probs], behaviours=behaviours, seed=collect.seed,
                         fps=collect.fps, executor=executor_config(params), license=collect.license)


def model_config(params: Params, env_name: str, method: str):
    """The decision transformer of ``models.<env>`` for one method (its conditioning and formulation)."""
    from hnsdt.models.dt import DTConfig

    env = env_spec(params, env_name)
    if env_name not in params.models:
        raise params.error(f"missing key models.{env_name} (the decision transformers' size on that env)")
    sizes = params.models[env_name]
    try:
        return DTConfig(condition=METHODS[method].condition, formulation=train_settings(params).formulation[method],
                        n_flags=env.layout.n_flags, grid_h=env.layout.shape[0],
                        grid_w=env.layout.shape[1], dropout=params.need("train").dropout,
                        max_timestep=env.max_steps,
                        tokens=sizes.tokens, n_layers=sizes.n_layers, n_heads=sizes.n_heads,
                        d_model=sizes.d_model, context=sizes.context)
    except ValueError as e:
        raise params.error(f"models.{env_name}: {e}") from None


@dataclass(frozen=True)
class TrainSettings:
    """The decision transformers' training (``train``)."""

    envs: tuple[str, ...]
    methods: tuple[str, ...]
    seeds: tuple[int, ...]
    config: Any  # the shared hnsdt.models.train.TrainConfig
    behaviours: dict[str, tuple[str, ...]]  # per method: the collected episodes it learns from (empty = all)
    loss: dict[str, str]  # per method: the window steps its loss counts
    formulation: dict[str, str]  # per method: its examples, windows or whole episodes (hnsdt.models.dt)
    budget: dict[str, dict]  # per method with a validation: its TrainConfig fields (validation, patience, epochs)
    measure: dict[str, tuple[str, int]]  # per method with a validation: its measure and (steps) start states

    def method_config(self, method: str, seed: int):
        """The training config of one method and seed."""
        return replace(self.config, seed=seed, behaviours=self.behaviours[method], loss=self.loss[method],
                       **self.budget.get(method, {}))


def train_settings(params: Params) -> TrainSettings:
    from hnsdt.models.windows import FORMULATIONS, LOSS_STEPS
    from hnsdt.models.train import TrainConfig

    train = params.need("train")
    for e in train.envs:
        env_spec(params, e)
    return TrainSettings(
        envs=tuple(train.envs), methods=tuple(train.methods), seeds=tuple(train.seeds),
        config=TrainConfig(epochs=train.epochs, batch_size=train.batch_size, lr=float(train.lr),
                           max_steps=train.max_steps, device=train.device),
        behaviours={m: tuple(train.behaviours.get(m, [])) for m in DT_METHODS},
        loss={m: train.loss.get(m, LOSS_STEPS[0]) for m in DT_METHODS},
        formulation={m: train.formulation.get(m, FORMULATIONS[0]) for m in DT_METHODS},
        budget={m: {"validation": float(v.share), "patience": v.patience, "epochs": v.max_epochs}
                for m, v in train.validation.items()},
        measure={m: (v.measure, v.starts) for m, v in train.validation.items()})


def typed_config(params: Params, key: str, cls, section: dict, **fixed):
    """A config dataclass (``cls``) from the knobs of ``section`` that name its fields, validated by its pydantic
    schema (:func:`~hnsdt.compose.params.config_schema`), and the ``fixed`` fields the pipeline sets itself;
    ``key`` names the section in errors (one line: the knob, the type it must have, the value it got)."""
    from pydantic import ValidationError

    names = {f.name for f in dataclasses.fields(cls)}
    given = {k: v for k, v in section.items() if k in names and k not in fixed}
    try:
        checked = config_schema(cls).model_validate(given)
        return cls(**{k: getattr(checked, k) for k in given}, **fixed)
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(part) for part in (key, *err["loc"]))
        kind = err["type"].removesuffix("_type")
        if kind in _TYPE_NAMES:  # a value of the wrong type
            raise params.error(f"{where} must be {_TYPE_NAMES[kind]}, got {err['input']!r}") from None
        raise params.error(f"{where}: {err['msg']}, got {err['input']!r}") from None
    except (TypeError, ValueError) as e:  # the dataclass's own checks (__post_init__)
        raise params.error(f"{key}: {e}") from None


_TYPE_NAMES = {"int": "int", "float": "float", "bool": "bool", "string": "str", "tuple": "a list"}  # pydantic's names


@dataclass(frozen=True)
class BaselineSettings:
    """One baseline on one env and seed: its network config, training config and evaluation exploration."""

    method: str
    env: EnvSpec
    model: Any  # the registry entry's network config
    train: Any  # the registry entry's training config
    eval_epsilon: float = 0.0  # online methods: the evaluation's exploration (0 = greedy)


def baseline_settings(params: Params, method: str, env: str | EnvSpec, seed: int,
                      env_steps: tuple[str, object] | None = None) -> BaselineSettings:
    """The knobs of ``baselines.<method>`` on one env and seed; unknown keys and wrongly typed values are
    errors. ``env``: a key of ``envs``, or the spec of a generated family (the unseen-layout experiment: a
    per-env budget is then looked up under the family's name, unless ``env_steps`` — the key that sets a
    budget of its own, and its value — replaces it)."""
    from hnsdt.models.train import pick_device

    if method not in BASELINES:
        raise params.error(f"{method!r} is not a baseline; expected one of {list(BASELINES)}")
    key = f"baselines.{method}"
    section = (params.baselines.model_extra or {}).get(method)
    if section is None:
        raise params.error(f"missing key {key} (the knobs of {method})")
    section = dict(section)
    env = env_spec(params, env) if isinstance(env, str) else env
    lay = env.layout
    device = str(pick_device(params.need("train").device))
    grid = {"n_flags": lay.n_flags, "grid_h": lay.shape[0], "grid_w": lay.shape[1]}
    entry = METHODS[method]
    net_cls, train_cls = resolve(code_of(entry.name).network).config_class, resolve(code_of(entry.name).config)
    net_fixed = {**entry.fixed, **grid}
    train_fixed = {"seed": seed, "device": device}
    train_fields = {f.name for f in dataclasses.fields(train_cls)}
    if "behaviours" in train_fields:  # offline: the collection behaviours it learns from
        behaviours = section.get("behaviours", [])
        if not isinstance(behaviours, list) or not set(behaviours) <= set(POLICIES):
            raise params.error(f"{key}.behaviours must be a list drawn from {POLICIES}, got {behaviours!r}")
        train_fixed["behaviours"] = tuple(behaviours)
    if "env_steps" in train_fields:  # online: a budget of environment steps, one number or one per env
        where, budget = (f"{key}.env_steps", section.get("env_steps")) if env_steps is None else env_steps
        if env_steps is None and isinstance(budget, dict):
            budget = budget.get(env.name)
        if not isinstance(budget, int) or isinstance(budget, bool) or budget < 1:
            raise params.error(f"{where} must be a positive integer, got {env_steps[1]!r}" if env_steps else
                               f"{where} must be a positive integer or a mapping env -> one "
                               f"(missing or bad for {env.name!r}: {section.get('env_steps')!r})")
        train_fixed["env_steps"] = budget
    if "fail_probs" in train_fields and "fail_probs" in section:
        train_fixed["fail_probs"] = tuple(_fail_probs(params, f"{key}.fail_probs", section["fail_probs"]))
    extra = {}
    if entry.training == "online":  # the evaluation's exploration (0 = greedy)
        extra = {"eval_epsilon": _eval_epsilon(params, method)}
    known = ({f.name for f in dataclasses.fields(net_cls)} | train_fields | set(extra)) - set(net_fixed) - {
        "seed", "device"}
    unknown = sorted(set(section) - known)
    if unknown:
        raise params.error(f"{key}: unknown keys {unknown}; expected some of {sorted(known)}")
    return BaselineSettings(method, env, typed_config(params, key, net_cls, section, **net_fixed),
                            typed_config(params, key, train_cls, section, **train_fixed), **extra)


def _fail_probs(params: Params, key: str, values) -> list[float]:
    if not isinstance(values, list) or not values or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 1 for v in values):
        raise params.error(f"{key} must be a non-empty list of numbers in [0, 1], got {values!r}")
    return [float(v) for v in values]


def _eval_epsilon(params: Params, method: str) -> float:
    eps = (params.baselines.model_extra or {}).get(method, {}).get("eval_epsilon", 0.0)
    if not isinstance(eps, (int, float)) or isinstance(eps, bool) or not 0 <= eps <= 1:
        raise params.error(f"baselines.{method}.eval_epsilon must be a number in [0, 1], got {eps!r}")
    return float(eps)


def eval_epsilon(params: Params, method: str) -> float:
    """The evaluation's exploration of a method: ``baselines.<method>.eval_epsilon`` (online), else 0."""
    return _eval_epsilon(params, method) if METHODS[method].training == "online" else 0.0


def compute_settings(params: Params, executor: str | None = None, workers: int | None = None):
    """Where runs execute (``compute``), with command-line overrides; see :mod:`hnsdt.core.compute`."""
    from hnsdt.core.compute import Compute

    compute = params.compute
    try:
        return Compute(executor if executor is not None else compute.executor,
                       workers if workers is not None else compute.workers, compute.threads)
    except ValueError as e:
        raise params.error(str(e)) from None


@dataclass(frozen=True)
class EvaluateSettings:
    """The paper protocol's evaluation: every method × env × fail_prob × seed."""

    methods: tuple[str, ...]
    envs: tuple[str, ...]
    seeds: tuple[int, ...]
    fail_probs: tuple[float, ...]
    episodes: int  # per cell, run as one batch
    device: str
    log_episodes: int  # recorded episodes per cell (first seed)
    train_behaviours: tuple[str, ...]  # HNSDT's training episodes (Theorem 2's segment counts)
    eval_epsilon: dict[str, float]  # per online method


def evaluate_settings(params: Params) -> EvaluateSettings:
    evaluate, train = params.need("evaluate"), params.need("train")
    if params.logs.episodes_per_cell > evaluate.episodes:
        raise params.error(f"logs.episodes_per_cell must be in 0..evaluate.episodes, got "
                           f"{params.logs.episodes_per_cell}")
    methods = tuple(evaluate.methods)
    trained = set(train.methods) | set(params.baselines.offline) | set(params.baselines.online)
    untrained = [m for m in methods if METHODS[m].training != "none" and m not in trained]
    if untrained:
        raise params.error(f"evaluate.methods: {untrained} are never trained (add them to train.methods, "
                           "baselines.offline or baselines.online)")
    return EvaluateSettings(
        methods=methods, envs=tuple(train.envs), seeds=tuple(train.seeds),
        fail_probs=tuple(float(f) for f in evaluate.fail_probs), episodes=evaluate.episodes,
        device=evaluate.device, log_episodes=params.logs.episodes_per_cell,
        train_behaviours=tuple(train.behaviours.get(PROPOSED, [])),
        eval_epsilon={m: _eval_epsilon(params, m) for m in methods if METHODS[m].training == "online"})
