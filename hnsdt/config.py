"""params.yaml -> the library's configs.

The schema of the file (every knob's type, range, default and meaning) is :mod:`hnsdt.params`; this module
loads a params file, validates it there (bad input stops with one line naming the key) and builds the typed
configs each stage runs with.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.data.collect import POLICIES, Behaviour, CollectConfig
from hnsdt.envs import ENV_IDS, LayoutError, load_layout
from hnsdt.methods import BASELINES, DT_METHODS, METHODS, PROPOSED, resolve
from hnsdt.params import SECTIONS, Params, validate


class ParamsError(ValueError):
    """A malformed params file; the message names the file and the key."""


def load_params(path: str | Path = "params.yaml") -> dict[str, Any]:
    """The params file as a mapping (validated; ``_path`` records where it came from)."""
    path = Path(path)
    if not path.is_file():
        raise ParamsError(f"{path}: no such params file")
    try:
        params = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ParamsError(f"{path}: not valid YAML{where}") from None
    if not isinstance(params, dict):
        raise ParamsError(f"{path}: expected a mapping of sections at the top level")
    unknown = sorted(set(params) - set(SECTIONS))
    if unknown:
        raise ParamsError(f"{path}: unknown section(s) {unknown}; params.yaml has {', '.join(SECTIONS)}")
    params["_path"] = str(path)
    typed(params)  # every knob checked before any work starts
    return params


def typed(params: dict) -> Params:
    """The params as typed sections (:class:`hnsdt.params.Params`); keys starting with ``_`` are bookkeeping."""
    try:
        return validate({k: v for k, v in params.items() if not k.startswith("_")}, _source(params))
    except ValueError as e:
        raise ParamsError(str(e)) from None


def _section(params: dict, name: str, spec: Params | None = None):
    """A section that the running command needs (and a partial params file may lack); ``spec``: the params
    already validated by the caller."""
    section = getattr(spec or typed(params), name)
    if section is None:
        raise _fail(params, f"missing key {name}")
    return section


def _source(params: dict) -> str:
    return params.get("_path", "params")


def _fail(params: dict, msg: str) -> ParamsError:
    return ParamsError(f"{_source(params)}: {msg}")


def env_settings(params: dict, name: str) -> dict:
    """``name``, gymnasium ``id``, the loaded ``layout`` and ``max_steps`` of one env of ``envs``."""
    envs = typed(params).envs
    if name not in envs:
        raise _fail(params, f"unknown env {name!r}; params defines {', '.join(envs) or 'none'}")
    env = envs[name]
    if env.id not in ENV_IDS:
        raise _fail(params, f"envs.{name}.id {env.id!r} is not a registered id ({', '.join(ENV_IDS)})")
    try:
        layout = load_layout(env.layout)
    except LayoutError as e:
        raise _fail(params, f"envs.{name}.layout: {e}") from None
    return {"name": name, "id": env.id, "layout": layout, "max_steps": env.max_steps}


def executor_config(params: dict, arm: str = "ours") -> ExecutorConfig:
    """The planner and executor settings of an arm: ``planner`` (ours) or ``planner.paper`` over it (the
    paper's arm; its mode and operators default to the paper's BFS over Move operators)."""
    planner = typed(params).planner
    mode, operators = planner.mode, planner.operators
    factor, minimum = planner.allowance_factor, planner.allowance_min
    if arm == "paper":
        paper = planner.paper
        mode, operators = paper.mode, paper.operators
        factor = paper.allowance_factor if paper.allowance_factor is not None else factor
        minimum = paper.allowance_min if paper.allowance_min is not None else minimum
    return ExecutorConfig(plan_mode=mode, operators=operators, allowance_factor=float(factor),
                          allowance_min=minimum)


def method_executor(params: dict, method: str) -> ExecutorConfig:
    """The executor settings a plan-following method runs with (its arm's planner)."""
    return executor_config(params, METHODS[method].arm)


def fail_probs(params: dict, key: str, values) -> list[float]:
    if not isinstance(values, list) or not values or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 1 for v in values):
        raise _fail(params, f"{key} must be a non-empty list of numbers in [0, 1], got {values!r}")
    return [float(v) for v in values]


def collect_config(params: dict, name: str) -> CollectConfig:
    env = env_settings(params, name)
    collect = _section(params, "collect")
    behaviours = [Behaviour(b.policy, b.episodes, b.start, float(b.epsilon)) for b in collect.behaviours]
    return CollectConfig(
        env_id=env["id"], layout=env["layout"], max_steps=env["max_steps"],
        fail_probs=[float(f) for f in collect.fail_probs], behaviours=behaviours, seed=collect.seed, fps=collect.fps,
        executor=executor_config(params), license=collect.license, render=collect.render,
    )


