"""params.yaml: the one place for knobs. Loaded and checked here so a bad value fails with one clear line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.data.collect import POLICIES, Behaviour, CollectConfig
from hnsdt.envs import ENV_IDS, LayoutError, load_layout
from hnsdt.symbolic.operators import OPERATOR_SETS
from hnsdt.symbolic.planner import PLAN_MODES
from hnsdt.methods import DT_METHODS, METHODS, OFFLINE_BASELINES, ONLINE_BASELINES

LEARNED_METHODS = DT_METHODS  # the decision transformers, configured under `train`
EVAL_METHODS = tuple(METHODS)


SECTIONS = ("envs", "planner", "collect", "models", "train", "baselines", "evaluate", "logs", "theorems", "compute")


class ParamsError(ValueError):
    """A malformed params file; the message names the file and the key."""


def load_params(path: str | Path = "params.yaml") -> dict[str, Any]:
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
    return params


def _get(params: dict, dotted: str, kind: type | tuple, default: Any = ...) -> Any:
    node: Any = params
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            if default is not ...:
                return default
            raise ParamsError(f"{params.get('_path', 'params')}: missing key {dotted}")
        node = node[part]
    if kind is float and isinstance(node, int) and not isinstance(node, bool):
        node = float(node)
    if not isinstance(node, kind) or (isinstance(node, bool) and kind in (int, float)):
        names = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
        raise ParamsError(f"{params.get('_path', 'params')}: {dotted} must be {names}, got {node!r}")
    return node


def _fail(params: dict, msg: str) -> ParamsError:
    return ParamsError(f"{params.get('_path', 'params')}: {msg}")


def env_names(params: dict) -> list[str]:
    return list(_get(params, "envs", dict))


def env_settings(params: dict, name: str) -> dict:
    envs = _get(params, "envs", dict)
    if name not in envs:
        raise _fail(params, f"unknown env {name!r}; params defines {', '.join(envs) or 'none'}")
    env_id = _get(params, f"envs.{name}.id", str)
    if env_id not in ENV_IDS:
        raise _fail(params, f"envs.{name}.id {env_id!r} is not a registered id ({', '.join(ENV_IDS)})")
    layout_spec = _get(params, f"envs.{name}.layout", str)
    try:
        layout = load_layout(layout_spec)
    except LayoutError as e:
        raise _fail(params, f"envs.{name}.layout: {e}") from None
    max_steps = _get(params, f"envs.{name}.max_steps", int)
    if max_steps < 1:
        raise _fail(params, f"envs.{name}.max_steps must be >= 1, got {max_steps}")
    return {"name": name, "id": env_id, "layout": layout, "max_steps": max_steps}


PAPER_PARAMS = {"mode": "bfs", "operators": "move"}  # the paper's arm (Appendix B) unless planner.paper says else


def executor_config(params: dict, arm: str = "ours") -> ExecutorConfig:
    """The planner and executor settings of an arm: ``planner`` (ours) or ``planner.paper`` over it (the
    paper's arm; its mode and operators default to the paper's BFS over Move operators)."""
    section = dict(_get(params, "planner", dict, {}))
    paper = section.pop("paper", {})
    known = {"mode", "operators", "allowance_factor", "allowance_min"}
    for key, values in (("planner", section), ("planner.paper", paper)):
        if not isinstance(values, dict):
            raise _fail(params, f"{key} must be a mapping, got {values!r}")
        unknown = sorted(set(values) - known)
        if unknown:
            raise _fail(params, f"{key}: unknown keys {unknown}; expected some of {sorted(known)}")
    if arm == "paper":
        section = section | PAPER_PARAMS | paper
        prefix = "planner.paper"
    else:
        prefix = "planner"
    mode, operators = section.get("mode", "cost"), section.get("operators", "goto")
    if mode not in PLAN_MODES:
        raise _fail(params, f"{prefix}.mode must be one of {PLAN_MODES}, got {mode!r}")
    if operators not in OPERATOR_SETS:
        raise _fail(params, f"{prefix}.operators must be one of {OPERATOR_SETS}, got {operators!r}")
    factor, minimum = section.get("allowance_factor", 3.0), section.get("allowance_min", 6)
    if (not isinstance(factor, (int, float)) or isinstance(factor, bool) or factor <= 0
            or not isinstance(minimum, int) or isinstance(minimum, bool) or minimum < 1):
        raise _fail(params, f"{prefix}.allowance_factor must be a number > 0 and {prefix}.allowance_min an "
                    f"integer >= 1, got {factor!r} and {minimum!r}")
    return ExecutorConfig(plan_mode=mode, operators=operators, allowance_factor=float(factor),
                          allowance_min=minimum)


def method_executor(params: dict, method: str) -> ExecutorConfig:
    """The executor settings a plan-following method runs with (its arm's planner)."""
    return executor_config(params, METHODS[method].arm)


def fail_probs(params: dict, key: str) -> list[float]:
    values = _get(params, key, list)
    if not values or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 1
                             for v in values):
        raise _fail(params, f"{key} must be a non-empty list of numbers in [0, 1], got {values!r}")
    return [float(v) for v in values]


