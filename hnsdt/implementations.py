"""What implements each method of the registry (:mod:`hnsdt.core.methods`): an entry's ``code`` names one of the
families below, each naming its code as ``"module:attribute"`` strings, imported only when used (so reading the
registry costs no torch import). This module sits with the policies (agents, baselines), above the networks:

* ``network``: the model class (its ``arch`` names the checkpoint architecture, its ``config_class`` the
  network knobs), ``config``: the training-knob dataclass, both filled from ``params.yaml``;
* ``trainer``: ``trainer(data, network_cfg, train_cfg, progress, desc, network) -> (model, curve, usage)``,
  where ``data`` is the dataset's frames (``training="dataset"``) or ``(layout, max_steps)`` (``"online"``);
  each also takes ``stop_after`` (epochs, or env steps online) and ``state``: it then returns a state to
  continue from instead, which ``state`` resumes (:mod:`hnsdt.models.fit`, ``OnlineRun.pause``);
* ``agent``: ``agent(model, meta, layout, executor, epsilon, seed)``, the batched agent that is evaluated;
* ``view_network``: the same model reading the grid around the agent (the unseen layouts).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from hnsdt.core.methods import method


@dataclass(frozen=True)
class Code:
    agent: str  # "module:function" building the evaluated agent
    network: str = ""  # "module:Class" of the trained model
    config: str = ""  # "module:Class" of its training knobs
    trainer: str = ""  # "module:function" that trains it
    view_network: str = ""  # "module:Class" of the model reading the grid around the agent


CODE = {
    "transformer": Code("hnsdt.agents.dt_agents:make_agent", "hnsdt.models.dt:DecisionTransformer",
                        "hnsdt.models.train:TrainConfig", "hnsdt.models.train:train_decision_transformer",
                        "hnsdt.models.view:ViewDecisionTransformer"),
    "recurrent": Code("hnsdt.baselines.recurrent:make_agent", "hnsdt.models.recurrent:RecurrentPolicy",
                      "hnsdt.baselines.recurrent:RecurrentTrainConfig", "hnsdt.baselines.recurrent:train_recurrent",
                      "hnsdt.models.view:ViewRecurrentPolicy"),
    "q_learning": Code("hnsdt.baselines.dqn:make_agent", "hnsdt.models.qnetwork:QNetwork",
                       "hnsdt.baselines.dqn:DQNConfig", "hnsdt.baselines.dqn:train_dqn",
                       "hnsdt.models.view:ViewQNetwork"),
    "option_critic": Code("hnsdt.baselines.options:make_agent", "hnsdt.models.qnetwork:OptionCritic",
                          "hnsdt.baselines.options:OptionsConfig", "hnsdt.baselines.options:train_options",
                          "hnsdt.models.view:ViewOptionCritic"),
    "policy_gradient": Code("hnsdt.baselines.ppo:make_agent", "hnsdt.models.qnetwork:ActorCritic",
                            "hnsdt.baselines.ppo:PPOConfig", "hnsdt.baselines.ppo:train_ppo",
                            "hnsdt.models.view:ViewActorCritic"),
    "controllers": Code("hnsdt.agents.symbolic:make_agent"),  # the planner and hand-written controllers
}


def code_of(name: str) -> Code:
    """The code that implements method ``name``."""
    return CODE[method(name).code]


def resolve(ref: str) -> Any:
    """The object a ``"module:attribute"`` reference names."""
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


def network_for(name: str, cfg) -> type:
    """The class of ``name``'s network that ``cfg`` configures: its ``network`` or its ``view_network``."""
    code = code_of(name)
    for ref in (code.network, code.view_network):
        if ref and resolve(ref).config_class is type(cfg):
            return resolve(ref)
    raise ValueError(f"{name}: no network of this method is configured by a {type(cfg).__name__}")