def model_config(params: dict, env_name: str, condition: str):
    """The decision transformer of ``models.<env>`` for one conditioning."""
    from hnsdt.models.dt import DTConfig

    env = env_settings(params, env_name)
    spec = typed(params)
    if env_name not in spec.models:
        raise _fail(params, f"missing key models.{env_name} (the decision transformers' size on that env)")
    sizes = spec.models[env_name]
    try:
        return DTConfig(condition=condition, n_flags=env["layout"].n_flags, grid_h=env["layout"].shape[0],
                        grid_w=env["layout"].shape[1], dropout=_section(params, "train").dropout,
                        max_timestep=env["max_steps"],
                        tokens=sizes.tokens, n_layers=sizes.n_layers, n_heads=sizes.n_heads,
                        d_model=sizes.d_model, context=sizes.context)
    except ValueError as e:
        raise _fail(params, f"models.{env_name}: {e}") from None


def train_settings(params: dict) -> dict:
    """The decision transformers' training (``train``): envs, methods, seeds, the shared ``TrainConfig`` and
    each method's behaviours and loss."""
    from hnsdt.data.windows import LOSS_STEPS
    from hnsdt.models.train import TrainConfig

    train = _section(params, "train")
    for e in train.envs:
        env_settings(params, e)
    return {
        "envs": list(train.envs), "methods": list(train.methods), "seeds": list(train.seeds),
        "config": TrainConfig(epochs=train.epochs, batch_size=train.batch_size, lr=float(train.lr),
                              max_steps=train.max_steps, device=train.device),
        "behaviours": {m: tuple(train.behaviours.get(m, [])) for m in DT_METHODS},
        "loss": {m: train.loss.get(m, LOSS_STEPS[0]) for m in DT_METHODS},
    }


def baseline_lists(params: dict) -> dict[str, list[str]]:
    """The baselines to train: ``baselines.offline`` (on the dataset) and ``baselines.online``."""
    baselines = typed(params).baselines
    return {"offline": list(baselines.offline), "online": list(baselines.online)}


def _fill(params: dict, key: str, cls, section: dict, **fixed):
    """A dataclass from the entries of ``section`` that name its fields, each checked against the type of
    the field's default (tuples come from lists)."""
    import dataclasses

    values = {}
    for f in dataclasses.fields(cls):
        if f.name not in section or f.name in fixed:
            continue
        v, default = section[f.name], f.default
        if isinstance(default, tuple):
            if not isinstance(v, list):
                raise _fail(params, f"{key}.{f.name} must be a list, got {v!r}")
            v = tuple(v)
        elif isinstance(default, bool) or isinstance(v, bool):
            if not isinstance(v, bool) or not isinstance(default, bool):
                raise _fail(params, f"{key}.{f.name} must be {type(default).__name__}, got {v!r}")
        elif isinstance(default, float) and isinstance(v, (int, float)):
            v = float(v)
        elif not isinstance(v, type(default)):
            raise _fail(params, f"{key}.{f.name} must be {type(default).__name__}, got {v!r}")
        values[f.name] = v
    try:
        return cls(**values, **fixed)
    except (TypeError, ValueError) as e:
        raise _fail(params, f"{key}: {e}") from None