def collect_config(params: dict, name: str) -> CollectConfig:
    env = env_settings(params, name)
    behaviours = []
    for i, b in enumerate(_get(params, "collect.behaviours", list)):
        if not isinstance(b, dict):
            raise _fail(params, f"collect.behaviours[{i}] must be a mapping")
        unknown = set(b) - {"policy", "episodes", "start", "epsilon"}
        if unknown:
            raise _fail(params, f"collect.behaviours[{i}]: unknown keys {sorted(unknown)}")
        episodes, eps = b.get("episodes"), b.get("epsilon", 0.0)
        if not isinstance(episodes, int) or isinstance(episodes, bool):
            raise _fail(params, f"collect.behaviours[{i}].episodes must be an integer, got {episodes!r}")
        if not isinstance(eps, (int, float)) or isinstance(eps, bool):
            raise _fail(params, f"collect.behaviours[{i}].epsilon must be a number, got {eps!r}")
        try:  # the values themselves are checked by Behaviour, for library callers too
            behaviours.append(Behaviour(b.get("policy"), episodes, b.get("start", "layout"), float(eps)))
        except ValueError as e:
            raise _fail(params, f"collect.behaviours[{i}].{e}") from None
    render = _get(params, "collect.render", int, 0)
    if not 0 <= render <= 64:
        raise _fail(params, f"collect.render must be 0 (no images) or pixels per cell up to 64, got {render}")
    fps = _get(params, "collect.fps", int, 10)
    if fps < 1:
        raise _fail(params, f"collect.fps must be >= 1, got {fps}")
    return CollectConfig(
        env_id=env["id"], layout=env["layout"], max_steps=env["max_steps"],
        fail_probs=fail_probs(params, "collect.fail_probs"), behaviours=behaviours,
        seed=_get(params, "collect.seed", int), fps=fps, executor=executor_config(params),
        license=_get(params, "collect.license", str, "apache-2.0"), render=render,
    )


def _int_list(params: dict, key: str) -> list[int]:
    values = _get(params, key, list)
    if not values or not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        raise _fail(params, f"{key} must be a non-empty list of integers, got {values!r}")
    return values


def _names(params: dict, key: str, allowed) -> list[str]:
    values = _get(params, key, list)
    bad = [v for v in values if v not in allowed]
    if not values or bad:
        raise _fail(params, f"{key}: unknown name(s) {bad!r}; expected some of {list(allowed)}")
    return values


def model_config(params: dict, env_name: str, condition: str):
    from hnsdt.models.dt import DTConfig

    env = env_settings(params, env_name)
    sizes = {k: _get(params, f"models.{env_name}.{k}", int) for k in ("n_layers", "n_heads", "d_model", "context")}
    if min(sizes.values()) < 1:
        raise _fail(params, f"models.{env_name}: sizes must be positive, got {sizes}")
    tokens = _get(params, f"models.{env_name}.tokens", str, "step")
    try:
        return DTConfig(condition=condition, n_flags=env["layout"].n_flags, grid_h=env["layout"].shape[0],
                        grid_w=env["layout"].shape[1], dropout=_get(params, "train.dropout", float, 0.1),
                        max_timestep=env["max_steps"], tokens=tokens, **sizes)
    except ValueError as e:
        raise _fail(params, f"models.{env_name}: {e}") from None


