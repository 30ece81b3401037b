"""The method registry (hnsdt.core.methods) is the one place that names a method."""

from __future__ import annotations

import ast
import copy
from pathlib import Path

import pytest

from hnsdt.agents.rollout import Agent
from hnsdt.core.methods import METHODS, STAGES
from hnsdt.implementations import CODE, code_of, resolve
from hnsdt.models.checkpoint import architectures
from tiny_repo import tiny_online

PACKAGE = Path(__file__).resolve().parent.parent / "hnsdt"


def _string_constants(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.lineno, node.value


# Strings that equal a method's name but mean something else where they appear.
OTHER_MEANINGS = {
    ("models/recurrent.py", "gru"),  # torch's recurrent cell type, which the `gru` and `lstm_hier` entries pick
}


def test_no_module_but_the_registry_spells_a_method_name():
    """Adding or renaming a method touches the registry, its own module and params.yaml, nothing else.
    (``hnsdt`` is also the package's name, which the card and the recordings use as the project's.)"""
    names = set(METHODS) - {"hnsdt"}
    found = [f"{path.relative_to(PACKAGE.parent)}:{line}: {value!r}"
             for path in sorted(PACKAGE.rglob("*.py")) if path.name != "methods.py"
             for line, value in _string_constants(path)
             if value in names and (str(path.relative_to(PACKAGE)), value) not in OTHER_MEANINGS]
    assert not found, "method names outside hnsdt/core/methods.py:\n" + "\n".join(found)


@pytest.mark.parametrize("name", sorted(METHODS))
def test_every_entry_resolves_to_its_code(name):
    import dataclasses

    m, code = METHODS[name], code_of(name)
    assert m.code in CODE and callable(resolve(code.agent))
    if m.training == "none":
        assert not (code.network or code.trainer or code.config or m.stage)
        return
    network, config = resolve(code.network), resolve(code.config)
    assert callable(resolve(code.trainer)) and dataclasses.is_dataclass(config)
    assert dataclasses.is_dataclass(network.config_class) and architectures()[network.arch] is network
    assert architectures()[resolve(code.view_network).arch] is resolve(code.view_network)
    assert set(m.fixed) <= {f.name for f in dataclasses.fields(network.config_class)}
    assert name in STAGES[m.stage]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Params at a tiny budget and a small Case 1 dataset (random walks cover every operator, Move included)."""
    from hnsdt.compose.config import collect_config, load_params
    from hnsdt.data.collect import collect_dataset
    from hnsdt.compose.params import validate

    params = copy.deepcopy(load_params(PACKAGE.parent / "params.yaml").raw)
    params["collect"]["fail_probs"] = [0.1]
    params["collect"]["behaviours"] = [{"policy": "random", "episodes": 30, "start": "random"},
                                       {"policy": "noisy_planner", "episodes": 6, "start": "random", "epsilon": 0.1}]
    params["train"].update(seeds=[0], epochs=1, max_steps=2)
    for name in params["baselines"]["offline"]:
        params["baselines"][name].update(epochs=1, max_steps=2)
    for name in params["baselines"]["online"]:
        tiny_online(params["baselines"][name], env_steps=64, learning_starts=32, rollout_steps=4)
    params = validate(params)
    dataset = tmp_path_factory.mktemp("data") / "keydoor"
    collect_dataset(collect_config(params, "keydoor"), dataset, repo_id="local/keydoor", progress=False)
    return params, dataset


@pytest.mark.parametrize("name", sorted(METHODS))
def test_every_method_trains_and_acts_through_its_registry_entry(tiny, name):
    """CleanRL-style smoke run of each entry's whole path at a tiny budget: its params, trainer, checkpoint
    architecture and agent, then a batch of evaluation episodes. (Whether it learns is tested elsewhere.)"""
    import json

    from hnsdt.compose.config import env_spec, method_executor
    from hnsdt.evaluation.paper import Cell, run_cell
    from hnsdt.evaluation.runs import build_agent
    from hnsdt.models.checkpoint import load_checkpoint, save_checkpoint
    from hnsdt.compose.training import plan_runs, train_run

    params, dataset = tiny
    env = env_spec(params, "keydoor")
    model, meta = None, {}
    if METHODS[name].training != "none":
        (run,) = plan_runs(params, "keydoor", name, [0], dataset)
        model, facts, curve = train_run(run)
        assert curve and facts["usage"]
        path = save_checkpoint(model, dataset.parent / "models" / name, {"method": name, **facts})
        model, meta = load_checkpoint(path)
        assert json.loads((path / "config.json").read_text())["arch"] == resolve(code_of(name).network).arch
    agent = build_agent(name, env.layout, method_executor(params, name), model, meta)
    assert isinstance(agent, Agent)  # the protocol every evaluated policy follows
    episodes = run_cell(Cell(name, "keydoor", 0.1, 0), 0, env.layout, 20, 3, agent)
    assert len(episodes) == 3 and all(1 <= ep.length <= 20 for ep in episodes)


def test_the_train_stage_declares_every_training_knob_it_reads():
    """A `train` knob the decision transformers' training reads but the `train` stage does not list in its params
    would not rerun training when changed (train.formulation and train.validation once were missing)."""
    import yaml

    from hnsdt.compose.params import TrainParams

    stage = yaml.safe_load((Path(__file__).parents[1] / "dvc.yaml").read_text())["stages"]["train"]
    declared = set(stage["params"])
    read = set(TrainParams.model_fields) - {"envs", "methods"}  # these two expand the stage's matrix instead
    assert "train" in declared or not {f"train.{knob}" for knob in read} - declared


@pytest.mark.parametrize("name", ["train_generalisation", "unseen_experiment"])
def test_the_unseen_layout_transformers_declare_the_train_knobs_they_read_and_not_the_paper_protocols(name):
    """The unseen-layout DTs read `train`'s training knobs but not the paper protocol's envs, methods and seeds
    (their seeds are generalisation's): `dvc exp run -S 'train.seeds=[0]'` or a further paper map must not
    retrain them."""
    import yaml

    from hnsdt.compose.params import TrainParams

    stage = yaml.safe_load((Path(__file__).parents[1] / "dvc.yaml").read_text())["stages"][name]["do"]
    declared = {p for p in stage["params"] if isinstance(p, str)}
    protocol = {"train.envs", "train.methods", "train.seeds"}
    assert not {f"train.{knob}" for knob in TrainParams.model_fields} - protocol - declared
    assert "train" not in declared and not protocol & declared