def baseline_settings(params: dict, method: str, env_name: str, seed: int, env: dict | None = None) -> dict:
    """Network config, training config and evaluation knobs of one baseline on one env and seed, from
    ``baselines.<method>``; unknown keys and wrongly typed values are errors. ``env`` (layout, max_steps)
    replaces ``envs.<env_name>`` (the generalisation experiment: ``env_name`` is then its family)."""
    import dataclasses

    from hnsdt.models.train import pick_device

    if method not in BASELINES:
        raise _fail(params, f"{method!r} is not a baseline; expected one of {list(BASELINES)}")
    key = f"baselines.{method}"
    spec = typed(params)
    section = (spec.baselines.model_extra or {}).get(method)
    if section is None:
        raise _fail(params, f"missing key {key} (the knobs of {method})")
    section = dict(section)
    env = env or env_settings(params, env_name)
    lay = env["layout"]
    device = str(pick_device(_section(params, "train", spec).device))
    grid = {"n_flags": lay.n_flags, "grid_h": lay.shape[0], "grid_w": lay.shape[1]}
    entry = METHODS[method]
    net_cls, train_cls = resolve(entry.network).config_class, resolve(entry.config)
    net_fixed = {**entry.fixed, **grid}
    train_fixed = {"seed": seed, "device": device}
    train_fields = {f.name for f in dataclasses.fields(train_cls)}
    if "behaviours" in train_fields:  # offline: the collection behaviours it learns from
        behaviours = section.get("behaviours", [])
        if not isinstance(behaviours, list) or not set(behaviours) <= set(POLICIES):
            raise _fail(params, f"{key}.behaviours must be a list drawn from {POLICIES}, got {behaviours!r}")
        train_fixed["behaviours"] = tuple(behaviours)
    if "env_steps" in train_fields:  # online: a budget of environment steps, one number or one per env
        budget = section.get("env_steps")
        if isinstance(budget, dict):
            budget = budget.get(env_name)
        if not isinstance(budget, int) or isinstance(budget, bool) or budget < 1:
            raise _fail(params, f"{key}.env_steps must be a positive integer or a mapping env -> one "
                        f"(missing or bad for {env_name!r}: {section.get('env_steps')!r})")
        train_fixed["env_steps"] = budget
    if "fail_probs" in train_fields and "fail_probs" in section:
        train_fixed["fail_probs"] = tuple(fail_probs(params, f"{key}.fail_probs", section["fail_probs"]))
    extra = {}
    if entry.training == "online":  # the evaluation's exploration (0 = greedy)
        extra = {"eval_epsilon": baseline_eval_epsilon(params, method, spec)}
    known = ({f.name for f in dataclasses.fields(net_cls)} | train_fields | set(extra)) - set(net_fixed) - {
        "seed", "device"}
    unknown = sorted(set(section) - known)
    if unknown:
        raise _fail(params, f"{key}: unknown keys {unknown}; expected some of {sorted(known)}")
    return {"method": method, "env": env, "model": _fill(params, key, net_cls, section, **net_fixed),
            "train": _fill(params, key, train_cls, section, **train_fixed), **extra}


def compute_settings(params: dict, executor: str | None = None, workers: int | None = None):
    """Where runs execute (``compute``), with command-line overrides; see :mod:`hnsdt.executor`."""
    from hnsdt.executor import Compute

    compute = typed(params).compute
    try:
        return Compute(executor if executor is not None else compute.executor,
                       workers if workers is not None else compute.workers, compute.threads)
    except ValueError as e:
        raise _fail(params, str(e)) from None


def evaluate_settings(params: dict) -> dict:
    spec = typed(params)
    evaluate, train = _section(params, "evaluate", spec), _section(params, "train", spec)
    if spec.logs.episodes_per_cell > evaluate.episodes:
        raise _fail(params, f"logs.episodes_per_cell must be in 0..evaluate.episodes, got "
                    f"{spec.logs.episodes_per_cell}")
    methods = list(evaluate.methods)
    trained = set(train.methods) | set(spec.baselines.offline) | set(spec.baselines.online)
    untrained = [m for m in methods if METHODS[m].training != "none" and m not in trained]
    if untrained:
        raise _fail(params, f"evaluate.methods: {untrained} are never trained (add them to train.methods, "
                    "baselines.offline or baselines.online)")
    return {
        "methods": methods, "envs": list(train.envs), "seeds": list(train.seeds),
        "fail_probs": [float(f) for f in evaluate.fail_probs], "episodes": evaluate.episodes,
        "device": evaluate.device, "log_episodes": spec.logs.episodes_per_cell,
        "train_behaviours": tuple(train.behaviours.get(PROPOSED, [])),
        "eval_epsilon": {m: baseline_eval_epsilon(params, m, spec) for m in methods
                         if METHODS[m].training == "online"},
    }


def baseline_eval_epsilon(params: dict, method: str, spec: Params | None = None) -> float:
    eps = ((spec or typed(params)).baselines.model_extra or {}).get(method, {}).get("eval_epsilon", 0.0)
    if not isinstance(eps, (int, float)) or isinstance(eps, bool) or not 0 <= eps <= 1:
        raise _fail(params, f"baselines.{method}.eval_epsilon must be a number in [0, 1], got {eps!r}")
    return float(eps)


def theorem_settings(params: dict) -> dict:
    t = _section(params, "theorems")
    return {"gamma": t.gamma, "B": t.B, "delta": t.delta, "vc_dimension": t.vc_dimension}