def train_settings(params: dict) -> dict:
    from hnsdt.models.train import TrainConfig

    envs = _get(params, "train.envs", list)
    for e in envs:
        env_settings(params, e)
    out = {
        "envs": envs, "methods": _names(params, "train.methods", LEARNED_METHODS),
        "seeds": _int_list(params, "train.seeds"),
        "config": TrainConfig(epochs=_get(params, "train.epochs", int), batch_size=_get(params, "train.batch_size", int),
                              lr=_get(params, "train.lr", float), max_steps=_get(params, "train.max_steps", int, 0),
                              device=_get(params, "train.device", str, "auto")),
    }
    behaviours = _get(params, "train.behaviours", dict, {})
    for method, names in behaviours.items():
        if method not in LEARNED_METHODS or not isinstance(names, list) or not set(names) <= set(POLICIES):
            raise _fail(params, f"train.behaviours.{method} must be a list drawn from {POLICIES}, for a method "
                        f"in {LEARNED_METHODS}; got {names!r}")
    out["behaviours"] = {m: tuple(behaviours.get(m, [])) for m in LEARNED_METHODS}
    from hnsdt.data.windows import LOSS_STEPS

    losses = _get(params, "train.loss", dict, {})
    for method, value in losses.items():
        if method not in LEARNED_METHODS or value not in LOSS_STEPS:
            raise _fail(params, f"train.loss.{method} must be one of {LOSS_STEPS}, for a method in "
                        f"{LEARNED_METHODS}; got {value!r}")
    out["loss"] = {m: losses.get(m, "window") for m in LEARNED_METHODS}
    cfg = out["config"]
    if cfg.epochs < 1 or cfg.batch_size < 1 or cfg.lr <= 0 or cfg.max_steps < 0:
        raise _fail(params, "train: epochs and batch_size must be >= 1, lr > 0, max_steps >= 0")
    return out


def baseline_lists(params: dict) -> dict[str, list[str]]:
    """The baselines to train: ``baselines.offline`` (on the dataset) and ``baselines.online``."""
    out = {}
    for kind, allowed in (("offline", OFFLINE_BASELINES), ("online", ONLINE_BASELINES)):
        values = _get(params, f"baselines.{kind}", list, [])
        bad = [v for v in values if v not in allowed]
        if bad:
            raise _fail(params, f"baselines.{kind}: unknown name(s) {bad!r}; expected some of {list(allowed)}")
        out[kind] = values
    return out


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


def baseline_settings(params: dict, method: str, env_name: str, seed: int) -> dict:
    """Network config, training config and evaluation knobs of one baseline on one env and seed, from
    ``baselines.<method>``; unknown keys and wrongly typed values are errors."""
    import dataclasses

    from hnsdt.models.train import pick_device

    if method not in OFFLINE_BASELINES + ONLINE_BASELINES:
        raise _fail(params, f"{method!r} is not a baseline; expected one of "
                    f"{list(OFFLINE_BASELINES + ONLINE_BASELINES)}")
    key = f"baselines.{method}"
    section = dict(_get(params, key, dict))
    env = env_settings(params, env_name)
    lay = env["layout"]
    device = str(pick_device(_get(params, "train.device", str, "auto")))
    grid = {"n_flags": lay.n_flags, "grid_h": lay.shape[0], "grid_w": lay.shape[1]}
    if method in OFFLINE_BASELINES:
        from hnsdt.agents.baselines.recurrent import RecurrentTrainConfig
        from hnsdt.models.recurrent import RecurrentConfig

        behaviours = section.get("behaviours", [])
        if not isinstance(behaviours, list) or not set(behaviours) <= set(POLICIES):
            raise _fail(params, f"{key}.behaviours must be a list drawn from {POLICIES}, got {behaviours!r}")
        net_cls, train_cls = RecurrentConfig, RecurrentTrainConfig
        net_fixed = {"cell": "lstm" if method == "lstm_hier" else "gru", "hierarchical": method == "lstm_hier", **grid}
        train_fixed = {"seed": seed, "device": device, "behaviours": tuple(behaviours)}
        extra = {}
    else:
        from hnsdt.models.qnetwork import OptionCriticConfig, QNetworkConfig

        if method == "dqn":
            from hnsdt.agents.baselines.dqn import DQNConfig as train_cls
            net_cls = QNetworkConfig
        else:
            from hnsdt.agents.baselines.options import OptionsConfig as train_cls
            net_cls = OptionCriticConfig
        budget = section.get("env_steps")
        if isinstance(budget, dict):
            budget = budget.get(env_name)
        if not isinstance(budget, int) or isinstance(budget, bool) or budget < 1:
            raise _fail(params, f"{key}.env_steps must be a positive integer or a mapping env -> one "
                        f"(missing or bad for {env_name!r}: {section.get('env_steps')!r})")
        probs = fail_probs(params, f"{key}.fail_probs") if "fail_probs" in section else None
        net_fixed = grid
        train_fixed = {"seed": seed, "device": device, "env_steps": budget,
                       **({"fail_probs": tuple(probs)} if probs else {})}
        eps = section.get("eval_epsilon", 0.0)
        if not isinstance(eps, (int, float)) or isinstance(eps, bool) or not 0 <= eps <= 1:
            raise _fail(params, f"{key}.eval_epsilon must be a number in [0, 1], got {eps!r}")
        extra = {"eval_epsilon": float(eps)}
    known = ({f.name for f in dataclasses.fields(net_cls)} | {f.name for f in dataclasses.fields(train_cls)}
             | {"behaviours", "env_steps", "eval_epsilon"}) - set(grid) - {"cell", "hierarchical", "seed", "device"}
    unknown = sorted(set(section) - known)
    if unknown:
        raise _fail(params, f"{key}: unknown keys {unknown}; expected some of {sorted(known)}")
    return {"method": method, "env": env, "model": _fill(params, key, net_cls, section, **net_fixed),
            "train": _fill(params, key, train_cls, section, **train_fixed), **extra}


def compute_settings(params: dict, executor: str | None = None, workers: int | None = None):
    """Where runs execute (``compute``), with command-line overrides; see :mod:`hnsdt.executor`."""
    from hnsdt.executor import Compute

    unknown = sorted(set(_get(params, "compute", dict, {})) - {"executor", "workers", "threads"})
    if unknown:
        raise _fail(params, f"compute: unknown keys {unknown}; expected some of ['executor', 'threads', 'workers']")
    try:
        return Compute(executor if executor is not None else _get(params, "compute.executor", str, "local"),
                       workers if workers is not None else _get(params, "compute.workers", int, 0),
                       _get(params, "compute.threads", int, 1))
    except ValueError as e:
        raise _fail(params, str(e)) from None


def evaluate_settings(params: dict) -> dict:
    episodes = _get(params, "evaluate.episodes", int)
    if episodes < 1:
        raise _fail(params, f"evaluate.episodes must be >= 1, got {episodes}")
    per_cell = _get(params, "logs.episodes_per_cell", int, 1)
    if not 0 <= per_cell <= episodes:
        raise _fail(params, f"logs.episodes_per_cell must be in 0..evaluate.episodes, got {per_cell}")
    methods = _names(params, "evaluate.methods", EVAL_METHODS)
    trained = set(_get(params, "train.methods", list)) | {m for v in baseline_lists(params).values() for m in v}
    untrained = [m for m in methods if METHODS[m].training != "none" and m not in trained]
    if untrained:
        raise _fail(params, f"evaluate.methods: {untrained} are never trained (add them to train.methods, "
                    "baselines.offline or baselines.online)")
    return {
        "methods": methods,
        "envs": _get(params, "train.envs", list), "seeds": _int_list(params, "train.seeds"),
        "fail_probs": fail_probs(params, "evaluate.fail_probs"), "episodes": episodes,
        "device": _get(params, "evaluate.device", str, "cpu"), "log_episodes": per_cell,
        "datasets": "data/datasets", "train_behaviours": train_settings(params)["behaviours"]["hnsdt"],
        "eval_epsilon": {m: _get(params, f"baselines.{m}.eval_epsilon", float, 0.0) for m in ONLINE_BASELINES},
    }


def theorem_settings(params: dict) -> dict:
    gamma = _get(params, "theorems.gamma", float)
    bound_b = _get(params, "theorems.B", float)
    delta = _get(params, "theorems.delta", float)
    vc = _get(params, "theorems.vc_dimension", (int, float, str))
    if not 0 < gamma < 1 or bound_b < 0 or not 0 < delta < 1:
        raise _fail(params, "theorems: gamma and delta must be in (0, 1) and B >= 0")
    if not (vc == "parameters" or (isinstance(vc, (int, float)) and not isinstance(vc, bool) and vc > 0)):
        raise _fail(params, f"theorems.vc_dimension must be a positive number or 'parameters', got {vc!r}")
    return {"gamma": gamma, "B": bound_b, "delta": delta, "vc_dimension": vc}
